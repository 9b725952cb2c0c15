"""What an episode is made of: the robot, the storey's room rules, the reward, the observation and
the evaluation, put together in :class:`EnvConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nbs_env.config.checks import Config, _at_most, _finite, _integer, _plain_numbers, _require, _within
from nbs_env.config.robot import RobotConfig
from nbs_env.config.rooms import MAX_SCANS, RoomRules
from nbs_env.config.scanners import SCANNERS, datasheet_differences
from scenes.corpus import corpus_source_options
from scenes.generator import GeneratorConfig
from scenes.jsonio import json_text
from scenes.limits import UNITS
from scenes.loader import source_options

#: The most cells an observation window may have (64× the default 64 × 64 × 16): each is a float per
#: step and a network input.
MAX_WINDOW_CELLS = 1 << 22

__all__ = ["EnvConfig", "ObservationConfig", "QualityConfig", "RewardConfig"]


@dataclass(frozen=True)
class ObservationConfig(Config):
    """The voxel window of the observation.

    Attributes
    ----------
    shape : (int, int, int)
        Cells along x, y and z.
    cell : float
        Edge of an observation cell in metres (a whole number of voxels is best: 0.2 m pools 4³
        voxels of 5 cm or 2³ of 10 cm).
    below_floor : float
        How far below the robot's floor the window starts, metres (the floor slab must be inside).
    """

    shape: tuple[int, int, int] = (64, 64, 16)
    cell: float = 0.2
    below_floor: float = 0.2

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _require(
            len(self.shape) == 3 and all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in self.shape),
            f"shape must be three positive integers, got {self.shape}",
        )
        cells = math.prod(self.shape)  # Python ints: a float product overflowed to inf (10**200 cells)
        _require(
            cells <= MAX_WINDOW_CELLS,
            f"shape {str(tuple(self.shape))[:80]} has "
            f"{f'{cells:,}' if cells < 10**18 else f'about 10^{len(str(cells)) - 1}'} cells; "
            f"at most {MAX_WINDOW_CELLS:,} (the default has 65,536)",
        )
        _finite(cell=self.cell, below_floor=self.below_floor)
        _require(self.cell > 0, f"cell must be > 0 metres, got {self.cell}")
        # A window cell pools voxels (at least 1 cm); the window's extent is the cells times the shape.
        _within(self, "cell", 0.01, 10.0, "metres")
        _within(self, "below_floor", 0.0, 10.0, "metres")

    @property
    def extent(self) -> np.ndarray:
        """(3,) float: the window's size in metres."""
        return np.asarray(self.shape, dtype=float) * self.cell


