"""Profile: where whole greedy episodes spend their time (cProfile), the top entries as Markdown.

One warm-up episode runs first, so that imports and first-call set-up are not counted. Then the
episodes of the given scenes and seeds run under cProfile, and the functions with the most time of
their own (``tottime``) and the most time in all they call (``cumtime``) are printed with their
share of the profiled time, ready for benchmarks/README.md.

The reference in the same run is the bare Embree cast of the scans the episodes took (the
scanner's ``cast_rays``): the profiled time is also given as a multiple of it.

Usage:
    python benchmarks/hotspots.py --preset fast --scenes generated:0-9 --cores 1
    python benchmarks/hotspots.py --preset default --scenes five_rooms --cores 2 --max-scans 20
"""

from __future__ import annotations

import argparse
import os
import sys


def _pin(cores: int) -> None:
    # Thread pools read these when they load, so they are set before numpy and open3d are imported.
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(cores)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, set(range(cores)))


def _scenes(spec: str) -> list[str]:
    """``generated:A-B`` expands to one scene per seed; otherwise a comma-separated list."""
    out = []
    for part in spec.split(","):
        if part.startswith("generated:") and "-" in part:
            a, b = part.split(":", 1)[1].split("-")
            out.extend(f"generated:{k}" for k in range(int(a), int(b) + 1))
        else:
            out.append(part)
    return out


def _short(key: tuple[str, int, str]) -> str:
    path, line, name = key
    if path == "~":
        return name
    for root in ("nbs_env/", "scenes/", "policies/", "site-packages/"):
        if root in path:
            path = path[path.index(root) + (len("site-packages/") if root == "site-packages/" else 0) :]
            break
    return f"{path}:{line} {name}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=("fast", "train", "default"), default="fast")
    parser.add_argument("--scenes", default="generated:0-9", help="generated:A-B or a comma-separated list")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds")
    parser.add_argument("--max-scans", type=int, default=40)
    parser.add_argument("--cores", type=int, default=1, help="CPU cores the process may use")
    parser.add_argument("--top", type=int, default=15, help="entries per table")
    args = parser.parse_args()
    _pin(args.cores)

    import cProfile
    import pstats
    import time

    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.sensing.scanner import Scanner
    from policies import GreedyPolicy

    casts: list[float] = []
    raw = Scanner.raw_cast

    def timed_cast(self, rays):
        t = time.perf_counter()
        out = raw(self, rays)
        casts.append(time.perf_counter() - t)
        return out

    def episode(scene: str, seed: int, profile: cProfile.Profile | None) -> tuple[int, float]:
        env = NBSEnv(make_config(args.preset, scene=scene, max_scans=args.max_scans))
        policy = GreedyPolicy()
        obs, info = env.reset(seed=seed)
        steps, spent = 0, 0.0
        while True:
            action = policy.act(obs, info)
            t = time.perf_counter()
            if profile is not None:
                profile.enable()
            obs, _, terminated, truncated, info = env.step(action)
            if profile is not None:
                profile.disable()
            spent += time.perf_counter() - t
            steps += 1
            if profile is not None:
                # The bare cast of this step's last scan, outside the profile: the reference.
                robot = env.storey.robot
                timed_cast(robot._scanner, robot._scanner.rays(robot.true_pose))
            if terminated or truncated:
                return steps, spent

    scenes = _scenes(args.scenes)
    seeds = [int(s) for s in args.seeds.split(",")]
    episode(scenes[0], 1000, None)  # warm-up: imports, first calls
    profile = cProfile.Profile()
    steps, spent = 0, 0.0
    for scene in scenes:
        for seed in seeds:
            n, s = episode(scene, seed, profile)
            steps, spent = steps + n, spent + s
    cast = sorted(casts)[len(casts) // 2]
    stats = pstats.Stats(profile)
    total = stats.total_tt
    print(
        f"{args.preset} preset, {len(scenes)} scene(s) x {len(seeds)} seed(s), {args.cores} core(s): "
        f"{steps} steps, {1e3 * spent / steps:.1f} ms a step ({steps / spent:.1f} steps/s), "
        f"{spent / steps / cast:.0f}x the median bare cast of a step's scan ({1e3 * cast:.2f} ms)"
    )
    rows = stats.stats  # type: ignore[attr-defined]
    for title, column in (("own time (tottime)", 2), ("with callees (cumtime)", 3)):
        print(f"\n| {title} | calls | ms a step | share |\n|---|---|---|---|")
        ranked = sorted(rows.items(), key=lambda kv: kv[1][column], reverse=True)
        shown = 0
        for key, value in ranked:
            if column == 3 and not any(root in key[0] for root in ("nbs_env/", "scenes/", "policies/")):
                continue  # with callees, only the project's own functions say where time goes
            ms, share = 1e3 * value[column] / steps, 100 * value[column] / total
            print(f"| `{_short(key)}` | {value[1]} | {ms:.1f} | {share:.0f}% |")
            shown += 1
            if shown == args.top:
                break


if __name__ == "__main__":
    sys.exit(main())
