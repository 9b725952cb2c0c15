"""NBSEnv: the scanning loop of the paper as a Gymnasium environment.

The env wraps a :class:`~nbs_env.robot.Robot` (the method: move, scan, register, perceive, label,
plan) and a :class:`~nbs_env.metrics.CoverageMeter` (evaluation against ground truth). Observations
are built from the robot's belief only; the reward and the ``*_sensed_pct`` figures come from the
meter, the one reader of ground truth here.
"""

from __future__ import annotations

import copy
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import shapely
from gymnasium import spaces
from shapely.geometry import Polygon

from nbs_env.config import OdometryConfig, ScannerConfig, _finite, _require
from nbs_env.errors import ConfigError, InvalidActionError, InvalidPoseError, UnreachableDoorError
from nbs_env.labels import VoxelLabel
from nbs_env.metrics import CoverageMeter
from nbs_env.observation import CANDIDATE_FEATURES, ObservationConfig, candidate_table, voxel_window
from nbs_env.robot import Robot, RobotConfig, RoomModel, StepReport
from scenes import FloorPlan, Scene, load_scene
from scenes.generator import GeneratorConfig, generate_plan
from scenes.geometry import point_is_free

__all__ = [
    "PRESETS",
    "BeliefView",
    "EnvConfig",
    "NBSEnv",
    "RewardConfig",
    "StageTimes",
    "candidate_table_of",
    "make_config",
]

#: Stage names of ``info["times"]``, in the order a step runs them.
STAGES = ("scan", "registration", "roi", "classification", "voxels", "planning")


@dataclass(frozen=True)
class RewardConfig:
    """What a step is worth.

    Attributes
    ----------
    kind : {"coverage", "conversions"}
        ``"coverage"`` (default): the increase of the true structural surface sensed, in
        percentage points of the storey's structural surface (evaluation-side ground truth).
        ``"conversions"``: the robot's own realised Occluded-structure→Structure conversions, in
        percent of the room's structural voxels; no ground truth is read.
    scan_cost : float
        Subtracted per scan taken in the step (a door crossing adds a scan).
    metre_cost : float
        Subtracted per metre driven in the step.
    invalid_action_penalty : float
        Subtracted for a masked action (no scan is taken).
    """

    kind: str = "coverage"
    scan_cost: float = 0.5
    metre_cost: float = 0.05
    invalid_action_penalty: float = 1.0

    def __post_init__(self) -> None:
        _require(
            self.kind in ("coverage", "conversions"),
            f"reward kind must be 'coverage' or 'conversions', got {self.kind!r}",
        )
        _finite(
            scan_cost=self.scan_cost, metre_cost=self.metre_cost, invalid_action_penalty=self.invalid_action_penalty
        )


