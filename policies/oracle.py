"""The oracle: the yardstick of the comparison, and the ONE policy that reads ground truth.

It is not a competitor. With the true building it lists the scan positions a robot could stand at
(a lattice over the indoor free floor, found by geometry as :mod:`scenes.interior` finds it,
keeping the 0.45 m clearance from walls and furniture, and the pole of any free patch it misses)
and could drive to from the scene's start (a disc of the robot's radius connects them: the
other dwelling of a storey, or a level up a stair, is no place a plan of this robot scans from),
takes a noise-free
scan of the true building from each with the same scanner as the robot, finds which samples of the
true structural surface each scan senses by the evaluation's own rule (a point within the
meter's radius, :class:`nbs_env.evaluation.CoverageMeter`), and picks positions by greedy set cover.
That gives, per scene and scanner:

- the largest share of the structural surface any plan of scans from those positions senses
  (``max_coverage_pct``), and
- the fewest scans found to reach a given share (``scans_to_reach``; greedy set cover is within a
  factor ln(n) of the optimum, and is what is reported).

The oracle's scans are perfectly registered and noise-free, so a robot can fall short of its
coverage through registration error and noise, and exceed it slightly only by noise.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import polylabel

from nbs_env.config import ScannerConfig
from nbs_env.planning.navigation import NavigationConfig
from scenes import Scene
from scenes.geometry import free_region
from scenes.interior import indoor_floor, interior_samples, separating_footprint
from scenes.limits import MAX_ORIGIN_DISTANCE

__all__ = ["DOORWAY_DEPTH", "REACH_TOLERANCE", "OraclePlan", "oracle_plan", "reach"]

#: Metres: the thickest wall whose doorway the oracle's :func:`reach` passes where the file draws
#: no floor under the door or no ceiling over it.
DOORWAY_DEPTH = 0.5
#: Metres taken off the robot's radius for :func:`reach` (one voxel of the default map).
REACH_TOLERANCE = 0.05
ROOM_KEY = re.compile(r"0|[1-9][0-9]{0,8}", re.ASCII)


@dataclass(frozen=True)
class OraclePlan:
    """The oracle's greedy set cover of one scene.

    Attributes
    ----------
    positions : (m, 3) float
        The chosen scanner positions, in the order chosen.
    coverage_pct : (m,) float
        Share of the structural samples seen after each chosen scan, in %.
    max_coverage_pct : float
        Share seen from all candidate positions together.
    candidates : int
        How many candidate positions there were.
    samples : int
        How many structural samples.
    room_max_pct : dict of int to float
        Per true room (the scene's rooms, from the file or derived), the share of its samples seen
        from all candidate positions together, in %.
    """

    positions: np.ndarray
    coverage_pct: np.ndarray
    max_coverage_pct: float
    candidates: int
    samples: int
    room_max_pct: dict[int, float] = field(default_factory=dict)

    def scans_to_reach(self, pct: float) -> int | None:
        """The fewest scans of the plan that see at least ``pct`` % (None if it never does)."""
        hit = np.flatnonzero(self.coverage_pct >= pct - 1e-9)
        return int(hit[0]) + 1 if len(hit) else None

    @classmethod
    def from_dict(cls, record: dict) -> OraclePlan:
        """The plan :meth:`to_dict` wrote, each field checked against the others.

        Raises
        ------
        ValueError
            Naming the field that is missing, of the wrong kind or out of range: positions not
            (m, 3) finite metres, a coverage curve of another length than the positions, falling,
            outside 0..100 or above the best coverage, more scans than candidates.
        """

        def numbers(value: object, depth: int = 0) -> bool:  # JSON numbers, not strings float() reads
            if isinstance(value, (list, tuple)):  # a record is at most a list of triples: no deeper
                return depth < 2 and all(numbers(v, depth + 1) for v in value)
            return type(value) in (int, float)

        fields = ("positions", "coverage_pct", "max_coverage_pct")
        if not isinstance(record, dict) or not all(numbers(record.get(k)) for k in fields):
            raise ValueError(f"not an oracle plan: {', '.join(fields)} must be JSON numbers, nested at most twice")
        rooms_record = record.get("room_max_pct", {})
        if not isinstance(rooms_record, dict) or not numbers(list(rooms_record.values())):
            raise ValueError("not an oracle plan: room_max_pct must map rooms to JSON numbers")
        # to_dict writes room ids as str(int): one spelling a room, so no two keys name the same room
        odd = [k for k in rooms_record if not (isinstance(k, str) and ROOM_KEY.fullmatch(k))]
        if odd:
            raise ValueError(f"not an oracle plan: room_max_pct key {odd[0]!r} is not a room id (0, 1, 2, ...)")
        try:
            positions = np.asarray(record["positions"], dtype=float)
            coverage = np.asarray(record["coverage_pct"], dtype=float)
            best = float(record["max_coverage_pct"])
            candidates, samples = record["candidates"], record["samples"]
            rooms = {int(k): float(v) for k, v in rooms_record.items()}
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:  # 10**400 overflows
            raise ValueError(f"not an oracle plan ({type(exc).__name__}: {exc})") from None
        if positions.size == 0:  # [] reads as shape (0,): a plan of no scans
            positions = positions.reshape(0, 3)
        if positions.ndim != 2 or positions.shape[1] != 3:
            raise ValueError(f"positions must be (m, 3) metres, got shape {positions.shape}")
        if type(candidates) is not int or type(samples) is not int or candidates < 0 or samples < 0:
            raise ValueError("candidates and samples are not counts")
        if not np.isfinite(positions).all():
            raise ValueError("a position is not finite")
        if len(positions) and np.abs(positions).max() > MAX_ORIGIN_DISTANCE:  # no storey's (scenes.limits)
            raise ValueError(f"a position lies beyond {MAX_ORIGIN_DISTANCE:,.0f} m of the origin, where no storey does")
        if coverage.ndim != 1 or len(coverage) != len(positions) or len(positions) > candidates:
            raise ValueError(
                f"{len(coverage)} coverage values for {len(positions)} positions of {candidates} candidates"
            )
        if not (0 <= best <= 100) or not all(0 <= v <= 100 for v in rooms.values()):  # NaN fails too
            raise ValueError("a best coverage outside 0..100 %")
        if not (((coverage >= 0) & (coverage <= best + 1e-6)).all() and (np.diff(coverage) >= -1e-9).all()):
            raise ValueError("the coverage curve falls, or leaves 0..max_coverage_pct")
        return cls(positions, coverage, best, candidates, samples, rooms)

    def to_dict(self) -> dict:
        return {
            "positions": self.positions.round(3).tolist(),
            "coverage_pct": [float(v) for v in self.coverage_pct],
            "max_coverage_pct": float(self.max_coverage_pct),
            "candidates": int(self.candidates),
            "samples": int(self.samples),
            "room_max_pct": {str(k): float(v) for k, v in self.room_max_pct.items()},
        }


def reach(scene: Scene, radius: float, indoor: tuple | None = None) -> Polygon:
    """The indoor free floor a disc of ``radius`` metres drives over from the scene's start.

    Parameters
    ----------
    scene : Scene
        The true building; its ``start`` (the file's, the caller's or :func:`scenes.geometry.auto_start`'s).
    radius : float
        The robot's radius (it passes doors with no safety distance, as the storey's crossings do).
    indoor : (floor, floor_z), optional
        :func:`scenes.interior.indoor_floor`'s result, when the caller has it.

    Returns
    -------
    shapely Polygon
        The part of the indoor free floor, shrunk by ``radius`` and cut at the scene's doors to the
        outside (``Door.rooms`` holding -1), that holds the start (the nearest
        part when the start lies in none, which a start within ``radius`` of a wall may); empty
        when the storey has no floor.
    """
    floor, floor_z = indoor if indoor is not None else indoor_floor(scene)
    # The indoor floor stops at walls, and so at a doorway whose floor lies under no ceiling (a wall's
    # thickness): closing it over gaps up to DOORWAY_DEPTH and taking the walls out again joins rooms
    # at their doorways only.
    walls = separating_footprint(scene, floor_z)
    floor = floor.buffer(DOORWAY_DEPTH / 2).buffer(-DOORWAY_DEPTH / 2)
    floor = floor.difference(walls) if not walls.is_empty else floor
    # Nor is the outside a place to scan from: a door the file gives to the outside is closed here
    # (a roofed porch or balcony is indoor floor by the ceiling test).
    for door in scene.doors:
        if -1 in door.rooms and np.linalg.norm(door.normal) > 0.5:
            along = np.array([-door.normal[1], door.normal[0]]) * (door.width / 2 + DOORWAY_DEPTH)
            centre = np.asarray(door.position[:2], dtype=float)
            floor = floor.difference(LineString([centre - along, centre + along]).buffer(0.01))
    parts = []
    for part in getattr(floor, "geoms", [floor]):
        if isinstance(part, Polygon) and not part.is_empty:
            free = free_region(scene, part, floor_z, radius)
            parts += [g for g in getattr(free, "geoms", [free]) if isinstance(g, Polygon) and not g.is_empty]
    if not parts:
        return Polygon()
    start = Point(float(scene.start[0]), float(scene.start[1]))
    return min(parts, key=lambda g: g.distance(start))


def _positions(scene: Scene, lattice: float, clearance: float, radius: float) -> np.ndarray:
    """Lattice points of the indoor free floor (by geometry: the same with or without room
    annotations) that keep ``clearance`` from every obstacle and lie in the :func:`reach` of a
    disc of ``radius``."""
    floor, floor_z = indoor_floor(scene)
    reachable = reach(scene, radius, (floor, floor_z))
    out = []
    for part in getattr(floor, "geoms", [floor]):
        if not isinstance(part, Polygon) or part.is_empty:
            continue
        free = free_region(scene, part, floor_z, clearance).intersection(reachable)
        if free.is_empty:
            continue
        lo, hi = np.floor(np.asarray(free.bounds[:2]) / lattice), np.ceil(np.asarray(free.bounds[2:]) / lattice)
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + 1) * lattice, np.arange(lo[1], hi[1] + 1) * lattice)
        pts = np.column_stack([gx.ravel(), gy.ravel()])
        inside = shapely.contains_xy(free, pts[:, 0], pts[:, 1])
        for p in pts[inside]:
            out.append([p[0], p[1], floor_z])
        # A free patch the lattice misses (a small room between lattice lines) still has a place to
        # scan from: its pole of inaccessibility.
        for patch in getattr(free, "geoms", [free]):
            missed = isinstance(patch, Polygon) and not patch.is_empty
            if missed and not shapely.contains_xy(patch, pts[inside, 0], pts[inside, 1]).any():
                pole = polylabel(patch, tolerance=0.01)
                out.append([pole.x, pole.y, floor_z])
    return np.asarray(out, dtype=float).reshape(-1, 3)


class PlanningStoppedError(Exception):
    """:func:`oracle_plan` was asked to stop (a signal to the command running it) before it finished."""


def oracle_plan(
    scene: Scene,
    scanner: ScannerConfig | None = None,
    *,
    lattice: float = 0.5,
    clearance: float | None = None,
    spacing: float = 0.05,
    radius: float = 0.05,
    stop: Callable[[], bool] | None = None,
) -> OraclePlan:
    """Greedy set cover of the scene's structural surface by scan positions (module docstring).

    Parameters
    ----------
    scene : Scene
        The true building (ground truth: this is the yardstick).
    scanner : ScannerConfig
        The robot's scanner; its range noise is left out.
    lattice : float
        Spacing of the candidate positions, metres (the robot's NVP lattice).
    clearance : float, optional
        Distance to keep from walls and furniture, metres; by default the robot's footprint
        (``NavigationConfig().required_clearance``: radius plus safety distance).
    spacing, radius : float
        The evaluation's sample spacing and sensing radius (as the env's ``coverage_spacing`` and
        ``coverage_radius``).
    stop : callable, optional
        Asked before each candidate's scan; True ends the planning with :class:`PlanningStoppedError`
        (a storey's scans take tens of seconds: a signal waited for all of them).
    """
    from dataclasses import replace

    from scipy.spatial import cKDTree

    from nbs_env.sensing.pose import planar
    from nbs_env.sensing.scanner import Scanner

    scanner = replace(scanner or ScannerConfig(), range_noise=0.0)
    structure = interior_samples(scene, spacing)
    samples = structure.points
    if clearance is None:
        clearance = NavigationConfig().required_clearance
    # The robot's map places an obstacle to within a voxel (5 cm by default), and a robot has passed
    # a gap a voxel narrower than its diameter: the yardstick grants the same, never less.
    positions = _positions(scene, lattice, clearance, NavigationConfig().robot_radius - REACH_TOLERANCE)
    caster = Scanner(scene, scanner)
    sees = np.zeros((len(positions), len(samples)), dtype=bool)
    for k, (x, y, z) in enumerate(positions):
        if stop is not None and stop():
            raise PlanningStoppedError(f"stopped after {k} of {len(positions)} candidate scans")
        pose = planar(x, y, 0.0, z + scanner.height)
        points = caster.scan(pose).to_world(pose)
        if not len(points):
            continue
        distance, _ = cKDTree(points).query(samples, distance_upper_bound=radius, workers=-1)
        sees[k] = np.isfinite(distance)
    reachable = sees.any(axis=0)
    covered = np.zeros(len(samples), dtype=bool)
    chosen, curve = [], []
    while True:
        gain = (sees & ~covered).sum(axis=1)
        best = int(np.argmax(gain)) if len(gain) else 0
        if not len(gain) or gain[best] == 0:
            break
        covered |= sees[best]
        chosen.append(positions[best])
        curve.append(100.0 * covered.sum() / max(1, len(samples)))
    return OraclePlan(
        positions=np.asarray(chosen, dtype=float).reshape(-1, 3),
        coverage_pct=np.asarray(curve, dtype=float),
        max_coverage_pct=100.0 * reachable.sum() / max(1, len(samples)),
        candidates=len(positions),
        samples=len(samples),
        room_max_pct={
            int(room.id): 100.0 * float(reachable[structure.rooms == room.id].mean())
            for room in scene.rooms
            if np.any(structure.rooms == room.id)
        },
    )
