"""The mobile scanner, with no gymnasium import: move, scan, register, perceive and map; doors.

The :class:`Robot` couples the simulator (the true scene, the true pose, the scanner, odometry) with
the robot's estimator and belief (its pose estimate, S(t), the current room's RoI and V(t)). Everything
the robot decides from is in its belief; the simulator's state is kept in attributes named ``true_*``.

- :meth:`Robot.scan` and :meth:`Robot.move_to`: one cycle of the method in a room (METHOD §1-6):
  drive (with drift), scan the true building, register, update the belief.
- :meth:`Robot.plan`: the next decision's NVPs and gains, from
  :func:`nbs_env.planning.planner.plan` (a query: it never writes into the belief).
- The door memory (METHOD §8): :meth:`Robot.finish_room` detects the doors of the room just done,
  :meth:`Robot.next_door` picks the nearest unvisited one, :meth:`Robot.cross_door` drives there,
  stands under its frame and takes the first scan of the next room.

When a room is done is the storey session's decision (:mod:`nbs_env.storey`), not the robot's.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace

import numpy as np
from shapely.geometry import Point, Polygon

from nbs_env.belief import BeliefUpdate, RoomBelief, RoomModel
from nbs_env.config import OdometryConfig
from nbs_env.errors import UnreachableDoorError
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.cloud import AccumulatedCloud
from nbs_env.perception.doors import detect_doors
from nbs_env.perception.roi import RoIError
from nbs_env.planning.navigation import Candidates, Geodesic, Passage, TraversabilityMap, candidates, geodesic
from nbs_env.planning.planner import (
    Plan,
    blocked_directions,
    plan,
    sensor_positions,
    traversable_floor,
    unobservable_after,
    without_unobservable,
)
from nbs_env.planning.visibility import VisibilityModel
from nbs_env.planning.wall_search import approach_position, search_position, unviewed_wall
from nbs_env.sensing.odometry import Odometry
from nbs_env.sensing.pose import planar, pose_error, yaw_of
from nbs_env.sensing.registration import RegistrationResult, level_from_floor, register
from nbs_env.sensing.scanner import Scan, Scanner
from nbs_env.settings import RobotConfig
from scenes import Scene

__all__ = ["APPROACH_DEPTH", "BEYOND_DOOR", "SAME_DOOR", "KnownDoor", "Robot", "SearchStop", "StepReport"]

#: How far in front of the frame (metres) an approach is searched for when the preferred point is
#: not free: any free cell on the robot's side from which it can drive straight through the opening.
APPROACH_DEPTH = 1.5
#: Doors detected closer than this (metres) are one door seen from both sides.
SAME_DOOR = 0.6
#: A door leads into a scanned room when the point this far (metres) beyond its frame lies in it.
BEYOND_DOOR = 0.6


@dataclass
class KnownDoor:
    """A door the robot detected (its own estimate), and whether it went through it."""

    centre: np.ndarray
    outward: np.ndarray
    width: float
    found_in_room: int
    visited: bool = False
    failed: bool = False
    entered_room: int | None = None
    exterior: bool = False
    covered: float = float("nan")
    reason: str | None = None


@dataclass(frozen=True)
class SearchStop:
    """Where a wall-search scan is taken (:meth:`Robot.wall_search`).

    Attributes
    ----------
    kind : str
        ``"view"`` (the NVP that views most of the unviewed wall), ``"approach"`` (no NVP views it;
        the NVP nearest to it), ``"narrow"`` (no NVP views it or comes near; a place reached
        keeping only the robot's radius clear views it) or ``"door"`` (:meth:`Robot.door_search`:
        nearer to a door no route reaches).
    nvp : int or None
        The plan's NVP index (``"view"``, ``"approach"``); None for ``"narrow"``.
    point : (2,) float
        Where the robot stands for the scan.
    path : (p, 2) float
        The route there.
    length : float
        Its length, metres.
    """

    kind: str
    nvp: int | None
    point: np.ndarray
    path: np.ndarray = field(repr=False)
    length: float


@dataclass(frozen=True)
class StepReport:
    """What one scan cycle did (``true_*`` fields are the simulator's, for evaluation only).

    ``path``: the planned (p, 2) polyline :meth:`Robot.move_to` drove (empty for other scans).
    ``conversions``: the voxels that were Occluded-structure before the move and are Structure
    after its scan (counted when :meth:`Robot.move_to` is asked to; 0 otherwise).
    ``scan``: the scan itself (its measured points in the scanner frame; its ``truth`` is the
    simulator's).
    """

    scan_index: int
    path_length: float
    predicted_gain: int
    estimated_pose: np.ndarray
    true_pose: np.ndarray
    registration: RegistrationResult | None
    belief: BeliefUpdate
    points: int
    acquisition_time: float
    times: dict[str, float]
    world_points: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 3)))
    scan: Scan | None = field(repr=False, default=None)
    path: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 2)))
    conversions: int = 0


class Robot:
    """The mobile scanner in a scene.

    Parameters
    ----------
    scene : Scene
        The true building (the simulator's; the robot's decisions never read it).
    config : RobotConfig
    rng : numpy.random.Generator
        The only source of randomness (noise, drift, tilt).
    """

    def __init__(self, scene: Scene, config: RobotConfig | None, rng: np.random.Generator) -> None:
        self.config = config or RobotConfig()
        self.rng = rng
        self._scanner = Scanner(scene, self.config.scanner)
        self._odometry = Odometry(
            OdometryConfig(0.0, 0.0, 0.0) if self.config.perfect_localisation else self.config.odometry, rng
        )
        self._floor_z = float(scene.start[2])
        # S(t) of the storey, ICP's target; without ICP it needs no normals.
        registration = self.config.registration
        self.cloud = AccumulatedCloud(
            registration.voxel_size, normals=not self.config.perfect_localisation, rooms=False
        )
        self.belief = RoomBelief(self.config.scanner, voxel_size=self.config.voxel_size, roi_config=self.config.roi)
        self.visited: list[np.ndarray] = []
        self.stops: list[np.ndarray] = []
        self.path_length = 0.0
        #: Metres driven since the last accepted registration: a refused scan keeps its odometry
        #: pose, whose drift the next scan's correction gates must still allow for.
        self.unregistered_m = 0.0
        start = np.asarray(scene.start[:2], dtype=float)
        self.true_pose = self._odometry.true_sensor_pose(start, 0.0, self._floor_z, self.config.scanner.height)
        # The robot knows where it starts (the origin of its map); it does not know its tilt.
        self.pose = planar(start[0], start[1], 0.0, self._floor_z + self.config.scanner.height)
        self._plan: Plan | None = None
        self._door_map: tuple[TraversabilityMap, Geodesic] | None = None
        #: The door the robot came into the current room by (None in the first room).
        self.entrance: Passage | None = None
        self.doors: list[KnownDoor] = []
        self.room_index = 0
        self.rooms_done: list[int] = []
        self.room_polygons: dict[int, Polygon] = {}
        self.room_models: list[RoomModel] = []

    @property
    def scans_in_room(self) -> int:
        """Scans taken in the current room (its door-frame scan included)."""
        return len(self.stops)

    # ------------------------------------------------------------------ the cycle
    def scan(
        self, path_length: float = 0.0, predicted_gain: int = 0, keep_direction: np.ndarray | None = None
    ) -> StepReport:
        """Scan from where the robot truly is, register, and update the belief."""
        times: dict[str, float] = {}
        t = time.perf_counter()
        scan: Scan = self._scanner.scan(self.true_pose, self.rng)
        times["scan"] = time.perf_counter() - t
        result = None
        t = time.perf_counter()
        if self.config.perfect_localisation:
            self.pose = self.true_pose.copy()
        else:
            if not len(self.cloud):
                # S(t)'s frame is the first scan's: level it by its floor (level_from_floor).
                self.pose = level_from_floor(scan.points, self.pose, self.config.scanner.height)
            travelled = self.unregistered_m + path_length
            result = register(scan.points, self.pose, self.cloud, self.config.registration, travelled=travelled)
            self.pose = result.pose
            self.unregistered_m = 0.0 if result.accepted else travelled
        times["registration"] = time.perf_counter() - t
        world = scan.to_world(self.pose)
        world.flags.writeable = False  # shared by S(t), the belief's RoI scan and the step's report
        self.cloud.add(world, self.pose[:3, 3], room=self.room_index, pose=None if result is None else self.pose)
        update = self.belief.add_scan(scan, self.pose, keep_direction, world)
        nav = self.config.navigation
        self.belief.cover(self.pose[:2, 3], nav.robot_radius + nav.safety_distance + 2 * self.config.voxel_size)
        times.update(update.times)
        self.visited.append(self.pose[:2, 3].copy())
        self.stops.append(self.pose[:3, 3].copy())
        self._plan = None
        self._door_map = None
        return StepReport(
            scan_index=len(self.stops) - 1,
            path_length=path_length,
            predicted_gain=predicted_gain,
            estimated_pose=self.pose.copy(),
            true_pose=self.true_pose.copy(),
            registration=result,
            belief=update,
            points=len(scan),
            acquisition_time=scan.acquisition_time,
            times=times,
            world_points=world,
            scan=scan,
        )

    def plan(self) -> Plan:
        """The next decision's NVPs and predicted gains, from the robot's own belief (kept until the
        next scan)."""
        if self._plan is None:
            passages = () if self.entrance is None else (self.entrance,)
            self._plan = plan(self.belief, self.pose, self.stops, self.visited, self.config.planning, passages)
        return self._plan

    def move_to(self, index: int, count_conversions: bool = False) -> StepReport:
        """Drive the planned path to NVP ``index`` and scan there.

        ``count_conversions``: count the Occluded-structure voxels the scan turned into Structure
        (:attr:`StepReport.conversions`).
        """
        planned = self.plan()
        cands = planned.candidates
        if not (0 <= index < cands.count):
            raise IndexError(f"candidate {index} is not valid: {cands.count} candidates")
        watched = self.belief.occluded_structure_centres() if count_conversions else None
        roi = self.belief.roi
        grid = self.belief.grid
        expected, _ = unobservable_after(
            planned, index, roi.floor_z, self.config.scanner, self.config.voxel_size, grid.speculative if grid else None
        )
        path = cands.path(index)
        length = float(cands.path_length[index])
        report = self._drive_and_scan(cands.points[index], path, length, int(planned.gains[index]))
        if len(expected):
            missed = expected[self.belief.labels_at(expected) == VoxelLabel.OCCLUDED_STRUCTURE]
            self.belief.unobservable = np.concatenate([self.belief.unobservable, missed])
        return replace(report, path=path, conversions=self._converted(watched))

    def _drive_and_scan(self, point: np.ndarray, path: np.ndarray, length: float, predicted_gain: int) -> StepReport:
        """Drive the planned ``path`` (``length`` metres) to ``point``, facing along its last leg, and scan."""
        heading = path[-1] - path[-2] if len(path) >= 2 else np.array([1.0, 0.0])
        self._drive(point, float(np.arctan2(heading[1], heading[0])), length)
        return self.scan(length, predicted_gain)

    def _converted(self, watched: np.ndarray | None) -> int:
        """How many of the ``watched`` Occluded-structure voxel centres are Structure now (0 for None)."""
        if watched is None or not len(watched):
            return 0
        return int(np.count_nonzero(self.belief.labels_at(watched) == VoxelLabel.STRUCTURE))

    def _drive(self, target_xy: np.ndarray, yaw: float, distance: float) -> None:
        """Execute a planned motion: the true robot moves by the planned displacement from where it
        truly is, and odometry reports it with drift."""
        planned = planar(float(target_xy[0]), float(target_xy[1]), yaw, self.pose[2, 3])
        motion = np.linalg.inv(planar(*self.pose[:2, 3], yaw_of(self.pose))) @ planned
        true_from = self.true_pose
        true_planar = planar(*true_from[:2, 3], yaw_of(true_from)) @ motion
        true_to = self._odometry.true_sensor_pose(
            true_planar[:2, 3], yaw_of(true_planar), self._floor_z, self.config.scanner.height
        )
        self.pose = self._odometry.drive(self.pose, true_from, true_to, distance)
        self.true_pose = true_to
        self.path_length += distance

    # ------------------------------------------------------------------ doors and rooms (METHOD §8)
    def finish_room(self) -> list[KnownDoor]:
        """Detect the doors of the room just completed and add the new ones to the storey's list."""
        belief = self.belief
        # Every face of the RoI, not only those classified SE: a wall the classifier gave to clutter
        # (a shelf before it, a short face by a corner) still has its doors, and the see-through test
        # tells a door from a shadow on any face (generated:10000000-19, fast: 3.6% of the rooms
        # were never entered behind doors on faces classified not SE).
        # Under the sky every opening has the sky beyond it: inside cannot be told from outside.
        roofed = belief.roi is None or belief.roi.has_ceiling
        found = detect_doors(
            belief.roi.wall_faces if belief.roi is not None else belief.se_faces,
            [(s.points, s.origin) for s in belief.scans],
            self.config.doors,
            no_return=[s.near_directions for s in belief.scans] if roofed else None,
            min_range=self.config.scanner.min_range,
        )
        polygon = Polygon(belief.roi.polygon) if belief.roi is not None else None
        if polygon is not None:
            self.room_polygons[self.room_index] = polygon
        for door in found:
            known = next((d for d in self.doors if np.linalg.norm(d.centre[:2] - door.centre[:2]) < SAME_DOOR), None)
            if known is not None:
                continue  # a door seen from both sides is one door
            self.doors.append(
                KnownDoor(
                    door.centre,
                    door.outward,
                    door.width,
                    self.room_index,
                    exterior=door.exterior,
                    covered=door.covered,
                )
            )
        # A door into a room already scanned needs no crossing: its far side is known.
        for known in self.doors:
            if known.visited:
                continue
            beyond = Point(*(known.centre[:2] + BEYOND_DOOR * known.outward))
            for room, poly in self.room_polygons.items():
                if room != known.found_in_room and poly.contains(beyond):
                    known.visited, known.entered_room = True, room
        model = self.room_model()
        if model is not None:
            self.room_models.append(model)
        self.rooms_done.append(self.room_index)
        return list(self.doors)

    def wall_search(self) -> SearchStop | None:
        """Where to scan for the room's wall no stop viewed frontally
        (:mod:`nbs_env.planning.wall_search`), in this order: the NVP that views the most of that
        wall (``"view"``); the NVP nearest to it (``"approach"``); a place that views it among
        those reached keeping only the robot's radius clear (``"narrow"``, when
        ``config.wall_search.narrow``). None when every wall stretch as wide as a door was viewed,
        or none of the three finds a place. Reads the robot's belief only; :meth:`search_scan`
        drives there and scans.
        """
        belief = self.belief
        if belief.roi is None or belief.grid is None or not self.stops:
            return None
        planned = self.plan()
        if planned.count == 0:
            return None
        model = planned.model
        if not isinstance(model, VisibilityModel):
            # Lines of sight through V(t) as the paper's gain model draws them, whatever model
            # predicts the gains (or none, when a policy turned the gains off).
            grid = belief.grid
            labels = without_unobservable(grid, belief.unobservable)
            model = VisibilityModel(labels, grid.origin, grid.voxel_size, self.config.gain)
        scanner = self.config.scanner
        config = self.config.wall_search

        def sees(sensors: np.ndarray, targets: np.ndarray) -> np.ndarray:
            return model.sees(sensors, targets, scanner)

        scanned = [poly for room, poly in self.room_polygons.items() if room != self.room_index]
        walls = unviewed_wall(belief.roi, self.stops, sees, scanned, config, self.config.doors.min_width, scanner)
        n = planned.count
        sensors = sensor_positions(planned.candidates.points[:n], belief.roi.floor_z, scanner)
        path_length = planned.candidates.path_length[:n]
        cands = planned.candidates
        index = search_position(walls, sensors, path_length, sees, config, scanner)
        if index is not None:
            return SearchStop("view", index, cands.points[index], cands.path(index), float(path_length[index]))
        index = approach_position(walls, sensors, path_length, np.asarray(self.stops, dtype=float), config)
        if index is not None:
            return SearchStop("approach", index, cands.points[index], cands.path(index), float(path_length[index]))
        if not config.narrow or not walls.target.any():
            return None
        narrow = self._narrow_candidates()
        if narrow.count == 0:
            return None
        sensors = sensor_positions(narrow.points, belief.roi.floor_z, scanner)
        lengths = narrow.path_length[: narrow.count]
        index = search_position(walls, sensors, lengths, sees, config, scanner)
        if index is None:
            return None
        return SearchStop("narrow", None, narrow.points[index], narrow.path(index), float(lengths[index]))

    def door_search(self, door: KnownDoor) -> SearchStop | None:
        """Where to scan so that ``door`` of the current room, which no route reaches, may be
        reached: the place (among those reached keeping the robot's radius clear) nearest to the
        door across floor not yet measured, when it is at least ``config.wall_search.approach``
        metres nearer so than every stop of the room (``"door"``). None when there is no such place.

        A door is found from afar: the floor in front of it may be unmeasured (furniture's shadow
        on the way), so no route reaches it, though the robot's map shows nothing in between. Floor
        not measured, holding no obstacle and leaving the robot's radius clear, counts as passable
        for the distance only; the robot still drives on measured floor. Reads the robot's belief.
        """
        belief = self.belief
        if belief.grid is None or belief.roi is None or not self.stops:
            return None
        tmap, _ = self._door_routes()
        side = 1.0 if np.dot(self.pose[:2, 3] - door.centre[:2], door.outward) > 0 else -1.0
        goal = door.centre[:2] + side * 0.5 * np.asarray(door.outward[:2], dtype=float)
        if not tmap.contains(goal[None])[0]:
            return None
        hopeful = tmap.free | (~tmap.obstacle & (tmap.clearance >= tmap.robot_radius))
        towards = geodesic(replace(tmap, free=hopeful), goal).distances
        near = self._narrow_candidates()
        if near.count == 0:
            return None

        def distance(xy: np.ndarray) -> np.ndarray:
            xy = np.asarray(xy, dtype=float).reshape(-1, 2)
            inside = tmap.contains(xy)
            out = np.full(len(xy), np.inf)
            if inside.any():
                cells = tmap.cell_of(xy[inside], "door search")
                out[inside] = towards[cells[:, 0], cells[:, 1]]
            return out

        d = distance(near.points)
        reach = distance(np.asarray(self.stops, dtype=float)[:, :2]).min()
        if not np.isfinite(d).any() or d.min() > reach - self.config.wall_search.approach + 1e-9:
            return None
        index = int(np.lexsort((near.path_length[: near.count], d))[0])
        return SearchStop("door", None, near.points[index], near.path(index), float(near.path_length[index]))

    def _narrow_candidates(self) -> Candidates:
        """Places the robot reaches keeping only its radius clear: the door routes' map, with no
        safety distance (the NVPs' margin can close a gap between furniture the robot fits through)."""
        tmap, route = self._door_routes()
        return candidates(tmap, self.pose[:2, 3], replace(self.config.navigation, safety_distance=0.0), route)

    def search_scan(self, stop: SearchStop, count_conversions: bool = False) -> StepReport:
        """Drive to a stop of :meth:`wall_search` or :meth:`door_search` and scan there."""
        if stop.nvp is not None:
            return self.move_to(stop.nvp, count_conversions=count_conversions)
        watched = self.belief.occluded_structure_centres() if count_conversions else None
        path = np.asarray(stop.path, dtype=float)
        report = self._drive_and_scan(np.asarray(stop.point, dtype=float), path, stop.length, 0)
        return replace(report, path=path, conversions=self._converted(watched))

    def room_model(self) -> RoomModel | None:
        """The current room's recovered model (None before its first scan)."""
        return self.belief.model(self.room_index)

    def door_open(self, door: KnownDoor) -> bool:
        """Whether ``door`` still waits to be crossed: not visited, not given up, and not an
        exterior door the robot leaves (``config.doors.cross_exterior``)."""
        return not (door.visited or door.failed or (door.exterior and not self.config.doors.cross_exterior))

    def next_door(self) -> int | None:
        """The nearest unvisited door the robot can reach, by its estimated travel, or None.

        Exterior doors are left (unless ``config.doors.cross_exterior``); a door that cannot be
        reached keeps the reason in :attr:`KnownDoor.reason` (see :meth:`abandon_unreachable`)."""
        best, best_length = None, np.inf
        for k, door in enumerate(self.doors):
            if not self.door_open(door):
                continue
            length, reason = self._route_length(door)
            door.reason = reason
            if length is not None and length < best_length:
                best, best_length = k, length
        return best

    def abandon_unreachable(self) -> list[KnownDoor]:
        """Mark every door still open that no route reaches as failed; returns them (with reasons)."""
        left = []
        for door in self.doors:
            if not self.door_open(door):
                continue
            door.failed = True
            door.reason = door.reason or "no route"
            left.append(door)
        return left

    def _room_route(self, target_room: int) -> list[KnownDoor] | None:
        """Doors already crossed that lead from the current room to ``target_room`` (breadth first)."""
        links = [d for d in self.doors if d.visited and d.entered_room is not None]
        queue: list[tuple[int, list[KnownDoor]]] = [(self.room_index, [])]
        seen = {self.room_index}
        while queue:
            room, route = queue.pop(0)
            if room == target_room:
                return route
            for d in links:
                for a, b in ((d.found_in_room, d.entered_room), (d.entered_room, d.found_in_room)):
                    if a == room and b not in seen:
                        seen.add(b)
                        queue.append((b, [*route, d]))
        return None

    def _route_length(self, door: KnownDoor) -> tuple[float | None, str | None]:
        """Travel to stand under ``door`` and why there is none: the geodesic to its approach in this
        room, else through rooms already scanned (straight legs between the doors on the way, an
        estimate)."""
        if door.found_in_room == self.room_index:
            found = self._approach(door)
            return (found[1], None) if found[0] is not None else (None, found[2])
        route = self._room_route(door.found_in_room)
        if route is None:
            return None, "no route through the rooms crossed to the room it was found in"
        legs = [self.pose[:2, 3], *[d.centre[:2] for d in route], door.centre[:2]]
        return float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(legs))), None

    def _approach(self, door: KnownDoor) -> tuple[np.ndarray | None, float | None, str]:
        """Where the robot starts its drive through ``door``, the travel to stand under the frame from
        here, and, when there is no approach, why.

        The approach is the free cell on the robot's side of the frame, within :data:`APPROACH_DEPTH`
        of it and in front of the opening (so that the last leg runs straight through it), that
        minimises the geodesic to it plus that last leg."""
        if self.belief.grid is None or self.belief.roi is None:
            return None, None, "no map of the room"
        tmap, route = self._door_routes()
        side = 1.0 if np.dot(self.pose[:2, 3] - door.centre[:2], door.outward) > 0 else -1.0
        normal = side * np.asarray(door.outward, dtype=float)
        along = np.array([-normal[1], normal[0]])
        step = tmap.voxel_size
        depth = np.arange(step, APPROACH_DEPTH + 1e-9, step)
        half = max(0.0, door.width / 2 - tmap.robot_radius)
        lateral = np.arange(-half, half + 1e-9, step) if half > 0 else np.zeros(1)
        dd, ll = np.meshgrid(depth, lateral, indexing="ij")
        points = door.centre[:2] + dd.reshape(-1, 1) * normal + ll.reshape(-1, 1) * along
        inside = tmap.contains(points)
        if not inside.any():
            return None, None, "the floor in front of it lies outside the room's map"
        points = points[inside]
        cells = tmap.cell_of(points, "door approach")
        free = tmap.free[cells[:, 0], cells[:, 1]]
        distance = route.distances[cells[:, 0], cells[:, 1]]
        ok = free & np.isfinite(distance)
        if not ok.any():
            # The floor just in front of a frame is often unseen (a jamb's shadow, furniture beside
            # the door): within APPROACH_DEPTH of it, unseen cells that hold no obstacle and keep the
            # robot's radius may carry the last leg, as the robot's bumpers would allow.
            centres = tmap.centre_of(np.argwhere(np.ones(tmap.shape, dtype=bool))).reshape(*tmap.shape, 2)
            near = np.linalg.norm(centres - door.centre[:2], axis=2) <= APPROACH_DEPTH + door.width / 2
            relaxed = tmap.free | (near & ~tmap.obstacle & (tmap.clearance >= tmap.robot_radius))
            distance = geodesic(replace(tmap, free=relaxed), self.pose[:2, 3]).distances[cells[:, 0], cells[:, 1]]
            free = relaxed[cells[:, 0], cells[:, 1]]
            ok = free & np.isfinite(distance)
            if not free.any():
                return None, None, f"no free floor within {APPROACH_DEPTH} m in front of the frame"
            if not ok.any():
                return None, None, "the free floor in front of the frame is cut off from the robot"
        last_leg = np.linalg.norm(points - door.centre[:2], axis=1)
        cost = np.where(ok, distance + last_leg, np.inf)
        k = int(np.argmin(cost))
        return points[k], float(cost[k]), ""

    def _door_routes(self) -> tuple[TraversabilityMap, Geodesic]:
        """Routes from here in the current room, kept until the next scan (one per room, not per door)."""
        if self._door_map is None:
            belief = self.belief
            assert belief.grid is not None and belief.roi is not None, "scan first"
            # Standing at a door needs only the robot's radius: its clearance would close a 0.8 m door.
            narrow = replace(self.config.navigation, safety_distance=0.0)
            blocked = blocked_directions(belief, self.stops)
            tmap = traversable_floor(
                belief.grid, belief.roi.floor_z, self.stops, self.visited, self.config.scanner, narrow, blocked
            )
            self._door_map = (tmap, geodesic(tmap, self.pose[:2, 3]))
        return self._door_map

    def cross_door(self, k: int) -> StepReport:
        """Drive to door ``k``, stand under its frame, and take the first scan of the next room."""
        door = self.doors[k]
        length, reason = self._route_length(door)
        if length is None:
            door.failed, door.reason = True, reason
            raise UnreachableDoorError(f"door {k} at {door.centre[:2].round(2).tolist()} cannot be reached: {reason}")
        # The door leads out of the room it was found in: the robot enters the room beyond.
        into = door.outward
        self._drive(door.centre[:2], float(np.arctan2(into[1], into[0])), length)
        door.visited = True
        self.room_index = max([*self.rooms_done, self.room_index]) + 1
        door.entered_room = self.room_index
        self.belief = RoomBelief(
            self.config.scanner,
            self.belief.classifier,
            voxel_size=self.config.voxel_size,
            roi_config=self.config.roi,
            exclude=[m.polygon for m in self.room_models],
        )
        self.visited = [self.pose[:2, 3].copy()]
        self.stops = []
        unit = np.asarray(into[:2], dtype=float) / np.hypot(*into[:2])
        self.entrance = Passage(tuple(door.centre[:2]), tuple(unit), door.width, APPROACH_DEPTH)
        try:
            return self.scan(length, 0, keep_direction=into)
        except RoIError as exc:
            # The frame scan measured no floor or ceiling beyond the door (a false door onto a wall
            # just behind it, a shaft): there is no room to scan there. The door is given up and the
            # storey goes on to the next one; the scan, taken, is in S(t) but not in the episode log.
            door.failed, door.reason = True, f"no room measured beyond it ({exc})"
            raise UnreachableDoorError(
                f"door {k} at {door.centre[:2].round(2).tolist()}: no room measured beyond it ({exc})"
            ) from exc

    def registration_error(self) -> tuple[float, float]:
        """(m, degrees) between the pose estimate and the true pose: evaluation only."""
        return pose_error(self.pose, self.true_pose)
