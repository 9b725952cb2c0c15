"""The simulated scanner: geometry against analytic ranges, limits, noise, determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import box_ranges
from helpers import box_room as make_box_room

from nbs_env.config import ScannerConfig
from nbs_env.errors import ConfigError, InvalidPoseError
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner, ray_pattern
from scenes import SurfaceClass, load_scene

A, B, H = 6.0, 4.0, 3.0  # clear inner size of the box room


@pytest.fixture(scope="module")
def box_room():
    return make_box_room(A, B, H)


def analytic_ranges(origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance from ``origin`` inside [0, A] x [0, B] x [0, H] to the box along each direction."""
    return box_ranges(origin, directions, (A, B, H))


@pytest.fixture(scope="module")
def exact_scan(box_room):
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.0, min_range=0.0)
    pose = pose_from_xyz_rpy(2.0, 1.5, 1.5, 0.0, 0.0, 0.3)
    return Scanner(box_room, cfg).scan(pose), pose, cfg


def test_points_lie_on_the_mesh(exact_scan):
    scan, _, _ = exact_scan
    p = scan.truth.points_world
    dist = np.min(np.abs(np.concatenate([p, p - [A, B, H]], axis=1)), axis=1)
    assert dist.max() < 1e-4
    assert np.all((p > -1e-4) & (p < np.array([A, B, H]) + 1e-4))


def test_ranges_match_the_analytic_distances(exact_scan):
    scan, pose, cfg = exact_scan
    directions, _, _ = ray_pattern(cfg)
    flat = scan.rows * cfg.n_cols + scan.cols
    world_dirs = directions[flat].astype(np.float64) @ pose[:3, :3].T
    expected = analytic_ranges(pose[:3, 3], world_dirs)
    assert np.max(np.abs(scan.ranges - expected)) < 1e-4
    assert np.allclose(np.linalg.norm(scan.points, axis=1), scan.ranges, atol=1e-5)


def test_pattern_shape_and_elevation_limits(box_room):
    cfg = ScannerConfig(angular_step=0.5, range_noise=0.0)
    assert (cfg.n_rows, cfg.n_cols) == (201, 720)
    scan = Scanner(box_room, cfg).scan(pose_from_xyz_rpy(3.0, 2.0, 1.5))
    el = np.degrees(np.arcsin(scan.points[:, 2] / scan.ranges))
    assert el.min() >= -40 - 1e-3 and el.max() <= 60 + 1e-3
    assert scan.ranges.min() >= cfg.min_range
    assert scan.depth_image().shape == (201, 720)


def test_point_count_is_pattern_minus_dropped_returns(box_room):
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.0, min_range=2.5, max_range=4.0)
    pose = pose_from_xyz_rpy(2.0, 1.5, 1.5)
    scan = Scanner(box_room, cfg).scan(pose)
    directions, _, _ = ray_pattern(cfg)
    expected = analytic_ranges(pose[:3, 3], directions.astype(np.float64))
    # Rays within 0.1 mm of a limit may fall either side in float32; all others are decided.
    surely = np.count_nonzero((expected >= 2.5 + 1e-4) & (expected <= 4.0 - 1e-4))
    maybe = np.count_nonzero((expected >= 2.5 - 1e-4) & (expected <= 4.0 + 1e-4))
    assert surely > 0 and maybe < cfg.n_rays and maybe - surely < 20
    assert surely <= len(scan) <= maybe
    assert np.all((scan.ranges >= 2.5) & (scan.ranges <= 4.0))


def test_range_noise_has_the_configured_sigma(box_room):
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.01)
    scan = Scanner(box_room, cfg).scan(pose_from_xyz_rpy(3.0, 2.0, 1.5), np.random.default_rng(1))
    err = scan.ranges.astype(np.float64) - scan.truth.ranges
    assert np.std(err) == pytest.approx(0.01, rel=0.1)
    assert abs(np.mean(err)) < 0.001


def test_ground_truth_is_kept_apart(box_room):
    scan = Scanner(box_room, ScannerConfig(angular_step=2.0, range_noise=0.0)).scan(pose_from_xyz_rpy(3, 2, 1.5))
    assert not hasattr(scan, "labels") and not hasattr(scan, "pose")
    labels = scan.truth.labels
    assert set(np.unique(labels)) == {SurfaceClass.FLOOR, SurfaceClass.CEILING, SurfaceClass.WALL}
    # Points below the sensor that hit the floor have z = -1.5 in the sensor frame.
    floor = labels == SurfaceClass.FLOOR
    assert np.allclose(scan.points[floor, 2], -1.5, atol=1e-4)