@dataclass(frozen=True)
class QualityConfig(Config):
    """The scan-quality thresholds of the evaluation (:meth:`CoverageMeter.quality`).

    Coverage counts a structural sample as sensed once one point lies within 5 cm of it, whether
    that point came head-on from 3 m or at a grazing 85° from 20 m. Scan-to-BIM work judges a scan
    plan also by how densely and how squarely each surface was sampled; these thresholds say when a
    sample counts as well sensed.

    Attributes
    ----------
    min_density : float
        Least point density around a sample, points per m² of surface, over all scans. Default
        400 per m², one point per 5 cm × 5 cm: the scale at which the method works (its 5 cm
        working copies and voxels, RegistrationConfig.voxel_size, RobotConfig.voxel_size), so a
        surface below it is one the structural model rests on single points for. For context, the
        US GSA's BIM Guide for 3D Imaging (Series 03, v1.0, 2009; figures as recalled, not checked
        against a stored copy) asks for a 152 mm grid (about 43 per m²) at its level 1 and 25 mm
        (1,600 per m²) at its level 2. The env's 0.5° pattern puts 400 per m² on a wall seen head-on
        from at most 6.5 m; the fast preset's 1° pattern from 3.3 m.
    max_incidence : float
        Largest incidence angle, in degrees from the surface normal, at which a sample must have
        been seen at least once. Default 70°: there the laser footprint is 2.9 times as long as
        head-on, and the incidence angle's share of the range noise grows steeply (Soudarissanane
        et al. 2011, "Scanning geometry: influencing factor on the quality of terrestrial laser
        scanning points", ISPRS J. Photogramm. 66(4)), the range where scan planners set their limit.
    density_radius : float
        The density around a sample is the points attributed to the samples within this distance of
        it, over their area (the samples' count times the sample spacing squared), metres. 0.1 m
        holds about 12 samples at the default 5 cm spacing, so that one sample's share of a sparse
        pattern does not decide it.
    """

    min_density: float = 400.0
    max_incidence: float = 70.0
    density_radius: float = 0.1

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(min_density=self.min_density, max_incidence=self.max_incidence, density_radius=self.density_radius)
        # 10^8 per m² is a 0.1 mm spacing, ten times finer than any terrestrial scanner's finest
        # setting: a larger figure is a typo or a unit mistake, not a quality level.
        _require(
            0 <= self.min_density <= 1e8,
            f"min_density must be within [0, 1e8] points per m² (1e8: a 0.1 mm spacing), got {self.min_density}",
        )
        _require(0 < self.max_incidence <= 90, f"max_incidence must be in (0, 90] degrees, got {self.max_incidence}")
        _require(
            0 < self.density_radius <= 1, f"density_radius must be within (0, 1] metres, got {self.density_radius}"
        )


