"""The storey's rooms and doors as the robot measured them, and where to go next (METHOD §8).

:class:`Rooms` is the robot's door memory and room record: the doors it detected in each room it
finished, which it crossed, gave up or left as exterior, and the outlines and models of the rooms
done. From the robot's belief it answers the storey session's questions:

- :meth:`Rooms.finish_room`: detect the doors of the room just done and remember the new ones;
- :meth:`Rooms.next_door`: the nearest door still to cross that a route reaches, by the travel to
  stand under its frame (:meth:`Rooms.route_length`: the geodesic to its approach in this room, or
  straight legs through the rooms crossed);
- :meth:`Rooms.enter`: the door is crossed, the robot's number of the room beyond and the passage
  the next room's plans keep open;
- :meth:`Rooms.wall_search` and :meth:`Rooms.door_search`: where to scan for a door no scan
  faced, or to come nearer to a door no route reaches (:mod:`nbs_env.planning.wall_search`).

It reads only what the robot measured (the :class:`RobotView`: its belief, pose estimate, stops,
configuration and plan) and never drives: the storey session moves the robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple, Protocol

import numpy as np
from shapely.geometry import Point, Polygon

from nbs_env.belief import RoomBelief, RoomModel
from nbs_env.config import RobotConfig, RoomRules
from nbs_env.perception.doors import detect_doors
from nbs_env.planning.navigation import (
    Candidates,
    Geodesic,
    Passage,
    TraversabilityMap,
    candidates,
    geodesic,
    path_to,
)
from nbs_env.planning.planner import (
    Plan,
    blocked_directions,
    sensor_positions,
    traversable_floor,
    within_roi,
    without_unobservable,
)
from nbs_env.planning.visibility import VisibilityModel
from nbs_env.planning.wall_search import approach_position, search_position, unviewed_wall

__all__ = ["APPROACH_DEPTH", "BEYOND_DOOR", "SAME_DOOR", "KnownDoor", "RobotView", "Rooms", "SearchStop"]

#: How far in front of the frame (metres) an approach is searched for when the preferred point is
#: not free: any free cell on the robot's side from which it can drive straight through the opening.
APPROACH_DEPTH = 1.5
#: Doors detected closer than this (metres) are one door seen from both sides.
SAME_DOOR = 0.6
#: A door leads into a scanned room when the point this far (metres) beyond its frame lies in it.
BEYOND_DOOR = 0.6


class RobotView(Protocol):
    """What :class:`Rooms` reads of the robot: its own estimates, never the simulator's state.

    Attributes
    ----------
    config : RobotConfig
    belief : RoomBelief
        The current room's belief.
    pose : (4, 4) float
        The pose estimate of the scanner.
    stops : list of (3,) float
        The scanner positions of the current room's scans.
    visited : list of (2,) float
        Where the robot stood in the current room (its entrance included).
    scans_taken : int
        Scans taken so far, in every room: a new scan invalidates what was derived from the last.
    """

    config: RobotConfig
    belief: RoomBelief
    pose: np.ndarray
    stops: list[np.ndarray]
    visited: list[np.ndarray]
    scans_taken: int

    def plan(self) -> Plan: ...


@dataclass
class KnownDoor:
    """A door the robot detected (its own estimate), and whether it went through it.

    Attributes
    ----------
    centre : (3,) float
        The opening's centre on the floor, in the robot's map frame.
    outward : (3,) float
        Unit normal of the wall, pointing out of the room it was found in.
    width : float
        Clear width, metres.
    found_in_room : int
        The robot's number of the room it was detected in.
    visited : bool
        Crossed, or found to lead into a room already scanned.
    failed : bool
        Given up (no route, or no room measured beyond it); :attr:`reason` says why.
    entered_room : int or None
        The robot's number of the room beyond, once known.
    exterior : bool
        It opens onto the outside (not crossed unless ``doors.cross_exterior``).
    covered : float
        Share of the rising rays through the opening that returned beyond it (NaN: not measured).
    reason : str or None
        Why no route reaches it, or why it was given up.
    """

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
    """Where a search scan is taken (:meth:`Rooms.wall_search`, :meth:`Rooms.door_search`).

    Attributes
    ----------
    kind : str
        ``"view"`` (the NVP that views most of the unviewed wall), ``"approach"`` (no NVP views it;
        the NVP nearest to it), ``"narrow"`` (no NVP views it or comes near; a place reached
        keeping only the robot's radius clear views it) or ``"door"`` (:meth:`Rooms.door_search`:
        nearer to a door no route reaches).
    nvp : int or None
        The plan's NVP index (``"view"``, ``"approach"``); None for ``"narrow"`` and ``"door"``.
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


