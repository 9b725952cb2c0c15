"""Benchmark: the scan-quality bookkeeping of the coverage meter against the coverage it extends.

On the bundled ``five_rooms``, for the default (0.5°, 5 cm samples) and the fast (1°, 10 cm
samples) preset, the scans of a short greedy run are replayed into fresh meters:
- ``CoverageMeter.add(points)``: the coverage alone (the reference, the meter before the quality
  figures);
- ``CoverageMeter.add(points, origin)``: the coverage and the quality observation (each point
  attributed to its nearest sample, incidence and range noted), and the ratio of the two;
- ``CoverageMeter.quality()``: the end-of-run figures (the samples' neighbourhoods, built once, and
  the per-scan curves).

Usage: python benchmarks/quality.py [--scans 6] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

from _timing import median_seconds

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from nbs_env.evaluation import CoverageMeter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=6)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    for preset in ("default", "fast"):
        cfg = make_config(preset, scene="five_rooms", max_scans=args.scans)
        env = NBSEnv(cfg)
        env.reset(seed=0)
        scans = list(env.storey.step_scans)
        while env.storey.open:
            env.step(env.storey.plan.best())
            scans += env.storey.step_scans
        scene = env.storey.scene

        def replay(with_origin: bool, scene=scene, cfg=cfg, scans=scans) -> CoverageMeter:
            meter = CoverageMeter(scene, cfg.coverage_spacing, cfg.coverage_radius)
            for points, origin in scans:
                meter.add(points, origin if with_origin else None)
            return meter

        plain = median_seconds(lambda: replay(False), args.repeat)
        observed = median_seconds(lambda: replay(True), args.repeat)
        meter = replay(True)
        t = time.perf_counter()
        meter.quality(cfg.quality)
        first = time.perf_counter() - t
        again = median_seconds(lambda meter=meter, q=cfg.quality: meter.quality(q), args.repeat)
        n = len(scans)
        print(
            f"{preset}: {n} scans, {len(meter.samples):,} samples; coverage alone {1000 * plain / n:.1f} ms a scan, "
            f"with the quality observation {1000 * observed / n:.1f} ms a scan ({observed / plain:.2f}x); "
            f"quality() {first:.2f} s the first time (neighbourhoods built), {again:.2f} s after"
        )


if __name__ == "__main__":
    main()
