"""Benchmark: the checks a building file passes before its reader, against the reader itself.

Prints, per file, the time of the checks (``scenes.stepgraph.check_references`` for IFC: the STEP
reference graph, its cycles and depth; ``scenes.headers.check_ply_header`` for PLY) and of the
reader they guard (``ifcopenshell.open``; trimesh's PLY load) in the same process, and their ratio;
for IFC also the whole load of a storey (``load_scene``, with its geometry), which is what a user waits
for. Last, nbs-env's own OBJ reader (``scenes.importers._read_obj``: the format's grammar, polygon faces
ear-clipped where concave) against trimesh's OBJ load of the same text.

Usage: python benchmarks/file_checks.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import time
from pathlib import Path

import trimesh

from scenes import load_scene
from scenes.corpus import corpus_entry
from scenes.headers import check_ply_header
from scenes.importers import export_scene
from scenes.stepgraph import check_references

ROOT = Path(__file__).resolve().parents[1]


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    import ifcopenshell

    ifcs = [corpus_entry("fzk_haus_eg").path(), *sorted((ROOT / "scenes" / "data" / "corpus" / "ifc").glob("*.ifc"))]
    print(
        f"{'file':32s} {'bytes':>10s} {'checks ms':>10s} {'reader ms':>10s} {'ratio':>6s} {'load ms':>9s} {'share':>6s}"
    )
    for path in ifcs:
        data = path.read_bytes()
        checks = best(lambda data=data, path=path: check_references(str(path), data), args.repeat)
        reader = best(lambda path=path: ifcopenshell.open(str(path)), args.repeat)
        load = best(lambda path=path: load_scene(str(path), storey=0), 1)
        print(
            f"{path.name:32s} {len(data):10,d} {checks * 1e3:10.1f} {reader * 1e3:10.1f} {checks / reader:6.2f} "
            f"{load * 1e3:9.0f} {checks / load:6.1%}"
        )
    with tempfile.TemporaryDirectory() as folder:
        for name in ("office", "five_rooms"):
            ply = Path(folder) / f"{name}.ply"
            export_scene(load_scene(name), ply)
            data = ply.read_bytes()
            checks = best(lambda data=data, name=name: check_ply_header(name, data), args.repeat)
            reader = best(
                lambda data=data: trimesh.load(io.BytesIO(data), file_type="ply", force="mesh", process=False),
                args.repeat,
            )
            print(f"{ply.name:32s} {len(data):10,d} {checks * 1e3:10.2f} {reader * 1e3:10.1f} {checks / reader:6.3f}")
    import numpy as np

    from scenes.importers import _read_obj

    rng = np.random.default_rng(0)
    grid = 300  # a 300 x 300 lattice of quads, and 200,000 scattered triangles
    xs, ys = np.meshgrid(np.arange(grid), np.arange(grid))
    quads = (
        "".join(f"v {x} {y} 0\n" for x, y in zip(xs.ravel(), ys.ravel(), strict=True))
        + "o floor\n"
        + "".join(
            f"f {i * grid + j + 1} {i * grid + j + 2} {(i + 1) * grid + j + 2} {(i + 1) * grid + j + 1}\n"
            for i in range(grid - 1)
            for j in range(grid - 1)
        )
    )
    points = rng.random((200_000, 3)) * 10
    triangles = (
        "o wall\n"
        + "".join(f"v {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in points)
        + "".join(f"f {i + 1} {i + 2} {i + 3}\n" for i in range(len(points) - 2))
    )
    print(f"\n{'OBJ':32s} {'bytes':>10s} {'nbs ms':>10s} {'trimesh ms':>10s} {'ratio':>6s}")
    for name, text in (("office.obj", None), ("quads_300x300.obj", quads), ("triangles_200k.obj", triangles)):
        if text is None:
            with tempfile.TemporaryDirectory() as folder:
                export_scene(load_scene("office"), Path(folder) / name)
                text = (Path(folder) / name).read_text()
        data = text.encode()
        ours = best(lambda data=data: _read_obj("x.obj", data), args.repeat)
        theirs = best(
            lambda data=data: trimesh.load(io.BytesIO(data), file_type="obj", force="mesh", process=False),
            args.repeat,
        )
        print(f"{name:32s} {len(data):10,d} {ours * 1e3:10.1f} {theirs * 1e3:10.1f} {ours / theirs:6.2f}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
