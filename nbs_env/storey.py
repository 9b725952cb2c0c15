"""The storey session: one episode of the method over a storey, room by room through doors.

A :class:`Storey` owns the :class:`~nbs_env.robot.Robot`, the robot's door memory
(:class:`~nbs_env.planning.rooms.Rooms`), the room rules (:class:`~nbs_env.config.RoomRules`), the
:class:`~nbs_env.evaluation.CoverageMeter` (the evaluation's reader of ground truth) and the
episode log. It runs the method's loop (paper Fig. 2, METHOD §7-8)::

    storey = Storey(scene, config, rng)        # the first scan, then advance()
    while storey.open:
        storey.scan_at(storey.plan.best())     # or storey.room_done() when completion="policy"

- :meth:`Storey.scan_at`: the robot drives to an NVP and scans there; then :meth:`Storey.advance`.
- :meth:`Storey.advance`: while the room is complete (METHOD §7: no NVP predicts enough
  Occluded-structure→Structure conversions, or the agent declared it done; the scan cap and running
  out of NVPs end it too), search for doors no scan faced (``rooms.wall_search``), detect its doors,
  drive to the nearest unvisited door and take the first scan of the next room (METHOD §8); with no
  door left, the storey is complete.

No gymnasium import: :class:`~nbs_env.env.NBSEnv` puts spaces, reward and observation around it.
"""

from __future__ import annotations

import copy
import numbers
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon

from nbs_env import threads
from nbs_env.belief import RoomModel
from nbs_env.config import EnvConfig
from nbs_env.errors import ConfigError, InvalidPoseError, UnreachableDoorError
from nbs_env.evaluation import CoverageMeter
from nbs_env.labels import VoxelLabel
from nbs_env.observation import BeliefView
from nbs_env.perception.roi import RoIError
from nbs_env.planning.planner import Plan
from nbs_env.planning.rooms import KnownDoor, Rooms, SearchStop
from nbs_env.robot import Robot, StepReport
from scenes import FloorPlan, Scene, load_scene
from scenes.generator import generate_storey
from scenes.geometry import point_is_free
from scenes.labels import STRUCTURAL_CLASSES
from scenes.limits import MAX_ORIGIN_DISTANCE

__all__ = [
    "STAGES",
    "ScanPoints",
    "ScanRecord",
    "StageTimes",
    "StepOutcome",
    "Storey",
    "join_paths",
    "resolve_scene",
    "start_problem",
]

#: Stage names of a scan's ``times``, in the order a step runs them.
STAGES = ("scan", "registration", "roi", "classification", "voxels", "planning")
#: A room with no NVP ended as an ``"earlier room"`` when at least this share of its RoI lies in the
#: rooms scanned before: the space beyond its door was scanned as part of one of them.
EARLIER_ROOM_SHARE = 0.5
#: Metres a start's given z may lie from the floor under it (the robot stands on the floor; a floor
#: drawn a little off level, or a height read off another model of the building, is still that floor).
START_HEIGHT_TOLERANCE = 0.5


@dataclass(frozen=True)
class StageTimes:
    """Seconds each stage of a step took, as ``info["times"]``.

    Timings measure the machine, not the environment's state, so two of them always compare equal:
    determinism checks (Gymnasium's ``check_env``, same-seed tests) compare everything else.
    ``times["roi"]`` and ``times.as_dict()`` read them.
    """

    values: dict[str, float] = field(compare=False, default_factory=dict)

    def __getitem__(self, stage: str) -> float:
        return self.values[stage]

    def keys(self):
        return self.values.keys()

    def items(self):
        return self.values.items()

    def as_dict(self) -> dict[str, float]:
        return dict(self.values)


