"""``nbs compare``: the grid runs, a failed run is recorded, the table is complete and reproducible,
and the Ray backend gives the local backend's results."""

from __future__ import annotations

import csv
import json

import pytest

from train.cli import main
from train.compare import CompareError, expand_scenes, grid, run_grid, summarise, write_outputs

TINY = dict(scenes="l_room", policies="greedy,random,stachniss_burgard", seeds="0,1", preset="fast", max_scans=3)


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


def test_rerunning_reproduces_the_table(tiny):
    specs, _, _, rows, _ = tiny
    again = summarise(*run_grid(specs, jobs=1, progress=False))
    assert strip_times(again) == strip_times(rows)


def test_a_failed_run_is_recorded_and_the_others_go_on(tmp_path, capsys):
    code = main(["compare", "--scenes", "l_room,no_such_scene", "--policies", "greedy", "--seeds", "0",
                 "--preset", "fast", "--max-scans", "2", "--out", str(tmp_path), "--quiet"])  # fmt: skip
    assert code == 1
    err = capsys.readouterr().err
    assert "no_such_scene" in err and "UnknownSceneError" in err
    assert (tmp_path / "runs" / "no_such_scene" / "greedy" / "seed0" / "error.txt").exists()
    assert (tmp_path / "runs" / "l_room" / "greedy" / "seed0" / "metrics.json").exists()
    assert "1 of 1 runs failed" in (tmp_path / "table.md").read_text()


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
