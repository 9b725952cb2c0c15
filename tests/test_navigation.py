"""Traversability, reachability, geodesic paths and NVP candidates on hand-built voxel grids."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from skimage.graph import MCP_Geometric

from nbs_env.errors import ConfigError
from nbs_env.labels import VoxelLabel, is_occupied
from nbs_env.planning.navigation import (
    NavigationConfig,
    Passage,
    assume_blind_zone_free,
    candidates,
    geodesic,
    path_to,
    reachable,
    traversability,
)

VS = 0.05
CFG = NavigationConfig()
NEED = CFG.robot_radius + CFG.safety_distance  # 0.45 m


def box_room(nx: int, ny: int, nz: int = 40, vs: float = VS) -> np.ndarray:
    """Walls one voxel thick round the edge, floor (k = 0) and ceiling (top layer) Structure, inside Empty.

    With the origin at 0 the floor surface is at z = vs; the height band of the defaults is then the
    voxel centres in [vs + 0.10, vs + 1.80].
    """
    labels = np.full((nx, ny, nz), VoxelLabel.EMPTY, dtype=np.uint8)
    labels[:, :, 0] = VoxelLabel.STRUCTURE
    labels[:, :, -1] = VoxelLabel.STRUCTURE
    labels[[0, -1], :, :] = VoxelLabel.STRUCTURE
    labels[:, [0, -1], :] = VoxelLabel.STRUCTURE
    return labels


def brute_clearance(labels, origin, vs, floor_z, xy) -> np.ndarray:
    """(n,) horizontal distance from each point to every occupied voxel centre in the height band, directly."""
    ijk = np.argwhere(is_occupied(labels))
    centres = np.asarray(origin) + (ijk + 0.5) * vs
    band = (centres[:, 2] >= floor_z + CFG.floor_clearance - 1e-9) & (centres[:, 2] <= floor_z + CFG.robot_height)
    c = centres[band, :2]
    d = np.linalg.norm(np.asarray(xy, dtype=float)[:, None, :] - c[None, :, :], axis=2)
    return d.min(axis=1)


def real(c) -> np.ndarray:
    return c.xy[c.mask].astype(float)


def polyline_length(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def cells_along(tmap, p: np.ndarray, per_voxel: int = 4) -> np.ndarray:
    """(m, 2) cells of points sampled along the polyline. The samples avoid t = 0.5 of a diagonal
    step, which lies exactly on the corner shared by four cells."""
    out = []
    for a, b in itertools.pairwise(p):
        n = max(2, int(np.linalg.norm(b - a) / VS * per_voxel))
        t = (np.arange(n) + 0.37) / n
        out.append(a + t[:, None] * (b - a))
    return tmap.cell_of(np.vstack(out))


# --------------------------------------------------------------------------------------------------
# The empty box room


def test_empty_room_candidates_are_exactly_the_clear_lattice_points():
    labels = box_room(102, 82)  # walls at x = 0.025, 5.075 and y = 0.025, 4.075
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    robot = (2.3, 1.8)
    c = candidates(tmap, robot, CFG)

    # Clear lattice points: x in 0.5..4.5, y in 0.5..3.5, less the four within 0.5 m of the robot.
    near = {(2.0, 1.5), (2.5, 1.5), (2.0, 2.0), (2.5, 2.0)}
    expected = [(x, y) for x in np.arange(0.5, 4.51, 0.5) for y in np.arange(0.5, 3.51, 0.5) if (x, y) not in near]
    assert c.count == len(expected) == 59
    np.testing.assert_array_equal(real(c), np.array(expected))  # (x index, y index) order

    # Clearance against the grid itself, by brute force.
    assert brute_clearance(labels, np.zeros(3), VS, VS, real(c)).min() >= NEED - 1e-9
    # On the 0.5 m world lattice.
    np.testing.assert_array_equal(c.lattice_index[c.mask] * 0.5, real(c))
    # mask, count and padding agree.
    assert c.mask.sum() == c.count and c.mask[: c.count].all() and not c.mask[c.count :].any()
    assert c.xy.shape == (64, 2) and c.xy.dtype == np.float32 and c.path_length.dtype == np.float32
    assert not c.xy[~c.mask].any() and not c.path_length[~c.mask].any()
    # In an empty room the geodesic is close to the straight line (8-connected: at most 8 % longer).
    straight = np.linalg.norm(real(c) - robot, axis=1)
    length = c.path_length[c.mask]
    assert np.all(length >= straight - 1e-5) and np.all(length <= straight * 1.09 + 2 * VS)


@pytest.mark.parametrize("fill", [VoxelLabel.EMPTY, VoxelLabel.UNKNOWN])
def test_candidates_stable_when_the_grid_grows(fill):
    labels = box_room(102, 82)
    robot = (2.3, 1.8)
    before = candidates(traversability(labels, np.zeros(3), VS, VS, CFG), robot, CFG)

    # Uneven margins (not multiples of the lattice), wide enough that an Empty margin holds free
    # cells outside the walls, which must stay unreachable.
    pad = ((13, 20), (7, 24), (0, 0))
    grown = np.pad(labels, pad, constant_values=int(fill))
    origin = np.array([-13 * VS, -7 * VS, 0.0])
    tmap = traversability(grown, origin, VS, VS, CFG)
    after = candidates(tmap, robot, CFG)
    if fill == VoxelLabel.EMPTY:
        assert tmap.free[-5, -5] and not reachable(tmap, robot)[-5, -5]

    assert after.count == before.count
    np.testing.assert_array_equal(after.xy, before.xy)
    np.testing.assert_array_equal(after.lattice_index, before.lattice_index)
    np.testing.assert_allclose(after.path_length, before.path_length, atol=1e-5)


def test_lattice_point_checked_exactly_not_by_its_cell():
    # A west wall two voxels thick: its inner face has centre x = 0.075. The lattice point x = 0.5 is
    # 0.425 m from it, but the cell holding it (centre 0.525) is 0.45 m away and passes.
    labels = box_room(102, 82)
    labels[1, :, :] = VoxelLabel.STRUCTURE
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    assert tmap.free[10, 40]
    lattice_only = NavigationConfig(snap=False)
    c = candidates(tmap, (2.3, 1.8), lattice_only)
    assert c.count > 0 and real(c)[:, 0].min() == 1.0
    assert brute_clearance(labels, np.zeros(3), VS, VS, real(c)).min() >= NEED - 1e-9
    # Snapped, the same: the lattice point next in, x = 1.0, is a candidate, so the wall's lattice cell
    # is no hole to fill.
    snapped = candidates(tmap, (2.3, 1.8), CFG)
    np.testing.assert_array_equal(snapped.lattice_index, c.lattice_index)


def test_a_passage_narrower_than_the_lattice_keeps_candidates():
    # Two rooms joined by a passage whose walls' voxel centres are 0.95 m apart (x = 0.475, 1.425): its
    # clear floor, x 0.925..0.975, lies between the lattice columns x = 0.5 and 1.0, neither clear.
    labels = box_room(122, 162, nz=40)  # 6 x 8 m
    labels[:, 60:100, 1:-1] = VoxelLabel.STRUCTURE  # a solid block y 3..5 ...
    labels[10:28, 60:100, 1:-1] = VoxelLabel.EMPTY  # ... cut by the passage, x 0.5..1.4
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    start = (3.0, 1.5)
    lattice = real(candidates(tmap, start, NavigationConfig(snap=False, max_candidates=500)))
    snapped_c = candidates(tmap, start, NavigationConfig(max_candidates=500))
    snapped = snapped_c.points

    def in_passage(p):
        return p[(p[:, 1] > 3.0) & (p[:, 1] < 5.0)]

    assert lattice[:, 1].max() > 5.0 and not len(in_passage(lattice))  # the robot passes, never stops in it
    # Snapped, every lattice cell of the passage with no clear lattice point beside it (y = 3.5, 4.0,
    # 4.5; y = 3.0 has y = 2.5 beside it) has its stop: one scan can look along it.
    assert len(in_passage(snapped)) == 3 and np.allclose(in_passage(snapped)[:, 0], 0.975)
    assert brute_clearance(labels, np.zeros(3), VS, VS, snapped).min() >= NEED - 1e-9
    # One candidate per lattice cell, each inside its cell, and the lattice points kept as they were.
    index = snapped_c.lattice_index[snapped_c.mask]
    assert len({tuple(i) for i in index.tolist()}) == len(index)
    assert np.abs(snapped - index * CFG.lattice).max() <= CFG.lattice / 2 + 1e-6
    on_lattice = {tuple(np.round(p, 6)) for p in lattice}
    assert on_lattice <= {tuple(np.round(p, 6)) for p in snapped}


def test_no_stand_in_where_all_clear_floor_is_near_the_robot():
    # A 1.4 x 1.4 m closet: its clear floor lies within min_distance of the robot in its middle.
    labels = box_room(30, 30)
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    c = candidates(tmap, (0.75, 0.75), CFG)
    assert c.count == 0 and not c.mask.any()


def test_clutter_box_keeps_candidates_away():
    labels = box_room(122, 122)  # 6 x 6 m
    # A table-high clutter box, centres x 2.075..3.075, y 2.075..3.075, z up to 0.8 m.
    labels[41:62, 41:62, 1:16] = VoxelLabel.CLUTTER
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    c = candidates(tmap, (1.0, 1.0), CFG)
    xy = real(c)
    assert c.count > 40
    assert brute_clearance(labels, np.zeros(3), VS, VS, xy).min() >= NEED - 1e-9
    # Beside the box, x = 3.5 is 0.425 m from its east face (centre 3.075), though the cell holding
    # it (centre 3.525) is exactly 0.45 m away and traversable: the point itself must be checked.
    assert tmap.obstacle[50, 50] and tmap.free[70, 50] and not tmap.free[69, 50]
    beside = (xy[:, 0] == 3.5) & (xy[:, 1] > 2.0) & (xy[:, 1] < 3.1)
    assert not beside.any()
    # Path lengths are geodesic: the point across the box is farther than the straight line.
    far = np.flatnonzero((xy[:, 0] == 4.0) & (xy[:, 1] == 4.0))
    assert len(far) == 1
    assert c.path_length[far[0]] > np.hypot(3.0, 3.0) + 0.1


def test_fenced_island_is_never_a_candidate():
    labels = box_room(162, 122)  # 8 x 6 m
    # A ring of clutter, 1 m high, around x 3..6, y 1.5..4.5; inside it Empty, outside the robot.
    ring = np.zeros(labels.shape[:2], dtype=bool)
    ring[60:121, 30:91] = True
    ring[61:120, 31:90] = False
    labels[ring, 1:21] = VoxelLabel.CLUTTER
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    inside = np.zeros_like(ring)
    inside[61:120, 31:90] = True
    assert tmap.free[inside].sum() > 500  # traversable inside, so only reachability keeps it out

    robot = (1.0, 1.0)
    region = reachable(tmap, robot)
    assert region[20, 20] and not region[inside].any()
    assert np.isinf(geodesic(tmap, robot).distances[inside]).all()
    c = candidates(tmap, robot, CFG)
    xy = real(c)
    assert c.count > 20
    assert not np.any((xy[:, 0] > 3.0) & (xy[:, 0] < 6.0) & (xy[:, 1] > 1.5) & (xy[:, 1] < 4.5))

    # From inside the island, the outside is unreachable instead.
    c_in = candidates(tmap, (4.5, 3.0), CFG)
    assert c_in.count > 0
    assert np.all((real(c_in) > [3.0, 1.5]) & (real(c_in) < [6.0, 4.5]))


# --------------------------------------------------------------------------------------------------
# Column test, visited cells


@pytest.mark.parametrize(
    "label", [VoxelLabel.UNKNOWN, VoxelLabel.OCCLUDED_CLUTTER, VoxelLabel.OCCLUDED_STRUCTURE, VoxelLabel.CLUTTER]
)
def test_one_voxel_blocks_its_column(label):
    labels = box_room(82, 82)
    clean = traversability(labels, np.zeros(3), VS, VS, CFG)
    labels[40, 40, 20] = label  # a single voxel, 1.025 m up
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    assert clean.free[40, 40] and not tmap.free[40, 40]
    if label == VoxelLabel.CLUTTER:
        # Occupied: an obstacle, with the clearance margin around it.
        assert tmap.obstacle[40, 40] and not tmap.free[45, 40] and tmap.clearance[45, 40] == pytest.approx(0.25)
    else:
        # Not seen: not traversable, but no obstacle; the neighbours keep their clearance.
        assert not tmap.obstacle.any() or not tmap.obstacle[40, 40]
        np.testing.assert_array_equal(tmap.clearance, clean.clearance)
        assert tmap.free[41, 40] and tmap.free[40, 39]


def test_floor_and_voxels_below_floor_clearance_are_ignored():
    labels = box_room(82, 82)
    labels[40, 40, 2] = VoxelLabel.UNKNOWN  # centre 0.125 m: 0.075 m above the floor at 0.05 m
    labels[30, 30, 1:3] = VoxelLabel.CLUTTER  # a cable on the floor
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    assert tmap.free[40, 40] and tmap.free[30, 30] and not tmap.obstacle[30, 30]
    # The floor (Structure, k = 0) and the ceiling (k = 39, 1.975 m) are outside the band.
    assert tmap.obstacle.sum() == 4 * 81  # the walls only
    # Raising the floor_z puts the same voxels in the band.
    raised = traversability(labels, np.zeros(3), VS, 0.0, CFG)
    assert not raised.free[40, 40] and raised.obstacle[30, 30]


def test_visited_positions_are_traversable_even_if_unknown():
    labels = box_room(82, 82)
    # The scanner's blind spot: a 0.5 x 0.5 m patch of Unknown columns round (2.0, 2.0).
    labels[35:45, 35:45, 1:39] = VoxelLabel.UNKNOWN
    origin = np.zeros(3)
    blind = traversability(labels, origin, VS, VS, CFG)
    assert not blind.free[35:45, 35:45].any()
    assert not reachable(blind, (2.0, 2.0)).any()  # nothing traversable within the robot's radius
    assert candidates(blind, (2.0, 2.0), CFG).count == 0

    tmap = traversability(labels, origin, VS, VS, CFG, visited_xy=[(2.0, 2.0)])
    centres = tmap.centre_of(np.argwhere(np.ones(tmap.shape, dtype=bool))).reshape(*tmap.shape, 2)
    dist = np.linalg.norm(centres - [2.0, 2.0], axis=2)
    in_patch = np.zeros(tmap.shape, dtype=bool)
    in_patch[35:45, 35:45] = True
    np.testing.assert_array_equal(tmap.free[in_patch], dist[in_patch] <= CFG.robot_radius)
    assert tmap.free[40, 40] and tmap.free[35, 40] and not tmap.free[35, 35]  # 0.225 and 0.318 m away
    # From there the robot reaches the rest of the room.
    c = candidates(tmap, (2.0, 2.0), CFG)
    assert c.count > 20 and reachable(tmap, (2.0, 2.0))[10, 10]


def test_start_snaps_to_a_traversable_cell_within_the_radius():
    labels = box_room(82, 82)
    labels[40, 40, 20] = VoxelLabel.UNKNOWN
    tmap = traversability(labels, np.zeros(3), VS, VS, CFG)
    start = (2.025, 2.025)  # the centre of the blocked cell
    g = geodesic(tmap, start)
    assert g.source is not None and g.source != (40, 40) and tmap.free[g.source]
    assert reachable(tmap, start)[10, 10]
    p = path_to(tmap, g, (3.0, 3.0))
    np.testing.assert_array_equal(p[0], start)
    np.testing.assert_array_equal(p[-1], (3.0, 3.0))


# --------------------------------------------------------------------------------------------------
# Geodesic paths


def l_corridor() -> tuple[np.ndarray, object]:
    """A 6 x 6 m room filled by a solid block but for a 1.5 m wide L along its south and west walls."""
    labels = box_room(122, 122)
    labels[30:, 30:, :] = VoxelLabel.STRUCTURE  # the block, centres from 1.525 m
    return labels, traversability(labels, np.zeros(3), VS, VS, CFG)


def test_geodesic_length_around_the_corner():
    _, tmap = l_corridor()

    # Where the robot may stand, worked out from the geometry: 0.45 m from the walls (centres 0.025
    # and 6.075) and from the block (centres from 1.525 in x and y), whose corner rounds the free L.
    c = (np.arange(122) + 0.5) * VS
    x, y = np.meshgrid(c, c, indexing="ij")
    to_walls = np.minimum.reduce([x - 0.025, y - 0.025, 6.075 - x, 6.075 - y])
    to_block = np.hypot(np.maximum(1.525 - x, 0), np.maximum(1.525 - y, 0))
    expected_free = (to_walls >= NEED - 1e-9) & (to_block >= NEED - 1e-9)
    np.testing.assert_array_equal(tmap.free, expected_free)

    start, goal = np.array([5.525, 0.775]), np.array([0.775, 5.525])
    g = geodesic(tmap, start)
    goal_cell = tuple(tmap.cell_of(goal)[0])
    d = g.distances[goal_cell]
    # The shortest 8-connected path by another library: scikit-image's minimum-cost path.
    mcp = MCP_Geometric(np.where(expected_free, 1.0, np.inf))
    costs, _ = mcp.find_costs([tuple(tmap.cell_of(start)[0])], [goal_cell])
    assert abs(d - VS * costs[goal_cell]) <= 2 * VS
    assert d > np.linalg.norm(goal - start) + 2.0  # it goes round, not through the block

    p = path_to(tmap, g, goal)
    np.testing.assert_array_equal(p[0], start)
    np.testing.assert_array_equal(p[-1], goal)
    assert polyline_length(p) == pytest.approx(d, abs=1e-9)
    cells = cells_along(tmap, p)
    assert tmap.free[cells[:, 0], cells[:, 1]].all()
    # No point in the middle of a straight run.
    u, v = np.diff(p, axis=0)[:-1], np.diff(p, axis=0)[1:]
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    assert np.all((np.abs(cross) > 1e-12) | (np.einsum("ij,ij->i", u, v) < 0))
    assert len(p) < 12  # a handful of turns, not one point per cell

    # Unreachable goals and goals off the grid are errors.
    with pytest.raises(ValueError, match="not reachable"):
        path_to(tmap, g, (4.0, 4.0))
    with pytest.raises(ValueError, match="outside the grid"):
        path_to(tmap, g, (7.0, 1.0))


def test_candidate_paths_match_their_lengths():
    _, tmap = l_corridor()
    start = (5.525, 0.775)
    c = candidates(tmap, start, CFG)
    # Lattice points of the free L: x or y in {0.5, 1.0}, the other in 0.5..5.5 (40), less the two
    # within 0.5 m of the start, (5.5, 0.5) and (5.5, 1.0).
    assert c.count == 38
    for i in range(c.count):
        p = c.path(i)
        np.testing.assert_allclose(p[0], start)
        np.testing.assert_allclose(p[-1], c.xy[i])
        assert polyline_length(p) == pytest.approx(float(c.path_length[i]), abs=1e-4)
        cells = cells_along(tmap, p)
        assert tmap.free[cells[:, 0], cells[:, 1]].all()
    with pytest.raises(IndexError):
        c.path(c.count)


# --------------------------------------------------------------------------------------------------
# More than K


def test_more_than_k_candidates_are_thinned_evenly_and_deterministically():
    vs = 0.1
    labels = box_room(202, 202, nz=21, vs=vs)  # 20 x 20 m at 10 cm
    tmap = traversability(labels, np.zeros(3), vs, vs, CFG)
    robot = (10.05, 10.05)
    everything = candidates(tmap, robot, NavigationConfig(max_candidates=5000))
    n = everything.count
    assert n > 1000 and everything.total == n

    c = candidates(tmap, robot, CFG)
    assert c.count == 64 and c.mask.all() and c.total == n
    pick = (np.arange(64) * n) // 64
    np.testing.assert_array_equal(c.xy, everything.xy[pick])
    np.testing.assert_array_equal(c.path_length, everything.path_length[pick])
    again = candidates(traversability(labels, np.zeros(3), vs, vs, CFG), robot, CFG)
    np.testing.assert_array_equal(again.xy, c.xy)
    np.testing.assert_array_equal(again.path_length, c.path_length)
    # Spread over the room, in lattice order.
    assert c.xy[:, 0].min() == 0.5 and c.xy[:, 0].max() >= 19.0
    assert np.all(np.diff(c.lattice_index[:, 0] * 10_000 + c.lattice_index[:, 1]) > 0)


# --------------------------------------------------------------------------------------------------
# Bad input


def test_bad_grids_are_refused():
    labels = box_room(42, 42)
    origin = np.zeros(3)
    with pytest.raises(ValueError, match=r"voxel_size.*0\.0"):
        traversability(labels, origin, 0.0, VS)
    with pytest.raises(ValueError, match=r"-0\.05"):
        traversability(labels, origin, -0.05, VS)
    with pytest.raises(ValueError, match=r"3-D uint8.*float64"):
        traversability(labels.astype(float), origin, VS, VS)
    with pytest.raises(ValueError, match=r"3-D uint8.*2-D"):
        traversability(labels[:, :, 0], origin, VS, VS)
    with pytest.raises(ValueError, match=r"floor_z -0\.5"):
        traversability(labels, origin, VS, -0.5)
    with pytest.raises(ValueError, match=r"floor_z 2\.0"):
        traversability(labels, origin, VS, 2.0)  # the top of the grid: outside
    with pytest.raises(ValueError, match="origin"):
        traversability(labels, [0.0, 0.0], VS, VS)
    with pytest.raises(ValueError, match="visited_xy"):
        traversability(labels, origin, VS, VS, CFG, visited_xy=[1.0, 1.0, 1.0])


def test_starts_outside_the_grid_are_refused():
    tmap = traversability(box_room(42, 42), np.zeros(3), VS, VS)
    for call in (reachable, geodesic, lambda t, s: candidates(t, s, CFG)):
        with pytest.raises(ValueError, match=r"start_xy \(2\.500, 1\.000\)"):
            call(tmap, (2.5, 1.0))
        with pytest.raises(ValueError, match="start_xy"):
            call(tmap, (float("nan"), 1.0))


def test_band_above_the_grid_is_unknown():
    labels = box_room(42, 42, nz=30)  # 1.5 m high: the top of the 1.8 m column was never seen
    tmap = traversability(labels, np.zeros(3), VS, VS)
    assert not tmap.free.any()
    assert traversability(labels, np.zeros(3), VS, VS, NavigationConfig(robot_height=1.2)).free.any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"robot_radius": 0}, "robot_radius"),
        ({"safety_distance": -0.1}, "safety_distance"),
        ({"robot_height": 0.05}, "robot_height"),
        ({"lattice": 0.0}, "lattice"),
        ({"max_candidates": 0}, "max_candidates"),
        ({"max_candidates": 2.5}, "max_candidates"),
        ({"min_distance": float("nan")}, "min_distance"),
    ],
)
def test_config_is_checked(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        NavigationConfig(**kwargs)


def test_config_round_trips_as_json_dict():
    import json

    cfg = NavigationConfig(lattice=0.4, max_candidates=32)
    assert NavigationConfig(**json.loads(json.dumps(cfg.to_dict()))) == cfg


def test_low_rays_with_no_return_keep_their_columns_unknown():
    """A stop beside a wall it cannot measure (closer than the minimum range): the low rays toward
    the wall returned nothing, so the floor that way is not assumed free; the other way it is."""
    s, n = 0.1, 40
    labels = np.full((n, n, 20), VoxelLabel.UNKNOWN, dtype=np.uint8)
    origin = np.array([-2.0, -2.0, 0.0])
    sensor = np.array([0.0, 0.0, 1.5])
    # Rays toward +x (azimuth within ±30°) at elevations -40..+10° returned nothing.
    az, el = np.meshgrid(np.radians(np.arange(-30, 31, 2)), np.radians(np.arange(-40, 11, 5)))
    toward_wall = np.column_stack(
        [(np.cos(el) * np.cos(az)).ravel(), (np.cos(el) * np.sin(az)).ravel(), np.sin(el).ravel()]
    )
    free = assume_blind_zone_free(labels, origin, s, [sensor], -40.0, 1.5, blocked=[toward_wall])
    plain = assume_blind_zone_free(labels, origin, s, [sensor], -40.0, 1.5)
    column_free = lambda grid, x, y: bool(np.all(grid[int((x + 2) / s), int((y + 2) / s), :10] == VoxelLabel.EMPTY))  # noqa: E731
    assert column_free(plain, 1.0, 0.0) and column_free(plain, -1.0, 0.0)
    assert not column_free(free, 1.0, 0.0) and not column_free(free, 0.5, 0.2)
    assert column_free(free, -1.0, 0.0) and column_free(free, 0.0, 1.0)
    with pytest.raises(ValueError, match="blocked"):
        assume_blind_zone_free(labels, origin, s, [sensor, sensor], -40.0, 1.5, blocked=[toward_wall])


@pytest.mark.parametrize(("elevation_min", "min_range"), [(-40.0, 1.5), (-60.0, 0.5), (-45.0, 0.6)])
def test_every_voxel_the_carving_cannot_see_below_the_field_is_assumed_free(elevation_min, min_range):
    """The blind zone is what the voxel carving leaves: a voxel whose lower angular edge lies below
    the lowest elevation is never carved (VoxelGrid's field-of-view test), so it must be assumed
    free. Under a steep scanner (-60°, a Leica RTC360's or a FARO Focus's) the old vertical margin
    left a ring of such voxels around the stop, and the robot could not leave its first stop."""
    s, n = 0.1, 40
    labels = np.full((n, n, 20), VoxelLabel.UNKNOWN, dtype=np.uint8)
    origin = np.array([-2.0, -2.0, 0.0])
    sensor = np.array([0.0, 0.0, 1.5])
    free = assume_blind_zone_free(labels, origin, s, [sensor], elevation_min, min_range)
    centres = origin + (np.stack(np.meshgrid(*[np.arange(k) for k in labels.shape], indexing="ij"), -1) + 0.5) * s
    offset = centres - sensor
    r = np.linalg.norm(offset, axis=-1)
    elevation = np.degrees(np.arctan2(offset[..., 2], np.hypot(offset[..., 0], offset[..., 1])))
    half_angle = np.degrees(s * np.sqrt(3) / 2 / np.maximum(r, 1e-3))
    uncarvable = (elevation - half_angle < elevation_min) | (r < min_range)
    assert np.all(free[uncarvable] == VoxelLabel.EMPTY)
    # ... and nothing the carving can see is assumed.
    assert np.all(free[~uncarvable] == VoxelLabel.UNKNOWN)


def _blind_zone_plain(labels, origin, s, sensors, elevation_min, min_range, blocked):
    """The blind zone voxel by voxel over the whole grid: the oracle of the windowed version."""
    from nbs_env.planning.navigation import _blocked_columns

    out = labels.copy()
    centres = origin + (np.stack(np.meshgrid(*[np.arange(k) for k in labels.shape], indexing="ij"), -1) + 0.5) * s
    for sensor, directions in zip(sensors, blocked, strict=True):
        offset = centres - sensor
        d = np.hypot(offset[..., 0], offset[..., 1])
        r = np.hypot(d, offset[..., 2])
        below = np.arctan2(offset[..., 2], d) - s * np.sqrt(3) / 2 / np.maximum(r, 1e-3) < np.radians(elevation_min)
        below |= r < min_range
        if len(directions):
            below &= ~_blocked_columns(directions, sensor, min_range, origin, s, labels.shape[:2])[:, :, None]
        unsensed = (labels == VoxelLabel.UNKNOWN) | (labels == VoxelLabel.OCCLUDED_CLUTTER)
        out[below & unsensed] = VoxelLabel.EMPTY
    return out


@pytest.mark.parametrize(("elevation_min", "min_range"), [(-40.0, 1.5), (-60.0, 0.5), (-10.0, 0.0)])
def test_the_blind_zone_looked_at_round_each_stop_is_the_whole_grid_answer(elevation_min, min_range):
    """assume_blind_zone_free looks only at the columns round each stop that its cone or its minimum
    range can reach; over a room much larger than the cone it frees exactly the voxels the test over
    the whole grid frees."""
    rng = np.random.default_rng(7)
    s = 0.1
    labels = rng.choice(
        np.array(
            [
                VoxelLabel.UNKNOWN,
                VoxelLabel.OCCLUDED_CLUTTER,
                VoxelLabel.OCCLUDED_STRUCTURE,
                VoxelLabel.EMPTY,
                VoxelLabel.CLUTTER,
            ],
            dtype=np.uint8,
        ),
        size=(100, 80, 30),
    )
    origin = np.array([-3.0, -2.0, -0.2])
    sensors = np.array([[0.0, 0.0, 1.5], [4.2, 3.1, 1.45], [-2.95, 5.9, 1.5], [6.9, -1.9, 1.2]])
    toward = rng.normal(size=(200, 3))
    toward[:, 2] = -np.abs(toward[:, 2])
    blocked = [toward / np.linalg.norm(toward, axis=1, keepdims=True), np.zeros((0, 3)), toward[:50], np.zeros((0, 3))]
    got = assume_blind_zone_free(labels, origin, s, sensors, elevation_min, min_range, blocked)
    want = _blind_zone_plain(labels, origin, s, sensors, elevation_min, min_range, blocked)
    np.testing.assert_array_equal(got, want)
    assert (got != labels).sum() > 1000  # the test frees something


# --------------------------------------------------------------------------------------------------
# The door the robot came in by


def door_room() -> tuple[np.ndarray, Passage]:
    """A 4 x 3 m room entered by a 0.8 m door in its 0.2 m thick wall at y = 0.2..0.4; the robot
    stands under the frame at (2.0, 0.3). Behind the door wall (the room it came from) is Unknown."""
    labels = box_room(82, 62)
    labels[:, 1:4, 1:39] = VoxelLabel.UNKNOWN  # the room behind
    labels[1:-1, 4:8, 1:39] = VoxelLabel.STRUCTURE  # the door wall, y in [0.2, 0.4)
    labels[32:48, 4:8, 1:39] = VoxelLabel.EMPTY  # the opening, x in [1.6, 2.4)
    labels[32:48, 4:8, 37:39] = VoxelLabel.STRUCTURE  # the lintel, above the robot's height band
    return labels, Passage((2.0, 0.3), (0.0, 1.0), 0.8)


def test_the_robot_leaves_the_door_it_came_in_by_with_its_radius_of_clearance():
    labels, door = door_room()
    start = (2.0, 0.3)
    # The full clearance (0.45 m) closes a 0.8 m door: the robot's own disc is cut off from the room.
    closed = traversability(labels, np.zeros(3), VS, VS, CFG, visited_xy=[start])
    assert not reachable(closed, start)[40, 40]
    assert candidates(closed, start, CFG).count == 0

    tmap = traversability(labels, np.zeros(3), VS, VS, CFG, visited_xy=[start], passages=[door])
    assert reachable(tmap, start)[40, 40]
    c = candidates(tmap, start, CFG)
    assert c.count > 10
    # The relaxed cells carry paths, not scans: every NVP keeps the full clearance.
    assert (tmap.clearance_at(real(c)) >= NEED - 1e-9).all()
    relaxed = tmap.free & ~closed.free
    assert relaxed.any()
    # Only in front of the opening, within its depth and half its width less the robot's radius ...
    centres = tmap.centre_of(np.argwhere(relaxed))
    assert (np.abs(centres[:, 0] - 2.0) <= 0.4 - CFG.robot_radius + 1e-9).all()
    assert (centres[:, 1] >= 0.3).all() and (centres[:, 1] <= 0.3 + door.depth).all()
    # ... and never closer to an obstacle than the robot's radius.
    assert (tmap.clearance[relaxed] >= CFG.robot_radius - 1e-9).all()
    # Unknown columns stay closed there too.
    labels[38:42, 12:14, 20] = VoxelLabel.UNKNOWN
    blind = traversability(labels, np.zeros(3), VS, VS, CFG, visited_xy=[start], passages=[door])
    assert not blind.free[38:42, 12:14].any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"direction": (1.0, 1.0)}, "unit"),
        ({"width": 0.0}, "width"),
        ({"depth": float("nan")}, "depth"),
        ({"centre": (1.0,)}, "centre"),
    ],
)
def test_passage_is_checked(kwargs, match):
    args = {"centre": (0.0, 0.0), "direction": (0.0, 1.0), "width": 0.8} | kwargs
    with pytest.raises(ConfigError, match=match):
        Passage(**args)


def test_overlapping_blind_zones_free_what_one_shared_mask_freed():
    """Three stops whose cones overlap, on random labels: freeing window by window frees exactly
    the unsensed voxels under any stop's cone, as one mask of the labels before any freeing did."""
    from nbs_env.planning.navigation import _blind_cone

    rng = np.random.default_rng(6)
    s = 0.1
    labels = rng.choice(6, size=(50, 40, 20), p=[0.4, 0.3, 0.1, 0.05, 0.1, 0.05]).astype(np.uint8)
    origin = np.array([-2.0, -2.0, 0.0])
    sensors = np.array([[0.0, 0.0, 1.5], [0.8, 0.3, 1.5], [1.5, 0.9, 1.5]])
    free = assume_blind_zone_free(labels, origin, s, sensors, -40.0, 1.5)
    want = labels.copy()
    unsensed = (labels == VoxelLabel.UNKNOWN) | (labels == VoxelLabel.OCCLUDED_CLUTTER)
    for sensor in sensors:
        window, below = _blind_cone(tuple(origin), s, labels.shape, tuple(sensor), -40.0, 1.5, None)
        want[window][below & unsensed[window]] = VoxelLabel.EMPTY
    assert np.array_equal(free, want)
    assert (free != labels).sum() > 100 and (labels == VoxelLabel.UNKNOWN).sum() > (free == VoxelLabel.UNKNOWN).sum()
