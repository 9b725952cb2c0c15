"""How much can a scan policy save against the greedy? The share of scans and path it controls.

Usage::

    python -m train.headroom --storeys 24 [--base 20000000] [--jobs 2] [--out headroom.json]

Plays the greedy (:class:`policies.GreedyPolicy`) on the generated storeys ``generated:BASE`` to
``BASE + storeys - 1`` (the fast preset, seed 0; by default the validation storeys of
:mod:`train.ppo`, never the test storeys) and splits the episode's scans and path, scan by scan
(the episode log's :class:`~nbs_env.storey.ScanRecord`):

- *chosen*: the scans inside a room and the metres driven to them, what any policy decides;
- *hand-over*: the storey's first scan and every door-frame scan, with the drive to the door: the
  robot's door rule, the same for every policy that ends the rooms where the greedy does.

It then estimates, in hindsight, what ending rooms earlier could save: drop each room's trailing
chosen scans that each gained less than a threshold (true coverage, percentage points of the
storey), and report the scans, path and coverage dropped. An estimate, not a bound: a room left
earlier changes the drive to the next door and what the door search sees. It reads ground truth;
it measures the task, it is not a policy.
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import get_context

import numpy as np

from train.ppo import VALIDATION_BASE

#: Gains (percentage points of the storey's structure) below which a trailing scan is dropped.
THRESHOLDS = (0.25, 0.5, 0.75, 1.0, 1.5)


def greedy_scans(scene: str, seed: int = 0) -> list[dict]:
    """The greedy's episode on ``scene`` (fast preset), scan by scan.

    Returns
    -------
    list of dict
        Per scan: ``room`` (the robot's room index), ``handover`` (the first scan or a door-frame
        scan), ``metres`` (driven to it) and ``gain_pt`` (true coverage it added, points).
    """
    from nbs_env.env import NBSEnv
    from policies import GreedyPolicy

    env = NBSEnv("fast", scene=scene)
    obs, info = env.reset(seed=seed)
    policy = GreedyPolicy()
    while env.storey.open:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    out, path, pct = [], 0.0, 0.0
    for k, record in enumerate(env.storey.scans):
        out.append(
            {
                "room": record.room,
                "handover": k == 0 or record.door,
                "metres": record.path_length - path,
                "gain_pt": record.structure_sensed_pct - pct,
            }
        )
        path, pct = record.path_length, record.structure_sensed_pct
    return out


def summarise(episodes: list[list[dict]]) -> dict:
    """The split and the hindsight estimate over episodes of :func:`greedy_scans` (means per storey)."""
    n = len(episodes)
    scans = sum(len(e) for e in episodes)
    metres = sum(s["metres"] for e in episodes for s in e)
    chosen = [s for e in episodes for s in e if not s["handover"]]
    out = {
        "storeys": n,
        "scans": scans / n,
        "path_m": metres / n,
        "coverage_pct": float(np.mean([sum(s["gain_pt"] for s in e) for e in episodes])),
        "chosen_scans": len(chosen) / n,
        "chosen_path_m": sum(s["metres"] for s in chosen) / n,
        "estimate": [],
    }
    for threshold in THRESHOLDS:
        dropped = {"scans": 0, "metres": 0.0, "gain_pt": 0.0}
        for episode in episodes:
            rooms: dict[int, list[dict]] = {}
            for s in episode:
                if not s["handover"]:
                    rooms.setdefault(s["room"], []).append(s)
            for room_scans in rooms.values():
                k = len(room_scans)
                while k > 0 and room_scans[k - 1]["gain_pt"] < threshold:
                    k -= 1
                for s in room_scans[k:]:
                    dropped["scans"] += 1
                    dropped["metres"] += s["metres"]
                    dropped["gain_pt"] += s["gain_pt"]
        out["estimate"].append(
            {
                "threshold_pt": threshold,
                "fewer_scans_pct": 100 * dropped["scans"] / scans,
                "shorter_path_pct": 100 * dropped["metres"] / metres,
                "coverage_lost_pt": dropped["gain_pt"] / n,
            }
        )
    return out


def _run(scene: str) -> list[dict]:
    return greedy_scans(scene)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.headroom", description=__doc__.splitlines()[0])
    p.add_argument("--storeys", type=int, default=24)
    p.add_argument("--base", type=int, default=VALIDATION_BASE, help="seed of the first generated storey")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--out", default=None, help="write the summary as JSON here")
    args = p.parse_args(argv)
    if args.storeys < 1 or args.jobs < 1:
        p.error("--storeys and --jobs must be >= 1")
    scenes = [f"generated:{args.base + k}" for k in range(args.storeys)]
    with get_context("spawn").Pool(args.jobs) as pool:
        episodes = pool.map(_run, scenes, chunksize=1)
    summary = summarise(episodes)
    s = summary
    print(f"{s['storeys']} storeys: {s['scans']:.2f} scans, {s['path_m']:.1f} m, {s['coverage_pct']:.2f}% per storey")
    print(
        f"chosen in rooms: {s['chosen_scans']:.2f} scans ({100 * s['chosen_scans'] / s['scans']:.0f}%), "
        f"{s['chosen_path_m']:.1f} m ({100 * s['chosen_path_m'] / s['path_m']:.0f}%); the rest is the first scans "
        "and the door-frame scans with the drives to the doors"
    )
    for b in s["estimate"]:
        print(
            f"hindsight, each room's trailing scans that gained < {b['threshold_pt']} pt dropped: "
            f"{b['fewer_scans_pct']:.1f}% fewer scans, {b['shorter_path_pct']:.1f}% shorter path, "
            f"{b['coverage_lost_pt']:.2f} pt lost"
        )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(summary, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
