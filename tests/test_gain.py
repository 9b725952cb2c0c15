"""The greedy NBS gain on hand-built grids: occlusion, field of view, range, ranking."""

from __future__ import annotations

import numpy as np
import pytest

from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.planner import greedy_order
from nbs_env.planning.visibility import GainConfig, VisibilityModel, coarse_blocking

S = 0.1


def room_with_cabinet() -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 6 x 3 m grid at 10 cm: the wall at x = 5.95 m is still Occluded-structure, and a cabinet
    (Clutter, 0.5 m deep, 1.5 m wide, 2 m tall) stands 0.3 m in front of it for y in [1, 2.5]."""
    labels = np.full((60, 60, 30), VoxelLabel.EMPTY, dtype=np.uint8)
    labels[59, :, :] = VoxelLabel.OCCLUDED_STRUCTURE
    labels[51:56, 10:25, 0:20] = VoxelLabel.CLUTTER
    return labels, np.zeros(3)


@pytest.mark.parametrize("group", [1, 2, 3])
def test_target_groups_are_the_voxels_sharing_their_index_over_group(group):
    """The groups are those of np.unique over the rows of index // group (the oracle), in its order,
    with its counts and the mean centres of their members."""
    rng = np.random.default_rng(5)
    labels = rng.choice(
        np.array([VoxelLabel.EMPTY, VoxelLabel.OCCLUDED_STRUCTURE, VoxelLabel.CLUTTER], dtype=np.uint8),
        p=[0.6, 0.3, 0.1],
        size=(37, 23, 11),
    )
    origin = np.array([1.25, -3.5, 0.05])
    model = VisibilityModel(labels, origin, S, GainConfig(group=group))
    idx = np.argwhere(labels == VoxelLabel.OCCLUDED_STRUCTURE)
    _, inverse, counts = np.unique(idx // group, axis=0, return_inverse=True, return_counts=True)
    centres = origin + (idx + 0.5) * S
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.reshape(-1), centres)
    np.testing.assert_array_equal(model.group_counts, counts)
    np.testing.assert_array_equal(model.group_centres, sums / counts[:, None])


def _first_entry(blocking: np.ndarray, origin: np.ndarray, size: float, start: np.ndarray, unit: np.ndarray) -> float:
    """The oracle: the smallest t >= 0 at which start + t * unit is in a blocking voxel's closed box
    (the slab test against every blocking voxel), inf when there is none."""
    lo = origin + np.argwhere(blocking) * size
    hi = lo + size
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - start) / unit, (hi - start) / unit
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    hit = (near <= far) & (far >= 0)
    return float(max(near[hit].min(), 0.0)) if hit.any() else np.inf


@pytest.mark.parametrize("seed", range(6))
def test_lines_of_sight_are_those_of_the_slab_test_against_every_blocking_voxel(seed):
    """On random grids, with sensors inside and outside them, a target is seen exactly when it lies
    in the range limits and the elevation band and the line to it enters no blocking voxel before the
    tolerance short of it (the oracle tests every voxel's box)."""
    rng = np.random.default_rng(seed)
    shape = tuple(int(n) for n in rng.integers(4, 26, 3))
    labels = np.where(rng.random(shape) < rng.uniform(0.01, 0.12), VoxelLabel.CLUTTER, VoxelLabel.EMPTY)
    labels = labels.astype(np.uint8)
    origin = rng.uniform(-2, 2, 3)
    size = float(rng.uniform(0.04, 0.2))
    config = GainConfig(tolerance_voxels=float(rng.uniform(0, 1.5)))
    model = VisibilityModel(labels, origin, size, config)
    scanner = ScannerConfig(min_range=0.1, max_range=float(np.ptp(shape) * size), elevation_min=-60.0)
    extent = np.asarray(shape) * size
    sensors = origin + rng.uniform(-0.3, 1.3, (4, 3)) * extent
    targets = origin + rng.uniform(-0.2, 1.2, (60, 3)) * extent
    got = model.sees(sensors, targets, scanner)
    blocking = labels == VoxelLabel.CLUTTER
    lo, hi = np.sin(np.radians(scanner.elevation_min)), np.sin(np.radians(scanner.elevation_max))
    for c, sensor in enumerate(sensors):
        for n, target in enumerate(targets):
            d = np.linalg.norm(target - sensor)
            unit = (target - sensor) / d
            inside = scanner.min_range <= d <= scanner.max_range and lo <= unit[2] <= hi
            want = inside and _first_entry(blocking, origin, size, sensor, unit) >= d - config.tolerance_voxels * size
            assert got[c, n] == want, (c, n)
    assert got.any() and not got.all()


def test_lines_along_an_axis_and_through_a_corner():
    """Lines parallel to an axis are traversed; a line through the edge that two diagonal blocking
    voxels share does not slip between them."""
    labels = np.zeros((12, 12, 4), dtype=np.uint8)
    labels[6, 2, :] = VoxelLabel.STRUCTURE  # on the x axis line at y = 2.5 voxels
    labels[5, 6, :] = labels[6, 5, :] = VoxelLabel.CLUTTER  # a diagonal step meeting at (6, 6)
    model = VisibilityModel(labels, np.zeros(3), 1.0, GainConfig(tolerance_voxels=0.5))
    scanner = ScannerConfig(min_range=0.0, max_range=100.0, elevation_min=-90.0, elevation_max=90.0)
    sensors = np.array([[0.5, 2.5, 2.5], [0.5, 8.5, 2.5], [3.0, 3.0, 2.5]])
    targets = np.array([[11.5, 2.5, 2.5], [11.5, 8.5, 2.5], [0.5, 2.5, 0.5], [9.0, 9.0, 2.5], [3.5, 11.5, 2.5]])
    seen = model.sees(sensors, targets, scanner)
    assert not seen[0, 0]  # along x through the wall at x = 6
    assert seen[1, 1]  # along x, clear
    assert seen[0, 2]  # down a free column
    assert not seen[2, 3]  # along the diagonal through the corner (6, 6) of the step
    assert seen[2, 4]  # away from the step


def test_coarse_cells_hold_a_blocking_voxel_exactly_when_one_of_theirs_does():
    rng = np.random.default_rng(4)
    blocking = rng.random((9, 13, 6)) < 0.02
    coarse = coarse_blocking(blocking, 4)
    assert coarse.shape == (3, 4, 2)
    for i, j, k in np.ndindex(coarse.shape):
        assert coarse[i, j, k] == blocking[4 * i : 4 * i + 4, 4 * j : 4 * j + 4, 4 * k : 4 * k + 4].any()


def test_a_wall_hidden_behind_a_cabinet_favours_the_far_side():
    labels, origin = room_with_cabinet()
    model = VisibilityModel(labels, origin, S)
    scanner = ScannerConfig(min_range=0.5)
    behind = model.targets[(model.targets[:, 1] > 1.1) & (model.targets[:, 1] < 2.4) & (model.targets[:, 2] < 1.9)]
    assert len(behind) > 0
    # In front of the cabinet, looking at it: the wall part behind it is hidden.
    front = np.array([3.0, 1.75, 1.5])
    # Beside the cabinet, close to the wall: the wall part behind the cabinet is seen at an angle.
    side = np.array([5.4, 4.0, 1.5])
    vis_front = model.visible(front, scanner)
    vis_side = model.visible(side, scanner)
    hidden = (model.targets[:, 1] > 1.2) & (model.targets[:, 1] < 2.3) & (model.targets[:, 2] < 1.9)
    assert not vis_front[hidden].any()
    assert vis_side[hidden].sum() > 0
    assert vis_side[hidden].sum() > vis_front[hidden].sum()
    # When the rest of the wall is already Structure, the whole gain is the hidden part: the far side wins.
    seen = labels.copy()
    wall = seen[59]
    wall[wall == VoxelLabel.OCCLUDED_STRUCTURE] = VoxelLabel.STRUCTURE
    wall[10:25, 0:20] = VoxelLabel.OCCLUDED_STRUCTURE
    gains = VisibilityModel(seen, origin, S).gains(np.array([front, side]), scanner)
    assert gains[1] > gains[0]
    assert gains[0] < 0.1 * 15 * 20


def test_field_of_view_and_range_limits_are_never_counted():
    labels, origin = room_with_cabinet()
    model = VisibilityModel(labels, origin, S)
    scanner = ScannerConfig(min_range=1.5, elevation_min=-40.0, elevation_max=60.0)
    sensor = np.array([4.8, 4.0, 1.5])
    visible = model.visible(sensor, scanner)
    rel = model.targets[visible] - sensor
    dist = np.linalg.norm(rel, axis=1)
    elevation = np.degrees(np.arcsin(rel[:, 2] / dist))
    assert visible.sum() > 100
    assert dist.min() >= 1.5
    assert elevation.min() >= -40.0 and elevation.max() <= 60.0
    # Some wall voxels are close enough, or steep enough, to be left out.
    rel_all = model.targets - sensor
    d_all = np.linalg.norm(rel_all, axis=1)
    assert np.any(d_all < 1.5) and not visible[d_all < 1.5].any()


def test_occluded_clutter_switch_blocks_lines_of_sight():
    labels, origin = room_with_cabinet()
    labels[40:45, 30:40, :25] = VoxelLabel.OCCLUDED_CLUTTER
    sensor = np.array([2.0, 3.5, 1.5])
    scanner = ScannerConfig(min_range=0.5)
    free = VisibilityModel(labels, origin, S, GainConfig(occluded_clutter_blocks=False)).gains(sensor[None], scanner)
    blocked = VisibilityModel(labels, origin, S, GainConfig(occluded_clutter_blocks=True)).gains(sensor[None], scanner)
    assert blocked[0] < free[0]


def test_greedy_order_ties_go_to_the_shorter_path():
    gains = np.array([10, 30, 30, 5, 99])
    paths = np.array([1.0, 4.0, 2.0, 0.5, 0.1])
    mask = np.array([True, True, True, True, False])
    assert greedy_order(gains, paths, mask).tolist() == [2, 1, 0, 3, 4]


@pytest.mark.expensive
def test_predicted_gain_ranks_like_realised_conversions_on_generated_rooms():
    from train.evaluate_gain import room_correlations

    rows = room_correlations(20, GainConfig())
    rho = [r["spearman"] for r in rows]
    assert len(rho) == 20
    # Measured on the NVPs the robot plans over (0.63 mean, 0.72 median on this machine); a gain
    # unrelated to what a scan converts would give about 0.
    assert np.mean(rho) >= 0.5 and np.median(rho) >= 0.6, rho
    # Few NVPs lie inside furniture the robot never measured (the blind zone taken as free).
    assert sum(r["inside_obstacles"] for r in rows) <= 0.1 * sum(r["candidates"] for r in rows)


@pytest.mark.parametrize("clutter_blocks", [False, True])
def test_the_models_compiled_read_of_the_labels_is_numpys(clutter_blocks):
    """Blocking voxels, their coarse cells and the Occluded-structure targets, as numpy's masks,
    ``argwhere`` and the padded reshape gave them."""
    from nbs_env.labels import is_occupied

    rng = np.random.default_rng(11)
    labels = rng.choice(6, size=(23, 17, 11), p=[0.3, 0.3, 0.1, 0.1, 0.1, 0.1]).astype(np.uint8)
    model = VisibilityModel(labels, np.array([0.3, -1.2, 0.0]), 0.1, GainConfig(occluded_clutter_blocks=clutter_blocks))
    blocking = is_occupied(labels) | (clutter_blocks & (labels == VoxelLabel.OCCLUDED_CLUTTER))
    padded = np.zeros((24, 20, 12), dtype=bool)
    padded[:23, :17, :11] = blocking
    assert np.array_equal(model.blocking, blocking)
    assert np.array_equal(model.coarse, padded.reshape(6, 4, 5, 4, 3, 4).any(axis=(1, 3, 5)))
    targets = np.argwhere(labels == VoxelLabel.OCCLUDED_STRUCTURE)
    assert np.array_equal(model.targets, np.array([0.3, -1.2, 0.0]) + (targets + 0.5) * 0.1)


def _policy_inputs(gains, paths, mask):
    from nbs_env.observation import CandidateColumn

    table = np.zeros((len(gains), len(CandidateColumn)), dtype=np.float32)
    table[:, CandidateColumn.PATH_LENGTH] = paths
    table[:, CandidateColumn.VALID] = mask
    return {"candidates": table.ravel()}, {"candidate_gains": np.asarray(gains), "action_mask": np.asarray(mask)}


def test_greedy_near_takes_the_nearest_candidate_close_enough_to_the_best_gain():
    from policies import GreedyPolicy, UnknownPolicyError, make_policy

    gains = [100, 85, 79, 90, 200]
    paths = [6.0, 3.0, 1.0, 3.0, 0.1]
    mask = [True, True, True, True, False]  # the masked 200 is neither the best gain nor a choice
    obs, info = _policy_inputs(gains, paths, mask)
    assert make_policy("greedy").act(obs, info) == 0
    # 85 and 90 reach 0.8 × 100 at the same path: the larger gain; 79 does not reach it.
    assert make_policy("greedy:0.8").act(obs, info) == 3
    assert make_policy("greedy:0.75").act(obs, info) == 2
    assert GreedyPolicy(near=1.0).act(obs, info) == GreedyPolicy().act(obs, info)
    assert make_policy("greedy:0.8").name == "greedy:0.8"
    for bad in ("greedy:0", "greedy:1.5", "greedy:near", "greedy:nan"):
        with pytest.raises(UnknownPolicyError, match=r"\(0, 1\]"):
            make_policy(bad)


def test_greedy_stop_ends_rooms_at_its_completion_fraction():
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from policies import UnknownPolicyError, config_for, make_policy
    from train.episode import run_episode

    policy = make_policy("greedy:0.8+stop=0.2")
    assert (policy.name, policy.near) == ("greedy:0.8+stop=0.2", 0.8)
    assert policy.config_overrides == {"rooms.completion_fraction": 0.2} and policy.requires == {}
    assert make_policy("greedy").config_overrides == {}
    bad_options = ("stop=1", "stop=-0.1", "stop=nan", "stop=x", "far=0.5", "0.8+0.9", "stop=0.1+stop=0.2")
    for bad in (f"greedy:{option}" for option in bad_options):
        with pytest.raises(UnknownPolicyError, match=r"stop=FRACTION"):
            make_policy(bad)
    # The same room, the same first scan: a rule that asks a candidate for 40% of the room's
    # structural voxels ends it sooner than the paper's 3%, and the room ends by the gain rule.
    scans = {}
    for name in ("greedy", "greedy:stop=0.4"):
        policy = make_policy(name, 0)
        env = NBSEnv(config_for(make_config("fast", scene="l_room"), policy))
        assert env.config.rooms.completion_fraction == (0.4 if "stop" in name else 0.03)
        run_episode(env, policy, 0)
        assert [end["reason"] for end in env.storey.room_ends] == ["gain"]
        scans[name] = len(env.storey.scans)
    assert scans["greedy:stop=0.4"] < scans["greedy"]
