"""Wall search: where to scan so that the room's walls no scan faced get a frontal view.

The robot finds a door only on a wall some scan faced: the lintel in range and the opening crossed
by rays (:func:`~nbs_env.perception.doors.detect_doors`). The NBS gain does not ask for that: a wall
seen edge-on, or never seen at all, holds no Occluded-structure, so a room can end by the gain rule
(or by a learned "room done") with a door never in front of a scan, and the rooms behind it are
never entered. This module measures, from the robot's belief only, which stretches of the RoI's
walls no stop of the room viewed frontally, and picks the NVP that would view most of them::

    unviewed_wall(roi, stops, sees, scanned_rooms, config) -> WallSamples (targets flagged)
    search_position(walls, sensors, path_length, sees, config) -> NVP index or None
    approach_position(walls, sensors, path_length, stops, config) -> NVP index or None

When no NVP views the targets (they lie beyond floor the robot has not measured, so no NVP stands
where they could be seen), :func:`approach_position` picks the NVP nearest to them instead: its
scan measures the floor in between from closer, which may open a way to stand where they show.
When no NVP comes near either, the robot looks for a place that views them among those it reaches
keeping only its radius clear (``narrow``; the NVPs keep a safety distance more).

``sees(sensors, targets)`` is a line-of-sight test through V(t)
(:meth:`~nbs_env.planning.visibility.VisibilityModel.sees`). Not part of the paper's method
(METHOD §7 ends a room by its gain alone): :attr:`nbs_env.config.WallSearchConfig.scans`
switches it on, 0 (off) by default.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from nbs_env.config import ScannerConfig, WallSearchConfig
from nbs_env.perception.roi import RoI

__all__ = ["WallSamples", "WallSearchConfig", "approach_position", "search_position", "unviewed_wall"]

#: ``sees(sensors (c, 3), targets (n, 3)) -> (c, n) bool``.
LineOfSight = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class WallSamples:
    """The RoI's walls as sample columns.

    Attributes
    ----------
    points : (m * h, 3) float
        Each column's samples (h = ``len(config.heights)``), column-major; NaN for columns that
        need no view.
    normals : (m, 2) float
        The inward normal of each column's face.
    face : (m,) int
        Index of each column's face in ``roi.wall_faces``.
    target : (m,) bool
        Columns in unviewed stretches of at least ``config.min_run``.
    floor_z : float
        The RoI's floor height.
    """

    points: np.ndarray
    normals: np.ndarray
    face: np.ndarray
    target: np.ndarray
    floor_z: float = 0.0

    @property
    def columns(self) -> int:
        return len(self.face)

    @property
    def column_xy(self) -> np.ndarray:
        """(m, 2) float: each column's place in the plane (NaN for columns that need no view)."""
        return self.points[:: len(self.points) // self.columns if self.columns else 1, :2]


def opening_rays(
    sensors: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    floor_z: float,
    scanner: ScannerConfig,
    width: float,
    height: float,
    thickness: float = 0.0,
) -> np.ndarray:
    """(c, n) float: about how many of a scanner's rays from each of the (c, 3) sensors pass
    through a ``width`` x ``height`` opening in the wall at each of the (n, 3) points (its floor at
    ``floor_z``, its face's inward normal (n, 2), in a wall ``thickness`` thick): the opening's
    angular width (foreshortened by the incidence, less what its far jamb hides) times its angular
    height (within the elevation band), over the angular step squared. 0 from behind the wall."""
    ray = sensors[:, None, :2] - points[None, :, :2]
    d = np.maximum(np.linalg.norm(ray, axis=2), 1e-6)
    cos = np.clip(np.einsum("cnk,nk->cn", ray, normals) / d, 0.0, 1.0)
    z = sensors[:, None, 2] - floor_z
    lo = np.maximum(np.arctan2(-z, d), np.radians(scanner.elevation_min))
    hi = np.minimum(np.arctan2(height - z, d), np.radians(scanner.elevation_max))
    step = np.radians(scanner.angular_step)
    sin = np.sqrt(1.0 - cos**2)
    clear = np.maximum(width * cos - thickness * sin, 0.0)
    return (clear / d / step) * (np.maximum(hi - lo, 0.0) / step)


def _viewed(
    walls: WallSamples,
    sensors: np.ndarray,
    sees: LineOfSight,
    config: WallSearchConfig,
    scanner: ScannerConfig | None = None,
    columns: np.ndarray | None = None,
) -> np.ndarray:
    """(c, m) bool: which columns each of the (c, 3) sensors views; only the ``columns`` (m,) bool
    are tested when given (the rest read False)."""
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    h = len(config.heights)
    out = np.zeros((len(sensors), walls.columns * h), dtype=bool)
    valid = np.isfinite(walls.points[:, 0])
    if columns is not None:
        valid &= np.repeat(columns, h)
    if valid.any() and len(sensors):
        points = walls.points[valid]
        normals = np.repeat(walls.normals, h, axis=0)[valid]
        ray = sensors[:, None, :] - points[None, :, :]
        dist = np.linalg.norm(ray, axis=2)
        cos = np.einsum("cnk,nk->cn", ray[:, :, :2], normals) / np.maximum(dist, 1e-9)
        frontal = (cos >= np.cos(np.radians(config.incidence_deg))) & (dist <= config.max_range)
        if scanner is not None:
            # A door is found by its lintel: standing under it, the scanner's minimum range hides it.
            lintel = points.copy()
            lintel[:, 2] = walls.floor_z + config.opening_height
            frontal &= np.linalg.norm(sensors[:, None, :] - lintel[None, :, :], axis=2) >= scanner.min_range
        if config.min_rays and scanner is not None:
            rays = opening_rays(
                sensors,
                points,
                normals,
                walls.floor_z,
                scanner,
                config.opening_width,
                config.opening_height,
                config.wall_thickness,
            )
            frontal &= rays >= config.min_rays
        out[:, valid] = sees(sensors, points) & frontal
    return out.reshape(len(sensors), walls.columns, h).any(axis=2)


def unviewed_wall(
    roi: RoI,
    stops: Sequence[np.ndarray] | np.ndarray,
    sees: LineOfSight,
    scanned_rooms: Sequence[Polygon] = (),
    config: WallSearchConfig | None = None,
    min_face: float = 0.0,
    scanner: ScannerConfig | None = None,
) -> WallSamples:
    """Sample the RoI's wall faces and flag the stretches no stop viewed frontally.

    Parameters
    ----------
    roi : RoI
        The room's region of interest (its polygon is counter-clockwise: normals point inward).
    stops : (s, 3) float
        The room's scanner positions.
    sees : callable
        ``sees(sensors (c, 3), targets (n, 3)) -> (c, n) bool``, lines of sight through V(t).
    scanned_rooms : sequence of Polygon
        Outlines of rooms already scanned: a column whose far side lies in one needs no view.
    config : WallSearchConfig
    min_face : float
        Faces shorter than this (metres) are not sampled (shorter than the narrowest door).
    scanner : ScannerConfig, optional
        The scanner. With it, a stop views a column only if the top of an ``opening_height``
        opening there lies beyond the scanner's minimum range (a lintel under the scanner is never
        measured, and door detection needs it), and ``config.min_rays`` applies.
    """
    config = config or WallSearchConfig()
    points, normals, faces = [], [], []
    for k, face in enumerate(roi.wall_faces):
        if face.length < max(min_face, 1e-9):
            continue
        u = np.arange(config.step / 2, face.length, config.step)
        xy = np.asarray(face.p0, dtype=float) + u[:, None] * face.direction
        if scanned_rooms:
            behind = xy - config.beyond * face.normal
            known = np.zeros(len(xy), dtype=bool)
            for polygon in scanned_rooms:
                known |= shapely.contains_xy(polygon, behind[:, 0], behind[:, 1])
            xy = np.where(known[:, None], np.nan, xy)
        points.append(xy + config.inset * face.normal)
        normals.append(np.broadcast_to(face.normal, xy.shape))
        faces.append(np.full(len(xy), k))
    if not points:
        empty = np.zeros(0, dtype=bool)
        return WallSamples(np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, dtype=int), empty)
    xy, normal, face = np.concatenate(points), np.concatenate(normals), np.concatenate(faces)
    heights = np.asarray(config.heights, dtype=float)
    samples = np.column_stack([np.repeat(xy, len(heights), axis=0), np.tile(roi.floor_z + heights, len(xy))])
    walls = WallSamples(samples, normal, face, np.zeros(len(xy), dtype=bool), float(roi.floor_z))
    stops = np.asarray(stops, dtype=float).reshape(-1, 3)
    open_columns = np.isfinite(xy[:, 0]) & ~_viewed(walls, stops, sees, config, scanner).any(axis=0)
    run = int(np.ceil(config.min_run / config.step - 1e-9))
    target = np.zeros(len(xy), dtype=bool)
    for k in np.unique(face):
        idx = np.flatnonzero(face == k)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], open_columns[idx].astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a >= run:
                target[idx[a:b]] = True
    return WallSamples(samples, normal, face, target, float(roi.floor_z))