def test_same_seed_same_scan():
    scene = load_scene("l_room")
    scanner = Scanner(scene, ScannerConfig(angular_step=1.0))
    pose = pose_from_xyz_rpy(3.0, 4.5, 1.5, 0.01, -0.01, 1.0)
    a = scanner.scan(pose, np.random.default_rng(7))
    b = scanner.scan(pose, np.random.default_rng(7))
    c = scanner.scan(pose, np.random.default_rng(8))
    assert a.points.tobytes() == b.points.tobytes()
    assert a.points.tobytes() != c.points.tobytes()


def test_acquisition_time():
    scene = load_scene("office")
    scan = Scanner(scene, ScannerConfig(angular_step=1.0)).scan(pose_from_xyz_rpy(3, 2, 1.5), np.random.default_rng(0))
    assert scan.acquisition_time == pytest.approx(len(scan) / 122_000)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"angular_step": 0.0}, "angular_step must be > 0"),
        ({"angular_step": -1.0}, "angular_step must be > 0"),
        ({"angular_step": 0.005}, "rays per scan; the limit is 50,000,000"),
        ({"min_range": 10.0, "max_range": 5.0}, "min_range .* must be below max_range"),
        ({"range_noise": float("nan")}, "range_noise must be a finite number"),
    ],
)
def test_bad_scanner_config(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        ScannerConfig(**kwargs)


def test_bad_pose(box_room):
    scanner = Scanner(box_room, ScannerConfig(angular_step=2.0, range_noise=0.0))
    pose = pose_from_xyz_rpy(3, 2, 1.5)
    pose[0, 3] = np.nan
    with pytest.raises(InvalidPoseError, match="NaN"):
        scanner.scan(pose)
    with pytest.raises(InvalidPoseError, match="not a rotation"):
        scanner.scan(np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="rng"):
        Scanner(box_room, ScannerConfig(angular_step=2.0)).scan(pose_from_xyz_rpy(3, 2, 1.5))


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_the_compiled_scan_is_the_numpy_scan(noise):
    """Rays built, noised, filtered and gathered in compiled passes give what the numpy version
    gives (kept here as the oracle), bit for bit: directions, points, ranges, pattern indices, faces;
    with a minimum range whose float32 rounds down (0.7 m), where numpy compares in float32."""
    scene = load_scene("five_rooms")
    cfg = ScannerConfig(angular_step=1.0, range_noise=noise, min_range=0.7, max_range=9.3)
    scanner = Scanner(scene, cfg)
    pose = pose_from_xyz_rpy(4.6, 1.8, 1.5, 0.01, -0.02, 0.7)
    scan = scanner.scan(pose, np.random.default_rng(4))

    directions, rows, cols = ray_pattern(cfg)
    R = pose[:3, :3].astype(np.float32)
    rays = np.empty((len(directions), 6), dtype=np.float32)
    rays[:, :3] = pose[:3, 3]
    columns = [np.ascontiguousarray(directions[:, i]) for i in range(3)]
    for i in range(3):
        acc = columns[0] * R[i, 0]
        acc += columns[1] * R[i, 1]
        acc += columns[2] * R[i, 2]
        rays[:, 3 + i] = acc
    np.testing.assert_array_equal(scanner.rays(pose), rays)
    t_hit, prim = scanner.cast(rays)
    measured = t_hit
    if noise > 0:
        draws = np.random.default_rng(4).standard_normal(len(t_hit), dtype=np.float32)
        measured = t_hit + draws * np.float32(noise)
    idx = np.flatnonzero((measured >= cfg.min_range) & (measured <= cfg.max_range))
    np.testing.assert_array_equal(scan.ranges, measured[idx])
    np.testing.assert_array_equal(scan.points, directions[idx] * measured[idx][:, None])
    np.testing.assert_array_equal(scan.rows, rows[idx])
    np.testing.assert_array_equal(scan.cols, cols[idx])
    np.testing.assert_array_equal(scan.truth.face_ids, prim[idx].astype(np.int64))
    np.testing.assert_array_equal(scan.truth.ranges, t_hit[idx])
    assert 0 < len(idx) < len(t_hit)
