"""The 3D replay (nbs_env.replay): a real episode recorded and read back with rerun's own reader."""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import nbs_env  # noqa: F401  (registers the gym ids)
from nbs_env.env import NBSEnv
from nbs_env.replay import (
    INSTALL_HINT,
    NotARecordingError,
    RunRecorder,
    check_recording,
    downsample,
    gain_colours,
    prism_strips,
    view,
)
from policies import GreedyPolicy

#: Small enough that every scan is thinned, so that the test sees the limit kept.
MAX_POINTS = 4000


def read_rows(path: Path) -> dict[str, list[dict]]:
    """The recording store of ``path`` as {entity path: rows}, each row {column: value}, through
    rerun's chunk reader (``rerun.chunk.RrdReader``: one pyarrow RecordBatch per chunk)."""
    import rerun as rr

    rows: dict[str, list[dict]] = defaultdict(list)
    for chunk in rr.chunk.RrdReader(path).stream():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n != "rerun.controls.RowId"]
        columns = {n: batch.column(n).to_pylist() for n in names}
        for i in range(batch.num_rows):
            rows[chunk.entity_path].append({n: columns[n][i] for n in names} | {"static": chunk.is_static})
    return rows


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """A fast five_rooms episode of the greedy, recorded step by step: (env, path, scans per step)."""
    pytest.importorskip("rerun")
    path = tmp_path_factory.mktemp("replay") / "five_rooms.rrd"
    # Five scans: on seed 0 the third decision ends the first room and crosses a door, two scans.
    env = NBSEnv("fast", scene="five_rooms", max_scans=5)
    policy = GreedyPolicy()
    per_step = []
    with RunRecorder(path, "five_rooms", max_points_per_scan=MAX_POINTS) as recorder:
        obs, info = env.reset(seed=0)
        recorder.log_step(env)
        per_step.append(len(env.storey.scans))
        done = False
        while not done:
            before = len(env.storey.scans)
            obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
            recorder.log_step(env)
            per_step.append(len(env.storey.scans) - before)
            done = terminated or truncated
    return env, path, per_step


def test_scan_timeline_has_one_entry_per_scan(episode):
    env, path, per_step = episode
    n = len(env.storey.scans)
    assert n == 5 and 2 in per_step, f"the episode must hold a two-scan step to test it, got {per_step}"
    rows = read_rows(path)
    indices = {row["scan"] for entity in rows.values() for row in entity if "scan" in row}
    assert indices == set(range(1, n + 1))
    # Each scan's points at its own index, in its own entity, thinned to the limit.
    for t in range(1, n + 1):
        below, above = rows[f"/world/scans/{t:03d}"], rows[f"/world/ceiling/scans/{t:03d}"]
        assert [r["scan"] for r in below] == [t] and [r["scan"] for r in above] == [t]
        kept = len(below[0]["Points3D:positions"]) + len(above[0]["Points3D:positions"])
        assert 0 < kept <= MAX_POINTS
    assert {k for k in rows if k.startswith("/world/scans/")} == {f"/world/scans/{t:03d}" for t in range(1, n + 1)}
    # The robot's position is logged at every scan, where the episode log says it was.
    positions = {r["scan"]: r["Points3D:positions"][0] for r in rows["/world/robot/position"]}
    for record in env.storey.scans:
        np.testing.assert_allclose(positions[record.scan + 1], record.estimated_position, atol=1e-5)


def test_truth_mesh_is_static_and_hidden_by_the_blueprint(episode):
    env, path, _ = episode
    rows = read_rows(path)
    mesh = rows["/world/truth/mesh"]
    assert len(mesh) == 1 and mesh[0]["static"]
    assert len(mesh[0]["Mesh3D:vertex_positions"]) == 3 * len(env.storey.scene.mesh.faces)
    import rerun as rr

    reader = rr.chunk.RrdReader(path)
    (blueprint,) = reader.blueprints()
    hidden = set()
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        override = "EntityBehavior:visible" in batch.schema.names and "/overrides/" in chunk.entity_path
        if override and batch.column("EntityBehavior:visible").to_pylist() == [[False]]:
            hidden.add(chunk.entity_path.split("/overrides/")[1].rsplit("/visualizers", 1)[0])
    assert "world/truth" in hidden