def search_position(
    walls: WallSamples,
    sensors: np.ndarray,
    path_length: np.ndarray,
    sees: LineOfSight,
    config: WallSearchConfig | None = None,
    scanner: ScannerConfig | None = None,
) -> int | None:
    """The candidate that views most target columns (ties: the shorter path), or None when there
    is no target or no candidate views ``config.min_run`` metres of them.

    Parameters
    ----------
    walls : WallSamples
        From :func:`unviewed_wall`.
    sensors : (k, 3) float
        The scanner above each candidate.
    path_length : (k,) float
        Each candidate's path from the robot, metres.
    sees : callable
        As in :func:`unviewed_wall`.
    config, scanner
        As in :func:`unviewed_wall`.
    """
    config = config or WallSearchConfig()
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    if not walls.target.any() or not len(sensors):
        return None
    score = _viewed(walls, sensors, sees, config, scanner, walls.target)[:, walls.target].sum(axis=1)
    if score.max() * config.step < config.min_run - 1e-9:
        return None
    return int(np.lexsort((np.asarray(path_length, dtype=float)[: len(sensors)], -score))[0])


def approach_position(
    walls: WallSamples,
    sensors: np.ndarray,
    path_length: np.ndarray,
    stops: np.ndarray,
    config: WallSearchConfig | None = None,
) -> int | None:
    """The candidate nearest (in the plane) to a target column, when it is at least
    ``config.approach`` metres nearer to the targets than every stop; ties go to the shorter path.
    None when there is no target, no candidate, ``config.approach`` is 0, or no candidate is near
    enough.

    For targets that no candidate views (:func:`search_position` is None): a wall beyond floor
    the scans have not measured (behind furniture, round a corner of the room) has no NVP in view
    of it, and only a scan from nearer measures the floor on the way. Built for
    ``corpus:edge_8rooms_1``, where an L-shaped room's far arm, behind a tall cabinet, holds the
    only door to two rooms; measured there, the rooms come back when an approach scan elsewhere
    changes the order of the rooms, not through the arm (docs/experiments/robot.md). What brings
    them back through the arm is ``narrow``: the arm's floor is measured, but the way in is
    narrower than the NVPs' clearance.

    Parameters
    ----------
    walls, sensors, path_length
        As in :func:`search_position`.
    stops : (s, 3) float
        The room's scanner positions.
    config : WallSearchConfig
    """
    config = config or WallSearchConfig()
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    stops = np.asarray(stops, dtype=float).reshape(-1, 3)
    if config.approach <= 0 or not walls.target.any() or not len(sensors):
        return None
    targets = walls.column_xy[walls.target]

    def nearest(points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points[:, None, :2] - targets[None], axis=2).min(axis=1)

    distance = nearest(sensors)
    reach = nearest(stops).min() if len(stops) else np.inf
    if distance.min() > reach - config.approach + 1e-9:
        return None
    return int(np.lexsort((np.asarray(path_length, dtype=float)[: len(sensors)], distance))[0])
