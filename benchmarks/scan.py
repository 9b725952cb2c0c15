"""Benchmark: our scan vs the raw Embree cast of the same rays, and ICP time per scan.

For the default (0.5°) and the fine (0.2°) pattern, on the bundled ``five_rooms``:
- rays per second of ``Scanner.scan`` with thin rays (ray construction, cast, noise, range filter,
  points);
- rays per second of a bare ``RaycastingScene.cast_rays`` of the same prebuilt rays, in the same
  process, and the ratio (goal: our wrapper costs less than 25% over the raw cast);
- the cost of the beam's footprint (mixed pixels, the default scanner's 0.3 mrad beam): the default
  scan's time over the thin-ray scan's, in % of the raw cast;
- the time to register a scan into S(t) by ICP.

Usage: python benchmarks/scan.py [--repeat 15]
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import replace

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
        beam = Scanner(scene, cfg)
        scanner = Scanner(scene, replace(cfg, beam_divergence=0.0))
        rng = np.random.default_rng(0)
        rays = scanner.rays(pose)
        # Interleave the three so that machine load affects them alike.
        ours, raw, beamed = [], [], []
        for _ in range(args.repeat):
            raw.append(median_seconds(lambda rays=rays, scanner=scanner: scanner.raw_cast(rays), 1))
            ours.append(median_seconds(lambda scanner=scanner, rng=rng: scanner.scan(pose, rng), 1))
            beamed.append(median_seconds(lambda beam=beam, rng=rng: beam.scan(pose, rng), 1))
        t_ours, t_raw, t_beam = statistics.median(ours), statistics.median(raw), statistics.median(beamed)
        n = cfg.n_rays
        mixed = int(beam.scan(pose, rng).truth.mixed.sum())
        print(f"{label} ({step}°, {n:,} rays)")
        print(f"  Scanner.scan, thin rays : {n / t_ours / 1e6:6.2f} M rays/s  ({t_ours * 1e3:7.1f} ms)")
        print(f"  raw cast_rays, same rays: {n / t_raw / 1e6:6.2f} M rays/s  ({t_raw * 1e3:7.1f} ms)")
        print(f"  overhead of our wrapper : {100 * (t_ours / t_raw - 1):6.1f} %")
        extra = 100 * (t_beam - t_ours) / t_raw
        print(f"  the beam's footprints   : {t_beam * 1e3:7.1f} ms a scan, +{extra:.1f} % of the cast ({mixed} mixed)")
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
