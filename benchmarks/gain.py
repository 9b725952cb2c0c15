"""Benchmark: the greedy NBS gain of 64 candidates in a 10 x 8 x 3 m cluttered room at 5 cm.

The room (a plan built here: one 10 x 8 m room, 3 m ceiling, ten pieces of furniture) is scanned
once at the default 0.5° pattern; the robot's belief gives V(t), navigation gives the candidates, and
the gain of each is counted with ``VisibilityModel`` (lines of sight traversed through the voxels).
Goal: under 0.5 s for 64 candidates on a 2-core machine. It also prints how the time grows with the
number of candidates and with the voxel count (voxel sizes 10, 7.5 and 5 cm).

Usage: python benchmarks/gain.py [--repeat 5]
"""

from __future__ import annotations

import argparse

import numpy as np
from _timing import median_seconds

from nbs_env.belief import RoomBelief
from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.planner import PlanningConfig, plan, sensor_positions
from nbs_env.planning.visibility import VisibilityModel
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import ClutterPlan, FloorPlan, RoomPlan

ROOM = FloorPlan(
    rooms=(RoomPlan("big", ((0.0, 0.0), (10.15, 0.0), (10.15, 8.15), (0.0, 8.15))),),
    ceiling_height=3.0,
    wall_thickness=0.15,
    clutter=(
        ClutterPlan("cabinet", (1.0, 7.75), (1.4, 0.5, 2.0), 0.0),
        ClutterPlan("shelf", (4.0, 7.8), (1.8, 0.4, 2.1), 0.0),
        ClutterPlan("sofa", (8.0, 0.6), (2.2, 0.9, 0.85), 180.0),
        ClutterPlan("cabinet", (9.75, 4.0), (1.2, 0.6, 1.9), 270.0),
        ClutterPlan("shelf", (0.4, 3.0), (1.6, 0.4, 2.0), 90.0),
        ClutterPlan("table", (3.0, 3.0), (1.6, 0.9, 0.75), 0.0),
        ClutterPlan("table", (7.0, 5.0), (1.8, 1.0, 0.75), 90.0),
        ClutterPlan("column", (5.0, 4.0), (0.4, 0.4, 3.0), 0.0),
        ClutterPlan("box", (2.0, 0.5), (0.8, 0.6, 0.9), 180.0),
        ClutterPlan("chair", (3.0, 2.3), (0.45, 0.45, 0.9), 180.0),
    ),
    start=(5.0, 2.0),
    name="benchmark_room",
)


def state(voxel_size: float):
    scene = ROOM.to_scene()
    cfg = ScannerConfig()
    belief = RoomBelief(cfg, voxel_size=voxel_size)
    pose = pose_from_xyz_rpy(5.0, 2.0, 1.5, 0.0, 0.0, 0.3)
    belief.add_scan(Scanner(scene, cfg).scan(pose, np.random.default_rng(0)), pose)
    # The robot's NVPs (the planner's blind zone and footprint); the gains are timed below.
    cands = plan(belief, pose, [pose[:3, 3]], [(5.0, 2.0)], PlanningConfig(scanner=cfg, predict_gains=False)).candidates
    return belief.grid, sensor_positions(cands.points, belief.roi.floor_z, cfg), cfg


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    for voxel in (0.05, 0.075, 0.10):
        grid, sensors, cfg = state(voxel)
        targets = int(np.count_nonzero(grid.labels == VoxelLabel.OCCLUDED_STRUCTURE))
        print(
            f"voxel {voxel * 100:.1f} cm: grid {grid.shape} = {grid.labels.size:,} voxels, "
            f"{targets:,} Occluded-structure, {len(sensors)} candidates"
        )
        build = median_seconds(
            lambda grid=grid: VisibilityModel(grid.labels, grid.origin, grid.voxel_size), args.repeat
        )
        model = VisibilityModel(grid.labels, grid.origin, grid.voxel_size)
        print(f"  build the model (targets, groups, coarse cells): {build * 1e3:7.1f} ms")
        for n in (8, 16, 32, 64):
            if n > len(sensors):
                break
            t = median_seconds(
                lambda n=n, model=model, sensors=sensors, cfg=cfg: model.gains(sensors[:n], cfg), args.repeat
            )
            total = build + t
            print(f"  gain of {n:2d} candidates: {t * 1e3:7.1f} ms (with the build {total * 1e3:7.1f} ms)")


if __name__ == "__main__":
    main()