@dataclass
class ScanRecord:
    """One scan of the episode, as the report records it (``true_*`` for evaluation only)."""

    scan: int
    room: int
    door: bool
    true_position: np.ndarray
    estimated_position: np.ndarray
    predicted_gain: int
    path_length: float
    structure_sensed_pct: float
    processing_time: float
    acquisition_time: float
    points: int
    structure_points: int
    registration_error: tuple[float, float]
    times: dict[str, float]
    registration_refused: str = ""
    #: (4, 4) float: the robot's estimate of the scanner pose.
    estimated_pose: np.ndarray = field(repr=False, default_factory=lambda: np.eye(4))
    #: Registration's share of the scan that S(t) explains (its overlap with the cloud before it)
    #: and ICP's fitness; None for the first scan and without registration.
    registration_overlap: float | None = None
    registration_fitness: float | None = None
    #: (p, 2) float: the polyline the robot drove from the scan before to this one, in its map
    #: frame, as it planned it (its length is ``path_length`` less the scan before's); (0, 2) for
    #: the first scan.
    path: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 2)))


@dataclass(frozen=True)
class ScanPoints:
    """One scan as measured, for export: points in the scanner frame and the robot's pose of it.

    Attributes
    ----------
    points : (n, 3) float32
        Measured points in the scanner frame.
    rows, cols : (n,) uint16 (int32 for a pattern over 65,535 rows or columns)
        Each point's row (elevation) and column (azimuth) in the scan pattern.
    pose : (4, 4) float
        The estimated scanner pose (scanner frame to the robot's map frame).
    """

    points: np.ndarray = field(repr=False)
    rows: np.ndarray = field(repr=False)
    cols: np.ndarray = field(repr=False)
    pose: np.ndarray


@dataclass(frozen=True)
class StepOutcome:
    """What one decision did to the storey.

    Attributes
    ----------
    scans : int
        Scans taken (a door crossing adds one).
    metres : float
        Distance driven.
    coverage_gain : float
        Increase of the true structural surface sensed, percentage points (evaluation side).
    conversions : int
        The robot's realised Occluded-structure→Structure conversions of the scan at the chosen NVP
        (counted when the session was asked to, else 0).
    structural_voxels : int
        Structure + Occluded-structure voxels of the room before the decision (the unit
        ``conversions`` is read in).
    mapped_gain : float
        Increase of the surface the robot labelled Structure, percentage points of the storey's
        structural surface (:attr:`Storey.mapped_pct`).
    """

    scans: int = 0
    metres: float = 0.0
    coverage_gain: float = 0.0
    conversions: int = 0
    structural_voxels: int = 0
    mapped_gain: float = 0.0


def join_paths(paths: list[np.ndarray]) -> np.ndarray:
    """Consecutive drives as one polyline: each drive's first point dropped where it repeats the
    last point of the drive before.

    A drive after a door crossing given up starts at the robot's pose estimate after that crossing's
    frame scan, which registration may have moved off the door's centre the drive before ended at:
    the polyline then jumps there, as the robot's estimate did (the jump is no travel of its plan).

    Parameters
    ----------
    paths : list of (p, 2) float
        In the order driven; empty ones are skipped.

    Returns
    -------
    (q, 2) float
        (0, 2) when no drive has a point.
    """
    drives = [np.asarray(p, dtype=float).reshape(-1, 2) for p in paths]
    drives = [p for p in drives if len(p)]
    if not drives:
        return np.zeros((0, 2))
    joined = [drives[0]]
    for p in drives[1:]:
        same = np.allclose(joined[-1][-1], p[0], rtol=0.0, atol=1e-9)
        joined.append(p[1:] if same else p)
    return np.vstack(joined)


