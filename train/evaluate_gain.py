"""Does the predicted gain rank candidates like the conversions realised by scanning from them?

Usage::

    python -m train.evaluate_gain --rooms 20 [--occluded-clutter-blocks]

For rooms of generated storeys (seeds from 300000 on; 2-4 rooms each), the robot scans once from a
well-spread free position, builds its belief (RoI, SE faces, V(t)), and plans as the robot does
(:func:`nbs_env.planning.planner.plan`: the same blind zone, NVPs and gain). For up to 8 candidates
spread along the NVP list it takes the predicted Occluded-structure→Structure conversions (the greedy
gain), then actually scans from each candidate (in a copy of the belief) and counts the voxels that
were Occluded-structure before and are Structure after.

Only NVPs where the robot could truly stand are ranked: the robot's map takes the unsensed space
within the scanner's minimum range of a stop as free (``assume_blind_zone_free``), so some NVPs near
the first stop lie inside furniture it never measured, and a scan from inside a cabinet says nothing
about the gain. The evaluation checks each NVP against the true building (a disc of the robot's
radius) and reports how many it left out (``inside_obstacles``): a measure of the planner's map,
not of the gain. The Spearman rank
correlation of predicted and realised counts is averaged over the rooms.
"""

from __future__ import annotations

import argparse
import copy
import json
import time

import numpy as np
from scipy.stats import spearmanr

from nbs_env.belief import RoomBelief
from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.navigation import NavigationConfig
from nbs_env.planning.planner import PlanningConfig, plan, sensor_positions
from nbs_env.planning.visibility import GainConfig
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene
from scenes.geometry import point_is_free
from train.perception_data import spread_positions

EVAL_BASE = 300_000


def room_correlations(n_rooms: int, gain: GainConfig, seed: int = 0, per_room: int = 8) -> list[dict]:
    cfg = ScannerConfig()
    rng = np.random.default_rng(seed)
    rows: list[dict] = []
    storey = EVAL_BASE
    while len(rows) < n_rooms:
        scene = load_scene(f"generated:{storey}", rooms=(2, 4))
        storey += 1
        scanner = Scanner(scene, cfg)
        for room in scene.rooms:
            if len(rows) == n_rooms:
                break
            first = spread_positions(scene, room, rng, 1)
            if not first:
                continue
            pose = pose_from_xyz_rpy(first[0][0], first[0][1], room.floor_z + cfg.height, 0.0, 0.0, 0.0)
            belief = RoomBelief(cfg)
            belief.add_scan(scanner.scan(pose, rng), pose)
            planned = plan(belief, pose, [pose[:3, 3]], [first[0]], PlanningConfig(scanner=cfg, gain=gain))
            cands = planned.candidates
            # Evaluation side: which NVPs a robot could truly stand on (ground truth, module docstring).
            radius = NavigationConfig().robot_radius
            feasible = np.array(
                [i for i in range(cands.count) if point_is_free(scene, cands.points[i], room.floor_z, radius)],
                dtype=int,
            )
            if len(feasible) < 5:
                continue
            pick = feasible[np.unique(np.linspace(0, len(feasible) - 1, min(per_room, len(feasible))).astype(int))]
            sensors = sensor_positions(cands.points[pick], belief.roi.floor_z, cfg)
            predicted = planned.gains[pick]
            before = belief.occluded_structure_centres()
            realised = []
            for sensor in sensors:
                trial = copy.deepcopy(belief)
                p = pose_from_xyz_rpy(*sensor, 0.0, 0.0, 0.0)
                trial.add_scan(scanner.scan(p, rng), p)
                realised.append(int(np.count_nonzero(trial.labels_at(before) == VoxelLabel.STRUCTURE)))
            rho = spearmanr(predicted, realised).statistic
            if not np.isfinite(rho):
                continue
            rows.append(
                {
                    "scene": scene.name,
                    "room": room.name,
                    "candidates": int(cands.count),
                    "inside_obstacles": int(cands.count - len(feasible)),
                    "predicted": predicted.tolist(),
                    "realised": realised,
                    "spearman": float(rho),
                }
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Rank correlation of predicted and realised gains.")
    parser.add_argument("--rooms", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--occluded-clutter-blocks", action="store_true")
    parser.add_argument("--json", default=None, help="write the per-room rows here")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    rows = room_correlations(args.rooms, GainConfig(occluded_clutter_blocks=args.occluded_clutter_blocks), args.seed)
    rho = [r["spearman"] for r in rows]
    summary = {
        "rooms": len(rows),
        "occluded_clutter_blocks": args.occluded_clutter_blocks,
        "mean_spearman": float(np.mean(rho)),
        "median_spearman": float(np.median(rho)),
        "min_spearman": float(np.min(rho)),
        "nvps": sum(r["candidates"] for r in rows),
        "nvps_inside_obstacles": sum(r["inside_obstacles"] for r in rows),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(summary, indent=1))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summary | {"rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
