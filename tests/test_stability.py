"""Figures that hold on any machine: a perturbation far below any sensor's precision may fork a
trajectory, but the storey's scans and coverage stay within the spread over seeds."""

from __future__ import annotations

import numpy as np

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from nbs_env.report import metrics_dict
from nbs_env.sensing.scanner import Scanner
from policies import GreedyPolicy
from train.episode import run_episode

SCENE = "generated:1"


def _play(seed: int) -> dict:
    env = NBSEnv(make_config("fast", scene=SCENE))
    policy = GreedyPolicy()
    run_episode(env, policy, seed)
    return metrics_dict(env.storey, SCENE, policy, seed)


def test_a_micrometre_on_every_range_stays_within_the_spread_over_seeds(monkeypatch):
    seeds = [_play(seed) for seed in (0, 1, 2)]
    cast = Scanner.cast

    def shifted(self, rays):
        # Every true range 1 µm longer: the last bits a different CPU's kernels would change.
        t, prim = cast(self, rays)
        return t + np.float32(1e-6), prim

    monkeypatch.setattr(Scanner, "cast", shifted)
    perturbed = [_play(seed) for seed in (0, 1)]
    for key, floor in (("scans", 2.0), ("structure_sensed_pct", 1.5)):
        values = np.array([m[key] for m in seeds], dtype=float)
        mean, std = values.mean(), values.std()
        # A floor on the band: three seeds can agree by chance and give a std near 0.
        band = max(3 * std, floor)
        for m in perturbed:
            assert abs(m[key] - mean) <= band, (key, m[key], values.tolist())
    # The storey is still scanned well: a perturbation is no excuse for losing rooms.
    assert min(m["structure_sensed_pct"] for m in perturbed) > 85.0
