"""Odometry drift, ICP registration into S(t), and the accumulated cloud."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from nbs_env.config import OdometryConfig, RegistrationConfig, ScannerConfig
from nbs_env.mapping.cloud import AccumulatedCloud
from nbs_env.sensing.odometry import Odometry, path_length
from nbs_env.sensing.pose import planar, pose_error, pose_from_xyz_rpy, yaw_of
from nbs_env.sensing.registration import level_from_floor, register
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene
from scenes.geometry import STOREY_CLEARANCE, point_is_free


def second_stop(scene, rng):
    """A free point 0.5-1.5 m from the start, in the simulator's truth."""
    rooms = [Polygon(r.polygon) for r in scene.rooms]
    for _ in range(200):
        p = scene.start[:2] + rng.uniform(-1.5, 1.5, 2)
        inside = any(room.contains(Point(p)) for room in rooms)
        if inside and np.linalg.norm(p - scene.start[:2]) >= 0.5 and point_is_free(scene, p, 0.0, STOREY_CLEARANCE):
            return p
    return scene.start[:2]


def perturb(pose, rng, max_shift=0.3, max_yaw_deg=5.0):
    d = rng.normal(size=2)
    d = d / np.linalg.norm(d) * rng.uniform(0.0, max_shift)
    yaw = yaw_of(pose) + np.radians(rng.uniform(-max_yaw_deg, max_yaw_deg))
    return planar(pose[0, 3] + d[0], pose[1, 3] + d[1], yaw, pose[2, 3])


@pytest.mark.expensive
def test_icp_recovers_known_perturbations_on_generated_storeys():
    rng = np.random.default_rng(2024)
    cfg = ScannerConfig(angular_step=0.5)
    good, trials = 0, 40
    errors = []
    for trial in range(trials):
        scene = load_scene(f"generated:{trial}", rooms=(1, 3))
        scanner = Scanner(scene, cfg)
        odometry = Odometry(OdometryConfig(), rng)
        t0 = odometry.true_sensor_pose(scene.start[:2], rng.uniform(-np.pi, np.pi), 0.0, cfg.height)
        cloud = AccumulatedCloud()
        first = scanner.scan(t0, rng)
        cloud.add(first.truth.points_world, t0[:3, 3])
        t1 = odometry.true_sensor_pose(second_stop(scene, rng), rng.uniform(-np.pi, np.pi), 0.0, cfg.height)
        result = register(scanner.scan(t1, rng).points, perturb(t1, rng), cloud)
        dt, dr = pose_error(result.pose, t1)
        errors.append((dt, dr))
        good += result.accepted and dt < 0.02 and dr < 0.2
    assert good >= 0.95 * trials, errors


def _l_room_first_scan(seed: int):
    """(scanner, rng, first pose, S(t) holding the first scan's noise-free points) in l_room."""
    rng = np.random.default_rng(seed)
    scanner = Scanner(load_scene("l_room"), ScannerConfig(angular_step=0.5))
    t0 = pose_from_xyz_rpy(3.0, 4.5, 1.5)
    cloud = AccumulatedCloud()
    cloud.add(scanner.scan(t0, rng).truth.points_world, t0[:3, 3])
    return scanner, rng, t0, cloud


def test_icp_recovers_roll_and_pitch_the_odometry_cannot_see():
    scanner, rng, _, cloud = _l_room_first_scan(5)
    t1 = pose_from_xyz_rpy(2.0, 5.5, 1.5, np.radians(0.4), np.radians(-0.3), 0.5)
    initial = planar(2.0 + 0.1, 5.5 - 0.05, 0.5 + np.radians(2), 1.5)
    result = register(scanner.scan(t1, rng).points, initial, cloud)
    assert result.accepted, result.reason
    dt, dr = pose_error(result.pose, t1)
    assert dt < 0.01 and dr < 0.1
    assert pose_error(initial, t1)[1] > 2.0  # the starting error was real


