"""The ``nbs`` command line.

Exit codes: 0 success; 1 a scene could not be loaded or built (the message says what and where),
or ``nbs scan`` could not run it (a start inside a wall or outside the building), a file could not
be written (a full disk), or ``nbs view`` found no readable recording; 2 a bad command line (unknown
flag, bad value, unknown policy, a configuration value out of range, an output path that cannot be
written or holds an earlier run's: :mod:`train.outputs`, a bad ``NBS_THREADS`` or ``MPLBACKEND``);
3 ``nbs view`` could start no viewer (no display, or rerun's viewer or web server failed); 128 + the
signal (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP) a command stopped by a signal, what was done kept
(:mod:`train.stopping`); 141 the reader of stdout went away.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

from train.arguments import add_robot_arguments, add_scene_arguments, integer_from, scene_option_error, seed_number
from train.outputs import (
    COMPARISON,
    TRAINING_RUN,
    NamedStream,
    Output,
    OutputBusyError,
    OutputError,
    check_outputs,
    claimed,
    output_path,
)
from train.stopping import STOP_SIGNALS, StopRequest, exit_code

EXIT_SCENE_ERROR = 1
EXIT_USAGE = 2
#: ``nbs view`` could start no viewer: no display for the native one, or rerun's process failed.
EXIT_NO_VIEWER = 3
#: The scan budget of ``nbs scan`` and ``nbs compare`` runs when ``--max-scans`` is not given (the
#: presets' own budgets are the env's: 80 default, 40 fast).
SCAN_BUDGET = 80


def _rooms(text: str) -> int | tuple[int, int]:
    from train.arguments import parse_range

    try:
        lo, hi = parse_range(text)
    except ValueError:  # its message says 0 <= A <= B: the rooms' own bounds are the ones to give
        lo, hi = 0, -1
    if not 1 <= lo <= hi <= 8:
        raise argparse.ArgumentTypeError(f"rooms must be N or A-B with integers 1 <= A <= B <= 8, got {text!r}")
    return lo if "-" not in text else (lo, hi)


def _clutter_density(text: str) -> float:
    from nbs_env.config.checks import parse_float
    from scenes.generator import MAX_CLUTTER_DENSITY

    try:
        value = parse_float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 <= value <= MAX_CLUTTER_DENSITY:
        raise argparse.ArgumentTypeError(f"expected a number within 0..{MAX_CLUTTER_DENSITY:g}, got {text!r}")
    return value


_seed = seed_number
_positive_int = integer_from(1)

#: What matplotlib's savefig writes, by file suffix.
PICTURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp")


def _picture(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in PICTURE_SUFFIXES:
        raise argparse.ArgumentTypeError(
            f"{text!r}: a picture file ends in one of {', '.join(PICTURE_SUFFIXES)} (e.g. top.png)"
        )
    return path


def _plan_file(text: str) -> Path:
    """argparse type of ``nbs scenes generate --out``: a floor plan is JSON, and nbs-env reads it by
    its name (``load_scene("x.json")``); a name of another format (``mesh.obj``) was written over
    with JSON that every reader of that format then refused."""
    path = output_path(text)
    if path.suffix.lower() != ".json" and not getattr(path, "given", None):
        raise argparse.ArgumentTypeError(f"{text!r}: a floor plan is JSON; name a file ending in .json (e.g. p.json)")
    return path


def _start(text: str) -> tuple[float, float]:
    from nbs_env.config.checks import parse_float

    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        x, y = (parse_float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in metres (e.g. 3.0,4.5), got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected finite X,Y, got {text!r}")
    from scenes.limits import MAX_ORIGIN_DISTANCE

    if max(abs(x), abs(y)) > MAX_ORIGIN_DISTANCE:
        raise argparse.ArgumentTypeError(
            f"expected X,Y within {MAX_ORIGIN_DISTANCE:,.0f} m of the origin, where storeys lie, got {text!r}"
        )
    return x, y


def build_parser() -> argparse.ArgumentParser:
    from nbs_env import __version__

    parser = argparse.ArgumentParser(prog="nbs", description="nbs-env: next-best-scan planning of building interiors.")
    parser.add_argument("--version", action="version", version=f"nbs-env {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    scenes = sub.add_parser("scenes", help="list, show, inspect and generate buildings")
    ssub = scenes.add_subparsers(dest="action", required=True, metavar="ACTION")

    ssub.add_parser("list", help="list the bundled scenes")

    def scene_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("scene", help="bundled name, .json/.obj/.glb/.gltf/.ply/.ifc path, or generated:SEED")
        add_scene_arguments(p)

    show = ssub.add_parser("show", help="draw a top-down picture of a scene")
    scene_args(show)
    show.add_argument("--out", required=True, type=_picture, help="picture to write (.png, .pdf, .svg, ...)")
    show.add_argument("--force", action="store_true", help="write over an existing --out")

    info = ssub.add_parser("info", help="print a scene's class areas, rooms and doors as JSON")
    scene_args(info)

    gen = ssub.add_parser("generate", help="generate a storey and write its floor plan as JSON")
    gen.add_argument("--seed", type=_seed, required=True)
    gen.add_argument("--rooms", type=_rooms, default=None, help="number of rooms R, or a range LO-HI (1..8)")
    gen.add_argument(
        "--clutter-density", type=_clutter_density, default=None, help="objects per 6 m², 0..10 (default 1)"
    )
    gen.add_argument("--out", type=_plan_file, required=True, help="floor-plan JSON to write (.json)")
    gen.add_argument("--show", type=_picture, default=None, help="also draw the storey to this picture (.png, ...)")
    gen.add_argument("--force", action="store_true", help="write over an existing --out or --show")

    scan = sub.add_parser(
        "scan",
        help="scan a storey autonomously and write a report",
        description="Scan a storey with a policy (the paper's greedy NBS by default) and write metrics.json, "
        "scans.e57, cloud.laz, structure.ply, cloud.ply, model.obj, samples.npz, topdown.png and "
        "steps/step_NNN.png into --out.",
    )
    scan.add_argument(
        "--scene", required=True, help="bundled name, .json/.obj/.glb/.gltf/.ply/.ifc path, or generated:SEED"
    )
    scan.add_argument("--policy", default="greedy", help="who chooses the next scan (default: greedy)")
    scan.add_argument("--seed", type=_seed, default=0, help="seed of the episode, >= 0 (default 0)")
    scan.add_argument("--out", type=output_path, default=None, help="report folder (default: ./scan-<scene>)")
    scan.add_argument(
        "--force", action="store_true", help="write over the report (and --record file) an earlier scan left there"
    )
    scan.add_argument(
        "--record",
        type=output_path,
        default=None,
        metavar="RUN.rrd",
        help="also log the run as a rerun recording, for nbs view (needs the viz extra)",
    )
    scan.add_argument(
        "--start",
        type=_start,
        default=None,
        metavar="X,Y",
        help="start position in metres (--start=-1,2 for a negative X)",
    )
    scan.add_argument("--no-steps", action="store_true", help="do not save a picture per step")
    scan.add_argument(
        "--full-cloud",
        action="store_true",
        help="cloud.laz holds every measured point of the scans, not the rooms' 5 cm working copies",
    )
    scan.add_argument("--quiet", action="store_true", help="no progress bar")
    add_robot_arguments(scan)

    view = sub.add_parser(
        "view",
        help="replay a run recorded with `nbs scan --record` in rerun's viewer",
        description="Open a recording in rerun's viewer, or with --web serve it to a browser (no display "
        "needed) until Ctrl-C. Exit codes: 0 closed or stopped; 1 no readable recording; 2 rerun-sdk "
        "missing; 3 no viewer could start (no display: use --web; a port in use).",
    )
    view.add_argument("recording", type=Path, help="a .rrd file")
    view.add_argument(
        "--web", action="store_true", help="serve rerun's web viewer over HTTP and print its URL; Ctrl-C stops it"
    )
    view.add_argument("--port", type=_port, help="with --web: the recording's gRPC port (default 9876; 0 free)")
    view.add_argument("--web-port", type=_port, help="with --web: the web viewer's HTTP port (default 9090; 0 free)")
    view.add_argument(
        "--bind",
        default=None,
        help="with --web: the address to listen on (default 127.0.0.1, this machine only; 0.0.0.0 every interface)",
    )

    sub.add_parser("train", help="train a masked PPO agent (see `nbs train --help`)", add_help=False)

    compare = sub.add_parser(
        "compare",
        help="run policies on scenes over seeds and write the comparison table",
        description="Run every (scene, policy, seed) and write table.csv, table.md, coverage_vs_scans.png, "
        "path_time.png and each run's metrics.json into --out.",
    )
    compare.add_argument(
        "--scenes",
        required=True,
        help="comma-separated scenes; generated:A-B is a range of seeds, suite:unseen the evaluation corpus",
    )
    # Named here rather than read from policies.POLICIES: importing policies adds about a second to
    # every command, --help included; test_cli checks this list against the registry.
    compare.add_argument(
        "--policies",
        required=True,
        help="comma-separated policies: greedy (greedy:NEAR, greedy:stop=F), stachniss_burgard, blaer_allen, "
        "potthast_sukhatme, information_gain:F, nearest_frontier, random, ppo:PATH (docs/comparing.md)",
    )
    compare.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    compare.add_argument("--out", type=output_path, required=True, help="output folder")
    compare.add_argument(
        "--jobs", type=_positive_int, default=1, help="worker processes, at most twice the cores here (default 1)"
    )
    compare.add_argument("--backend", choices=("local", "ray"), default="local", help="local processes or Ray")
    compare.add_argument("--address", default=None, help="Ray cluster address (default: start a local instance)")
    compare.add_argument("--quiet", action="store_true", help="no progress bar")
    compare.add_argument(
        "--resume", action="store_true", help="reuse the successful runs and oracles already in --out (same specs)"
    )
    compare.add_argument(
        "--force", action="store_true", help="write over what an earlier comparison left in --out, reusing nothing"
    )
    add_robot_arguments(compare)
    return parser


def run_train(argv: Sequence[str]) -> int:
    """``nbs train ...``: :mod:`train.ppo`'s command line."""
    from train.ppo import main as train_main

    return train_main(list(argv))


