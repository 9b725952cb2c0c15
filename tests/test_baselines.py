"""The compared methods and the oracle: they run, respect the mask, are deterministic, and keep to
their sources' rules."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from nbs_env.env import NBSEnv, make_config
from policies import POLICIES, UnknownPolicyError, config_for, make_policy
from policies.baselines import FORMULATIONS
from policies.baselines._maps import march, stop_value, visible_cells_2d

BASELINES = ["stachniss_burgard", "blaer_allen", "potthast_sukhatme", "nearest_frontier"] + [
    f"information_gain:{f}" for f in FORMULATIONS
]


def play(name: str, seed: int, steps: int, scene: str = "l_room"):
    policy = make_policy(name, seed)
    env = NBSEnv(config_for(make_config("fast", scene=scene, max_scans=steps + 1), policy))
    obs, info = env.reset(seed=seed)
    policy.reset()
    actions = []
    for _ in range(steps):
        a = policy.act(obs, info)
        assert info["action_mask"][a], f"{name} chose masked action {a}"
        actions.append(a)
        obs, _, terminated, truncated, info = env.step(a)
        assert not info["invalid_action"]
        if terminated or truncated:
            break
    return actions, info, env


@pytest.mark.parametrize("name", BASELINES)
def test_each_baseline_runs_respects_the_mask_and_is_deterministic(name):
    a, info_a, env = play(name, 0, 3)
    b, info_b, _ = play(name, 0, 3)
    assert a == b and info_a["structure_sensed_pct"] == info_b["structure_sensed_pct"]
    assert info_a["scans"] >= 2 and info_a["structure_sensed_pct"] > 50.0
    # They end rooms by their own rule: the env gives them the "room done" action and no gains.
    assert env.action_space.n == env.max_candidates + 1 and not info_a["candidate_gains"].any()


def test_baselines_refuse_an_env_without_the_belief_view():
    env = NBSEnv("fast", scene="l_room")
    obs, info = env.reset(seed=0)
    with pytest.raises(KeyError, match="expose_belief"):
        make_policy("stachniss_burgard").act(obs, info)


def test_unknown_names_and_formulations_are_refused():
    with pytest.raises(UnknownPolicyError, match="unknown policy"):
        make_policy("clairvoyant")
    with pytest.raises(UnknownPolicyError, match="formulation"):
        make_policy("information_gain:psychic")
    assert {"greedy", "random", "stachniss_burgard", "blaer_allen", "potthast_sukhatme"} <= set(POLICIES)


def test_the_room_done_action_ends_the_room_and_a_one_room_storey():
    # Without the searches (which the declaration would first run): the paper's robot ends the room.
    env = NBSEnv("fast", scene="l_room", completion="policy", expose_belief=True, **{"rooms.wall_search.scans": 0})
    _, info = env.reset(seed=0)
    stop = env.stop_action
    assert info["action_mask"][stop] and info["belief"].new_room and len(info["belief"].scans) == 1
    _, _, terminated, _, info = env.step(stop)
    assert terminated and info["scans"] == 1 and not info["invalid_action"]


def test_2d_line_of_sight_stops_at_the_first_blocked_cell():
    blocked = np.zeros((40, 40), dtype=bool)
    blocked[30, :] = True  # a wall at x = 3.0-3.1 m
    seen = visible_cells_2d(blocked, np.zeros(2), 0.1, np.array([1.0, 2.0]), 0.0, 10.0)
    i, _ = np.unravel_index(seen, blocked.shape)
    assert i.max() == 30 and (i == 30).sum() > 5  # the wall is seen, nothing behind it


def test_march_counts_each_voxel_once():
    flat, first, inside, _ = march((10, 10, 10), np.zeros(3), 0.1, np.array([0.05, 0.55, 0.55]),
                                          np.array([[1.0, 0.0, 0.0]]), 2.0)  # fmt: skip
    voxels = flat[0][first[0] & inside[0]]
    i = np.unravel_index(voxels, (10, 10, 10))[0]
    # Samples every voxel: the ray starts in voxel 0 and crosses 1..9 along x; each counted once.
    assert len(voxels) == len(set(voxels.tolist())) and set(i.tolist()) == set(range(1, 10))


def test_oracle_sees_an_empty_box_almost_whole_and_is_monotone():
    from nbs_env.config import ScannerConfig
    from policies.oracle import oracle_plan
    from tests.helpers import box_room

    plan = oracle_plan(box_room(6.0, 4.0, 2.6), ScannerConfig(angular_step=1.0), spacing=0.1, radius=0.1)
    assert plan.max_coverage_pct > 97.0  # nothing hides anything in an empty box
    assert np.all(np.diff(plan.coverage_pct) > 0) and plan.coverage_pct[-1] == pytest.approx(plan.max_coverage_pct)
    assert plan.scans_to_reach(plan.coverage_pct[0]) == 1 and plan.scans_to_reach(100.1) is None
    # One scan misses the floor of its blind zone (1.5 m minimum range); a second one covers it.
    assert 1 < len(plan.positions) <= 4


@pytest.mark.parametrize(("opening", "outside", "reached"), [(True, False, 2), (False, False, 1), (True, True, 1)])
def test_the_oracle_scans_only_from_floor_the_robot_drives_to(opening, outside, reached):
    """Two rooms side by side: through a doorway both are the oracle's to scan from; with a wall
    between them (two dwellings), or with the doorway given as a door to the outside (a porch),
    only the start's."""
    from policies.oracle import reach
    from scenes import Door
    from tests.helpers import boxed_storey

    door = [(1.5, 2.5, 2.0)] if opening else []
    walls = [((0, 0), (8, 0), []), ((8, 0), (8, 4), []), ((8, 4), (0, 4), []), ((0, 4), (0, 0), []),
             ((4, 0), (4, 4), door)]  # fmt: skip
    scene = boxed_storey(walls, [(-0.1, -0.1, 8.1, 4.1)], [(-0.1, -0.1, 8.1, 4.1)], start=(2.0, 2.0))
    if outside:
        scene.doors = (Door((0, -1), np.array([4.0, 2.0, 0.0]), 1.0, 2.0, np.array([1.0, 0.0])),)
    area = reach(scene, 0.2)
    rooms = [shapely.box(0.1, 0.1, 3.9, 3.9), shapely.box(4.1, 0.1, 7.9, 3.9)]
    assert sum(area.intersection(r).area > 1.0 for r in rooms) == reached
    assert area.intersection(rooms[0]).area > 5.0  # the start's room always


