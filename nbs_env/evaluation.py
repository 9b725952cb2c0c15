"""Evaluation against ground truth (METHOD §9): the coverage meter, the true room of every scan, and
the ``metrics.json`` schema.

With the scanner, the only part of ``nbs_env`` that reads a scene's labels, rooms and true poses: it
scores the robot, it never informs it.

The metrics schema, ``"nbs-metrics/1"``
---------------------------------------
A stable, versioned format: a later version may add keys, never remove or retype one without
changing the version. Every value is a plain JSON type. Lengths are metres, times seconds,
percentages in 0..100 of the true structural surface (floor, ceiling and wall samples of the
evaluation, :class:`CoverageMeter`). This is the evaluation side: it reads the
scene's ground truth (true positions, true rooms), which the robot never sees.

.. code-block:: text

    schema                  "nbs-metrics/1"
    scene                   str     the scene as given (bundled name, file, generated:SEED)
    policy                  str     the policy's name
    seed                    int | null
    complete                bool    the storey was completed (False: the scan budget ran out)
    scans                   int     scans taken, door-frame scans included
    structure_sensed_pct    float   true structural surface sensed, % of the storey's
    path_length_m           float   distance driven
    processed_points        int     points the pipeline processed (the paper's measure): the SE
                                    points for a structure-aware policy (ours), every point for
                                    the structure-agnostic compared methods
    measured_points         int     points of all scans
    processing_time_s       float   registration, RoI, classification, voxels, planning, and the
                                    policy's own decision time
    policy_time_s           float   the policy's decision time alone
    acquisition_time_s      float   scanner time: the scanner preset's station time per scan, else
                                    the points over the configured acquisition rate
    travel_time_s           float   path_length_m / config.travel_speed
    registration_error      {mean_m, max_m, mean_deg, max_deg}: pose estimate vs true pose,
                            over the scans
    quality                 the scan-quality figures (:meth:`CoverageMeter.quality`):
        min_density_per_m2, max_incidence_deg, density_radius_m   the thresholds (config.quality)
        dense_pct           float   % of the structural samples with a point density >= the least
        incidence_pct       float   % seen at least once at an incidence <= the largest
        quality_pct         float   % meeting both
        median_density_per_m2, median_incidence_deg, median_range_m   over the samples sensed
                                    (null when none): the density around them, the best incidence
                                    angle and the shortest range each was seen at
    registrability          {scans, mean_overlap, min_overlap, mean_fitness, min_fitness,
                            refused}: over the scans registered to the cloud before them (all but
                            the first; none without registration, then null): overlap is the
                            share of the scan the cloud before it explains, fitness ICP's, refused
                            the count of poses refused
    rooms                   list, one per TRUE room of the scene, in scene order:
        id                  int     the scene's room id
        name                str
        scans               int     scans whose true position lies in the room (0: never scanned)
        structure_sensed_pct float  the room's structural surface sensed, % of the room's
        path_length_m       float   the legs driven to the room's scans
        processed_points    int
        processing_time_s   float
        quality_pct         float   the room's structural samples meeting both quality thresholds, %
    steps                   list, one per scan, in order:
        scan                int     0, 1, ...
        room                int | null  the true room of the scan (see below)
        position            [x, y, z]   true scanner position
        estimated_position  [x, y, z]   the robot's estimate
        estimated_rotation  [w, x, y, z]   the robot's estimate of the scanner's orientation, a unit
                            quaternion (scanner frame to map frame, as an E57 pose)
        predicted_gain      int     predicted Occluded-structure→Structure conversions (0: first scan
                                    of a room)
        structure_sensed_pct float  cumulative
        path_length_m       float   cumulative
        processing_time_s   float
        points              int     points of the scan
        structure_points    int     of which labelled Structure
        door                bool    a scan taken in a door frame on entering a room
        times               {stage: seconds}: scan, registration, roi, classification, voxels,
                            planning, evaluation
        registration_refused str    why ICP's pose was refused and the odometry's kept ("" when
                            accepted)
        registration_overlap, registration_fitness   float | null   the scan's overlap with the
                            cloud before it and ICP's fitness (null for the first scan)
        dense_pct, incidence_pct, quality_pct   float   the quality shares after this scan
    door_events             list of the env's door events: detected (with exterior, covered),
                            crossed, abandoned (with reason)
    room_ends               list, one per room the robot completed: {room (the robot's number),
                            scans, reason: "gain" | "declared" | "cap" | "no NVP"}
    wall_searches           list, one per wall-search scan (RoomRules.wall_search.scans > 0):
                            {scan (its index in steps), room (the robot's number)}
    config                  the env's EnvConfig as a dict (tuples as lists)

A scan belongs to the true room whose floor polygon (clear floor inside the walls) contains its
true position, with one exception: a door-frame scan (``door``: the first scan of a room, taken
standing in the door) stands on the wall face of the room just left, a few centimetres inside its
polygon, but belongs to the room entered. It goes to the true room that holds most of the other
scans the robot took in the same room; when there are none (the budget ran out on entering), to the
nearest room within 0.5 m that no earlier scan was in. A scan in no polygon (drift at a wall) goes to
the majority room of its robot room, else to the nearest room within 0.5 m, else to none
(``null``). A room's ``path_length_m`` is the sum of the legs driven to its scans, so the drive to a
door counts for the room entered.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numba
import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Point, Polygon

from nbs_env import threads
from nbs_env.config import QualityConfig
from scenes import Scene, SurfaceClass
from scenes.interior import interior_samples

if TYPE_CHECKING:
    from nbs_env.storey import Storey

__all__ = [
    "ROOM_TOLERANCE",
    "SCHEMA",
    "CoverageMeter",
    "QualityConfig",
    "QualityReport",
    "json_safe",
    "metrics_dict",
    "true_rooms_of",
]

#: The version tag of :func:`metrics_dict`'s output.
SCHEMA = "nbs-metrics/1"

#: How far (m) a scan outside every room polygon may lie from a room to be counted in it.
ROOM_TOLERANCE = 0.5


@numba.njit(cache=True, nogil=True)
def _sense(
    points: np.ndarray,
    samples: np.ndarray,
    order: np.ndarray,
    starts: np.ndarray,
    lo: np.ndarray,
    cell: float,
    shape: np.ndarray,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples within ``radius`` of the (n, 3) points, and each point's nearest sample and its
    distance: :meth:`_SampleColumns.query` on the columns' sorted ``samples``."""
    count = len(order)
    near = np.zeros(count, dtype=np.bool_)
    nearest = np.full(len(points), count, dtype=np.int64)
    distance = np.full(len(points), np.inf)
    r2 = radius * radius
    for p in range(len(points)):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        x0 = max(int(np.floor((x - radius - lo[0]) / cell)), 0)
        x1 = min(int(np.floor((x + radius - lo[0]) / cell)), shape[0] - 1)
        y0 = max(int(np.floor((y - radius - lo[1]) / cell)), 0)
        y1 = min(int(np.floor((y + radius - lo[1]) / cell)), shape[1] - 1)
        best, which = np.inf, count
        for ix in range(x0, x1 + 1):
            for iy in range(y0, y1 + 1):
                a, b = starts[ix * shape[1] + iy], starts[ix * shape[1] + iy + 1]
                j = a + np.searchsorted(samples[a:b, 2], z - radius)
                while j < b and samples[j, 2] <= z + radius:
                    dx, dy, dz = samples[j, 0] - x, samples[j, 1] - y, samples[j, 2] - z
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 < r2:
                        s = order[j]
                        near[s] = True
                        if d2 < best or (d2 == best and s < which):
                            best, which = d2, s
                    j += 1
        if which < count:
            nearest[p] = which
            distance[p] = np.sqrt(best)
    return near, nearest, distance


