"""The robot's cycle in one room, the storey session's room-and-door loop, and the coverage metric."""

from __future__ import annotations

import numpy as np
import pytest

from nbs_env.config import EnvConfig, RobotConfig, ScannerConfig, make_config
from nbs_env.evaluation import CoverageMeter, QualityConfig
from nbs_env.robot import Robot
from nbs_env.storey import Storey
from policies.greedy import scan_storey
from scenes import SurfaceClass, load_scene


def test_coverage_meter_counts_against_the_full_surface():
    scene = load_scene("office")
    meter = CoverageMeter(scene, spacing=0.1)
    assert meter.percent() == 0.0
    floor = meter.samples.points[meter.samples.labels == SurfaceClass.FLOOR]
    newly = meter.add(floor)
    # The floor samples, plus the wall samples within 5 cm of the floor.
    assert len(floor) <= newly < 1.05 * len(floor)
    assert meter.percent(label=SurfaceClass.FLOOR) == pytest.approx(100.0)
    assert 0.0 < meter.percent(label=SurfaceClass.WALL) < 5.0
    assert meter.percent() == pytest.approx(100 * newly / len(meter.samples))
    # Points 10 cm off the surface sense nothing.
    ceiling = meter.samples.points[meter.samples.labels == SurfaceClass.CEILING]
    meter.add(ceiling - [0, 0, 0.1])
    assert meter.percent(label=SurfaceClass.CEILING) == 0.0
    meter.add(meter.samples.points)
    assert meter.percent(room=0) == pytest.approx(100.0)


@pytest.mark.parametrize("radius", [0.05, 0.16])
def test_coverage_meter_senses_what_a_tree_over_each_scan_senses(radius):
    """The meter indexes the samples once (in plan columns) and queries each scan's points against
    them; the samples it marks are exactly those with a point within reach (the direct query from
    every sample into a tree of the scan's points), and each point goes to its nearest sample (a
    tree of the samples). At 16 cm a point has dozens of samples within reach; points far off the
    building reach none."""
    from scipy.spatial import cKDTree

    scene = load_scene("office")
    meter = CoverageMeter(scene, spacing=0.05, radius=radius)
    rng = np.random.default_rng(3)
    samples = meter.samples.points
    scans = [samples[rng.choice(len(samples), 4000)] + rng.normal(scale=0.03, size=(4000, 3)) for _ in range(3)]
    scans[1] = np.vstack([scans[1], [[100.0, 100.0, 100.0], [-50.0, 0.0, 1.0], [0.0, 0.0, -30.0]]])  # far off
    sensed = np.zeros(len(samples), dtype=bool)
    for k, points in enumerate(scans):
        origin = np.array([2.0, 2.0, 1.5])
        newly = meter.add(points, origin)
        distance, _ = cKDTree(points).query(samples, distance_upper_bound=radius)
        want = np.isfinite(distance)
        assert newly == np.count_nonzero(want & ~sensed)
        sensed |= want
        np.testing.assert_array_equal(meter.sensed, sensed)
        d, nearest = cKDTree(samples).query(points, distance_upper_bound=radius)
        index, count = np.unique(nearest[np.isfinite(d)], return_counts=True)
        np.testing.assert_array_equal(meter.observations[k][0], index)
        np.testing.assert_array_equal(meter.observations[k][1], count)
    assert meter.add(np.zeros((0, 3)), np.zeros(3)) == 0 and len(meter.observations[-1][0]) == 0


