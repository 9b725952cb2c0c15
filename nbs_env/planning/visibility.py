"""The greedy NBS gain (paper §4, METHOD §7): predicted Occluded-structure→Structure conversions.

For each next valid position, the scanner is placed there and the OCCLUDED_STRUCTURE voxels it
would see are counted: a voxel counts when it lies inside the field of view and the range limits,
and the line of sight to its centre meets no occupied voxel on the way. Lines of sight are cast with
Embree against a mesh of the occupied voxels' exposed faces, built once per grid; only V(t) is used,
never the scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nbs_env.config import Config, ScannerConfig, _finite_fields, _integer, _require
from nbs_env.labels import VoxelLabel, is_occupied
from scenes._open3d import open3d

__all__ = ["GainConfig", "VisibilityModel", "occupied_surface"]


@dataclass(frozen=True)
class GainConfig(Config):
    """Options of the gain.

    Attributes
    ----------
    model : str
        The gain model, by its name in :data:`nbs_env.planning.planner.GAIN_MODELS`: ``"visibility"``
        (this module's :class:`VisibilityModel`, the paper's gain) or one registered with
        :func:`nbs_env.planning.planner.register_gain_model`. The options below are the visibility
        model's; another model may read them or not.
    occluded_clutter_blocks : bool
        Whether OCCLUDED_CLUTTER voxels block lines of sight as occupied ones do. Unsensed space
        may hold furniture; blocking is the pessimistic reading (see benchmarks/README.md for the
        measurement that chose the default).
    tolerance_voxels : float
        A line of sight that reaches within this many voxels of the target counts: the target's own
        neighbours on the same wall must not hide it at grazing angles.
    group : int
        Occluded-structure voxels are cast to in groups of ``group``³ voxels: one line of sight to
        the mean centre of a group's members stands for all of them. Surfaces are thin, so groups of
        2 cut the rays about fourfold at 5 cm (measured in benchmarks/gain.py); 1 casts to every voxel.
    """

    model: str = "visibility"
    occluded_clutter_blocks: bool = False
    tolerance_voxels: float = 1.0
    group: int = 2

    def __post_init__(self) -> None:
        _require(
            isinstance(self.model, str) and self.model != "", f"model must be a gain model's name, got {self.model!r}"
        )
        _require(
            isinstance(self.occluded_clutter_blocks, bool),
            f"occluded_clutter_blocks must be true or false, got {self.occluded_clutter_blocks!r}",
        )
        _finite_fields(self, "tolerance_voxels")
        _require(self.tolerance_voxels >= 0, f"tolerance_voxels must be >= 0, got {self.tolerance_voxels}")
        _integer(self, "group", 1)


def occupied_surface(blocking: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exposed faces of the blocking voxels as a triangle mesh in voxel units.

    Parameters
    ----------
    blocking : (nx, ny, nz) bool

    Returns
    -------
    vertices : (v, 3) float32
        Corners in voxel units (voxel (i, j, k) spans [i, i+1] x [j, j+1] x [k, k+1]).
    triangles : (t, 3) uint32
    """
    padded = np.pad(blocking, 1)
    quads = []
    # For each axis and direction, a face is exposed where the neighbour is not blocking.
    corners = {
        0: np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]),
        1: np.array([[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]),
        2: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
    }
    inner = padded[1:-1, 1:-1, 1:-1]
    for axis in range(3):
        for side in (0, 1):
            # The neighbour across the face: one voxel along the axis, read from the padded grid.
            window = [slice(1, -1)] * 3
            window[axis] = slice(2, None) if side else slice(0, -2)
            idx = np.argwhere(inner & ~padded[tuple(window)])
            if not len(idx):
                continue
            base = idx.astype(np.float32)
            base[:, axis] += side
            quads.append(base[:, None, :] + corners[axis][None, :, :])
    if not quads:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)
    q = np.concatenate(quads).astype(np.float32)  # (m, 4, 3)
    vertices = q.reshape(-1, 3)
    base = np.arange(len(q), dtype=np.uint32)[:, None] * 4
    triangles = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])]).astype(np.uint32)
    return vertices, triangles


