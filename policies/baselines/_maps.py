"""Shared machinery of the compared methods: structure-agnostic views of the robot's voxel space,
2-D line of sight, 3-D ray marching, and the policy base class with its own stopping rule.

The compared methods got the paper's dynamic voxel space and door detection, not its SE
classification: here the five labels collapse to free (Empty), occupied (Clutter or Structure) and
unknown (Unknown, Occluded-clutter, Occluded-structure).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from nbs_env.labels import VoxelLabel, is_occupied
from nbs_env.observation import BeliefView

__all__ = ["MappingPolicy", "band_columns", "collapse", "march", "sphere_directions", "visible_cells_2d"]


def collapse(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(free, occupied, unknown) bool arrays of the labels' shape: what a structure-agnostic method sees."""
    free = labels == VoxelLabel.EMPTY
    occupied = is_occupied(labels)
    return free, occupied, ~(free | occupied)


def band_columns(grid, floor_z: float, lo: float = 0.3, hi: float = 2.0) -> slice:
    """The z slice of ``grid`` from ``lo`` to ``hi`` metres above the floor (a 2-D map's band)."""
    k0 = int(np.clip(math.floor((floor_z + lo - grid.origin[2]) / grid.voxel_size), 0, grid.shape[2] - 1))
    k1 = int(np.clip(math.ceil((floor_z + hi - grid.origin[2]) / grid.voxel_size), k0 + 1, grid.shape[2]))
    return slice(k0, k1)


def visible_cells_2d(
    blocked: np.ndarray,
    origin_xy: np.ndarray,
    cell: float,
    sensor_xy: np.ndarray,
    min_range: float,
    max_range: float,
    n_rays: int = 360,
) -> np.ndarray:
    """Flat indices of the cells of a 2-D map a 360° sensor at ``sensor_xy`` sees.

    Parameters
    ----------
    blocked : (nx, ny) bool
        Cells that stop a ray (the first blocked cell on a ray is itself seen).
    origin_xy : (2,) float
        World xy of the corner of cell (0, 0).
    cell : float
        Cell size, metres.
    sensor_xy : (2,) float
    min_range, max_range : float
        Cells nearer than ``min_range`` are not measured (but do block).

    Returns
    -------
    (v,) int64, unique flat indices into ``blocked``.
    """
    nx, ny = blocked.shape
    theta = (np.arange(n_rays) + 0.5) * (2 * np.pi / n_rays)
    radii = np.arange(cell / 2, max_range, cell / 2)
    xy = sensor_xy[None, None, :] + radii[None, :, None] * np.stack([np.cos(theta), np.sin(theta)], -1)[:, None, :]
    ij = np.floor((xy - origin_xy) / cell).astype(np.int64)
    inside = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
    flat = np.where(inside, ij[..., 0] * ny + ij[..., 1], 0)
    hit = blocked.reshape(-1)[flat] & inside
    # A ray stops after its first blocked cell, and at the edge of the map.
    before = np.cumsum(hit, axis=1) - hit
    ok = inside & (before == 0) & (np.cumsum(~inside, axis=1) == 0) & (radii[None, :] >= min_range)
    return np.unique(flat[ok])


def sphere_directions(step_deg: float, elevation_min: float, elevation_max: float) -> np.ndarray:
    """(r, 3) float unit directions on a regular azimuth-elevation grid of the scanner's field."""
    az = np.radians(np.arange(0.0, 360.0, step_deg))
    el = np.radians(np.arange(elevation_min + step_deg / 2, elevation_max, step_deg))
    a, e = np.meshgrid(az, el, indexing="ij")
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)


def march(
    shape: tuple[int, int, int],
    origin: np.ndarray,
    voxel: float,
    sensor: np.ndarray,
    directions: np.ndarray,
    max_range: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Walk rays through a voxel array in steps of one voxel from ``sensor``.

    Returns
    -------
    flat : (r, s) int64
        Flat index of the voxel of each sample (0 outside: mask with ``inside``); gather any array
        of ``shape`` with ``array.reshape(-1)[flat]``.
    first : (r, s) bool
        The sample is the first of its voxel on the ray.
    inside : (r, s) bool
        The sample lies in the array.
    distance : (s,) float
        Distance of each step from the sensor.
    """
    distance = np.arange(voxel / 2, max_range, voxel, dtype=np.float32)
    pts = sensor.astype(np.float32)[None, None, :] + distance[None, :, None] * directions.astype(np.float32)[:, None, :]
    idx = np.floor((pts - origin.astype(np.float32)) / np.float32(voxel)).astype(np.int64)
    dims = np.asarray(shape)
    inside = np.all((idx >= 0) & (idx < dims), axis=-1)
    idx[~inside] = 0
    flat = (idx[..., 0] * dims[1] + idx[..., 1]) * dims[2] + idx[..., 2]
    first = np.ones(flat.shape, dtype=bool)
    first[:, 1:] = (flat[:, 1:] != flat[:, :-1]) | (inside[:, 1:] != inside[:, :-1])
    return flat, first, inside, distance


class MappingPolicy:
    """Base of the compared methods: keeps per-room state from ``info["belief"]``, and ends a room by
    its own rule (completion="policy": the last action means "room done").

    The stopping rule, common in spirit to all of them ("stop when no candidate's gain is above
    ε"), is made scale-free: a room ends when the best utility falls below ``stop_fraction`` of the
    best utility at the room's first decision.
    """

    name = "mapping"
    #: The env settings the policy needs (``nbs compare`` and ``nbs scan`` apply them).
    env_overrides: ClassVar[dict[str, Any]] = {"completion": "policy", "expose_belief": True}
    robot_overrides: ClassVar[dict[str, Any]] = {"predict_gains": False}
    #: Structure-agnostic methods process every point (METHOD §9).
    structure_aware = False

    def __init__(self, stop_fraction: float = 0.05) -> None:
        self.stop_fraction = stop_fraction
        self.reset()

    def reset(self) -> None:
        self._room: int | None = None
        self._first_best: float | None = None

    def _belief(self, info: dict[str, Any]) -> BeliefView:
        if "belief" not in info:
            raise KeyError(
                f"{type(self).__name__} keeps its own map and needs info['belief']: make the env with "
                f"expose_belief=True and completion='policy' (see {type(self).__name__}.env_overrides)"
            )
        return info["belief"]

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        belief = self._belief(info)
        stop = len(belief.mask)  # the "room done" action
        self._track_room(belief)
        self.observe(belief)
        valid = np.flatnonzero(belief.mask)
        if not len(valid):
            return stop
        utility = self.utilities(belief, valid)
        best = int(valid[int(np.argmax(utility))])
        top = float(np.max(utility))
        if self._first_best is None:
            self._first_best = max(top, 1e-9)
        elif self.should_stop(top, belief):
            return stop
        return best

    def _track_room(self, belief: BeliefView) -> None:
        """Start afresh when the robot has entered a room."""
        if belief.room != self._room or belief.new_room:
            self._room = belief.room
            self._first_best = None
            self.new_room(belief)

    # ------------------------------------------------------------------ hooks
    def new_room(self, belief: BeliefView) -> None:
        """Start the maps of a new room."""

    def observe(self, belief: BeliefView) -> None:
        """Take in this step's measurements."""

    def utilities(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        """(len(valid),) float: the utility of each valid candidate."""
        raise NotImplementedError

    def should_stop(self, best: float, belief: BeliefView) -> bool:
        assert self._first_best is not None
        return best < self.stop_fraction * self._first_best
