"""Bounds of the configuration found by the second robustness probe: values that were accepted and
then crashed or asked for unbounded memory or time are refused by ``make_config`` with a message
naming the dotted key, the boundary values pass, and numpy numbers are taken as plain ones.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from nbs_env import make_config
from nbs_env.config import SCANNERS, scanner_config
from nbs_env.errors import ConfigError

#: (dotted key, refused value): the probe's cases first, then one per class of bad input.
REFUSED = [
    # N1: a pair that is not one.
    ("generator.rooms", []),
    ("generator.rooms", [1]),
    ("generator.rooms", [3, 1]),
    ("generator.rooms", [1.5, 2]),
    ("generator.rooms", [True, 2]),
    ("generator.rooms", "2"),
    ("generator.cell_size", []),
    ("generator.cell_size", [3.0]),
    ("generator.cell_size", [4.0, 3.0]),
    ("generator.cell_size", [2.0, math.nan]),
    ("generator.cell_size", [2.0, 1e9]),
    ("generator.ceiling_height", [2.5]),
    ("generator.max_attempts", 10**12),
    ("generator.max_attempts", 0),
    ("generator.windows", "a"),
    # N2
    ("rooms.wall_search.step", 1e-9),
    ("rooms.wall_search.step", 1e6),
    ("rooms.wall_search.heights", [1.0] * 101),
    ("rooms.wall_search.scans", 10**9),
    ("rooms.wall_search.max_range", 1e300),
    # N3
    ("robot.registration.voxel_size", 1e-9),
    ("robot.registration.voxel_size", 100.0),
    # N4
    ("robot.registration.neighbours", 10**12),
    ("robot.registration.neighbours", 1e12),
    # N5 and the registration's other counts and thresholds
    ("robot.registration.max_iterations", 10**12),
    ("robot.registration.max_iterations", 1e12),
    ("robot.registration.max_iterations", 2.5),
    ("robot.registration.min_points", 10**12),
    ("robot.registration.min_inliers", -1),
    ("robot.registration.convergence", 0.0),
    ("robot.registration.convergence", math.inf),
    ("robot.registration.max_correspondence", [math.inf]),
    ("robot.registration.max_correspondence", [0.5] * 11),
    ("robot.registration.stage_voxels", [0.3, 0.2, 1e6]),
    ("robot.registration.correction_per_metre_m", math.nan),
    ("robot.registration.correction_per_metre_deg", -1.0),
    ("robot.registration.max_rmse", -0.01),
    ("robot.registration.target_radius", 1e12),
    ("robot.registration.crop_margin", 1e12),
    ("robot.registration.deterministic", 1),
    # N6
    ("coverage_radius", 1e-9),
    ("coverage_radius", 0.0),
    # N22
    ("robot.scanner.angular_step", 1e12),
    ("robot.scanner.angular_step", 46.0),
    ("robot.scanner.height", -1.0),
    ("robot.scanner.height", 0.0),
    ("robot.scanner.height", 1e12),
    ("robot.scanner.instrument_step", 1e-300),
    ("robot.scanner.points_per_second", 1e-300),
    ("robot.scanner.range_noise", 1e6),
    ("robot.scanner.station_time", 1e12),
    # every other section: too small a size, too big a count, negative, not finite, a bool
    ("robot.odometry.sigma_tilt_deg", 1e6),
    ("robot.navigation.robot_radius", 1e6),
    ("robot.gain.group", 10**6),
    ("robot.gain.tolerance_voxels", 1e12),
    ("robot.roi.band_above_floor", 1e12),
    ("robot.doors.max_extension", 1e12),
    ("robot.doors.min_behind_points", 10**12),
    ("rooms.max_scans_per_room", 10**12),
    ("observation.cell", 1e-9),
    ("observation.below_floor", -1.0),
    ("reward.scan_cost", 1e300),
    ("reward.invalid_action_penalty", -1.0),
    ("max_scans", 10**12),
    ("travel_speed", 1e-300),
    ("coverage_spacing", True),
]


@pytest.mark.parametrize(("key", "value"), REFUSED, ids=[f"{k}={v!r}"[:60] for k, v in REFUSED])
def test_refused_with_the_dotted_key(key, value):
    with pytest.raises(ConfigError) as caught:
        make_config("fast", **{key: value})
    assert key in str(caught.value)
    assert "\n" not in str(caught.value)


#: Values at (or just inside) the new bounds: each builds.
ACCEPTED = [
    ("generator.rooms", 1),
    ("generator.rooms", [8, 8]),
    ("generator.cell_size", [1.8, 10.0]),
    ("generator.max_attempts", 1),
    ("rooms.wall_search.step", 0.01),
    ("rooms.wall_search.step", 5.0),
    ("robot.registration.voxel_size", 0.01),
    ("robot.registration.stage_voxels", None),
    ("robot.registration.neighbours", 5),
    ("robot.registration.neighbours", 1000),
    ("robot.registration.max_iterations", 1),
    ("robot.registration.max_iterations", 10_000),
    ("robot.registration.convergence", 1.0),
    ("coverage_radius", 0.01),
    ("coverage_radius", 1.0),
    ("robot.scanner.angular_step", 45.0),
    ("robot.scanner.height", 10.0),
    ("robot.scanner.height", 0.1),
    ("robot.scanner.instrument_step", 0.001),
    ("max_scans", 100_000),
    ("travel_speed", 0.001),
    ("observation.cell", 0.01),
]


@pytest.mark.parametrize(("key", "value"), ACCEPTED, ids=[f"{k}={v!r}" for k, v in ACCEPTED])
def test_the_bounds_themselves_pass(key, value):
    config = make_config("fast", **{key: value})
    *sections, leaf = key.split(".")
    node = config
    for part in sections:
        node = getattr(node, part)
    got = getattr(node, leaf)
    assert got == (tuple(value) if isinstance(value, list) else value)


def test_the_coarsest_registration_voxel_passes_with_stages_as_coarse():
    config = make_config("fast", **{"robot.registration.voxel_size": 2.0, "robot.registration.stage_voxels": [2, 2, 2]})
    assert config.robot.registration.voxel_size == 2.0


def test_presets_and_scanner_datasheets_stay_valid():
    for preset in ("default", "paper", "fast", "train"):
        json.dumps(make_config(preset).to_dict())
    for model in SCANNERS.values():
        for setting in model.setting_names:
            scanner_config(f"{model.name}:{setting}")


def test_numpy_numbers_are_taken_as_plain_ones():
    config = make_config(
        "fast",
        max_scans=np.int64(3),
        coverage_radius=np.float64(0.05),
        **{
            "robot.navigation.max_candidates": np.int32(32),
            "robot.scanner.height": np.float32(1.25),
            "robot.registration.max_correspondence": [np.float64(0.5), np.float64(0.1)],
            "robot.registration.stage_voxels": [np.float64(0.2), np.float64(0.1)],
            "observation.shape": [np.int64(32), np.int64(32), np.int64(8)],
            "generator.rooms": [np.int64(1), np.int64(2)],
            "generator.cell_size": [np.float64(2.0), np.float64(3.0)],
        },
    )
    assert config.max_scans == 3 and type(config.max_scans) is int
    assert type(config.coverage_radius) is float
    assert type(config.robot.navigation.max_candidates) is int
    assert type(config.robot.scanner.height) is float and config.robot.scanner.height == 1.25
    assert all(type(d) is float for d in config.robot.registration.max_correspondence)
    assert all(type(n) is int for n in config.observation.shape)
    assert config.generator.rooms == (1, 2) and all(type(n) is int for n in config.generator.rooms)
    assert all(type(c) is float for c in config.generator.cell_size)
    json.dumps(config.to_dict())  # JSON-safe: numpy's int64 is not


def test_bools_and_numpy_floats_are_no_integers():
    for value in (True, np.bool_(True), np.float64(3.0), 3.0):
        with pytest.raises(ConfigError, match="max_scans"):
            make_config("fast", max_scans=value)
    with pytest.raises(ConfigError, match="coverage_spacing"):
        make_config("fast", coverage_spacing=False)


@pytest.mark.parametrize(
    "key", ["rooms.wall_search.heights", "robot.registration.max_correspondence", "observation.shape"]
)
def test_a_number_where_a_list_is_wanted_names_the_key(key):
    """It was Python's "'float' object is not iterable", naming the section."""
    with pytest.raises(ConfigError, match=f"^{key} must be a list, got 1.0$"):
        make_config("fast", **{key: 1.0})


@pytest.mark.parametrize("preset", ["nope", "", "rtc360:1mm"])
def test_a_scanner_preset_must_be_a_datasheet_setting(preset):
    """metrics.json recorded "nope" as the scanner a run simulated."""
    with pytest.raises(ConfigError, match=r"robot\.scanner\.preset must be None or a datasheet scanner's NAME:SETTING"):
        make_config("fast", **{"robot.scanner.preset": preset})
