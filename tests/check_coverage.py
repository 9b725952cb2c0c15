"""The project's coverage against the independent count (:mod:`tests.independent_coverage`), per storey.

Runs the greedy on each storey at a preset and seed, keeps every registered scan's points, and
counts their coverage both ways::

    python -m tests.check_coverage --scenes suite:unseen --seed 0 --jobs 2

prints a markdown table: the project's figure, the independent one, and their difference (points).
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from tests.independent_coverage import count


def both(scene: str, seed: int = 0, preset: str = "default", max_scans: int = 80) -> dict:
    """The greedy's run of ``scene``: the project's coverage and the independent count of its cloud."""
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from policies import config_for, make_policy

    t0 = time.perf_counter()
    policy = make_policy("greedy")
    env = NBSEnv(config_for(make_config(preset, scene=scene, max_scans=max_scans), policy))
    obs, info = env.reset(seed=seed)
    policy.reset()
    clouds = [points for points, _ in env.storey.step_scans]
    done = not env.storey.open
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        clouds += [points for points, _ in env.storey.step_scans]
        done = terminated or truncated
    storey = env.storey
    mesh = storey.scene.mesh
    independent = count(mesh.vertices, mesh.faces, storey.scene.face_labels, np.concatenate(clouds))
    return {
        "scene": scene,
        "scans": len(storey.scans),
        "project": float(storey.meter.percent()),
        "independent": independent.percent,
        "visible_share": 100.0 * independent.visible / max(1, independent.samples),
        "wall_s": time.perf_counter() - t0,
    }


def main() -> None:
    from train.compare import expand_scenes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="suite:unseen")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="default")
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    scenes = expand_scenes(args.scenes)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(both, scenes, [args.seed] * len(scenes), [args.preset] * len(scenes)))
    print("| storey | scans | project (%) | independent (%) | difference (points) | structure visible (%) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        d = r["project"] - r["independent"]
        print(
            f"| {r['scene'].removeprefix('corpus:')} | {r['scans']} | {r['project']:.1f} | {r['independent']:.1f} "
            f"| {d:+.1f} | {r['visible_share']:.1f} |"
        )
    worst = max(abs(r["project"] - r["independent"]) for r in rows)
    print(f"\nlargest difference: {worst:.1f} points over {len(rows)} storeys")


if __name__ == "__main__":
    main()
