"""Traversability, reachability, geodesic paths and the next valid positions (NVPs), METHOD §6.

Everything here works on the robot's own labelled voxel grid V(t) (plain arrays: ``labels``,
``origin``, ``voxel_size``) and its own pose estimate. It never sees a scene: this is the honest
simulation of what the robot can plan from its map.

The pipeline, per decision step::

    tmap = traversability(labels, origin, voxel_size, floor_z, config, visited_xy)
    cands = candidates(tmap, robot_xy, config)   # reachable() and geodesic() run inside
    cands.xy[cands.mask], cands.path_length[cands.mask], cands.path(i)

Conventions
-----------
- The 2-D grid is the voxel grid seen from above: cell (i, j) is the column of voxels (i, j, :), its
  centre is at ``origin[:2] + (i + 0.5, j + 0.5) * voxel_size``; x ↔ i, y ↔ j.
- Distances between a cell and an obstacle are measured between cell centres (the Euclidean
  distance transform); candidate points, which lie on a world lattice rather than on cell centres,
  are checked with the exact distance from the point to the nearest obstacle cell centre.
- Paths are 8-connected through traversable cell centres; a diagonal step may pass between two
  non-traversable cells through their shared corner (the clearance margin already keeps the robot
  away from what makes them non-traversable).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from nbs_env.config import NavigationConfig, _finite, _require
from nbs_env.labels import VoxelLabel, is_occupied

__all__ = [
    "Candidates",
    "Geodesic",
    "NavigationConfig",
    "Passage",
    "TraversabilityMap",
    "assume_blind_zone_free",
    "candidates",
    "geodesic",
    "path_to",
    "reachable",
    "traversability",
]

#: Slack, in cell units, when a world coordinate is turned into a cell index: a lattice point that
#: lies exactly on a cell boundary must land in the same cell whatever the rounding of the origin.
_CELL_EPS = 1e-6
#: Slack, in metres, of distance comparisons, so that a distance equal to a threshold passes.
_DIST_EPS = 1e-9
#: 8-connectivity for ndimage.label.
_EIGHT = np.ones((3, 3), dtype=bool)
#: Neighbour offsets whose edges, taken both ways, make the 8-connected graph.
_HALF_NEIGHBOURHOOD = ((1, 0), (0, 1), (1, 1), (1, -1))


@dataclass(frozen=True)
class Passage:
    """A door the robot drove through into the room, as it measured the door.

    A door is narrower than the robot's footprint plus its safety distance (a 0.8 m door, a 0.5 m
    robot, 20 cm each side), so the clearance rule alone would close it. The robot crossed it with
    its radius only (the approach of the door memory does the same on the other side), and it may
    leave it the same way: in front of the opening, cells that keep the robot's radius clear of
    every obstacle and whose column is Empty are traversable.

    Attributes
    ----------
    centre : (2,) float
        The door's centre on the floor, world xy (the robot's estimate).
    direction : (2,) float
        Unit horizontal direction through the door into the room.
    width : float
        The door's width as measured, metres.
    depth : float
        How far in front of the frame the relaxed rule holds, metres.
    """

    centre: tuple[float, float]
    direction: tuple[float, float]
    width: float
    depth: float = 1.5

    def __post_init__(self) -> None:
        centre = np.asarray(self.centre, dtype=float)
        direction = np.asarray(self.direction, dtype=float)
        _require(
            centre.shape == (2,) and np.isfinite(centre).all(), f"centre must be 2 finite numbers, got {self.centre}"
        )
        _require(
            direction.shape == (2,) and np.isfinite(direction).all() and abs(np.hypot(*direction) - 1) < 1e-6,
            f"direction must be a unit 2-vector, got {self.direction}",
        )
        _finite(width=self.width, depth=self.depth)
        _require(self.width > 0, f"width must be > 0, got {self.width}")
        _require(self.depth > 0, f"depth must be > 0, got {self.depth}")

    def cells(self, origin: np.ndarray, voxel_size: float, shape: tuple[int, int], robot_radius: float) -> np.ndarray:
        """(nx, ny) bool: the cells whose centre lies in front of the opening, within ``depth`` of the
        frame and ``width / 2 - robot_radius`` of its axis (at least half a cell: a door barely wider
        than the robot still has its axis)."""
        nx, ny = shape
        xs = origin[0] + (np.arange(nx) + 0.5) * voxel_size - self.centre[0]
        ys = origin[1] + (np.arange(ny) + 0.5) * voxel_size - self.centre[1]
        d, n = self.direction
        along = xs[:, None] * d + ys[None, :] * n
        across = -xs[:, None] * n + ys[None, :] * d
        half = max(self.width / 2 - robot_radius, voxel_size / 2)
        return (along >= 0) & (along <= self.depth) & (np.abs(across) <= half + _DIST_EPS)


@dataclass(frozen=True, eq=False)
class TraversabilityMap:
    """Where the robot may stand, on the 2-D grid of voxel columns.

    Attributes
    ----------
    free : (nx, ny) bool
        Traversable cells: column test passed and clearance large enough, or visited.
    clearance : (nx, ny) float64
        Metres from the cell centre to the nearest obstacle cell centre; ``inf`` when there is none.
    obstacle : (nx, ny) bool
        Cells whose column, within the height band, holds a Clutter or Structure voxel.
    column_empty : (nx, ny) bool
        Cells whose column is Empty over the whole height band.
    visited : (nx, ny) bool
        Cells within ``robot_radius`` of a position the robot has occupied.
    origin : (2,) float64
        World xy of the corner of cell (0, 0).
    voxel_size : float
        Cell size, metres.
    robot_radius : float
        The robot's radius, metres (how far a start position may be snapped to a traversable cell).
    required_clearance : float
        robot_radius + safety_distance, metres.
    outline : (nx, ny) bool or None
        Cells whose centre lies inside the room's outline, where the map is limited to one
        (:func:`~nbs_env.planning.planner.within_roi`); None otherwise. A door's opening holds no
        obstacle but is the outline's edge: snapped candidates (``NavigationConfig.snap``) keep the
        clearance from it too.
    """

    free: np.ndarray
    clearance: np.ndarray
    obstacle: np.ndarray
    column_empty: np.ndarray
    visited: np.ndarray
    origin: np.ndarray
    voxel_size: float
    robot_radius: float
    required_clearance: float
    outline: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape  # type: ignore[return-value]

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(n,) bool: which of the (n, 2) world points lie inside the grid."""
        cells = self._raw_cells(xy)
        nx, ny = self.shape
        return (cells[:, 0] >= 0) & (cells[:, 0] < nx) & (cells[:, 1] >= 0) & (cells[:, 1] < ny)

    def cell_of(self, xy: np.ndarray, name: str = "point") -> np.ndarray:
        """(n, 2) intp: the cells holding the (n, 2) world points.

        Raises
        ------
        ValueError
            A point lies outside the grid; the message names it with ``name``.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        inside = self.contains(xy)
        if not inside.all():
            bad = xy[np.flatnonzero(~inside)[0]]
            lo = self.origin
            hi = self.origin + np.array(self.shape) * self.voxel_size
            raise ValueError(
                f"{name} ({bad[0]:.3f}, {bad[1]:.3f}) lies outside the grid "
                f"x [{lo[0]:.3f}, {hi[0]:.3f}), y [{lo[1]:.3f}, {hi[1]:.3f})"
            )
        return self._raw_cells(xy)

    def centre_of(self, cells: np.ndarray) -> np.ndarray:
        """(n, 2) float64: world xy of the centres of the (n, 2) cells."""
        cells = np.asarray(cells).reshape(-1, 2)
        return self.origin + (cells + 0.5) * self.voxel_size

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """(n,) float64: exact distance from the (n, 2) world points to the nearest obstacle cell centre.

        ``clearance`` holds this distance for cell centres only; a point elsewhere in a cell may be
        up to half a cell diagonal closer to an obstacle, which matters for lattice candidates.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self._obstacle_tree is None:
            return np.full(len(xy), np.inf)
        distance, _ = self._obstacle_tree.query(xy)
        return np.asarray(distance, dtype=float)

    @cached_property
    def _obstacle_tree(self) -> cKDTree | None:
        # cached_property writes the instance __dict__ directly, so it works on a frozen dataclass.
        centres = self.centre_of(np.argwhere(self.obstacle))
        return cKDTree(centres) if len(centres) else None

    def _raw_cells(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return np.floor((xy - self.origin) / self.voxel_size + _CELL_EPS).astype(np.intp)


class Geodesic(NamedTuple):
    """Shortest 8-connected paths from the robot's cell to every reachable cell.

    Attributes
    ----------
    distances : (nx, ny) float64
        Path length in metres between cell centres, from the source cell; ``inf`` where unreachable.
    predecessors : (nx, ny) intp
        Flat index (``np.ravel_multi_index`` over (nx, ny)) of the previous cell on the shortest
        path; -1 at the source and where unreachable.
    source : tuple of int or None
        The cell the paths start from: the start's own cell, or the nearest traversable cell within
        robot_radius of it; None when there is none (then every distance is ``inf``).
    start_xy : (2,) float64
        The robot's position the paths were asked for.
    """

    distances: np.ndarray
    predecessors: np.ndarray
    source: tuple[int, int] | None
    start_xy: np.ndarray


@dataclass(frozen=True, eq=False)
class Candidates:
    """The NVP candidate list: the action space, K entries in a stable order.

    Attributes
    ----------
    xy : (K, 2) float32
        World xy of each candidate, on the world lattice; zeros for padding.
    path_length : (K,) float32
        Geodesic length in metres of the path from the robot to each candidate (the length of
        ``path(i)``); 0 for padding.
    mask : (K,) bool
        True for real entries; they come first.
    count : int
        Number of real entries, ``mask.sum()``.
    lattice_index : (K, 2) int64
        Integer lattice coordinates (``xy / lattice``) of each candidate; zeros for padding. Stable
        names of the positions as the map grows.
    total : int
        How many valid lattice points there were before the list was thinned to K.
    geodesic : Geodesic
        The shortest paths the lengths come from.
    tmap : TraversabilityMap
        The map the candidates were taken from.
    points : (count, 2) float64
        ``xy`` of the real entries at full precision; the paths end there (float32 could move a
        point on a cell boundary into the neighbouring cell).
    """

    xy: np.ndarray
    path_length: np.ndarray
    mask: np.ndarray
    count: int
    lattice_index: np.ndarray
    total: int
    geodesic: Geodesic = field(repr=False)
    tmap: TraversabilityMap = field(repr=False)
    points: np.ndarray = field(repr=False)

    def path(self, i: int) -> np.ndarray:
        """(p, 2) float64 polyline from the robot to candidate ``i``; see :func:`path_to`."""
        if not (0 <= i < self.count):
            raise IndexError(f"candidate {i} is not a real entry (count {self.count})")
        return path_to(self.tmap, self.geodesic, self.points[i])


# --------------------------------------------------------------------------------------------------
# Input checks


def _check_grid(labels: np.ndarray, origin: np.ndarray, voxel_size: float, floor_z: float) -> np.ndarray:
    if not isinstance(labels, np.ndarray) or labels.ndim != 3 or labels.dtype != np.uint8:
        what = f"{labels.ndim}-D {labels.dtype}" if isinstance(labels, np.ndarray) else type(labels).__name__
        raise ValueError(f"labels must be a 3-D uint8 array, got {what}")
    if min(labels.shape) == 0:
        raise ValueError(f"labels must not be empty, got shape {labels.shape}")
    if not (isinstance(voxel_size, (int, float, np.floating)) and math.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"voxel_size must be a finite number > 0, got {voxel_size}")
    origin = np.asarray(origin, dtype=float)
    if origin.shape != (3,) or not np.isfinite(origin).all():
        raise ValueError(f"origin must be 3 finite numbers, got {origin.tolist()}")
    z_top = origin[2] + labels.shape[2] * voxel_size
    if not (isinstance(floor_z, (int, float, np.floating)) and origin[2] <= floor_z < z_top):
        raise ValueError(f"floor_z {floor_z} lies outside the grid's z range [{origin[2]:.3f}, {z_top:.3f})")
    return origin


def _check_xy(xy: Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    point = np.asarray(xy, dtype=float)
    if point.shape != (2,) or not np.isfinite(point).all():
        raise ValueError(f"{name} must be 2 finite numbers (x, y), got {np.asarray(xy).tolist()}")
    return point


# --------------------------------------------------------------------------------------------------
# Traversability


def traversability(
    labels: np.ndarray,
    origin: np.ndarray,
    voxel_size: float,
    floor_z: float,
    config: NavigationConfig | None = None,
    visited_xy: np.ndarray | Sequence[Sequence[float]] = (),
    passages: Sequence[Passage] = (),
) -> TraversabilityMap:
    """Which floor cells the robot may stand on, METHOD §6.

    The height band is the voxels whose centre lies in
    ``[floor_z + floor_clearance, floor_z + robot_height]``. A cell (i, j) is traversable when

    - every voxel of its column in the band is Empty (the label itself), and
    - its clearance, the distance from its centre to the centre of the nearest obstacle cell, is at
      least ``robot_radius + safety_distance``. An obstacle cell is one whose column holds a Clutter
      or Structure voxel in the band.

    Unknown and occluded voxels make their column non-traversable (the robot does not drive where
    it has not seen free space) but are *not* obstacles for the clearance: they are what the robot
    has yet to see, and counting them would fence the robot in behind every unscanned shadow.
    Voxels of the band above the top of the grid count as Unknown.

    Cells whose centre lies within ``robot_radius`` of a visited position (and the cell holding the
    position) are traversable whatever their labels: the robot stood there, and the scanner cannot
    see the floor right below itself.

    In front of each of ``passages`` (the door the robot came in by) the clearance needed is the
    robot's radius alone (:class:`Passage`). NVPs still need the full clearance
    (:func:`candidates`): the relaxed cells carry paths out of the door, not scans.

    Parameters
    ----------
    labels : (nx, ny, nz) uint8
        VoxelLabel values.
    origin : (3,) float
        World position of the corner of voxel (0, 0, 0).
    voxel_size : float
        Edge of a voxel, metres.
    floor_z : float
        Height of the floor surface, metres; must lie inside the grid's z range.
    config : NavigationConfig, optional
        Defaults to ``NavigationConfig()``.
    visited_xy : (m, 2) float, optional
        World xy of the positions the robot has physically occupied. Points outside the grid only
        mark the part of their disc that lies inside.
    passages : sequence of Passage, optional
        Doors the robot drove through into the room.

    Returns
    -------
    TraversabilityMap

    Raises
    ------
    ValueError
        labels not a 3-D uint8 array, voxel_size <= 0, origin not 3 finite numbers, floor_z outside
        the grid, visited_xy not (m, 2) finite, or a band so thin that no voxel centre lies in it.
    """
    config = config or NavigationConfig()
    origin = _check_grid(labels, origin, voxel_size, floor_z)
    voxel_size = float(voxel_size)
    nx, ny, nz = labels.shape

    # Voxel k's centre is origin_z + (k + 0.5) * voxel_size; the band is the k whose centre lies in
    # [floor_z + floor_clearance, floor_z + robot_height].
    rel = (floor_z - origin[2]) / voxel_size - 0.5
    k_lo = max(0, math.ceil(rel + config.floor_clearance / voxel_size - _CELL_EPS))
    k_hi = math.floor(rel + config.robot_height / voxel_size + _CELL_EPS)
    if k_hi < k_lo:
        raise ValueError(
            f"no voxel centre lies between {config.floor_clearance} m and {config.robot_height} m above "
            f"floor_z {floor_z} at voxel_size {voxel_size}"
        )
    band = labels[:, :, k_lo : min(k_hi, nz - 1) + 1]
    # When the band reaches above the grid, its top is Unknown and no column passes.
    column_empty = np.all(band == VoxelLabel.EMPTY, axis=2) & (k_hi < nz)
    obstacle = np.any(is_occupied(band), axis=2) if band.shape[2] else np.zeros((nx, ny), dtype=bool)

    if obstacle.any():
        clearance = ndimage.distance_transform_edt(~obstacle, sampling=voxel_size)
    else:
        # distance_transform_edt of an input without a zero is meaningless; nothing is near.
        clearance = np.full((nx, ny), np.inf)

    visited = _visited_mask(visited_xy, origin[:2], voxel_size, (nx, ny), config.robot_radius)
    free = (column_empty & (clearance >= config.required_clearance - _DIST_EPS)) | visited
    for passage in passages:
        narrow = passage.cells(origin, voxel_size, (nx, ny), config.robot_radius)
        free |= narrow & column_empty & (clearance >= config.robot_radius - _DIST_EPS)

    arrays = [free, clearance, obstacle, column_empty, visited]
    for array in arrays:
        array.setflags(write=False)
    origin_xy = origin[:2].copy()
    origin_xy.setflags(write=False)
    return TraversabilityMap(
        free=free,
        clearance=clearance,
        obstacle=obstacle,
        column_empty=column_empty,
        visited=visited,
        origin=origin_xy,
        voxel_size=voxel_size,
        robot_radius=config.robot_radius,
        required_clearance=config.required_clearance,
    )


def _visited_mask(
    visited_xy: np.ndarray | Sequence[Sequence[float]],
    origin_xy: np.ndarray,
    voxel_size: float,
    shape: tuple[int, int],
    radius: float,
) -> np.ndarray:
    """(nx, ny) bool: cells whose centre is within ``radius`` of a visited position, or that hold one."""
    points = np.asarray(visited_xy, dtype=float)
    if points.size == 0:
        return np.zeros(shape, dtype=bool)
    if points.ndim != 2 or points.shape[1] != 2 or not np.isfinite(points).all():
        raise ValueError(f"visited_xy must be (m, 2) finite world xy, got shape {points.shape}")
    mask = np.zeros(shape, dtype=bool)
    reach = math.ceil(radius / voxel_size) + 1
    for point in points:
        # A window of cells around the point, clipped to the grid, then the disc inside it.
        rel = (point - origin_xy) / voxel_size
        home = np.floor(rel + _CELL_EPS).astype(int)
        lo = np.maximum(home - reach, 0)
        hi = np.minimum(home + reach + 1, shape)
        if np.any(hi <= lo):
            continue
        ii = np.arange(lo[0], hi[0])[:, None]
        jj = np.arange(lo[1], hi[1])[None, :]
        d2 = (ii + 0.5 - rel[0]) ** 2 + (jj + 0.5 - rel[1]) ** 2
        mask[lo[0] : hi[0], lo[1] : hi[1]] |= d2 * voxel_size**2 <= radius**2 + _DIST_EPS
        if 0 <= home[0] < shape[0] and 0 <= home[1] < shape[1]:
            mask[home[0], home[1]] = True  # the robot's own cell, even with a radius below a cell
    return mask


# --------------------------------------------------------------------------------------------------
# Reachability and shortest paths


def _source_cell(tmap: TraversabilityMap, start_xy: np.ndarray) -> tuple[int, int] | None:
    """The start's cell if traversable, else the nearest traversable cell within robot_radius, else None."""
    cell = tmap.cell_of(start_xy, "start_xy")[0]
    if tmap.free[cell[0], cell[1]]:
        return int(cell[0]), int(cell[1])
    reach = math.ceil(tmap.robot_radius / tmap.voxel_size) + 1
    nx, ny = tmap.shape
    lo = np.maximum(cell - reach, 0)
    hi = np.minimum(cell + reach + 1, (nx, ny))
    window = np.argwhere(tmap.free[lo[0] : hi[0], lo[1] : hi[1]]) + lo
    if len(window) == 0:
        return None
    d = np.hypot(*(tmap.centre_of(window) - start_xy).T)
    best = int(np.argmin(d))  # ties: the first in (i, j) order, so the choice is deterministic
    if d[best] > tmap.robot_radius + _DIST_EPS:
        return None
    return int(window[best, 0]), int(window[best, 1])


def reachable(tmap: TraversabilityMap, start_xy: Sequence[float] | np.ndarray) -> np.ndarray:
    """The traversable cells the robot can drive to from ``start_xy``.

    Parameters
    ----------
    tmap : TraversabilityMap
    start_xy : (2,) float
        The robot's position (its pose estimate), world metres.

    Returns
    -------
    (nx, ny) bool
        The 8-connected component of ``tmap.free`` holding the start's cell; when that cell is not
        traversable, the component of the nearest traversable cell within ``robot_radius``; all False
        when there is none.

    Raises
    ------
    ValueError
        ``start_xy`` is not 2 finite numbers or lies outside the grid.
    """
    start = _check_xy(start_xy, "start_xy")
    source = _source_cell(tmap, start)
    if source is None:
        return np.zeros(tmap.shape, dtype=bool)
    components, _ = ndimage.label(tmap.free, structure=_EIGHT)
    return components == components[source]


def _shift(n: int, d: int) -> tuple[slice, slice]:
    """Slices a, b of an axis of length n such that index b = index a + d."""
    return (slice(0, n - d), slice(d, n)) if d >= 0 else (slice(-d, n), slice(0, n + d))


def geodesic(tmap: TraversabilityMap, start_xy: Sequence[float] | np.ndarray) -> Geodesic:
    """Shortest 8-connected paths through the reachable cells, from the robot's cell.

    scipy's Dijkstra (``scipy.sparse.csgraph.dijkstra``) runs on the graph whose nodes are the
    reachable cells and whose edges join 8-neighbours, weighted ``voxel_size`` (straight) and
    ``voxel_size * sqrt(2)`` (diagonal).

    Parameters
    ----------
    tmap : TraversabilityMap
    start_xy : (2,) float
        The robot's position, world metres.

    Returns
    -------
    Geodesic
        ``distances`` (nx, ny) float64 (``inf`` where unreachable), ``predecessors`` (nx, ny) intp,
        ``source`` and ``start_xy``.

    Raises
    ------
    ValueError
        ``start_xy`` is not 2 finite numbers or lies outside the grid.
    """
    start = _check_xy(start_xy, "start_xy")
    nx, ny = tmap.shape
    distances = np.full((nx, ny), np.inf)
    predecessors = np.full((nx, ny), -1, dtype=np.intp)
    source = _source_cell(tmap, start)
    if source is None:
        return Geodesic(distances, predecessors, None, start)
    components, _ = ndimage.label(tmap.free, structure=_EIGHT)
    region = components == components[source]

    # Number the reachable cells 0..n-1 and join each to its 8-neighbours (each edge once).
    nodes = np.flatnonzero(region)
    node_of = np.full((nx, ny), -1, dtype=np.int64)
    node_of.flat[nodes] = np.arange(len(nodes))
    rows, cols, weights = [], [], []
    for di, dj in _HALF_NEIGHBOURHOOD:
        (ia, ib), (ja, jb) = _shift(nx, di), _shift(ny, dj)
        a, b = node_of[ia, ja], node_of[ib, jb]
        both = (a >= 0) & (b >= 0)
        rows.append(a[both])
        cols.append(b[both])
        weights.append(np.full(int(both.sum()), tmap.voxel_size * math.hypot(di, dj)))
    n = len(nodes)
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    dist, pred = dijkstra(graph, directed=False, indices=int(node_of[source]), return_predecessors=True)

    distances.flat[nodes] = dist
    has_pred = pred >= 0  # scipy marks "no predecessor" with -9999
    predecessors.flat[nodes[has_pred]] = nodes[pred[has_pred]]
    for array in (distances, predecessors):
        array.setflags(write=False)
    return Geodesic(distances, predecessors, source, start)


def path_to(tmap: TraversabilityMap, geodesic_result: Geodesic, goal_xy: Sequence[float] | np.ndarray) -> np.ndarray:
    """The shortest path from the robot to ``goal_xy`` as a world polyline.

    The polyline runs from ``start_xy`` through the centres of the cells of the shortest path
    (source cell to the goal's cell) to ``goal_xy``; repeated points and interior points on a
    straight run are removed, so its length is unchanged. When the start was snapped to a nearby
    traversable cell, the first segment joins the start to that cell's centre.

    Parameters
    ----------
    tmap : TraversabilityMap
        The map ``geodesic_result`` was computed on.
    geodesic_result : Geodesic
    goal_xy : (2,) float
        World xy of the goal; its cell must be reachable.

    Returns
    -------
    (p, 2) float64
        ``p >= 1``; the first point is ``start_xy`` and the last is ``goal_xy``.

    Raises
    ------
    ValueError
        ``goal_xy`` outside the grid or not reachable.
    """
    goal = _check_xy(goal_xy, "goal_xy")
    cell = tmap.cell_of(goal, "goal_xy")[0]
    if geodesic_result.source is None or not np.isfinite(geodesic_result.distances[cell[0], cell[1]]):
        raise ValueError(f"goal_xy ({goal[0]:.3f}, {goal[1]:.3f}) is not reachable from the start")
    shape = tmap.shape
    source = int(np.ravel_multi_index(geodesic_result.source, shape))
    flat = int(np.ravel_multi_index((int(cell[0]), int(cell[1])), shape))
    chain = [flat]
    pred = geodesic_result.predecessors.ravel()
    while flat != source:
        flat = int(pred[flat])
        if flat < 0 or len(chain) > pred.size:
            raise ValueError("the predecessors do not lead back to the source: not from this map?")
        chain.append(flat)
    cells = np.column_stack(np.unravel_index(np.array(chain[::-1]), shape))
    points = np.vstack([geodesic_result.start_xy, tmap.centre_of(cells), goal])
    return _simplify(points)


def _simplify(points: np.ndarray) -> np.ndarray:
    """Drop repeated points and interior points of straight runs; keeps the polyline's length."""
    steps = np.diff(points, axis=0)
    moves = np.hypot(steps[:, 0], steps[:, 1]) > 1e-12
    points = np.vstack([points[:1], points[1:][moves]])
    if len(points) < 3:
        return points
    u, v = np.diff(points, axis=0)[:-1], np.diff(points, axis=0)[1:]
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    scale = np.hypot(u[:, 0], u[:, 1]) * np.hypot(v[:, 0], v[:, 1])
    # An interior point where the path goes on straight ahead adds nothing; a turn or a reversal stays.
    straight = (np.abs(cross) <= 1e-9 * scale) & (np.einsum("ij,ij->i", u, v) > 0)
    return np.vstack([points[:1], points[1:-1][~straight], points[-1:]])


# --------------------------------------------------------------------------------------------------
# Candidates


def candidates(
    tmap: TraversabilityMap,
    start_xy: Sequence[float] | np.ndarray,
    config: NavigationConfig | None = None,
    geodesic_result: Geodesic | None = None,
) -> Candidates:
    """The next valid positions: reachable points of the world lattice, at most K, in a stable order.

    A point (a * lattice, b * lattice), a and b integers, is a candidate when

    - its cell (the cell holding the point) is reachable from the robot,
    - the point itself is at least ``robot_radius + safety_distance`` from every obstacle cell
      centre (exact distance, not the cell's: a lattice point is off its cell's centre), and
    - it is at least ``min_distance`` from the robot (Euclidean).

    Candidates are ordered by (a, b). Because the lattice is anchored at world multiples, the same
    physical points keep the same order as the map grows. When more than K qualify, the list keeps
    the entries at positions ``floor(k * n / K)``, k = 0..K-1, of that order (n the number that
    qualify): evenly spread over the room, deterministic, and the first one always kept. This
    thinning depends on n, so with more than K candidates a grown map may keep other points.

    Parameters
    ----------
    tmap : TraversabilityMap
    start_xy : (2,) float
        The robot's position, world metres.
    config : NavigationConfig, optional
        ``lattice``, ``max_candidates`` (K) and ``min_distance`` are used. Defaults to
        ``NavigationConfig()``.
    geodesic_result : Geodesic, optional
        Reuse one computed by :func:`geodesic` for the same map and start.

    Returns
    -------
    Candidates

    Raises
    ------
    ValueError
        ``start_xy`` invalid or outside the grid, or ``geodesic_result`` for another start.
    """
    config = config or NavigationConfig()
    start = _check_xy(start_xy, "start_xy")
    tmap.cell_of(start, "start_xy")  # validates: outside the grid is an error even with a given result
    if geodesic_result is None:
        geodesic_result = geodesic(tmap, start)
    elif not np.allclose(geodesic_result.start_xy, start, rtol=0, atol=1e-9):
        raise ValueError(f"geodesic_result starts at {geodesic_result.start_xy.tolist()}, not at {start.tolist()}")
    K = config.max_candidates
    step = config.lattice
    nx, ny = tmap.shape
    lo = tmap.origin
    hi = tmap.origin + np.array([nx, ny]) * tmap.voxel_size

    # All lattice points over the grid, in (a, b) order (meshgrid 'ij' flattens a-major).
    a = np.arange(math.floor(lo[0] / step), math.ceil(hi[0] / step) + 1)
    b = np.arange(math.floor(lo[1] / step), math.ceil(hi[1] / step) + 1)
    A, B = np.meshgrid(a, b, indexing="ij")
    index = np.column_stack([A.ravel(), B.ravel()]).astype(np.int64)
    points = index * step
    keep = tmap.contains(points)
    index, points = index[keep], points[keep]
    cells = tmap._raw_cells(points)

    if geodesic_result.source is None or len(points) == 0:
        keep = np.zeros(len(points), dtype=bool)
    else:
        keep = np.isfinite(geodesic_result.distances[cells[:, 0], cells[:, 1]])
        keep[keep] &= tmap.clearance_at(points[keep]) >= tmap.required_clearance - _DIST_EPS
    # A lattice point too near the robot is no candidate, and no other point of its cell stands in.
    clear_index = index[keep]
    keep &= np.hypot(*(points - start).T) >= config.min_distance - _DIST_EPS
    index, points, cells = index[keep], points[keep], cells[keep]
    if config.snap and geodesic_result.source is not None:
        index, points, cells = _with_snapped(tmap, geodesic_result, start, config, clear_index, index, points, cells)
    total = len(points)
    if total > K:
        pick = (np.arange(K) * total) // K
        index, points, cells = index[pick], points[pick], cells[pick]

    count = len(points)
    xy = np.zeros((K, 2), dtype=np.float32)
    path_length = np.zeros(K, dtype=np.float32)
    mask = np.zeros(K, dtype=bool)
    lattice_index = np.zeros((K, 2), dtype=np.int64)
    if count:
        # The polyline of path_to: start -> source centre -> ... -> goal cell centre -> goal point.
        source_centre = tmap.centre_of(np.array(geodesic_result.source))[0]
        length = (
            geodesic_result.distances[cells[:, 0], cells[:, 1]]
            + np.hypot(*(start - source_centre))
            + np.hypot(*(points - tmap.centre_of(cells)).T)
        )
        xy[:count] = points
        path_length[:count] = length
        mask[:count] = True
        lattice_index[:count] = index
    for array in (xy, path_length, mask, lattice_index, points):
        array.setflags(write=False)
    return Candidates(
        xy=xy,
        path_length=path_length,
        mask=mask,
        count=count,
        lattice_index=lattice_index,
        total=total,
        geodesic=geodesic_result,
        tmap=tmap,
        points=points,
    )


def _with_snapped(
    tmap: TraversabilityMap,
    geodesic_result: Geodesic,
    start: np.ndarray,
    config: NavigationConfig,
    clear_index: np.ndarray,
    index: np.ndarray,
    points: np.ndarray,
    cells: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lattice candidates plus, for each lattice cell (the square of side ``lattice`` around a
    lattice point) where neither its point nor any of its eight neighbours is reachable with the
    clearance (``clear_index`` lists those that are), its reachable cell nearest the point that has
    the required clearance from obstacles and from the room's outline (ties: the clearer), at least
    ``min_distance`` from the robot; all in (a, b) order.

    Only the lattice's holes are filled: beside a wall of an open room the next lattice point in
    is a candidate, and a stand-in there would add a place the lattice already nearly has."""
    step = config.lattice
    clear = np.isfinite(geodesic_result.distances) & (tmap.clearance >= tmap.required_clearance - _DIST_EPS)
    if tmap.outline is not None and not tmap.outline.all():
        # Distance to the outline, computed only here: the lattice candidates do not need it.
        clear &= ndimage.distance_transform_edt(tmap.outline) * tmap.voxel_size >= tmap.required_clearance - _DIST_EPS
    free_cells = np.argwhere(clear)
    if not len(free_cells):
        return index, points, cells
    centres = tmap.centre_of(free_cells)
    far = np.hypot(*(centres - start).T) >= config.min_distance - _DIST_EPS
    free_cells, centres = free_cells[far], centres[far]
    if not len(free_cells):
        return index, points, cells
    square = np.floor(centres / step + 0.5).astype(np.int64)
    lo = square.min(axis=0) - 1  # one lattice cell of margin: the neighbours of the outermost
    taken = np.zeros(tuple(square.max(axis=0) - lo + 2), dtype=bool)
    inside = np.all((clear_index >= lo) & (clear_index - lo < taken.shape), axis=1)
    taken[tuple((clear_index[inside] - lo).T)] = True
    near_taken = ndimage.binary_dilation(taken, structure=np.ones((3, 3), dtype=bool))
    open_square = ~near_taken[tuple((square - lo).T)]
    free_cells, centres, square = free_cells[open_square], centres[open_square], square[open_square]
    if not len(free_cells):
        return index, points, cells
    clearance = tmap.clearance[free_cells[:, 0], free_cells[:, 1]]
    off = np.hypot(*(centres - square * step).T)
    order = np.lexsort((-clearance, off, square[:, 1], square[:, 0]))
    square, centres, free_cells = square[order], centres[order], free_cells[order]
    first = np.ones(len(square), dtype=bool)
    first[1:] = np.any(square[1:] != square[:-1], axis=1)
    index = np.concatenate([index, square[first]])
    points = np.concatenate([points, centres[first]])
    cells = np.concatenate([cells, free_cells[first].astype(cells.dtype)])
    order = np.lexsort((index[:, 1], index[:, 0]))
    return index[order], points[order], cells[order]


def assume_blind_zone_free(
    labels: np.ndarray,
    origin: np.ndarray,
    voxel_size: float,
    sensors: Sequence[Sequence[float]] | np.ndarray,
    elevation_min: float,
    min_range: float = 0.0,
    blocked: Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """A copy of ``labels`` with the unsensed voxels under each stop's field of view taken as EMPTY.

    Unsensed means UNKNOWN or OCCLUDED_CLUTTER; OCCLUDED_STRUCTURE (the floor's slab) stays.

    The scanner sees nothing below ``elevation_min`` (-40°), so after a stop every column within
    about 1.8 m of it has an unseen foot, and the strict column test of :func:`traversability` would
    leave the robot unable to move from its first stop. This copy, for navigation only (V(t) keeps
    its labels), assumes that cone below the scanner free: anything in it taller than the cone is
    seen, so only low objects close to the robot could be missed, which a real base's bumpers or
    2-D lidar would catch.

    Parameters
    ----------
    labels : (nx, ny, nz) uint8
    origin : (3,) float
    voxel_size : float
    sensors : (m, 3) float
        Scanner positions of the stops (the robot's estimates).
    elevation_min : float
        Lower limit of the field of view in degrees (negative).
    min_range : float
        The scanner's minimum range. Nothing closer than it is ever measured, so the unsensed space
        within it of a stop is taken as free too (same reasoning: the robot's own near-field
        sensing, not simulated, would stop it).
    blocked : sequence of (k, 3) float, optional
        Per stop, the world directions of its low rays that returned nothing: something nearer than
        ``min_range`` stopped each (a wall beside a door frame, furniture). No column along such a
        ray within ``min_range`` of the stop is assumed free; the robot waits to see it.
    """
    out = np.array(labels, copy=True)
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    if blocked is not None and len(blocked) != len(sensors):
        raise ValueError(f"{len(blocked)} blocked-direction sets for {len(sensors)} stops")
    grid = (tuple(float(v) for v in np.asarray(origin, dtype=float)), float(voxel_size), out.shape)
    for k, sensor in enumerate(sensors):
        directions = None
        if blocked is not None and min_range > 0 and len(blocked[k]):
            directions = np.ascontiguousarray(blocked[k], dtype=float).tobytes()
        cone = _blind_cone(*grid, tuple(float(v) for v in sensor), float(elevation_min), float(min_range), directions)
        if cone is None:
            continue
        window, below = cone
        # Only the window is read: freeing a voxel never makes another one unsensed, so an earlier
        # stop's freeing changes nothing for this one.
        part = out[window]
        part[below & ((part == VoxelLabel.UNKNOWN) | (part == VoxelLabel.OCCLUDED_CLUTTER))] = VoxelLabel.EMPTY
    return out


@lru_cache(maxsize=64)
def _blind_cone(
    origin: tuple[float, float, float],
    voxel_size: float,
    shape: tuple[int, int, int],
    sensor: tuple[float, float, float],
    elevation_min: float,
    min_range: float,
    blocked: bytes | None,
) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """The window of columns round one stop and which of its voxels lie below the stop's field of
    view or within its minimum range (:func:`assume_blind_zone_free`): geometry alone, so each plan
    of a room reuses its stops' cones while the grid keeps its place and size (read-only masks)."""
    nx, ny, nz = shape
    s = voxel_size
    xs = origin[0] + (np.arange(nx) + 0.5) * s
    ys = origin[1] + (np.arange(ny) + 0.5) * s
    zs = origin[2] + (np.arange(nz) + 0.5) * s
    lowest = np.radians(elevation_min)
    half_diagonal = s * np.sqrt(3) / 2
    plan_distance = np.hypot(xs[:, None] - sensor[0], ys[None, :] - sensor[1])  # (nx, ny)
    # Only columns whose lowest voxel could pass the test below are looked at: the elevation
    # grows with the height and the half-diagonal's angle shrinks with the range, which is at
    # least the column's plan distance. The window is the stop's cone, not the whole room.
    possible = np.arctan2(zs[0] - sensor[2], plan_distance) - half_diagonal / np.maximum(plan_distance, 1e-3) < lowest
    if min_range > 0:
        possible |= plan_distance < min_range
    rows, cols = np.flatnonzero(possible.any(axis=1)), np.flatnonzero(possible.any(axis=0))
    if not len(rows):
        return None
    window = np.s_[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    d = plan_distance[window][:, :, None]
    dz = (zs - sensor[2])[None, None, :]
    r = np.hypot(d, dz)
    # Partly below the lowest ray: carving needs the whole voxel in view (its centre's elevation
    # less the angle its half diagonal subtends above the lowest elevation, the test of
    # VoxelGrid's carving), so a voxel that straddles the cone is never carved either. Near a
    # steep cone (a -60° scanner) that angle exceeds the voxel's height measured vertically.
    below = np.arctan2(dz, d) - half_diagonal / np.maximum(r, 1e-3) < lowest
    if min_range > 0:
        below |= r < min_range
    if blocked is not None:
        directions = np.frombuffer(blocked, dtype=float).reshape(-1, 3)
        columns = _blocked_columns(directions, np.asarray(sensor), min_range, np.asarray(origin), s, (nx, ny))
        below &= ~columns[window][:, :, None]
    below.setflags(write=False)
    return window, below


def _blocked_columns(
    directions: np.ndarray, sensor: np.ndarray, min_range: float, origin: np.ndarray, size: float, shape: tuple
) -> np.ndarray:
    """(nx, ny) bool: columns a ray of ``directions`` from ``sensor`` crosses within ``min_range``."""
    d = np.asarray(directions, dtype=float).reshape(-1, 3)
    horizontal = np.hypot(d[:, 0], d[:, 1])
    d, horizontal = d[horizontal > 1e-6], horizontal[horizontal > 1e-6]
    # One ray per azimuth bin of a voxel's width at the far end: the farthest reach among its rays.
    bins = max(8, int(np.ceil(2 * np.pi * min_range / size)))
    azimuth = np.arctan2(d[:, 1], d[:, 0])
    b = ((azimuth + np.pi) / (2 * np.pi) * bins).astype(np.int64) % bins
    reach = np.zeros(bins)
    np.maximum.at(reach, b, min_range * horizontal)
    used = np.flatnonzero(reach > 0)
    theta = (used + 0.5) / bins * 2 * np.pi - np.pi
    steps = np.arange(0.0, min_range + size, size / 2)
    r = np.minimum(steps[None, :], reach[used][:, None])
    x = sensor[0] + r * np.cos(theta)[:, None]
    y = sensor[1] + r * np.sin(theta)[:, None]
    i = np.floor((x - origin[0]) / size).astype(np.int64).ravel()
    j = np.floor((y - origin[1]) / size).astype(np.int64).ravel()
    ok = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1])
    mask = np.zeros(shape, dtype=bool)
    mask[i[ok], j[ok]] = True
    return mask
