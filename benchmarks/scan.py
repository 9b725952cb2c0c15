"""Benchmark: our scan vs the raw Embree cast of the same rays, and ICP time per scan.

For the default (0.5°) and the fine (0.2°) pattern, on the bundled ``five_rooms``:
- rays per second of ``Scanner.scan`` (ray construction, cast, noise, range filter, points);
- rays per second of a bare ``RaycastingScene.cast_rays`` of the same prebuilt rays, in the same
  process, and the ratio (goal: our wrapper costs less than 25% over the raw cast);
- the time to register a scan into S(t) by ICP.

Usage: python benchmarks/scan.py [--repeat 15]
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np
from _timing import median_seconds

from nbs_env.config import ScannerConfig
from nbs_env.mapping.cloud import AccumulatedCloud
from nbs_env.sensing.pose import planar, pose_from_xyz_rpy
from nbs_env.sensing.registration import register
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    scene = load_scene("five_rooms")
    start = scene.start
    pose = pose_from_xyz_rpy(start[0], start[1], 1.5, 0.002, -0.003, 0.4)
    print(f"scene five_rooms, {len(scene.mesh.faces)} triangles; median of {args.repeat} runs")
    for label, step in (("default", 0.5), ("fine", 0.2)):
        cfg = ScannerConfig(angular_step=step)
        scanner = Scanner(scene, cfg)
        rng = np.random.default_rng(0)
        rays = scanner.rays(pose)
        # Interleave the two so that machine load affects both alike.
        ours, raw = [], []
        for _ in range(args.repeat):
            raw.append(median_seconds(lambda rays=rays, scanner=scanner: scanner.raw_cast(rays), 1))
            ours.append(median_seconds(lambda scanner=scanner, rng=rng: scanner.scan(pose, rng), 1))
        t_ours, t_raw = statistics.median(ours), statistics.median(raw)
        n = cfg.n_rays
        print(f"{label} ({step}°, {n:,} rays)")
        print(f"  Scanner.scan            : {n / t_ours / 1e6:6.2f} M rays/s  ({t_ours * 1e3:7.1f} ms)")
        print(f"  raw cast_rays, same rays: {n / t_raw / 1e6:6.2f} M rays/s  ({t_raw * 1e3:7.1f} ms)")
        print(f"  overhead of our wrapper : {100 * (t_ours / t_raw - 1):6.1f} %")
        cloud = AccumulatedCloud()
        first = scanner.scan(pose, rng)
        cloud.add(first.truth.points_world, pose[:3, 3])
        second_pose = pose_from_xyz_rpy(start[0] + 0.8, start[1] + 0.4, 1.5, 0.001, 0.002, 0.9)
        second = scanner.scan(second_pose, rng)
        guess = planar(second_pose[0, 3] + 0.1, second_pose[1, 3] - 0.1, 0.95, 1.5)
        t_icp = median_seconds(lambda second=second, cloud=cloud, guess=guess: register(second.points, guess, cloud), 5)
        result = register(second.points, guess, cloud)
        print(
            f"  ICP per scan            : {t_icp * 1e3:7.1f} ms"
            f"  (accepted={result.accepted}, fitness={result.fitness:.3f})"
        )


if __name__ == "__main__":
    main()
