"""``nbs compare``: every (scene, policy, seed) run, locally in worker processes or on a Ray cluster,
and the paper's comparison table.

Each run plays one policy on one scene with one seed (:func:`run_one`) and returns its
``metrics.json`` content, or its error: a failed run does not stop the others. The oracle
(:mod:`policies.oracle`, ground truth, the yardstick) is computed once per scene. The outputs:

- ``runs/<scene>/<policy>/seed<k>/metrics.json`` for every run (``error.txt`` for a failed one);
- ``table.csv`` and ``table.md``: per scene, policy and room, and in total, mean ± std over seeds of
  the paper's five quantities (scans, time, % structural surface sensed, processed points, path
  length), and two against the oracle: coverage as a share of the largest any plan reaches, and the
  scans taken over the oracle's scans to the same coverage;
- ``storeys.md``: per scene and policy, what a storey is judged by: scans, coverage, its share of the
  oracle's and the oracle's scans to it, the rooms the oracle covers (at least
  :data:`COVERABLE_ROOM_PCT` % of their surface) that the robot never scanned, the rooms ended by the
  per-room cap, those ended for want of an NVP after their first scan, and the share ended by the
  room-completion rule (not by the cap or no NVP left), the doors abandoned (and why) and found
  exterior, path, registration error;
- ``methods.md``: per policy over every scene and seed, how its rooms ended (its own rule, the
  per-room cap, or no NVP left: the storey session's end, neither the rule's nor the cap's; and of
  those, after one scan), the rooms it left unscanned, its mean scans, coverage and path;
- ``quality.md``: per scene and policy, the scan-quality figures (``metrics.json``'s ``quality`` and
  ``registrability``): the share of the structural surface sensed densely enough, squarely enough
  and both, and each scan's overlap with the cloud before it and ICP's fitness;
- ``coverage_vs_scans.png`` (one curve per policy, a band over runs), ``quality_vs_scans.png`` (the
  coverage at the density and at the incidence threshold, against scans) and ``path_time.png``.

Runs are deterministic: the same seeds give the same table, times aside. Each run is written as it
finishes (:func:`write_record`), every file whole or not at all (:mod:`nbs_env.atomic`); a grid
stopped by Ctrl-C or SIGTERM (``run_grid``'s ``stop``) ends its workers and keeps what finished,
for ``--resume``.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import math
import multiprocessing
import re
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from nbs_env.atomic import replacing
from nbs_env.atomic import write_text as _write_text
from nbs_env.config import json_form
from nbs_env.config.checks import parse_int, same_json
from nbs_env.errors import ConfigError
from scenes.jsonio import json_text, read_json_file
from scenes.limits import MAX_SEED_DIGITS
from train.arguments import MAX_RUNS, parse_range

__all__ = [
    "GridStoppedError",
    "RunSpec",
    "WorkerLostError",
    "expand_scenes",
    "record_problem",
    "run_grid",
    "run_one",
    "summarise",
    "write_outputs",
]

#: How often (s) a grid waiting on its workers looks whether it was asked to stop.
STOP_POLL_S = 0.25

#: The table's quantities: (key, heading, format).
QUANTITIES = (
    ("scans", "scans", "{:.1f}"),
    ("time_s", "time (s)", "{:.0f}"),
    ("structure_sensed_pct", "SE sensed (%)", "{:.1f}"),
    ("processed_points", "processed points", "{:,.0f}"),
    ("path_length_m", "path (m)", "{:.1f}"),
)


class CompareError(ValueError):
    """A bad grid specification (scenes, policies, seeds)."""


class WorkerLostError(RuntimeError):
    """A worker process of the local backend died mid-run (killed, out of memory)."""


class GridStoppedError(Exception):
    """:func:`run_grid` was asked to stop (Ctrl-C, SIGTERM) before every run finished.

    The runs and oracles that finished went to ``on_done`` first; the workers are ended.

    Attributes
    ----------
    finished, total : int
        Runs and oracles done (reused ones included), and in all.
    """

    def __init__(self, finished: int, total: int) -> None:
        super().__init__(f"stopped with {finished} of {total} runs and oracles done")
        self.finished, self.total = finished, total


@dataclass(frozen=True)
class RunSpec:
    """One run of the grid (JSON-safe).

    Attributes
    ----------
    scene, policy : str
    seed : int
    preset : str
        The configuration preset (:data:`nbs_env.config.PRESETS`).
    overrides : dict
        The grid's dotted configuration overrides (:func:`nbs_env.config.make_config`): the robot
        options of the command line and what the grid's policies require. The policy's own
        settings are applied on top when the run starts (:func:`policies.config_for`).
    """

    scene: str
    policy: str
    seed: int
    preset: str = "default"
    overrides: dict[str, Any] = field(default_factory=dict)

    @property
    def key(self) -> str:
        return f"{self.scene}|{self.policy}|{self.seed}"

    def config(self):
        """The run's configuration, the policy's own settings aside (raises ConfigError)."""
        from nbs_env.config import make_config

        return make_config(self.preset, scene=self.scene, **self.overrides)


def expand_scenes(text: str, skipped: list[str] | None = None) -> list[str]:
    """``"five_rooms,generated:0-9,suite:unseen"`` → the scene specs; ``generated:A-B`` is a range of
    seeds, ``suite:NAME`` the corpus entries of a suite (:mod:`scenes.corpus`) that can run here.

    ``skipped``: a list that receives the suite entries left out (local-only files absent)."""
    out: list[str] = []
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        if part.startswith("suite:"):
            from scenes import SceneError
            from scenes.corpus import suite

            try:
                present, absent = suite(part[len("suite:") :])
            except SceneError as exc:
                raise CompareError(str(exc)) from None
            out.extend(present)
            if skipped is not None:
                skipped.extend(absent)
        elif part.startswith("generated:") and "-" in part[len("generated:") :]:
            try:
                a, b = parse_range(part[len("generated:") :])
            except ValueError as exc:
                raise CompareError(f"scene range {part!r}: use generated:A-B ({exc})") from None
            out.extend(f"generated:{k}" for k in range(a, b + 1))
        else:
            out.append(part)
    if not out:
        raise CompareError("no scenes given")
    return out


def source_digest(scene: str) -> str | None:
    """The SHA-256 of the file a scene is read from (a path or a corpus entry's file), or None (a
    bundled or generated storey, or no file there): ``--resume`` reuses a run only while its
    building's file is the one it ran on."""
    from scenes.corpus import PREFIX as CORPUS_PREFIX
    from scenes.corpus import corpus_entry

    try:
        if scene.startswith(CORPUS_PREFIX):
            path = corpus_entry(scene[len(CORPUS_PREFIX) :]).path()
        elif scene.startswith("generated:") or not Path(scene).suffix:
            return None
        else:
            path = Path(scene)
        if path is None or not Path(path).is_file():
            return None
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        return digest.hexdigest()
    except Exception:  # an unknown entry, an unreadable file: the run itself will say so
        return None


def policy_digest(policy: str) -> str | None:
    """The SHA-256 of a ``ppo:PATH`` checkpoint's description (which holds its weights' SHA-256), or
    None for any other policy: ``--resume`` reuses a run only while its checkpoint is the same."""
    if not policy.startswith("ppo:"):
        return None
    try:
        from policies.learned import resolve_checkpoint

        path = resolve_checkpoint(policy[len("ppo:") :])
        path = path / "policy.json" if path.is_dir() else path
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except Exception:  # no such checkpoint: the run itself will say so
        return None


def run_one(spec: RunSpec, stop: Callable[[], bool] | None = None) -> dict[str, Any] | None:
    """Play one run; returns ``{"spec", "ok", "metrics" | "error"}`` and never raises.

    ``stop`` (in this process: ``--jobs 1``) is asked between the episode's steps; once it says
    True the run ends unfinished and None is returned: it is no result."""
    started = time.perf_counter()
    source, checkpoint = source_digest(spec.scene), policy_digest(spec.policy)
    try:
        from nbs_env.env import NBSEnv
        from nbs_env.report import metrics_dict
        from policies import config_for, make_policy
        from train.episode import run_episode

        policy = make_policy(spec.policy, spec.seed)
        env = NBSEnv(config_for(spec.config(), policy))
        times = run_episode(env, policy, spec.seed, stop=stop)
        if stop is not None and stop():
            return None
        metrics = metrics_dict(env.storey, spec.scene, policy, spec.seed, times)
        metrics["policy"] = spec.policy
        return {
            "spec": asdict(spec),
            "ok": True,
            "metrics": metrics,
            "wall_s": time.perf_counter() - started,
            "source_sha256": source,
            "policy_sha256": checkpoint,
        }
    except Exception as exc:  # a failed run is recorded, the others go on
        return {
            "spec": asdict(spec),
            "source_sha256": source,
            "policy_sha256": checkpoint,
            "ok": False,
            "error": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
            "wall_s": time.perf_counter() - started,
        }


def _oracle(
    scene: str,
    preset: str = "default",
    overrides: dict[str, Any] | None = None,
    stop: Callable[[], bool] | None = None,
) -> dict[str, Any] | None:
    """The oracle's plan of ``scene`` with the grid's scanner and evaluation (never raises); None
    when ``stop`` said to stop before it was done (nothing to keep: ``--resume`` plans it again)."""
    from policies.oracle import PlanningStoppedError

    setting = {"preset": preset, "overrides": json_form(overrides or {}), "source_sha256": source_digest(scene)}
    try:
        from policies.oracle import oracle_plan
        from scenes import load_scene

        cfg = RunSpec(scene, "oracle", 0, preset, overrides or {}).config()
        plan = oracle_plan(
            load_scene(scene, **cfg.scene_options),
            cfg.robot.scanner,
            spacing=cfg.coverage_spacing,
            radius=cfg.coverage_radius,
            stop=stop,
        )
        return {"scene": scene, **setting, "ok": True, **plan.to_dict()}
    except PlanningStoppedError:
        return None
    except Exception as exc:
        return {"scene": scene, **setting, "ok": False, "error": f"{type(exc).__name__}: {exc}"}