def test_a_two_metre_error_is_rejected():
    rng = np.random.default_rng(3)
    scene = load_scene("five_rooms")
    scanner = Scanner(scene, ScannerConfig(angular_step=0.5))
    t0 = pose_from_xyz_rpy(*scene.start[:2], 1.5)
    cloud = AccumulatedCloud()
    cloud.add(scanner.scan(t0, rng).truth.points_world, t0[:3, 3])
    t1 = pose_from_xyz_rpy(scene.start[0] + 0.8, scene.start[1] + 0.5, 1.5, 0, 0, 0.3)
    wrong = t1.copy()
    wrong[:2, 3] += [2.0, 0.0]
    result = register(scanner.scan(t1, rng).points, wrong, cloud)
    assert not result.accepted
    assert result.reason
    assert np.array_equal(result.pose, wrong)  # a rejected ICP keeps the odometry pose


def test_first_scan_is_accepted_as_is():
    cloud = AccumulatedCloud()
    pose = pose_from_xyz_rpy(1, 2, 1.5)
    result = register(np.random.default_rng(0).normal(size=(100, 3)), pose, cloud)
    assert result.accepted and np.array_equal(result.pose, pose)


def test_odometry_drift_grows_with_distance():
    cfg = OdometryConfig(sigma_xy_per_m=0.02, sigma_yaw_deg_per_m=0.5, sigma_tilt_deg=0.0)
    start = planar(0, 0, 0, 1.5)
    for distance, expected in ((1.0, 0.02), (5.0, 0.1)):
        errs, yaws = [], []
        odometry = Odometry(cfg, np.random.default_rng(11))
        end = planar(distance, 0, 0, 1.5)
        for _ in range(2000):
            believed = odometry.drive(start, start, end, distance)
            errs.append(believed[:2, 3] - end[:2, 3])
            yaws.append(np.degrees(yaw_of(believed)))
        assert np.std(np.asarray(errs), axis=0) == pytest.approx([expected, expected], rel=0.1)
        assert np.std(yaws) == pytest.approx(0.5 * distance, rel=0.1)
    # Driving nowhere adds no error.
    assert np.allclose(Odometry(cfg, np.random.default_rng(0)).drive(start, start, start, 0.0), start)


def test_odometry_is_deterministic_for_a_seed():
    a = Odometry(None, np.random.default_rng(4)).drive(planar(0, 0, 0), planar(0, 0, 0), planar(3, 1, 1), 3.2)
    b = Odometry(None, np.random.default_rng(4)).drive(planar(0, 0, 0), planar(0, 0, 0), planar(3, 1, 1), 3.2)
    assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="distance"):
        Odometry(None, np.random.default_rng(4)).drive(planar(0, 0, 0), planar(0, 0, 0), planar(3, 1, 1), np.nan)


def test_true_pose_has_small_tilt():
    odometry = Odometry(OdometryConfig(sigma_tilt_deg=0.2), np.random.default_rng(0))
    tilts = [
        pose_error(odometry.true_sensor_pose(np.zeros(2), 0.0, 0.0, 1.5), planar(0, 0, 0, 1.5))[1] for _ in range(500)
    ]
    # The angle of a 2-D Gaussian tilt is Rayleigh distributed: mean = sigma * sqrt(pi / 2).
    assert np.mean(tilts) == pytest.approx(0.2 * np.sqrt(np.pi / 2), rel=0.1)


def test_accumulated_cloud_keeps_full_resolution_and_rooms():
    rng = np.random.default_rng(0)
    cloud = AccumulatedCloud(voxel_size=0.1)
    a = rng.uniform(0, 5, size=(20000, 3))
    b = rng.uniform(5, 10, size=(10000, 3))
    cloud.add(a, np.zeros(3), room=0)
    cloud.add(b, np.zeros(3), room=1)
    assert len(cloud) == 2 and cloud.n_points == 30000
    assert np.array_equal(cloud.room_points(1), b)
    assert len(cloud.storey_points()) == 30000
    work = cloud.working_points()
    assert len(work) < 30000 and cloud.working_cloud().has_normals()
    assert len(cloud.working_points(room=0)) < len(work)
    with pytest.raises(ValueError, match="finite"):
        cloud.add(np.full((3, 3), np.nan), np.zeros(3))


