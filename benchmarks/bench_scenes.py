"""Benchmark: drawing, extruding and sampling storeys.

Prints absolute times and ratios against reference runs in the same process:
- our extrusion (labelled walls with door and window openings, clutter) vs trimesh's plain
  ``extrude_polygon`` prisms of the same clear room outlines (no openings, no labels);
- our deterministic structure samples vs trimesh's random ``sample_surface`` of the same count.

Usage: python benchmarks/bench_scenes.py [--rooms 5] [--seeds 10]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import trimesh
from shapely.geometry import Polygon

from scenes import extrude, generate_plan, load_scene
from scenes.validation import validate_plan_scene


def timed(fn, repeat: int = 1):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rooms", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()

    load_scene("office")  # warm-up: imports, open3d
    gen, ext, ref, val, samp, samp_ref = [], [], [], [], [], []
    for seed in range(args.seeds):
        t, plan = timed(lambda seed=seed: generate_plan(seed, rooms=args.rooms))
        gen.append(t)
        t, scene = timed(lambda plan=plan: extrude(plan, validate=False), repeat=3)
        ext.append(t)
        t, _ = timed(lambda plan=plan, scene=scene: validate_plan_scene(plan, scene), repeat=3)
        val.append(t)
        t, _ = timed(
            lambda scene=scene, height=plan.ceiling_height: [
                trimesh.creation.extrude_polygon(Polygon(r.polygon), height) for r in scene.rooms
            ],
            repeat=3,
        )
        ref.append(t)
        t, samples = timed(lambda scene=scene: scene.structure_samples(0.05), repeat=3)
        samp.append(t)
        se = scene.mesh.submesh([np.flatnonzero(scene.structural_mask())], append=True)
        n = len(samples)
        t, _ = timed(lambda se=se, n=n: trimesh.sample.sample_surface(se, n, seed=0), repeat=3)
        samp_ref.append(t)

    med = statistics.median
    print(f"{args.seeds} generated storeys of {args.rooms} rooms (median over seeds)")
    print(f"  generate_plan (draw + extrude + validate, with redraws): {med(gen) * 1e3:8.1f} ms")
    print(f"  extrude (labelled mesh)                                : {med(ext) * 1e3:8.1f} ms")
    print(f"  validate (reachability, start, 4096 rays per room)     : {med(val) * 1e3:8.1f} ms")
    print(f"  reference: trimesh.extrude_polygon of the same rooms   : {med(ref) * 1e3:8.1f} ms")
    print(f"  ratio extrude / reference                              : {med(ext) / med(ref):8.2f}x")
    print(f"  structure_samples(0.05)                                : {med(samp) * 1e3:8.1f} ms")
    print(f"  reference: trimesh.sample.sample_surface, same count   : {med(samp_ref) * 1e3:8.1f} ms")
    print(f"  ratio samples / reference                              : {med(samp) / med(samp_ref):8.2f}x")


if __name__ == "__main__":
    main()