def run_grid(
    specs: Sequence[RunSpec],
    jobs: int = 1,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    finished: dict[str, Any] | None = None,
    on_done: Callable[[str, dict[str, Any]], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """Run every spec, and the oracle of every scene.

    Parameters
    ----------
    specs : sequence of RunSpec
    jobs : int
        Worker processes (local), or CPUs of a local Ray instance.
    backend : {"local", "ray"}
        ``"ray"`` sends each run as a Ray task to ``address`` (a running cluster), or to a local
        instance started here when ``address`` is None.
    finished : dict, optional
        :func:`load_finished`'s records (``"runs"``: RunSpec key → record, ``"oracles"``: scene →
        plan): these are reused, not run again.
    on_done : callable, optional
        ``on_done(kind, record)`` as each run (``"run"``) or oracle (``"oracle"``) finishes, e.g.
        :func:`write_record`, so that a grid that fails later keeps what it computed. Called in
        this process, one record at a time.
    stop : callable, optional
        Asked while the grid runs (:class:`train.stopping.StopRequest`: Ctrl-C, SIGTERM); once it
        says True, the workers are ended (their runs in progress are lost: no result) and
        :class:`GridStoppedError` is raised. With one job, a run in progress ends at its next step, an
        oracle's plan when it is made.

    Returns
    -------
    results : list of dict
        :func:`run_one`'s records, in the order of ``specs``.
    oracles : dict
        Scene → the oracle's plan (``OraclePlan.to_dict()``) or its error.

    Raises
    ------
    GridStoppedError
        ``stop`` said True before every run finished.
    CompareError
        More than one configuration, an unknown backend, or Ray missing.
    WorkerLostError
        A worker process died (the local backend).
    """
    from tqdm import tqdm

    scenes = sorted({s.scene for s in specs})
    settings = {json.dumps([s.preset, s.overrides], sort_keys=True) for s in specs}
    if len(settings) > 1:
        raise CompareError(f"one configuration per grid, got {sorted(settings)}")
    preset, overrides = json.loads(settings.pop()) if settings else ("default", {})
    finished = finished or {}
    old_runs, old_oracles = finished.get("runs", {}), finished.get("oracles", {})
    tasks: list[tuple[str, Any]] = [("run", s) for s in specs] + [("oracle", s) for s in scenes]
    done: dict[int, Any] = {}
    for k, (kind, arg) in enumerate(tasks):
        if kind == "run" and arg.key in old_runs:
            done[k] = old_runs[arg.key]
        elif kind == "oracle" and arg in old_oracles:
            done[k] = old_oracles[arg]
    todo = [(k, task) for k, task in enumerate(tasks) if k not in done]

    def stopping() -> bool:
        return stop is not None and stop()

    def stopped() -> GridStoppedError:
        return GridStoppedError(len(done), len(tasks))

    def finish(k: int, record: dict[str, Any]) -> None:
        done[k] = record
        if on_done is not None:
            on_done(tasks[k][0], record)
        bar.update()

    if backend not in ("local", "ray"):
        raise CompareError(f"unknown backend {backend!r}; backends: local, ray")
    bar = tqdm(total=len(todo), unit="run", disable=not progress, dynamic_ncols=True)
    try:
        if not todo:
            pass
        elif backend == "local" and jobs <= 1:
            for k, (kind, arg) in todo:
                if stopping():
                    raise stopped()
                if kind == "oracle":
                    record = _oracle(arg, preset, overrides, stop)
                else:
                    record = run_one(arg) if stop is None else run_one(arg, stop)
                if record is None:  # the run was cut short: no result
                    raise stopped()
                finish(k, record)
        elif backend == "local":
            _run_local(todo, jobs, preset, overrides, finish, stopping, stopped)
        else:
            _run_ray(todo, jobs, address, preset, overrides, finish, stopping, stopped)
    finally:
        bar.close()
    results = [done[k] for k in range(len(specs))]
    oracles = {scenes[k]: done[len(specs) + k] for k in range(len(scenes))}
    return results, oracles


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """End a pool's worker processes now, their tasks unfinished, and drop the tasks not started.

    ``shutdown`` alone would wait for every task already sent to a worker, a grid's worth."""
    if hasattr(pool, "terminate_workers"):  # Python 3.14: it shuts the executor down too
        pool.terminate_workers()
        return
    # Before 3.14 the executor's processes are only reachable through its private table, which
    # shutdown() empties: read it first.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=10)
        if process.is_alive():
            process.kill()
            process.join()


def _run_local(
    todo: list[tuple[int, tuple[str, Any]]],
    jobs: int,
    preset: str,
    overrides: dict[str, Any],
    finish: Callable[[int, dict[str, Any]], None],
    stopping: Callable[[], bool],
    stopped: Callable[[], GridStoppedError],
) -> None:
    """:func:`run_grid`'s tasks in ``jobs`` worker processes, each result handed to ``finish`` here."""
    from train.stopping import ignore_interrupts, start_resource_tracker

    start_resource_tracker()
    # spawn: forked children would inherit open3d's and OpenBLAS's threads mid-state.
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=ignore_interrupts)
    try:
        futures = {
            (pool.submit(run_one, arg) if kind == "run" else pool.submit(_oracle, arg, preset, overrides)): k
            for k, (kind, arg) in todo
        }
        pending = set(futures)
        while pending:
            # A timeout, not a blocking wait: a signal's handler only sets a flag, looked at here.
            ready, pending = wait(pending, timeout=STOP_POLL_S, return_when=FIRST_COMPLETED)
            for future in ready:  # what finished is kept, stop or not
                try:
                    record = future.result()
                except BrokenProcessPool:
                    if stopping():  # SIGTERM sent to the whole process group ended a worker first
                        raise stopped() from None
                    raise WorkerLostError(
                        "a worker process died (killed, or out of memory?); the runs finished so far are "
                        "kept: rerun with --resume, perhaps with fewer --jobs"
                    ) from None
                finish(futures[future], record)
            if pending and stopping():
                raise stopped()
    except BaseException:
        _end_workers(pool)  # stopped, a record that could not be written, a second Ctrl-C
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_ray(
    todo: list[tuple[int, tuple[str, Any]]],
    jobs: int,
    address: str | None,
    preset: str,
    overrides: dict[str, Any],
    finish: Callable[[int, dict[str, Any]], None],
    stopping: Callable[[], bool],
    stopped: Callable[[], GridStoppedError],
) -> None:
    """:func:`run_grid`'s tasks as Ray tasks, on the cluster at ``address`` or a local instance."""
    try:
        import ray
    except ImportError:
        raise CompareError('the Ray backend needs ray: pip install "nbs-env[cluster]"') from None
    started_here = not ray.is_initialized()
    if started_here:
        from train.ray_connect import connect_ray

        # A cluster already running is joined without local-only arguments; RayConnectionError is a
        # ConfigError: one line, exit 2.
        connect_ray(address, num_cpus=max(1, jobs))
    pending: list[Any] = []
    try:
        run_remote = ray.remote(run_one)
        oracle_remote = ray.remote(_oracle)
        index = {
            (run_remote.remote(arg) if kind == "run" else oracle_remote.remote(arg, preset, overrides)): k
            for k, (kind, arg) in todo
        }
        pending = list(index)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=STOP_POLL_S)
            for ref in ready:  # what finished is kept, stop or not
                finish(index[ref], ray.get(ref))
            if pending and stopping():
                raise stopped()
    except BaseException:
        for ref in pending:  # the tasks not finished: none of them is a result now
            with contextlib.suppress(Exception):  # already finished, or the cluster is gone
                ray.cancel(ref, force=True)
        raise
    finally:
        if started_here:
            ray.shutdown()


# ---------------------------------------------------------------------- the table
def _mean_std(values: Iterable[float]) -> tuple[float, float]:
    v = np.asarray(list(values), dtype=float)
    if not len(v):
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0


def _total_time(m: dict[str, Any]) -> float:
    return float(m["processing_time_s"] + m["acquisition_time_s"] + m["travel_time_s"])


TOTAL_KEYS = ("scans", "time_s", "structure_sensed_pct", "processed_points", "path_length_m",
              "of_oracle_pct", "vs_oracle_scans", "unscanned_rooms", "cap_ended", "no_nvp_first", "earlier_room",
              "rule_ended_pct",
              "abandoned",
              "exterior_doors", "reg_mean_cm", "reg_max_cm", "dense_pct", "incidence_pct", "quality_pct",
              "mean_overlap", "min_overlap", "min_fitness", "refused")  # fmt: skip
#: The room ends (:attr:`nbs_env.storey.Storey.room_ends` reasons) that are a completion rule's: the
#: greedy's ("gain") or the policy's "room done" ("declared"), not the cap's nor "no NVP".
RULE_ENDS = ("gain", "declared")
#: A room counts as one the oracle covers when it sees at least this share (%) of its surface.
COVERABLE_ROOM_PCT = 10.0


def _vanished_at_first_scan(end: dict) -> bool:
    """A room its first scan ended for want of a place to scan from while its measured floor held
    the robot (the candidates vanished); a room whose aisles are narrower than the robot is not."""
    return end["reason"] == "no NVP" and end["scans"] <= 1 and end.get("standing_room", 1) > 0