def test_path_length():
    assert path_length(np.array([[0, 0], [3, 4], [3, 0]])) == pytest.approx(9.0)
    assert path_length(np.zeros((1, 2))) == 0.0


def test_registration_config_checks():
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match="voxel_size"):
        RegistrationConfig(voxel_size=0)
    with pytest.raises(ConfigError, match="max_correspondence"):
        RegistrationConfig(max_correspondence=())
    with pytest.raises(ConfigError, match="method"):
        RegistrationConfig(method="ndt")
    with pytest.raises(ConfigError, match="min_agreement"):
        RegistrationConfig(min_agreement=1.5)


def test_same_seed_same_registered_poses():
    scene = load_scene("l_room")
    scanner = Scanner(scene, ScannerConfig(angular_step=0.5))

    def run(seed):
        rng = np.random.default_rng(seed)
        odometry = Odometry(OdometryConfig(), rng)
        t0 = odometry.true_sensor_pose(np.array([3.0, 4.5]), 0.0, 0.0, 1.5)
        cloud = AccumulatedCloud()
        first = scanner.scan(t0, rng)
        cloud.add(first.to_world(t0), t0[:3, 3])
        t1 = odometry.true_sensor_pose(np.array([2.0, 6.0]), 0.7, 0.0, 1.5)
        believed = odometry.drive(t0, t0, t1, 1.8)
        second = scanner.scan(t1, rng)
        return first, second, believed, register(second.points, believed, cloud).pose

    a, b = run(9), run(9)
    assert a[0].points.tobytes() == b[0].points.tobytes() and a[1].points.tobytes() == b[1].points.tobytes()
    assert np.array_equal(a[2], b[2])
    assert np.array_equal(a[3], b[3])


def _corridor(length: float = 30.0):
    from scenes.floorplan import FloorPlan

    plan = {
        "format": "nbs-floorplan",
        "version": 1,
        "name": "corridor",
        "ceiling_height": 2.6,
        "wall_thickness": 0.2,
        "rooms": [{"name": "corridor", "polygon": [[0, 0], [length, 0], [length, 2], [0, 2]]}],
        "start": [1.0, 1.0],
    }
    return load_scene(FloorPlan.from_dict(plan, source="corridor"))


def test_after_a_long_corridor_leg_the_walls_heading_rescues_icp():
    # 15 m down a 2 m corridor with the odometry 14° and 0.68 m off: ICP's coarsest stage starts
    # too far off to turn, the histogram of wall headings does not care how far the robot drove.
    scene = _corridor()
    scanner = Scanner(scene, ScannerConfig(angular_step=0.5))
    rng = np.random.default_rng(1)
    t0 = pose_from_xyz_rpy(3.0, 1.0, 1.5)
    first = scanner.scan(t0, rng).truth.points_world
    t1 = pose_from_xyz_rpy(18.0, 1.0, 1.5)
    prior = planar(18.67, 1.1, np.radians(14.0), 1.5)
    points = scanner.scan(t1, rng).points
    errors = {}
    for check in (RegistrationConfig().heading_check_deg, 0.0):
        cloud = AccumulatedCloud()
        cloud.add(first, t0[:3, 3])
        result = register(points, prior, cloud, RegistrationConfig(heading_check_deg=check), travelled=15.0)
        errors[check] = (result.accepted, *pose_error(result.pose, t1))
    accepted, dt, dr = errors[RegistrationConfig().heading_check_deg]
    assert accepted and dt < 0.02 and dr < 0.2, errors
    assert errors[0.0][1] > 0.1, errors  # without the check, ICP does not get there


@pytest.mark.parametrize("method", ["gicp", "plane", "open3d"])
def test_every_icp_method_recovers_a_small_perturbation(method):
    scanner, rng, _, cloud = _l_room_first_scan(5)
    t1 = pose_from_xyz_rpy(2.0, 5.5, 1.5, 0.0, 0.0, 0.5)
    prior = planar(2.15, 5.4, 0.55, 1.5)
    result = register(scanner.scan(t1, rng).points, prior, cloud, RegistrationConfig(method=method))
    assert result.accepted, result.reason
    assert pose_error(result.pose, t1)[0] < 0.01 and 0.5 < result.agreement <= 1.0


