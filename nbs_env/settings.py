"""The env's configuration: what a robot, a reward and an episode are made of, and the named presets.

Every configuration is a frozen dataclass with JSON-safe fields, checked on construction;
``EnvConfig.to_dict()`` is what ``metrics.json`` records. The parts live beside the code that reads
them (:class:`~nbs_env.config.ScannerConfig`, :class:`~nbs_env.planning.navigation.NavigationConfig`,
:class:`~nbs_env.planning.visibility.GainConfig`, :class:`~nbs_env.perception.roi.RoIConfig`,
:class:`~nbs_env.perception.doors.DoorConfig`, :class:`~nbs_env.observation.ObservationConfig`,
:class:`scenes.GeneratorConfig`); this module puts them together.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from nbs_env.config import Config, OdometryConfig, RegistrationConfig, ScannerConfig, _finite, _integer, _require
from nbs_env.errors import ConfigError
from nbs_env.evaluation import QualityConfig
from nbs_env.observation import ObservationConfig
from nbs_env.perception.doors import DoorConfig
from nbs_env.perception.roi import RoIConfig
from nbs_env.planning.navigation import NavigationConfig
from nbs_env.planning.planner import GAIN_MODELS, PlanningConfig
from nbs_env.planning.visibility import GainConfig
from nbs_env.planning.wall_search import WallSearchConfig
from scenes.generator import GeneratorConfig

__all__ = ["PRESETS", "EnvConfig", "RewardConfig", "RobotConfig", "make_config"]


@dataclass(frozen=True)
class RobotConfig(Config):
    """Everything the robot is made of (JSON-safe, frozen).

    Attributes
    ----------
    scanner, odometry, registration : ScannerConfig, OdometryConfig, RegistrationConfig
        The sensor, its motion drift and the ICP.
    navigation : NavigationConfig
        The robot's footprint and the candidate list.
    gain : GainConfig
        The greedy's gain model (``gain.model`` selects it) and its options.
    roi : RoIConfig
        The dynamic RoI. Its ``azimuth_bins`` is capped at the scanner's columns (more bins than
        columns leave most bins empty, and the RoI would refuse a door-frame scan).
    doors : DoorConfig
        The limits of a door opening.
    voxel_size : float
        Edge of the voxels of V(t), metres.
    completion_fraction : float
        The room is complete when the best predicted gain falls below this share of the room's
        structural voxels (Structure + Occluded-structure), METHOD §7. METHOD's 1% was changed to 3%
        after measuring greedy runs (default config, seed 0): on ``five_rooms`` 1% took 30 scans for
        95.0% of the structural surface, 3% 21 scans for 93.6%, 5% 17 scans for 93.6%; on six
        generated 2-3-room storeys (seeds 500000-500005) 1% took 88 scans for a mean 80.9%, 3% 73
        scans for 88.1%, 5% 49 scans for 78.0% (the coverage there depends mostly on which doors are
        found, which changes with the scans taken).
    max_scans_per_room : int
        The scan cap per room.
    perfect_localisation : bool
        Skip odometry drift and registration (the belief is the true pose): for fast RL.
    predict_gains : bool
        Compute the greedy's predicted gain of every NVP. Policies with their own utility turn it
        off, so that their processing time does not carry the greedy's; room completion by gain
        (METHOD §7) then cannot run.
    wall_search_scans : int
        Door-search scans per room, at most, before its hand-over
        (:mod:`nbs_env.planning.wall_search`): a scan from the NVP that views most of the room's
        wall no stop viewed frontally, taken when the room would end (by the gain rule or by a
        policy's "room done"); the gain rule may then reopen the room. 0 (default) is the paper's
        method: a room ends by its gain alone, and a door on a wall no scan faced is not found.
    wall_search : WallSearchConfig
        How the search samples the walls and when a wall counts as viewed.
    """

    scanner: ScannerConfig = field(default_factory=ScannerConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    navigation: NavigationConfig = field(default_factory=NavigationConfig)
    gain: GainConfig = field(default_factory=GainConfig)
    roi: RoIConfig = field(default_factory=RoIConfig)
    doors: DoorConfig = field(default_factory=DoorConfig)
    voxel_size: float = 0.05
    completion_fraction: float = 0.03
    max_scans_per_room: int = 12
    perfect_localisation: bool = False
    predict_gains: bool = True
    wall_search_scans: int = 0
    wall_search: WallSearchConfig = field(default_factory=WallSearchConfig)

    def __post_init__(self) -> None:
        _finite(voxel_size=self.voxel_size, completion_fraction=self.completion_fraction)
        _require(0.01 <= self.voxel_size <= 1.0, f"voxel_size must be within [0.01, 1] metres, got {self.voxel_size}")
        _require(
            0.0 <= self.completion_fraction < 1.0,
            f"completion_fraction is a share in [0, 1), got {self.completion_fraction}",
        )
        _integer(self, "max_scans_per_room", 1)
        _integer(self, "wall_search_scans", 0)
        _require(
            self.gain.model in GAIN_MODELS,
            f"unknown gain model {self.gain.model!r}; registered: {', '.join(sorted(GAIN_MODELS))}",
        )

    @property
    def planning(self) -> PlanningConfig:
        """What the planner reads of this configuration."""
        return PlanningConfig(self.scanner, self.navigation, self.gain, self.predict_gains)


@dataclass(frozen=True)
class RewardConfig(Config):
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
class EnvConfig(Config):
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
    quality : QualityConfig
        The evaluation's scan-quality thresholds (point density, incidence angle).
    keep_scans : bool
        Keep every scan's measured points in the scanner frame with its estimated pose
        (:attr:`Storey.scan_log`), for the E57 export of ``nbs scan``: 10 bytes a point, about
        1.4 MB a scan at the default 0.5° pattern and 6 MB at 0.2°.
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
    quality: QualityConfig = field(default_factory=QualityConfig)
    keep_scans: bool = False
    travel_speed: float = 0.5

    def __post_init__(self) -> None:
        _require(
            isinstance(self.scene, str) and self.scene != "", f"scene must be a non-empty string, got {self.scene!r}"
        )
        _integer(self, "max_scans", 1)
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
