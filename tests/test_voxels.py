"""The labelled voxel grid: growth, carving, occupied and occluded labels, export."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import box_ranges, box_room

from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.voxels import TRACE_HEIGHT, VoxelGrid
from nbs_env.perception.faces import WallFace
from nbs_env.planning.navigation import NavigationConfig
from nbs_env.planning.planner import traversable_floor
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner

A, B, H = 4.0, 3.0, 2.5


@pytest.fixture(scope="module")
def box_scene():
    return box_room(A, B, H)


def analytic_range(origin, directions):
    return box_ranges(origin, directions, (A, B, H))


def test_labels_survive_growth():
    grid = VoxelGrid.covering([0, 0, 0], [1, 1, 1], 0.1)
    rng = np.random.default_rng(0)
    grid.labels[:] = rng.integers(0, 6, grid.shape, dtype=np.uint8)
    centres = grid.centres(np.argwhere(np.ones(grid.shape, bool)))
    before = grid.labels.reshape(-1).copy()
    offset = grid.ensure_covers([-0.55, -0.2, 0.0], [1.3, 2.0, 1.25])
    assert tuple(offset) == (6, 2, 0)
    assert grid.shape == (19, 22, 13)
    after = grid.labels[tuple(grid.index_of(centres).T)]
    assert np.array_equal(after, before)
    # Voxel boundaries stay on multiples of the voxel size.
    assert np.allclose(grid.origin / 0.1, np.round(grid.origin / 0.1))
    # New voxels are UNKNOWN.
    assert grid.labels.sum() == before.sum()


def test_carving_never_goes_beyond_the_measured_range(box_scene):
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.0, min_range=0.5)
    pose = pose_from_xyz_rpy(1.3, 1.1, 1.5, 0.0, 0.0, 0.4)
    scan = Scanner(box_scene, cfg).scan(pose)
    grid = VoxelGrid.covering([-0.3, -0.3, -0.3], [A + 0.3, B + 0.3, H + 0.3], 0.05)
    stats = grid.integrate(scan.to_world(pose), np.ones(len(scan), bool), pose, scan.depth_image(), cfg)
    empty = grid.centres(np.argwhere(grid.labels == VoxelLabel.EMPTY))
    assert stats.carved == len(empty) > 0.5 * (A * B * H / 0.05**3)  # most of the room is carved
    rel = empty - pose[:3, 3]
    r = np.linalg.norm(rel, axis=1)
    half_diagonal = 0.05 * np.sqrt(3) / 2
    # Along its own direction, every Empty voxel's far corner is nearer than the wall.
    assert np.all(r + half_diagonal <= analytic_range(pose[:3, 3], rel / r[:, None]) + 1e-6)
    # And nothing outside the room is Empty.
    assert np.all((empty > 0) & (empty < [A, B, H]))


def _sliding_min_plain(a: np.ndarray, size: int, axis: int) -> np.ndarray:
    a = np.moveaxis(a, axis, 0)
    cur, length = a, 1
    while 2 * length <= size:
        cur = np.minimum(cur[:-length], cur[length:])
        length *= 2
    n = a.shape[0] - size + 1
    return np.moveaxis(np.minimum(cur[:n], cur[size - length : size - length + n]), 0, axis)


def _min_filter_plain(image: np.ndarray, size: int) -> np.ndarray:
    if size <= 1:
        return image
    half = size // 2
    padded = np.pad(image, ((half, half), (0, 0)), mode="edge")
    padded = np.pad(padded, ((0, 0), (half, half)), mode="wrap")
    return _sliding_min_plain(_sliding_min_plain(padded, size, 0), size, 1)


def _block_pooled_plain(image: np.ndarray, size: int) -> tuple[np.ndarray, int]:
    """The pooling of VoxelGrid's carving in numpy (the oracle of the compiled one)."""
    if size <= 5:
        return _min_filter_plain(image, size), 1
    half = (size - 1) // 2
    f = max(1, half // 2)
    h, w = image.shape
    padded = np.pad(image, ((0, -h % f), (0, 0)), mode="edge")
    padded = np.pad(padded, ((0, 0), (0, -w % f)), mode="wrap")
    blocks = padded.reshape(padded.shape[0] // f, f, padded.shape[1] // f, f).min(axis=(1, 3))
    reach = -(-half // f)
    return _min_filter_plain(blocks, 2 * reach + 1), f


@pytest.mark.parametrize("shape", [(100, 360), (37, 53), (5, 7)])
def test_the_compiled_pooling_is_the_numpy_pooling(shape):
    """Every window size, on images whose sides are and are not multiples of the block size, with
    ties (whole centimetres) and no-return pixels (0)."""
    from nbs_env.mapping.voxels import _POOL_SIZES, _block_pooled

    rng = np.random.default_rng(shape[0])
    image = np.round(rng.uniform(0, 9, shape), 2).astype(np.float32)
    image[rng.random(shape) < 0.1] = 0.0
    for size in _POOL_SIZES:
        got, f = _block_pooled(image, size)
        want, g = _block_pooled_plain(image, size)
        assert f == g
        np.testing.assert_array_equal(got, want)


def _carve_whole_box(grid, T, depth, config):
    """The carving computed for every voxel of the box within reach (the oracle of VoxelGrid._carve,
    which computes only the unsensed voxels)."""
    from nbs_env.mapping.voxels import _POOL_SIZES, _block_pooled

    s = grid.voxel_size
    measured = np.nan_to_num(depth, nan=0.0).astype(np.float32)
    reach = float(measured.max())
    centre = T[:3, 3]
    first = np.maximum(np.floor((centre - reach - grid.origin) / s).astype(np.int64), 0)
    last = np.minimum(np.ceil((centre + reach - grid.origin) / s).astype(np.int64), np.asarray(grid.shape))
    gi = [np.arange(first[a], last[a]) for a in range(3)]
    axes = [(grid.origin[a] + (gi[a] + 0.5) * s - centre[a]).astype(np.float32) for a in range(3)]
    R = T[:3, :3].astype(np.float32)
    sx, sy, sz = (
        axes[0][:, None, None] * R[0, c] + axes[1][None, :, None] * R[1, c] + axes[2][None, None, :] * R[2, c]
        for c in range(3)
    )
    horizontal = np.hypot(sx, sy)
    r = np.hypot(horizontal, sz)
    step = np.float32(np.radians(config.angular_step))
    half_diagonal = np.float32(s * np.sqrt(3) / 2)
    elevation = np.arctan2(sz, horizontal)
    half_angle = half_diagonal / np.maximum(r, np.float32(1e-3))
    lowest = np.float32(np.radians(config.elevation_min))
    highest = np.float32(np.radians(config.elevation_min + (config.n_rows - 1) * config.angular_step))
    in_fov = (elevation - half_angle >= lowest) & (elevation + half_angle <= highest)
    row = np.clip(np.rint((elevation - lowest) / step), 0, config.n_rows - 1).astype(np.int32)
    col = np.rint((np.arctan2(sy, sx) + np.float32(np.pi)) / np.float32(2 * np.pi / config.n_cols)) % config.n_cols
    col = col.astype(np.int32)
    footprint = 2 * half_diagonal / np.maximum(r, np.float32(1e-3)) / step
    sizes = np.asarray(_POOL_SIZES)
    which = np.searchsorted(np.maximum(sizes - 1, 1), footprint)
    wide = which >= len(sizes)
    which = np.minimum(which, len(sizes) - 1)
    limit = np.zeros(r.shape, dtype=np.float32)
    for size in np.unique(which[in_fov & ~wide]):
        pooled, f = _block_pooled(measured, int(sizes[size]))
        sel = (which == size) & in_fov & ~wide
        limit[sel] = pooled[row[sel] // f, col[sel] // f]
    carve = in_fov & ~wide & (r + half_diagonal < limit)
    block = grid.labels[first[0] : last[0], first[1] : last[1], first[2] : last[2]]
    carve &= (block != VoxelLabel.CLUTTER) & (block != VoxelLabel.STRUCTURE)
    newly = int(np.count_nonzero(carve & (block != VoxelLabel.EMPTY)))
    block[carve] = VoxelLabel.EMPTY
    return newly


@pytest.mark.parametrize("step", [1.0, 0.5])
def test_carving_only_the_unsensed_voxels_is_carving_the_whole_box(box_scene, step):
    """Over a grid holding every label, two scans in turn: the carving of the unsensed voxels alone
    leaves the same labels, and counts the same voxels, as the carving of every voxel in reach."""
    cfg = ScannerConfig(angular_step=step, range_noise=0.0, min_range=0.5)
    rng = np.random.default_rng(11)
    grid = VoxelGrid.covering([-0.3, -0.3, -0.3], [A + 0.3, B + 0.3, H + 0.3], 0.05)
    grid.labels[:] = rng.choice(np.array(list(VoxelLabel), dtype=np.uint8), size=grid.shape)
    oracle = VoxelGrid(grid.origin.copy(), grid.voxel_size, grid.labels.copy())
    for xyzrpy in ((1.3, 1.1, 1.5, 0.0, 0.0, 0.4), (3.1, 2.2, 1.2, 0.02, -0.01, 2.9)):
        pose = pose_from_xyz_rpy(*xyzrpy)
        depth = Scanner(box_scene, cfg).scan(pose).depth_image()
        assert grid._carve(pose, depth, cfg) == _carve_whole_box(oracle, pose, depth, cfg) > 1000
        np.testing.assert_array_equal(grid.labels, oracle.labels)


def test_voxels_outside_the_field_of_view_are_not_carved(box_scene):
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.0, elevation_min=-10.0, elevation_max=10.0)
    pose = pose_from_xyz_rpy(2.0, 1.5, 1.25)
    scan = Scanner(box_scene, cfg).scan(pose)
    grid = VoxelGrid.covering([0, 0, 0], [A, B, H], 0.05)
    grid.integrate(scan.to_world(pose), np.ones(len(scan), bool), pose, scan.depth_image(), cfg)
    empty = grid.centres(np.argwhere(grid.labels == VoxelLabel.EMPTY))
    rel = empty - pose[:3, 3]
    elevation = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
    # A voxel is carved only if its whole footprint is seen: its centre lies inside the field of view.
    assert len(empty) > 0 and np.all(np.abs(elevation) <= 10.0 + 1e-6)


def test_occupied_labels_and_structure_priority():
    grid = VoxelGrid.covering([0, 0, 0], [1, 1, 1], 0.1)
    points = np.array([[0.05, 0.05, 0.05], [0.06, 0.04, 0.05], [0.55, 0.55, 0.55], [0.95, 0.95, 0.95]])
    structure = np.array([False, True, False, True])
    cfg = ScannerConfig(angular_step=10.0)
    depth = np.full((cfg.n_rows, cfg.n_cols), np.nan)
    stats = grid.integrate(points, structure, pose_from_xyz_rpy(0.5, 0.5, 0.5), depth, cfg)
    assert grid.labels[0, 0, 0] == VoxelLabel.STRUCTURE  # a Structure point wins its voxel
    assert grid.labels[5, 5, 5] == VoxelLabel.CLUTTER
    assert grid.labels[9, 9, 9] == VoxelLabel.STRUCTURE
    assert stats.occupied == 3 and stats.structure == 2
    # Points outside the grid are ignored, not an error.
    grid.integrate(np.array([[5.0, 5.0, 5.0]]), np.array([True]), pose_from_xyz_rpy(0.5, 0.5, 0.5), depth, cfg)


def test_occlusion_labels_follow_the_roi_and_se_faces():
    grid = VoxelGrid.covering([-1, -1, 0], [3, 3, 1], 0.1)
    polygon = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    east = WallFace(np.array([2.0, 0.0]), np.array([2.0, 2.0]), 0.0, 1.0)

    def label_at(x, y, z):
        return grid.labels[tuple(grid.index_of(np.array([[x, y, z]]))[0])]

    grid.labels[tuple(grid.index_of(np.array([[0.55, 0.55, 0.55]]))[0])] = VoxelLabel.EMPTY
    grid.update_occlusion(polygon, 0.0, 1.0, [east])
    assert label_at(0.55, 0.55, 0.55) == VoxelLabel.EMPTY  # sensed voxels keep their label
    assert label_at(1.95, 0.55, 0.55) == VoxelLabel.OCCLUDED_STRUCTURE  # the SE east face passes through
    assert label_at(0.05, 0.55, 0.55) == VoxelLabel.OCCLUDED_CLUTTER  # the west face is not SE
    assert label_at(1.05, 1.05, 0.55) == VoxelLabel.OCCLUDED_CLUTTER  # the middle of the room
    assert label_at(0.55, 0.55, 0.05) == VoxelLabel.OCCLUDED_STRUCTURE  # the floor is SE
    assert label_at(0.55, 0.55, 0.95) == VoxelLabel.OCCLUDED_STRUCTURE  # the ceiling too
    assert label_at(2.55, 0.55, 0.55) == VoxelLabel.UNKNOWN  # outside the RoI
    # A smaller RoI returns the occluded voxels it no longer covers to UNKNOWN.
    grid.update_occlusion(polygon / 2, 0.0, 1.0, [])
    assert label_at(1.55, 1.55, 0.55) == VoxelLabel.UNKNOWN


def test_floor_and_ceiling_go_on_past_a_frontier_face_and_not_past_a_wall():
    grid = VoxelGrid.covering([-1, -1, 0], [3, 3, 1], 0.1)
    polygon = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])  # counter-clockwise
    east = WallFace(np.array([2.0, 0.0]), np.array([2.0, 2.0]), 0.0, 1.0)  # the room on its left
    north = WallFace(np.array([2.0, 2.0]), np.array([0.0, 2.0]), 0.0, 1.0)

    def label_at(x, y, z):
        return grid.labels[tuple(grid.index_of(np.array([[x, y, z]]))[0])]

    grid.update_occlusion(polygon, 0.0, 1.0, [north], frontier=[east], frontier_reach=0.5)
    for z in (0.05, 0.95):
        assert label_at(2.35, 1.05, z) == VoxelLabel.OCCLUDED_STRUCTURE  # past the frontier
        assert label_at(2.75, 1.05, z) == VoxelLabel.UNKNOWN  # farther than the reach
        assert label_at(1.05, 2.35, z) == VoxelLabel.UNKNOWN  # past a wall
    assert label_at(2.35, 1.05, 0.55) == VoxelLabel.UNKNOWN  # only the floor and ceiling go on
    # The guesses are known as such (a scan that should see them and does not refutes them).
    assert grid.speculative(np.array([[2.35, 1.05, 0.05], [0.55, 0.55, 0.05]])).tolist() == [True, False]
    # Without a ceiling (a room under the sky) only the floor does.
    grid.update_occlusion(polygon, 0.0, 1.0, [north], ceiling=False, frontier=[east], frontier_reach=0.5)
    assert label_at(2.35, 1.05, 0.05) == VoxelLabel.OCCLUDED_STRUCTURE
    assert label_at(2.35, 1.05, 0.95) == VoxelLabel.UNKNOWN


def test_a_frontier_is_an_edge_without_wall():
    from nbs_env.belief import frontier_faces

    east = WallFace(np.array([2.0, 0.0]), np.array([2.0, 2.0]), 0.0, 1.0)
    wall = np.array([[2.0, y, z] for y in np.arange(0.0, 2.0, 0.02) for z in np.arange(0.0, 1.0, 0.02)])
    floor = np.array([[x, y, 0.0] for x in np.arange(1.9, 2.1, 0.02) for y in np.arange(0.0, 2.0, 0.02)])
    assert frontier_faces([east], floor) == [east]  # only the floor along it: no wall seen
    assert frontier_faces([east], np.concatenate([wall, floor])) == []
    assert frontier_faces([WallFace(np.array([2.0, 0.0]), np.array([2.0, 0.2]), 0.0, 1.0)], floor) == []  # short


def test_npz_round_trip_and_ply(tmp_path):
    grid = VoxelGrid.covering([0, 0, 0], [1, 1, 1], 0.1)
    grid.labels[2:4, 2:4, 2:4] = VoxelLabel.STRUCTURE
    grid.labels[5, 5, 5] = VoxelLabel.OCCLUDED_STRUCTURE
    again = VoxelGrid.from_npz(grid.to_npz(tmp_path / "v.npz"))
    assert np.array_equal(again.labels, grid.labels) and np.allclose(again.origin, grid.origin)
    import trimesh

    cloud = trimesh.load(grid.to_ply(tmp_path / "v.ply"))
    assert len(cloud.vertices) == 9
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"bad\.npz: not a voxel grid"):
        VoxelGrid.from_npz(tmp_path / "bad.npz")