@dataclass(frozen=True)
class EnvConfig:
    """Everything an :class:`NBSEnv` is made of (JSON-safe, frozen).

    Attributes
    ----------
    scene : str
        What ``reset`` loads when its options name no scene: anything :func:`scenes.load_scene`
        takes (a bundled name, a file, ``generated:SEED``), or ``"generated"`` for a fresh storey
        per reset drawn from the env's generator with ``generator``.
    scene_options : dict
        Options for :func:`scenes.load_scene` (e.g. ``{"storey": "Erdgeschoss"}`` for IFC).
    generator : GeneratorConfig
        The storeys ``"generated"`` draws.
    robot : RobotConfig
    reward : RewardConfig
    observation : ObservationConfig
    max_scans : int
        The scan budget of an episode; reaching it truncates.
    completion : {"gain", "policy"}
        Who decides that a room is complete. ``"gain"`` (the paper's method, METHOD §7): the robot,
        when the best predicted Occluded-structure→Structure gain falls below
        ``robot.completion_fraction`` of the room's structural voxels. ``"policy"``: the agent, through
        one more action, index K ("this room is done"), always valid; the compared methods use it
        for their own stopping rules. In both, the room's scan cap and running out of NVPs end it.
    expose_belief : bool
        Put a :class:`BeliefView` of the robot's belief (its grid, RoI, candidates, this step's
        registered scans) in ``info["belief"]``, for policies that keep their own maps. References,
        not copies: use it in-process only (it does not pickle).
    coverage_spacing, coverage_radius : float
        Ground-truth sample spacing and sensing radius of the evaluation, metres.
    travel_speed : float
        Driving speed for the travel time, m/s.
    """

    scene: str = "generated"
    scene_options: dict[str, Any] = field(default_factory=dict)
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    max_scans: int = 80
    completion: str = "gain"
    expose_belief: bool = False
    coverage_spacing: float = 0.05
    coverage_radius: float = 0.05
    travel_speed: float = 0.5

    def __post_init__(self) -> None:
        _require(
            isinstance(self.scene, str) and self.scene != "", f"scene must be a non-empty string, got {self.scene!r}"
        )
        _require(
            isinstance(self.max_scans, int) and self.max_scans >= 1,
            f"max_scans must be an integer >= 1, got {self.max_scans!r}",
        )
        _finite(
            coverage_spacing=self.coverage_spacing, coverage_radius=self.coverage_radius, travel_speed=self.travel_speed
        )
        _require(self.coverage_spacing > 0 and self.coverage_radius > 0, "coverage spacing and radius must be > 0")
        _require(self.travel_speed > 0, f"travel_speed must be > 0, got {self.travel_speed}")
        _require(
            self.completion in ("gain", "policy"), f"completion must be 'gain' or 'policy', got {self.completion!r}"
        )
        _require(
            self.robot.predict_gains or self.completion == "policy",
            "completion='gain' needs robot.predict_gains (the room ends when the predicted gain is small)",
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _fast() -> EnvConfig:
    """The RL preset: a 1° scanner, 10 cm voxels, perfect localisation, 1-3 room storeys."""
    robot = RobotConfig(
        scanner=ScannerConfig(angular_step=1.0),
        odometry=OdometryConfig(0.0, 0.0, 0.0),
        voxel_size=0.1,
        perfect_localisation=True,
    )
    return EnvConfig(
        generator=GeneratorConfig(rooms=(1, 3)),
        robot=robot,
        max_scans=40,
        coverage_spacing=0.1,
        coverage_radius=0.1,
    )


#: Named configurations; ``make_config`` builds them.
PRESETS = {"default": EnvConfig, "fast": _fast}


def make_config(preset: str = "default", **overrides: Any) -> EnvConfig:
    """A preset's :class:`EnvConfig` with top-level fields replaced, e.g. ``scene="five_rooms"``."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; presets: {', '.join(PRESETS)}")
    config = PRESETS[preset]()
    unknown = sorted(set(overrides) - set(EnvConfig.__dataclass_fields__))
    if unknown:
        raise ConfigError(f"EnvConfig has no field(s) {unknown}; fields: {list(EnvConfig.__dataclass_fields__)}")
    return replace(config, **overrides)


def candidate_table_of(obs: dict[str, np.ndarray]) -> np.ndarray:
    """(..., K, 5) float32: ``obs["candidates"]`` as a table with columns ``CANDIDATE_FEATURES``
    (works on a single observation and on a batch from a vector env)."""
    flat = np.asarray(obs["candidates"])
    return flat.reshape(*flat.shape[:-1], -1, len(CANDIDATE_FEATURES))


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


@dataclass(frozen=True)
class BeliefView:
    """What the robot believes, for policies that keep their own state (``info["belief"]``).

    Everything here is the robot's: measured points placed with its pose estimates, its own grid
    and RoI. Nothing is ground truth. Arrays are references into the live belief: read, never write.

    Attributes
    ----------
    pose : (4, 4) float
        The pose estimate.
    room : int
        The robot's number of the room it is in.
    new_room : bool
        This step (or reset) started the room: maps of the previous room no longer apply.
    scans : list of ((n, 3) float, (3,) float)
        The scans registered during this step (a door crossing adds one): world points and the
        scanner position.
    grid : VoxelGrid or None
        The room's labelled voxel space V(t).
    roi : RoI or None
        The room's region of interest.
    candidates_xy : (K, 2) float
        World positions of the NVPs (zeros for padding).
    path_length : (K,) float
        Geodesic path lengths to them.
    mask : (K,) bool
        Which entries are real.
    scanner : ScannerConfig
        The scanner's pattern and limits.
    """

    pose: np.ndarray
    room: int
    new_room: bool
    scans: list[tuple[np.ndarray, np.ndarray]]
    grid: Any
    roi: Any
    candidates_xy: np.ndarray
    path_length: np.ndarray
    mask: np.ndarray
    scanner: ScannerConfig


@dataclass
class _Step:
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


class NBSEnv(gym.Env):
    """
    ## Description

    Autonomous next-best-scan planning of a building storey (Kim et al., "Autonomous Scanning of
    Structural Elements in Buildings"). A mobile robot with a 360°×100° terrestrial laser scanner
    stands in a storey of cluttered rooms joined by doors. At every stop it has scanned, registered
    the scan (ICP), found the room's region of interest (RoI), classified its wall faces as
    structural elements (SE) with an SVM, and labelled its voxel space V(t). The agent chooses the
    next scan among the next valid positions (NVPs). When the robot judges the room complete
    (no NVP predicts enough Occluded-structure→Structure conversions), it detects the room's doors,
    drives to the nearest unvisited one and takes the first scan of the next room, all inside the
    same step.

    ## Action Space

    `Discrete(K)` with K = `robot.navigation.max_candidates` (64): an index into the candidate
    list. Only the first `count` entries are real; `action_masks()` (and `info["action_mask"]`)
    says which. With `completion="policy"` the space is `Discrete(K + 1)` and action K, always
    allowed, declares the room complete (the robot then looks for the next door). A masked action
    takes no scan, costs `reward.invalid_action_penalty` and sets
    `info["invalid_action"] = True`. An action outside `Discrete(K)` raises `InvalidActionError`.

    ## Observation Space

    A flat `Dict`:

    - `voxels`: `observation.shape` (64, 64, 16) uint8, space 0..255, values 0..5. The
      `VoxelLabel`s of the current room's V(t) in a window of 0.2 m cells centred on the robot's
      estimated position, axis-aligned, from 0.2 m below its floor. Labels are pooled by priority
      Structure > Occluded-structure > Clutter > Occluded-clutter > Empty > Unknown; cells outside
      the grid are Unknown.
    - `candidates`: (K·5,) float32, row-major (K, 5); `candidate_table_of(obs)` reshapes it. Per
      NVP: dx, dy (m, world axes, from the robot), geodesic path length (m), predicted conversions
      as a share of the room's structural voxels, valid (1/0); zeros for padding.
    - `pose`: (4,) float32, the robot's pose estimate: x, y, z (m) and yaw (rad).

    Everything in the observation comes from the robot's own measurements and pose estimate. The
    shapes are those stable-baselines3 takes without a warning: `voxels` is image-like (its default
    `MultiInputPolicy` sees a 64×64 picture with 16 height channels), `candidates` is flat.

    ## Rewards

    `RewardConfig`. By default the increase of the true structural surface sensed, in percentage
    points of the storey's structural surface, minus `scan_cost` (0.5) per scan and `metre_cost`
    (0.05) per metre driven. `kind="conversions"` replaces the first term with the robot's own
    realised Occluded-structure→Structure conversions (% of the room's structural voxels): no
    ground truth.

    ## Starting State

    The robot stands at the scene's start position (its own map's origin) and has taken its first
    scan. `reset(seed=..., options={"scene": ..., "start": (x, y)})` picks the storey: anything
    `scenes.load_scene` takes, a `Scene` or `FloorPlan`, or `"generated"` (a fresh storey per
    reset from the env's random generator).

    ## Episode End

    `terminated` when the storey is complete: the current room is complete and no detected door is
    left that the robot can reach. `truncated` when `max_scans` scans have been taken, and through
    `max_episode_steps` of the registered ids.

    ## Arguments

    `NBSEnv(config=None, render_mode=None, **overrides)`: `config` is an `EnvConfig` or a preset
    name (`"default"`, `"fast"`); `overrides` replace top-level `EnvConfig` fields (e.g.
    `scene="five_rooms"`, `max_scans=30`). `render_mode="rgb_array"` draws a top-down picture.

    ## Registered Configurations

    | id | preset | scene | max_episode_steps |
    |---|---|---|---|
    | `nbs_env/NBS-v0` | default: 0.5° scanner, 5 cm voxels, odometry drift + ICP | generated 1-8 rooms | 80 |
    | `nbs_env/NBS-Fast-v0` | fast: 1° scanner, 10 cm voxels, perfect localisation | generated 1-3 rooms | 40 |
    | `nbs_env/NBS-FiveRooms-v0` | default | `five_rooms` | 60 |
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, config: EnvConfig | str | None = None, render_mode: str | None = None, **overrides: Any) -> None:
        if config is None or isinstance(config, str):
            config = make_config(config or "default", **overrides)
        elif overrides:
            config = replace(config, **overrides)
        if not isinstance(config, EnvConfig):
            raise ConfigError(f"config must be an EnvConfig or a preset name, got {type(config).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        self.config = config
        self.render_mode = render_mode
        k = config.robot.navigation.max_candidates
        self.max_candidates = k
        #: The "room done" action of completion="policy" (None otherwise).
        self.stop_action: int | None = k if config.completion == "policy" else None
        self.n_actions = k + (self.stop_action is not None)
        self.action_space = spaces.Discrete(self.n_actions)
        self.observation_space = spaces.Dict(
            {
                # uint8 in 0..255 is what stable-baselines3 expects of image-like arrays; only 0..5 occur.
                "voxels": spaces.Box(0, 255, shape=config.observation.shape, dtype=np.uint8),
                # Flat, because stable-baselines3 accepts 1-D and image-like arrays only.
                "candidates": spaces.Box(-1e4, 1e4, shape=(k * len(CANDIDATE_FEATURES),), dtype=np.float32),
                "pose": spaces.Box(-1e4, 1e4, shape=(4,), dtype=np.float32),
            }
        )
        self._scene_cache: dict[str, Scene] = {}
        self._episode: dict[str, Any] | None = None  # what reset was given, for pickling
        self._actions: list[int] = []
        self.robot: Robot | None = None

    # ------------------------------------------------------------------ scenes
    def _scene(self, spec: Any, start: Any) -> Scene:
        if isinstance(spec, Scene):
            scene = spec
        elif isinstance(spec, FloorPlan):
            scene = load_scene(spec)
        elif isinstance(spec, (str, Path)) and str(spec) == "generated":
            seed = int(self.np_random.integers(0, 2**31 - 1))
            scene = generate_plan(seed, self.config.generator).to_scene(source=f"generated:{seed}", validate=False)
        elif isinstance(spec, (str, Path)):
            key = str(spec)
            if key not in self._scene_cache:
                self._scene_cache[key] = load_scene(key, **self.config.scene_options)
            scene = self._scene_cache[key]
        else:
            raise ConfigError(
                f"options['scene'] must be a scene name, path, Scene or FloorPlan, got {type(spec).__name__}"
            )
        if start is not None:
            scene = copy.copy(scene)  # the cached scene keeps its own start
            scene.start = start
        # A start inside a wall or furniture is the caller's mistake; it is checked against the true
        # building, as a simulator checks where a robot is put down.
        xy = scene.start[:2]
        inside = not scene.rooms or any(shapely.contains_xy(Polygon(r.polygon), *xy) for r in scene.rooms)
        if not inside or not point_is_free(scene, xy, float(scene.start[2]), self.config.robot.navigation.robot_radius):
            raise InvalidPoseError(
                f"{scene.name}: start {np.round(scene.start[:2], 3).tolist()} is not free floor "
                f"(inside a wall or an object, or outside the building)"
            )
        return scene

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"scene", "start"})
        if unknown:
            raise ConfigError(f"reset options {unknown} are not known; use 'scene' and 'start'")
        self._episode = {"rng_state": self.np_random.bit_generator.state, "options": options}
        self._actions = []
        self._start(options)
        return self._observation(), self._info()

    def _start(self, options: dict[str, Any]) -> None:
        scene = self._scene(options.get("scene", self.config.scene), options.get("start"))
        self.scene = scene
        self.robot = Robot(scene, self.config.robot, self.np_random)
        self.meter = CoverageMeter(scene, self.config.coverage_spacing, self.config.coverage_radius)
        self.steps: list[_Step] = []
        self.door_events: list[dict[str, Any]] = []
        self.paths: list[np.ndarray] = []
        self.complete = False
        self._last_conversions = 0
        self._step_scans: list[tuple[np.ndarray, np.ndarray]] = []
        self._new_room = True
        self._record(self.robot.scan(), door=False)
        self._advance()

    def step(self, action: Any):
        if self.robot is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = self._check_action(action)
        self._step_scans = []
        self._new_room = False
        if self.complete or len(self.steps) >= self.config.max_scans:
            # Stepping past the end of an episode: nothing to do, nothing changes.
            return self._observation(), 0.0, self.complete, not self.complete, self._info()
        mask = self.action_masks()
        stop = a == self.stop_action
        if not mask[a] or (not stop and self.robot.candidates()[0].count == 0):
            info = self._info(invalid_action=True)
            return self._observation(), -self.config.reward.invalid_action_penalty, False, False, info
        self._actions.append(a)
        reward_cfg = self.config.reward
        before_pct = self.meter.percent()
        before_len = self.robot.path_length
        scans_before = len(self.steps)
        conversions = 0
        structural = max(1, self.robot.room_structural_voxels())
        if stop:
            self._advance(done=True)
        else:
            watched = self.robot.belief.occluded_structure_centres() if reward_cfg.kind == "conversions" else None
            cands, _ = self.robot.candidates()
            self.paths.append(cands.path(a))
            self._record(self.robot.move_to(a), door=False)
            if watched is not None and len(watched):
                conversions = int(np.count_nonzero(self.robot.belief.labels_at(watched) == VoxelLabel.STRUCTURE))
            self._advance()
        self._last_conversions = conversions
        scans = len(self.steps) - scans_before
        metres = self.robot.path_length - before_len
        gain = self.meter.percent() - before_pct if reward_cfg.kind == "coverage" else 100.0 * conversions / structural
        reward = gain - reward_cfg.scan_cost * scans - reward_cfg.metre_cost * metres
        terminated = self.complete
        truncated = not terminated and len(self.steps) >= self.config.max_scans
        return self._observation(), float(reward), terminated, truncated, self._info()

    def _check_action(self, action: Any) -> int:
        try:
            a = int(np.asarray(action).reshape(()))
            ok = float(np.asarray(action).reshape(())) == a
        except (TypeError, ValueError):
            ok = False
        if not ok or not (0 <= a < self.n_actions):
            raise InvalidActionError(f"action must be an integer in [0, {self.n_actions}), got {action!r}")
        return a

    def action_masks(self) -> np.ndarray:
        """(n_actions,) bool: which actions are real candidates (sb3-contrib's MaskablePPO reads
        this); with completion="policy" the last, "room done", is always allowed."""
        mask = np.zeros(self.n_actions, dtype=bool)
        if self.robot is None:
            return mask
        if not self.complete and len(self.steps) < self.config.max_scans:
            mask[: self.max_candidates] = self.robot.candidates()[0].mask
            if self.stop_action is not None:
                mask[self.stop_action] = True
        if not mask.any():
            # A finished episode keeps one action so that a masked sampler always has a choice;
            # stepping it changes nothing.
            mask[0] = True
        return mask

    def candidate_gains(self) -> np.ndarray:
        """(K,) int64: predicted Occluded-structure→Structure conversions of each candidate, from the
        robot's own grid (the paper's greedy criterion); 0 for padding."""
        if self.robot is None or self.complete:
            return np.zeros(self.max_candidates, dtype=np.int64)
        return self.robot.candidates()[1].copy()

    # ------------------------------------------------------------------ the storey
    def _room_complete(self, done: bool) -> bool:
        robot = self.robot
        assert robot is not None
        if self.config.completion == "gain":
            return robot.room_complete()
        return done or robot.room_exhausted()

    def _advance(self, done: bool = False) -> None:
        """Room completion (METHOD §7) and the door hand-over (METHOD §8), until a room is open.

        ``done``: the agent declared the room complete (completion="policy")."""
        robot = self.robot
        assert robot is not None
        while len(self.steps) < self.config.max_scans and self._room_complete(done):
            done = False  # the declaration was for the room the robot was in
            before = len(robot.doors)
            robot.finish_room()
            for door in robot.doors[before:]:
                self.door_events.append(
                    {
                        "event": "detected",
                        "scan": len(self.steps),
                        "room": door.found_in_room,
                        "centre": door.centre[:2].round(3).tolist(),
                        "width": round(float(door.width), 3),
                    }
                )
            while True:
                k = robot.next_door()
                if k is None:
                    self.complete = True
                    return
                if len(self.steps) >= self.config.max_scans:
                    return
                door = robot.doors[k]
                start = robot.pose[:2, 3].copy()
                try:
                    report = robot.cross_door(k)
                except UnreachableDoorError:
                    self.door_events.append(
                        {"event": "unreachable", "scan": len(self.steps), "centre": door.centre[:2].round(3).tolist()}
                    )
                    continue
                self.paths.append(np.array([start, door.centre[:2]]))
                self.door_events.append(
                    {
                        "event": "crossed",
                        "scan": len(self.steps),
                        "centre": door.centre[:2].round(3).tolist(),
                        "into_room": robot.room_index,
                    }
                )
                self._record(report, door=True)
                self._new_room = True
                break

    def _record(self, report: StepReport, door: bool) -> None:
        robot = self.robot
        assert robot is not None
        self._step_scans.append((report.world_points, report.estimated_pose[:3, 3].copy()))
        t = time.perf_counter()
        self.meter.add(report.world_points)
        evaluation = time.perf_counter() - t
        # Planning for the next decision belongs to this step: it runs now, not at the next call.
        robot.candidates()
        times = {**{s: 0.0 for s in STAGES}, **report.times, "planning": robot.planning_time, "evaluation": evaluation}
        processing = sum(times[s] for s in STAGES if s != "scan")
        self.steps.append(
            _Step(
                scan=len(self.steps),
                room=robot.room_index,
                door=door,
                true_position=report.true_pose[:3, 3].copy(),
                estimated_position=report.estimated_pose[:3, 3].copy(),
                predicted_gain=int(report.predicted_gain),
                path_length=robot.path_length,
                structure_sensed_pct=self.meter.percent(),
                processing_time=processing,
                acquisition_time=report.acquisition_time,
                points=report.points,
                structure_points=report.belief.structure_points,
                registration_error=robot.registration_error(),
                times=times,
            )
        )

    # ------------------------------------------------------------------ observation and info
    def _observation(self) -> dict[str, np.ndarray]:
        robot = self.robot
        assert robot is not None
        pose = robot.pose
        xy = pose[:2, 3]
        roi = robot.belief.roi
        floor_z = roi.floor_z if roi is not None else float(pose[2, 3] - self.config.robot.scanner.height)
        voxels = voxel_window(robot.belief.grid, xy, floor_z, self.config.observation)
        table = np.zeros((self.max_candidates, len(CANDIDATE_FEATURES)), dtype=np.float32)
        if not self.complete and len(self.steps) < self.config.max_scans:
            cands, gains = robot.candidates()
            table = candidate_table(cands.xy, cands.path_length, gains, cands.mask, xy, robot.room_structural_voxels())
        yaw = float(np.arctan2(pose[1, 0], pose[0, 0]))
        pose_vec = np.array([pose[0, 3], pose[1, 3], pose[2, 3], yaw], dtype=np.float32)
        return {
            "voxels": voxels,
            "candidates": np.clip(table, -1e4, 1e4).reshape(-1),
            "pose": np.clip(pose_vec, -1e4, 1e4),
        }

    def _info(self, invalid_action: bool = False) -> dict[str, Any]:
        robot = self.robot
        assert robot is not None
        last = self.steps[-1]
        m, deg = last.registration_error
        return {
            "scans": len(self.steps),
            "room": robot.room_index,
            "rooms_done": len(robot.rooms_done),
            "structure_sensed_pct": self.meter.percent(),
            "path_length_m": robot.path_length,
            "times": StageTimes(dict(last.times)),
            "registration_error_m": m,
            "registration_error_deg": deg,
            "door_events": list(self.door_events),
            "action_mask": self.action_masks(),
            "candidate_gains": self.candidate_gains(),
            "invalid_action": invalid_action,
            "conversions": self._last_conversions,
            "complete": self.complete,
            **({"belief": self.belief_view()} if self.config.expose_belief else {}),
        }

    def belief_view(self) -> BeliefView:
        """The robot's belief now (see :class:`BeliefView`)."""
        robot = self.robot
        assert robot is not None
        k = self.max_candidates
        xy, length, mask = np.zeros((k, 2)), np.zeros(k), np.zeros(k, dtype=bool)
        if not self.complete and len(self.steps) < self.config.max_scans:
            cands, _ = robot.candidates()
            xy[: cands.count], length, mask = cands.points, cands.path_length.astype(float), cands.mask
        return BeliefView(
            pose=robot.pose,
            room=robot.room_index,
            new_room=self._new_room,
            scans=list(self._step_scans),
            grid=robot.belief.grid,
            roi=robot.belief.roi,
            candidates_xy=xy,
            path_length=length,
            mask=mask,
            scanner=self.config.robot.scanner,
        )

    # ------------------------------------------------------------------ results
    def room_models(self) -> list[RoomModel]:
        """The recovered model of every room entered, the current one included."""
        robot = self.robot
        if robot is None:
            return []
        models = list(robot.room_models)
        if robot.room_index not in robot.rooms_done:
            current = robot.room_model()
            if current is not None:
                models.append(current)
        return models

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() was called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self.robot is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        from nbs_env.render import render_topdown

        robot = self.robot
        belief = robot.belief
        cands_xy = gains = None
        if not self.complete and len(self.steps) < self.config.max_scans:
            cands, all_gains = robot.candidates()
            cands_xy, gains = cands.points, all_gains[: cands.count]
        last = self.steps[-1]
        title = (
            f"{self.scene.name}: scan {len(self.steps)}, room {robot.room_index + 1}, "
            f"SE sensed {last.structure_sensed_pct:.1f}%, path {robot.path_length:.1f} m"
            + (" (complete)" if self.complete else "")
        )
        return render_topdown(
            grid=belief.grid,
            roi=belief.roi,
            se=belief.se,
            candidates_xy=cands_xy,
            gains=gains,
            paths=self.paths,
            stops=np.array([s.estimated_position[:2] for s in self.steps]),
            rooms=robot.room_models,
            title=title,
        )

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        # The episode holds Embree scenes and open3d clouds, which do not pickle; it is rebuilt on
        # unpickling by replaying the same reset and actions (a seed gives the same trajectory).
        return {
            "config": self.config,
            "render_mode": self.render_mode,
            "episode": self._episode,
            "actions": list(self._actions),
            "np_random_state": None if self._np_random is None else self.np_random.bit_generator.state,
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["config"], render_mode=state["render_mode"])
        episode = state["episode"]
        if episode is not None:
            self._np_random = np.random.Generator(np.random.PCG64())
            self._np_random.bit_generator.state = episode["rng_state"]
            self._episode = episode
            self._start(episode["options"])
            for a in state["actions"]:
                self.step(a)
        if state["np_random_state"] is not None:
            if self._np_random is None:
                self._np_random = np.random.Generator(np.random.PCG64())
            self._np_random.bit_generator.state = state["np_random_state"]
