"""Benchmark: where ``nbs train``'s time goes, the rollouts (env steps in the workers) against PPO's updates.

The setup of ``nbs train`` (MaskablePPO, the bundled network, ``train.ppo.make_training_envs``:
generated storeys of 1-5 rooms on ``NBS-Fast-v0`` settings, one ``SubprocVecEnv`` worker per env),
timed by stable-baselines3's callbacks at each rollout's start and end. The reference in the same
run is the rollouts' own time: the updates are printed as a ratio of it.

Usage: python benchmarks/training.py [--timesteps 1024] [--envs 2] [--n-steps 128] [--torch-threads N]
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=1024)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--n-steps", type=int, default=128)
    parser.add_argument("--torch-threads", type=int, default=0, help="0: torch's default")
    parser.add_argument(
        "--completion", choices=("gain", "policy"), default="gain", help="gain: as every figure before issue 19"
    )
    args = parser.parse_args()

    import torch
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.callbacks import BaseCallback

    from train.ppo import TrainConfig, _policy_class, make_training_envs

    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    # nbs train's own envs and workers (each worker's share of the cores included).
    config = TrainConfig(envs=args.envs, rooms=(1, 5), max_episode_steps=40, seed=0, completion=args.completion)
    venv = make_training_envs(config)
    model = MaskablePPO(
        _policy_class(),
        venv,
        n_steps=args.n_steps,
        batch_size=64,
        seed=0,
        device="cpu",
        policy_kwargs={"network": config.network},
        verbose=0,
    )
    marks: list[tuple[str, float]] = []

    class Phases(BaseCallback):
        def _on_rollout_start(self) -> None:
            marks.append(("start", time.perf_counter()))

        def _on_rollout_end(self) -> None:
            marks.append(("end", time.perf_counter()))

        def _on_step(self) -> bool:
            return True

    t0 = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=Phases())
    t1 = time.perf_counter()
    venv.close()
    pairs = list(zip(marks, [*marks[1:], ("start", t1)], strict=True))
    rollouts = sum(b[1] - a[1] for a, b in pairs if a[0] == "start" and b[0] == "end")
    updates = sum(b[1] - a[1] for a, b in pairs if a[0] == "end")
    n = model.num_timesteps
    print(f"{n} timesteps, {args.envs} worker(s), torch threads {torch.get_num_threads()}")
    print(f"  whole run : {t1 - t0:7.1f} s  {n / (t1 - t0):6.2f} steps/s")
    print(f"  rollouts  : {rollouts:7.1f} s  {n / rollouts:6.2f} steps/s")
    print(f"  updates   : {updates:7.1f} s  {updates / rollouts:6.2f}x the rollouts")


if __name__ == "__main__":
    main()