def resolve_scene(
    spec: Any,
    start: Any,
    config: EnvConfig,
    rng: np.random.Generator,
    cache: dict[str, Scene] | None = None,
) -> Scene:
    """The scene an episode runs in, with its start checked against the true building.

    Parameters
    ----------
    spec : str, Path, Scene or FloorPlan
        Anything :func:`scenes.load_scene` takes, a Scene, a FloorPlan, or ``"generated"`` (a fresh
        storey drawn from ``rng`` with ``config.generator``).
    start : (2,) or (3,) float, optional
        Replaces the scene's start.
    config : EnvConfig
    rng : numpy.random.Generator
    cache : dict, optional
        Scenes loaded by name, reused.

    Raises
    ------
    ConfigError
        ``spec`` is of no known kind.
    InvalidPoseError
        The start is not free floor (the caller's mistake, checked as a simulator checks where a
        robot is put down).
    """
    cache = {} if cache is None else cache
    if isinstance(spec, os.PathLike) and not isinstance(spec, Path):
        spec = Path(os.fspath(spec))
    if start is not None:
        given = start
        try:
            # Numbers, not what numpy turns into them: "1.5" and True were taken as 1.5 and 1.0.
            if isinstance(start, (str, bytes)) or not all(
                isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in start
            ):
                raise TypeError
            start = np.asarray(start, dtype=float)
        except (TypeError, ValueError, OverflowError):  # 10**400 overflows
            start = np.full(1, np.nan)
        if start.shape not in ((2,), (3,)) or not np.isfinite(start).all():
            shown = repr(given)[:80]
            raise ConfigError(f"options['start'] must be 2 or 3 finite numbers in metres (x, y[, z]), got {shown}")
        if np.abs(start).max() > MAX_ORIGIN_DISTANCE:  # where no storey lies (scenes.limits), and 1e308 overflows
            raise ConfigError(
                f"options['start'] must lie within {MAX_ORIGIN_DISTANCE:,.0f} m of the origin, as every storey "
                f"does, got {repr(given)[:80]}"
            )
    if isinstance(spec, Scene):
        scene = spec
    elif isinstance(spec, FloorPlan):
        scene = load_scene(spec)
    elif isinstance(spec, (str, Path)) and str(spec) == "generated":
        seed = int(rng.integers(0, 2**31 - 1))
        # The scene the generator validated its plan on, with the plan's metadata.
        scene = generate_storey(seed, config.generator)[1]
    elif isinstance(spec, (str, Path)):
        key = str(spec)
        if key not in cache:
            try:
                cache[key] = load_scene(key, **config.scene_options)
            except TypeError as exc:  # an option the kind of source does not take (units on a plan)
                raise ConfigError(f"scene_options: {exc}") from None
        scene = cache[key]
    else:
        raise ConfigError(f"options['scene'] must be a scene name, path, Scene or FloorPlan, got {type(spec).__name__}")
    if start is not None:
        scene = copy.copy(scene)  # the cached scene keeps its own start
        scene.start = start
    xy = scene.start[:2]
    if start is not None and len(start) == 3:
        floor = scene.floor_height_at(xy)
        if abs(float(start[2]) - floor) > START_HEIGHT_TOLERANCE:
            # The robot stands on the floor: a start above it put the scanner above the ceiling,
            # and the error came from the region of interest, naming no start.
            raise InvalidPoseError(
                f"{scene.name}: start {np.round(start, 3).tolist()} is {float(start[2]) - floor:+.2f} m from the "
                f"floor under it (at z = {floor:.3f} m); give (x, y) and the floor's height is taken"
            )
    problem = start_problem(scene, config.robot.navigation.robot_radius)
    if problem is not None:
        raise InvalidPoseError(f"{scene.name}: {problem}")
    return scene


def start_problem(scene: Scene, radius: float) -> str | None:
    """Why a robot of ``radius`` metres cannot stand at the scene's start, or None: the start must
    be free floor of a room (``nbs scenes info`` says so as :func:`resolve_scene` refuses it)."""
    xy = scene.start[:2]
    inside = not scene.rooms or any(shapely.contains_xy(Polygon(r.polygon), *xy) for r in scene.rooms)
    if not inside or not point_is_free(scene, xy, float(scene.start[2]), radius):
        return (
            f"start {np.round(scene.start[:2], 3).tolist()} is not free floor "
            "(inside a wall or an object, or outside the building)"
        )
    return None


