"""Benchmark: integrating one fine scan into V(t), against OctoMap's insertPointCloud, same process.

One 0.2° scan (~0.9 M rays) of ``five_rooms`` from the living room is integrated into a 5 cm grid
covering the room's RoI plus 0.3 m (what the robot keeps), and the same points and origin are
inserted into ``octomap.OcTree(0.05)`` (``pip install "nbs-env[bench]"`` for octomap-python). OctoMap
traces every ray (free voxels along it, the end voxel occupied); ours carves projectively and marks
the end voxels.

Usage: python benchmarks/voxels.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from nbs_env.config import ScannerConfig
from nbs_env.mapping.voxels import VoxelGrid
from nbs_env.perception.roi import RoIScan, compute_roi
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    scene = load_scene("five_rooms")
    cfg = ScannerConfig(angular_step=0.2)
    pose = pose_from_xyz_rpy(4.6, 1.8, 1.5, 0.0, 0.0, 0.2)
    scan = Scanner(scene, cfg).scan(pose, np.random.default_rng(0))
    points = scan.to_world(pose)
    roi = compute_roi([RoIScan.from_scan(scan, pose)])
    lo = np.array([*roi.polygon.min(axis=0), roi.floor_z]) - 0.3
    hi = np.array([*roi.polygon.max(axis=0), roi.ceiling_z]) + 0.3
    structure = np.ones(len(points), dtype=bool)
    depth = scan.depth_image()

    ours = []
    for _ in range(args.repeat):
        grid = VoxelGrid.covering(lo, hi, 0.05)
        t0 = time.perf_counter()
        grid.integrate(points, structure, pose, depth, cfg)
        ours.append(time.perf_counter() - t0)
    t_ours = statistics.median(ours)
    print(f"one 0.2° scan: {len(points):,} points; grid {grid.shape} = {np.prod(grid.shape):,} voxels of 5 cm")
    print(f"  VoxelGrid.integrate          : {t_ours * 1e3:8.1f} ms")
    try:
        import octomap
    except ImportError:
        print("  octomap-python is not installed: pip install 'nbs-env[bench]'")
        return
    theirs = []
    for _ in range(max(1, args.repeat // 2)):
        tree = octomap.OcTree(0.05)
        t0 = time.perf_counter()
        tree.insertPointCloud(points.astype(np.float64), pose[:3, 3].astype(np.float64))
        theirs.append(time.perf_counter() - t0)
    t_theirs = statistics.median(theirs)
    print(f"  OcTree(0.05).insertPointCloud: {t_theirs * 1e3:8.1f} ms")
    print(f"  ratio OctoMap / ours         : {t_theirs / t_ours:8.1f}x")


if __name__ == "__main__":
    main()