def test_plan_candidates_and_chosen_nbs(episode):
    env, path, per_step = episode
    rows = read_rows(path)
    scans = env.storey.scans
    # The NBS is marked at the index of the decision that chose it: before every scan that was not
    # the first or a door crossing's.
    marked = {r["scan"] for r in rows["/world/plan/nbs"] if r.get("Points3D:positions")}
    assert marked == {s.scan for s in scans if s.scan > 0 and not s.door}
    for r in rows["/world/plan/nbs"]:
        if r.get("Points3D:positions"):
            np.testing.assert_allclose(r["Points3D:positions"][0][:2], env.storey.paths[r["scan"] - 1][-1], atol=1e-5)
    # Candidates at the ends of steps while the episode was open; never at a scan inside a step.
    with_candidates = {r["scan"] for r in rows["/world/plan/candidates"] if r.get("Points3D:positions")}
    ends = np.cumsum(per_step)
    assert with_candidates and with_candidates <= set(ends.tolist())
    inside = {int(end) - 1 for end, count in zip(ends, per_step, strict=True) if count == 2}
    assert inside and not inside & with_candidates
    # The belief: voxels of both rooms, the RoI and SE faces.
    for room in (0, 1):
        assert rows[f"/world/belief/rooms/{room}/voxels/structure"]
        assert rows[f"/world/belief/rooms/{room}/roi"] and rows[f"/world/belief/rooms/{room}/se_faces"]
    assert rows["/world/belief/doors/0/frame"]


def test_a_late_recorder_logs_every_scan_and_warns(episode, tmp_path):
    env, first, _ = episode
    path = tmp_path / "late.rrd"
    with RunRecorder(path, "late") as recorder, pytest.warns(UserWarning, match="without their points"):
        recorder.log_step(env)
    rows = read_rows(path)
    assert {r["scan"] for r in rows["/world/robot/position"]} == set(range(1, len(env.storey.scans) + 1))
    # Two recorders in one process write two recordings, each to its own file.
    import rerun as rr

    ids = {rr.chunk.RrdReader(p).recordings()[0].recording_id for p in (first, path)}
    assert len(ids) == 2


def test_a_recorder_holds_one_episode(tmp_path):
    pytest.importorskip("rerun")
    env = gym.make("nbs_env/NBS-Fast-v0", scene="l_room", max_scans=2)  # through gym.make's wrappers
    recorder = RunRecorder(tmp_path / "one.rrd", "l_room")
    with pytest.raises(RuntimeError, match="reset"):
        recorder.log_step(env)
    env.reset(seed=0)
    recorder.log_step(env)
    env.reset(seed=1)
    with pytest.raises(RuntimeError, match="one episode"):
        recorder.log_step(env)
    recorder.close()
    recorder.close()
    with pytest.raises(RuntimeError, match="closed"):
        recorder.log_step(env)


def test_view_refuses_a_missing_file_and_a_file_that_is_no_recording(tmp_path):
    with pytest.raises(FileNotFoundError, match="no recording at"):
        view(tmp_path / "missing.rrd")
    other = tmp_path / "metrics.rrd"
    other.write_text("{}")
    with pytest.raises(NotARecordingError, match="not a rerun recording"):
        view(other)


def test_missing_rerun_gives_the_install_hint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)
    monkeypatch.setitem(sys.modules, "rerun.blueprint", None)
    with pytest.raises(ImportError, match=r'pip install "nbs-env\[viz\]"'):
        RunRecorder(tmp_path / "x.rrd", "x")
    fake = tmp_path / "x.rrd"
    fake.write_bytes(b"RRF2" + bytes(16))
    with pytest.raises(ImportError) as error:
        view(fake)
    assert INSTALL_HINT in str(error.value)