class Storey:
    """One storey scanned room by room (module docstring).

    Parameters
    ----------
    scene : Scene
        The true building (the simulator's and the meter's; the robot's decisions never read it).
    config : EnvConfig
        ``robot``, ``rooms``, ``max_scans`` and the evaluation's ``coverage_*`` are read.
    rng : numpy.random.Generator
        The only source of randomness.
    count_conversions : bool
        Count each scan's realised conversions (:attr:`StepOutcome.conversions`).

    Attributes
    ----------
    robot : Robot
    rooms : Rooms
        The robot's door memory and record of rooms.
    rules : RoomRules
        ``config.rooms``: when a room ends, its scan cap, the door searches.
    meter : CoverageMeter
    scans : list of ScanRecord
        The episode log, one record per scan.
    door_events : list of dict
        ``detected`` (with ``exterior``: it opens onto the outside, and is not crossed by default),
        ``crossed`` and ``abandoned`` (with its ``reason``) events, in order.
    room_ends : list of dict
        One per room completed, in order: the robot's ``room`` number, its ``scans``, the area of
        its RoI (``roi_m2``) and the ``reason`` it ended: ``"gain"``, ``"declared"``, ``"cap"``, ``"no
        NVP"`` or ``"earlier room"`` (no NVP, and at least :data:`EARLIER_ROOM_SHARE` of the RoI its
        scans outline lies in rooms scanned before: the door was found inside a room whose RoI had
        already reached beyond it). A ``"no NVP"`` end also has ``standing_room``: the places of the
        RoI the robot reaches keeping only its radius clear (0: its measured floor holds no footprint
        of the robot, as in a stack room whose aisles are narrower).
    wall_searches : list of dict
        One per search scan (``config.rooms.wall_search.scans`` > 0), in order: the index of
        its ``scan``, the robot's ``room`` number and the ``kind`` of stop
        (:class:`~nbs_env.planning.rooms.SearchStop`; ``"door"``: a scan toward a door of the room no route
        reaches, taken once no other door is left).
    paths : list of (p, 2) float
        The planned paths driven, in the robot's map frame: ``paths[j]`` is ``scans[j + 1].path``,
        the drive to scan j + 1 (door crossings through their approach and the rooms on the way),
        and a last entry when the episode ended after a drive that took no scan (a door crossing
        whose frame scan measured no room beyond it). Their lengths add up to :attr:`path_length`
        (but for a jump :func:`join_paths` keeps after such a crossing).
    scan_log : list of ScanPoints
        Every scan as measured, when ``config.keep_scans`` (else empty).
    complete : bool
        The storey is done: the current room is complete and no detected door is left to reach.
    """

    def __init__(
        self, scene: Scene, config: EnvConfig, rng: np.random.Generator, count_conversions: bool = False
    ) -> None:
        self.scene = scene
        self.config = config
        self.count_conversions = count_conversions
        self.rules = config.rooms
        self.robot = Robot(scene, config.robot, rng)
        self.rooms = Rooms(config.robot, config.rooms)
        self.meter = (
            CoverageMeter(
                scene,
                config.coverage_spacing,
                config.coverage_radius,
                density_weight=config.robot.scanner.density_weight,
                density_radius=config.quality.density_radius,
            )
            if config.coverage_meter
            else None
        )
        # The robot's own account of the surface it sensed (reward.kind="mapped"): its Structure
        # voxels, summed over the rooms' grids as each scan changed them.
        self.mapped_voxels = 0
        self._mapped_at: tuple[int, int] = (-1, 0)  # (room, its Structure voxels after the last scan)
        structural = np.isin(np.asarray(scene.face_labels), [int(c) for c in STRUCTURAL_CLASSES])
        self.structure_area = float(np.asarray(scene.mesh.area_faces)[structural].sum())
        self.scans: list[ScanRecord] = []
        self.door_events: list[dict[str, Any]] = []
        self.room_ends: list[dict[str, Any]] = []
        self.paths: list[np.ndarray] = []
        # Drives since the last scan, joined into the next scan's path (a crossing given up after
        # its drive leaves one here).
        self._driven: list[np.ndarray] = []
        self.complete = False
        self.new_room = True
        self.step_scans: list[tuple[np.ndarray, np.ndarray]] = []
        self.scan_log: list[ScanPoints] = []
        self.wall_searches: list[dict[str, Any]] = []
        self._record(self.robot.scan(), door=False)
        self.advance()

    # ------------------------------------------------------------------ state
    @property
    def open(self) -> bool:
        """The episode goes on: the storey is not complete and the scan budget is not spent."""
        return not self.complete and len(self.scans) < self.config.max_scans

    @property
    def plan(self) -> Plan:
        """The robot's plan for the next decision (NVPs and predicted gains)."""
        return self.robot.plan()

    @property
    def room(self) -> int:
        """The robot's number of the room it is in."""
        return self.rooms.current

    @property
    def rooms_done(self) -> int:
        """How many rooms were completed."""
        return len(self.rooms.done)

    @property
    def path_length(self) -> float:
        """Metres driven."""
        return self.robot.path_length

    def gain_rule_done(self, fraction: float | None = None) -> bool:
        """Whether the robot's own gain rule (METHOD §7) would end the current room now.

        Parameters
        ----------
        fraction : float, optional
            The completion fraction to read the rule at, in [0, 1); None (the default):
            ``rooms.completion_fraction``. A behaviour-cloning teacher that ends rooms at another
            fraction (``greedy:stop=F``) asks with its own.

        Returns
        -------
        bool
            True when no NVP predicts ``rooms.completion_fraction`` of the room's structural voxels;
            False once the episode is over and when the robot predicts no gains
            (``robot.predict_gains=False``: the rule has nothing to read). With
            ``rooms.completion="gain"`` the session ends such a room itself; with ``"policy"`` it is what
            the greedy (and the behaviour-cloning teacher) declares by. Reads the robot's plan
            only, never ground truth.
        """
        robot = self.robot
        if fraction is None:
            fraction = self.rules.completion_fraction
        elif not 0.0 <= fraction < 1.0:
            raise ValueError(f"fraction is a share in [0, 1), got {fraction}")
        return self.open and robot.config.predict_gains and self.plan.gain_below(fraction)

    def coverage_pct(self) -> float:
        """True structural surface sensed, % of the storey's (evaluation side); NaN without the
        meter (``config.coverage_meter=False``)."""
        return float("nan") if self.meter is None else self.meter.percent()

    @property
    def mapped_pct(self) -> float:
        """The surface the robot labelled Structure, one voxel face per Structure voxel, in % of
        the storey's structural surface (the area of the mesh's floor, ceiling and wall faces).

        The robot's own account (its labels, not ground truth) put on the scale of
        :meth:`coverage_pct`; the normaliser is the one figure of the true building it reads, a
        constant of the episode. Over 100 where walls are thicker than a voxel layer."""
        size = self.config.robot.voxel_size
        return 100.0 * self.mapped_voxels * size * size / max(self.structure_area, 1e-9)

    def room_models(self, current: bool = True) -> list[RoomModel]:
        """The recovered model of every room completed, and of the current one (``current``)."""
        rooms = self.rooms
        models = list(rooms.models)
        if current and rooms.current not in rooms.done:
            model = self.robot.belief.model(rooms.current)
            if model is not None:
                models.append(model)
        return models

    def view(self) -> BeliefView:
        """What the robot believes now (see :class:`~nbs_env.observation.BeliefView`); the plan's
        slots are padding once the episode is over."""
        robot = self.robot
        k = robot.config.navigation.max_candidates
        xy, length, mask = np.zeros((k, 2)), np.zeros(k), np.zeros(k, dtype=bool)
        gains, share = np.zeros(k, dtype=np.int64), np.zeros(k)
        belief = robot.belief
        labels = belief.grid.labels if belief.grid is not None else None
        if self.open:
            planned = robot.plan()
            cands = planned.candidates
            xy[: cands.count], length, mask = cands.points, cands.path_length.astype(float), cands.mask
            gains, share = planned.gains.copy(), planned.gain_share()
            labels = planned.labels if planned.labels is not None else labels
        return BeliefView(
            pose=robot.pose,
            room=self.rooms.current,
            new_room=self.new_room,
            scans=list(self.step_scans),
            grid=belief.grid,
            labels=labels,
            roi=belief.roi,
            se=belief.se,
            frontier=list(belief.frontier),
            candidates_xy=xy,
            path_length=length,
            mask=mask,
            gains=gains,
            gain_share=share,
            scanner=robot.config.scanner,
            scans_in_room=robot.scans_in_room,
            rooms_done=len(self.rooms.done),
            scans_taken=len(self.scans),
            doors_waiting=np.array(
                [d.centre[:2] for d in self.rooms.doors if self.rooms.door_open(d)], dtype=float
            ).reshape(-1, 2),
        )

    # ------------------------------------------------------------------ decisions
    def begin_step(self) -> None:
        """Start a decision step: this step's registered scans and the new-room flag start afresh."""
        self.step_scans = []
        self.new_room = False

    def scan_at(self, index: int) -> StepOutcome:
        """Drive to NVP ``index`` of the plan and scan there, then :meth:`advance`.

        Raises
        ------
        IndexError
            ``index`` is not a real NVP.
        RuntimeError
            The episode is over.
        """
        self._check_open()
        before = self._before()
        report = self.robot.move_to(index, count_conversions=self.count_conversions)
        self._driven.append(report.path)
        self._record(report, door=False)
        self.advance()
        return self._outcome(before, report.conversions)

    def room_done(self) -> StepOutcome:
        """The agent declares the room complete (completion="policy"): :meth:`advance` to the next room."""
        self._check_open()
        before = self._before()
        self.advance(done=True)
        return self._outcome(before, 0)

    def advance(self, done: bool = False) -> None:
        """Room completion (METHOD §7) and the door hand-over (METHOD §8), until a room is open.

        ``done``: the agent declared the room complete (completion="policy")."""
        robot = self.robot
        while len(self.scans) < self.config.max_scans and (reason := self._room_complete(done)) is not None:
            done = False  # the declaration was for the room the robot was in
            if reason in ("gain", "declared") and self._wall_search():
                # The search scan may open the room again (the gain rule says so); otherwise the
                # agent's declaration stands, so that completion="policy" scans as "gain" does.
                done = reason == "declared" and robot.plan().gain_below(self.rules.completion_fraction)
                continue
            if reason == "no NVP" and robot.belief.earlier_share() >= EARLIER_ROOM_SHARE:
                reason = "earlier room"
            roi = robot.belief.roi
            area = 0.0 if roi is None else float(Polygon(roi.polygon).area)
            end = {"room": self.rooms.current, "scans": robot.scans_in_room, "reason": reason, "roi_m2": round(area, 2)}
            if reason == "no NVP":
                end["standing_room"] = self.rooms.standing_room(robot)
            self.room_ends.append(end)
            before = len(self.rooms.doors)
            self.rooms.finish_room(robot)
            for door in self.rooms.doors[before:]:
                self.door_events.append(
                    {
                        "event": "detected",
                        "scan": len(self.scans),
                        "room": door.found_in_room,
                        "centre": door.centre[:2].round(3).tolist(),
                        "width": round(float(door.width), 3),
                        "exterior": bool(door.exterior),
                        "covered": None if np.isnan(door.covered) else round(float(door.covered), 3),
                    }
                )
            if not self._enter_next_room():
                return

    # ------------------------------------------------------------------ inside
    def _room_complete(self, done: bool) -> str | None:
        """Why the current room is done, or None: ``"gain"`` (the gain rule), ``"declared"`` (the
        agent's declaration), ``"cap"`` (the room's scan cap) or ``"no NVP"``."""
        robot, rules = self.robot, self.rules
        if robot.scans_in_room >= rules.max_scans_per_room:
            return "cap"
        planned = robot.plan()
        if planned.count == 0:
            return "no NVP"
        if rules.completion == "gain":
            return "gain" if planned.gain_below(rules.completion_fraction) else None
        return "declared" if done else None

    def _wall_search(self) -> bool:
        """Before the hand-over: scan from the NVP that views most of the room's wall no stop viewed
        frontally (:meth:`Rooms.wall_search`), at most ``rules.wall_search.scans`` times a room and
        never past the room's cap; whether it scanned."""
        robot, rules = self.robot, self.rules
        room = self.rooms.current
        if sum(search["room"] == room for search in self.wall_searches) >= rules.wall_search.scans:
            return False
        if robot.scans_in_room >= rules.max_scans_per_room:
            return False
        stop = self.rooms.wall_search(robot)
        if stop is None:
            return False
        self._search_scan(stop)
        return True

    def _door_search(self) -> bool:
        """With no door left that a route reaches: scan to come nearer to a door of the current room
        that none reaches (:meth:`Rooms.door_search`), at most ``rules.wall_search.scans`` times a
        room and never past the room's cap or the budget; whether it scanned."""
        robot, rules, rooms = self.robot, self.rules, self.rooms
        if not rules.wall_search.doors:
            return False
        room = rooms.current
        searches = sum(s["room"] == room and s["kind"] == "door" for s in self.wall_searches)
        if searches >= rules.wall_search.scans or robot.scans_in_room >= rules.max_scans_per_room:
            return False
        if len(self.scans) >= self.config.max_scans:
            return False
        here = robot.pose[:2, 3]
        doors = [d for d in rooms.doors if d.found_in_room == room and rooms.door_open(d)]
        for door in sorted(doors, key=lambda d: float(np.linalg.norm(d.centre[:2] - here))):
            stop = rooms.door_search(robot, door)
            if stop is not None:
                self._search_scan(stop)
                return True
        return False

    def _search_scan(self, stop: SearchStop) -> None:
        """Scan from a search stop and log it in :attr:`wall_searches`."""
        room, robot = self.rooms.current, self.robot
        if stop.nvp is not None:
            report = robot.move_to(stop.nvp, count_conversions=self.count_conversions)
        else:
            report = robot.scan_from(stop.point, stop.path, stop.length, count_conversions=self.count_conversions)
        self._driven.append(report.path)
        self._record(report, door=False)
        self.wall_searches.append({"scan": len(self.scans) - 1, "room": room, "kind": stop.kind})

    def _enter_next_room(self) -> bool:
        """Cross the nearest reachable unvisited door and scan the next room; False when the storey
        is complete or the budget is spent."""
        robot, rooms = self.robot, self.rooms
        while True:
            k = rooms.next_door(robot)
            if k is None and self._door_search():
                continue
            if k is None:
                for door in rooms.abandon_unreachable():
                    self._abandoned(door)
                self.complete = True
                self._end_drives()
                return False
            if len(self.scans) >= self.config.max_scans:
                self._end_drives()
                return False
            door = rooms.doors[k]
            try:
                report = self._cross_door(k)
            except UnreachableDoorError:
                self._abandoned(door)
                continue
            self.door_events.append(
                {
                    "event": "crossed",
                    "scan": len(self.scans),
                    "centre": door.centre[:2].round(3).tolist(),
                    "into_room": rooms.current,
                }
            )
            self._record(report, door=True)
            self.new_room = True
            return True

    def _cross_door(self, k: int) -> StepReport:
        """Drive to door ``k``, stand under its frame, and take the first scan of the room beyond.

        Raises
        ------
        UnreachableDoorError
            No route reaches it, or its frame scan measured no room beyond it; the door is given up.
        """
        robot, rooms = self.robot, self.rooms
        door = rooms.doors[k]
        path, length, reason = rooms.route(robot, door)
        if path is None or length is None:
            rooms.give_up(door, str(reason))
            raise UnreachableDoorError(f"door {k} at {door.centre[:2].round(2).tolist()} cannot be reached: {reason}")
        # The door leads out of the room it was found in: the robot enters the room beyond.
        into = door.outward
        robot.drive_to(door.centre[:2], float(np.arctan2(into[1], into[0])), length)
        # Driven whatever comes of the frame scan: a crossing given up below still moved the robot.
        self._driven.append(path)
        room, entrance = rooms.enter(door)
        robot.enter_room(room, entrance, exclude=[m.polygon for m in rooms.models])
        try:
            return robot.scan(length, 0, keep_direction=into)
        except RoIError as exc:
            # The frame scan measured no floor or ceiling beyond the door (a false door onto a wall
            # just behind it, a shaft): there is no room to scan there. The door is given up and the
            # storey goes on to the next one; the scan, taken, is in S(t) but not in the episode log.
            rooms.give_up(door, f"no room measured beyond it ({exc})")
            raise UnreachableDoorError(
                f"door {k} at {door.centre[:2].round(2).tolist()}: no room measured beyond it ({exc})"
            ) from exc

    def _abandoned(self, door: KnownDoor) -> None:
        self.door_events.append(
            {
                "event": "abandoned",
                "scan": len(self.scans),
                "room": door.found_in_room,
                "centre": door.centre[:2].round(3).tolist(),
                "reason": door.reason or "no route",
            }
        )

    def _take_driven(self) -> np.ndarray:
        """(p, 2) float: the drives since the last scan as one polyline (:func:`join_paths`);
        :attr:`_driven` is emptied."""
        path = join_paths(self._driven)
        self._driven = []
        return path

    def _end_drives(self) -> None:
        """The episode ends: a drive that took no scan (a crossing given up) still goes on :attr:`paths`."""
        if self._driven:
            path = self._take_driven()
            if len(path):
                self.paths.append(path)

    def _record(self, report: StepReport, door: bool) -> None:
        robot = self.robot
        path = self._take_driven()
        if self.scans:
            self.paths.append(path)
        self.step_scans.append((report.world_points, report.estimated_pose[:3, 3].copy()))

        meter = self.meter

        def evaluate() -> float:
            t = time.perf_counter()
            if meter is not None:
                meter.add(report.world_points, report.estimated_pose[:3, 3])
            return time.perf_counter() - t

        # The meter (ground truth, not the robot's) shares nothing with the plan: on more than one
        # core it runs beside it, its compiled query free of the GIL the plan's numpy holds.
        measured = threads.beside(evaluate) if meter is not None else None
        # Planning for the next decision belongs to this step: it runs now, not at the next call.
        planned = robot.plan()
        evaluation = 0.0 if measured is None else measured.result()
        self._count_mapped()
        times = {**{s: 0.0 for s in STAGES}, **report.times, "planning": planned.seconds, "evaluation": evaluation}
        processing = sum(times[s] for s in STAGES if s != "scan")
        # The first scan has no S(t) to register to: registration then reports no overlap.
        reg = report.registration if report.registration is not None and len(self.scans) else None
        self.scans.append(
            ScanRecord(
                scan=len(self.scans),
                room=self.rooms.current,
                door=door,
                true_position=report.true_pose[:3, 3].copy(),
                estimated_position=report.estimated_pose[:3, 3].copy(),
                predicted_gain=int(report.predicted_gain),
                path_length=robot.path_length,
                structure_sensed_pct=self.coverage_pct(),
                processing_time=processing,
                acquisition_time=report.acquisition_time,
                points=report.points,
                structure_points=report.belief.structure_points,
                registration_error=robot.registration_error(),
                times=times,
                registration_refused=report.registration.reason
                if report.registration is not None and not report.registration.accepted
                else "",
                estimated_pose=report.estimated_pose.copy(),
                registration_overlap=None if reg is None else float(reg.overlap),
                registration_fitness=None if reg is None else float(reg.fitness),
                path=path,
            )
        )
        if self.config.keep_scans and report.scan is not None:
            scan = report.scan
            # uint16 indices where the pattern fits (any step above 0.0055°): 10 bytes a point.
            index = np.uint16 if max(scan.config.n_rows, scan.config.n_cols) <= 65535 else np.int32
            self.scan_log.append(
                ScanPoints(
                    np.asarray(scan.points, dtype=np.float32),
                    np.asarray(scan.rows, dtype=index),
                    np.asarray(scan.cols, dtype=index),
                    report.estimated_pose.copy(),
                )
            )

    def _count_mapped(self) -> None:
        """Add the last scan's change of the current room's Structure voxels to :attr:`mapped_voxels`."""
        room = self.rooms.current
        now = int(np.count_nonzero(self.robot.belief.grid.labels == VoxelLabel.STRUCTURE))
        last_room, last = self._mapped_at
        self.mapped_voxels += now - (last if room == last_room else 0)
        self._mapped_at = (room, now)

    def _check_open(self) -> None:
        if not self.open:
            raise RuntimeError("the episode is over: the storey is complete or the scan budget is spent")

    def _before(self) -> tuple[int, float, float, int, float]:
        plan = self.robot.plan()
        return len(self.scans), self.robot.path_length, self.coverage_pct(), plan.structural_voxels, self.mapped_pct

    def _outcome(self, before: tuple[int, float, float, int, float], conversions: int) -> StepOutcome:
        scans, metres, pct, structural, mapped = before
        return StepOutcome(
            scans=len(self.scans) - scans,
            metres=self.robot.path_length - metres,
            coverage_gain=self.coverage_pct() - pct,
            conversions=conversions,
            structural_voxels=structural,
            mapped_gain=self.mapped_pct - mapped,
        )
