"""The ``nbs`` command line.

Exit codes: 0 success; 1 a scene could not be loaded or built (the message says what and where);
2 a bad command line (unknown flag, bad value).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

EXIT_SCENE_ERROR = 1
EXIT_USAGE = 2


def _rooms(text: str) -> int | tuple[int, int]:
    try:
        if "-" in text:
            lo, hi = (int(v) for v in text.split("-", 1))
            value: int | tuple[int, int] = (lo, hi)
        else:
            lo = hi = int(text)
            value = lo
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R or LO-HI with integers, got {text!r}") from None
    if not 1 <= lo <= hi <= 8:
        raise argparse.ArgumentTypeError(f"rooms must be within 1..8, got {text!r}")
    return value


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def _storey(text: str) -> str | int:
    return int(text) if text.lstrip("-").isdigit() else text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nbs", description="nbs-env: next-best-scan planning of building interiors.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    scenes = sub.add_parser("scenes", help="list, show, inspect and generate buildings")
    ssub = scenes.add_subparsers(dest="action", required=True, metavar="ACTION")

    ssub.add_parser("list", help="list the bundled scenes")

    def scene_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("scene", help="bundled name, .json/.obj/.glb/.gltf/.ply/.ifc path, or generated:SEED")
        p.add_argument("--storey", type=_storey, help="IFC storey name or index")
        p.add_argument("--y-up", action="store_true", help="mesh coordinates are y-up (glTF convention)")

    show = ssub.add_parser("show", help="draw a top-down picture of a scene")
    scene_args(show)
    show.add_argument("--out", required=True, type=Path, help="PNG file to write")

    info = ssub.add_parser("info", help="print a scene's class areas, rooms and doors as JSON")
    scene_args(info)

    gen = ssub.add_parser("generate", help="generate a storey and write its floor plan as JSON")
    gen.add_argument("--seed", type=int, required=True)
    gen.add_argument("--rooms", type=_rooms, default=None, help="number of rooms R, or a range LO-HI (1..8)")
    gen.add_argument("--clutter-density", type=_non_negative, default=None, help="objects per 6 m² (default 1)")
    gen.add_argument("--out", type=Path, required=True, help="floor-plan JSON to write")
    gen.add_argument("--show", type=Path, default=None, help="also draw the storey to this PNG")
    return parser


def _load(args: argparse.Namespace):
    from scenes import load_scene

    opts: dict = {}
    if args.storey is not None:
        opts["storey"] = args.storey
    if args.y_up:
        opts["y_up"] = True
    return load_scene(args.scene, **opts)


def _scene_summary(scene) -> dict:
    from scenes import SurfaceClass

    areas = scene.class_areas()
    return {
        "name": scene.name,
        "faces": len(scene.mesh.faces),
        "class_areas_m2": {c.name.lower(): round(areas[c], 3) for c in SurfaceClass},
        "structural_area_m2": round(scene.structural_area(), 3),
        "rooms": [{"id": r.id, "name": r.name, "floor_area_m2": round(r.area, 3)} for r in scene.rooms],
        "doors": [
            {"rooms": list(map(int, d.rooms)), "position": [round(float(v), 3) for v in d.position], "width": d.width}
            for d in scene.doors
        ],
        "start": [round(float(v), 3) for v in scene.start],
    }


def run(args: argparse.Namespace) -> int:
    from scenes import list_scenes, load_scene

    if args.action == "list":
        for name in list_scenes():
            scene = load_scene(name, validate=False)
            floor = sum(r.area for r in scene.rooms)
            print(f"{name:12s} {len(scene.rooms)} rooms, {len(scene.doors)} doors, {floor:6.1f} m² of floor")
        return 0
    if args.action == "show":
        from scenes.render import save_scene_png

        scene = _load(args)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        save_scene_png(scene, args.out)
        print(f"wrote {args.out}")
        return 0
    if args.action == "info":
        print(json.dumps(_scene_summary(_load(args)), indent=1))
        return 0
    if args.action == "generate":
        from scenes import generate_plan

        opts: dict = {}
        if args.rooms is not None:
            opts["rooms"] = args.rooms
        if args.clutter_density is not None:
            opts["clutter_density"] = args.clutter_density
        t0 = time.perf_counter()
        plan = generate_plan(args.seed, **opts)
        scene = plan.to_scene(validate=False)
        elapsed = time.perf_counter() - t0
        args.out.parent.mkdir(parents=True, exist_ok=True)
        plan.to_json(args.out)
        summary = f"{len(plan.rooms)} rooms, {len(plan.doors)} doors, {len(plan.clutter)} clutter objects"
        print(f"wrote {args.out}: {summary} ({elapsed:.2f} s)")
        if args.show is not None:
            from scenes.render import save_scene_png

            save_scene_png(scene, args.show)
            print(f"wrote {args.show}")
        return 0
    raise AssertionError(args.action)  # argparse only lets known actions through


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nbs`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from scenes.errors import SceneError

    try:
        return run(args)
    except SceneError as exc:
        print(f"nbs: error: {exc}", file=sys.stderr)
        return EXIT_SCENE_ERROR
    except OSError as exc:  # e.g. an --out folder we may not write
        print(f"nbs: error: {exc}", file=sys.stderr)
        return EXIT_SCENE_ERROR


if __name__ == "__main__":
    sys.exit(main())
