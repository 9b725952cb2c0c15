"""``nbs compare --resume`` reuses a finished run only when its record is one the table can be made
of: numbers of the right type, finite and within their meaning, well-formed steps, and the scene,
policy and seed of the folder it sits in. Anything else is run again, named on stderr in one line."""

from __future__ import annotations

import copy
import json
import math
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import train.compare as compare
from train.compare import CompareError, grid, record_problem, write_outputs

ROOT = Path(__file__).resolve().parents[1]
SEEDS = "0,1,2,3,4,5,6"
ARGS = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", SEEDS]
ARGS += ["--preset", "fast", "--max-scans", "1", "--quiet"]


def nbs(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "train", *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


def metrics_path(out: Path, seed: int) -> Path:
    return out / "runs" / "l_room" / "random" / f"seed{seed}" / "metrics.json"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    out = tmp_path_factory.mktemp("grid") / "base"
    done = nbs(*ARGS, "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


def _broken_steps(m):
    m["steps"] = [{"x": 1}] * 3


def _broken_step_entry(m):
    m["steps"] = [{"x": 1}] * len(m["steps"])  # as many steps as scans, none with its coverage


# (seed, edit, what the stderr line must say)
DAMAGES = [
    (0, lambda m: m.update(structure_sensed_pct=1e308, path_length_m=-5), "structure_sensed_pct is 1e+308"),
    (1, lambda m: m.update(structure_sensed_pct=math.nan), "structure_sensed_pct is NaN"),
    (2, lambda m: m.update(path_length_m=-5), "path_length_m is -5"),
    (3, lambda m: m.update(scene="office", seed=5), 'scene "office"'),
    (4, _broken_steps, "3 steps for 1 scans"),
    (5, _broken_step_entry, "steps[0].structure_sensed_pct is missing"),
]


def _table_numbers(markdown: str) -> list[float]:
    total = next(line for line in markdown.splitlines() if "| total |" in line)
    cells = [c.strip() for c in total.strip("|").split("|")][3:10]
    return [float(v.replace(",", "")) for c in cells for v in c.split(" ± ")]


def test_resume_runs_damaged_records_again_and_names_each(base, tmp_path):
    out = tmp_path / "damaged"
    shutil.copytree(base, out)
    for seed, edit, _ in DAMAGES:
        m = json.loads(metrics_path(out, seed).read_text())
        edit(m)
        metrics_path(out, seed).write_text(json.dumps(m))  # NaN is written as JSON's NaN
    before = {seed: metrics_path(base, seed).read_text() for seed in range(7)}

    done = nbs(*ARGS, "--out", str(out), "--resume")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    # One line per damaged record, naming the file and the reason; nothing else (no warnings).
    assert len(lines) == len(DAMAGES), done.stderr
    for (seed, _, reason), line in zip(DAMAGES, lines, strict=True):
        assert line.startswith(f"nbs compare: {metrics_path(out, seed)}: "), line
        assert reason in line and line.endswith("running it again"), line
    assert "Warning" not in done.stderr and "7 of 7 runs ok" in done.stdout
    # Each damaged run was run again: its record is the run's own again (deterministic but for times).
    for seed in range(7):
        again = json.loads(metrics_path(out, seed).read_text())
        first = json.loads(before[seed])
        assert (
            record_problem(
                {"spec": {"scene": "l_room", "policy": "random", "seed": seed}, "ok": True, "metrics": again}
            )
            is None
        )
        for key in ("scene", "policy", "seed", "scans", "structure_sensed_pct", "path_length_m"):
            assert again[key] == first[key], (seed, key)
        assert len(again["steps"]) == len(first["steps"])
        assert again["steps"][-1]["structure_sensed_pct"] == first["steps"][-1]["structure_sensed_pct"]
    # The undamaged run was reused, not rewritten.
    assert metrics_path(out, 6).read_text() == before[6]
    numbers = _table_numbers((out / "table.md").read_text())
    assert numbers and all(math.isfinite(v) for v in numbers), numbers
    assert 0 <= numbers[4] <= 100  # SE sensed (%)
    assert numbers[8] >= 0  # path (m)
    # A second --resume reuses everything, quietly: no loop.
    specs = grid("l_room", "random", SEEDS, "fast", {"max_scans": 1})
    again = nbs(*ARGS, "--out", str(out), "--resume")
    assert again.returncode == 0 and again.stderr == "", again.stderr
    assert len(compare.load_finished(out, specs)["runs"]) == 7


def test_resume_names_a_run_json_of_another_run(base, tmp_path, capsys):
    out = tmp_path / "moved"
    shutil.copytree(base, out)
    run = metrics_path(out, 0).parent / "run.json"
    record = json.loads(run.read_text())
    record["spec"]["seed"] = 5
    run.write_text(json.dumps(record))
    specs = grid("l_room", "random", SEEDS, "fast", {"max_scans": 1})
    finished = compare.load_finished(out, specs)
    assert "l_room|random|0" not in finished["runs"] and len(finished["runs"]) == 6
    assert capsys.readouterr().err == (
        f'nbs compare: {run}: it is the record of scene "l_room", policy "random", seed 5, not of the run '
        "whose folder it is in; running it again\n"
    )


@pytest.fixture(scope="module")
def good(base):
    return json.loads(metrics_path(base, 0).read_text())


def _set(path: str, value):
    def edit(m):
        *parents, last = path.split(".")
        target = m
        for part in parents:
            target = target[int(part)] if isinstance(target, list) else target[part]
        if isinstance(target, list):
            target[int(last)] = value
        else:
            target[last] = value

    return edit


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (_set("scans", True), "scans is true, not an integer"),
        (_set("scans", 1.0), "scans is 1.0, not an integer"),
        (_set("processed_points", 10**400), "processed_points is 1000"),
        (_set("structure_sensed_pct", math.inf), "structure_sensed_pct is Infinity"),
        (_set("structure_sensed_pct", "50"), 'structure_sensed_pct is "50", not a number'),
        (_set("travel_time_s", -1.0), "travel_time_s is -1.0"),
        (_set("acquisition_time_s", 1e300), "acquisition_time_s is 1e+300"),
        (_set("complete", 1), "complete is 1"),
        (_set("policy", "greedy"), 'policy "greedy"'),
        (_set("seed", "0"), 'seed "0"'),
        (_set("rooms", {}), "rooms is {}, not a list"),
        (_set("rooms.0.structure_sensed_pct", 100.5), "rooms[0].structure_sensed_pct is 100.5"),
        (_set("rooms.0.name", None), "rooms[0].name is null"),
        (_set("steps.0", 3), "steps[0] is 3, not an object"),
        (_set("steps.0.dense_pct", -1), "steps[0].dense_pct is -1"),
        (_set("registration_error", None), "registration_error is null"),
        (_set("registration_error.max_m", math.nan), "registration_error.max_m is NaN"),
        (_set("quality.min_density_per_m2", "x"), 'quality.min_density_per_m2 is "x"'),
        (_set("quality.quality_pct", 400), "quality.quality_pct is 400"),
        (_set("registrability.min_overlap", 2.0), "registrability.min_overlap is 2.0"),
        (_set("registrability.refused", None), "registrability.refused is null"),
        (_set("room_ends", [{"reason": "no NVP", "scans": 1, "standing_room": None}]), "standing_room is null"),
        (_set("door_events", [{"event": "abandoned", "reason": ["x"]}]), 'door_events[0].reason is ["x"]'),
        (_set("door_events", [7]), "door_events[0] is 7"),
    ],
)
def test_a_record_out_of_its_meaning_is_refused_with_the_reason(good, edit, reason):
    spec = {"scene": "l_room", "policy": "random", "seed": 0}
    assert record_problem({"spec": spec, "ok": True, "metrics": good}) is None
    bad = copy.deepcopy(good)
    edit(bad)
    problem = record_problem({"spec": spec, "ok": True, "metrics": bad})
    assert problem is not None and reason in problem, problem
    assert len(problem) < 200  # a 400-digit number is not echoed whole