def test_max_points_per_scan_must_be_positive(tmp_path):
    pytest.importorskip("rerun")
    with pytest.raises(ValueError, match="max_points_per_scan"):
        RunRecorder(tmp_path / "x.rrd", "x", max_points_per_scan=0)


def test_downsample_is_a_deterministic_stride():
    points = np.arange(30.0).reshape(10, 3)
    assert downsample(points, 10) is points
    np.testing.assert_array_equal(downsample(points, 4), points[::3])
    for n in (1, 7, 1000, 1001, 144_000):
        for limit in (1, 3, 999, 50_000):
            assert 1 <= len(downsample(np.zeros((n, 3)), limit)) <= min(n, limit)


def test_gain_colours_and_prism_strips():
    colours = gain_colours(np.array([0, 5, 10]))
    assert colours.dtype == np.uint8 and colours.shape == (3, 3)
    np.testing.assert_array_equal(colours[0], [68, 1, 84])  # viridis' lowest
    np.testing.assert_array_equal(colours[2], [253, 231, 37])  # and highest
    assert gain_colours(np.zeros(2)).shape == (2, 3) and gain_colours(np.zeros(0)).shape == (0, 3)
    strips = prism_strips(np.array([[0, 0], [4, 0], [4, 3], [0, 3]]), 0.0, 2.5)
    assert len(strips) == 2 + 4
    assert strips[0].shape == (5, 3) and np.all(strips[0][:, 2] == 0.0) and np.all(strips[1][:, 2] == 2.5)
    np.testing.assert_array_equal(strips[2], [[0, 0, 0], [0, 0, 2.5]])


def test_nbs_scan_record_writes_one_timeline_entry_per_scan(tmp_path, capsys):
    """``nbs scan --record`` records the run it reports: one ``scan`` entry per scan of metrics.json."""
    import json

    from train.cli import main

    pytest.importorskip("rerun")
    out, rrd = tmp_path / "report", tmp_path / "run.rrd"
    args = ["scan", "--scene", "l_room", "--resolution", "1", "--voxel", "0.1", "--max-scans", "3"]
    assert main([*args, "--out", str(out), "--record", str(rrd), "--no-steps", "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    rows = read_rows(rrd)
    scans = {row["scan"] for entity, rs in rows.items() if entity.startswith("/world/scans/") for row in rs}
    assert scans == set(range(1, metrics["scans"] + 1)) and metrics["scans"] == 3
    assert "nbs view" in capsys.readouterr().out
    # A recording's name must say what it is; nbs view refuses what is none.
    assert main([*args, "--out", str(out), "--record", str(tmp_path / "run.txt"), "--quiet"]) == 2
    assert main(["view", str(tmp_path / "missing.rrd")]) == 1
    (tmp_path / "bad.rrd").write_text("not a recording")
    assert main(["view", str(tmp_path / "bad.rrd")]) == 1
    assert "not a rerun recording" in capsys.readouterr().err


def test_a_recording_is_at_its_name_only_once_whole(tmp_path, monkeypatch, capsys):
    """The recording is written under a temporary name and renamed when the run ends: a run that
    fails leaves no file at --record (nbs view served half a recording; the same command then
    refused to run again because the file existed), a run that ends leaves a whole one."""
    pytest.importorskip("rerun")
    from train.cli import main

    monkeypatch.chdir(tmp_path)
    failing = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "2", "--quiet", "--no-steps"]
    code = main([*failing, "--out", "bad", "--record", "bad.rrd", "--start", "500,500"])  # outside the building
    assert code == 1 and "not free floor" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no recording, no temporary file
    assert main([*failing, "--out", "good", "--record", "good.rrd"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good", "good.rrd"]
    assert check_recording(tmp_path / "good.rrd") == tmp_path / "good.rrd"
