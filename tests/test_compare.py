"""``nbs compare``: the grid runs, a failed run is recorded, the table is complete and reproducible,
and the Ray backend gives the local backend's results."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from train.cli import main
from train.compare import CompareError, expand_scenes, folder_name, grid, run_grid, summarise, write_outputs

TINY = dict(
    scenes="l_room", policies="greedy,random,stachniss_burgard", seeds="0,1", preset="fast", overrides={"max_scans": 3}
)


def strip_times(rows):
    return [{k: v for k, v in r.items() if k != "time_s"} for r in rows]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    specs = grid(**TINY)
    results, oracles = run_grid(specs, jobs=2, progress=False)
    out = tmp_path_factory.mktemp("compare")
    rows = write_outputs(results, oracles, out)
    return specs, results, oracles, rows, out


def test_scene_ranges_expand():
    assert expand_scenes("five_rooms,generated:3-5") == ["five_rooms", "generated:3", "generated:4", "generated:5"]
    with pytest.raises(CompareError, match="generated:A-B"):
        expand_scenes("generated:a-b")
    with pytest.raises(CompareError, match="unknown policy"):
        grid("l_room", "greedy,clairvoyant", "0")
    with pytest.raises(CompareError, match="seeds"):
        grid("l_room", "greedy", "0,x")


def test_the_tiny_grid_writes_a_complete_table(tiny):
    specs, results, oracles, rows, out = tiny
    assert len(results) == len(specs) == 6 and all(r["ok"] for r in results)
    for name in ("table.csv", "table.md", "coverage_vs_scans.png", "path_time.png", "oracle.json"):
        assert (out / name).stat().st_size > 0, name
    totals = {r["policy"]: r for r in rows if r["room"] == "total"}
    assert set(totals) == {"greedy", "random", "stachniss_burgard"}
    for r in totals.values():
        for key in ("scans", "time_s", "structure_sensed_pct", "processed_points", "path_length_m", "of_oracle_pct"):
            mean, std = r[key]
            assert mean == mean and std >= 0, (r["policy"], key)  # not NaN
        assert r["scans"][0] <= 3  # the budget
    # The oracle is the yardstick: nobody sees more than it can (up to noise).
    assert all(r["of_oracle_pct"][0] <= 103.0 for r in totals.values())
    assert oracles["l_room"]["ok"] and oracles["l_room"]["max_coverage_pct"] > 80.0
    with (out / "table.csv").open() as f:
        assert len(list(csv.DictReader(f))) == len(rows)
    markdown = (out / "table.md").read_text()
    assert markdown.count("| l_room | greedy |") == 2  # its room and its total
    metrics = json.loads((out / "runs" / "l_room" / "stachniss_burgard" / "seed1" / "metrics.json").read_text())
    # A structure-agnostic method processes every point it measured.
    assert metrics["processed_points"] == metrics["measured_points"] > 0
    # methods.md: one line per policy, with how its rooms ended.
    methods = (out / "methods.md").read_text()
    assert "by its rule (%)" in methods and all(methods.count(f"| {p} |") == 1 for p in totals)


def _fake_metrics(scale: float) -> dict:
    """five_rooms metrics whose every quantity is ``scale`` times a base (rooms 1-5)."""
    rooms = [
        {"id": k, "name": f"r{k}", "scans": 2, "structure_sensed_pct": 90.0, "path_length_m": scale * (k + 1),
         "processed_points": int(scale * 1000 * (k + 1)), "processing_time_s": scale * 10.0}
        for k in range(5)
    ]  # fmt: skip
    steps = [{"room": k, "points": 1000} for k in range(5) for _ in range(2)]
    return {
        "scans": 10, "processing_time_s": scale * 50.0, "acquisition_time_s": 50.0 * scale,
        "travel_time_s": 50.0 * scale, "structure_sensed_pct": 90.0,
        "processed_points": int(scale * 15000), "path_length_m": scale * 15.0, "rooms": rooms, "steps": steps,
        "room_ends": [{"room": k, "scans": 2, "reason": "declared"} for k in range(5)],
    }  # fmt: skip


def test_the_paper_section5_tables_compute_reductions_as_the_paper_states_them(tmp_path):
    from train.paper_section5 import METHODS, tables

    scale = {"greedy": 1.0, "stachniss_burgard": 2.0, "blaer_allen": 4.0, "potthast_sukhatme": 1.25}
    for p in METHODS:
        for seed in (0, 1):
            folder = tmp_path / "runs" / "five_rooms" / p / f"seed{seed}"
            folder.mkdir(parents=True)
            (folder / "metrics.json").write_text(json.dumps(_fake_metrics(scale[p])))
    text = tables(tmp_path)
    # Against a method that takes twice as long, processes twice the points and drives twice as far,
    # every reduction is 50%; against 4x, 75%; against 1.25x, 20%.
    assert (
        "| Stachniss & Burgard [12] | 33.6% | 50.0 ± 0.0% | 7.2% | 50.0 ± 0.0% | 30.0% | 50.0 ± 0.0% | #1, #2, #3 |"
        in text
    )
    assert (
        "| Blaer & Allen [3] | 83.7% | 75.0 ± 0.0% |" in text
        and "| Potthast & Sukhatme [2] | 78.7% | 20.0 ± 0.0%" in text
    )
    assert text.count("| | ours |") == 4 and "0 of 10" in text  # no room ended by the cap
    with pytest.raises(FileNotFoundError, match="controlled"):
        tables(tmp_path, controlled=True)


def test_rerunning_reproduces_the_table(tiny):
    specs, _, _, rows, _ = tiny
    again = summarise(*run_grid(specs, jobs=1, progress=False))
    assert strip_times(again) == strip_times(rows)


def test_a_failed_run_is_recorded_and_the_others_go_on(tmp_path, capsys):
    # A file that is there but cannot be read as a storey fails in its run (a name that is no source
    # at all is refused before any run: tests/test_bad_input.py).
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0\nf 1 2 3\n")
    out = tmp_path / "out"
    code = main(["compare", "--scenes", f"l_room,{broken}", "--policies", "greedy", "--seeds", "0",
                 "--preset", "fast", "--max-scans", "2", "--out", str(out), "--quiet"])  # fmt: skip
    assert code == 1
    err = capsys.readouterr().err
    assert str(broken) in err and "InvalidMeshError" in err
    assert (out / "runs" / folder_name(str(broken)) / "greedy" / "seed0" / "error.txt").exists()
    assert (out / "runs" / "l_room" / "greedy" / "seed0" / "metrics.json").exists()
    assert "1 of 1 runs failed" in (out / "table.md").read_text()


def test_bad_command_lines_exit_2(tmp_path, capsys):
    assert main(["compare", "--scenes", "l_room", "--policies", "psychic", "--out", str(tmp_path)]) == 2
    assert "psychic" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["compare", "--scenes", "l_room", "--policies", "greedy", "--out", str(tmp_path), "--backend", "mpi"])
    assert exc.value.code == 2


@pytest.mark.expensive
def test_ray_backend_gives_the_local_results(tiny):
    """Each run a task of a local Ray instance (started here: about half a minute on 2 cores)."""
    pytest.importorskip("ray")
    specs, _, _, rows, _ = tiny
    results, oracles = run_grid(specs, jobs=2, backend="ray", progress=False)
    assert all(r["ok"] for r in results)
    assert strip_times(summarise(results, oracles)) == strip_times(rows)


def _fake_run(scene, seed, scans, pct):
    metrics = {
        "scans": scans,
        "structure_sensed_pct": pct,
        "processed_points": 10 * scans,
        "path_length_m": 2.0 * scans,
        "processing_time_s": 1.0,
        "acquisition_time_s": 1.0,
        "travel_time_s": 1.0,
        "complete": True,
        "rooms": [{"name": "room0", "scans": scans, "structure_sensed_pct": pct, "processed_points": 10 * scans,
                   "path_length_m": 2.0 * scans}],
    }  # fmt: skip
    return {"spec": {"scene": scene, "policy": "greedy", "seed": seed}, "ok": True, "metrics": metrics}


def test_all_scenes_spread_is_over_seeds_not_over_storeys():
    # Storeys differ by 100 scans, seeds by 2: the "all scenes" std must show the seeds' spread.
    results = [
        _fake_run("small", 0, 10, 90.0),
        _fake_run("small", 1, 12, 92.0),
        _fake_run("large", 0, 110, 80.0),
        _fake_run("large", 1, 112, 82.0),
    ]
    (row,) = [r for r in summarise(results, {}) if r["scene"] == "all scenes"]
    assert row["scans"] == pytest.approx((61.0, 2**0.5))  # per-seed means 60 and 62
    assert row["structure_sensed_pct"] == pytest.approx((86.0, 2**0.5))
    assert row["runs"] == 4 and "of_oracle_pct" not in row


def test_resume_reuses_finished_runs_and_reruns_the_rest(tiny, monkeypatch):
    import shutil

    import train.compare as compare

    specs, _, _, rows, out = tiny
    resumed = out.parent / "resumed"
    shutil.copytree(out, resumed)
    shutil.rmtree(resumed / "runs" / "l_room" / "random" / "seed1")  # one run lost
    finished = compare.load_finished(resumed, specs)
    assert len(finished["runs"]) == 5 and set(finished["oracles"]) == {"l_room"}
    calls = []
    real = compare.run_one
    monkeypatch.setattr(compare, "run_one", lambda spec: calls.append(spec) or real(spec))
    monkeypatch.setattr(compare, "_oracle", lambda *a: pytest.fail("the oracle was recomputed"))
    again, again_oracles = compare.run_grid(specs, jobs=1, progress=False, finished=finished)
    assert [(c.policy, c.seed) for c in calls] == [("random", 1)]
    assert strip_times(summarise(again, again_oracles)) == strip_times(rows)
    # Another preset, scan budget or wall search is another comparison: --resume refuses to write
    # over its runs (it once replaced them, and the tables, unasked).
    for other in (
        grid(**{**TINY, "overrides": {"max_scans": 2}}),
        grid(**{**TINY, "overrides": {"max_scans": 3, "rooms.wall_search.scans": 1}}),
        grid(**{**TINY, "preset": "default"}),
    ):
        with pytest.raises(compare.CompareError, match=r"holds a finished run with"):
            compare.load_finished(resumed, other)


@pytest.mark.parametrize(
    ("damage", "runs", "oracles"),
    [
        ("metrics {}", 5, 1),  # once: every --resume failed the same way on the table's KeyError
        ("metrics []", 5, 1),
        ("oracle null", 6, 0),  # once: a TypeError when the next oracle was recorded
        ("oracle curve x", 6, 0),
    ],
)
def test_a_damaged_record_is_run_again_not_reused(tiny, damage, runs, oracles):
    import shutil

    import train.compare as compare

    specs, _, _, _, out = tiny
    damaged = out.parent / f"damaged-{damage.replace(' ', '-')}"
    shutil.copytree(out, damaged)
    run = damaged / "runs" / "l_room" / "random" / "seed1"
    if damage.startswith("metrics"):
        (run / "metrics.json").write_text(damage.split(" ", 1)[1])
    elif damage == "oracle null":
        (damaged / "oracle.json").write_text("null")
    else:
        stored = json.loads((damaged / "oracle.json").read_text())
        stored["l_room"]["coverage_pct"] = "x"
        (damaged / "oracle.json").write_text(json.dumps(stored))
    finished = compare.load_finished(damaged, specs)
    assert (len(finished["runs"]), len(finished["oracles"])) == (runs, oracles)
    # Recording an oracle over a damaged oracle.json starts it afresh rather than failing.
    compare.write_record(damaged, "oracle", {"scene": "l_room", "ok": False})
    assert json.loads((damaged / "oracle.json").read_text())["l_room"]["ok"] is False


def test_the_calibration_raises_epsilon_until_the_rule_ends_the_share_of_rooms():
    """The knee (most ε losing at most the allowed points) is kept unless the rule would then end
    fewer than the required share of rooms; then ε rises to the smallest that ends that share."""
    from train.calibrate_stops import replay, sweep

    def room(room, stats, added):
        pairs = zip(stats, added, strict=True)
        return [{"room": room, "statistic": s, "area_m2": 10.0, "added_pct": a} for s, a in pairs]

    # Twenty rooms: the gain of room k falls to k/10 and stays; each scan after the first adds 0.01 points.
    logs = [
        {"decisions": room(k, [50.0, 5.0, k / 10, k / 10], [10.0, 0.01, 0.01, 0.01]), "scans": 4, "coverage_pct": 10.0}
        for k in range(1, 21)
    ]
    assert replay(logs[0], 0.15) == (2, pytest.approx(0.02))  # stops at its third decision (0.1 < 0.15)
    assert replay(logs[0], 6.0) == (3, pytest.approx(0.03))
    # The forms: the statistic per (10 m²)^power. Per m², 5.0 is 0.5 (< 0.6): the second decision.
    assert replay(logs[0], 0.6, 1.0) == (3, pytest.approx(0.03))
    # Per √m², 5.0 is 1.58 (not below) and 0.1 is 0.032 (below): the third.
    assert replay(logs[0], 0.6, 0.5) == (2, pytest.approx(0.02))
    grid = [0.0, 0.5, 1.05, 1.95, 2.05, 10.0]
    loose = sweep(logs, grid, max_loss=1.0, min_rule_share=0.5)
    strict = sweep(logs, grid, max_loss=1.0, min_rule_share=0.95)
    # The knee: 10.0 loses 0.03 points a storey, within 1 point, and ends every room.
    assert loose["chosen"]["epsilon"] == strict["chosen"]["epsilon"] == 10.0
    tight = sweep(logs, grid, max_loss=0.0, min_rule_share=0.5)  # no loss allowed: the knee is ε = 0
    assert tight["knee"]["epsilon"] == 0.0
    assert tight["chosen"]["epsilon"] == 1.05 and tight["chosen"]["rooms_ended_by_rule"] == 10
    assert sweep(logs, grid, max_loss=0.0, min_rule_share=0.95)["chosen"]["epsilon"] == 1.95  # 19 of 20
    assert sweep(logs, grid, max_loss=0.0, min_rule_share=1.0)["chosen"]["epsilon"] == 2.05
    # A room the session ended first ("no NVP") is not the rule's to end: its high gain sets no ε.
    from train.calibrate_stops import rooms_to_end

    stuck = {
        "decisions": room(99, [50.0, 40.0], [10.0, 1.0]),
        "scans": 2,
        "coverage_pct": 10.0,
        "room_ends": [{"room": 99, "scans": 2, "reason": "no NVP"}],
    }
    assert rooms_to_end(stuck) == set() and rooms_to_end(logs[0]) == {1}
    with_stuck = sweep([*logs, stuck], grid, max_loss=0.0, min_rule_share=1.0)
    assert with_stuck["chosen"]["epsilon"] == 2.05 and with_stuck["rooms"] == 20
    stuck["room_ends"][0]["reason"] = "cap"  # ran to the cap: the rule must end it; no ε on the grid does
    assert sweep([*logs, stuck], grid, max_loss=0.0, min_rule_share=1.0)["chosen"]["epsilon"] == 10.0


def test_methods_table_tells_the_rule_from_the_cap_and_from_no_nvp_left():
    from train.compare import _methods_markdown

    def run(reasons):
        m = {"scans": 3, "structure_sensed_pct": 90.0, "processed_points": 10, "path_length_m": 5.0,
             "processing_time_s": 1.0, "acquisition_time_s": 1.0, "travel_time_s": 1.0, "rooms": [],
             "room_ends": [{"room": k, "scans": 2 if k == 4 else 1, "reason": r}
                           for k, r in enumerate(reasons)]}  # fmt: skip
        return {"spec": {"policy": "p", "scene": "s"}, "ok": True, "metrics": m}

    text = _methods_markdown([run(["declared", "cap", "no NVP", "gain", "no NVP"])], {})
    row = next(line for line in text.splitlines() if line.startswith("| p |"))
    # 5 rooms: 2 by the rule (40%), 1 by the cap, 2 with no NVP left, of which 1 after one scan
    # (room 2; room 4 had two).
    assert row.split(" | ")[2:7] == ["5", "40.0", "1", "2", "1"], row
    # A room whose measured floor holds no footprint of the robot (aisles narrower than it) is no
    # room whose candidates vanished: not counted after one scan.
    narrow = run(["declared", "cap", "no NVP", "gain", "no NVP"])
    narrow["metrics"]["room_ends"][2]["standing_room"] = 0
    row = next(line for line in _methods_markdown([narrow], {}).splitlines() if line.startswith("| p |"))
    assert row.split(" | ")[2:7] == ["5", "40.0", "1", "2", "0"], row


@pytest.mark.parametrize("name", ["ppo:../../outside", "ppo:/abs/run", "ppo:a/b", "..", "scenes/x.obj"])
def test_a_run_folder_is_one_component_inside_out(tmp_path, name):
    """A ppo:PATH or a file scene names its folder: it stays one path component under OUT/runs,
    and names that differ never share one."""
    from train.compare import _run_folder, folder_name

    component = folder_name(name)
    assert component and "/" not in component and component not in (".", "..")
    folder = _run_folder(tmp_path, {"scene": name, "policy": name, "seed": 0})
    assert folder.resolve().is_relative_to((tmp_path / "runs").resolve())
    assert folder_name("ppo:a/b") != folder_name("ppo:a_b")
    assert folder_name("greedy") == "greedy" and folder_name("ppo:reference") == "ppo_reference"


def test_resume_runs_again_where_the_building_file_changed(tmp_path, capsys):
    """Runs were matched by the scene's name only: an edited file's old results came back as they were.
    Probe 43: they were then run again without a word, as if reused; each is now named."""
    import shutil

    import train.compare as compare

    plan = tmp_path / "plan.json"
    shutil.copy(Path(__file__).parents[1] / "scenes" / "data" / "l_room.json", plan)
    specs = grid(str(plan), "random", "0", "fast", {"max_scans": 2})
    out = tmp_path / "out"
    results, oracles = run_grid(specs, jobs=1, progress=False)
    write_outputs(results, oracles, out)
    for record in results:
        compare.write_record(out, "run", record)
    for record in oracles.values():
        compare.write_record(out, "oracle", record)
    assert results[0]["source_sha256"] == compare.source_digest(str(plan)) is not None
    assert len(compare.load_finished(out, specs)["runs"]) == 1
    plan.write_text(plan.read_text().replace('"ceiling_height": 2.6', '"ceiling_height": 2.7'))
    capsys.readouterr()
    finished = compare.load_finished(out, specs)
    assert finished == {"runs": {}, "oracles": {}}
    folder = compare._run_folder(out, {"scene": str(plan), "policy": "random", "seed": 0})
    assert capsys.readouterr().err == (
        f"nbs compare: {folder}: its scene file changed since it ran; running it again (its result is replaced)\n"
    )
