"""The compared methods and the oracle: they run, respect the mask, are deterministic, and keep to
their sources' rules."""

from __future__ import annotations

import numpy as np
import pytest

from nbs_env.env import NBSEnv, make_config
from policies import POLICIES, UnknownPolicyError, make_policy
from policies.baselines import FORMULATIONS
from policies.baselines._maps import march, visible_cells_2d
from train.episode import config_for

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
    env = NBSEnv("fast", scene="l_room", completion="policy", expose_belief=True)
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
