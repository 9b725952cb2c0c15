"""How well does the robot find the doors of a room it has scanned? (METHOD §8)

Usage::

    python -m train.evaluate_doors --rooms 12

For rooms of generated storeys (seeds from 400000 on, 2-4 rooms each), the robot starts in the room
(at a free point chosen from ground truth), scans it with the greedy NBS in a storey session until the
room is complete, and takes the doors the robot detected in its SE wall faces. A detection matches a
true door of that room when its centre lies within 0.3 m of the door's centre line position.
Reports precision, recall and width error.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from nbs_env.config import EnvConfig
from nbs_env.storey import Storey
from policies.greedy import scan_storey
from scenes import load_scene
from train.perception_data import spread_positions

EVAL_BASE = 400_000


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Door detection against ground truth.")
    parser.add_argument("--rooms", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    rows = []
    storey = EVAL_BASE
    while len(rows) < args.rooms:
        base = load_scene(f"generated:{storey}", rooms=(2, 4))
        storey += 1
        for room in base.rooms:
            if len(rows) == args.rooms:
                break
            start = spread_positions(base, room, rng, 1)
            if not start:
                continue
            scene = load_scene(f"generated:{storey - 1}", rooms=(2, 4), start=tuple(start[0]))
            session = Storey(scene, EnvConfig(), rng)
            scan_storey(session, max_rooms=1)
            found = [d for d in session.rooms.doors if d.found_in_room == 0]
            truth = [d for d in scene.doors if room.id in d.rooms]
            matched, width_errors = set(), []
            for f in found:
                dist = [np.linalg.norm(f.centre[:2] - d.position[:2]) for d in truth]
                k = int(np.argmin(dist)) if dist else -1
                if k >= 0 and dist[k] < 0.3 and k not in matched:
                    matched.add(k)
                    width_errors.append(abs(f.width - truth[k].width))
            rows.append(
                {
                    "scene": scene.name,
                    "room": room.name,
                    "scans": sum(1 for s in session.scans if s.room == 0),
                    "true_doors": len(truth),
                    "found": len(found),
                    "matched": len(matched),
                    "width_errors": width_errors,
                }
            )
    found = sum(r["found"] for r in rows)
    true = sum(r["true_doors"] for r in rows)
    matched = sum(r["matched"] for r in rows)
    errors = [e for r in rows for e in r["width_errors"]]
    summary = {
        "rooms": len(rows),
        "true_doors": true,
        "detections": found,
        "precision": matched / found if found else None,
        "recall": matched / true if true else None,
        "mean_width_error_m": float(np.mean(errors)) if errors else None,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