# ---------------------------------------------------------------------- a fair comparison (issue 15)
PAPER_METHODS = ["stachniss_burgard", "blaer_allen", "potthast_sukhatme"]


def _episode(policy, scene, seed: int = 0, max_scans: int = 30):
    env = NBSEnv(config_for(make_config("fast", max_scans=max_scans), policy))
    obs, info = env.reset(seed=seed, options={"scene": scene})
    policy.reset()
    done = not env.storey.open
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
    env.last_info = info
    return env


@pytest.mark.parametrize("name", PAPER_METHODS)
def test_each_compared_method_ends_a_small_room_by_its_own_rule_before_the_cap(name):
    from tests.helpers import box_room

    policy = make_policy(name, 0)
    env = _episode(policy, box_room(5.0, 4.0, 2.6))
    ends = env.storey.room_ends
    cap = env.config.rooms.max_scans_per_room
    assert len(ends) == 1 and ends[0]["reason"] == "declared" and ends[0]["scans"] < cap, ends

    # The rule, not chance: the last decision's statistic was below the method's calibrated ε and
    # every earlier one at or above it.
    def value(t):
        return stop_value(t["statistic"], t["area_m2"], policy.stop_area_power)

    assert policy.trace[-1]["stop"] and value(policy.trace[-1]) < policy.stop_below
    assert all(value(t) >= policy.stop_below for t in policy.trace[:-1])
    assert env.last_info["structure_sensed_pct"] > 80.0