class _SampleColumns:
    """The meter's samples sorted into plan columns of twice the sensing radius, by height within
    each: a point's samples within reach lie in the (at most 2 x 2) columns its reach overlaps, in
    one run of heights each. Built once per scene; a k-d tree queried with each scan's points did
    the same three times slower (benchmarks/README.md)."""

    def __init__(self, samples: np.ndarray, radius: float) -> None:
        self.radius = float(radius)
        self.cell = 2.0 * self.radius
        self.lo = samples[:, :2].min(axis=0) - self.cell
        cells = np.floor((samples[:, :2] - self.lo) / self.cell).astype(np.int64)
        self.shape = cells.max(axis=0) + 2
        column = cells[:, 0] * self.shape[1] + cells[:, 1]
        self.order = np.lexsort((samples[:, 2], column))
        self.samples = np.ascontiguousarray(samples[self.order], dtype=float)
        counts = np.bincount(column, minlength=int(np.prod(self.shape)))
        self.starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(samples within ``radius`` of a point, each point's nearest sample (the sample count
        where none is within reach), its distance (inf where none))."""
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)

        def rows(part: slice):
            some = np.ascontiguousarray(points[part])
            return _sense(some, self.samples, self.order, self.starts, self.lo, self.cell, self.shape, self.radius)

        # Each point reads the samples of up to four columns within its reach: tens of steps.
        parts = threads.split(rows, len(points), cost=30 * len(points))
        if len(parts) == 1:
            return parts[0]
        near = np.logical_or.reduce([p[0] for p in parts])
        nearest = np.empty(len(points), dtype=np.int64)
        distance = np.empty(len(points))
        for k, (_, which, dist) in enumerate(parts):
            nearest[k :: len(parts)] = which
            distance[k :: len(parts)] = dist
        return near, nearest, distance


@dataclass(frozen=True)
class QualityReport:
    """What :meth:`CoverageMeter.quality` measured.

    Attributes
    ----------
    density : (n,) float
        Points per m² around each sample, over all scans (``QualityConfig.density_radius``).
    incidence : (n,) float
        The smallest incidence angle (degrees from the normal) each sample was seen at; NaN when no
        point was attributed to it.
    range : (n,) float
        The shortest range (metres) each sample was seen from; NaN when never.
    dense_pct, incidence_pct, quality_pct : (k,) float
        After each of the ``k`` scans: % of the structural samples with density >= ``min_density``,
        seen at <= ``max_incidence``, and both.
    """

    density: np.ndarray
    incidence: np.ndarray
    range: np.ndarray
    dense_pct: np.ndarray
    incidence_pct: np.ndarray
    quality_pct: np.ndarray


class CoverageMeter:
    """Share of the true structural surface sensed, overall and per room, and how well.

    A ground-truth sample (one per ``spacing``² of floor, ceiling and wall) counts as sensed when a
    registered point lies within ``radius`` of it. The denominator is always the full surface.

    Given the scan's origin, :meth:`add` also attributes every point to its nearest sample within
    ``radius`` and notes, per sample, how many points it got and the incidence angle and range it
    was seen at: the scan-quality figures of :meth:`quality`.

    Parameters
    ----------
    scene : Scene
        The true building.
    spacing : float
        Sample spacing in metres (0.05: one sample per 25 cm²).
    radius : float
        Sensing radius in metres.
    interior_only : bool
        Count only the SE surface that faces the building's interior, decided by geometry
        (:func:`scenes.interior.interior_samples`): never the far sides of walls or the undersides
        of slabs, and the same whether or not the file names its rooms.
    """

    def __init__(self, scene: Scene, spacing: float = 0.05, radius: float = 0.05, interior_only: bool = True) -> None:
        self.samples = interior_samples(scene, spacing) if interior_only else scene.structure_samples(spacing)
        self.spacing = float(spacing)
        self.radius = radius
        self.sensed = np.zeros(len(self.samples), dtype=bool)
        self.room_ids = sorted({int(r) for r in self.samples.rooms})
        self.normals = np.asarray(scene.mesh.face_normals, dtype=float)[self.samples.faces].reshape(-1, 3)
        # Per scan: (sample indices, points attributed, incidence degrees, range m, samples newly sensed).
        self.observations: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._tree: cKDTree | None = None
        self._columns: _SampleColumns | None = None
        self._neighbours: tuple[float, tuple[Any, np.ndarray]] | None = None
        self._quality: tuple[tuple[QualityConfig, int], QualityReport] | None = None

    def add(self, points: np.ndarray, origin: np.ndarray | None = None) -> int:
        """Mark the samples the (n, 3) registered points sense; returns how many were newly sensed.

        ``origin`` (3,): where the scan was taken from; when given, the scan's quality figures are
        noted too (:meth:`quality`)."""
        points = np.asarray(points, dtype=float)
        near, nearest, distance = self._query(points)
        hit = np.flatnonzero(near & ~self.sensed)
        self.sensed[hit] = True
        if origin is not None:
            self._observe(np.asarray(origin, dtype=float).reshape(3), nearest[np.isfinite(distance)], hit)
        return len(hit)

    def _sample_tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.samples.points)
        return self._tree

    def _query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n_samples,) bool: the samples within ``radius`` of some point; and per point its nearest
        sample and the distance to it (``inf`` where none is within ``radius``)."""
        n = len(self.samples)
        if not len(points) or not n:
            return np.zeros(n, dtype=bool), np.full(len(points), n, dtype=np.int64), np.full(len(points), np.inf)
        if self._columns is None:
            self._columns = _SampleColumns(self.samples.points, self.radius)
        return self._columns.query(points)

    def _observe(self, origin: np.ndarray, nearest: np.ndarray, newly: np.ndarray) -> None:
        """Note one scan's quality figures; ``nearest`` holds each attributed point's sample."""
        count = np.bincount(nearest, minlength=len(self.samples))
        index = np.flatnonzero(count)
        count = count[index]
        ray = origin - self.samples.points[index]
        rng = np.linalg.norm(ray, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", ray, self.normals[index])) / np.maximum(rng, 1e-9)
        incidence = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
        self.observations.append(
            (
                index.astype(np.int32),
                count.astype(np.int32),
                incidence.astype(np.float32),
                rng.astype(np.float32),
                newly.astype(np.int32),
            )
        )

    def _neighbourhoods(self, radius: float) -> tuple[Any, np.ndarray]:
        """The (n, n) sparse 0/1 matrix of samples within ``radius`` of each other (self included),
        and each sample's count of them; built once per meter."""
        from scipy.sparse import csr_matrix, identity

        if self._neighbours is None or self._neighbours[0] != radius:
            n = len(self.samples)
            pairs = self._sample_tree().query_pairs(radius, output_type="ndarray")
            rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
            cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
            near = csr_matrix((np.ones(len(rows), dtype=np.float32), (rows, cols)), shape=(n, n))
            near = (near + identity(n, dtype=np.float32, format="csr")).tocsr()
            self._neighbours = (radius, (near, np.asarray(near.sum(axis=1)).ravel()))
        return self._neighbours[1]

    def quality(self, config: QualityConfig | None = None) -> QualityReport:
        """The scan-quality figures of the scans added with their origin (:class:`QualityReport`).

        Every point is attributed to its nearest sample within ``radius``. A sample's density is the
        points attributed around it (``config.density_radius``), over all scans. Its incidence and
        range are the smallest of the samples around it that a scan's points were attributed to, so
        that a sample between the points of a sparse pattern, sensed but attributed none, takes its
        neighbours' angle. Only sensed samples (:meth:`percent`) count, so the shares never exceed
        the coverage; like it, they are shares of all samples.
        """
        config = config or QualityConfig()
        # metrics.json and the report's samples.npz both ask at the run's end: computed once.
        key = (config, len(self.observations))
        if self._quality is not None and self._quality[0] == key:
            return self._quality[1]
        n = len(self.samples)
        near, size = self._neighbourhoods(config.density_radius)
        counts = np.zeros(n)
        seen = np.full(n, np.inf, dtype=np.float32)
        closest = np.full(n, np.inf, dtype=np.float32)
        sensed = np.zeros(n, dtype=bool)
        area = size * self.spacing**2
        curves = np.zeros((len(self.observations), 3))
        density, incidence, rng = np.zeros(n), np.full(n, np.inf), np.full(n, np.inf)
        for k, (index, count, angle, distance, newly) in enumerate(self.observations):
            counts[index] += count
            np.minimum.at(seen, index, angle)
            np.minimum.at(closest, index, distance)
            sensed[newly] = True
            if not n:
                continue
            density = np.where(sensed, near @ counts / area, 0.0)
            incidence = np.where(sensed, _neighbourhood_min(near, seen), np.inf)
            dense = density >= max(config.min_density, 1e-12)
            square = incidence <= config.max_incidence
            curves[k] = [dense.mean(), square.mean(), (dense & square).mean()]
        if n:
            rng = np.where(sensed, _neighbourhood_min(near, closest), np.inf)
        incidence = np.where(np.isfinite(incidence), incidence, np.nan)
        rng = np.where(np.isfinite(rng), rng, np.nan)
        report = QualityReport(density, incidence, rng, *(100.0 * curves.T))
        self._quality = (key, report)
        return report

    def percent(self, room: int | None = None, label: SurfaceClass | None = None) -> float:
        """Sensed share in % of all samples, of one room's, and/or of one class's."""
        mask = self._mask(room, label)
        total = int(mask.sum())
        return 100.0 * float(self.sensed[mask].sum()) / total if total else 0.0

    def _mask(self, room: int | None = None, label: SurfaceClass | None = None) -> np.ndarray:
        mask = np.ones(len(self.samples), dtype=bool)
        if room is not None:
            mask &= self.samples.rooms == room
        if label is not None:
            mask &= self.samples.labels == label
        return mask


def _neighbourhood_min(near: Any, values: np.ndarray) -> np.ndarray:
    """(n,) float: the smallest of ``values`` over each row's neighbours of the sparse matrix ``near``
    (every row holds at least its own sample)."""
    return np.minimum.reduceat(values[near.indices], near.indptr[:-1]).astype(float)


def json_safe(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples and Paths made plain JSON types."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"cannot make a {type(value).__name__} JSON-safe")


def true_rooms_of(storey: Storey) -> list[int | None]:
    """The true room id of every scan of the storey session (the module docstring says how
    door-frame scans are placed)."""
    rooms = storey.scene.rooms
    polys = [Polygon(np.asarray(r.polygon, dtype=float)) for r in rooms]
    steps = storey.scans
    points = [Point(float(s.true_position[0]), float(s.true_position[1])) for s in steps]
    contained: list[int | None] = []
    for point in points:
        inside = [r.id for r, p in zip(rooms, polys, strict=True) if shapely.contains_xy(p, point.x, point.y)]
        contained.append(int(inside[0]) if inside else None)
    # The true room of each robot room, by the majority of its scans away from doors.
    votes: dict[int, Counter] = {}
    for step, room in zip(steps, contained, strict=True):
        if room is not None and not step.door:
            votes.setdefault(int(step.room), Counter())[room] += 1

    def nearest(point: Point, exclude: set[int | None]) -> int | None:
        best, best_distance = None, ROOM_TOLERANCE
        for room, poly in zip(rooms, polys, strict=True):
            distance = poly.distance(point)
            if room.id not in exclude and distance <= best_distance:
                best, best_distance = int(room.id), distance
        return best

    out: list[int | None] = []
    for i, step in enumerate(steps):
        vote = votes.get(int(step.room))
        majority = int(vote.most_common(1)[0][0]) if vote else None
        if step.door:
            # Taken in a door frame, which stands on the wall face of the room just left: the scan
            # belongs to the room entered, a room no earlier scan was in.
            room = majority if majority is not None else nearest(points[i], set(out))
            out.append(room if room is not None else contained[i])
        elif contained[i] is not None:
            out.append(contained[i])
        else:
            out.append(majority if majority is not None else nearest(points[i], set()))
    return out


def _share(flags: np.ndarray, mask: np.ndarray | None = None) -> float:
    """% of the samples (of ``mask``'s) whose flag is set; 0 with none."""
    flags = flags if mask is None else flags[mask]
    return 100.0 * float(np.count_nonzero(flags)) / len(flags) if len(flags) else 0.0


def quaternion_wxyz(pose: np.ndarray) -> np.ndarray:
    """The rotation of a (4, 4) pose as a unit quaternion ``[w, x, y, z]`` (E57's order), w >= 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(pose, dtype=float)[:3, :3]).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


def metrics_dict(
    storey: Storey,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
    structure_aware: bool | None = None,
) -> dict[str, Any]:
    """The ``metrics.json`` content of an episode (schema ``"nbs-metrics/1"``, module docstring).

    Parameters
    ----------
    storey : Storey
        A storey session (an env's ``storey`` after ``reset`` and any number of steps).
    scene_name : str
        The scene as the user named it.
    policy : str
        The policy's name (an object with a ``name`` attribute is also taken).
    seed : int or None
        The seed given to ``reset``.
    policy_times : dict of int to float, optional
        Seconds the policy spent deciding, by the index of the scan its decision led to; added to
        that scan's processing time (the greedy's gains are already in the env's planning stage).
    structure_aware : bool, optional
        Whether the policy's pipeline keeps only the SE points (the paper's method) or processes
        every point (the structure-agnostic methods), for ``processed_points``; by default the
        policy object's ``structure_aware`` attribute, else True.

    Returns
    -------
    dict
        Plain JSON types only.
    """
    if structure_aware is None:
        structure_aware = bool(getattr(policy, "structure_aware", True))
    policy_times = policy_times or {}
    steps = storey.scans
    if not steps:
        raise ValueError("the storey has no scans: call reset() first")

    def processed(s) -> int:
        return int(s.structure_points if structure_aware else s.points)

    def processing(i: int) -> float:
        return float(steps[i].processing_time + policy_times.get(i, 0.0))

    policy_name = str(getattr(policy, "name", policy))
    meter = storey.meter
    true_rooms = true_rooms_of(storey)
    cumulative = np.array([float(s.path_length) for s in steps])
    legs = np.diff(cumulative, prepend=0.0)
    path_length = float(cumulative[-1])
    reg = np.array([s.registration_error for s in steps], dtype=float).reshape(-1, 2)

    quality_config = storey.config.quality
    quality = meter.quality(quality_config)
    good = (quality.density >= quality_config.min_density) & (quality.incidence <= quality_config.max_incidence)
    if len(quality.dense_pct) != len(steps):  # scans added without their origin: no curves
        quality_rows = [{"dense_pct": None, "incidence_pct": None, "quality_pct": None} for _ in steps]
    else:
        quality_rows = [
            {"dense_pct": float(d), "incidence_pct": float(a), "quality_pct": float(q)}
            for d, a, q in zip(quality.dense_pct, quality.incidence_pct, quality.quality_pct, strict=True)
        ]
    seen = np.isfinite(quality.incidence)

    def median(values: np.ndarray) -> float | None:
        return float(np.median(values[seen])) if seen.any() else None

    registered = [s for s in steps if s.registration_overlap is not None]
    overlaps = np.array([s.registration_overlap for s in registered], dtype=float)
    fitness = np.array([s.registration_fitness for s in registered], dtype=float)

    rooms = []
    for room in storey.scene.rooms:
        mine = [i for i, r in enumerate(true_rooms) if r == room.id]
        rooms.append(
            {
                "id": int(room.id),
                "name": str(room.name),
                "scans": len(mine),
                "structure_sensed_pct": float(meter.percent(room=room.id)),
                "path_length_m": float(sum(legs[i] for i in mine)),
                "processed_points": int(sum(processed(steps[i]) for i in mine)),
                "processing_time_s": float(sum(processing(i) for i in mine)),
                "quality_pct": _share(good, meter.samples.rooms == room.id),
            }
        )

    step_rows = [
        {
            "scan": int(s.scan),
            "room": room,
            "position": [float(v) for v in s.true_position[:3]],
            "estimated_position": [float(v) for v in s.estimated_position[:3]],
            "estimated_rotation": quaternion_wxyz(s.estimated_pose).tolist(),
            "predicted_gain": int(s.predicted_gain),
            "structure_sensed_pct": float(s.structure_sensed_pct),
            "path_length_m": float(s.path_length),
            "processing_time_s": processing(k),
            "points": int(s.points),
            "structure_points": int(s.structure_points),
            "door": bool(s.door),
            "times": {str(k): float(v) for k, v in s.times.items()},
            "registration_refused": str(s.registration_refused),
            "registration_overlap": s.registration_overlap,
            "registration_fitness": s.registration_fitness,
            **quality_rows[k],
        }
        for k, (s, room) in enumerate(zip(steps, true_rooms, strict=True))
    ]

    metrics = {
        "schema": SCHEMA,
        "scene": str(scene_name),
        "policy": policy_name,
        "seed": None if seed is None else int(seed),
        "complete": bool(storey.complete),
        "scans": len(steps),
        "structure_sensed_pct": float(meter.percent()),
        "path_length_m": path_length,
        "processed_points": int(sum(processed(s) for s in steps)),
        "measured_points": int(sum(s.points for s in steps)),
        "processing_time_s": float(sum(processing(i) for i in range(len(steps)))),
        "policy_time_s": float(sum(policy_times.values())),
        "acquisition_time_s": float(sum(s.acquisition_time for s in steps)),
        "travel_time_s": path_length / float(storey.config.travel_speed),
        "registration_error": {
            "mean_m": float(reg[:, 0].mean()),
            "max_m": float(reg[:, 0].max()),
            "mean_deg": float(reg[:, 1].mean()),
            "max_deg": float(reg[:, 1].max()),
        },
        "quality": {
            "min_density_per_m2": float(quality_config.min_density),
            "max_incidence_deg": float(quality_config.max_incidence),
            "density_radius_m": float(quality_config.density_radius),
            "dense_pct": _share(quality.density >= quality_config.min_density),
            "incidence_pct": _share(quality.incidence <= quality_config.max_incidence),
            "quality_pct": _share(good),
            "median_density_per_m2": median(quality.density),
            "median_incidence_deg": median(quality.incidence),
            "median_range_m": median(quality.range),
        },
        "registrability": {
            "scans": len(registered),
            "mean_overlap": float(overlaps.mean()) if len(overlaps) else None,
            "min_overlap": float(overlaps.min()) if len(overlaps) else None,
            "mean_fitness": float(fitness.mean()) if len(fitness) else None,
            "min_fitness": float(fitness.min()) if len(fitness) else None,
            "refused": sum(1 for s in steps if s.registration_refused),
        },
        "rooms": rooms,
        "steps": step_rows,
        "door_events": storey.door_events,
        "room_ends": storey.room_ends,
        "wall_searches": storey.wall_searches,
        "config": storey.config.to_dict(),
    }
    return json_safe(metrics)
