"""Benchmark: the training fidelity's step against the fast preset's, side by side on the same storeys.

Each storey is a generated one (seeds from ``--base``, ``--rooms`` rooms, the distribution
``nbs train`` draws from); a policy plays it once per preset, the presets alternating in order
from storey to storey so that neither gets the warmer cache. A step's cost is the episode's whole
time (its reset included: training pays for resets too) over its decisions; the ratio against the
first preset, run in the same process, is the figure. The coverage of a preset without the
coverage meter is counted afterwards, outside the timing, by a meter fed the same registered
points, so that both presets' figures are the same measurement.

A preset may carry dotted overrides, ``NAME+PATH=VALUE+...`` (values read as JSON): how a coarser
variant of the training fidelity would fare.

Usage:
    python benchmarks/fidelity.py --storeys 12 --cores 1
    python benchmarks/fidelity.py --presets fast,train --policy greedy:0.8+stop=0.04 --completion policy
    python benchmarks/fidelity.py --presets fast,train,train+robot.scanner.angular_step=2.0
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from _timing import pin_cores


def _play(env, policy, seed: int) -> dict:
    """One episode: its seconds (reset and steps), decisions, scans, path and coverage."""
    import numpy as np

    from nbs_env.evaluation import CoverageMeter

    points: list[tuple[np.ndarray, np.ndarray]] = []
    t = time.perf_counter()
    obs, info = env.reset(seed=seed)
    reset = time.perf_counter() - t
    points += env.storey.step_scans
    seconds, steps = reset, 0
    while True:
        action = policy.act(obs, info)
        t = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(action)
        seconds += time.perf_counter() - t
        steps += 1
        points += env.storey.step_scans
        if terminated or truncated:
            break
    storey = env.storey
    stages: dict[str, float] = {}
    for record in storey.scans:  # every scan's stage times, the reset's first scan included
        for stage, t in record.times.items():
            stages[stage] = stages.get(stage, 0.0) + t
    coverage = storey.coverage_pct()
    if storey.meter is None:  # counted outside the timing, with the meter the other preset ran
        meter = CoverageMeter(storey.scene, env.config.coverage_spacing, env.config.coverage_radius)
        for world, origin in points:
            meter.add(world, origin)
        coverage = meter.percent()
    return {
        "seconds": seconds,
        "reset": reset,
        "steps": steps,
        "scans": len(storey.scans),
        "path": storey.path_length,
        "coverage": coverage,
        "stages": stages,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--storeys", type=int, default=12)
    parser.add_argument("--base", type=int, default=30_000_000, help="seed of the first storey")
    parser.add_argument("--rooms", default="1-8", help="room range of the generated storeys")
    parser.add_argument("--presets", default="fast,train", help="the reference first")
    parser.add_argument("--policy", default="greedy")
    parser.add_argument("--completion", choices=("gain", "policy"), default="gain")
    parser.add_argument("--cores", type=int, default=1)
    parser.add_argument("--max-episode-steps", type=int, default=60)
    args = parser.parse_args()
    pin_cores(args.cores)

    import numpy as np

    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from policies import make_policy

    lo, _, hi = args.rooms.partition("-")
    presets = args.presets.split(",")
    common = {
        "generator.rooms": (int(lo), int(hi or lo)),
        "rooms.completion": args.completion,
        "max_scans": args.max_episode_steps,
    }
    envs = {}
    for name in presets:
        base, *assignments = name.split("+")
        overrides = dict(common)
        for assignment in assignments:
            key, _, value = assignment.partition("=")
            overrides[key] = json.loads(value)
        envs[name] = NBSEnv(make_config(base, **overrides))
    policy = make_policy(args.policy)
    _play(envs[presets[0]], policy, args.base - 1)  # warm-up: imports, compilation, first calls
    runs: dict[str, list[dict]] = {name: [] for name in presets}
    for k in range(args.storeys):
        order = presets if k % 2 == 0 else presets[::-1]
        for name in order:
            runs[name].append(_play(envs[name], policy, args.base + k))

    print(
        f"{args.policy} (completion {args.completion}) on {args.storeys} generated storeys of {args.rooms} rooms "
        f"(seeds {args.base}-{args.base + args.storeys - 1}), {args.cores} core(s)\n"
    )
    print("| preset | ms a step (reset included) | × the first | ms a reset | SE % | scans | path m | steps |")
    print("|---|---|---|---|---|---|---|---|")
    reference = None
    for name in presets:
        r = runs[name]
        per_step = 1000 * sum(x["seconds"] for x in r) / sum(x["steps"] for x in r)
        reference = reference or per_step
        print(
            f"| {name} | {per_step:.1f} | {per_step / reference:.2f} | {1000 * np.mean([x['reset'] for x in r]):.0f} "
            f"| {np.mean([x['coverage'] for x in r]):.2f} | {np.mean([x['scans'] for x in r]):.2f} "
            f"| {np.mean([x['path'] for x in r]):.1f} | {np.mean([x['steps'] for x in r]):.2f} |"
        )
    print("\nWhere a step's time goes, ms a step (the stages of every scan; 'other': the rest of the")
    print("reset, door detection, the observation and the bookkeeping):\n")
    stages = ("scan", "registration", "roi", "classification", "voxels", "planning", "evaluation")
    print("| preset | " + " | ".join(stages) + " | other |")
    print("|---|" + "---|" * (len(stages) + 1))
    for name in presets:
        r = runs[name]
        steps = sum(x["steps"] for x in r)
        per = {st: 1000 * sum(x["stages"].get(st, 0.0) for x in r) / steps for st in stages}
        other = 1000 * sum(x["seconds"] for x in r) / steps - sum(per.values())
        print(f"| {name} | " + " | ".join(f"{per[st]:.1f}" for st in stages) + f" | {other:.1f} |")
    first = runs[presets[0]]
    for name in presets[1:]:
        d = [b["coverage"] - a["coverage"] for a, b in zip(first, runs[name], strict=True)]
        s = [b["scans"] - a["scans"] for a, b in zip(first, runs[name], strict=True)]
        print(
            f"\n{name} against {presets[0]}, storey by storey: SE {np.mean(d):+.2f} points (largest |Δ| "
            f"{np.max(np.abs(d)):.2f}), scans {np.mean(s):+.2f}"
        )


if __name__ == "__main__":
    sys.exit(main())