def _run_quantities(m: dict[str, Any], oracle: dict[str, Any]) -> dict[str, float]:
    """One run's storey totals, and its standing against the scene's oracle when there is one."""
    events = m.get("door_events", [])
    ends = m.get("room_ends", [])
    q = {
        "scans": float(m["scans"]),
        "time_s": _total_time(m),
        "structure_sensed_pct": float(m["structure_sensed_pct"]),
        "processed_points": float(m["processed_points"]),
        "path_length_m": float(m["path_length_m"]),
        "cap_ended": float(sum(1 for e in ends if e["reason"] == "cap")),
        "no_nvp_first": float(sum(1 for e in ends if _vanished_at_first_scan(e))),
        # A "room" beyond a door found inside a room whose RoI already held it: scanned there.
        "earlier_room": float(sum(1 for e in ends if e["reason"] == "earlier room")),
        "abandoned": float(sum(1 for e in events if e["event"] == "abandoned")),
        "exterior_doors": float(sum(1 for e in events if e["event"] == "detected" and e.get("exterior"))),
    }
    if ends:
        # Rooms the completion rule ended: not the per-room scan cap, nor having no NVP left.
        q["rule_ended_pct"] = 100.0 * sum(1 for e in ends if e["reason"] in RULE_ENDS) / len(ends)
    if "registration_error" in m:
        q["reg_mean_cm"] = 100.0 * float(m["registration_error"]["mean_m"])
        q["reg_max_cm"] = 100.0 * float(m["registration_error"]["max_m"])
    quality = m.get("quality") or {}
    for key in ("dense_pct", "incidence_pct", "quality_pct"):
        if quality.get(key) is not None:
            q[key] = float(quality[key])
    registrability = m.get("registrability") or {}
    for key in ("mean_overlap", "min_overlap", "min_fitness"):
        if registrability.get(key) is not None:
            q[key] = 100.0 * float(registrability[key])
    if "refused" in registrability:
        q["refused"] = float(registrability["refused"])
    if oracle.get("ok") and "room_max_pct" in oracle:
        room_max = oracle["room_max_pct"]
        q["unscanned_rooms"] = float(
            sum(1 for r in m["rooms"] if r["scans"] == 0 and room_max.get(str(r["id"]), 0.0) >= COVERABLE_ROOM_PCT)
        )
    # An oracle that senses nothing (a scene with no structural samples counted) is no yardstick.
    if oracle.get("ok") and oracle.get("max_coverage_pct", 0) > 0 and len(oracle.get("coverage_pct", ())):
        q["of_oracle_pct"] = 100.0 * m["structure_sensed_pct"] / oracle["max_coverage_pct"]
        curve = np.asarray(oracle["coverage_pct"])
        # Above the oracle's best (noise can do it), against the oracle's scans to its best.
        reach = np.flatnonzero(curve >= min(m["structure_sensed_pct"], curve[-1]) - 1e-9)
        if len(reach):
            q["vs_oracle_scans"] = m["scans"] / (int(reach[0]) + 1)
    return q