def _os_error(exc: OSError) -> str:
    """An OSError on one line, the file first: ``r/metrics.json: No space left on device``."""
    if exc.filename is not None and exc.strerror:
        from scenes.errors import short_name

        return f"{short_name(exc.filename)}: {exc.strerror}"
    return str(exc)


def run_compare(args: argparse.Namespace) -> int:
    """``nbs compare``: the grid, its table and plots."""
    with contextlib.ExitStack() as held:  # --out, claimed from its check to the tables' end
        return _run_compare(args, held)


def _run_compare(args: argparse.Namespace, held: contextlib.ExitStack) -> int:
    from nbs_env.errors import ConfigError
    from train.arguments import config_from_arguments
    from train.compare import (
        CompareError,
        GridStoppedError,
        WorkerLostError,
        check_out_dir,
        grid,
        load_finished,
        run_grid,
        write_outputs,
        write_record,
    )

    def error(message: object, code: int) -> int:
        print(f"nbs compare: error: {message}", file=sys.stderr)
        return code

    if args.resume and args.force:
        return error("--resume reuses what is in --out and --force writes over it: pass one of them", EXIT_USAGE)
    if args.address is not None and args.backend != "ray":
        return error(f"--address applies to --backend ray only (this run is --backend {args.backend})", EXIT_USAGE)
    cores = os.cpu_count() or 1
    if args.jobs > 2 * cores and (args.backend == "local" or args.address is None):
        # Each worker holds a storey, its maps and a scanner's rays (about 1 GB): workers beyond the
        # cores only share them, and a hundred of them would exhaust the memory. Twice the cores
        # leaves room for a machine whose count is read low (a container's).
        where = "local workers" if args.backend == "local" else "workers of a Ray instance started here"
        return error(
            f"--jobs {args.jobs}: this machine has {cores} cores, and {where} beyond them only share them; "
            f"pass at most {2 * cores}, or --backend ray --address for a cluster",
            EXIT_USAGE,
        )
    try:
        preset, overrides = config_from_arguments(args, "default", max_scans=SCAN_BUDGET)
        specs = grid(args.scenes, args.policies, args.seeds, preset, overrides)
        if args.backend == "ray":  # the cluster answers (or Ray is there to start one) before anything runs
            from train.ray_connect import resolve_address

            resolve_address(args.address)
        # What --out holds is looked at only once no other command is writing it: two grids in one
        # folder each tabled the other's runs as their own.
        held.enter_context(claimed([Output("--out", args.out)]))
        out = check_out_dir(args.out, keep=args.resume or args.force, specs=specs)  # before anything runs
        finished = load_finished(out, specs) if args.resume else None
    except (CompareError, ConfigError, OutputBusyError) as exc:
        return error(exc, EXIT_USAGE)
    if finished and not args.quiet:
        runs, oracles = len(finished["runs"]), len(finished["oracles"])
        print(f"resuming: {runs} runs and {oracles} oracles already in {out}")
    with StopRequest() as stop:
        try:
            # Each run is written as it finishes: a grid that fails or is stopped later keeps it.
            results, oracles = run_grid(
                specs,
                args.jobs,
                args.backend,
                args.address,
                progress=not args.quiet,
                finished=finished,
                on_done=lambda kind, record: write_record(out, kind, record),
                stop=stop,
            )
        except GridStoppedError as exc:
            print(
                f"nbs compare: stopped by {stop.name}: {exc.finished} of {exc.total} runs and oracles are done and "
                f"kept in {out}; continue with the same command and --resume",
                file=sys.stderr,
            )
            return exit_code(stop.signal or signal.SIGINT)
        except KeyboardInterrupt:  # a second signal: the workers are ended, the records written are whole
            print(f"nbs compare: interrupted; the runs recorded so far are in {out}", file=sys.stderr)
            return exit_code(stop.signal or signal.SIGINT)
        except (CompareError, ConfigError) as exc:  # Ray missing, or a cluster that stopped answering
            return error(exc, EXIT_USAGE)
        except WorkerLostError as exc:
            return error(exc, EXIT_SCENE_ERROR)
        except OSError as exc:  # a record that could not be written (a full disk)
            return error(_os_error(exc), EXIT_SCENE_ERROR)
        try:
            write_outputs(results, oracles, out)
        except CompareError as exc:
            return error(exc, EXIT_SCENE_ERROR)
        except OSError as exc:
            return error(_os_error(exc), EXIT_SCENE_ERROR)
    failed = [r for r in results if not r["ok"]]
    print((args.out / "table.md").read_text())
    print(f"{len(results) - len(failed)} of {len(results)} runs ok; wrote {args.out}/")
    for r in failed:
        spec = r["spec"]
        print(f"failed: {spec['scene']} {spec['policy']} seed {spec['seed']}: {r['error']}", file=sys.stderr)
    if stop.signal is not None:  # asked to stop while the tables were written: they are whole
        print(f"nbs compare: stopped by {stop.name} after the grid finished; wrote {out}/", file=sys.stderr)
        return exit_code(stop.signal)
    return 0 if not failed else 1