def test_bad_grid_input():
    with pytest.raises(ValueError, match="voxel_size"):
        VoxelGrid([0, 0, 0], 0.0, np.zeros((2, 2, 2), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        VoxelGrid([0, 0, 0], 0.1, np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="no VoxelLabel"):
        VoxelGrid([0, 0, 0], 0.1, np.full((2, 2, 2), 9, np.uint8))


def test_rays_down_to_the_floor_mark_the_voxels_they_crossed_and_navigation_reads_them_free():
    # A long empty room at the fast preset's 1 degree and 10 cm: the carving's pooled windows leave
    # voxels a hand's width above the floor unsensed in stripes, where rays that meet the floor in
    # front of a voxel share its window; the rays that crossed them say they are free.
    a, b, h = 9.0, 3.0, 2.5
    scene = box_room(a, b, h)
    cfg = ScannerConfig(angular_step=1.0, range_noise=0.0)
    pose = pose_from_xyz_rpy(1.0, 1.5, 1.5, 0.0, 0.0, 0.0)
    scan = Scanner(scene, cfg).scan(pose)
    grid = VoxelGrid.covering([-0.3, -0.3, -0.3], [a + 0.3, b + 0.3, h + 0.3], 0.1)
    grid.integrate(scan.to_world(pose), np.ones(len(scan), bool), pose, scan.depth_image(), cfg, floor_z=0.0)
    layer = 4  # the voxels from 0.1 to 0.2 m, the lowest of navigation's height band
    assert grid.origin[2] + layer * 0.1 == pytest.approx(0.1)
    row = slice(round((3.0 + 0.3) / 0.1), round((6.0 + 0.3) / 0.1))  # 2-5 m from the scanner
    centre = round((1.5 + 0.3) / 0.1)
    along = grid.labels[row, centre - 5 : centre + 5, layer]
    assert np.mean(along != VoxelLabel.EMPTY) > 0.1  # what the carving leaves
    assert grid.crossed[row, centre - 5 : centre + 5, layer].all()
    # Nothing crossed lies outside the room, at or below the floor, or above the traced height.
    crossed = grid.centres(np.argwhere(grid.crossed))
    assert np.all((crossed[:, :2] > 0) & (crossed[:, :2] < [a, b]))
    assert crossed[:, 2].min() > 0 and crossed[:, 2].max() < TRACE_HEIGHT + 0.1
    # Navigation reads them free: the room's middle is walkable from 1.5 m to 5 m out.
    tmap = traversable_floor(grid, 0.0, [pose[:3, 3]], [pose[:2, 3]], cfg, NavigationConfig())
    cells = tmap.cell_of(np.column_stack([np.arange(2.5, 6.0, 0.1), np.full(35, 1.5)]))
    assert tmap.free[cells[:, 0], cells[:, 1]].all()
    # Without the rays' evidence the same map is cut across.
    grid.crossed[:] = False
    cut = traversable_floor(grid, 0.0, [pose[:3, 3]], [pose[:2, 3]], cfg, NavigationConfig())
    assert not cut.free[cells[:, 0], cells[:, 1]].all()


def _occupy_plain(grid: VoxelGrid, points: np.ndarray, structure: np.ndarray) -> tuple[int, int]:
    """The marking of occupied voxels with whole-grid masks (the oracle of VoxelGrid._occupy)."""
    rel = (points.astype(np.float32) - grid.origin.astype(np.float32)) / np.float32(grid.voxel_size)
    idx = np.floor(rel).astype(np.int32)
    shape = np.asarray(grid.shape, dtype=np.int32)
    ok = ((idx >= 0) & (idx < shape)).all(axis=1)
    idx, structure = idx[ok], structure[ok]
    flat = (idx[:, 0].astype(np.int64) * shape[1] + idx[:, 1]) * shape[2] + idx[:, 2]
    labels = grid.labels.reshape(-1)
    before_occupied = (labels == VoxelLabel.CLUTTER) | (labels == VoxelLabel.STRUCTURE)
    before_structure = labels == VoxelLabel.STRUCTURE
    hit = np.zeros(labels.size, dtype=bool)
    hit[flat] = True
    hit_structure = np.zeros(labels.size, dtype=bool)
    hit_structure[flat[structure]] = True
    labels[hit & ~hit_structure & ~before_structure] = VoxelLabel.CLUTTER
    labels[hit_structure] = VoxelLabel.STRUCTURE
    return int(np.count_nonzero(hit & ~before_occupied)), int(np.count_nonzero(hit_structure & ~before_structure))


@pytest.mark.parametrize("seed", range(3))
def test_marking_occupied_voxels_point_by_point_is_the_whole_grid_marking(seed):
    """Points in and out of a grid holding every label, several to a voxel, Structure and Clutter
    mixed: the same labels and counts as the whole-grid masks."""
    rng = np.random.default_rng(seed)
    grid = VoxelGrid(np.array([-1.0, 0.5, 0.0]), 0.1, rng.integers(0, 6, (20, 15, 10)).astype(np.uint8))
    oracle = VoxelGrid(grid.origin.copy(), grid.voxel_size, grid.labels.copy())
    for _ in range(2):
        points = grid.origin + rng.uniform(-0.3, 2.3, (3000, 3)) * [1.0, 0.75, 0.5]
        points = np.vstack([points, points[:500]])  # repeated points
        structure = rng.random(len(points)) < 0.4
        assert grid._occupy(points, structure) == _occupy_plain(oracle, points, structure)
        np.testing.assert_array_equal(grid.labels, oracle.labels)


def _trace_low_plain(grid: VoxelGrid, points: np.ndarray, centre: np.ndarray, floor_z: float) -> np.ndarray:
    """The low rays' crossed voxels with every sample materialised (the oracle of the kernel)."""
    from nbs_env.mapping.voxels import TRACE_HEIGHT

    s = grid.voxel_size
    top = floor_z + TRACE_HEIGHT
    low = points[points[:, 2] < top]
    d = low - centre
    drop = -d[:, 2]
    length = np.linalg.norm(d, axis=1)
    ok = drop > 1e-6
    d, drop, length = d[ok], drop[ok], length[ok]
    enter = np.maximum((centre[2] - top) / drop, 0.0) * length
    leave = length - s * np.sqrt(3) / 2
    step = s / 2
    count = np.maximum(np.floor((leave - enter) / step).astype(np.int64) + 1, 0)
    crossed = np.zeros(grid.shape, dtype=bool)
    total = int(count.sum())
    if total:
        ray = np.repeat(np.arange(len(d)), count)
        first = np.cumsum(count) - count
        along = enter[ray] + (np.arange(total) - first[ray]) * step
        samples = centre + d[ray] * (along / length[ray])[:, None]
        idx = grid.index_of(samples)
        idx = idx[grid.inside(idx)]
        crossed[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return crossed


@pytest.mark.parametrize("seed", range(3))
def test_tracing_the_low_rays_ray_by_ray_marks_what_every_sample_marks(seed):
    """Returns below, at and above the traced height, in and out of the grid: the same voxels."""
    rng = np.random.default_rng(seed)
    grid = VoxelGrid(np.array([-3.0, -2.0, -0.2]), 0.05, np.zeros((120, 90, 40), dtype=np.uint8))
    centre = np.array([0.3, 0.4, 1.5])
    points = np.column_stack([rng.uniform(-5, 5, 4000), rng.uniform(-4, 4, 4000), rng.uniform(-0.3, 2.5, 4000)])
    grid._trace_low(points, centre, 0.0)
    want = _trace_low_plain(grid, points, centre, 0.0)
    assert want.any()
    np.testing.assert_array_equal(grid.crossed, want)


def _numpy_occlusion(grid, polygon, floor_z, ceiling_z, se_faces, ceiling, frontier, reach):
    """update_occlusion as numpy did it before the compiled pass (the oracle): whole-grid masks,
    one per SE face. Returns (labels, speculative flat indices)."""
    import shapely
    from shapely.geometry import Polygon

    from nbs_env.mapping.voxels import frontier_strips

    s = grid.voxel_size
    strips = frontier_strips(frontier, reach)
    grid._cover_prism(polygon, floor_z, ceiling_z, strips)
    labels = grid.labels.copy()
    labels[(labels == VoxelLabel.OCCLUDED_CLUTTER) | (labels == VoxelLabel.OCCLUDED_STRUCTURE)] = VoxelLabel.UNKNOWN
    xs, ys, zs = (grid.origin[a] + (np.arange(labels.shape[a]) + 0.5) * s for a in range(3))
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    in_plan = shapely.contains_xy(Polygon(polygon).buffer(s / 2), gx, gy)
    inside = in_plan[:, :, None] & ((zs >= floor_z - s / 2) & (zs <= ceiling_z + s / 2))[None, None, :]
    half = s / 2 * (1 + 1e-6)
    near = (np.abs(zs - floor_z) <= half) | ((np.abs(zs - ceiling_z) <= half) & ceiling)
    slab = in_plan[:, :, None] & near[None, None, :]
    past = np.zeros(labels.shape, dtype=bool)
    if strips:
        beyond = shapely.contains_xy(shapely.union_all(strips), gx, gy) & ~in_plan
        past = beyond[:, :, None] & near[None, None, :] & (labels == VoxelLabel.UNKNOWN)
        labels[past] = VoxelLabel.OCCLUDED_STRUCTURE
    for face in se_faces:
        rel_x, rel_y = gx - face.p0[0], gy - face.p0[1]
        u = rel_x * face.direction[0] + rel_y * face.direction[1]
        w = rel_x * face.normal[0] + rel_y * face.normal[1]
        on = (np.abs(w) <= half) & (u >= -half) & (u <= face.length + half)
        slab |= on[:, :, None] & ((zs >= face.z0 - half) & (zs <= face.z1 + half))[None, None, :]
    unsensed = labels == VoxelLabel.UNKNOWN
    labels[inside & unsensed & slab] = VoxelLabel.OCCLUDED_STRUCTURE
    labels[inside & unsensed & ~slab] = VoxelLabel.OCCLUDED_CLUTTER
    return labels, np.flatnonzero(past)


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_occlusion_pass_is_the_numpy_one(seed):
    """Random labels, a random concave RoI, slanted SE faces (some on voxel boundaries), frontier
    faces and the ceiling on or off: the compiled relabelling writes numpy's labels and speculative
    voxels, bit for bit, including after the grid grows."""
    rng = np.random.default_rng(seed)
    s = (0.05, 0.1)[seed % 2]
    grid = VoxelGrid.covering([-0.5, -0.5, -0.2], [3.2, 3.0, 2.6], s)  # the frontier reaches past it
    grid.labels[:] = rng.choice(6, size=grid.labels.shape, p=[0.4, 0.3, 0.05, 0.05, 0.1, 0.1]).astype(np.uint8)
    polygon = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 1.2], [1.5, 1.2], [1.2, 2.5], [0.0, 2.5]])
    polygon += rng.normal(0, 0.02, polygon.shape)
    faces = [WallFace(polygon[k], polygon[(k + 1) % 6], 0.0, 2.4) for k in range(6) if rng.random() < 0.7]
    faces.append(WallFace(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.3, 1.1))  # on voxel boundaries
    frontier = [WallFace(polygon[1], polygon[2], 0.0, 2.4)] if seed % 3 else []
    ceiling = bool(seed % 2)
    shape = grid.shape
    want, speculative = _numpy_occlusion(grid, polygon, 0.0, 2.4, faces, ceiling, frontier, 0.8)
    grid.update_occlusion(polygon, 0.0, 2.4, faces, ceiling=ceiling, frontier=frontier, frontier_reach=0.8)
    assert np.array_equal(grid.labels, want)
    assert np.array_equal(grid._speculative, speculative)
    assert (want == VoxelLabel.OCCLUDED_STRUCTURE).any() and (want == VoxelLabel.OCCLUDED_CLUTTER).any()
    assert bool(len(speculative)) == bool(frontier)
    assert (grid.shape != shape) == bool(frontier)  # the grid grew to hold the strip past the frontier
