"""One cycle of the method, with no gymnasium import: move, scan, register, perceive, map, plan.

The :class:`Robot` couples the simulator (the true scene, the true pose, the scanner) with the
robot's belief (its pose estimate, S(t), the current room's RoI and V(t), its candidates). Everything
the robot decides from is in its belief; the simulator's state is kept in attributes named ``true_*``.

Scope so far: the scanning of the room the robot is in (METHOD §6-7). Door detection and the hand-over
to the next room (METHOD §8) come with the environment.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from nbs_env.belief import BeliefUpdate, RoomBelief
from nbs_env.config import OdometryConfig, RegistrationConfig, ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.navigation import (
    Candidates,
    NavigationConfig,
    assume_blind_zone_free,
    candidates,
    traversability,
)
from nbs_env.planning.visibility import GainConfig, VisibilityModel
from nbs_env.sensing.odometry import Odometry
from nbs_env.sensing.pose import planar, pose_error, yaw_of
from nbs_env.sensing.registration import AccumulatedCloud, RegistrationResult, register
from nbs_env.sensing.scanner import Scan, Scanner
from scenes import Scene

__all__ = ["Robot", "RobotConfig", "StepReport"]


@dataclass(frozen=True)
class RobotConfig:
    """Everything the robot is made of (JSON-safe, frozen).

    Attributes
    ----------
    completion_fraction : float
        The room is complete when the best predicted gain falls below this share of the room's
        structural voxels (Structure + Occluded-structure), METHOD §7.
    max_scans_per_room : int
        The scan cap per room.
    perfect_localisation : bool
        Skip odometry drift and registration (the belief is the true pose): for fast RL.
    """

    scanner: ScannerConfig = field(default_factory=ScannerConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    navigation: NavigationConfig = field(default_factory=NavigationConfig)
    gain: GainConfig = field(default_factory=GainConfig)
    voxel_size: float = 0.05
    completion_fraction: float = 0.01
    max_scans_per_room: int = 12
    perfect_localisation: bool = False


@dataclass(frozen=True)
class StepReport:
    """What one scan cycle did (``true_*`` fields are the simulator's, for evaluation only)."""

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
        self.cloud = AccumulatedCloud(self.config.voxel_size)
        self.belief = RoomBelief(self.config.scanner, voxel_size=self.config.voxel_size)
        self.visited: list[np.ndarray] = []
        self.stops: list[np.ndarray] = []
        self.scans_in_room = 0
        self.path_length = 0.0
        start = np.asarray(scene.start[:2], dtype=float)
        self.true_pose = self._odometry.true_sensor_pose(start, 0.0, self._floor_z, self.config.scanner.height)
        # The robot knows where it starts (the origin of its map); it does not know its tilt.
        self.pose = planar(start[0], start[1], 0.0, self._floor_z + self.config.scanner.height)
        self._candidates: Candidates | None = None
        self._gains: np.ndarray | None = None

    # ------------------------------------------------------------------ the cycle
    def scan(self, path_length: float = 0.0, predicted_gain: int = 0) -> StepReport:
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
            result = register(scan.points, self.pose, self.cloud, self.config.registration)
            self.pose = result.pose
        times["registration"] = time.perf_counter() - t
        self.cloud.add(scan.to_world(self.pose), self.pose[:3, 3])
        update = self.belief.add_scan(scan, self.pose)
        times.update(update.times)
        self.visited.append(self.pose[:2, 3].copy())
        self.stops.append(self.pose[:3, 3].copy())
        self.scans_in_room += 1
        self._candidates = None
        self._gains = None
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
        )

    def candidates(self) -> tuple[Candidates, np.ndarray]:
        """The next valid positions and their predicted gains, from the robot's own grid."""
        if self._candidates is None:
            grid = self.belief.grid
            assert grid is not None and self.belief.roi is not None, "scan first"
            cfg = self.config
            walkable = assume_blind_zone_free(
                grid.labels, grid.origin, grid.voxel_size, self.stops, cfg.scanner.elevation_min, cfg.scanner.min_range
            )
            tmap = traversability(
                walkable, grid.origin, grid.voxel_size, self.belief.roi.floor_z, cfg.navigation, self.visited
            )
            self._candidates = candidates(tmap, self.pose[:2, 3], cfg.navigation)
            sensors = np.column_stack(
                [self._candidates.points, np.full(self._candidates.count, self.belief.roi.floor_z + cfg.scanner.height)]
            )
            model = VisibilityModel(grid.labels, grid.origin, grid.voxel_size, cfg.gain)
            gains = np.zeros(cfg.navigation.max_candidates, dtype=np.int64)
            gains[: self._candidates.count] = model.gains(sensors, cfg.scanner)
            self._gains = gains
        return self._candidates, self._gains

    def move_to(self, index: int) -> StepReport:
        """Drive the planned path to candidate ``index`` and scan there."""
        cands, gains = self.candidates()
        if not (0 <= index < cands.count):
            raise IndexError(f"candidate {index} is not valid: {cands.count} candidates")
        path = cands.path(index)
        distance = float(cands.path_length[index])
        heading = path[-1] - path[-2] if len(path) >= 2 else np.array([1.0, 0.0])
        yaw = float(np.arctan2(heading[1], heading[0]))
        # The robot executes the motion it planned in its belief; the true robot moves by the same
        # displacement from where it truly is, and odometry reports it with drift.
        planned = planar(*cands.points[index], yaw, self.pose[2, 3])
        motion = np.linalg.inv(planar(*self.pose[:2, 3], yaw_of(self.pose))) @ planned
        true_from = self.true_pose
        true_planar = planar(*true_from[:2, 3], yaw_of(true_from)) @ motion
        true_to = self._odometry.true_sensor_pose(
            true_planar[:2, 3], yaw_of(true_planar), self._floor_z, self.config.scanner.height
        )
        self.pose = self._odometry.drive(self.pose, true_from, true_to, distance)
        self.true_pose = true_to
        self.path_length += distance
        return self.scan(distance, int(gains[index]))

    # ------------------------------------------------------------------ room completion (METHOD §7)
    def room_structural_voxels(self) -> int:
        grid = self.belief.grid
        if grid is None:
            return 0
        return int(
            np.count_nonzero((grid.labels == VoxelLabel.STRUCTURE) | (grid.labels == VoxelLabel.OCCLUDED_STRUCTURE))
        )

    def room_complete(self) -> bool:
        """Best predicted gain below the completion share, no NVP, or the scan cap reached."""
        if self.scans_in_room >= self.config.max_scans_per_room:
            return True
        cands, gains = self.candidates()
        if cands.count == 0:
            return True
        return int(gains[: cands.count].max()) < self.config.completion_fraction * self.room_structural_voxels()

    def registration_error(self) -> tuple[float, float]:
        """(m, degrees) between the pose estimate and the true pose: evaluation only."""
        return pose_error(self.pose, self.true_pose)