@pytest.mark.parametrize("name", PAPER_METHODS)
def test_a_threshold_of_zero_never_stops_and_a_huge_one_stops_at_the_first_decision(name):
    from tests.helpers import box_room

    room = box_room(5.0, 4.0, 2.6)
    never = make_policy(name, 0)
    never.stop_below = 0.0
    env = _episode(never, room, max_scans=6)
    assert not any(t["stop"] for t in never.trace) and len(env.storey.scans) == 6
    at_once = make_policy(name, 0)
    at_once.stop_below = 1e12
    env = _episode(at_once, room)
    # Blaer & Allen visit their phase-1 views before the rule applies.
    assert env.storey.room_ends[0]["reason"] == "declared" and at_once.trace[-1]["stop"]
    if name != "blaer_allen":
        assert len(env.storey.scans) == 1


@pytest.mark.parametrize("name", [*PAPER_METHODS, "nearest_frontier", "information_gain:rear_side_voxel+controlled"])
def test_the_controlled_mode_ends_rooms_by_the_greedys_rule(name):
    full = name if name.endswith("controlled") else f"{name}:controlled"
    policy = make_policy(full, 0)
    env = _episode(policy, "l_room", max_scans=40)
    # No "room done" action: the greedy's gain rule (or the cap, or no NVP) ends every room.
    assert env.stop_action is None and env.config.rooms.completion == "gain"
    assert {e["reason"] for e in env.storey.room_ends} <= {"gain", "cap", "no NVP"}
    assert env.storey.room_ends and not any(t.get("stop") for t in getattr(policy, "trace", []))


def test_a_bad_option_of_a_compared_method_is_refused():
    with pytest.raises(UnknownPolicyError, match="controlled"):
        make_policy("blaer_allen:fast")
    with pytest.raises(UnknownPolicyError, match="controlled"):
        make_policy("information_gain:rear_side_voxel+uncontrolled")
    with pytest.raises(ValueError, match="stop_below"):
        from policies.baselines import StachnissBurgardPolicy

        StachnissBurgardPolicy(stop_below=float("nan"))


def test_the_blind_zone_helper_is_the_one_the_greedy_and_the_compared_methods_read(monkeypatch):
    """Changing :func:`nbs_env.planning.planner.unseeable_free` changes the greedy's NVPs and the
    compared methods' maps alike."""
    import nbs_env.planning.planner as planner

    def views(name):
        policy = make_policy(name, 0)
        env = NBSEnv(config_for(make_config("fast", scene="l_room", max_scans=5), policy))
        _, info = env.reset(seed=0)
        return env, info

    _, info = views("stachniss_burgard")
    belief = info["belief"]
    walls_only = belief.grid.labels
    # The view takes the cone under the first stop as free: Empty voxels V(t) itself does not have.
    assert (belief.labels == 1).sum() > (walls_only == 1).sum()
    greedy_before = NBSEnv("fast", scene="l_room").reset(seed=0)[1]["action_mask"].sum()
    policy = make_policy("stachniss_burgard", 0)
    policy.observe(belief)
    free_before = policy.free.sum()

    monkeypatch.setattr(planner, "unseeable_free", lambda grid, stops, scanner, blocked=None: grid.labels.copy())
    _, info = views("stachniss_burgard")
    belief = info["belief"]
    assert np.array_equal(belief.labels, belief.grid.labels)
    policy.observe(belief)
    assert policy.free.sum() < free_before
    greedy_after = NBSEnv("fast", scene="l_room").reset(seed=0)[1]["action_mask"].sum()
    assert greedy_after < greedy_before  # the unseen cone under the stop is no floor to stand on


def test_potthast_sukhatme_sees_unknown_space_across_free_space():
    """A ray crosses known-free voxels (OctoMap's ray casting) and reaches the unknown beyond: the
    gain of a view over 2 m of free space onto unknown space is about what the same view has from
    right beside it."""
    from types import SimpleNamespace

    from policies.baselines.information_gain import PotthastSukhatmePolicy, sphere_directions

    policy = PotthastSukhatmePolicy()
    shape, s = (80, 20, 20), 0.1
    log_odds = np.full(shape, -2.0, dtype=np.float32)  # known free
    log_odds[40:] = 0.0  # unknown from x = 4 m
    policy.log_odds = log_odds
    grid = SimpleNamespace(shape=shape, origin=np.zeros(3), voxel_size=s)
    p = (1.0 / (1.0 + np.exp(-log_odds))).astype(np.float32)
    p[log_odds < -0.2] = 0.0
    unknown = np.abs(log_odds) < 0.2
    dirs = sphere_directions(5.0, -40.0, 60.0)

    def gain(x, probs=p):
        return policy._gain(probs, unknown, None, grid, np.array([x, 1.0, 1.0]), dirs, 6.0, 0.0)

    near, far = gain(3.5), gain(1.5)
    assert far > 0.1 * near > 0
    # Free voxels at their clamped p (0.12) would hide the unknown 2.5 m off almost entirely.
    clamped = (1.0 / (1.0 + np.exp(-log_odds))).astype(np.float32)
    assert gain(1.5, clamped) < 0.1 * far