def test_an_empty_scan_is_refused_and_a_refused_scan_stays_out_of_the_target():
    scanner, rng, t0, cloud = _l_room_first_scan(0)
    result = register(np.zeros((0, 3)), t0, cloud)
    assert not result.accepted and "points" in result.reason and np.array_equal(result.pose, t0)
    # The refused scan's points (here: a copy of the room 1 m off) join S(t) but not ICP's target.
    shifted = cloud.storey_points() + np.array([1.0, 0.0, 0.0])
    cloud.add(shifted, t0[:3, 3] + [1.0, 0.0, 0.0])
    assert cloud.registered == [True, False]
    assert len(cloud.target_cloud().points) < len(cloud.working_cloud().points)
    # The next scan registers against the registered scan only, not its shifted twin.
    t1 = pose_from_xyz_rpy(2.5, 5.0, 1.5, 0.0, 0.0, 0.2)
    result = register(scanner.scan(t1, rng).points, planar(2.6, 5.0, 0.25, 1.5), cloud)
    assert result.accepted and pose_error(result.pose, t1)[0] < 0.01, result.reason


def test_a_refused_registration_is_reported_in_info_and_metrics():
    from dataclasses import replace

    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.report import metrics_dict

    config = make_config("default", scene="l_room", max_scans=3)
    # No pose can have every point of its overlap on S(t)'s planes within 1 mm: every ICP is refused.
    strict = replace(config.robot.registration, min_agreement=1.0, plane_tolerance=0.001)
    env = NBSEnv(replace(config, robot=replace(config.robot, registration=strict)))
    _, info = env.reset(seed=0)
    assert info["registration_refused"] == ""  # the first scan is placed as it is
    mask = env.action_masks()
    _, _, _, _, info = env.step(int(np.flatnonzero(mask)[0]))
    assert "S(t)'s planes" in info["registration_refused"], info["registration_refused"]
    steps = metrics_dict(env.storey, "l_room", "greedy", 0)["steps"]
    assert steps[0]["registration_refused"] == "" and "S(t)'s planes" in steps[-1]["registration_refused"]


@pytest.mark.parametrize("scene_name", ["five_rooms", "generated:3"])
def test_the_first_scan_is_levelled_by_the_floor_it_measured(scene_name):
    """The map's frame is the first scan's; a stop out of level would tilt the whole map."""
    scene = load_scene(scene_name)
    cfg = ScannerConfig(angular_step=1.0)
    scanner = Scanner(scene, cfg)
    rng = np.random.default_rng(7)
    x, y, z = scene.start
    for roll, pitch in [(0.0, 0.0), (0.0114, 0.0), (-0.004, 0.009)]:  # up to 0.65°, as five_rooms seed 3
        true = pose_from_xyz_rpy(x, y, z + cfg.height, roll, pitch, 0.3)
        initial = planar(x, y, 0.3, z + cfg.height)
        levelled = level_from_floor(scanner.scan(true, rng).points, initial, cfg.height)
        _, rotation_deg = pose_error(levelled, true)
        assert rotation_deg < 0.03, (roll, pitch, rotation_deg)
        # Roll and pitch only: the heading and the position are the initial pose's.
        assert np.allclose(levelled[:3, 3], initial[:3, 3])
        assert abs(yaw_of(levelled) - 0.3) < np.radians(0.01)


def test_levelling_keeps_the_pose_without_a_floor():
    initial = planar(1.0, 2.0, 0.0, 1.5)
    walls_only = np.random.default_rng(0).uniform(-5, 5, (5000, 3)) * [1, 1, 0.1]  # nothing 1.5 m below
    assert np.array_equal(level_from_floor(walls_only, initial, 1.5), initial)


