"""The simulated scanner: geometry against analytic ranges, limits, noise, determinism, bad input."""

from __future__ import annotations

import dataclasses

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
        ({"noise_floor": -0.001}, "noise_floor must be >= 0"),
        ({"noise_range": 0.0}, "noise_range must be >= 0.1"),
        ({"noise_range": 1e-300}, "noise_range must be >= 0.1"),  # a ZeroDivisionError in the scan once
        ({"noise_exponent": 3.0}, r"noise_exponent must be in \[0, 2\]"),
        ({"beam_divergence": -0.001}, "beam_divergence must be in"),
        ({"beam_divergence": 1.0}, "beam_divergence must be in"),
        ({"beam_diameter": float("inf")}, "beam_diameter must be a finite number"),
        ({"echo_separation": 0.0}, "echo_separation must be > 0"),
        ({"echo_separation": float("nan")}, "echo_separation must be a finite number"),
        ({"instrument_step": 0.0}, "instrument_step must be > 0"),
        ({"setup_time": -1.0}, "setup_time must be within"),
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
    with a minimum range whose float32 rounds down (0.7 m), where numpy compares in float32. The
    thin ray: mixed pixels have their own tests."""
    scene = load_scene("five_rooms")
    cfg = ScannerConfig(angular_step=1.0, range_noise=noise, min_range=0.7, max_range=9.3, beam_divergence=0.0)
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


# --- The scanner model: range noise by range and incidence, mixed pixels, the instrument's density ---

CORRIDOR = (60.0, 4.0, 3.0)


@pytest.fixture(scope="module")
def corridor():
    return make_box_room(*CORRIDOR)


def _incidence_cos(scene, scan, pose) -> np.ndarray:
    normals = np.asarray(scene.mesh.face_normals)[scan.truth.face_ids]
    rays = scan.truth.points_world - pose[:3, 3]
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return np.abs(np.einsum("ij,ij->i", rays, normals))


def test_range_noise_grows_with_range_and_incidence_as_configured(corridor):
    from nbs_env.sensing.scanner import noise_sigma

    cfg = ScannerConfig(
        angular_step=0.5, range_noise=0.003, noise_floor=0.001, noise_range=10.0, noise_exponent=0.5, beam_divergence=0
    )
    # 20 m from the corridor's end wall, which is then seen head-on from afar.
    pose = pose_from_xyz_rpy(40.0, 2.0, 1.5, 0.0, 0.0, 0.2)
    scan = Scanner(corridor, cfg).scan(pose, np.random.default_rng(3))
    err = scan.ranges.astype(np.float64) - scan.truth.ranges
    r = scan.truth.ranges.astype(np.float64)
    cos = _incidence_cos(corridor, scan, pose)
    expected = noise_sigma(cfg, r, cos)
    # The errors are the configured σ's draws: standardised, they are a unit normal.
    assert np.std(err / expected) == pytest.approx(1.0, abs=0.02)
    # Head-on at 2-4 m against 15-30 m (σ 1.3 against 5.7 mm); and at 4-8 m, steeper than 66° from the
    # normal against beyond 78° (about 2.7 against 4.5 mm).
    near, far = (r < 4) & (cos > 0.9), (r > 15) & (r < 30) & (cos > 0.9)
    square, grazing = (r > 4) & (r < 8) & (cos > 0.4), (r > 4) & (r < 8) & (cos < 0.2)
    for a, b, ratio in ((near, far, 3.0), (square, grazing, 1.3)):
        assert a.sum() > 200 and b.sum() > 200
        assert np.std(err[b]) > ratio * np.std(err[a])
        for group in (a, b):
            assert np.std(err[group]) == pytest.approx(np.sqrt(np.mean(expected[group] ** 2)), rel=0.1)
    # The exponent 0 is METHOD's constant σ, whatever the range and angle.
    flat = Scanner(corridor, dataclasses.replace(cfg, noise_exponent=0.0)).scan(pose, np.random.default_rng(3))
    flat_err = flat.ranges.astype(np.float64) - flat.truth.ranges
    flat_r = flat.truth.ranges
    assert np.std(flat_err[flat_r > 15]) == pytest.approx(0.003, rel=0.1)
    assert np.std(flat_err[flat_r < 4]) == pytest.approx(0.003, rel=0.1)


def _pole_room():
    from helpers import boxed_storey

    walls = [((0, 0), (8, 0), ()), ((8, 0), (8, 6), ()), ((8, 6), (0, 6), ()), ((0, 6), (0, 0), ())]
    # A free-standing board 2 cm thick: its edges, unlike a pole's, have no side a grazing beam runs along.
    return boxed_storey(walls, [(0, 0, 8, 6)], [(0, 0, 8, 6)], clutter=[(3.99, 2.6, 4.01, 3.4, 2.2)])


def _off_surface(scene, points: np.ndarray) -> np.ndarray:
    """(n,) float: each point's distance to the true mesh (an Embree distance query, not the scan's)."""
    from scenes._open3d import open3d

    o3d = open3d()
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(
        o3d.core.Tensor(np.asarray(scene.mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(scene.mesh.faces, dtype=np.uint32)),
    )
    return rs.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


@pytest.mark.parametrize("separation", [None, 0.75])
def test_mixed_pixels_float_between_a_board_and_the_wall_behind_it(separation):
    """A board 2.5 m from the scanner, the wall 4 m behind it. A wide beam (5 mrad) straddles the
    board's edges: a phase scanner (no echo separation) returns points between board and wall; a pulsed
    one (0.75 m) keeps one echo, so every point stays on a surface; a thin beam has no mixed pixels."""
    scene = _pole_room()
    pose = pose_from_xyz_rpy(1.5, 3.0, 1.5, 0.0, 0.0, 0.01)
    cfg = ScannerConfig(
        angular_step=0.5, range_noise=0.0, min_range=0.0, beam_divergence=0.005, echo_separation=separation
    )
    scan = Scanner(scene, cfg).scan(pose)
    off = _off_surface(scene, scan.truth.points_world)
    floating = off > 0.05
    assert scan.truth.mixed.sum() >= 20
    if separation is None:
        assert floating.sum() >= 10
        assert np.all(scan.truth.mixed[floating])
        # Between the board (2.49 m away) and the wall behind it (6.5 m).
        assert np.all((scan.ranges[floating] > 2.45) & (scan.ranges[floating] < 6.7))
    else:
        assert not floating.any()
    thin = Scanner(scene, dataclasses.replace(cfg, beam_divergence=0.0)).scan(pose)
    assert not thin.truth.mixed.any()
    assert _off_surface(scene, thin.truth.points_world).max() < 1e-3


def test_the_instrument_density_is_measured_not_assumed(box_room):
    """A 1° scan whose returns each count for the (1 / 0.25)² = 16 returns of a 0.25° instrument gives
    the density a 0.25° scan gives, sample by sample (the stated subsampling, checked by casting it)."""
    from nbs_env.evaluation import CoverageMeter

    pose = pose_from_xyz_rpy(2.2, 1.7, 1.5, 0.0, 0.0, 0.3)
    fine_cfg = ScannerConfig(angular_step=0.25, range_noise=0.0, min_range=0.0)
    coarse_cfg = dataclasses.replace(fine_cfg, angular_step=1.0, instrument_step=0.25)
    assert coarse_cfg.density_weight == 16.0
    densities = {}
    for name, cfg in (
        ("fine", fine_cfg),
        ("coarse", coarse_cfg),
        ("unweighted", dataclasses.replace(coarse_cfg, instrument_step=None)),
    ):
        meter = CoverageMeter(box_room, density_weight=cfg.density_weight)
        meter.add(Scanner(box_room, cfg).scan(pose).truth.points_world, pose[:3, 3])
        densities[name] = meter.quality().density
    fine, coarse, unweighted = densities["fine"], densities["coarse"], densities["unweighted"]
    assert np.median(coarse) == pytest.approx(np.median(fine), rel=0.05)
    assert np.median(unweighted) == pytest.approx(np.median(fine) / 16, rel=0.05)
    # Per sample the two densities agree within a quarter for nine samples in ten.
    both = (fine > 0) & (coarse > 0)
    assert np.mean(np.abs(coarse[both] / fine[both] - 1) < 0.25) > 0.9


@pytest.mark.parametrize("z", [0.0, 3.0])
def test_a_scanner_on_a_surface_scans(box_room, z):
    """A scanner whose centre lies on the floor or the ceiling (the oracle's positions may) gets
    returns at range 0: the footprints of the beams there have nothing to straddle."""
    scan = Scanner(box_room, ScannerConfig(range_noise=0.0, min_range=0.0)).scan(pose_from_xyz_rpy(3.0, 2.0, z))
    assert len(scan) > 1000 and scan.truth.ranges.min() == 0.0
