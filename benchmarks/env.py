"""Benchmark: NBSEnv steps per second, and the time of each stage of a step against the raw cast.

Two parts:

1. ``nbs_env/NBS-Fast-v0`` steps per second on one core (the process is pinned to CPU 0 and every
   thread pool is set to one thread before numpy and open3d load): greedy episodes on generated 1-3
   room storeys. Reset time is reported apart. Goal: at least 20 steps/s.
2. The default config (``nbs_env/NBS-FiveRooms-v0``, 0.5° scanner, 5 cm voxels, odometry drift and
   ICP): the median time of each stage of a step over a greedy episode, each as a ratio to the bare
   Embree ``RaycastingScene.cast_rays`` of the same scan's rays, cast in the same process; the
   whole step's median, and apart for the steps within a room and those that end one.

Usage:
    python benchmarks/env.py --part fast --cores 1 [--episodes 10]
    python benchmarks/env.py --part default --cores 2
"""

from __future__ import annotations

import argparse
import sys

from _timing import pin_cores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="NBS-Fast-v0 episodes (seeds 0..N-1)")
    parser.add_argument("--cores", type=int, default=1, help="CPU cores the process may use")
    parser.add_argument("--part", choices=("fast", "default", "both"), default="both")
    args = parser.parse_args()
    pin_cores(args.cores)

    import nbs_env  # noqa: F401  (registers the ids)
    from policies import GreedyPolicy

    policy = GreedyPolicy()
    if args.part != "default":
        fast(args, policy)
    if args.part != "fast":
        default(args, policy)


def _play(env, policy, seed: int, stages: dict, casts: list, moves: list | None = None) -> tuple[float, list[float]]:
    """One episode: (reset seconds, step seconds); appends each step's stage times to ``stages`` and
    the bare Embree cast of the same step's scan, timed in this process, to ``casts``, and to
    ``moves`` whether the step ended a room (and so also searched doors and crossed one)."""
    import time

    t = time.perf_counter()
    obs, info = env.reset(seed=seed)
    reset = time.perf_counter() - t
    steps = []
    while True:
        action = policy.act(obs, info)
        room = info.get("room")
        t = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(action)
        steps.append(time.perf_counter() - t)
        if moves is not None:
            moves.append(terminated or info.get("room") != room)
        for s in stages:
            stages[s].append(info["times"][s])
        robot = env.unwrapped.storey.robot
        rays = robot._scanner.rays(robot.true_pose)
        t = time.perf_counter()
        robot._scanner.raw_cast(rays)
        casts.append(time.perf_counter() - t)
        if terminated or truncated:
            return reset, steps


def fast(args, policy) -> None:
    import statistics

    import gymnasium as gym

    from nbs_env.storey import STAGES

    print(f"part 1: nbs_env/NBS-Fast-v0 on {args.cores} core(s), {args.episodes} greedy episodes")
    env = gym.make("nbs_env/NBS-Fast-v0")
    step_times, reset_times, stages = [], [], {s: [] for s in (*STAGES, "evaluation")}
    casts: list[float] = []
    moves: list[bool] = []
    for seed in range(args.episodes):
        reset, steps = _play(env, policy, seed, stages, casts, moves)
        reset_times.append(reset)
        step_times.extend(steps)
    total = sum(step_times)
    cast = statistics.median(casts)
    mean = total / len(step_times)
    print(f"  steps: {len(step_times)}, {1 / mean:.1f} steps/s (mean {1e3 * mean:.0f} ms)")
    print(f"  reset: median {1e3 * statistics.median(reset_times):.0f} ms (storey generation + first scan)")
    rays = env.unwrapped.config.robot.scanner.n_rays
    print(f"  raw cast of one scan ({rays:,} rays): {1e3 * cast:.2f} ms; a mean step is {mean / cast:.0f}x it")
    for s, values in stages.items():
        print(f"    {s:15s} {1e3 * statistics.median(values):7.1f} ms median")
    for label, kind in (("within a room", False), ("ending a room", True)):
        some = [t for t, moved in zip(step_times, moves, strict=True) if moved == kind]
        if some:
            print(f"  steps {label}: {len(some)}, mean {1e3 * statistics.mean(some):.0f} ms")


def default(args, policy) -> None:
    import statistics

    import gymnasium as gym

    from nbs_env.storey import STAGES

    print(f"part 2: nbs_env/NBS-FiveRooms-v0 (default config), one greedy episode, {args.cores} core(s)")
    env = gym.make("nbs_env/NBS-FiveRooms-v0")
    per_stage = {s: [] for s in (*STAGES, "evaluation")}
    casts: list[float] = []
    moves: list[bool] = []
    _, steps = _play(env, policy, 0, per_stage, casts, moves)
    cast = statistics.median(casts)
    rays = env.unwrapped.config.robot.scanner.n_rays
    print(f"  {len(steps)} steps; raw cast of one scan ({rays:,} rays): {1e3 * cast:.1f} ms median")
    print(f"  {'stage':15s} {'median ms':>10s} {'x raw cast':>11s}")
    for s, values in per_stage.items():
        m = statistics.median(values)
        print(f"  {s:15s} {1e3 * m:10.1f} {m / cast:11.1f}")
    m = statistics.median(steps)
    print(f"  {'whole step':15s} {1e3 * m:10.1f} {m / cast:11.1f}")
    order = " ".join(f"{1e3 * t:.0f}{'*' * e}" for t, e in zip(steps, moves, strict=True))
    print(f"  steps in order (ms; * ends a room): {order}")
    # The median over steps depends on how many of them end a room, which the trajectory decides:
    # the two kinds apart compare runs whose trajectories differ.
    for label, kind in (("within a room", False), ("ending a room", True)):
        some = [t for t, moved in zip(steps, moves, strict=True) if moved == kind]
        if some:
            m = statistics.median(some)
            print(f"  {label:15s} {1e3 * m:10.1f} {m / cast:11.1f}   ({len(some)} steps)")
    print("  (a step that ends a room also detects doors, drives and takes the door-frame scan)")


if __name__ == "__main__":
    sys.exit(main())