class _Approach(NamedTuple):
    """The drive to stand under a door of the current room (:meth:`Rooms._approach`).

    ``point``: where the last, straight leg through the opening starts (None: no approach, and
    ``reason`` says why); ``length``: metres from the robot to the door's centre; ``tmap`` and
    ``route``: the map and geodesic the path to ``point`` runs on (the relaxed map when the floor in
    front of the frame is unseen).
    """

    point: np.ndarray | None
    length: float | None
    reason: str
    tmap: TraversabilityMap | None = None
    route: Geodesic | None = None


class Rooms:
    """The robot's door memory and record of rooms (module docstring).

    Parameters
    ----------
    config : RobotConfig
        The robot's door limits, footprint, scanner and gain options.
    rules : RoomRules
        The storey's rules: the wall and door searches.

    Attributes
    ----------
    doors : list of KnownDoor
        Every door detected, in the order found.
    current : int
        The robot's number of the room it is in (0 first, then in the order entered).
    done : list of int
        The rooms finished, in order.
    polygons : dict of int to shapely Polygon
        The RoI outline of each room finished.
    models : list of RoomModel
        The recovered model of each room finished.
    """

    def __init__(self, config: RobotConfig, rules: RoomRules) -> None:
        self.config = config
        self.rules = rules
        self.doors: list[KnownDoor] = []
        self.current = 0
        self.done: list[int] = []
        self.polygons: dict[int, Polygon] = {}
        self.models: list[RoomModel] = []
        self._door_map: tuple[int, TraversabilityMap, Geodesic] | None = None

    # ------------------------------------------------------------------ doors of a finished room
    def finish_room(self, robot: RobotView) -> list[KnownDoor]:
        """Detect the doors of the room just completed and add the new ones to the storey's list.

        Returns
        -------
        list of KnownDoor
            Every door known now.
        """
        belief = robot.belief
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
            self.polygons[self.current] = polygon
        for door in found:
            known = next((d for d in self.doors if np.linalg.norm(d.centre[:2] - door.centre[:2]) < SAME_DOOR), None)
            if known is not None:
                continue  # a door seen from both sides is one door
            self.doors.append(
                KnownDoor(
                    door.centre,
                    door.outward,
                    door.width,
                    self.current,
                    exterior=door.exterior,
                    covered=door.covered,
                )
            )
        # A door into a room already scanned needs no crossing: its far side is known.
        for known in self.doors:
            if known.visited:
                continue
            beyond = Point(*(known.centre[:2] + BEYOND_DOOR * known.outward))
            for room, poly in self.polygons.items():
                if room != known.found_in_room and poly.contains(beyond):
                    known.visited, known.entered_room = True, room
        model = belief.model(self.current)
        if model is not None:
            self.models.append(model)
        self.done.append(self.current)
        return list(self.doors)

    def door_open(self, door: KnownDoor) -> bool:
        """Whether ``door`` still waits to be crossed: not visited, not given up, and not an
        exterior door the robot leaves (``config.doors.cross_exterior``)."""
        return not (door.visited or door.failed or (door.exterior and not self.config.doors.cross_exterior))

    def next_door(self, robot: RobotView) -> int | None:
        """The nearest unvisited door the robot can reach, by its estimated travel, or None.

        Exterior doors are left (unless ``config.doors.cross_exterior``); a door that cannot be
        reached keeps the reason in :attr:`KnownDoor.reason` (see :meth:`abandon_unreachable`)."""
        best, best_length = None, np.inf
        for k, door in enumerate(self.doors):
            if not self.door_open(door):
                continue
            length, reason = self.route_length(robot, door)
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

    def give_up(self, door: KnownDoor, reason: str) -> None:
        """``door`` will not be crossed, for ``reason``."""
        door.failed, door.reason = True, reason

    def enter(self, door: KnownDoor) -> tuple[int, Passage]:
        """The robot crossed ``door``: the number of the room beyond and the passage its plans keep.

        Returns
        -------
        room : int
            The robot's number of the new room (one more than any room so far).
        entrance : Passage
            The door's opening, facing into the new room (:func:`nbs_env.planning.planner.plan`
            keeps it traversable).
        """
        door.visited = True
        self.current = max([*self.done, self.current]) + 1
        door.entered_room = self.current
        into = np.asarray(door.outward[:2], dtype=float)
        unit = into / np.hypot(*into)
        return self.current, Passage(tuple(door.centre[:2]), tuple(unit), door.width, APPROACH_DEPTH)

    # ------------------------------------------------------------------ routes
    def _room_route(self, target_room: int) -> list[KnownDoor] | None:
        """Doors already crossed that lead from the current room to ``target_room`` (breadth first)."""
        links = [d for d in self.doors if d.visited and d.entered_room is not None]
        queue: list[tuple[int, list[KnownDoor]]] = [(self.current, [])]
        seen = {self.current}
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

    def route_length(self, robot: RobotView, door: KnownDoor) -> tuple[float | None, str | None]:
        """Travel to stand under ``door`` and why there is none: the geodesic to its approach in this
        room, else through rooms already scanned (straight legs between the doors on the way, an
        estimate).

        Returns
        -------
        length : float or None
            Metres; None when no route is known.
        reason : str or None
            Why there is none (None when there is).
        """
        _path, length, reason = self._route(robot, door, with_path=False)
        return length, reason

    def route(self, robot: RobotView, door: KnownDoor) -> tuple[np.ndarray | None, float | None, str | None]:
        """The route :meth:`route_length` measures, as the polyline the robot drives to stand under
        ``door``.

        Returns
        -------
        path : (p, 2) float or None
            From the robot's position estimate to the door's centre, in the robot's map frame: the
            geodesic to the door's approach through this room's map, then straight through the
            opening; through rooms already scanned, the straight legs between the doors on the way.
            Its length is ``length``. None when no route is known.
        length : float or None
            Metres, as :meth:`route_length`.
        reason : str or None
            Why there is none (None when there is).
        """
        return self._route(robot, door, with_path=True)

    def _route(
        self, robot: RobotView, door: KnownDoor, with_path: bool
    ) -> tuple[np.ndarray | None, float | None, str | None]:
        if door.found_in_room == self.current:
            found = self._approach(robot, door)
            if found.point is None:
                return None, None, found.reason
            path = None
            if with_path:
                # The polyline the cost adds up (_Approach.length): geodesic to the approach, then
                # the straight last leg through the opening.
                path = np.vstack([path_to(found.tmap, found.route, found.point), door.centre[:2]])
            return path, found.length, None
        route = self._room_route(door.found_in_room)
        if route is None:
            return None, None, "no route through the rooms crossed to the room it was found in"
        legs = np.array([robot.pose[:2, 3], *[d.centre[:2] for d in route], door.centre[:2]], dtype=float)
        return legs if with_path else None, float(np.linalg.norm(np.diff(legs, axis=0), axis=1).sum()), None

    def _approach(self, robot: RobotView, door: KnownDoor) -> _Approach:
        """Where the robot starts its drive through ``door``, the travel to stand under the frame from
        here, and, when there is no approach, why.

        The approach is the free cell on the robot's side of the frame, within :data:`APPROACH_DEPTH`
        of it and in front of the opening (so that the last leg runs straight through it), that
        minimises the path to it (as :func:`~nbs_env.planning.navigation.path_to` draws it from the
        robot's position) plus that last leg."""
        if robot.belief.grid is None or robot.belief.roi is None:
            return _Approach(None, None, "no map of the room")
        tmap, route = self.door_routes(robot)
        side = 1.0 if np.dot(robot.pose[:2, 3] - door.centre[:2], door.outward) > 0 else -1.0
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
            return _Approach(None, None, "the floor in front of it lies outside the room's map")
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
            tmap = replace(tmap, free=relaxed)
            route = geodesic(tmap, robot.pose[:2, 3])
            distance = route.distances[cells[:, 0], cells[:, 1]]
            free = relaxed[cells[:, 0], cells[:, 1]]
            ok = free & np.isfinite(distance)
            if not free.any():
                return _Approach(None, None, f"no free floor within {APPROACH_DEPTH} m in front of the frame")
            if not ok.any():
                return _Approach(None, None, "the free floor in front of the frame is cut off from the robot")
        # The legs path_to adds to the geodesic between cell centres: from the robot to its cell's
        # centre, and from the approach's cell centre to the approach, so that the travel measured
        # is the polyline driven (as NVPs' path lengths are).
        source = tmap.centre_of(np.array(route.source))[0]
        ends = np.linalg.norm(points - tmap.centre_of(cells), axis=1) + float(np.linalg.norm(route.start_xy - source))
        last_leg = np.linalg.norm(points - door.centre[:2], axis=1)
        cost = np.where(ok, distance + ends + last_leg, np.inf)
        k = int(np.argmin(cost))
        return _Approach(points[k], float(cost[k]), "", tmap, route)

    def door_routes(self, robot: RobotView) -> tuple[TraversabilityMap, Geodesic]:
        """The floor the robot may cross to stand at a door, and the routes from where it is (kept
        until its next scan: one per room, not per door)."""
        if self._door_map is None or self._door_map[0] != robot.scans_taken:
            belief = robot.belief
            assert belief.grid is not None and belief.roi is not None, "scan first"
            # Standing at a door needs only the robot's radius: its clearance would close a 0.8 m door.
            narrow = replace(self.config.navigation, safety_distance=0.0)
            blocked = blocked_directions(belief, robot.stops)
            tmap = traversable_floor(
                belief.grid, belief.roi.floor_z, robot.stops, robot.visited, self.config.scanner, narrow, blocked
            )
            self._door_map = (robot.scans_taken, tmap, geodesic(tmap, robot.pose[:2, 3]))
        return self._door_map[1], self._door_map[2]

    def _narrow_candidates(self, robot: RobotView) -> Candidates:
        """Places the robot reaches keeping only its radius clear: the door routes' map, with no
        safety distance (the NVPs' margin can close a gap between furniture the robot fits through)."""
        tmap, route = self.door_routes(robot)
        # On the lattice alone: this map has no outline, and a stand-in could stand in a doorway.
        lattice = replace(self.config.navigation, safety_distance=0.0, snap=False)
        return candidates(tmap, robot.pose[:2, 3], lattice, route)

    def standing_room(self, robot: RobotView) -> int:
        """How many places of the current room's RoI the robot reaches over measured floor keeping
        only its radius clear (none: the room's measured floor holds no footprint of the robot; its
        aisles are narrower).

        Measured: the blind zone under and around the stops is not taken as free here, as it is
        for driving. In a stack room entered from its door frame, the shelf in front of the robot
        lies within the minimum range; the blind zone would hold places the robot cannot reach."""
        belief = robot.belief
        if belief.roi is None or belief.grid is None:
            return 0
        narrow = replace(self.config.navigation, safety_distance=0.0, snap=False)
        tmap = traversable_floor(
            belief.grid, belief.roi.floor_z, robot.stops, robot.visited, self.config.scanner, narrow,
            labels=belief.grid.labels,
        )  # fmt: skip
        return candidates(within_roi(tmap, belief.roi.polygon), robot.pose[:2, 3], narrow).count

    # ------------------------------------------------------------------ searches
    def wall_search(self, robot: RobotView) -> SearchStop | None:
        """Where to scan for the room's wall no stop viewed frontally
        (:mod:`nbs_env.planning.wall_search`), in this order: the NVP that views the most of that
        wall (``"view"``); the NVP nearest to it (``"approach"``); a place that views it among
        those reached keeping only the robot's radius clear (``"narrow"``, when
        ``rules.wall_search.narrow``). None when every wall stretch as wide as a door was viewed,
        or none of the three finds a place. Reads the robot's belief only.
        """
        belief = robot.belief
        if belief.roi is None or belief.grid is None or not robot.stops:
            return None
        planned = robot.plan()
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
        config = self.rules.wall_search

        def sees(sensors: np.ndarray, targets: np.ndarray) -> np.ndarray:
            return model.sees(sensors, targets, scanner)

        scanned = [poly for room, poly in self.polygons.items() if room != self.current]
        walls = unviewed_wall(belief.roi, robot.stops, sees, scanned, config, self.config.doors.min_width, scanner)
        n = planned.count
        sensors = sensor_positions(planned.candidates.points[:n], belief.roi.floor_z, scanner)
        path_length = planned.candidates.path_length[:n]
        cands = planned.candidates
        index = search_position(walls, sensors, path_length, sees, config, scanner)
        if index is not None:
            return SearchStop("view", index, cands.points[index], cands.path(index), float(path_length[index]))
        index = approach_position(walls, sensors, path_length, np.asarray(robot.stops, dtype=float), config)
        if index is not None:
            return SearchStop("approach", index, cands.points[index], cands.path(index), float(path_length[index]))
        if not config.narrow or not walls.target.any():
            return None
        narrow = self._narrow_candidates(robot)
        if narrow.count == 0:
            return None
        sensors = sensor_positions(narrow.points, belief.roi.floor_z, scanner)
        lengths = narrow.path_length[: narrow.count]
        index = search_position(walls, sensors, lengths, sees, config, scanner)
        if index is None:
            return None
        return SearchStop("narrow", None, narrow.points[index], narrow.path(index), float(lengths[index]))

    def door_search(self, robot: RobotView, door: KnownDoor) -> SearchStop | None:
        """Where to scan so that ``door`` of the current room, which no route reaches, may be
        reached: the place (among those reached keeping the robot's radius clear) nearest to the
        door across floor not yet measured, when it is at least ``rules.wall_search.approach``
        metres nearer so than every stop of the room (``"door"``). None when there is no such place.

        A door is found from afar: the floor in front of it may be unmeasured (furniture's shadow
        on the way), so no route reaches it, though the robot's map shows nothing in between. Floor
        not measured, holding no obstacle and leaving the robot's radius clear, counts as passable
        for the distance only; the robot still drives on measured floor. Reads the robot's belief.
        """
        belief = robot.belief
        if belief.grid is None or belief.roi is None or not robot.stops:
            return None
        tmap, _ = self.door_routes(robot)
        side = 1.0 if np.dot(robot.pose[:2, 3] - door.centre[:2], door.outward) > 0 else -1.0
        goal = door.centre[:2] + side * 0.5 * np.asarray(door.outward[:2], dtype=float)
        if not tmap.contains(goal[None])[0]:
            return None
        hopeful = tmap.free | (~tmap.obstacle & (tmap.clearance >= tmap.robot_radius))
        towards = geodesic(replace(tmap, free=hopeful), goal).distances
        near = self._narrow_candidates(robot)
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
        reach = distance(np.asarray(robot.stops, dtype=float)[:, :2]).min()
        if not np.isfinite(d).any() or d.min() > reach - self.rules.wall_search.approach + 1e-9:
            return None
        index = int(np.lexsort((near.path_length[: near.count], d))[0])
        return SearchStop("door", None, near.points[index], near.path(index), float(near.path_length[index]))
