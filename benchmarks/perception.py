"""Benchmark: perception per step against the scan's own ray casting, in the same process.

On ``five_rooms`` (living room, three stops at the default 0.5° pattern), it times
- ``RoIScan.from_scan`` (per new scan), ``compute_roi`` over 1 and 3 scans;
- SE classification of the RoI faces and Structure/Clutter labels, on the full-resolution points and
  on the 5 cm working copy of S(t) (what the robot keeps for perception);
and prints each as a ratio to a bare ``RaycastingScene.cast_rays`` of one scan's rays.

Usage: python benchmarks/perception.py [--repeat 15]
"""

from __future__ import annotations

import argparse

import numpy as np
from _timing import median_seconds

from nbs_env.config import ScannerConfig
from nbs_env.mapping.cloud import AccumulatedCloud
from nbs_env.perception.roi import RoIScan, compute_roi
from nbs_env.perception.structure import SEClassifier, label_points
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    scene = load_scene("five_rooms")
    scanner = Scanner(scene, ScannerConfig())
    rng = np.random.default_rng(0)
    stops = [(4.6, 1.8), (1.5, 4.8), (5.5, 1.0)]
    scans = []
    for x, y in stops:
        pose = pose_from_xyz_rpy(x, y, 1.5, 0.0, 0.0, 0.2)
        scans.append((scanner.scan(pose, rng), pose))
    roi_scans = [RoIScan.from_scan(s, p) for s, p in scans]
    cloud = AccumulatedCloud()
    for r in roi_scans:
        cloud.add(r.points, r.origin)
    full = np.concatenate([r.points for r in roi_scans])
    working = cloud.working_points()
    model = SEClassifier.load_default()
    roi = compute_roi(roi_scans)
    se = model.classify_faces(roi.wall_faces, working)
    se_faces = [f for f, s in zip(roi.wall_faces, se, strict=True) if s]
    rays = scanner.rays(scans[0][1])
    cast = 1e3 * median_seconds(lambda: scanner.raw_cast(rays), args.repeat)
    rows = [
        ("RoIScan.from_scan (one scan)", 1e3 * median_seconds(lambda: RoIScan.from_scan(*scans[0]), args.repeat)),
        ("compute_roi, 1 scan", 1e3 * median_seconds(lambda: compute_roi(roi_scans[:1]), args.repeat)),
        ("compute_roi, 3 scans", 1e3 * median_seconds(lambda: compute_roi(roi_scans), args.repeat)),
        (
            f"classify faces, full resolution ({len(full):,} pts)",
            1e3 * median_seconds(lambda: model.classify_faces(roi.wall_faces, full), args.repeat),
        ),
        (
            f"classify faces, working copy ({len(working):,} pts)",
            1e3 * median_seconds(lambda: model.classify_faces(roi.wall_faces, working), args.repeat),
        ),
        (
            "label points, full resolution",
            1e3
            * median_seconds(
                lambda: label_points(full, se_faces, roi.floor_z, roi.ceiling_z, roi.polygon), args.repeat
            ),
        ),
        (
            "label points, working copy",
            1e3
            * median_seconds(
                lambda: label_points(working, se_faces, roi.floor_z, roi.ceiling_z, roi.polygon), args.repeat
            ),
        ),
    ]
    print(f"reference: raw cast_rays of one 0.5° scan ({len(rays):,} rays): {cast:7.1f} ms")
    for name, ms in rows:
        print(f"  {name:48s} {ms:7.1f} ms  ({ms / cast:5.2f}x the cast)")
    step = rows[0][1] + rows[2][1] + rows[4][1] + rows[6][1]
    print(f"  {'perception per step (3 scans, working copy)':48s} {step:7.1f} ms  ({step / cast:5.2f}x the cast)")


if __name__ == "__main__":
    main()
