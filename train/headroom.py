"""How much can a scan policy save against the greedy? The share of scans and path it controls.

Usage::

    python -m train.headroom --storeys 24 [--base 20000000] [--jobs 2] [--out headroom.json]

Plays the greedy (:class:`policies.GreedyPolicy`) with ``completion="policy"`` on the generated
storeys ``generated:BASE`` to ``BASE + storeys - 1`` (the fast preset, seed 0; by default the
validation storeys of :mod:`train.ppo`, never the test storeys), where every step is either a scan
the policy chose or a "room done" declaration, and splits the episode's scans and path:

- *chosen*: the scans inside a room and the metres driven to them, what any policy decides;
- *hand-over*: the storey's first scan and, per room done, the drive to the nearest unvisited door,
  the crossing and the next room's first scan: the robot's door rule, the same for every policy
  that ends the rooms where the greedy does.

It then bounds what ending rooms earlier can save, in hindsight: drop each room's trailing chosen
scans that each gained less than a threshold (true coverage, percentage points of the storey), and
report the scans, path and coverage dropped. The bound reads ground truth; it is a measurement of
the task, not a policy.
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


def greedy_steps(scene: str, seed: int = 0) -> list[dict]:
    """The greedy's episode on ``scene`` (fast preset, ``completion="policy"``), step by step:
    ``{"room", "declared", "scans", "metres", "gain_pt"}`` per step (scans and metres of the step,
    true coverage gained in points)."""
    from nbs_env.env import NBSEnv
    from policies import GreedyPolicy

    env = NBSEnv("fast", scene=scene, completion="policy")
    obs, info = env.reset(seed=seed)
    policy = GreedyPolicy()
    steps = [{"room": -1, "declared": True, "scans": 1, "metres": 0.0, "gain_pt": info["structure_sensed_pct"]}]
    while True:
        before = (info["scans"], info["path_length_m"], info["structure_sensed_pct"], info["room"])
        action = policy.act(obs, info)
        obs, _, terminated, truncated, info = env.step(action)
        steps.append(
            {
                "room": before[3],
                "declared": action == env.stop_action,
                "scans": info["scans"] - before[0],
                "metres": info["path_length_m"] - before[1],
                "gain_pt": info["structure_sensed_pct"] - before[2],
            }
        )
        if terminated or truncated:
            return steps


def summarise(episodes: list[list[dict]]) -> dict:
    """The split and the hindsight bound over episodes of :func:`greedy_steps` (means per storey)."""
    n = len(episodes)
    scans = sum(s["scans"] for e in episodes for s in e)
    metres = sum(s["metres"] for e in episodes for s in e)
    chosen = [s for e in episodes for s in e if not s["declared"]]
    out = {
        "storeys": n,
        "scans": scans / n,
        "path_m": metres / n,
        "coverage_pct": float(np.mean([sum(s["gain_pt"] for s in e) for e in episodes])),
        "chosen_scans": sum(s["scans"] for s in chosen) / n,
        "chosen_path_m": sum(s["metres"] for s in chosen) / n,
        "bound": [],
    }
    for threshold in THRESHOLDS:
        dropped = {"scans": 0, "metres": 0.0, "gain_pt": 0.0}
        for episode in episodes:
            rooms: dict[int, list[dict]] = {}
            for s in episode:
                if not s["declared"]:
                    rooms.setdefault(s["room"], []).append(s)
            for steps in rooms.values():
                k = len(steps)
                while k > 0 and steps[k - 1]["gain_pt"] < threshold:
                    k -= 1
                for s in steps[k:]:
                    for key in dropped:
                        dropped[key] += s[key]
        out["bound"].append(
            {
                "threshold_pt": threshold,
                "fewer_scans_pct": 100 * dropped["scans"] / scans,
                "shorter_path_pct": 100 * dropped["metres"] / metres,
                "coverage_lost_pt": dropped["gain_pt"] / n,
            }
        )
    return out


def _run(scene: str) -> list[dict]:
    return greedy_steps(scene)


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
        "and the door hand-overs"
    )
    for b in s["bound"]:
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