def summarise(results: Sequence[dict[str, Any]], oracles: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows of the table: per (scene, policy) one per true room and one ``total``, plus per policy an
    ``all scenes`` row when there are several scenes. Each quantity is mean and std over seeds; in
    ``all scenes``, the mean over scenes is taken per seed first."""
    rows: list[dict[str, Any]] = []
    scenes = list(dict.fromkeys(r["spec"]["scene"] for r in results))
    policies = list(dict.fromkeys(r["spec"]["policy"] for r in results))
    # Each successful run's storey totals, once, for its scene's row and the "all scenes" row.
    quantities = [
        _run_quantities(r["metrics"], oracles.get(r["spec"]["scene"], {})) if r["ok"] else None for r in results
    ]
    for scene in scenes:
        oracle = oracles.get(scene, {})
        for policy in policies:
            index = [i for i, r in enumerate(results) if r["spec"]["scene"] == scene and r["spec"]["policy"] == policy]
            runs = [results[i] for i in index]
            ok = [r["metrics"] for r in runs if r["ok"]]
            failed = [r for r in runs if not r["ok"]]
            base = {"scene": scene, "policy": policy, "runs": len(runs), "failed": len(failed)}
            if failed:
                base["errors"] = sorted({r["error"] for r in failed})
            if not ok:
                rows.append({**base, "room": "total"})
                continue
            for k, room in enumerate(ok[0]["rooms"]):
                per = [m["rooms"][k] for m in ok]
                row = {**base, "room": room["name"]}
                row["not_scanned"] = sum(1 for p in per if p["scans"] == 0)
                for key, values in (
                    ("scans", [p["scans"] for p in per]),
                    ("structure_sensed_pct", [p["structure_sensed_pct"] for p in per]),
                    ("processed_points", [p["processed_points"] for p in per]),
                    ("path_length_m", [p["path_length_m"] for p in per]),
                ):
                    row[key] = _mean_std(values)
                rows.append(row)
            row = {**base, "room": "total"}
            row["abandon_reasons"] = sorted(
                {e["reason"] for m in ok for e in m.get("door_events", []) if e["event"] == "abandoned"}
            )
            row["complete"] = sum(1 for m in ok if m["complete"])
            row["not_scanned"] = sum(sum(1 for p in m["rooms"] if p["scans"] == 0) for m in ok)
            per_run = [quantities[i] for i in index if quantities[i] is not None]
            for key in TOTAL_KEYS:
                values = [q[key] for q in per_run if key in q]
                if values:
                    row[key] = _mean_std(values)
            if oracle.get("ok"):
                row["oracle_max_pct"] = oracle["max_coverage_pct"]
            rows.append(row)
    if len(scenes) > 1:
        for policy in policies:
            totals = [r for r in rows if r["policy"] == policy and r["room"] == "total"]
            row = {"scene": "all scenes", "policy": policy, "room": "total", "runs": sum(r["runs"] for r in totals)}
            row["failed"] = sum(r["failed"] for r in totals)
            # Mean over scenes per seed, then mean ± std of those over seeds: the spread a rerun
            # with other seeds would show, not the (much larger) spread between storeys.
            by_seed: dict[int, list[dict[str, float]]] = {}
            for r, q in zip(results, quantities, strict=True):
                if r["spec"]["policy"] == policy and q is not None:
                    by_seed.setdefault(r["spec"]["seed"], []).append(q)
            for key in TOTAL_KEYS:
                per_seed = [[q[key] for q in qs if key in q] for qs in by_seed.values()]
                means = [float(np.mean(v)) for v in per_seed if v]
                if means:
                    row[key] = _mean_std(means)
            row["complete"] = sum(r.get("complete", 0) for r in totals)
            row["not_scanned"] = sum(r.get("not_scanned", 0) for r in totals)
            rows.append(row)
    return rows


def _cell(value: Any, fmt: str) -> str:
    if value is None or (isinstance(value, tuple) and math.isnan(value[0])):
        return "–"
    mean, std = value
    return f"{fmt.format(mean)} ± {fmt.format(std)}"


def _md_row(cells: Sequence[Any]) -> str:
    """A Markdown table row: a ``|`` in a cell (a legal file or room name) is escaped, a line break
    is a space; written raw, they split the row into more cells than the header has."""
    return "| " + " | ".join(" ".join(str(c).split("\n")).replace("|", "\\|") for c in cells) + " |"


def _markdown(rows: list[dict[str, Any]]) -> str:
    head = ["scene", "policy", "room", *[h for _, h, _ in QUANTITIES], "% of oracle max", "scans ÷ oracle's", "notes"]
    lines = [_md_row(head), "|" + "---|" * len(head)]
    for r in rows:
        notes = []
        if r.get("failed"):
            notes.append(f"{r['failed']} of {r['runs']} runs failed")
        if r.get("not_scanned"):
            notes.append("room not scanned in " if r["room"] != "total" else "rooms not scanned: ")
            notes[-1] += f"{r['not_scanned']} run(s)" if r["room"] != "total" else str(r["not_scanned"])
        if r["room"] == "total" and "complete" in r:
            notes.append(f"complete {r['complete']}/{r['runs'] - r.get('failed', 0)}")
        cells = [r["scene"], r["policy"], r["room"]]
        cells += [_cell(r.get(key), fmt) for key, _, fmt in QUANTITIES]
        cells += [_cell(r.get("of_oracle_pct"), "{:.1f}"), _cell(r.get("vs_oracle_scans"), "{:.2f}")]
        cells.append("; ".join(notes))
        lines.append(_md_row(cells))
    return "\n".join(lines) + "\n"


def _storeys_markdown(rows: list[dict[str, Any]]) -> str:
    """One line per scene and policy: the figures the corpus is judged by (mean ± std over seeds)."""
    head = ["scene", "policy", "scans", "SE sensed (%)", "% of oracle max", "scans ÷ oracle's",
            "rooms unscanned", "rooms ended by cap", "no NVP after one scan", "in an earlier room",
            "rooms ended by rule (%)",
            "doors abandoned", "exterior doors",
            "path (m)",
            "reg. error mean / max (cm)", "notes"]  # fmt: skip
    lines = [_md_row(head), "|" + "---|" * len(head)]
    for r in rows:
        if r["room"] != "total" or r["scene"] == "all scenes":
            continue
        notes = []
        if r.get("failed"):
            notes.append(f"{r['failed']} of {r['runs']} runs failed: {'; '.join(r.get('errors', []))}")
        if r.get("abandon_reasons"):
            notes.append("abandoned: " + "; ".join(r["abandon_reasons"]))
        reg = r.get("reg_mean_cm"), r.get("reg_max_cm")
        cells = [
            r["scene"],
            r["policy"],
            _cell(r.get("scans"), "{:.1f}"),
            _cell(r.get("structure_sensed_pct"), "{:.1f}"),
        ]
        cells += [_cell(r.get("of_oracle_pct"), "{:.1f}"), _cell(r.get("vs_oracle_scans"), "{:.2f}")]
        ends = ("unscanned_rooms", "cap_ended", "no_nvp_first", "earlier_room", "rule_ended_pct")
        cells += [_cell(r.get(k), "{:.1f}") for k in ends]
        cells += [_cell(r.get(k), "{:.1f}") for k in ("abandoned", "exterior_doors")]
        cells.append(_cell(r.get("path_length_m"), "{:.1f}"))
        cells.append(" / ".join(_cell(v, "{:.1f}") for v in reg))
        cells.append("; ".join(notes))
        lines.append(_md_row(cells))
    return "\n".join(lines) + "\n"


def _quality_markdown(rows: list[dict[str, Any]], thresholds: dict[str, float] | None) -> str:
    """One line per scene and policy: the scan-quality figures (mean ± std over seeds)."""
    head = ["scene", "policy", "scans", "SE sensed (%)", "dense (%)", "square (%)", "both (%)",
            "overlap mean / min (%)", "ICP fitness min (%)", "poses refused"]  # fmt: skip
    lines = []
    if thresholds:
        lines += [
            f"dense: at least {thresholds['min_density_per_m2']:g} points per m² around the sample "
            f"(within {thresholds['density_radius_m']:g} m); square: seen at least once at an incidence of at most "
            f"{thresholds['max_incidence_deg']:g}°; overlap: the share of each scan the cloud before it explains.",
            "",
        ]
    lines += [_md_row(head), "|" + "---|" * len(head)]
    for r in rows:
        if r["room"] != "total":
            continue
        cells = [
            r["scene"],
            r["policy"],
            _cell(r.get("scans"), "{:.1f}"),
            _cell(r.get("structure_sensed_pct"), "{:.1f}"),
        ]
        cells += [_cell(r.get(k), "{:.1f}") for k in ("dense_pct", "incidence_pct", "quality_pct")]
        cells.append(" / ".join(_cell(r.get(k), "{:.0f}") for k in ("mean_overlap", "min_overlap")))
        cells += [_cell(r.get("min_fitness"), "{:.0f}"), _cell(r.get("refused"), "{:.1f}")]
        lines.append(_md_row(cells))
    return "\n".join(lines) + "\n"


def _methods_markdown(results: Sequence[dict[str, Any]], oracles: dict[str, dict[str, Any]]) -> str:
    """One line per policy over every scene and seed: how its rooms ended (its own rule, the
    per-room cap, no NVP left) and what it left, the figures a fair comparison is judged by."""
    head = ["policy", "runs", "rooms ended", "by its rule (%)", "by the cap", "no NVP left",
            "no NVP after one scan", "rooms unscanned", "scans / storey", "SE sensed (%)", "% of oracle max",
            "path (m) / storey"]  # fmt: skip
    lines = [_md_row(head), "|" + "---|" * len(head)]
    for policy in dict.fromkeys(r["spec"]["policy"] for r in results):
        runs = [r for r in results if r["spec"]["policy"] == policy and r["ok"]]
        if not runs:
            continue
        ends = [e for r in runs for e in r["metrics"].get("room_ends", [])]
        qs = [_run_quantities(r["metrics"], oracles.get(r["spec"]["scene"], {})) for r in runs]
        rule = sum(1 for e in ends if e["reason"] in RULE_ENDS)
        cap = sum(1 for e in ends if e["reason"] == "cap")
        first = sum(1 for e in ends if _vanished_at_first_scan(e))

        def mean(key: str, qs=qs) -> str:
            v = [q[key] for q in qs if key in q]
            return f"{np.mean(v):.1f}" if v else "–"

        cells = [policy, str(len(runs)), str(len(ends)), f"{100.0 * rule / max(1, len(ends)):.1f}",
                 str(cap), str(len(ends) - rule - cap), str(first),
                 str(int(sum(q.get("unscanned_rooms", 0) for q in qs))),
                 mean("scans"), mean("structure_sensed_pct"), mean("of_oracle_pct"), mean("path_length_m")]  # fmt: skip
        lines.append(_md_row(cells))
    return "\n".join(lines) + "\n"


def _csv(rows: list[dict[str, Any]], path: Path) -> None:
    keys = [k for k, _, _ in QUANTITIES] + ["of_oracle_pct", "vs_oracle_scans"]
    fields = ["scene", "policy", "room", "runs", "failed", "complete", "not_scanned"]
    fields += [f"{k}_{s}" for k in keys for s in ("mean", "std")]
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=fields)
    writer.writeheader()
    for r in rows:
        out = {k: r.get(k, "") for k in fields[:7]}
        for k in keys:
            mean, std = r.get(k, ("", ""))
            out[f"{k}_mean"], out[f"{k}_std"] = mean, std
        writer.writerow(out)
    _write_own(path, text.getvalue())


def _plots(results: list[dict[str, Any]], oracles: dict[str, dict[str, Any]], out: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = [r for r in results if r["ok"]]
    policies = list(dict.fromkeys(r["spec"]["policy"] for r in results))
    fig = Figure(figsize=(8, 5), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for policy in policies:
        curves = [
            [s["structure_sensed_pct"] for s in r["metrics"]["steps"]] for r in ok if r["spec"]["policy"] == policy
        ]
        if not curves:
            continue
        n = max(len(c) for c in curves)
        padded = np.array([c + [c[-1]] * (n - len(c)) for c in curves])  # a finished run keeps its coverage
        x = np.arange(1, n + 1)
        mean = padded.mean(axis=0)
        (line,) = ax.plot(x, mean, label=f"{policy} ({len(curves)} runs)")
        ax.fill_between(x, padded.min(axis=0), padded.max(axis=0), color=line.get_color(), alpha=0.15)
    curves = [o["coverage_pct"] for o in oracles.values() if o.get("ok") and o["coverage_pct"]]
    if curves:
        n = max(len(c) for c in curves)
        padded = np.array([c + [c[-1]] * (n - len(c)) for c in curves])
        ax.plot(np.arange(1, n + 1), padded.mean(axis=0), "k--", label="oracle (ground truth, set cover)")
    ax.set_xlabel("scan")
    ax.set_ylabel("structural surface sensed (%)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    _legend(ax)
    ax.set_title("Coverage against scans (mean over runs; band: min to max)")
    _save(fig, out / "coverage_vs_scans.png")
    _quality_plot(ok, policies, out)

    fig = Figure(figsize=(9, 4), dpi=110)
    FigureCanvasAgg(fig)
    for k, (key, label) in enumerate((("path_length_m", "path length (m)"), ("time", "total time (s)"))):
        ax = fig.add_subplot(1, 2, k + 1)
        means, stds = [], []
        for policy in policies:
            ms = [r["metrics"] for r in ok if r["spec"]["policy"] == policy]
            vals = [m["path_length_m"] if key == "path_length_m" else _total_time(m) for m in ms]
            means.append(np.mean(vals) if vals else 0.0)
            stds.append(np.std(vals) if vals else 0.0)
        ax.bar(range(len(policies)), means, yerr=stds, color="#4c72b0", capsize=3)
        ax.set_xticks(range(len(policies)), policies, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle("Path length and time per run (mean ± std)")
    fig.tight_layout()
    _save(fig, out / "path_time.png")


def _legend(ax: Any) -> None:
    """The plot's legend, when it has a labelled curve (none when every run failed: matplotlib warns)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="lower right")


def _write_own(path: Path, text: str) -> None:
    """Write one of the folder's files whole or not at all (:mod:`nbs_env.atomic`). The folder is the
    grid's own: a link found in a file's place is replaced by the file, never written through (to a
    file outside ``--out``)."""
    _write_text(path, text, follow_links=False)


def _save(fig: Any, path: Path) -> None:
    """Save a figure whole or not at all (:func:`nbs_env.atomic.replacing`); a link there is replaced."""
    with replacing(path, follow_links=False) as temporary:
        fig.savefig(temporary)


def _padded(curves: list[list[float]]) -> np.ndarray:
    """(runs, n) the curves, each held at its last value up to the longest: a finished run keeps it."""
    n = max(len(c) for c in curves)
    return np.array([c + [c[-1]] * (n - len(c)) for c in curves], dtype=float)


def _quality_plot(ok: list[dict[str, Any]], policies: list[str], out: Path) -> None:
    """``quality_vs_scans.png``: per policy, the coverage at the density threshold and at the
    incidence threshold against scans, beside the plain coverage (dotted)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    thresholds = next((r["metrics"]["quality"] for r in ok if "quality" in r["metrics"]), None)
    fig = Figure(figsize=(11, 4.5), dpi=110)
    FigureCanvasAgg(fig)
    panels = (
        ("dense_pct", f"at least {thresholds['min_density_per_m2']:g} points per m²" if thresholds else "dense"),
        (
            "incidence_pct",
            f"seen at an incidence of at most {thresholds['max_incidence_deg']:g}°" if thresholds else "",
        ),
    )
    for k, (key, title) in enumerate(panels):
        ax = fig.add_subplot(1, 2, k + 1)
        for policy in policies:
            runs = [r["metrics"]["steps"] for r in ok if r["spec"]["policy"] == policy]
            runs = [steps for steps in runs if steps and steps[0].get(key) is not None]
            if not runs:
                continue
            x = np.arange(1, max(len(s) for s in runs) + 1)
            quality = _padded([[s[key] for s in steps] for steps in runs])
            coverage = _padded([[s["structure_sensed_pct"] for s in steps] for steps in runs])
            (line,) = ax.plot(x, quality.mean(axis=0), label=f"{policy} ({len(runs)} runs)")
            ax.fill_between(x, quality.min(axis=0), quality.max(axis=0), color=line.get_color(), alpha=0.15)
            ax.plot(x, coverage.mean(axis=0), ":", color=line.get_color(), linewidth=1)
        ax.set_xlabel("scan")
        ax.set_ylabel("structural surface (%)")
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
        ax.set_title(title, fontsize=9)
        if k == 0:
            _legend(ax)
    fig.suptitle("Coverage meeting the quality thresholds against scans (dotted: all coverage)")
    fig.tight_layout()
    _save(fig, out / "quality_vs_scans.png")


def write_outputs(
    results: list[dict[str, Any]], oracles: dict[str, dict[str, Any]], out: str | Path
) -> list[dict[str, Any]]:
    """Write the runs' metrics, ``table.csv``, ``table.md`` and the two plots; returns the rows.

    The runs and the oracles are written first. Should the summary or the plots fail, what they
    could not write is replaced by ``summary_error.txt`` and :class:`CompareError` says so: the runs
    stay, and ``--resume`` reuses them. Every file is written whole or not at all
    (:mod:`nbs_env.atomic`); one that cannot be (a full disk) raises its ``OSError``, naming it.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for r in results:
        write_record(out, "run", r)
    _write_own(out / "oracle.json", json.dumps(oracles, indent=1))
    try:
        rows = summarise(results, oracles)
        _csv(rows, out / "table.csv")
        _write_own(out / "table.md", _markdown(rows))
        _write_own(out / "storeys.md", _storeys_markdown(rows))
        _write_own(out / "methods.md", _methods_markdown(results, oracles))
        thresholds = next((r["metrics"].get("quality") for r in results if r["ok"] and "quality" in r["metrics"]), None)
        _write_own(out / "quality.md", _quality_markdown(rows, thresholds))
        _plots(results, oracles, out)
    except OSError:
        raise  # a file that could not be written (a full disk): its own message names it
    except Exception as exc:  # the runs are on disk; say what failed and where they are
        _write_own(out / "summary_error.txt", f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}")
        bad = _culprits(results, out)
        if bad:  # --resume runs these again (load_finished refuses them) and reuses the others
            named = "; ".join(f"{path}: {reason}" for path, reason in bad[:3])
            more = f" (and {len(bad) - 3} more)" if len(bad) > 3 else ""
            advice = f"{named}{more}; rerun with --resume to run {'it' if len(bad) == 1 else 'them'} again"
        else:
            advice = "rerun with --resume to reuse the runs"
        raise CompareError(
            f"the runs are in {out}/runs, but the summary failed ({type(exc).__name__}: {exc}); "
            f"see {out / 'summary_error.txt'}; {advice}"
        ) from exc
    (out / "summary_error.txt").unlink(missing_ok=True)
    return rows


#: The files a run writes into its folder (:func:`write_record`).
_RUN_FILES = ("run.json", "metrics.json", "error.txt")
#: The files a comparison writes at the top of its folder.
_TOP_FILES = (
    "oracle.json", "table.md", "table.csv", "methods.md", "quality.md", "storeys.md", "summary_error.txt",
    "coverage_vs_scans.png", "quality_vs_scans.png", "path_time.png",
)  # fmt: skip


def _within_folder(path: Path, folder: Path) -> bool:
    """Whether ``path`` lies inside ``folder``, as the file system finds both (links resolved)."""
    from train.outputs import _where

    return _where(path).is_relative_to(_where(folder))


def check_out_dir(out: str | Path, *, keep: bool = False, specs: Sequence[RunSpec] = ()) -> Path:
    """``out`` as a folder this process can write into (created if missing), before any run starts.

    Parameters
    ----------
    out : str or Path
    keep : bool
        What an earlier grid left there may stay (``--resume`` reuses it, ``--force`` writes over
        it); else a folder that is not empty is refused.
    specs : sequence of RunSpec, optional
        The runs the grid will record: where one's folder, or a folder above it, is a file, the grid
        is refused before it runs (found when the run was written, it cost the run).

    Raises
    ------
    CompareError
        ``out`` is a file, its folder does not exist, it cannot be created or written, or it is not
        empty and ``keep`` is False (:func:`train.outputs.check_outputs`); or a file or folder in
        it is a symbolic link (the grid would read and write through it).
    """
    from train.outputs import SCAN_REPORT, TRAINING_RUN, Output, OutputError, check_outputs, odd_entry

    out = Path(out)
    replace = None if keep else "pass --resume to continue that comparison, or --force to write over it"
    # A scene file among what the grid writes (an oracle.json plan in --out) was written over.
    reads = [("--scenes", Path(s.scene)) for s in specs if Path(s.scene).suffix]
    inside = next((p for _, p in reads if _within_folder(p, out / "runs")), None)
    if inside is not None:
        raise CompareError(
            f"--out {out}: its runs/ holds --scenes {inside}, which the grid writes over: choose another --out"
        )
    try:
        others = SCAN_REPORT + TRAINING_RUN
        check_outputs([Output("--out", out, "folder", replace=replace, files=_TOP_FILES, others=others)], reads=reads)
        out.mkdir(exist_ok=True)
    except OutputError as exc:
        raise CompareError(str(exc)) from None
    except OSError as exc:
        raise CompareError(f"--out {out}: cannot create it ({exc.strerror or exc})") from None
    # What the grid writes at the top of the folder must be of its kind: found after the first run,
    # a file named runs would cost that run.
    for name, folder in (("runs", True), ("oracle.json", False), ("table.md", False), ("table.csv", False)):
        path = out / name
        if path.exists() and path.is_dir() != folder:
            what = "is not a folder" if folder else "is a folder"
            raise CompareError(f"--out {out}: {path} {what}; move it away or choose another --out")
    # Every file under the folder is the grid's own: a link there (to a file outside it) would be
    # read as a finished run and written through, overwriting what it points to.
    odd = odd_entry(out)
    if odd is None:  # a folder where a run writes a file: found after the run, it would cost the run
        runs = out / "runs"
        odd = (
            next(((p, "a folder") for p in sorted(runs.rglob("*")) if p.name in _RUN_FILES and p.is_dir()), None)
            if runs.is_dir()
            else None
        )
    if odd is not None:
        path, what = odd
        raise CompareError(
            f"--out {out}: {path} is {what}; the comparison's files must be its own: "
            "replace it by the file or remove it, or choose another --out"
        )
    in_the_way = _file_in_the_way(out, specs)
    if in_the_way is not None:
        path, spec = in_the_way
        raise CompareError(
            f"--out {out}: {path} is a file where the folder of the run of scene {spec.scene!r}, policy "
            f"{spec.policy!r}, seed {spec.seed} goes; move it away or choose another --out"
        )
    return out


def _refuse_shared_folders(specs: Sequence[RunSpec]) -> None:
    """Two runs of a grid whose records would share a folder would overwrite each other's."""
    seen: dict[Path, RunSpec] = {}
    for spec in specs:
        folder = _run_folder(Path(), asdict(spec)).parent
        other = seen.setdefault(folder, spec)
        if (other.scene, other.policy) != (spec.scene, spec.policy):
            raise CompareError(
                f"the runs of scene {other.scene!r}, policy {other.policy!r} and of scene {spec.scene!r}, policy "
                f"{spec.policy!r} would keep their records in one folder ({folder}); rename one of them"
            )


def _file_in_the_way(out: Path, specs: Sequence[RunSpec]) -> tuple[Path, RunSpec] | None:
    """The first file (not a folder) found where a run's folder, or a folder above it, goes."""
    checked: set[Path] = set()
    for spec in specs:
        folder = _run_folder(out, asdict(spec))
        for path in reversed([folder, *folder.parents[: len(folder.relative_to(out).parts) - 1]]):
            if path in checked:
                continue
            checked.add(path)
            if path.exists() and not path.is_dir():
                return path, spec
    return None


def write_record(out: str | Path, kind: str, record: dict[str, Any]) -> None:
    """Write one finished run (its ``run.json`` and ``metrics.json`` or ``error.txt``) or fold one
    oracle into ``oracle.json``, as :func:`run_grid` reports them.

    Each file is written whole or not at all (:mod:`nbs_env.atomic`), and ``run.json`` last: a run
    whose ``run.json`` is there is all there, whatever stopped the grid (:func:`load_finished`).
    """
    out = Path(out)
    if kind == "oracle":
        path = out / "oracle.json"
        try:
            if path.is_symlink():  # not the folder's own: replaced, never read or written through
                raise ValueError(path)
            stored = read_json_file(path)
        except (OSError, ValueError):
            stored = {}
        if not isinstance(stored, dict):  # a file damaged or edited into something else: start it afresh
            stored = {}
        stored[record["scene"]] = record
        _write_own(path, json.dumps(stored, indent=1))
        return
    folder = _run_folder(out, record["spec"])
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.json").unlink(missing_ok=True)  # until the new run's files are all written
    if record["ok"]:
        _write_own(folder / "metrics.json", json.dumps(record["metrics"], indent=1))
        (folder / "error.txt").unlink(missing_ok=True)  # an earlier failure of the same run
    else:
        _write_own(folder / "error.txt", record["error"] + "\n\n" + record.get("traceback", ""))
        (folder / "metrics.json").unlink(missing_ok=True)
    _write_own(folder / "run.json", json.dumps({k: v for k, v in record.items() if k != "metrics"}, indent=1))


def folder_name(name: str) -> str:
    """A scene's or policy's folder under ``OUT/runs``: one path component, whatever the name holds.

    ``ppo:PATH`` names a checkpoint by its path, which may hold ``/`` or ``..``: kept as they are,
    a run's files would land in nested folders or outside ``OUT``. Characters other than letters,
    digits, ``.``, ``_`` and ``-`` become ``_``, and a name so changed gets a short hash of itself,
    so that two names never share a folder (``ppo:a/b`` and ``ppo:a_b``). Plain names keep their
    folders (``greedy``, ``ppo_reference``, ``generated_7``); a name with a second ``:`` is changed
    (``ppo:ck_x:y`` and ``ppo:ck_x_y`` shared a folder, and each run overwrote the other's records).
    A name of more than 100 characters keeps its last 100 and the hash.
    """
    plain = name.replace(":", "_")
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", plain)
    if safe == plain and safe not in (".", "..") and name.count(":") <= 1 and len(safe) <= _MAX_FOLDER:
        return safe
    # A long path (each part within the system's 255 bytes) made one part of 300: its end, which
    # names the file, is kept, and the hash keeps the names apart.
    kept = safe if len(safe) <= _MAX_FOLDER else safe[-_MAX_FOLDER:]
    return f"{kept.strip('.')}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"


#: The longest scene or policy folder name kept whole (a file system's part is at most 255 bytes).
_MAX_FOLDER = 100


def _run_folder(out: Path, spec: dict[str, Any]) -> Path:
    return out / "runs" / folder_name(spec["scene"]) / folder_name(spec["policy"]) / f"seed{spec['seed']}"


def load_finished(out: str | Path, specs: Sequence[RunSpec]) -> dict[str, Any]:
    """The successful runs and oracles an earlier ``nbs compare --out OUT`` left, for ``--resume``.

    A run is reused when its ``run.json`` holds the same spec (scene, policy name, seed, preset and
    configuration overrides) and its ``metrics.json`` is a record the table can be made of
    (:func:`record_problem`); an oracle when ``oracle.json`` has it for the same preset and
    overrides, and while the scene's file (:func:`source_digest`) and a ``ppo:PATH`` checkpoint
    (:func:`policy_digest`) are those it ran on. Failed runs are run again, and so are damaged
    records and runs of a file or checkpoint changed since: each of the last two is named on
    stderr with the reason, in one line.
    """
    out = Path(out)
    runs: dict[str, Any] = {}
    paths: dict[str, Path] = {}
    digests = {scene: source_digest(scene) for scene in dict.fromkeys(s.scene for s in specs)}
    checkpoints = {policy: policy_digest(policy) for policy in dict.fromkeys(s.policy for s in specs)}

    def damaged(path: Path, reason: str) -> None:
        print(f"nbs compare: {path}: {reason}; running it again", file=sys.stderr)

    _check_same_comparison(out, specs)
    for spec in specs:
        folder = _run_folder(out, asdict(spec))
        try:
            record = read_json_file(folder / "run.json")
        except (OSError, UnicodeDecodeError):  # not there (not finished), or not a file: writing it says so
            continue
        except ValueError as exc:
            damaged(folder / "run.json", f"not JSON ({exc})")
            continue
        if not isinstance(record, dict):
            damaged(folder / "run.json", f"holds {_shown(record)}, not a run's record")
            continue
        # An edited building file is another building; a retrained checkpoint another policy.
        same_file = record.get("source_sha256") == digests[spec.scene]
        same_file &= record.get("policy_sha256") == checkpoints[spec.policy]
        stored = record.get("spec")
        identity = {"scene": spec.scene, "policy": spec.policy, "seed": spec.seed}
        # Typed: false and 0.0 equal a seed of 0 in Python, not in the record's JSON.
        if isinstance(stored, dict) and any(not same_json(stored.get(k), v) for k, v in identity.items()):
            other = ", ".join(f"{k} {_shown(stored.get(k))}" for k in identity)
            damaged(folder / "run.json", f"it is the record of {other}, not of the run whose folder it is in")
            continue
        problem = _run_record_problem(record)
        if problem is not None:
            damaged(folder / "run.json", problem)
            continue
        wanted = json_form(asdict(spec))
        if not (record.get("ok") is True and isinstance(stored, dict) and same_spec(stored, wanted)):
            continue  # a failed run: run it again
        if not same_file:
            # Another building or another policy: its result is replaced, which the user is told.
            changed = "scene file" if record.get("source_sha256") != digests[spec.scene] else "checkpoint"
            print(
                f"nbs compare: {folder}: its {changed} changed since it ran; running it again (its result is replaced)",
                file=sys.stderr,
            )
            continue
        path = folder / "metrics.json"
        try:
            finished = {**record, "metrics": read_json_file(path)}
        except FileNotFoundError:
            damaged(path, "missing")
            continue
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            damaged(path, f"cannot be read ({type(exc).__name__}: {exc})")
            continue
        problem = record_problem(finished)
        if problem is not None:
            damaged(path, problem)
            continue
        runs[spec.key], paths[spec.key] = finished, path
    for key, problem in _odd_rooms(runs).items():
        damaged(paths[key], problem)
        del runs[key]
    oracles: dict[str, Any] = {}
    try:
        stored = read_json_file(out / "oracle.json")
    except (OSError, ValueError):
        stored = {}
    for scene, plan in stored.items() if isinstance(stored, dict) else ():
        if (
            isinstance(plan, dict)
            and plan.get("ok") is True  # (1 and "no" are true in Python: a record's own word)
            and plan.get("scene") == scene
            and _oracle_matches(scene, plan, specs)
            and plan.get("source_sha256") == digests.get(scene)
            and _oracle_usable(plan)
        ):
            oracles[scene] = plan
    return {"runs": runs, "oracles": oracles}


# ---------------------------------------------------------------------- a run's record, checked
#: No figure of a run (scans, points, metres, seconds) comes near this: the table's means and
#: spreads of larger ones overflow (a hand-edited 1e308).
MAX_FIGURE = 1e15


class _BadRecordError(ValueError):
    """Why a run's ``metrics.json`` cannot go into the table (:func:`record_problem`)."""


def _spelled_otherwise(stored: dict[str, Any], specs: Sequence[RunSpec]) -> RunSpec | None:
    """The spec of ``specs`` that names the run ``stored`` records under another spelling (the
    identities :func:`_refuse_repeats` compares), or None."""
    from policies import make_policy

    def identity(scene: str, policy: str, seed: Any) -> Any:
        made = None if policy.startswith("ppo:") else make_policy(policy, 0)
        return (_scene_identity(scene), _policy_identity(policy, made), seed)

    try:
        theirs = identity(str(stored["scene"]), str(stored["policy"]), stored["seed"])
        return next((s for s in specs if identity(s.scene, s.policy, s.seed) == theirs), None)
    except Exception:  # a record naming no policy this version makes: left out, as before
        return None


def _check_same_comparison(out: Path, specs: Sequence[RunSpec]) -> None:
    """``--resume`` continues one comparison: every finished run in ``out`` must be one this grid
    names, with its settings, and every oracle of ``oracle.json`` of its settings; else the tables,
    the oracles and the runs of the earlier comparison would be rewritten without them, unasked.

    Raises
    ------
    CompareError
        Naming a run or an oracle of other settings, or runs this grid leaves out.
    """
    wanted = {s.key: json_form(asdict(s)) for s in specs}
    left_out: list[str] = []
    for path in sorted((out / "runs").glob("*/*/*/run.json")):
        try:
            record = read_json_file(path)
        except (OSError, ValueError):
            continue  # a damaged record: the run is named and run again, if this grid has it
        stored = record.get("spec") if isinstance(record, dict) else None
        if not (isinstance(stored, dict) and record.get("ok") is True):
            continue
        try:
            key = RunSpec(stored["scene"], stored["policy"], stored["seed"]).key
        except (KeyError, TypeError):
            continue
        if type(stored["seed"]) is not int or path.parent.name != f"seed{stored['seed']}":
            continue  # not its folder's run (false and 0.0 equal 0 in Python): load_finished names it, runs it again
        if key not in wanted:
            spelled = _spelled_otherwise(stored, specs)
            if spelled is not None:  # ppo:./run for ppo:run, generated:01 for generated:1
                raise CompareError(
                    f"{path.parent}: holds the run of scene {stored['scene']!r}, policy {stored['policy']!r}, which "
                    f"this comparison names scene {spelled.scene!r}, policy {spelled.policy!r}: --resume reuses "
                    "runs by name, so spell them as the earlier comparison did"
                )
            left_out.append(f"scene {stored['scene']!r}, policy {stored['policy']!r}, seed {stored['seed']}")
        elif not same_spec(stored, wanted[key]):
            theirs, mine = _settings_apart(stored, wanted[key])
            raise CompareError(
                f"{path.parent}: holds a finished run with {theirs}, where this comparison has {mine}; "
                "--resume continues a comparison with its own options: give them, or pass --force to replace "
                "its runs, or choose another --out"
            )
    if left_out:
        more = f" and {len(left_out) - 1} more" if len(left_out) > 1 else ""
        raise CompareError(
            f"--out {out} holds runs this comparison leaves out ({left_out[0]}{more}): --resume continues a "
            "comparison, and its tables would drop them; name them too, pass --force to start over, or choose "
            "another --out"
        )
    try:
        stored_oracles = read_json_file(out / "oracle.json")
    except (OSError, ValueError):
        return
    for scene, plan in stored_oracles.items() if isinstance(stored_oracles, dict) else ():
        if not (isinstance(plan, dict) and plan.get("ok")):
            continue
        if not _oracle_matches(scene, plan, specs):
            theirs, ours = _settings_apart(
                {"preset": plan.get("preset"), "overrides": plan.get("overrides")},
                {"preset": specs[0].preset, "overrides": json_form(specs[0].overrides)},
            )
            raise CompareError(
                f"{out / 'oracle.json'}: holds the oracle of {scene!r} with {theirs}, where this comparison has "
                f"{ours}; give the comparison's own options, pass --force, or choose another --out"
            )


class _Unset:
    """An override one spec has and the other not (the preset's value), as a message shows it."""

    def __repr__(self) -> str:
        return "not given"


_UNSET = _Unset()


def _oracle_matches(scene: str, plan: dict[str, Any], specs: Sequence[RunSpec]) -> bool:
    """Whether a recorded oracle of ``scene`` was planned with settings of this grid (the same
    configuration, as :func:`same_spec` tells)."""
    stored = {"scene": scene, "policy": "oracle", "seed": 0, "preset": plan.get("preset")}
    stored["overrides"] = plan.get("overrides")
    settings = {json.dumps([s.preset, json_form(s.overrides)], sort_keys=True): s for s in specs}
    wanted = [{**stored, "preset": s.preset, "overrides": json_form(s.overrides)} for s in settings.values()]
    return any(same_spec(stored, w) for w in wanted)


def same_spec(stored: dict[str, Any], wanted: dict[str, Any]) -> bool:
    """Whether a recorded run spec is the run ``wanted`` describes: the same scene, policy and seed,
    and options that make the same configuration (``--preset fast --resolution 1`` is fast's own
    step: the same run as ``--preset fast``).

    Parameters
    ----------
    stored, wanted : dict
        ``RunSpec`` as JSON reads it (``json_form(asdict(spec))``); ``stored`` from a record.
    """
    if same_json(stored, wanted):
        return True
    if any(stored.get(k) != wanted.get(k) for k in ("scene", "policy", "seed")) or set(stored) != set(wanted):
        return False
    if any(v == wanted.get(k) and not same_json(v, wanted.get(k)) for k, v in stored.items()):
        return False  # true for 1, 1.0 for 1: equal in Python, another value in the record
    try:
        return RunSpec(**stored).config().to_dict() == RunSpec(**wanted).config().to_dict()
    except (ConfigError, TypeError):  # a record this version cannot build: not this run
        return False


def _settings_apart(stored: dict[str, Any], wanted: dict[str, Any]) -> tuple[str, str]:
    """The settings two run specs differ in (scene, policy, seed, preset, each override), as each
    has them."""
    apart: list[tuple[str, Any, Any]] = []
    for key in ("scene", "policy", "seed"):  # a record edited by hand: "seed": "0"
        if key in stored and stored.get(key) != wanted.get(key):
            apart.append((key, stored.get(key), wanted.get(key)))
    if stored.get("preset") != wanted.get("preset"):
        apart.append(("preset", stored.get("preset"), wanted.get("preset")))
    old, new = stored.get("overrides"), wanted.get("overrides")
    _apart(old if isinstance(old, dict) else {}, new if isinstance(new, dict) else {}, "", apart)
    if not apart:
        return "other settings", "its own"
    return (
        ", ".join(f"{k} {_shown(a)}" for k, a, _ in apart[:4]),
        ", ".join(f"{k} {_shown(b)}" for k, _, b in apart[:4]),
    )


def _apart(old: dict[Any, Any], new: dict[Any, Any], prefix: str, apart: list[tuple[str, Any, Any]]) -> None:
    """Append to ``apart`` each dotted override the two differ in; a section both set as a dict
    (``robot.scanner`` of ``--scanner``) is opened into its fields, so that a message names the
    field that differs, not two dicts cut alike."""
    for key in sorted(set(old) | set(new), key=str):
        a, b = old.get(key, _UNSET), new.get(key, _UNSET)
        if isinstance(a, dict) and isinstance(b, dict):
            _apart(a, b, f"{prefix}{key}.", apart)
        elif a != b:
            apart.append((f"{prefix}{key}", a, b))


#: The fields :func:`_run` writes into a run's ``run.json`` (a failed run's ``error`` and ``traceback`` too).
RUN_FIELDS = ("spec", "ok", "wall_s", "source_sha256", "policy_sha256", "error", "traceback")


def _run_record_problem(record: dict[str, Any]) -> str | None:
    """What makes ``record`` (a ``run.json``) no record :func:`_run` wrote, or None: checked whole,
    fields the table never reads included, so that a resumed comparison keeps no edited record."""
    if not isinstance(record.get("ok"), bool):
        return f"ok is {_shown(record.get('ok'))}, not true or false"
    odd = [k for k in record if k not in RUN_FIELDS]
    if odd:
        return f"holds the field {_shown(odd[0])}, which no run writes"
    wall = record.get("wall_s")
    if not (isinstance(wall, (int, float)) and not isinstance(wall, bool) and 0 <= wall <= MAX_FIGURE):
        return f"wall_s is {_shown(wall)}, not a run's seconds"
    return None


def _shown(value: Any) -> str:
    """``value`` for a message, as the record's JSON spells it, bounded: a record may hold a
    300-digit number or a huge string."""
    return json_text(value, 40)


def _number(record: dict[str, Any], key: str, where: str, *, high: float = MAX_FIGURE, **kind: bool) -> None:
    """``record[key]`` is a number in [0, high]: ``integer``, an int; ``optional``, or absent;
    ``nullable``, or None or absent (what the summary reads only when it is not None); ``present``
    with ``nullable``, or None but not absent (a field every record of the schema writes)."""
    name = f"{where}{key}"
    if key not in record:
        if kind.get("optional") or (kind.get("nullable") and not kind.get("present")):
            return
        raise _BadRecordError(f"{name} is missing")
    value = record[key]
    if value is None and kind.get("nullable"):
        return
    integer = kind.get("integer", False)
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        raise _BadRecordError(f"{name} is {_shown(value)}, not {'an integer' if integer else 'a number'}")
    if not 0 <= value <= high:  # NaN and ±inf fail too
        raise _BadRecordError(f"{name} is {_shown(value)}, not within [0, {high:g}]")


def _entries(record: dict[str, Any], key: str, where: str = "", *, optional: bool = False) -> list[dict[str, Any]]:
    """``record[key]``: a list of objects (``optional``: or absent, an empty list)."""
    if key not in record and optional:
        return []
    value = record.get(key)
    if not isinstance(value, list):
        raise _BadRecordError(f"{where}{key} is {_shown(value)}, not a list")
    for k, entry in enumerate(value):
        if not isinstance(entry, dict):
            raise _BadRecordError(f"{where}{key}[{k}] is {_shown(entry)}, not an object")
    return value


def _text(record: dict[str, Any], key: str, where: str) -> None:
    if not isinstance(record.get(key), str):
        raise _BadRecordError(f"{where}{key} is {_shown(record.get(key))}, not a string")


def _budget(spec: dict[str, Any]) -> int | None:
    """The scan budget of the run ``spec`` describes (None where it describes no run)."""
    try:
        return int(RunSpec(**spec).config().max_scans)
    except Exception:  # a spec of another version, or edited: the spec's own check names it
        return None


def _check_metrics(m: Any, spec: dict[str, Any]) -> None:
    """Raise :class:`_BadRecordError` unless ``m`` holds, of the right type and within its meaning, every
    figure the tables and plots read of a run, and says it is the run of ``spec``."""
    if not isinstance(m, dict):
        raise _BadRecordError(f"it holds {_shown(m)}, not a run's figures")
    from nbs_env.report import SCHEMA

    if m.get("schema") != SCHEMA:  # another version's figures, or another file
        raise _BadRecordError(f"its schema is {_shown(m.get('schema'))}, not {SCHEMA!r}")
    for key in ("scene", "policy", "seed"):  # the record of another run, copied or edited in
        want, have = spec[key], m.get(key)
        if type(have) is not type(want) or have != want:
            raise _BadRecordError(
                f"it is the record of {key} {_shown(have)}, but it sits in the run of {key} {_shown(want)}"
            )
    pct = {"high": 100.0}
    _number(m, "scans", "", integer=True)
    _number(m, "structure_sensed_pct", "", **pct)
    _number(m, "processed_points", "", integer=True)
    for key in ("path_length_m", "processing_time_s", "acquisition_time_s", "travel_time_s"):
        _number(m, key, "")
    if not isinstance(m.get("complete"), bool):
        raise _BadRecordError(f"complete is {_shown(m.get('complete'))}, not true or false")
    for k, room in enumerate(_entries(m, "rooms")):
        where = f"rooms[{k}]."
        _number(room, "id", where, integer=True)
        _text(room, "name", where)
        _number(room, "scans", where, integer=True)
        _number(room, "structure_sensed_pct", where, **pct)
        _number(room, "processed_points", where, integer=True)
        _number(room, "path_length_m", where)
    steps = _entries(m, "steps")
    if len(steps) != m["scans"] or not steps:
        raise _BadRecordError(f"it has {len(steps)} steps for {m['scans']} scans")
    for k, step in enumerate(steps):
        _number(step, "structure_sensed_pct", f"steps[{k}].", **pct)
        for key in ("dense_pct", "incidence_pct"):  # the quality curves: every step's, or none
            _number(step, key, f"steps[{k}].", nullable=steps[0].get(key) is None, **pct)
    # Figures a run writes together agree (hand edits of one were reused and tabled): the sensed
    # structure only grows, the total is the last step's, and the scans are within the budget.
    curve = [step["structure_sensed_pct"] for step in steps]
    for k in range(1, len(curve)):
        if curve[k] < curve[k - 1] - 1e-6:
            raise _BadRecordError(f"steps[{k}].structure_sensed_pct {curve[k]:g} is below the step before's")
    if abs(m["structure_sensed_pct"] - curve[-1]) > 1e-6:
        raise _BadRecordError(
            f"structure_sensed_pct {m['structure_sensed_pct']:g} is not its last step's {curve[-1]:g}"
        )
    budget = _budget(spec)
    if budget is not None and m["scans"] > budget:
        raise _BadRecordError(f"it has {m['scans']} scans, more than the run's budget of {budget}")
    for k, end in enumerate(_entries(m, "room_ends", optional=True)):
        _text(end, "reason", f"room_ends[{k}].")
        _number(end, "scans", f"room_ends[{k}].", integer=True)
        _number(end, "standing_room", f"room_ends[{k}].", optional=True)
    for k, event in enumerate(_entries(m, "door_events", optional=True)):
        _text(event, "event", f"door_events[{k}].")
        if event["event"] == "abandoned":
            _text(event, "reason", f"door_events[{k}].")
    # Every part a run of this schema writes is there whole: an emptied one ("quality": {}) was
    # reused, and the tables showed "-" for figures the run had measured.
    for part in ("registration_error", "quality", "registrability", "config"):
        if not isinstance(m.get(part), dict):
            raise _BadRecordError(f"{part} is {_shown(m.get(part)) if part in m else 'missing'}, not an object")
    for key in ("mean_m", "max_m", "mean_deg", "max_deg"):
        _number(m["registration_error"], key, "registration_error.")
    quality = m["quality"]
    for key in ("min_density_per_m2", "max_incidence_deg", "density_radius_m"):  # head quality.md
        _number(quality, key, "quality.")
    for key in ("dense_pct", "incidence_pct", "quality_pct"):  # null where no structure was measured
        _number(quality, key, "quality.", nullable=True, present=True, **pct)
    for key in ("median_density_per_m2", "median_incidence_deg", "median_range_m"):
        _number(quality, key, "quality.", nullable=True, present=True)
    registrability = m["registrability"]
    _number(registrability, "scans", "registrability.", integer=True)
    for key in ("mean_overlap", "min_overlap", "mean_fitness", "min_fitness"):  # shares; null with one scan
        _number(registrability, key, "registrability.", high=1.0, nullable=True, present=True)
    _number(registrability, "refused", "registrability.", integer=True)
    _number(m, "measured_points", "", integer=True)
    _number(m, "policy_time_s", "")
    offset = m.get("scene_offset_m")  # an IFC storey moved near the origin: where it was (older records lack it)
    if not (offset is None or _is_point(offset)):
        raise _BadRecordError(f"scene_offset_m is {_shown(offset)}, not null or three finite numbers")
    from nbs_env.config import EnvConfig

    # The configuration the run ran with: EnvConfig's fields (an older record may lack later ones).
    names = {f.name for f in fields(EnvConfig)}
    odd = sorted(set(m["config"]) - names) or sorted({"preset", "robot", "rooms", "observation"} - set(m["config"]))
    if odd:
        said = "holds" if odd[0] in m["config"] else "lacks"
        raise _BadRecordError(f"config {said} {_shown(odd[0])}: not the configuration a run records")


def _is_point(value: Any) -> bool:
    """Three finite JSON numbers."""
    return (
        isinstance(value, list)
        and len(value) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    )


def record_problem(record: dict[str, Any], *, summary: bool = True) -> str | None:
    """Why a finished run (``{"spec", "ok", "metrics"}``) cannot go into the table, or None.

    Its ``metrics.json`` must hold every figure the tables and plots read, of the right type and
    within its meaning (percentages in [0, 100], counts integers, lengths and times finite and not
    negative, the steps' curves), and name the scene, policy and seed of the run it sits in. Then
    (``summary``) the table is made of it alone, warnings as errors: what the summary would choke on
    is found here, not after the grid.
    """
    try:
        _check_metrics(record.get("metrics"), record["spec"])
        if summary:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                summarise([record], {})
    except _BadRecordError as exc:
        return str(exc)
    except Exception as exc:
        return f"the table cannot be made of it ({type(exc).__name__}: {_shown(str(exc))})"
    return None


def _odd_rooms(runs: dict[str, dict[str, Any]]) -> dict[str, str]:
    """The runs whose rooms are not those most runs of their scene list: the table lines up every
    run's rooms with the first's (a record edited or copied from another scene's)."""
    rooms: dict[str, dict[str, tuple]] = {}
    for key, r in runs.items():
        rooms.setdefault(r["spec"]["scene"], {})[key] = tuple((p["id"], p["name"]) for p in r["metrics"]["rooms"])
    odd = {}
    for scene_rooms in rooms.values():
        counts: dict[tuple, int] = {}
        for names in scene_rooms.values():
            counts[names] = counts.get(names, 0) + 1
        ranked = sorted(counts.values(), reverse=True)
        # The rooms most runs list; with no such list (a tie), none can be told right: all run again.
        usual = max(counts, key=counts.__getitem__) if len(ranked) == 1 or ranked[0] > ranked[1] else None
        for key, names in scene_rooms.items():
            if usual is None:
                odd[key] = f"its {len(names)} rooms are not those of the scene's other runs"
            elif names != usual:
                odd[key] = f"its {len(names)} rooms are not the {len(usual)} of the scene's other runs"
    return odd


def _culprits(results: Sequence[dict[str, Any]], out: Path) -> list[tuple[Path, str]]:
    """The ``metrics.json`` files (and why) of the runs the summary could not be made of, as far as
    they can be told: a summary that fails on every run alike names none."""
    ok = {str(k): r for k, r in enumerate(results) if r.get("ok") and isinstance(r.get("spec"), dict)}
    found = {k: p for k, r in ok.items() if (p := record_problem(r, summary=False)) is not None}
    if not found:  # every record is well-formed: are they unlike each other, or does one alone fail?
        found = _odd_rooms(ok)
    if not found:
        found = {k: p for k, r in ok.items() if (p := record_problem(r)) is not None}
        found = found if len(found) < len(ok) else {}
    return [(_run_folder(out, ok[k]["spec"]) / "metrics.json", problem) for k, problem in found.items()]


def _check_scene(scene: str) -> None:
    """CompareError unless ``scene`` names a source that can be loaded, found without loading it."""
    from scenes import SceneError
    from scenes.corpus import PREFIX as CORPUS_PREFIX
    from scenes.corpus import corpus_entry
    from scenes.loader import check_source
    from train.outputs import utf8_problem

    problem = utf8_problem("--scenes", scene)
    if problem is not None:
        raise CompareError(problem)
    try:
        if scene.startswith(CORPUS_PREFIX):
            entry = corpus_entry(scene[len(CORPUS_PREFIX) :])
            if entry.generated is None and entry.path() is None:
                raise CompareError(f"{scene}: its local-only file {entry.file!r} is not here (see docs/buildings.md)")
        else:
            check_source(scene)
    except SceneError as exc:
        raise CompareError(str(exc)) from None


def _oracle_usable(plan: dict[str, Any]) -> bool:
    """An oracle record is one the oracle could have written (:meth:`OraclePlan.from_dict`): the
    table reads its best coverage, its curve against the scans, its rooms'."""
    from policies.oracle import OraclePlan

    try:
        OraclePlan.from_dict(plan)
    except ValueError:
        return False
    return _finite_leaves(plan)


def _finite_leaves(node: Any) -> bool:
    """No NaN or infinity anywhere in a record (its positions, its times): written back into
    ``oracle.json``, one would make the file invalid JSON."""
    if isinstance(node, float):
        return math.isfinite(node)
    if isinstance(node, dict):
        return all(_finite_leaves(v) for v in node.values())
    if isinstance(node, list):
        return all(_finite_leaves(v) for v in node)
    return True


def _refuse_repeats(flag: str, values: Sequence[Any], identities: Sequence[Any] | None = None) -> None:
    """A scene, policy or seed given twice would count one run twice in the table's means.
    ``identities`` tell what each value is, where two spellings name one (``generated:1`` and
    ``generated:01``, ``ppo:run`` and ``ppo:./run``)."""
    named: dict[Any, list[Any]] = {}
    for value, identity in zip(values, identities if identities is not None else values, strict=True):
        named.setdefault(identity, []).append(value)
    repeated = [
        f"{spellings[0]} ({len(spellings)} times)" if len(set(spellings)) == 1 else " and ".join(map(str, spellings))
        for spellings in named.values()
        if len(spellings) > 1
    ]
    if repeated:
        raise CompareError(f"{flag} names {'; '.join(repeated)}: one run each; give each once")


def _scene_identity(scene: str) -> Any:
    """What a scene spec names: a generated seed as its number, a file as its real path."""
    if scene.startswith("generated:") and scene[len("generated:") :].isdigit():
        return ("generated", int(scene[len("generated:") :]), None)
    if scene.startswith("corpus:"):  # an entry is its file, read with the entry's options
        try:
            from scenes.corpus import corpus_entry

            entry = corpus_entry(scene[len("corpus:") :])
            path, options = entry.path(), dict(entry.options)
        except Exception:  # no such entry: the scene check says so
            return ("name", scene)
        shown = json.dumps(options, sort_keys=True, default=str) if options else None
        if entry.generated is not None:  # a generated storey at the generator's edges: its seed and options
            return ("generated", entry.generated, shown)
        if path is None:  # a local-only file that is absent: the scene check says so
            return ("name", scene)
        return ("file", path.resolve(), shown)
    path = Path(scene)
    if path.suffix and path.exists():
        return ("file", path.resolve(), None)
    from scenes.loader import bundled_plan_path

    bundled = bundled_plan_path(scene)  # a bundled name is its plan file (office and scenes/data/office.json)
    if bundled is not None:
        return ("file", bundled.resolve(), None)
    return ("name", scene)


def _policy_identity(spec: str, policy: Any) -> Any:
    """What a policy spec names: a ``ppo:`` checkpoint as its real folder (``ppo:run``, ``ppo:./run``
    and ``ppo:run/policy.json`` are one), any other as its kind and settings (``greedy``, ``greedy:1``;
    ``greedy:0.8``, ``greedy:0.80``)."""
    if spec.startswith("ppo:"):
        try:
            from policies.learned import resolve_checkpoint

            path = resolve_checkpoint(spec[len("ppo:") :]).resolve()
        except Exception:  # made already: cannot happen, but the name is then its identity
            return ("name", spec)
        return ("ppo", path.parent if path.name == "policy.json" else path)
    settings = sorted(
        (key, value)
        for key, value in vars(policy).items()
        if not key.startswith("_") and key != "name" and isinstance(value, (int, float, str, bool, tuple, type(None)))
    )
    return (type(policy).__name__, tuple(settings))


def _items(flag: str, text: str) -> list[str]:
    """The comma-separated items of an option, stripped; an empty one (``0,``, ``a,,b``) is refused: a
    slip (a shell variable that expanded to nothing), not a choice to leave one out."""
    items = [p.strip() for p in str(text).split(",")]
    if len(items) > 1 and not all(items):
        raise CompareError(
            f"{flag} {text!r} has an empty item (a comma at an end, or two together); give each item once"
        )
    return [item for item in items if item]


def grid(
    scenes: str, policies: str, seeds: str, preset: str = "default", overrides: dict[str, Any] | None = None
) -> list[RunSpec]:
    """The RunSpecs of comma-separated scenes, policies and seeds, checked before anything runs.

    Parameters
    ----------
    scenes, policies, seeds : str
        Comma-separated; scenes as :func:`expand_scenes` reads them.
    preset : str
        The configuration preset of every run.
    overrides : dict, optional
        Dotted configuration overrides of every run (the command line's robot options); what the
        policies require (:attr:`policies.Policy.requires`) is added where they set nothing.

    Raises
    ------
    CompareError
        An unknown scene, policy or checkpoint, bad seeds, a scene, policy or seed given twice
        (``generated:0-3,generated:2`` included), or scene options (``--storey``, ``--ifc-doors``,
        ``--y-up``) that do not apply to one of the scenes.
    ConfigError
        A configuration value out of range, policies that require different robots, or options
        that contradict what a policy requires; the message names them.
    """
    from policies import UnknownPolicyError, agreed_requirements, make_policy

    _items("--scenes", scenes)
    skipped: list[str] = []
    scene_list = expand_scenes(scenes, skipped)
    for scene in scene_list:  # each named source exists before any run starts (not a failed run each)
        _check_scene(scene)
    if skipped:
        print(f"nbs compare: skipped (local-only files absent): {', '.join(skipped)}", file=sys.stderr)
    policy_list = _items("--policies", policies)
    if not policy_list:
        raise CompareError("no policies given")
    _refuse_repeats("--scenes", scene_list, [_scene_identity(x) for x in scene_list])
    _refuse_repeats("--policies", policy_list)
    from nbs_env.errors import ModelFileError
    from train.arguments import adopt_requirements, scene_option_error

    try:
        made = [make_policy(p, 0) for p in policy_list]
    except (UnknownPolicyError, ModelFileError) as exc:
        raise CompareError(str(exc)) from None
    _refuse_repeats("--policies", policy_list, [_policy_identity(p, m) for p, m in zip(policy_list, made, strict=True)])
    overrides = adopt_requirements(dict(overrides or {}), agreed_requirements(made))
    seed_items = _items("--seeds", seeds)
    try:
        seed_list = [parse_int(s) for s in seed_items]
    except ValueError:
        raise CompareError(f"seeds must be comma-separated integers, got {seeds!r}") from None
    if not seed_list:
        raise CompareError("no seeds given")
    if min(seed_list) < 0:
        raise CompareError(f"seeds are integers >= 0, got {seeds!r}")
    if max(seed_list) >= 10**MAX_SEED_DIGITS:  # a run's folder is named by its seed
        raise CompareError(f"seeds have at most {MAX_SEED_DIGITS} digits, got one of more in --seeds")
    _refuse_repeats("--seeds", seed_list)
    options = overrides.get("scene_options", {})
    for scene in scene_list:
        problem = scene_option_error(
            scene, options.get("storey"), bool(options.get("y_up")), options.get("doors"), options.get("units")
        )
        if problem is not None:
            raise CompareError(problem)
    runs = len(scene_list) * len(policy_list) * len(seed_list)
    if runs > MAX_RUNS:
        raise CompareError(
            f"{len(scene_list):,} scenes x {len(policy_list)} policies x {len(seed_list):,} seeds make {runs:,} "
            f"runs, at most {MAX_RUNS:,}"
        )
    specs = [
        RunSpec(scene, policy, seed, preset, overrides)
        for scene in scene_list
        for policy in policy_list
        for seed in seed_list
    ]
    _refuse_shared_folders(specs)
    from policies import config_for

    for policy in made:  # every run's configuration is checked here, not in a worker
        config_for(specs[0].config(), policy)
    return specs
