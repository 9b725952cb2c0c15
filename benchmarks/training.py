"""Benchmark: ``nbs train``'s steps per second against its workers, local and on Ray, and where the
time goes (the rollouts, the env steps in the workers, against PPO's updates).

Each setting is ``nbs train``'s own (MaskablePPO, the bundled network, the run's envs at the
training fidelity, generated storeys of ``--rooms`` rooms), timed by stable-baselines3's callbacks
at each rollout's start and end: the whole run's steps per second, the rollouts' alone, and the
updates' time. The reference in the same process is the first setting (one local worker by
default): every other is printed as a ratio of its steps per second. From the measured per-worker
rate and the update's cost per step the script also prints what N workers would give if each had
a core of its own (the projection's arithmetic is in the output).

Usage:
    python benchmarks/training.py                                  # local:1, local:2, ray:2
    python benchmarks/training.py --settings local:2,ray:2 --timesteps 2048 --preset fast
"""

from __future__ import annotations

import argparse
import time


def run(setting: str, args) -> dict:
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from train.ppo import TrainConfig, build_model, make_training_envs, ray_rollouts

    backend, _, envs = setting.partition(":")
    config = TrainConfig(
        envs=int(envs or 1),
        rooms=tuple(int(r) for r in args.rooms.split("-")),
        max_episode_steps=60,
        seed=0,
        completion=args.completion,
        n_steps=args.n_steps,
        preset=args.preset,
    )
    venv = ray_rollouts(config) if backend == "ray" else make_training_envs(config)
    model = build_model(config, venv)
    if backend == "ray":
        venv.attach(model)
    marks: list[tuple[str, float]] = []

    class Phases(BaseCallback):
        def _on_rollout_start(self) -> None:
            marks.append(("start", time.perf_counter()))

        def _on_rollout_end(self) -> None:
            marks.append(("end", time.perf_counter()))

        def _on_step(self) -> bool:
            return True

    # One rollout first, outside the timing: workers start, import and compile.
    model.learn(total_timesteps=config.n_steps * config.envs, callback=Phases())
    marks.clear()
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=Phases(), reset_num_timesteps=True)
    t1 = time.perf_counter()
    venv.close()
    pairs = list(zip(marks, [*marks[1:], ("start", t1)], strict=True))
    rollouts = sum(b[1] - a[1] for a, b in pairs if a[0] == "start" and b[0] == "end")
    updates = sum(b[1] - a[1] for a, b in pairs if a[0] == "end")
    n = model.num_timesteps
    return {
        "setting": setting,
        "workers": config.envs,
        "steps": n,
        "rate": n / (t1 - t0),
        "rollout_rate": n / rollouts,
        "update_per_step": updates / n,
        "threads": torch.get_num_threads(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settings", default="local:1,local:2,ray:2", help="BACKEND:WORKERS, the reference first")
    parser.add_argument("--timesteps", type=int, default=1024)
    parser.add_argument("--n-steps", type=int, default=128)
    parser.add_argument("--rooms", default="1-8")
    parser.add_argument("--preset", default="train")
    parser.add_argument("--completion", choices=("gain", "policy"), default="policy")
    parser.add_argument("--project", default="64", help="worker counts to project to, comma-separated")
    args = parser.parse_args()

    results = [run(s, args) for s in args.settings.split(",")]
    reference = results[0]["rate"]
    print(
        f"nbs train, preset {args.preset}, storeys of {args.rooms} rooms, completion {args.completion}, "
        f"{args.timesteps} timesteps a setting, n_steps {args.n_steps}\n"
    )
    print("| setting | steps/s | × the first | rollouts alone, steps/s | update, ms a step |")
    print("|---|---|---|---|---|")
    for r in results:
        print(
            f"| {r['setting']} | {r['rate']:.2f} | {r['rate'] / reference:.2f} | {r['rollout_rate']:.2f} "
            f"| {1000 * r['update_per_step']:.1f} |"
        )
    # The projection: a worker with a core of its own plays at the rate one local worker measured
    # here; the learner's update costs what it measured per step, and does not overlap the rollouts.
    single = results[0]
    per_worker = single["rollout_rate"] / single["workers"]
    update = min(r["update_per_step"] for r in results)
    print(
        f"\nprojection: one worker plays {per_worker:.2f} steps/s; an update costs {1000 * update:.1f} ms a step "
        f"(the least measured); N workers with a core each give N / (1 / {per_worker:.2f} + N × {update:.4f}) "
        "steps/s, if the rollouts do not wait on one another"
    )
    for text in args.project.split(","):
        workers = int(text)
        rate = workers / (1 / per_worker + workers * update)
        print(f"  {workers} workers: {rate:.0f} steps/s; 10^6 steps in {1e6 / rate / 3600:.1f} h")


if __name__ == "__main__":
    main()
