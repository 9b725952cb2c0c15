"""Benchmark: where a registration's time goes, piece by piece, over one greedy episode.

Each piece of ``nbs_env.sensing.registration`` (and of S(t), ``nbs_env.mapping.cloud``) is timed by
wrapping it (the scan's downsampled copy, the merge of the previous scan into S(t), the target's
cut, the target's k-d tree and covariances, the range image, the coarse copies, the ICP stages, the
checks after them, the heading check), over one greedy episode of the default configuration;
medians per call, against the median of ``register`` as a whole and of the bare Embree cast of the
episode's scans (the reference run in the same process).

Usage: PYTHONPATH=<checkout> python benchmarks/registration_pieces.py [--scene five_rooms] [--seed 0] [--cores 2]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict

from _timing import pin_cores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="five_rooms")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cores", type=int, default=2, help="CPU cores the process may use")
    args = parser.parse_args()
    pin_cores(args.cores)

    import nbs_env.robot as robot_module
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.mapping import cloud
    from nbs_env.sensing import registration as reg
    from policies import GreedyPolicy

    times: dict[str, list[float]] = defaultdict(list)

    def timed(owner, name: str, label: str) -> None:
        inner = getattr(owner, name)

        def wrapper(*a, **k):
            t = time.perf_counter()
            out = inner(*a, **k)
            times[label].append(time.perf_counter() - t)
            return out

        setattr(owner, name, wrapper)

    # Methods first, then the classes that own them.
    timed(cloud.AccumulatedCloud, "_update", "merge of the previous scan into S(t)")
    timed(reg._Source, "coarser", "a coarse copy of the scan")
    timed(reg._RangeImage, "see_through", "see-through test")
    timed(reg, "_ScanCopy", "the scan's copy (voxels, normals, covariances)")
    # S(t) makes the copy of a scan registered at its voxels, with the class it imported.
    timed(cloud, "_ScanCopy", "the scan's copy (voxels, normals, covariances)")
    timed(reg, "_select_target", "the target's cut (with the merge)")
    timed(reg, "_Target", "the target's k-d tree and covariances")
    timed(reg, "_RangeImage", "the range image")
    timed(reg, "_align", "ICP stages")
    timed(reg, "_attempt", "ICP stages and the checks after them")
    timed(reg, "_heading_offset", "heading check")
    timed(robot_module, "register", "register (whole)")

    env = NBSEnv(make_config("default", scene=args.scene))
    policy = GreedyPolicy()
    obs, info = env.reset(seed=args.seed)
    casts = []
    while True:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        robot = env.storey.robot
        rays = robot._scanner.rays(robot.true_pose)
        t = time.perf_counter()
        robot._scanner.raw_cast(rays)
        casts.append(time.perf_counter() - t)
        if terminated or truncated:
            break
    cast = statistics.median(casts)
    whole = statistics.median(times["register (whole)"])
    print(f"{args.scene} seed {args.seed}, {args.cores} core(s): {len(times['register (whole)'])} registrations")
    print(f"  raw cast of one scan: {1e3 * cast:.1f} ms median")
    print(f"  {'piece':50s} {'calls':>5s} {'median ms':>10s} {'x cast':>7s} {'of register':>11s}")
    for label, values in times.items():
        m = statistics.median(values)
        print(f"  {label:50s} {len(values):5d} {1e3 * m:10.1f} {m / cast:7.1f} {m / whole:11.2f}")


if __name__ == "__main__":
    main()