def test_quality_measures_density_incidence_and_range_of_each_sample():
    """One point on each floor sample, seen from 1.5 m above a point of the floor: the density is one
    point per sample's area, and the incidence and range are the geometry's."""
    scene = load_scene("office")
    meter = CoverageMeter(scene, spacing=0.1)
    floor = meter.samples.labels == SurfaceClass.FLOOR
    points = meter.samples.points[floor]
    origin = points[len(points) // 2] + [0.0, 0.0, 1.5]
    meter.add(points, origin)
    loose = QualityConfig(min_density=90.0, max_incidence=90.0, density_radius=0.25)
    report = meter.quality(loose)
    # 100 points per m² where every neighbour is a floor sample; less along the walls, whose
    # samples within 25 cm got no point.
    assert np.median(report.density[floor]) == pytest.approx(100.0, rel=1e-6)
    assert np.all(report.density <= 100.0 * (1 + 1e-5)) and np.all(report.density[~meter.sensed] == 0)
    # The incidence and range are the smallest within 25 cm: never above the sample's own, and
    # no more than 25 cm of floor away from it.
    d = np.linalg.norm(points[:, :2] - origin[:2], axis=1)
    own = np.degrees(np.arctan2(d, 1.5))
    inc, rng = report.incidence[floor], report.range[floor]
    assert np.all(inc <= own + 1e-3) and np.all(inc >= np.degrees(np.arctan2(np.maximum(d - 0.25, 0), 1.5)) - 1e-3)
    assert np.all(rng <= np.hypot(d, 1.5) + 1e-3) and np.all(rng >= 1.5 - 1e-3)
    # The shares: every sensed sample is square at 90°; at 60° only the floor within about 1.5·tan(60°).
    assert report.incidence_pct[-1] == pytest.approx(meter.percent())
    strict = meter.quality(QualityConfig(min_density=90.0, max_incidence=60.0, density_radius=0.25))
    share = 100.0 * np.count_nonzero(floor & (np.nan_to_num(strict.incidence, nan=90.0) <= 60.0)) / len(floor)
    assert share < 100.0 and np.all(d[inc <= 60.0 - 1e-3] <= 1.5 * np.tan(np.radians(60.0)) + 0.25 + 1e-6)
    # Density and incidence together never exceed either, nor the coverage.
    assert strict.quality_pct[-1] <= min(strict.dense_pct[-1], strict.incidence_pct[-1]) <= meter.percent() + 1e-9
    # A second pass doubles the density; the curves have one entry per scan.
    meter.add(points, origin)
    again = meter.quality(loose)
    assert np.median(again.density[floor]) == pytest.approx(200.0, rel=1e-6) and len(again.dense_pct) == 2


def greedy_run(scene_name: str, seed: int, config: RobotConfig | None = None, max_scans: int = 10):
    """Scan the first room of a scene greedily in a storey session (the paper's robot: every scan is
    the plan's, none a search's); returns its robot and meter."""
    scene = load_scene(scene_name)
    env_config = make_config("paper", robot=config or RobotConfig(), max_scans=max_scans)
    storey = Storey(scene, env_config, np.random.default_rng(seed))
    while storey.open and storey.rooms_done == 0:
        planned = storey.plan
        best = planned.best()
        storey.scan_at(best)
        # The scan's record carries the gain the plan predicted for the chosen NVP.
        assert storey.scans[len(storey.robot.stops) - 1].predicted_gain == planned.gains[best]
    return storey.robot, storey.meter


@pytest.mark.expensive
def test_greedy_scans_the_l_room():
    robot, meter = greedy_run("l_room", seed=0)
    assert len(robot.stops) <= 10
    assert meter.percent() >= 90.0
    assert robot.path_length > 3.0
    dt, dr = robot.registration_error()
    assert dt < 0.02 and dr < 0.2
    # Every stop keeps the robot's clearance from the true furniture and walls.
    from scenes.geometry import point_is_free

    assert all(point_is_free(robot._scanner.scene, stop[:2], 0.0, clearance=0.40) for stop in robot.stops)


def test_same_seed_same_trajectory():
    config = RobotConfig(scanner=ScannerConfig(angular_step=1.0), voxel_size=0.1, perfect_localisation=True)
    a, _ = greedy_run("office", seed=3, config=config, max_scans=3)
    b, _ = greedy_run("office", seed=3, config=config, max_scans=3)
    assert len(a.stops) == len(b.stops) >= 2
    assert all(np.array_equal(x, y) for x, y in zip(a.stops, b.stops, strict=True))
    # Perfect localisation: the belief is the truth.
    assert a.registration_error() == (0.0, 0.0)


def test_invalid_candidate_index():
    config = RobotConfig(scanner=ScannerConfig(angular_step=1.0), voxel_size=0.1, perfect_localisation=True)
    robot = Robot(load_scene("office"), config, np.random.default_rng(0))
    robot.scan()
    with pytest.raises(IndexError, match="not valid"):
        robot.move_to(999)


@pytest.mark.expensive
def test_the_robot_finds_the_door_and_scans_the_next_room(tmp_path, plan_dict):
    import json

    from scenes import load_scene as load

    plan_dict["clutter"] = [{"kind": "cabinet", "position": [1.0, 3.55], "size": [1.2, 0.5, 1.9], "yaw": 0}]
    path = tmp_path / "two.json"
    path.write_text(json.dumps(plan_dict))
    scene = load(str(path))
    storey = Storey(scene, EnvConfig(), np.random.default_rng(1))
    scan_storey(storey)
    meter = storey.meter
    rooms_entered, doors = storey.rooms.current + 1, storey.rooms.doors
    assert storey.complete
    assert rooms_entered == 2 and len(doors) == 1
    assert np.linalg.norm(doors[0].centre[:2] - [5.0, 2.0]) < 0.3  # the door between the rooms
    assert meter.percent(room=0) > 85.0 and meter.percent(room=1) > 85.0


def test_a_refused_registration_leaves_its_leg_to_the_next_scans_gates(monkeypatch):
    """A refused scan keeps its odometry pose, drift and all: the next scan's correction gates
    must allow for every metre since the last accepted registration (corpus:example_level1 lost
    three scans in a row to gates sized for one leg)."""
    import dataclasses

    import nbs_env.robot as robot_module
    from nbs_env.sensing.registration import register as real

    config = RobotConfig(scanner=ScannerConfig(angular_step=1.0), voxel_size=0.1)
    robot = Robot(load_scene("office"), config, np.random.default_rng(0))
    robot.scan()  # the first scan: S(t)'s frame, accepted
    seen, verdicts = [], iter([False, False, True, True])

    def register(points, initial, cloud, cfg, travelled=0.0):
        seen.append(travelled)
        result = real(points, initial, cloud, cfg, travelled=travelled)
        accepted = next(verdicts)
        return result if accepted else dataclasses.replace(result, pose=initial, accepted=False, reason="test")

    monkeypatch.setattr(robot_module, "register", register)
    for leg in (2.0, 3.0, 1.5, 4.0):
        robot.scan(path_length=leg)
    # Refused, refused, accepted, accepted: the legs add up until a scan is registered.
    assert seen == [2.0, 5.0, 6.5, 4.0]
    assert robot.unregistered_m == 0.0


def test_one_cloud_gives_one_coverage_at_every_preset():
    """The evaluation is not the robot's: the presets change the scanner and the voxels, never the
    samples or the radius coverage is counted with."""
    from nbs_env.config import PRESETS, make_config

    scene = load_scene("office")
    rng = np.random.default_rng(0)
    meters = [CoverageMeter(scene, c.coverage_spacing, c.coverage_radius) for c in map(make_config, PRESETS)]
    samples = meters[0].samples.points
    cloud = samples[rng.choice(len(samples), 3000)] + rng.normal(scale=0.04, size=(3000, 3))
    figures = [meter.add(cloud) and meter.percent() for meter in meters]
    assert 5.0 < figures[0] < 95.0 and max(figures) - min(figures) < 1.0, figures