def _load(args: argparse.Namespace):
    from scenes import load_scene

    opts: dict = {}
    if args.storey is not None:
        opts["storey"] = args.storey
    if args.ifc_doors is not None:
        opts["doors"] = args.ifc_doors
    if args.y_up:
        opts["y_up"] = True
    if args.units is not None:
        opts["units"] = args.units
    return load_scene(args.scene, **opts)


def _scene_summary(scene) -> dict:
    from nbs_env.config import EnvConfig
    from nbs_env.storey import start_problem
    from scenes import SurfaceClass

    areas = scene.class_areas()
    # As nbs scan checks it, with the default robot: a start it refuses is said here too.
    refused = start_problem(scene, EnvConfig().robot.navigation.robot_radius)
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
        "start_problem": refused,
    }


def run(args: argparse.Namespace) -> int:
    from scenes import list_scenes, load_scene

    if args.action == "list":
        for name in list_scenes():
            scene = load_scene(name, validate=False)
            floor = sum(r.area for r in scene.rooms)
            print(f"{name:12s} {len(scene.rooms)} rooms, {len(scene.doors)} doors, {floor:6.1f} m² of floor")
        return 0
    if args.action in ("show", "info"):
        problem = scene_option_error(args.scene, args.storey, args.y_up, args.ifc_doors, args.units, flag="")
        if problem is not None:
            print(f"nbs scenes {args.action}: error: {problem}", file=sys.stderr)
            return EXIT_USAGE
    if args.action in ("show", "generate"):
        # Before the storey is loaded or generated: a path found unwritable afterwards would waste it.
        # An edited plan, a checkpoint's policy.json or a report's picture was replaced without a word.
        replace = None if args.force else "pass --force to write over it"
        outputs = [Output("--out", args.out, "file", replace=replace)]
        if args.action == "generate" and args.show is not None:
            outputs.append(Output("--show", args.show, "file", replace=replace))
        reads = [("scene", Path(args.scene))] if args.action == "show" else []
        try:
            check_outputs(outputs, reads=reads)
        except OutputError as exc:
            print(f"nbs scenes {args.action}: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    if args.action == "show":
        scene = _load(args)
        _save_picture(scene, args.out)
        print(f"wrote {args.out}")
        return 0
    if args.action == "info":
        print(json.dumps(_scene_summary(_load(args)), indent=1))
        return 0
    if args.action == "generate":
        from nbs_env.atomic import write_text
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
        write_text(args.out, plan.to_json())  # whole or not at all: a full disk leaves no half a plan
        summary = f"{len(plan.rooms)} rooms, {len(plan.doors)} doors, {len(plan.clutter)} clutter objects"
        print(f"wrote {args.out}: {summary} ({elapsed:.2f} s)")
        if args.show is not None:
            _save_picture(scene, args.show)
            print(f"wrote {args.show}")
        return 0
    raise AssertionError(args.action)  # argparse only lets known actions through


def _save_picture(scene, path: Path) -> None:
    """The storey's top view, written whole or not at all (the format by ``path``'s suffix)."""
    from nbs_env.atomic import replacing
    from scenes.render import save_scene_png

    with replacing(path) as temporary:
        save_scene_png(scene, temporary)


# ---------------------------------------------------------------------- nbs scan
def _scan_error(message: object, code: int) -> int:
    print(f"nbs scan: error: {message}", file=sys.stderr)
    return code


def _default_out(scene: str) -> Path:
    stem = Path(scene).stem if Path(scene).suffix else scene
    return Path(f"scan-{re.sub(r'[^A-Za-z0-9_.-]+', '-', stem)}")


def _table(rows: list[list[str]], right: set[int]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for k, row in enumerate(rows):
        cells = [c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths, strict=True))]
        lines.append("  ".join(cells).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def scan_summary(metrics: dict, out: Path, files: Sequence[str], stopped_by: str = "") -> str:
    """The printed result of ``nbs scan``: a table per true room and the total, in the paper's terms.

    ``stopped_by``: the signal that ended the episode early (``"SIGINT"``), or ``""``."""
    header = ["room", "scans", "SE sensed %", "path m", "processed points", "processing s", "time s"]
    rows = [header]
    for room in metrics["rooms"]:
        rows.append(
            [
                room["name"],
                str(room["scans"]),
                f"{room['structure_sensed_pct']:.1f}",
                f"{room['path_length_m']:.1f}",
                f"{room['processed_points']:,}",
                f"{room['processing_time_s']:.1f}",
                "",
            ]
        )
    outside = [s for s in metrics["steps"] if s["room"] is None]
    if outside:
        rows.append(["(in no room)", str(len(outside)), "", "", "", "", ""])
    total_time = metrics["processing_time_s"] + metrics["acquisition_time_s"] + metrics["travel_time_s"]
    rows.append(
        [
            "total",
            str(metrics["scans"]),
            f"{metrics['structure_sensed_pct']:.1f}",
            f"{metrics['path_length_m']:.1f}",
            f"{metrics['processed_points']:,}",
            f"{metrics['processing_time_s']:.1f}",
            f"{total_time:.1f}",
        ]
    )
    budget = metrics["config"]["max_scans"]
    unscanned = sum(1 for room in metrics["rooms"] if room["scans"] == 0)
    if metrics["complete"] and unscanned:
        # The robot's account (no door left that it found) against the storey's rooms: a door it did
        # not detect (one taller than its door detection's lintels) left rooms it never entered.
        state = (
            f"yes by the robot's account (no door it found is left), but {unscanned} of the storey's "
            f"{len(metrics['rooms'])} rooms got no scan"
        )
    elif metrics["complete"]:
        state = "yes"
    elif stopped_by:
        state = f"no (stopped by {stopped_by})"
    elif metrics["scans"] >= budget:
        state = f"no (the budget of {budget} scans ran out)"
    else:
        state = "no"
    reg = metrics["registration_error"]
    scanner = metrics["config"]["robot"]["scanner"]
    setup = scanner.get("setup_time") or 0.0
    set_up = f" + {setup:g} s set-up" if setup else ""
    if scanner.get("station_time") is not None:
        acquisition = (
            f" ({metrics['scans']} stations: {scanner['station_time']:g} s scan{set_up}, the scanner preset's)"
        )
    else:
        acquisition = f" (points at {scanner['points_per_second']:,.0f} per s{set_up and set_up + ' a station'})"
    quality = metrics["quality"]
    reach = metrics["registrability"]
    overlap = (
        [
            f"registrability: each scan's overlap with the cloud before it mean {100 * reach['mean_overlap']:.0f}%,"
            f" least {100 * reach['min_overlap']:.0f}%; poses refused {reach['refused']}"
        ]
        if reach.get("mean_overlap") is not None
        else []
    )
    lines = [
        f"{metrics['scene']}: policy {metrics['policy']}, seed {metrics['seed']}",
        "",
        _table(rows, right={1, 2, 3, 4, 5, 6}),
        "",
        f"time {total_time:.1f} s = processing {metrics['processing_time_s']:.1f} s"
        f" + acquisition {metrics['acquisition_time_s']:.1f} s + travel {metrics['travel_time_s']:.1f} s",
        f"  acquisition{acquisition}; travel {metrics['path_length_m']:.1f} m at"
        f" {metrics['config']['travel_speed']} m/s",
        f"scan quality: {quality['quality_pct']:.1f}% of the structural surface dense and square (dense: >="
        f" {quality['min_density_per_m2']:g} points/m², {quality['dense_pct']:.1f}%; square: seen at <="
        f" {quality['max_incidence_deg']:g}°, {quality['incidence_pct']:.1f}%)",
        *overlap,
        f"registration error: mean {reg['mean_m'] * 100:.1f} cm / {reg['mean_deg']:.2f}°,"
        f" max {reg['max_m'] * 100:.1f} cm / {reg['max_deg']:.2f}°",
        f"storey complete: {state}",
        f"wrote {out}/: {', '.join(files)}",
    ]
    return "\n".join(lines)


def run_scan(args: argparse.Namespace) -> int:
    """``nbs scan``: run one episode with a policy and write its report."""

    problem = scene_option_error(args.scene, args.storey, args.y_up, args.ifc_doors, args.units)
    if problem is not None:
        return _scan_error(problem, EXIT_USAGE)
    from nbs_env.config import make_config
    from nbs_env.errors import ConfigError, ModelFileError
    from policies import POLICIES, UnknownPolicyError, agreed_requirements, config_for, make_policy
    from train.arguments import adopt_requirements, config_from_arguments

    try:
        policy = make_policy(args.policy, args.seed)
    except UnknownPolicyError as exc:
        detail = str(exc) if ":" in args.policy else f"unknown policy {args.policy!r}; policies: {', '.join(POLICIES)}"
        return _scan_error(detail, EXIT_USAGE)
    except ModelFileError as exc:
        return _scan_error(exc, EXIT_SCENE_ERROR)
    try:
        # The scans are kept for scans.e57, the report's scan project.
        preset, overrides = config_from_arguments(args, "default", max_scans=SCAN_BUDGET)
        overrides = adopt_requirements(overrides, agreed_requirements([policy]))
        config = config_for(make_config(preset, scene=args.scene, keep_scans=True, **overrides), policy)
    except ConfigError as exc:
        return _scan_error(exc, EXIT_USAGE)
    if args.record is not None:
        try:
            from nbs_env.replay import require_rerun

            require_rerun()
        except ImportError as exc:
            return _scan_error(f"--record: {exc}", EXIT_USAGE)
        if args.record.suffix != ".rrd" and not args.record.is_dir():
            return _scan_error(f"--record {args.record}: a rerun recording ends in .rrd", EXIT_USAGE)
    out = args.out if args.out is not None else _default_out(args.scene)
    replace = None if args.force else "pass --force to overwrite it"
    from nbs_env.export import REPORT_FILES

    outputs = [Output("--out", out, "folder", replace=replace, files=REPORT_FILES, others=COMPARISON + TRAINING_RUN)]
    if args.record is not None:
        outputs.append(Output("--record", args.record, "file", replace=replace, example="run.rrd"))
    try:
        # Held until the report is written: what the outputs hold is looked at only once no other
        # command is writing them (two scans into one --out each said it had written its report).
        with claimed(outputs):
            return _checked_scan(args, policy, out, config, outputs)
    except OutputBusyError as exc:
        return _scan_error(exc, EXIT_USAGE)


def _checked_scan(args: argparse.Namespace, policy, out: Path, config, outputs: list[Output]) -> int:
    """:func:`run_scan` from its output checks on, with its outputs claimed."""
    from nbs_env.errors import ConfigError, NBSError
    from nbs_env.export import report_path_problem
    from scenes.errors import SceneError

    try:
        # Before the scan: a path found unwritable after it would lose it, and the scene must not be
        # one of the files the report writes (--force onto the scene's own folder overwrote it).
        check_outputs(outputs, reads=[("--scene", Path(args.scene))])
        # The pictures' folder comes with every report (an empty one with --no-steps: the earlier
        # report's pictures leave with it).
        problem = report_path_problem(out, steps=True, pictures=not args.no_steps)
        if problem is not None:
            raise OutputError(f"--out {out}: {problem}")
    except OutputError as exc:
        return _scan_error(exc, EXIT_USAGE)
    with StopRequest() as stop:
        try:
            return _scan(args, policy, out, config, stop)
        except ConfigError as exc:
            return _scan_error(exc, EXIT_USAGE)
        except (SceneError, NBSError) as exc:  # InvalidPoseError: a start inside a wall or outside
            return _scan_error(exc, EXIT_SCENE_ERROR)
        except OSError as exc:  # a file of the report that could not be written (a full disk)
            return _scan_error(_os_error(exc), EXIT_SCENE_ERROR)
        except KeyboardInterrupt:  # before the scan began, or a second signal: no report waited for
            again = " a second time, during a scan" if stop.signal is not None else ""
            print(f"nbs scan: interrupted{again}; no report of this run was written to {out}/", file=sys.stderr)
            return exit_code(stop.signal or signal.SIGINT)


def _scan(args: argparse.Namespace, policy, out: Path, cfg, stop: StopRequest) -> int:
    """Run the episode and write its report; ``stop`` (:class:`train.stopping.StopRequest`) ends
    the episode early, and the report then holds the scans taken (``"complete": false``)."""
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    from nbs_env.atomic import replacing
    from nbs_env.env import NBSEnv
    from nbs_env.export import REPORT_FILES, write_report
    from train.episode import run_episode

    env = NBSEnv(cfg, render_mode="rgb_array")
    options = {} if args.start is None else {"start": args.start}
    made_out = not out.exists()
    steps_dir: Path | None = None
    bar = tqdm(total=cfg.max_scans, unit="scan", disable=args.quiet, file=sys.stderr, dynamic_ncols=True)
    k = -1

    def on_step(info: dict) -> None:
        nonlocal k, steps_dir
        k += 1
        if k == 0:
            # The scene loaded and the first scan is taken: now the report has somewhere to go. The
            # pictures wait in a folder of their own until the report is written, and move in with
            # it: an earlier report (--force) keeps its own until then, whatever stops this run.
            out.mkdir(parents=True, exist_ok=True)
            steps_dir = Path(tempfile.mkdtemp(prefix=".steps-", dir=out))
            # mkdtemp's folder is the owner's alone; moved in, it must be as any folder made here.
            umask = os.umask(0)
            os.umask(umask)
            steps_dir.chmod(0o777 & ~umask)
        if not args.no_steps:
            with replacing(steps_dir / f"step_{k:03d}.png") as temporary:
                plt.imsave(temporary, env.render())
        # The robot's room number (1, 2, ... in the order it entered them) and the true SE sensed.
        bar.set_postfix(room=info["room"] + 1, se=f"{info['structure_sensed_pct']:.1f}%", refresh=False)
        bar.update(info["scans"] - bar.n)

    recorder = None
    if args.record is not None:
        from nbs_env.replay import RunRecorder

        recorder = RunRecorder(args.record, args.scene)

    def on_step_recorded(info: dict) -> None:
        on_step(info)
        if recorder is not None:
            recorder.log_step(env)

    started = time.time()
    ran = False
    try:
        with bar:
            try:
                policy_times = run_episode(env, policy, args.seed, options, on_step_recorded, stop=stop)
                cut_short = stop()  # else the signal came after the episode's end: the report is whole
                ran = True
            except RuntimeError as exc:
                bar.close()
                return _scan_error(exc, EXIT_SCENE_ERROR)
            finally:
                if recorder is not None and not ran:
                    # Removed for a run that failed: no recording then passes for a run with no report.
                    recorder.close(keep=False)
        with stop.hold():  # a second Ctrl-C now would cost the report the first one asked for
            metrics = write_report(
                env,
                out,
                args.scene,
                policy,
                args.seed,
                policy_times,
                run_started=started,
                full_cloud=args.full_cloud,
                steps=steps_dir,
            )
            if recorder is not None:
                # Renamed into place with the report, never without it: a run whose report failed
                # (out of memory, a full disk) replaced the earlier recording with its own.
                try:
                    recorder.close(keep=True)
                except OSError as exc:  # the report is whole; the recording is not kept
                    exc.strerror = f"{exc.strerror}; the report was written to {out}/, without its recording"
                    raise
    finally:
        if recorder is not None:
            recorder.close(keep=False)  # unless closed with the report above (idempotent)
        # A run that wrote no report leaves nothing: not its pictures, nor a folder it made (which a
        # rerun would take for an earlier report).
        if steps_dir is not None:
            shutil.rmtree(steps_dir, ignore_errors=True)
        if made_out:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when empty
    files = [*REPORT_FILES, *([] if args.no_steps else [f"steps/ ({k + 1} pictures)"])]
    if not env.storey.scan_log:
        files.remove("scans.e57")
    if recorder is not None:
        files.append(f"{args.record} (nbs view {args.record})")
    print(scan_summary(metrics, out, files, stop.name if cut_short else ""))
    # --force replaces the report's own files; a recording in the folder may be an earlier run's
    # (written with --record OUT/x.rrd), which would replay a run this report is not about.
    this = None if args.record is None else args.record.resolve()
    for stale in sorted(p for p in out.glob("*.rrd") if p.resolve() != this):
        print(f"nbs scan: note: {stale} is kept; it is not this run's recording", file=sys.stderr)
    if stop.signal is not None:
        when = f"after {metrics['scans']} scans; wrote their report" if cut_short else "at the end; wrote the report"
        print(f"nbs scan: stopped by {stop.name} {when} to {out}/", file=sys.stderr)
        return exit_code(stop.signal)
    return 0


def _port(text: str) -> int:
    """A TCP port, 0..65535 (0: a free one)."""
    port = integer_from(0, "a port is a whole number")(text)
    if port > 65535:
        raise argparse.ArgumentTypeError(f"a port is a whole number <= 65535, got {text!r}")
    return port


def run_view(args: argparse.Namespace) -> int:
    """``nbs view [--web] RUN.rrd``: open a recording in rerun's viewer, or serve it to a browser."""
    from nbs_env.replay import GRPC_PORT, WEB_PORT, NotARecordingError, NoViewerError, serve_web, view

    given = [name for name in ("port", "web_port", "bind") if getattr(args, name) is not None]
    web_only = [f"--{name.replace('_', '-')}" for name in given]
    if web_only and not args.web:
        print(f"nbs view: error: {', '.join(web_only)} needs --web", file=sys.stderr)
        return EXIT_USAGE

    def ready(url: str) -> None:
        print(f"serving {args.recording} with rerun's web viewer: open {url}", flush=True)
        print("(Ctrl-C stops it)", flush=True)

    try:
        if not args.web:
            return view(args.recording)
        return serve_web(
            args.recording,
            port=GRPC_PORT if args.port is None else args.port,
            web_port=WEB_PORT if args.web_port is None else args.web_port,
            bind=args.bind or "127.0.0.1",
            on_ready=ready,
        )
    except ImportError as exc:
        print(f"nbs view: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, NotARecordingError) as exc:
        print(f"nbs view: error: {exc}", file=sys.stderr)
        return EXIT_SCENE_ERROR
    except NoViewerError as exc:
        hint = "" if args.web else f"; serve it to a browser instead: nbs view --web {args.recording}"
        print(f"nbs view: error: {exc}{hint}", file=sys.stderr)
        return EXIT_NO_VIEWER


def _environment_problem() -> str | None:
    """What is wrong with the environment the commands run in, before any work: a working folder
    that is gone, and the variables they read: the kernels' ``NBS_THREADS``, libgomp's
    ``OMP_NUM_THREADS`` and matplotlib's ``MPLBACKEND`` (which fails its import)."""
    from nbs_env.threads import cores

    try:
        os.getcwd()
    except OSError:  # every relative path (the default --out) fails, with no name to give
        return "the working folder no longer exists (removed or moved since the shell entered it): cd into one"
    try:
        cores()
    except ValueError as exc:
        return str(exc)
    omp = os.environ.get("OMP_NUM_THREADS")
    # What libgomp (torch, scikit-learn) reads when it loads: a value it refuses is two stray lines of
    # its own on stderr, whatever the command then does.
    if omp is not None and not re.fullmatch(r"\s*\+?0*[1-9]\d*\s*(,\s*\+?0*[1-9]\d*\s*)*", omp):
        return (
            f"OMP_NUM_THREADS={omp[:40]!r} is not a thread count (a positive integer, or a list such as 4,2): "
            "unset it or fix it (nbs sizes its own threads with NBS_THREADS)"
        )
    if "MPLBACKEND" in os.environ:
        try:
            import matplotlib  # noqa: F401  (it reads MPLBACKEND on import)
        except ValueError:
            shown = os.environ["MPLBACKEND"][:40]
            return f"MPLBACKEND={shown!r} is not a matplotlib backend: unset it (nbs draws its pictures with Agg)"
    return None


#: The longest line a command writes to stderr: an error that quotes a file's content (a room name
#: of a million characters) is cut to this, with the count of what was left out.
MAX_STDERR_LINE = 2000


class _BoundedLines:
    """stderr with each line cut to :data:`MAX_STDERR_LINE` characters."""

    def __init__(self, stream) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        lines = text.split("\n")
        for k, line in enumerate(lines):
            if len(line) > MAX_STDERR_LINE:
                keep = MAX_STDERR_LINE - 60
                lines[k] = f"{line[:keep]}… ({len(line) - keep:,} characters left out)"
        return self._stream.write("\n".join(lines))

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A library's warning as one line (``warnings.showwarning``), not two with a source line."""
    print(f"nbs: warning: {' '.join(str(message).split())}", file=sys.stderr)


class _OneLineLog(logging.Handler):
    """A library's log record of a warning or worse (matplotlib's, at WARNING) as one prefixed line:
    without a handler, Python's last resort prints the bare message, a stray line in a command's
    stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(Exception):  # a message that does not format is not worth a traceback
            print(f"nbs: warning: {' '.join(record.getMessage().split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """``nbs``: every command's errors end here as one line and an exit code, never a traceback:
    Ctrl-C before a command's own handler is in place (while modules load) exits 130, and a file
    the system refuses (a name too long, a loop of links) exits 1 naming it."""
    from train.stopping import defer_signals

    # A caller in the same process (a test, a notebook) gets its handlers back.
    handlers = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} if argv is not None and _main_thread() else {}
    defer_signals()
    if argv is None:
        _fill_closed_descriptors()
    stderr, stdout, showwarning = sys.stderr, sys.stdout, warnings.showwarning
    # A stream closed by the caller (`nbs scan ... >&-`: Python's is None) takes what is written and
    # drops it, as print() does; the report files are the command's work.
    sinks = {name: open(os.devnull, "w") for name in ("stdout", "stderr") if getattr(sys, name) is None}  # noqa: SIM115  # closed in main's finally
    if "stdout" in sinks and _prints_its_product(sys.argv[1:] if argv is None else argv):
        # What the command makes is what it prints (a scene's JSON, the list, the version): dropped,
        # it was lost with exit 0. As coreutils' `ls >&-` does, say so and fail.
        for sink in sinks.values():
            sink.close()
        if sys.stderr is not None:
            print("nbs: error: stdout is closed, and what this command makes is what it prints to it: "
                  "redirect it to a file or to /dev/null", file=sys.stderr)  # fmt: skip
        for sig, handler in handlers.items():
            if handler is not None:
                signal.signal(sig, handler)
        return EXIT_SCENE_ERROR
    if sinks:
        sys.stdout, sys.stderr = sinks.get("stdout", sys.stdout), sinks.get("stderr", sys.stderr)
        stderr, stdout = sys.stderr, sys.stdout
    # What no encoding can write (a lone surrogate in a name a file gave) is escaped, not a
    # UnicodeEncodeError halfway through a summary whose report is already written.
    errors = {stream: getattr(stream, "errors", None) for stream in (stdout, stderr)}
    for stream, previous in errors.items():
        if previous is not None and hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    sys.stderr, warnings.showwarning = _BoundedLines(stderr), _show_warning
    sys.stdout = NamedStream(stdout, "stdout")  # a full disk under `> file` is named as stdout's
    log = _OneLineLog(logging.WARNING)
    logging.getLogger().addHandler(log)
    try:
        code = _checked_main(argv)
    finally:  # a caller in the same process (a test, a notebook) gets its own back
        sys.stderr, sys.stdout, warnings.showwarning = stderr, stdout, showwarning
        for name, sink in sinks.items():
            setattr(sys, name, None)
            sink.close()
        logging.getLogger().removeHandler(log)
        for stream, previous in errors.items():
            if previous is not None and hasattr(stream, "reconfigure"):
                with contextlib.suppress(Exception):
                    stream.reconfigure(errors=previous)
        for sig, handler in handlers.items():
            if handler is not None:  # None: set outside Python, which cannot be put back
                signal.signal(sig, handler)
    if argv is None:
        # The process's own command line, whose work is done and said: a stop signal from here on
        # finds nothing to stop. Python restores the default handlers while it shuts down (half a
        # second with open3d and torch loaded), so one landing then killed the process silently
        # with 128 + the signal after a complete run. Ignored (a disposition of the whole process,
        # which the shutdown keeps; a mask would be the main thread's only), it is dropped.
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)
    return code


def _prints_its_product(argv: Sequence[str]) -> bool:
    """Whether the command line's whole product is what it prints: the version, help, and the
    ``scenes list`` and ``scenes info`` commands (the others write files, and print a summary)."""
    args = [str(a) for a in argv]
    if any(a in ("-h", "--help", "--version") for a in args):
        return True
    return len(args) >= 2 and args[0] == "scenes" and args[1] in ("list", "info")


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` is a ``KeyboardInterrupt`` or was caused by one: raised inside a C extension's
    import (open3d's, torch's), an interrupt comes out as ``ImportError: initialization failed``."""
    seen: set[int] = set()
    node: BaseException | None = exc
    while node is not None and id(node) not in seen:
        if isinstance(node, KeyboardInterrupt):
            return True
        seen.add(id(node))
        node = node.__cause__ or node.__context__
    return False


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _fill_closed_descriptors() -> None:
    """Put ``/dev/null`` on a closed descriptor 0, 1 or 2: else the first file the command opens
    (a report) takes its number, and whatever a library prints to it lands in the file."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)


def _stopped(sig: int | None) -> int:
    stop = sig or signal.SIGINT
    print(f"nbs: stopped by {signal.Signals(stop).name}", file=sys.stderr)
    return exit_code(stop)


def _checked_main(argv: Sequence[str] | None) -> int:
    from train.stopping import pending_signal

    problem = _environment_problem()
    if problem is not None:
        print(f"nbs: error: {problem}", file=sys.stderr)
        return EXIT_USAGE
    try:
        code = _main(argv)
        sys.stdout.flush()  # output still buffered fails here, named, not at the interpreter's exit
    except KeyboardInterrupt:
        return _stopped(pending_signal())
    except BrokenPipeError:  # the reader of stdout went away (`nbs scenes list | head -1`): as `cat` does
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return exit_code(signal.SIGPIPE)
    except OSError as exc:
        print(f"nbs: error: {_os_error(exc)}", file=sys.stderr)
        return EXIT_SCENE_ERROR
    except MemoryError as exc:
        # Under an address-space or container limit numpy says so (without one, Linux's OOM killer
        # ends the process and no line can be printed).
        reason = " ".join(str(exc).split())[:160] or "MemoryError"
        print(
            f"nbs: error: out of memory ({reason}); a finer voxel (--voxel), a larger storey or a longer run "
            "needs more: free memory or coarsen the voxel",
            file=sys.stderr,
        )
        return EXIT_SCENE_ERROR
    except Exception as exc:
        if not interrupted(exc):
            raise
        return _stopped(pending_signal())
    late = pending_signal()
    if late is not None and code == 0:  # a command with no steps to stop at finished meanwhile
        print(f"nbs: stopped by {signal.Signals(late).name}", file=sys.stderr)
        return exit_code(late)
    return code


def _main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nbs`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["train"]:
        return run_train(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    from scenes.errors import SceneError

    if args.command in ("scan", "compare"):
        try:
            return run_scan(args) if args.command == "scan" else run_compare(args)
        except KeyboardInterrupt:  # Ctrl-C while the command was still setting up, before its handler
            print(f"nbs {args.command}: interrupted", file=sys.stderr)
            return exit_code(signal.SIGINT)
        except Exception as exc:  # the same, raised inside a C extension's import as its ImportError
            if not interrupted(exc):
                raise
            print(f"nbs {args.command}: interrupted", file=sys.stderr)
            return exit_code(signal.SIGINT)
    if args.command == "view":
        from train.stopping import undefer_signals

        undefer_signals()  # it waits for Ctrl-C itself
        return run_view(args)
    from train.stopping import interrupt_on_signals

    interrupt_on_signals()  # nothing to keep: a stop signal stops it now, not at its end
    try:
        return run(args)
    except SceneError as exc:
        print(f"nbs: error: {exc}", file=sys.stderr)
        return EXIT_SCENE_ERROR
    except BrokenPipeError:  # not a file of ours: main's
        raise
    except OSError as exc:  # a file that could not be written (a full disk), named
        print(f"nbs: error: {_os_error(exc)}", file=sys.stderr)
        return EXIT_SCENE_ERROR


if __name__ == "__main__":
    sys.exit(main())
