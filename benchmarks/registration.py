"""Benchmark: registration error and time per scan, small_gicp's GICP (the default) against open3d's ICP.

A *sequence* is what the robot registers: per stop the raw scan (sensor frame), the true pose, the
odometry increment since the previous stop and the distance driven. Two sources:

- ``episode``: a greedy episode in :class:`~nbs_env.env.NBSEnv` at the default configuration; the
  scans, priors and true poses that ``Robot.scan`` hands to ``register`` are recorded by
  monkeypatching (nothing in the package changes);
- ``tour``: independent of the policy, stops on a grid over the storey's free floor visited in
  nearest-neighbour order (or ``--stops``), with the default odometry drift model and scanner.

Each method then re-registers the sequence *closed loop*: the prior of stop k is the method's own
estimate of stop k-1 composed with the recorded odometry increment, and each registered scan goes
into that method's own S(t), as in ``Robot.scan``. Per scene it prints each method's error against
the true pose, its refusals and its time per scan with the ratio to the first method (the
reference) in the same run; ``--per-scan`` adds one line per scan with the gates' figures
(agreement, see-through share).

Methods (``--methods``), each a RegistrationConfig:

- ``gicp``: the default;
- ``open3d``: the default with ``method="open3d"`` (open3d's point-to-plane ICP);
- ``before``: the registration before issue 14 (open3d, fitness and RMSE gates, refused scans in
  the target, no heading check, no see-through gate): :data:`BEFORE`;
- any of them with ``[field=value;...]`` appended, e.g. ``gicp[heading_check_deg=0]``.

Usage:
    python benchmarks/registration.py --suite unseen [--per-scan]
    python benchmarks/registration.py --scene five_rooms --source tour --spacing 1.5 --per-scan
    python benchmarks/registration.py --scene synthetic:corridor --source tour
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from nbs_env.config import RegistrationConfig  # noqa: E402
from nbs_env.mapping.cloud import AccumulatedCloud  # noqa: E402
from nbs_env.sensing.pose import planar, pose_error, yaw_of  # noqa: E402
from nbs_env.sensing.registration import register  # noqa: E402

#: The registration before issue 14, as RegistrationConfig fields: open3d point-to-plane, fitness
#: and RMSE gates, refused scans left in the target, no heading check, no see-through gate.
BEFORE: dict[str, Any] = dict(
    method="open3d",
    min_points=0,
    min_inliers=0,
    min_agreement=None,
    max_see_through=None,
    min_constraint=0.0,
    exclude_rejected=False,
    heading_check_deg=0.0,
    target_radius=30.0,
    crop_margin=None,
)


#: Synthetic storeys for what the corpus lacks: a long corridor with nothing along it (its axis is
#: constrained only by end walls, and from its middle both lie beyond the target crop).
SYNTHETIC: dict[str, dict[str, Any]] = {
    "synthetic:corridor": {
        "format": "nbs-floorplan",
        "version": 1,
        "name": "corridor",
        "description": "A 70 x 2 m corridor, plain walls, no doors, windows or furniture.",
        "ceiling_height": 2.6,
        "wall_thickness": 0.2,
        "rooms": [{"name": "corridor", "polygon": [[0, 0], [70, 0], [70, 2], [0, 2]]}],
        "start": [1.0, 1.0],
    },
}
#: Tours with given stops, by scene: down the synthetic corridor's centre line every 2.5 m.
TOUR_STOPS: dict[str, list[tuple[float, float]]] = {
    "synthetic:corridor": [(float(x), 1.0) for x in np.arange(1.0, 69.5, 2.5)],
}


def _load(spec: str, **options):
    from scenes import load_scene
    from scenes.floorplan import FloorPlan

    if spec in SYNTHETIC:
        return load_scene(FloorPlan.from_dict(SYNTHETIC[spec], source=spec), **options)
    return load_scene(spec, **options)


# ----------------------------------------------------------------------------------- sequences
@dataclass
class Stop:
    points: np.ndarray  # (n, 3) float32, sensor frame
    true: np.ndarray  # (4, 4) true pose
    increment: np.ndarray  # (4, 4) odometry increment from planar(estimate k-1) (k=0: the prior)
    travelled: float
    labels: np.ndarray  # (n,) uint8 SurfaceClass of the hit faces (ground truth, for diagnosis)
    rooms: np.ndarray  # (n,) int32 room of the hit faces, -1 none (outside faces)
    recorded_prior: np.ndarray | None = None  # the prior the robot had (episode)
    recorded_pose: np.ndarray | None = None  # the pose the robot's registration gave (episode)
    inside: bool = True  # the true position lies in a room polygon


@dataclass
class Sequence:
    label: str
    scene_name: str
    source: str
    seed: int
    stops: list[Stop] = field(default_factory=list)


def _planar_of(pose: np.ndarray) -> np.ndarray:
    return planar(float(pose[0, 3]), float(pose[1, 3]), yaw_of(pose), 0.0)


def _inside(scene, xy) -> bool:
    import shapely
    from shapely.geometry import Polygon

    if not scene.rooms:
        return True
    return any(shapely.contains_xy(Polygon(r.polygon), float(xy[0]), float(xy[1])) for r in scene.rooms)


def record_episode(label: str, spec: str, options: dict, seed: int, start=None) -> Sequence:
    """The scans ``Robot.scan`` registers in a greedy episode (default config), by monkeypatching."""
    import nbs_env.robot as robot_mod
    import policies
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.sensing import scanner as scanner_mod
    from policies import config_for
    from train.episode import run_episode

    calls: list[dict] = []
    last: dict[str, Any] = {}
    real_register, real_scan = robot_mod.register, scanner_mod.Scanner.scan

    def scan(self, pose, rng=None):
        last["scan"], last["scene"] = real_scan(self, pose, rng), self.scene
        return last["scan"]

    def spy(points, initial, cloud, config=None, travelled=0.0):
        result = real_register(points, initial, cloud, config, travelled)
        s = last["scan"]
        calls.append(
            dict(
                points=np.array(points, dtype=np.float32),
                prior=np.array(initial, dtype=float),
                pose=np.array(result.pose, dtype=float),
                true=np.array(s.truth.pose, dtype=float),
                travelled=float(travelled),
                labels=np.array(s.truth.labels),
                rooms=np.array(s.truth.rooms),
                inside=_inside(last["scene"], s.truth.pose[:2, 3]),
            )
        )
        return result

    policy = policies.make_policy("greedy", seed)
    config = config_for(make_config("default", scene=spec, scene_options=dict(options)), policy)
    scanner_mod.Scanner.scan, robot_mod.register = scan, spy
    try:
        run_episode(NBSEnv(config), policy, seed, {"start": start} if start is not None else None)
    finally:
        scanner_mod.Scanner.scan, robot_mod.register = real_scan, real_register
    seq = Sequence(label, spec, "episode", seed)
    previous = None
    for c in calls:
        inc = c["prior"] if previous is None else np.linalg.inv(_planar_of(previous)) @ c["prior"]
        seq.stops.append(
            Stop(
                c["points"], c["true"], inc, c["travelled"], c["labels"], c["rooms"], c["prior"], c["pose"], c["inside"]
            )
        )
        previous = c["pose"]
    return seq


def _free_stops(scene, scanner, spacing: float, floor_z: float) -> np.ndarray:
    """Grid points over the storey's floor where the robot fits: probed by rays from the scanner's
    raycaster (walls, furniture and the roof's low parts), not by plan outlines."""
    verts = scene.mesh.vertices
    lo, hi = verts[:, :2].min(0), verts[:, :2].max(0)
    xs = np.arange(lo[0] + spacing / 2, hi[0], spacing)
    ys = np.arange(lo[1] + spacing / 2, hi[1], spacing)
    grid = np.array([(x, y) for x in xs for y in ys])
    if not len(grid):
        return grid
    az = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    keep = []
    for p in grid:
        rays = []
        for h in (0.3, 0.9, 1.5):
            for a in az:
                rays.append([p[0], p[1], floor_z + h, np.cos(a), np.sin(a), 0.0])
        rays.append([p[0], p[1], floor_z + 0.2, 0, 0, -1])  # a floor below
        rays.append([p[0], p[1], floor_z + 0.2, 0, 0, 1])  # headroom above
        t, _ = scanner.cast(np.asarray(rays, dtype=np.float32))
        side, down, up = t[:-2], t[-2], t[-1]
        keep.append(side.min() > 0.5 and down < 0.4 and up > 1.9)
    return grid[np.asarray(keep, dtype=bool)]


def _drivable(scanner, a: np.ndarray, b: np.ndarray, floor_z: float, half_width: float = 0.3) -> bool:
    """Whether the robot can drive straight from ``a`` to ``b``: rays along the segment at three
    heights, on its centre line and both edges, hit nothing before ``b``."""
    d = b - a
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        return True
    u = d / length
    side = np.array([-u[1], u[0]]) * half_width
    rays = [[*(a + o), floor_z + h, u[0], u[1], 0.0] for o in (np.zeros(2), side, -side) for h in (0.3, 0.9, 1.5)]
    t, _ = scanner.cast(np.asarray(rays, dtype=np.float32))
    return bool(t.min() > length)


def _tour(scanner, start: np.ndarray, grid: np.ndarray, floor_z: float, max_stops: int):
    """A drivable tour: from the current stop the nearest unvisited grid point it can drive to in a
    straight line; when there is none, the nearest one drivable from any earlier stop, reached by
    driving back to that stop first. Returns the stops and the distance driven to each."""
    stops, driven = [np.asarray(start, dtype=float)], [0.0]
    left = [np.asarray(p, dtype=float) for p in grid if np.linalg.norm(p - start) > 1e-6]
    while left and len(stops) < max_stops:
        order = np.argsort([np.linalg.norm(p - stops[-1]) for p in left])
        nxt = next((int(i) for i in order if _drivable(scanner, stops[-1], left[int(i)], floor_z)), None)
        if nxt is not None:
            driven.append(float(np.linalg.norm(left[nxt] - stops[-1])))
            stops.append(left.pop(nxt))
            continue
        best = None  # (length, index in left, via stop)
        for i, p in enumerate(left):
            for v in stops[::-1]:
                length = float(np.linalg.norm(v - stops[-1]) + np.linalg.norm(p - v))
                if (best is None or length < best[0]) and _drivable(scanner, v, p, floor_z):
                    best = (length, i, v)
        if best is None:
            break
        driven.append(best[0])
        stops.append(left.pop(best[1]))
    return stops, driven


def record_tour(
    label: str, spec: str, options: dict, seed: int, start=None, spacing: float = 1.0, stops=None, max_stops: int = 40
) -> Sequence:
    """Scans along a drivable tour of the storey's free floor (policy-independent), with the default
    scanner and odometry drift model; the drift grows with the distance driven to each stop."""
    from nbs_env.config import RobotConfig
    from nbs_env.sensing.odometry import Odometry
    from nbs_env.sensing.scanner import Scanner

    load = dict(options)
    if start is not None:
        load["start"] = start
    scene = _load(spec, **load)
    robot = RobotConfig()
    scanner = Scanner(scene, robot.scanner)
    floor_z = float(scene.start[2])
    if stops is None and spec in TOUR_STOPS:
        stops = TOUR_STOPS[spec]
    if stops is None:
        grid = _free_stops(scene, scanner, spacing, floor_z)
        stops, driven = _tour(scanner, np.asarray(scene.start[:2], dtype=float), grid, floor_z, max_stops)
    else:
        stops = [np.asarray(p, dtype=float) for p in stops]
        driven = [0.0] + [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(stops)]
    rng = np.random.default_rng(seed)
    odometry = Odometry(robot.odometry, rng)
    seq = Sequence(label, scene.name, "tour", seed)
    true_prev = None
    for xy, dist in zip(stops, driven, strict=True):
        yaw = 0.0 if true_prev is None else float(np.arctan2(*(xy - true_prev[:2, 3])[::-1]))
        true = odometry.true_sensor_pose(xy, yaw, floor_z, robot.scanner.height)
        if true_prev is None:
            inc = planar(xy[0], xy[1], 0.0, floor_z + robot.scanner.height)
        else:
            inc = odometry.drive(np.eye(4), true_prev, true, dist)
        s = scanner.scan(true, rng)
        stop = Stop(np.array(s.points), true, inc, dist, np.array(s.truth.labels), np.array(s.truth.rooms))
        stop.inside = _inside(scene, xy)
        seq.stops.append(stop)
        true_prev = true
    return seq


# ------------------------------------------------------------------------------------- methods
def make_method(name: str) -> RegistrationConfig:
    """The RegistrationConfig of a method name (module docstring)."""
    base, _, extra = name.partition("[")
    overrides: dict[str, Any] = {}
    for item in filter(None, extra.removesuffix("]").split(";")):
        key, _, value = item.partition("=")
        if value in ("None", "True", "False"):
            overrides[key] = {"None": None, "True": True, "False": False}[value]
        else:
            overrides[key] = json.loads(value) if value[:1] in "0123456789-[" else value
    bases = {"gicp": {}, "open3d": {"method": "open3d"}, "before": BEFORE}
    if base not in bases:
        raise SystemExit(f"unknown method {name!r}: one of {', '.join(bases)}, optionally with [field=value;...]")
    return RegistrationConfig(**{**bases[base], **overrides})


# ------------------------------------------------------------------------------------- replay
def replay(seq: Sequence, method: str, target_mode: str = "estimated") -> list[dict]:
    """Register ``seq`` closed loop with ``method``; one row per scan."""
    cfg = make_method(method)
    cloud = AccumulatedCloud(cfg.voxel_size, normals=True, rooms=False)
    rows = []
    estimate = recorded = None
    for k, stop in enumerate(seq.stops):
        if k == 0:
            prior = stop.increment.copy()
        elif stop.recorded_prior is not None and recorded is not None and np.array_equal(estimate, recorded):
            prior = stop.recorded_prior.copy()  # bit for bit the robot's own prior while on its track
        else:
            prior = _planar_of(estimate) @ stop.increment
        if target_mode == "truth" and k:
            # Every earlier scan at its true pose; the prior is the true pose off by this leg's drift.
            prior = _planar_of(seq.stops[k - 1].true) @ stop.increment
        # The map update (downsampling and normals of the previous scan) happens in the first call
        # that reads the working copy; it is the same for every method, so it is done here, untimed.
        cloud.target_arrays()
        result = register(stop.points.astype(np.float64), prior, cloud, cfg, stop.travelled)
        estimate, recorded = result.pose, stop.recorded_pose
        dt, dr = pose_error(estimate, stop.true)
        pt, pr = pose_error(prior, stop.true)
        rows.append(
            dict(
                k=k, err_m=dt, err_deg=dr, prior_m=pt, prior_deg=pr, seconds=result.seconds,
                accepted=result.accepted, reason=result.reason, agreement=result.agreement,
                see_through=result.see_through, travelled=stop.travelled,
            )
        )  # fmt: skip
        placed = stop.true if target_mode == "truth" else estimate
        world = stop.points.astype(np.float64) @ placed[:3, :3].T + placed[:3, 3]
        cloud.add(world, placed[:3, 3], registered=None, pose=placed)
    return rows


def summary(rows: list[dict]) -> dict:
    """Errors (metres, degrees), milliseconds per registration (the first scan has none), refusals."""
    registered = [r for r in rows if r["k"] > 0] or rows
    return dict(
        scans=len(rows),
        mean_m=float(np.mean([r["err_m"] for r in rows])),
        max_m=float(np.max([r["err_m"] for r in rows])),
        mean_deg=float(np.mean([r["err_deg"] for r in rows])),
        max_deg=float(np.max([r["err_deg"] for r in rows])),
        ms=1e3 * float(np.mean([r["seconds"] for r in registered])),
        rejected=int(sum(not r["accepted"] for r in rows)),
        over=int(sum(r["err_m"] > 0.02 or r["err_deg"] > 0.5 for r in rows)),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", help="a suite of scenes.corpus (e.g. unseen): an episode of each storey")
    parser.add_argument("--tours", action="store_true", help="with --suite: a tour of each storey as well")
    parser.add_argument("--only", nargs="*", help="labels to run")
    parser.add_argument("--scene", help="a scene name or file (or synthetic:corridor)")
    parser.add_argument("--storey")
    parser.add_argument("--start", help="x,y")
    parser.add_argument("--source", choices=("episode", "tour"), default="episode")
    parser.add_argument("--stops", help="tour stops 'x,y;x,y;...' (default: a grid over the free floor)")
    parser.add_argument("--spacing", type=float, default=1.0, help="tour grid spacing, m")
    parser.add_argument("--max-stops", type=int, default=40)
    parser.add_argument("--seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--methods", default="gicp,open3d,before")
    parser.add_argument(
        "--target",
        choices=("estimated", "truth"),
        default="estimated",
        help="truth: every scan into S(t) at the true poses (one registration's error alone)",
    )
    parser.add_argument("--per-scan", action="store_true")
    parser.add_argument("--json", type=Path, help="write all rows here")
    args = parser.parse_args()

    runs: list[tuple[str, str, dict[str, Any], str, tuple[float, float] | None]] = []
    if args.suite:
        from scenes.corpus import suite

        specs, skipped = suite(args.suite)
        if skipped:
            print(f"suite {args.suite}: skipped (local files absent): {', '.join(skipped)}")
        for spec in specs:
            name = spec.split(":", 1)[1]
            runs.append((name, spec, {}, "episode", None))
            if args.tours:
                runs.append((name + "-tour", spec, {}, "tour", None))
    if args.scene:
        opts: dict[str, Any] = {}
        if args.storey is not None:
            opts["storey"] = int(args.storey) if args.storey.lstrip("-").isdigit() else args.storey
        start = tuple(float(v) for v in args.start.split(",")) if args.start else None
        runs.append((Path(args.scene).stem, args.scene, opts, args.source, start))
    if args.only:
        runs = [r for r in runs if r[0] in args.only]
    if not runs:
        parser.error("give --suite or --scene")
    # Commas inside [...] belong to a value (a list), not to the list of methods.
    methods = re.split(r",(?![^\[]*\])", args.methods)
    for m in methods:
        make_method(m)  # unknown names fail before any episode runs
    stops = [tuple(map(float, s.split(","))) for s in args.stops.split(";")] if args.stops else None
    out: dict[str, Any] = {"methods": methods, "target": args.target, "runs": []}
    table = []
    for label, spec, opts, source, start in runs:
        for seed in args.seeds:
            if source == "episode":
                seq = record_episode(label, spec, opts, seed, start)
            else:
                seq = record_tour(label, spec, opts, seed, start, args.spacing, stops, args.max_stops)
            results = {m: replay(seq, m, args.target) for m in methods}
            ref = methods[0]
            print(f"\n== {label} seed {seed} ({seq.source}, {len(seq.stops)} scans, target {args.target})")
            if args.per_scan:
                print("  k  trav  prior cm/deg | " + " | ".join(f"{m:>34s}" for m in methods))
                for k in range(len(seq.stops)):
                    r0 = results[ref][k]
                    cells = [
                        f"{100 * r['err_m']:6.2f}cm {r['err_deg']:5.2f}° a{r['agreement']:.2f} "
                        f"s{r['see_through']:.3f} {'  ' if r['accepted'] else ' R'}"
                        for r in (results[m][k] for m in methods)
                    ]
                    print(
                        f"{k:3d} {r0['travelled']:5.1f} {100 * r0['prior_m']:6.1f}/{r0['prior_deg']:4.2f} | "
                        + " | ".join(cells)
                    )
                    for m in methods:
                        if not results[m][k]["accepted"]:
                            print(f"      {m} refused: {results[m][k]['reason']}")
            t_ref = summary(results[ref])["ms"]
            for m in methods:
                s = summary(results[m])
                ratio = s["ms"] / t_ref if t_ref else float("nan")
                print(
                    f"  {m:11s} mean {100 * s['mean_m']:5.2f} cm  max {100 * s['max_m']:5.2f} cm  "
                    f"mean {s['mean_deg']:5.3f}°  max {s['max_deg']:5.3f}°  {s['ms']:6.0f} ms/scan "
                    f"(x{ratio:4.2f} of {ref})  refused {s['rejected']}  >2cm/0.5° {s['over']}"
                )
                table.append((label, seed, m, s, ratio))
            out["runs"].append(dict(label=label, seed=seed, source=seq.source, scans=len(seq.stops), results=results))
    head = "| scene | seed | method | scans | mean cm | max cm | mean ° | max ° | ms/scan | × ref | refused |"
    print("\n" + head + " >2cm/0.5° |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for label, seed, m, s, ratio in table:
        print(
            f"| {label} | {seed} | {m} | {s['scans']} | {100 * s['mean_m']:.2f} | {100 * s['max_m']:.2f} | "
            f"{s['mean_deg']:.3f} | {s['max_deg']:.3f} | {s['ms']:.0f} | {ratio:.2f} | {s['rejected']} | {s['over']} |"
        )
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
