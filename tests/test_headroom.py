"""train.headroom: the split of the greedy's scans and path, and the hindsight bound."""

from __future__ import annotations

import pytest

from nbs_env.env import NBSEnv
from policies import GreedyPolicy
from train.headroom import greedy_steps, summarise


def test_the_split_adds_up_to_the_greedy_episode():
    steps = greedy_steps("generated:20000002")
    env = NBSEnv("fast", scene="generated:20000002")
    obs, info = env.reset(seed=0)
    policy = GreedyPolicy()
    while True:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    assert sum(s["scans"] for s in steps) == info["scans"]
    assert sum(s["metres"] for s in steps) == pytest.approx(info["path_length_m"])
    assert sum(s["gain_pt"] for s in steps) == pytest.approx(info["structure_sensed_pct"])
    declared = [s for s in steps if s["declared"]]
    # The first scan, then one hand-over per room entered: each takes exactly one scan.
    assert len(declared) >= 2 and all(s["scans"] == 1 for s in declared[1:-1])
    assert all(s["scans"] == 1 for s in steps if not s["declared"])


def test_the_bound_drops_only_trailing_small_gains():
    def step(room, gain, metres=2.0, declared=False):
        return {"room": room, "declared": declared, "scans": 1, "metres": metres, "gain_pt": gain}

    episode = [
        step(-1, 30.0, 0.0, declared=True),
        step(0, 0.1),  # small, but a larger gain follows in the room: kept
        step(0, 5.0),
        step(0, 0.3),  # trailing: dropped at 0.5
        step(0, 0.2),  # trailing: dropped at 0.25 and 0.5
        step(0, 20.0, 4.0, declared=True),
        step(1, 0.4),  # trailing: dropped at 0.5
    ]
    summary = summarise([episode])
    assert summary["scans"] == 7 and summary["chosen_scans"] == 5 and summary["path_m"] == 14.0
    bound = {b["threshold_pt"]: b for b in summary["bound"]}
    assert bound[0.25]["fewer_scans_pct"] == pytest.approx(100 / 7)
    assert bound[0.5]["fewer_scans_pct"] == pytest.approx(300 / 7)
    assert bound[0.5]["coverage_lost_pt"] == pytest.approx(0.9)
    assert bound[0.5]["shorter_path_pct"] == pytest.approx(600 / 14)
