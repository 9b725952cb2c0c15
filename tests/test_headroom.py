"""train.headroom: the split of the greedy's scans and path, and the hindsight estimate."""

from __future__ import annotations

import pytest

from nbs_env.env import NBSEnv
from policies import GreedyPolicy
from train.headroom import greedy_scans, summarise


@pytest.mark.parametrize("scene", ["generated:20000002", "l_room"])
def test_the_split_adds_up_to_the_greedy_episode(scene):
    scans = greedy_scans(scene)
    env = NBSEnv("fast", scene=scene)
    obs, info = env.reset(seed=0)
    policy = GreedyPolicy()
    while True:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    assert len(scans) == info["scans"]
    assert sum(s["metres"] for s in scans) == pytest.approx(info["path_length_m"])
    assert sum(s["gain_pt"] for s in scans) == pytest.approx(info["structure_sensed_pct"])
    # One hand-over per room entered: the first scan and one door-frame scan per door crossed.
    crossed = sum(e["event"] == "crossed" for e in info["door_events"])
    assert sum(s["handover"] for s in scans) == 1 + crossed
    assert scans[0]["handover"] and scans[0]["metres"] == 0.0


def test_the_estimate_drops_only_trailing_small_gains():
    def scan(room, gain, metres=2.0, handover=False):
        return {"room": room, "handover": handover, "metres": metres, "gain_pt": gain}

    episode = [
        scan(0, 30.0, 0.0, handover=True),
        scan(0, 0.1),  # small, but a larger gain follows in the room: kept
        scan(0, 5.0),
        scan(0, 0.3),  # trailing: dropped at 0.5
        scan(0, 0.2),  # trailing: dropped at 0.25 and 0.5
        scan(1, 20.0, 4.0, handover=True),  # the next room's door-frame scan: never dropped
        scan(1, 0.4),  # trailing: dropped at 0.5
    ]
    summary = summarise([episode])
    assert summary["scans"] == 7 and summary["chosen_scans"] == 5 and summary["path_m"] == 14.0
    estimate = {b["threshold_pt"]: b for b in summary["estimate"]}
    assert estimate[0.25]["fewer_scans_pct"] == pytest.approx(100 / 7)
    assert estimate[0.5]["fewer_scans_pct"] == pytest.approx(300 / 7)
    assert estimate[0.5]["coverage_lost_pt"] == pytest.approx(0.9)
    assert estimate[0.5]["shorter_path_pct"] == pytest.approx(600 / 14)