def test_collapse_takes_the_skin_before_a_measured_surface_as_crossed_and_nothing_else():
    from nbs_env.labels import VoxelLabel
    from policies.baselines._maps import collapse

    labels = np.full((20, 6, 6), VoxelLabel.UNKNOWN, dtype=np.uint8)
    labels[:9] = VoxelLabel.EMPTY  # measured free space up to x = 8
    labels[10] = VoxelLabel.STRUCTURE  # a wall at x = 10; x = 9 is the carving's skin before it
    labels[3:5, 5, :] = VoxelLabel.UNKNOWN  # an unseen pocket in the free space, no surface beside it
    labels[3:5, 5, :] = VoxelLabel.UNKNOWN
    free, occupied, unknown = collapse(labels)
    assert free[9].all() and not unknown[9].any()  # crossed by the rays that measured the wall
    assert unknown[11:].all()  # behind the wall: unseen
    assert unknown[3:5, 5, :].all()  # free space beside it, but no measured surface: still unknown
    assert occupied[10].all() and not (free & occupied).any() and (free | occupied | unknown).all()


def test_the_workspace_reaches_past_frontier_faces_only():
    """The compared methods' region is the greedy's: the RoI, and 0.5 m past a frontier face; not past
    a wall or a door face (a margin all round reached into the next rooms through the doors)."""
    from types import SimpleNamespace

    from nbs_env.mapping.voxels import VoxelGrid
    from nbs_env.perception.faces import WallFace
    from policies.baselines._maps import WORKSPACE_REACH, workspace

    s = 0.1
    grid = VoxelGrid(np.array([-1.0, -1.0, -0.2]), s, np.zeros((60, 50, 30), dtype=np.uint8))
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]])  # counter-clockwise
    roi = SimpleNamespace(polygon=square, floor_z=0.0, ceiling_z=2.5, has_ceiling=True)
    east = WallFace(square[1], square[2], 0.0, 2.5)

    def column(belief, x, y):
        plan, prism = workspace(belief)
        i, j = int((x - grid.origin[0]) / s), int((y - grid.origin[1]) / s)
        assert prism[i, j].any() == plan[i, j]  # every column of the plan has voxels in the prism
        return bool(plan[i, j])

    walls = SimpleNamespace(grid=grid, roi=roi, frontier=[])
    opening = SimpleNamespace(grid=grid, roi=roi, frontier=[east])
    assert column(walls, 2.0, 1.5) and column(walls, 4.03, 1.5)  # inside, and the wall's voxels
    assert not column(walls, 4.3, 1.5)  # past a wall: none of the room's task
    assert column(opening, 4.3, 1.5) and column(opening, 4.0 + WORKSPACE_REACH - s, 1.5)
    assert not column(opening, 4.0 + WORKSPACE_REACH + s, 1.5)
    assert not column(opening, -0.3, 1.5) and not column(opening, 2.0, 3.3)  # other faces: walls
    prism = workspace(opening)[1]
    i, j = int((4.3 - grid.origin[0]) / s), int((1.5 - grid.origin[1]) / s)
    k_floor, k_mid, k_ceiling = (int((z - grid.origin[2]) / s) for z in (0.02, 1.25, 2.48))
    # Past the frontier only the floor and ceiling are taken to go on; inside, the whole height counts.
    assert prism[i, j, k_floor] and prism[i, j, k_ceiling] and not prism[i, j, k_mid]
    assert workspace(walls)[1][int((2.0 + 1) / s), j, k_mid]
