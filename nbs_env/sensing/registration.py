"""Registration of a new scan into the accumulated cloud S(t): point-to-plane ICP from the odometry pose.

S(t) keeps every registered scan at full resolution (for output and the coverage metric) and a
voxel-downsampled working copy with normals (for ICP and perception), for the storey and per room.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from nbs_env.config import RegistrationConfig
from nbs_env.sensing.pose import check_pose, pose_error
from scenes._open3d import open3d

__all__ = ["AccumulatedCloud", "RegistrationResult", "register"]


def _cloud(points: np.ndarray, normals: np.ndarray | None = None):
    o3d = open3d()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    return pc


def _downsample_with_normals(points: np.ndarray, origin: np.ndarray, voxel: float, radius: float | None):
    o3d = open3d()
    pc = _cloud(points).voxel_down_sample(voxel)
    if radius is None:
        return pc
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    # Normals face the scanner, so that averaging over scans does not cancel them.
    pc.orient_normals_towards_camera_location(np.asarray(origin, dtype=np.float64))
    return pc


@contextlib.contextmanager
def _open3d_threads(n: int | None) -> Iterator[None]:
    """Run open3d with ``n`` threads (None: leave as is), restoring the previous count afterwards."""
    if n is None:
        yield
        return
    utility = open3d().utility
    previous = utility.get_max_threads()
    utility.set_max_threads(n)
    try:
        yield
    finally:
        utility.set_max_threads(previous)


class AccumulatedCloud:
    """S(t): the registered scans of the storey and of each room.

    Parameters
    ----------
    voxel_size : float
        Voxel size of the working copies in metres.
    normal_radius : float
        Neighbourhood radius for the normals of the working copies.
    normals : bool
        Estimate normals (ICP's target needs them); without, adding a scan costs about a third.
    rooms : bool
        Keep a working copy per room as well as the storey's.
    """

    def __init__(
        self, voxel_size: float = 0.05, normal_radius: float = 0.15, *, normals: bool = True, rooms: bool = True
    ) -> None:
        self.voxel_size = voxel_size
        self.normal_radius = normal_radius
        self.normals = normals
        self.rooms = rooms
        self._full: list[np.ndarray] = []
        self._rooms_of_scans: list[int] = []
        self._origins: list[np.ndarray] = []
        self._storey = None
        self._room_copies: dict[int, object] = {}
        self._pending: list[int] = []

    def __len__(self) -> int:
        return len(self._full)

    @property
    def n_points(self) -> int:
        """Points at full resolution over all scans."""
        return int(sum(len(p) for p in self._full))

    def add(self, points_world: np.ndarray, origin: np.ndarray, room: int = 0) -> None:
        """Add a registered scan.

        Parameters
        ----------
        points_world : (n, 3) float
            The scan placed with the robot's pose estimate.
        origin : (3,) float
            The estimated scanner position (normals are oriented towards it).
        room : int
            The room the robot believes it is scanning.
        """
        points_world = np.asarray(points_world, dtype=np.float64)
        if points_world.ndim != 2 or points_world.shape[1] != 3 or not np.all(np.isfinite(points_world)):
            raise ValueError(f"points_world must be a finite (n, 3) array, got shape {points_world.shape}")
        self._full.append(points_world)
        self._rooms_of_scans.append(int(room))
        self._origins.append(np.asarray(origin, dtype=float))
        # The working copies are merged when first asked for: a robot without ICP never asks.
        self._pending.append(len(self._full) - 1)

    def _update(self) -> None:
        for k in self._pending:
            points, origin, room = self._full[k], self._origins[k], self._rooms_of_scans[k]
            new = _downsample_with_normals(
                points, origin, self.voxel_size, self.normal_radius if self.normals else None
            )
            self._storey = self._merge(self._storey, new)
            if self.rooms:
                self._room_copies[room] = self._merge(self._room_copies.get(room), new)
        self._pending = []

    def _merge(self, old, new):
        if old is None:
            return new
        merged = old + new
        return merged.voxel_down_sample(self.voxel_size)

    # ------------------------------------------------------------------ views
    def storey_points(self) -> np.ndarray:
        """(n, 3) float: all registered points at full resolution."""
        return np.concatenate(self._full) if self._full else np.zeros((0, 3))

    def room_points(self, room: int) -> np.ndarray:
        """(n, 3) float: the full-resolution points of the scans taken in ``room``."""
        parts = [p for p, r in zip(self._full, self._rooms_of_scans, strict=True) if r == room]
        return np.concatenate(parts) if parts else np.zeros((0, 3))

    def working_points(self, room: int | None = None) -> np.ndarray:
        """(n, 3) float: the downsampled working copy of the storey, or of one room."""
        self._update()
        pc = self._storey if room is None else self._room_copies.get(room)
        return np.zeros((0, 3)) if pc is None else np.asarray(pc.points)

    def working_cloud(self, room: int | None = None):
        """The downsampled working copy (an open3d PointCloud with normals), or None when empty."""
        self._update()
        return self._storey if room is None else self._room_copies.get(room)


@dataclass(frozen=True)
class RegistrationResult:
    """The outcome of registering one scan.

    Attributes
    ----------
    pose : (4, 4) float
        The pose to use: ICP's when accepted, the odometry pose when rejected.
    initial : (4, 4) float
        The odometry pose ICP started from.
    fitness : float
        Share of source points with a correspondence at the finest stage.
    rmse : float
        Inlier RMSE at the finest stage, metres.
    accepted : bool
        Whether ICP's pose was accepted.
    reason : str
        Why it was rejected (empty when accepted).
    correction_m, correction_deg : float
        How far ICP moved the pose away from the odometry pose.
    seconds : float
        Time spent.
    """

    pose: np.ndarray
    initial: np.ndarray
    fitness: float
    rmse: float
    accepted: bool
    reason: str
    correction_m: float
    correction_deg: float
    seconds: float


def register(
    points_sensor: np.ndarray,
    initial: np.ndarray,
    cloud: AccumulatedCloud,
    config: RegistrationConfig | None = None,
    travelled: float = 0.0,
) -> RegistrationResult:
    """Align a scan to S(t) by coarse-to-fine point-to-plane ICP, starting from the odometry pose.

    Parameters
    ----------
    points_sensor : (n, 3) float
        The scan in the sensor frame.
    initial : (4, 4) float
        The odometry pose estimate.
    cloud : AccumulatedCloud
        S(t). When it is empty (the first scan) the initial pose is accepted as it is.
    config : RegistrationConfig
    travelled : float
        Metres driven since the last scan: the correction gates grow with it.

    Returns
    -------
    RegistrationResult
        Rejected (keeping ``initial``) when fitness is too low, RMSE too high, or the correction is
        larger than odometry drift can explain.
    """
    cfg = config or RegistrationConfig()
    o3d = open3d()
    t0 = time.perf_counter()
    initial = check_pose(initial, "initial pose")
    target = cloud.working_cloud()
    if target is None or len(target.points) == 0:
        return RegistrationResult(initial, initial, 1.0, 0.0, True, "", 0.0, 0.0, time.perf_counter() - t0)
    # Only the part of S(t) the scan can overlap; a storey-wide target slows every ICP step.
    centre = initial[:3, 3]
    box = o3d.geometry.AxisAlignedBoundingBox(centre - cfg.target_radius, centre + cfg.target_radius)
    target = target.crop(box)
    # Only surfaces that face the scanner can be in its scan. Without this, the far face of a wall
    # (scanned from the next room, 10-25 cm behind) offers ICP a parallel twin to lock onto:
    # measured on five_rooms, accepted poses 15 cm off, one wall thickness.
    if target.has_normals() and len(target.points):
        pts, nrm = np.asarray(target.points), np.asarray(target.normals)
        facing = np.einsum("ij,ij->i", nrm, centre - pts) > 0
        target = target.select_by_index(np.flatnonzero(facing).tolist())
    source = _cloud(points_sensor).voxel_down_sample(cfg.voxel_size)
    reg = o3d.pipelines.registration
    pose = initial.copy()
    fitness, rmse = 0.0, float("inf")
    # Parallel reductions in open3d's ICP differ in the last bits from run to run, and ICP can
    # amplify that into a different local minimum; one thread makes a seed give the same poses.
    with _open3d_threads(1 if cfg.deterministic else None):
        for distance in cfg.max_correspondence:
            result = reg.registration_icp(
                source,
                target,
                distance,
                pose,
                reg.TransformationEstimationPointToPlane(),
                reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=cfg.max_iterations),
            )
            pose = np.asarray(result.transformation).copy()
            fitness, rmse = float(result.fitness), float(result.inlier_rmse)
    moved_m, moved_deg = pose_error(pose, initial)
    reason = ""
    if fitness < cfg.min_fitness:
        reason = f"fitness {fitness:.3f} below {cfg.min_fitness}"
    elif rmse > cfg.max_rmse:
        reason = f"RMSE {rmse:.4f} m above {cfg.max_rmse} m"
    else:
        gate_m = max(cfg.max_correction_m, cfg.correction_per_metre_m * travelled)
        gate_deg = max(cfg.max_correction_deg, cfg.correction_per_metre_deg * travelled)
        if moved_m > gate_m or moved_deg > gate_deg:
            reason = f"correction of {moved_m:.2f} m / {moved_deg:.1f}° exceeds {gate_m:.2f} m / {gate_deg:.1f}°"
    accepted = not reason
    return RegistrationResult(
        pose=pose if accepted else initial,
        initial=initial,
        fitness=fitness,
        rmse=rmse,
        accepted=accepted,
        reason=reason,
        correction_m=moved_m,
        correction_deg=moved_deg,
        seconds=time.perf_counter() - t0,
    )