class VisibilityModel:
    """Lines of sight through one state of the voxel grid.

    Parameters
    ----------
    labels : (nx, ny, nz) uint8
        VoxelLabel values of V(t).
    origin : (3,) float
        World position of the corner of voxel (0, 0, 0).
    voxel_size : float
    config : GainConfig
    """

    def __init__(self, labels: np.ndarray, origin: np.ndarray, voxel_size: float, config: GainConfig | None = None):
        self.config = config or GainConfig()
        self.origin = np.asarray(origin, dtype=float)
        self.voxel_size = float(voxel_size)
        blocking = is_occupied(labels)
        if self.config.occluded_clutter_blocks:
            blocking |= labels == VoxelLabel.OCCLUDED_CLUTTER
        targets = np.argwhere(labels == VoxelLabel.OCCLUDED_STRUCTURE)
        self.targets = self.origin + (targets + 0.5) * self.voxel_size  # (n, 3) world centres
        # Groups of voxels share one line of sight (see GainConfig.group).
        g = max(1, int(self.config.group))
        if len(targets):
            # One integer per group, in the lexicographic order of its (i, j, k) // g: the groups of
            # np.unique(targets // g, axis=0) without its sort of rows.
            cells = targets // g
            span = np.asarray(labels.shape) // g + 1
            key = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
            _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
            sums = np.zeros((len(counts), 3))
            np.add.at(sums, inverse, self.targets)
            self.group_centres = sums / counts[:, None]
            self.group_counts = counts.astype(np.int64)
        else:
            self.group_centres = np.zeros((0, 3))
            self.group_counts = np.zeros(0, dtype=np.int64)
        vertices, triangles = occupied_surface(blocking)
        o3d = open3d()
        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        if len(triangles):
            world = (self.origin + vertices.astype(np.float64) * self.voxel_size).astype(np.float32)
            self._scene.add_triangles(o3d.core.Tensor(world), o3d.core.Tensor(triangles))
        self.n_triangles = len(triangles)

    def visible(self, sensor: np.ndarray, scanner: ScannerConfig) -> np.ndarray:
        """(n,) bool: which OCCLUDED_STRUCTURE voxels (:attr:`targets`) a scanner at ``sensor`` (3,)
        would see, one line of sight each (no grouping): for inspecting the model."""
        targets = self.targets.astype(np.float32)
        _, idx = self._lines_of_sight(np.asarray(sensor, dtype=np.float32).reshape(1, 3), targets, scanner)
        out = np.zeros(len(targets), dtype=bool)
        out[idx] = True
        return out

    def gains(self, sensors: np.ndarray, scanner: ScannerConfig, chunk: int = 16) -> np.ndarray:
        """(m,) int: predicted conversions for each of the (m, 3) scanner positions.

        The lines of sight of ``chunk`` candidates go to Embree in one call: one large cast keeps
        both cores busy where many small ones do not.
        """
        sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
        out = np.zeros(len(sensors), dtype=np.int64)
        if not len(self.targets) or not len(sensors):
            return out
        targets = self.group_centres.astype(np.float32)
        for start in range(0, len(sensors), chunk):
            block = sensors[start : start + chunk].astype(np.float32)
            which, idx = self._lines_of_sight(block, targets, scanner)
            out[start : start + chunk] = np.bincount(which, weights=self.group_counts[idx], minlength=len(block))
        return out

    def _lines_of_sight(
        self, sensors: np.ndarray, targets: np.ndarray, scanner: ScannerConfig
    ) -> tuple[np.ndarray, np.ndarray]:
        """(sensor, target) index pairs with a clear line of sight inside the field of view and the
        range limits, for (c, 3) and (n, 3) float32 positions."""
        lo = np.float32(np.sin(np.radians(scanner.elevation_min)))
        hi = np.float32(np.sin(np.radians(scanner.elevation_max)))
        tolerance = np.float32(self.config.tolerance_voxels * self.voxel_size)
        rel = targets[None, :, :] - sensors[:, None, :]  # (c, n, 3)
        dist = np.sqrt(np.einsum("cni,cni->cn", rel, rel))
        sine = rel[..., 2] / np.maximum(dist, np.float32(1e-9))
        ok = (dist >= scanner.min_range) & (dist <= scanner.max_range) & (sine >= lo) & (sine <= hi)
        which, idx = np.nonzero(ok)
        if not len(idx) or self.n_triangles == 0:
            return which, idx
        d = dist[which, idx]
        rays = np.empty((len(idx), 6), dtype=np.float32)
        rays[:, :3] = sensors[which]
        rays[:, 3:] = rel[which, idx] / d[:, None]
        t_hit = self._scene.cast_rays(self._o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy()
        seen = t_hit >= d - tolerance
        return which[seen], idx[seen]