def _oracle_normals(points, radius, reach, k=20, least=6):
    """The plane normals of ``_plane_normals``, by brute force and numpy's eigh."""
    d2 = ((points[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    out = np.zeros_like(points)
    for i in range(len(points)):
        order = np.argsort(d2[i], kind="stable")[:k]
        near = order[d2[i, order] <= radius**2]
        if len(near) < least:
            near = order[d2[i, order] <= reach**2]
        if len(near) < 3:
            continue
        q = points[near] - points[near].mean(axis=0)
        out[i] = np.linalg.eigh(q.T @ q)[1][:, 0]
    return out


def test_the_compiled_plane_normals_are_the_eigenvector_normals():
    """Two noisy planes at a right angle, dense near the corner and sparse far out: each normal
    the smallest eigenvector of its neighbours' scatter (up to sign), the sparse points' from the
    wider reach, none for an isolated point."""
    import small_gicp

    from nbs_env.sensing.registration import _MIN_NORMAL_NEIGHBOURS, _NORMAL_NEIGHBOURS, _plane_normals

    rng = np.random.default_rng(3)
    dense = np.column_stack([rng.uniform(0, 1, 300), rng.uniform(0, 1, 300), rng.normal(0, 0.002, 300)])
    wall = np.column_stack([rng.normal(0, 0.002, 200), rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)])
    sparse = np.column_stack([rng.uniform(2, 4, 40), rng.uniform(0, 2, 40), rng.normal(0, 0.002, 40)])
    points = np.vstack([dense, wall, sparse, [[9.0, 9.0, 9.0]]])
    tree = small_gicp.KdTree(points, num_threads=1)
    idx, sq = tree.batch_knn_search(points, _NORMAL_NEIGHBOURS, num_threads=1)
    idx, sq = np.asarray(idx).astype(np.int64), np.asarray(sq)
    got = _plane_normals(points, idx, sq, 0.15**2, 0.6**2, _MIN_NORMAL_NEIGHBOURS)
    want = _oracle_normals(points, 0.15, 0.6, _NORMAL_NEIGHBOURS, _MIN_NORMAL_NEIGHBOURS)
    found = np.linalg.norm(want, axis=1) > 0
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", got[found], want[found])), 1.0, atol=1e-6)
    assert not got[~found].any() and not found[-1]
    # The sparse plane (0.3 m apart on average) took its normals from the reach: still the floor's.
    assert np.all(np.abs(got[500:540, 2]) > 0.99)


def test_the_range_image_kernels_are_numpys_norm_and_minimum_at_bit_for_bit():
    """The see-through gate's range image reads ranges and per-cell minima from compiled loops;
    they are numpy's ``linalg.norm(axis=1)`` and ``minimum.at``, to the last bit (repeated cells,
    empty cells, zero-length points)."""
    from nbs_env.sensing.registration import _cell_minima, _ranges

    rng = np.random.default_rng(5)
    points = rng.normal(0, 7, (5000, 3))
    points[:10] = 0.0
    np.testing.assert_array_equal(_ranges(points), np.linalg.norm(points, axis=1))
    cells = rng.integers(0, 300, 5000)  # about 17 values a cell, and cells 300-399 empty
    values = rng.uniform(0, 30, 5000)
    want = np.full(400, np.inf)
    np.minimum.at(want, cells, values)
    np.testing.assert_array_equal(_cell_minima(cells, values, 400), want)


def test_the_compiled_target_selection_is_numpys():
    """ICP's target, cut in one compiled pass (box, agreeing normals, facing the scanner), holds
    the same voxels and normals, to the last bit, as numpy's passes over the working copy."""
    from nbs_env.mapping.cloud import VoxelMeans
    from nbs_env.sensing.registration import _facing_voxels

    rng = np.random.default_rng(8)
    copy = VoxelMeans(0.1, normals=True)
    for _ in range(3):  # scans whose normals partly disagree in shared voxels
        points = rng.uniform(-4, 4, (4000, 3))
        normals = rng.normal(0, 1, (4000, 3))
        copy.add(points, normals / np.linalg.norm(normals, axis=1, keepdims=True))
    centre, lo, hi = np.array([0.5, -0.2, 1.0]), np.array([-3.0, -2.0, -4.0]), np.array([2.5, 4.0, 3.0])
    points = copy.points
    inside = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
    mean = copy.normal_sums[inside] / copy.counts[inside, None]
    # Sums in the kernel's order (einsum's order varies with the machine's SIMD width).
    length = np.sqrt(mean[:, 0] * mean[:, 0] + mean[:, 1] * mean[:, 1] + mean[:, 2] * mean[:, 2])
    keep = length >= 0.5
    want_points, want_normals = points[inside][keep], mean[keep] / length[keep, None]
    towards = centre - want_points
    facing = (want_normals * towards)[:, 0] + (want_normals * towards)[:, 1] + (want_normals * towards)[:, 2] > 0
    index, normals = _facing_voxels(points, copy.normal_sums, copy.counts, lo, hi, centre)
    assert 0 < len(index) < len(inside)
    np.testing.assert_array_equal(points[index], want_points[facing])
    np.testing.assert_array_equal(normals, want_normals[facing])


def test_a_registered_scan_is_downsampled_once_and_placed_with_its_pose():
    """``add(..., pose=)`` takes the copy ``register`` made of the same scan, placed with the pose
    (points, normals and covariances turned with it); a different scan with ``pose=`` is refused."""
    scanner, rng, _, cloud = _l_room_first_scan(2)
    t1 = pose_from_xyz_rpy(2.4, 5.2, 1.5, 0.0, 0.0, 0.3)
    scan = scanner.scan(t1, rng)
    result = register(scan.points, planar(2.45, 5.25, 0.32, 1.5), cloud)
    assert result.accepted, result.reason
    copy = cloud._prepared
    before = len(cloud.working_points())
    cloud.add(scan.to_world(result.pose), result.pose[:3, 3], pose=result.pose)
    placed, normals, covariances = copy.world()
    R = result.pose[:3, :3]
    np.testing.assert_allclose(placed, copy.points @ R.T + result.pose[:3, 3])
    np.testing.assert_allclose(normals, copy.normals @ R.T)
    # S(t) keeps the scan's covariances where the scan was dense, none (zero) elsewhere.
    assert 0 < copy.dense.sum() < len(copy.dense)
    kept = np.where(copy.dense[:, None, None], copy.covariances, 0.0)
    np.testing.assert_allclose(covariances, R @ kept @ R.T, atol=1e-12)
    assert len(cloud.working_points()) > before
    # Normals face the scanner that measured them.
    work, facing = cloud.working_points(), cloud.working_normals()
    assert np.all(np.abs(np.linalg.norm(facing, axis=1) - 1.0) < 1e-9)
    register(scan.points, result.pose, cloud)
    with pytest.raises(ValueError, match="pose= adds only the scan"):
        cloud.add(scan.to_world(result.pose)[:-5], result.pose[:3, 3], pose=result.pose)
    assert len(work) == len(cloud.working_points())


def test_registration_config_checks_its_stages():
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match="stage_voxels"):
        RegistrationConfig(stage_voxels=(0.3, 0.2))
    with pytest.raises(ConfigError, match="stage_voxels"):
        RegistrationConfig(voxel_size=0.1, stage_voxels=(0.3, 0.2, 0.05))
    with pytest.raises(ConfigError, match="convergence"):
        RegistrationConfig(convergence=0.0)
    RegistrationConfig(voxel_size=0.05, stage_voxels=None)


def _box_room_samples(rng, n):
    """(n, 3) points on the six faces of an 8 x 3 x 2.5 m box."""
    face = rng.integers(0, 6, n)
    u, v = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    x, y, z = u * 8, v * 3, np.zeros(n)
    x = np.where(face == 2, 0.0, np.where(face == 3, 8.0, x))
    y = np.where(face >= 4, np.where(face == 4, 0.0, 3.0), np.where(face >= 2, u * 3, y))
    z = np.where(face == 1, 2.5, np.where(face >= 2, v * 2.5, z))
    x = np.where(face >= 4, u * 8, x)
    return np.column_stack([x, y, z])


def test_the_compiled_gicp_is_small_gicps():
    """The covariances from given neighbours are small_gicp's ``estimate_covariances``, and an
    alignment with them lands where ``small_gicp.align`` (GICP, one thread, the same settings) does."""
    import small_gicp

    from nbs_env.sensing import gicp

    rng = np.random.default_rng(0)
    target, source = _box_room_samples(rng, 20000), _box_room_samples(rng, 8000)
    clouds = []
    for points in (target, source):
        cloud = small_gicp.PointCloud(points)
        tree = small_gicp.KdTree(cloud, num_threads=1)
        small_gicp.estimate_covariances(cloud, tree, num_neighbors=20, num_threads=1)
        idx, _ = tree.batch_knn_search(points, 20, num_threads=1)
        mine = gicp.covariances_from_neighbours(points, np.asarray(idx).astype(np.int64), 20)
        theirs = np.array(cloud.covs())[:, :3, :3]
        np.testing.assert_allclose(mine, theirs, atol=1e-9)
        clouds.append((cloud, tree, mine))
    (tcloud, ttree, tcov), (scloud, _, scov) = clouds
    start = pose_from_xyz_rpy(0.3, -0.2, 0.05, 0.0, 0.0, 0.1)
    want = small_gicp.align(
        tcloud, scloud, ttree, init_T_target_source=start, registration_type="GICP",
        max_correspondence_distance=0.5, num_threads=1, max_iterations=40,
        rotation_epsilon=1e-4, translation_epsilon=1e-4,
    ).T_target_source  # fmt: skip

    def nearest(world):
        idx, sq = ttree.batch_nearest_neighbor_search(world, num_threads=1)
        return np.asarray(idx, dtype=np.int64), np.asarray(sq, dtype=float)

    got = gicp.align(nearest, target, tcov, source, scov, start, 0.5, 40, 1e-4)
    dt, dr = pose_error(got, np.asarray(want))
    assert dt < 1e-6 and dr < 1e-5, (dt, dr)
    assert pose_error(got, np.eye(4))[0] < 0.01  # and it is the right answer: the same room


def test_a_refused_icp_after_a_large_turn_is_tried_again_from_the_walls_heading(monkeypatch):
    """When the walls' heading says the prior is off by more than the check and ICP, having turned
    there, was refused, ICP runs again from the walls' heading; an accepted first attempt is kept
    without a second (the rule that rescued a 22° turn on example_level1, which slid 3 m along a
    corridor from the prior)."""
    from nbs_env.sensing import registration as reg

    scanner, rng, _, cloud = _l_room_first_scan(4)
    t1 = pose_from_xyz_rpy(2.2, 5.3, 1.5, 0.0, 0.0, 0.2)
    points = scanner.scan(t1, rng).points
    prior = planar(2.25, 5.35, 0.2 + np.radians(12.0), 1.5)
    starts = []
    real = reg._attempt

    def refuse_first(src, target, start, *args):
        starts.append(start)
        out = real(src, target, start, *args)
        if len(starts) == 1:  # as if this attempt had slid off after turning
            from dataclasses import replace

            return replace(out, reason="refused for the test")
        return out

    monkeypatch.setattr(reg, "_attempt", refuse_first)
    # 8 m driven: the gates allow a 16° correction.
    result = register(points, prior, cloud, travelled=8.0)
    assert len(starts) == 2 and result.accepted, result.reason
    # The second start is the prior turned by the walls' heading: within a degree of the truth.
    assert pose_error(starts[1], t1)[1] < 1.0 < pose_error(starts[0], t1)[1]
    assert pose_error(result.pose, t1)[0] < 0.01
    starts.clear()
    monkeypatch.setattr(reg, "_attempt", lambda *a: (starts.append(a[2]), real(*a))[1])
    cloud2 = _l_room_first_scan(4)[3]
    assert register(points, prior, cloud2, travelled=8.0).accepted and len(starts) == 1
