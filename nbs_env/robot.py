"""The mobile scanner, with no gymnasium import: it senses, moves and keeps its belief.

The :class:`Robot` couples the simulator (the true scene, the true pose, the scanner, odometry) with
the robot's estimator and belief (its pose estimate, S(t), the current room's RoI and V(t)). Everything
the robot decides from is in its belief; the simulator's state is kept in attributes named ``true_*``.

- :meth:`Robot.scan`, :meth:`Robot.move_to` and :meth:`Robot.scan_from`: one cycle of the method in
  a room (METHOD §1-6): drive (with drift), scan the true building, register, update the belief.
- :meth:`Robot.plan`: the next decision's NVPs and gains, from
  :func:`nbs_env.planning.planner.plan` (a query: it never writes into the belief).
- :meth:`Robot.drive_to` and :meth:`Robot.enter_room`: a door crossing, the new room's belief.

Which door to cross, when a room is done and where to search for doors are not the robot's
decisions: the storey session (:mod:`nbs_env.storey`) runs that loop with the door memory of
:mod:`nbs_env.planning.rooms`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from nbs_env.belief import BeliefUpdate, RoomBelief
from nbs_env.config import OdometryConfig, RobotConfig
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.cloud import AccumulatedCloud
from nbs_env.planning.navigation import Passage
from nbs_env.planning.planner import Plan, check_gain_model, plan, unobservable_after
from nbs_env.sensing.odometry import Odometry
from nbs_env.sensing.pose import planar, pose_error, yaw_of
from nbs_env.sensing.registration import RegistrationResult, level_from_floor, register
from nbs_env.sensing.scanner import Scan, Scanner
from scenes import Scene

__all__ = ["Robot", "StepReport"]


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
        check_gain_model(self.config.gain)
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
        #: The door the robot came into the current room by (None in the first room).
        self.entrance: Passage | None = None
        self.room_index = 0
        #: Scans taken in every room (a scan that raised included): what is derived from the
        #: belief is valid until the next one.
        self.scans_taken = 0
        #: Scans that reached the belief (one that raised left out): the index of the next one in the
        #: episode's log (:attr:`nbs_env.storey.Storey.scans`), which the rooms' working copies tag
        #: its points with (:attr:`nbs_env.belief.RoomModel.scans`).
        self.scans_added = 0

    @property
    def scans_in_room(self) -> int:
        """Scans taken in the current room (its door-frame scan included)."""
        return len(self.stops)

    # ------------------------------------------------------------------ the cycle
    def scan(
        self, path_length: float = 0.0, predicted_gain: int = 0, keep_direction: np.ndarray | None = None
    ) -> StepReport:
        """Scan from where the robot truly is, register, and update the belief."""
        self.scans_taken += 1
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
        update = self.belief.add_scan(scan, self.pose, keep_direction, world, scan_index=self.scans_added)
        self.scans_added += 1
        nav = self.config.navigation
        self.belief.cover(self.pose[:2, 3], nav.robot_radius + nav.safety_distance + 2 * self.config.voxel_size)
        times.update(update.times)
        self.visited.append(self.pose[:2, 3].copy())
        self.stops.append(self.pose[:3, 3].copy())
        self._plan = None
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
        expected, sensor, far, far_range = unobservable_after(
            planned, index, roi.floor_z, self.config.scanner, self.config.voxel_size, grid.speculative if grid else None
        )
        path = cands.path(index)
        length = float(cands.path_length[index])
        report = self._drive_and_scan(cands.points[index], path, length, int(planned.gains[index]))
        self.belief.keep_unobservable(expected, far, far_range, sensor)
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

    # ------------------------------------------------------------------ searches and doors
    def scan_from(
        self, point: np.ndarray, path: np.ndarray, length: float, count_conversions: bool = False
    ) -> StepReport:
        """Drive the planned ``path`` (``length`` metres) to ``point``, a place that is no NVP (a
        search stop of :mod:`nbs_env.planning.rooms`), and scan there."""
        watched = self.belief.occluded_structure_centres() if count_conversions else None
        path = np.asarray(path, dtype=float)
        report = self._drive_and_scan(np.asarray(point, dtype=float), path, length, 0)
        return replace(report, path=path, conversions=self._converted(watched))

    def drive_to(self, target_xy: np.ndarray, yaw: float, distance: float) -> None:
        """Drive ``distance`` metres to ``target_xy``, ending at heading ``yaw`` (radians), without
        scanning: a door crossing's drive to stand under the frame."""
        self._drive(np.asarray(target_xy, dtype=float), yaw, distance)

    def enter_room(self, room: int, entrance: Passage, exclude: list[np.ndarray]) -> None:
        """Start the belief of room number ``room``, entered through ``entrance``; ``exclude`` are
        the outlines of the rooms scanned before, kept out of its RoI."""
        self.room_index = room
        self.belief = RoomBelief(
            self.config.scanner,
            self.belief.classifier,
            voxel_size=self.config.voxel_size,
            roi_config=self.config.roi,
            exclude=exclude,
        )
        self.visited = [self.pose[:2, 3].copy()]
        self.stops = []
        self.entrance = entrance
        self._plan = None

    def registration_error(self) -> tuple[float, float]:
        """(m, degrees) between the pose estimate and the true pose: evaluation only."""
        return pose_error(self.pose, self.true_pose)