@dataclass(frozen=True)
class RewardConfig(Config):
    """What a step is worth.

    Attributes
    ----------
    kind : {"coverage", "mapped", "conversions"}
        ``"coverage"`` (default): the increase of the true structural surface sensed, in
        percentage points of the storey's structural surface (evaluation-side ground truth: the
        coverage meter must run). ``"mapped"``: the increase of the surface the robot itself
        labelled Structure (its Structure voxels, one voxel face each), in percentage points of the
        storey's structural surface as the mesh's structural faces give it: the robot's own
        account on the same scale as ``"coverage"``, without the meter (the training fidelity's
        reward). ``"conversions"``: the robot's own realised Occluded-structure→Structure
        conversions, in percent of the room's structural voxels.
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
        _plain_numbers(self)
        _require(
            self.kind in ("coverage", "mapped", "conversions"),
            f"reward kind must be 'coverage', 'mapped' or 'conversions', got {self.kind!r}",
        )
        _finite(
            scan_cost=self.scan_cost, metre_cost=self.metre_cost, invalid_action_penalty=self.invalid_action_penalty
        )
        # Costs are subtracted from a reward in percentage points of the storey's surface.
        for name in ("scan_cost", "metre_cost", "invalid_action_penalty"):
            _require(getattr(self, name) >= 0, f"{name} must be >= 0, got {getattr(self, name)}")
            _at_most(self, name, 1000.0)


#: The options :func:`scenes.load_scene` takes for a file (those of a generated storey are ``generator``'s).
SCENE_OPTIONS = ("storey", "doors", "class_map", "y_up", "units", "name", "validate")


def _check_scene_options(options: Any) -> None:
    """``scene_options`` holds options :func:`scenes.load_scene` takes, of their types: checked when
    the configuration is made, not at the first reset (a TypeError from deep in the loader)."""
    _require(
        isinstance(options, dict) and all(isinstance(k, str) for k in options),
        f"scene_options must be a dict of scenes.load_scene's options (e.g. {{'storey': 'Erdgeschoss'}}), "
        f"got {json_text(options, 80)}",
    )
    # A generated:SEED storey takes the generator's fields (checked by GeneratorConfig when it loads).
    generator = tuple(GeneratorConfig.__dataclass_fields__)
    unknown = sorted(set(options) - set(SCENE_OPTIONS) - set(generator))
    _require(
        not unknown,
        f"scene_options {unknown} are not options of scenes.load_scene; they are {list(SCENE_OPTIONS)} and, for "
        "generated:SEED, the generator's fields",
    )
    checks = {
        "storey": (
            lambda v: (
                (isinstance(v, str) and v.strip() != "") or (isinstance(v, int) and not isinstance(v, bool) and v >= 0)
            ),
            "a storey's name or index",
        ),
        "doors": (lambda v: v in ("open", "closed"), "'open' or 'closed'"),
        "class_map": (lambda v: isinstance(v, dict), "a dict of IFC classes to surface classes"),
        "y_up": (lambda v: isinstance(v, bool), "a bool"),
        "validate": (lambda v: isinstance(v, bool), "a bool"),
        "units": (lambda v: isinstance(v, str) and v in UNITS, f"one of {', '.join(UNITS)}"),
        "name": (lambda v: isinstance(v, str), "a string"),
    }
    for key, value in options.items():
        if key not in checks:
            continue
        valid, what = checks[key]
        _require(valid(value), f"scene_options['{key}'] must be {what}, got {json_text(value, 80)}")


@dataclass(frozen=True)
class EnvConfig(Config):
    """Everything an :class:`NBSEnv` is made of (JSON-safe, frozen).

    Attributes
    ----------
    preset : str
        The named preset this configuration started from (:data:`nbs_env.config.PRESETS`), as
        :func:`~nbs_env.config.make_config` records it; ``"default"`` for ``EnvConfig()``.
    scene : str
        What ``reset`` loads when its options name no scene: anything :func:`scenes.load_scene`
        takes (a bundled name, a file, ``generated:SEED``), or ``"generated"`` for a fresh storey
        per reset drawn from the env's generator with ``generator``.
    scene_options : dict
        Options for :func:`scenes.load_scene` (e.g. ``{"storey": "Erdgeschoss"}`` for IFC).
    generator : GeneratorConfig
        The storeys ``"generated"`` draws.
    robot : RobotConfig
        The robot: hardware and the stages of a scan cycle.
    rooms : RoomRules
        The storey's rules for rooms: who ends a room and when, its scan cap, the door searches.
    reward : RewardConfig
    observation : ObservationConfig
    max_scans : int
        The scan budget of an episode; reaching it truncates.
    expose_belief : bool
        Put a :class:`BeliefView` of the robot's belief (its grid, RoI, candidates, this step's
        registered scans) in ``info["belief"]``, for policies that keep their own maps. References,
        not copies: use it in-process only (it does not pickle).
    coverage_spacing, coverage_radius : float
        Ground-truth sample spacing and sensing radius of the evaluation, metres: 5 cm, the scale
        the method works at, for every preset (the fast preset's 10 cm radius reached the top of a
        suspended ceiling through its underside, and counted a 1° pattern's gaps as sensed).
    quality : QualityConfig
        The evaluation's scan-quality thresholds (point density, incidence angle).
    keep_scans : bool
        Keep every scan's measured points in the scanner frame with its estimated pose
        (:attr:`Storey.scan_log`), for the E57 export of ``nbs scan``: 10 bytes a point, about
        1.4 MB a scan at the default 0.5° pattern and 6 MB at 0.2°.
    travel_speed : float
        Driving speed for the travel time, m/s.
    coverage_meter : bool
        Run the ground-truth coverage meter (True, the default). Off, nothing measures the true
        surface sensed: ``info["structure_sensed_pct"]`` is None, the reward must be robot-side
        (``reward.kind`` other than ``"coverage"``), and a reset skips the meter's sampling of the
        storey's interior (most of a reset's time). The training fidelity turns it off.
    """

    preset: str = "default"
    scene: str = "generated"
    scene_options: dict[str, Any] = field(default_factory=dict)
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    rooms: RoomRules = field(default_factory=RoomRules)
    reward: RewardConfig = field(default_factory=RewardConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    max_scans: int = 80
    expose_belief: bool = False
    coverage_spacing: float = 0.05
    coverage_radius: float = 0.05
    quality: QualityConfig = field(default_factory=QualityConfig)
    keep_scans: bool = False
    travel_speed: float = 0.5
    coverage_meter: bool = True

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _require(
            isinstance(self.scene, str) and self.scene != "", f"scene must be a non-empty string, got {self.scene!r}"
        )
        _integer(self, "max_scans", 1)
        _require(self.max_scans <= MAX_SCANS, f"max_scans must be at most {MAX_SCANS:,}, got {self.max_scans:,}")
        _finite(
            coverage_spacing=self.coverage_spacing, coverage_radius=self.coverage_radius, travel_speed=self.travel_speed
        )
        # The samples number (structural area / spacing²): below a centimetre, more than memory.
        _require(
            0.01 <= self.coverage_spacing <= 1,
            f"coverage_spacing must be within [0.01, 1] metres, got {self.coverage_spacing}",
        )
        # The meter's sensing radius: below a centimetre (the spacing's bound) its grid's cells
        # (radius-sized) overflow their count.
        _require(
            0.01 <= self.coverage_radius <= 1,
            f"coverage_radius must be within [0.01, 1] metres, got {self.coverage_radius}",
        )
        _check_scene_options(self.scene_options)
        if self.scene != "generated" and isinstance(self.scene, str):
            # Refused here, not at the first reset: whether a scene takes an option its name tells.
            if self.scene.startswith("corpus:"):
                kind, allowed = corpus_source_options(self.scene[len("corpus:") :])
            else:
                kind, allowed = source_options(self.scene)
            odd = sorted(set(self.scene_options) - set(allowed))
            _require(
                not odd,
                f"scene_options {odd} do not apply to scene {self.scene[:80]!r} ({kind}), which takes {list(allowed)}",
            )
        _require(isinstance(self.expose_belief, bool), f"expose_belief must be a bool, got {self.expose_belief!r}")
        preset = self.robot.scanner.preset
        if preset is not None:
            # metrics.json records it as the scanner the run simulated: only a datasheet's setting.
            presets = [f"{m.name}:{st.name}" for m in SCANNERS.values() for st in m.settings]
            _require(
                preset in presets,
                f"robot.scanner.preset must be None or a datasheet scanner's NAME:SETTING ({', '.join(presets)}), "
                f"got {json_text(preset, 60)}",
            )
            odd = datasheet_differences(self.robot.scanner)
            _require(
                not odd,
                f"robot.scanner.preset {preset!r} records the {SCANNERS[preset.split(':')[0]].title} at its "
                f"{preset.split(':')[1]} setting, but the scanner holds {', '.join(odd[:4])}"
                f"{f' and {len(odd) - 4} more' if len(odd) > 4 else ''}: use --scanner {preset} (in Python "
                f"scanner_config({preset!r})) for the datasheet's values, or set robot.scanner.preset to null "
                "for a scanner set by hand",
            )
        _require(self.travel_speed > 0, f"travel_speed must be > 0, got {self.travel_speed}")
        # The travel time is metres over the speed: a millimetre a second is already days per storey.
        _within(self, "travel_speed", 0.001, 100.0, "m/s")
        _require(isinstance(self.preset, str), f"preset must be a preset's name, got {self.preset!r}")
        _require(isinstance(self.coverage_meter, bool), f"coverage_meter must be a bool, got {self.coverage_meter!r}")
        _require(
            self.coverage_meter or self.reward.kind != "coverage",
            "reward.kind 'coverage' reads the coverage meter: with coverage_meter=False use 'mapped' or 'conversions'",
        )
        _require(
            self.robot.predict_gains or self.rooms.completion == "policy",
            "rooms.completion='gain' needs robot.predict_gains (the room ends when the predicted gain is small)",
        )
