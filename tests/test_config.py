"""The configuration: every part checked on construction and reachable from EnvConfig, one override path,
a JSON round trip; one palette."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbs_env.config import (
    PRESETS,
    DoorConfig,
    EnvConfig,
    GainConfig,
    QualityConfig,
    RobotConfig,
    RoIConfig,
    RoomRules,
    ScannerConfig,
    WallSearchConfig,
    config_paths,
    make_config,
)
from nbs_env.errors import ConfigError
from nbs_env.labels import LABEL_COLOURS, VoxelLabel
from nbs_env.storey import Storey
from scenes import load_scene


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: DoorConfig(min_width=-0.1), "min_width"),
        (lambda: DoorConfig(min_width=2.0, max_width=1.0), "min_width <= max_width"),
        (lambda: DoorConfig(max_height=float("nan")), "max_height must be a finite number"),
        (lambda: DoorConfig(min_behind_points=-1), "min_behind_points must be an integer >= 0"),
        (lambda: RoIConfig(pixel=0.0), "pixel must be > 0"),
        (lambda: RoIConfig(azimuth_bins=2), "azimuth_bins must be an integer >= 4"),
        (lambda: RoIConfig(collinear_deg=95.0), "collinear_deg"),
        (lambda: GainConfig(tolerance_voxels=-1.0), "tolerance_voxels"),
        (lambda: GainConfig(occluded_clutter_blocks="yes"), "occluded_clutter_blocks"),
        (lambda: RoomRules(max_scans_per_room=0), "max_scans_per_room must be an integer >= 1"),
        (lambda: RoomRules(completion="agent"), "completion must be 'gain' or 'policy'"),
        (lambda: RoomRules(completion_fraction=1.0), "completion_fraction is a share"),
        (lambda: WallSearchConfig(scans=-1), "scans must be an integer >= 0"),
        (lambda: RobotConfig(voxel_size=5.0), "voxel_size must be within"),
        (lambda: QualityConfig(min_density=-1.0), "min_density must be within"),
        (lambda: QualityConfig(max_incidence=95.0), "max_incidence must be in"),
        (lambda: QualityConfig(density_radius=float("inf")), "density_radius must be a finite number"),
        (lambda: ScannerConfig(station_time=0.0), "station_time must be > 0"),
        (lambda: EnvConfig(max_scans=True), "max_scans must be an integer"),
    ],
)
def test_bad_values_are_refused_with_their_name(make, message):
    with pytest.raises(ConfigError, match=message):
        make()


def test_the_roi_and_door_configs_reach_the_robot(monkeypatch):
    import nbs_env.planning.rooms as rooms

    seen = []
    detect = rooms.detect_doors

    def spy(faces, scans, config=None, **kwargs):
        seen.append(config)
        return detect(faces, scans, config, **kwargs)

    monkeypatch.setattr(rooms, "detect_doors", spy)
    base = make_config("fast", scene="office")
    doors = DoorConfig(min_width=0.7, max_width=1.2)
    roi = RoIConfig(pixel=0.08, azimuth_bins=720)
    config = replace(base, robot=replace(base.robot, doors=doors, roi=roi), max_scans=14)
    storey = Storey(load_scene("office"), config, np.random.default_rng(0))
    assert storey.robot.belief.roi_config.pixel == 0.08
    # More azimuth bins than the 1° scanner's 360 columns are capped.
    assert storey.robot.belief.roi_config.azimuth_bins == 360
    while storey.open:
        storey.scan_at(storey.plan.best())
    assert storey.rooms_done == 1 and seen == [doors]
    assert storey.config.to_dict()["robot"]["doors"]["max_width"] == 1.2


def test_make_config_takes_dotted_and_unique_names_and_records_its_preset():
    config = make_config(
        "fast", completion_fraction=0.05, **{"rooms.wall_search.scans": 2, "robot.scanner": {"height": 1.2}}
    )
    assert config.preset == "fast" and config.robot.voxel_size == 0.1  # the preset's
    assert config.rooms.completion_fraction == 0.05 and config.rooms.wall_search.scans == 2
    # A dict merges into its section; the preset's 1° step stays.
    assert config.robot.scanner.height == 1.2 and config.robot.scanner.angular_step == 1.0
    # A configuration instance replaces its section whole.
    assert make_config("fast", robot=RobotConfig()).robot == RobotConfig()
    # From a configuration: its preset is kept, the overrides go on top.
    again = make_config(config, max_scans=7)
    assert again.preset == "fast" and again.max_scans == 7 and again.rooms == config.rooms
    with pytest.raises(ConfigError, match=r"ambiguous: name one of robot\.registration\.voxel_size, robot\.voxel_size"):
        make_config(voxel_size=0.1)
    with pytest.raises(ConfigError, match="no field 'voxels'"):
        make_config(voxels=0.1)
    with pytest.raises(ConfigError, match="unknown preset 'quick'"):
        make_config("quick")
    with pytest.raises(ConfigError, match="completion_fraction is a share"):
        make_config(**{"rooms.completion_fraction": 2.0})
    assert set(PRESETS) >= {"default", "fast"}


def test_a_recorded_configuration_reads_back_equal():
    import json

    config = make_config("fast", scene="five_rooms", completion="policy", **{"rooms.wall_search.heights": [0.5, 1.5]})
    text = json.dumps(config.to_dict())
    back = EnvConfig.from_dict(json.loads(text))
    assert back == config and isinstance(back.rooms.wall_search.heights, tuple)
    assert isinstance(back.robot.registration.max_correspondence, tuple)
    with pytest.raises(ConfigError, match=r"robot\.scanner has no field\(s\) \['angle'\]"):
        EnvConfig.from_dict({"robot": {"scanner": {"angle": 1.0}}})
    # Every dotted name config_paths lists is one make_config takes.
    for path in config_paths():
        if path.count(".") == 2 and not path.startswith("scene_options"):
            value = eval("config." + path)
            assert make_config(config, **{path: value}) == config, path


def test_one_palette_for_pictures_and_ply(tmp_path):
    import trimesh

    from nbs_env.mapping.voxels import VoxelGrid
    from nbs_env.render import LABEL_COLOURS as PICTURE

    np.testing.assert_allclose(PICTURE * 255, LABEL_COLOURS, atol=1e-9)
    labels = np.zeros((6, 1, 1), dtype=np.uint8)
    labels[:, 0, 0] = np.arange(6)
    grid = VoxelGrid(np.zeros(3), 0.1, labels)
    cloud = trimesh.load(grid.to_ply(tmp_path / "v.ply", include=list(VoxelLabel)))
    order = np.argsort(cloud.vertices[:, 0])
    assert np.array_equal(np.asarray(cloud.colors)[order, :3], LABEL_COLOURS)
    # Occluded-structure is green, Structure blue (the paper's Fig. 4).
    r, g, b = LABEL_COLOURS[VoxelLabel.OCCLUDED_STRUCTURE]
    assert g > r and g > b
    r, g, b = LABEL_COLOURS[VoxelLabel.STRUCTURE]
    assert b > r and b > g