def test_a_summary_that_fails_names_the_record(good, tmp_path):
    spec = {"scene": "l_room", "policy": "random", "seed": 0}
    other = {**copy.deepcopy(good), "seed": 1}
    broken = copy.deepcopy(good)
    broken["rooms"] = []  # one run with rooms unlike the other's: the table cannot line them up
    results = [  # the table lines up every run's rooms with the first's: an IndexError
        {"spec": {**spec, "seed": 1}, "ok": True, "metrics": other},
        {"spec": spec, "ok": True, "metrics": broken},
        {"spec": {**spec, "seed": 2}, "ok": True, "metrics": {**copy.deepcopy(good), "seed": 2}},
    ]
    with pytest.raises(CompareError) as caught:
        write_outputs(results, {}, tmp_path)
    message = str(caught.value)
    assert f"{metrics_path(tmp_path, 0)}: its 0 rooms are not the" in message, message
    assert "rerun with --resume to run it again" in message
    steps = copy.deepcopy(good)
    steps["steps"] = [{"x": 1}]
    with pytest.raises(CompareError, match=r"seed0/metrics\.json: steps\[0\]\.structure_sensed_pct is missing"):
        write_outputs([{"spec": spec, "ok": True, "metrics": steps}], {}, tmp_path / "steps")


def test_a_grid_whose_runs_all_failed_draws_its_plots_without_warnings(tmp_path):
    failed = [{"spec": {"scene": "l_room", "policy": p, "seed": 0}, "ok": False, "error": "X: y"} for p in ("a", "b")]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_outputs(failed, {}, tmp_path)
    assert [str(w.message) for w in caught] == []
    assert (tmp_path / "coverage_vs_scans.png").stat().st_size > 0
