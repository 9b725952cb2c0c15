"""Write ``ppo_reference_observations.npz``: observations of ``NBS-Fast-v0`` and the shipped policy's
logits on them, for a test that checks the policy without replaying episodes (an episode forks at
near-ties on other CPUs; a forward pass does not).

Usage::

    python tests/data/make_ppo_observations.py

Greedy episodes on the first two validation storeys (``generated:20000000`` and ``20000001``, seed
0), in the env the policy was trained in (``completion="policy"`` for a policy with a "room done"
action); every second observation is kept, with its action mask.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from policies import GreedyPolicy, config_for, make_policy

OUT = Path(__file__).with_name("ppo_reference_observations.npz")


def main() -> None:
    policy = make_policy("ppo:reference")
    greedy = GreedyPolicy()
    keys = ("voxels", "candidates", "pose", "room")
    keep: dict[str, list[np.ndarray]] = {k: [] for k in (*keys, "mask", "logits")}
    for storey in (20_000_000, 20_000_001):
        # The robot the policy requires (its room rules and its "room done" action).
        env = NBSEnv(config_for(make_config("fast", scene=f"generated:{storey}"), policy))
        obs, info = env.reset(seed=0)
        for step in range(40):
            if step % 2 == 0:
                for key in keys:
                    keep[key].append(obs[key])
                keep["mask"].append(info["action_mask"])
                keep["logits"].append(policy.logits(obs).astype(np.float32))
            obs, _, terminated, truncated, info = env.step(greedy.act(obs, info))
            if terminated or truncated:
                break
    np.savez_compressed(OUT, **{k: np.stack(v) for k, v in keep.items()})
    print(f"wrote {OUT}: {len(keep['logits'])} observations")


if __name__ == "__main__":
    main()
