"""Cost of a learned policy's decision against the env step it chooses for.

Plays NBS-Fast-v0 storeys with the bundled ``ppo:reference`` policy and times, per decision, the
policy's ``act`` (the 3-D CNN and the candidate scorer on the CPU, one observation) and the env's
``step`` (scan, perception, voxels, planning), in the same process. Prints medians and their ratio.

    python benchmarks/learned.py --storeys 5 [--threads 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--storeys", type=int, default=5, help="generated storeys to play (seeds 0..N-1)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--policy", default="ppo:reference")
    args = parser.parse_args()

    import torch

    from nbs_env.env import NBSEnv, make_config
    from policies import make_policy

    torch.set_num_threads(args.threads)
    policy = make_policy(args.policy, 0)
    act_s, step_s = [], []
    for seed in range(args.storeys):
        env = NBSEnv(make_config("fast", scene=f"generated:{seed}", max_scans=40))
        obs, info = env.reset(seed=seed)
        while True:
            t0 = time.perf_counter()
            action = policy.act(obs, info)
            t1 = time.perf_counter()
            obs, _, terminated, truncated, info = env.step(action)
            t2 = time.perf_counter()
            act_s.append(t1 - t0)
            step_s.append(t2 - t1)
            if terminated or truncated:
                break
    act, step = float(np.median(act_s)), float(np.median(step_s))
    print(f"{len(act_s)} decisions on {args.storeys} storeys, torch threads {args.threads}")
    print(f"policy act   median {act * 1e3:7.2f} ms")
    print(f"env step     median {step * 1e3:7.2f} ms")
    print(f"ratio act / step: {act / step:.3f}")


if __name__ == "__main__":
    main()
