"""Bad input at every door: a message and an exit code, never a traceback, a hang or silent acceptance."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from train.cli import EXIT_SCENE_ERROR, EXIT_USAGE, main

#: (command line, exit code, a piece of the message). Every numeric flag with the kinds of bad value
#: a user types: negative, zero, NaN, inf, huge, not a number; outputs the writer cannot make;
#: options the subcommand does not take.
CASES = [
    # nbs scan
    ("scan --scene office --seed=-1", EXIT_USAGE, "a seed is an integer >= 0"),
    ("scan --scene office --seed 1.5", EXIT_USAGE, "expected an integer"),
    ("scan --scene office --max-scans 0", EXIT_USAGE, "expected an integer >= 1"),
    ("scan --scene office --max-scans x", EXIT_USAGE, "expected an integer"),
    ("scan --scene office --wall-search -1", EXIT_USAGE, "expected an integer >= 0"),
    ("scan --scene office --resolution 0", EXIT_USAGE, "angular_step must be > 0"),
    ("scan --scene office --resolution nan", EXIT_USAGE, "angular_step must be a finite number"),
    ("scan --scene office --resolution inf", EXIT_USAGE, "angular_step must be a finite number"),
    ("scan --scene office --resolution 0.0001", EXIT_USAGE, "rays per scan"),
    ("scan --scene office --resolution 1e-320", EXIT_USAGE, "rays per scan"),
    # A name longer than the file system takes (255 bytes): an OSError once escaped the checks.
    (f"scan --scene office --out {'b' * 300}", EXIT_USAGE, "cannot be used (File name too long)"),
    (f"scenes info {'b' * 300}.obj", EXIT_SCENE_ERROR, "File name too long"),
    # Names whose bytes are not UTF-8 (as Python holds them: surrogates) once failed halfway through a
    # report, in libE57, matplotlib or rerun.
    ("scan --scene office --out e4_\udcff_dir", EXIT_USAGE, "--out e4_\ufffd_dir: the name is not valid UTF-8"),
    ("scan --scene p_\udcff.json", EXIT_USAGE, "the name is not valid UTF-8; rename it"),
    ("compare --scenes p_\udcff.json --policies random --out c", EXIT_USAGE, "the name is not valid UTF-8"),
    ("scan --scene office --min-density 1e300", EXIT_USAGE, "min_density must be within [0, 1e8]"),
    # Sizes every grid, table or window is made from, bounded before any is made (each once asked
    # for more memory than the machine had, or overflowed to infinity with a warning).
    ("scan --scene office --set coverage_spacing=1e-6", EXIT_USAGE, "coverage_spacing must be within [0.01, 1]"),
    ("scan --scene office --set robot.navigation.lattice=1e-5", EXIT_USAGE, "lattice must be within [0.05, 5]"),
    ("scan --scene office --set robot.navigation.max_candidates=1000000000", EXIT_USAGE, "max_candidates must be"),
    ("scan --scene office --set robot.roi.pixel=1e-7", EXIT_USAGE, "pixel must be within [0.005, 1]"),
    ("scan --scene office --set robot.roi.histogram_bin=1e-9", EXIT_USAGE, "histogram_bin must be within"),
    ("scan --scene office --set robot.roi.azimuth_bins=1000000000", EXIT_USAGE, "azimuth_bins must be at most"),
    ("scan --scene office --set observation.shape=[100000,100000,100000]", EXIT_USAGE, "cells; at most 4,194,304"),
    ("scan --scene office --set quality.density_radius=1e9", EXIT_USAGE, "density_radius must be within (0, 1]"),
    ("scan --scene office --set robot.scanner.max_range=1e300", EXIT_USAGE, "max_range must be at most 10,000 m"),
    ("scan --scene office --set robot.scanner.setup_time=1e300", EXIT_USAGE, "setup_time must be within"),
    ("scan --scene office --set expose_belief=1", EXIT_USAGE, "expose_belief must be a bool"),
    ("scan --scene office --voxel nan", EXIT_USAGE, "voxel_size must be a finite number"),
    ("scan --scene office --voxel 1e9", EXIT_USAGE, "voxel_size must be within [0.01, 1] metres"),
    ("scan --scene office --preset slow", EXIT_USAGE, "--preset: invalid choice: 'slow'"),
    ("scan --scene office --scanner nope", EXIT_USAGE, "unknown scanner 'nope'"),
    ("scan --scene office --set robot.voxels=0.1", EXIT_USAGE, "--set robot.voxels: the configuration has no"),
    ("scan --scene office --set voxel", EXIT_USAGE, "expected KEY=VALUE"),
    ('scan --scene office --set scene="l_room"', EXIT_USAGE, "--set scene: the command's --scene"),
    ("scan --scene office --set keep_scans=false", EXIT_USAGE, "--set keep_scans: the command decides"),
    ("scan --scene office --set scene_options={}", EXIT_USAGE, "--set scene_options: --storey, --ifc-doors"),
    ("compare --scenes office --policies greedy --set preset=1 --out c", EXIT_USAGE, "--set preset: use --preset"),
    ("scan --scene office --voxel 0.1 --set robot.voxel_size=0.2", EXIT_USAGE, "both set robot.voxel_size"),
    ("scan --scene office --set rooms.completion=never", EXIT_USAGE, "completion must be 'gain' or 'policy'"),
    ("scan --scene office --policy ppo:reference --wall-search 0", EXIT_USAGE, "pass --wall-search 3"),
    ("scan --scene office --y-up", EXIT_USAGE, "--y-up applies to labelled meshes"),
    ("scan --scene office --storey 0", EXIT_USAGE, "--storey applies to .ifc files only"),
    ("scan --scene office --units mm", EXIT_USAGE, "--units applies to labelled meshes"),
    ("scan --scene office --units yd", EXIT_USAGE, "--units: invalid choice: 'yd'"),
    ("scan --scene office --start nan,1", EXIT_USAGE, "expected finite X,Y"),
    ("scan --scene office --policy nope", EXIT_USAGE, "unknown policy"),
    ("scan --scene office --policy greedy:x", EXIT_USAGE, "greedy takes NEAR, the share of the best gain"),
    ("scan --scene office --policy greedy:stop=1.5", EXIT_USAGE, "stop=FRACTION, the completion fraction"),
    ("scan --scene office --policy random:x", EXIT_USAGE, "takes no option"),
    ("scan --scene office --policy information_gain:psychic", EXIT_USAGE, "unknown formulation"),
    ("scan --scene office --policy information_gain:", EXIT_USAGE, "the option after the colon is empty"),
    ("scan --scene office --policy greedy:", EXIT_USAGE, "the option after the colon is empty"),
    ("scan --scene office --policy information_gain:+controlled", EXIT_USAGE, "an empty part around '+'"),
    ("scan --scene office --policy information_gain:rear_side_voxel+", EXIT_USAGE, "an empty part around '+'"),
    ("scan --scene nowhere", EXIT_SCENE_ERROR, "no bundled scene"),
    # nbs scenes
    ("scenes generate --seed=-1 --out p.json", EXIT_USAGE, "a seed is an integer >= 0"),
    ("scenes generate --seed 1 --clutter-density inf --out p.json", EXIT_USAGE, "within 0..10"),
    ("scenes generate --seed 1 --clutter-density nan --out p.json", EXIT_USAGE, "within 0..10"),
    ("scenes generate --seed 1 --clutter-density 1e6 --out p.json", EXIT_USAGE, "within 0..10"),
    ("scenes generate --seed 1 --clutter-density -1 --out p.json", EXIT_USAGE, "within 0..10"),
    ("scenes generate --seed 1 --rooms 0 --out p.json", EXIT_USAGE, "integers 1 <= A <= B <= 8"),
    ("scenes generate --seed 1 --rooms 9-12 --out p.json", EXIT_USAGE, "integers 1 <= A <= B <= 8"),
    ("scenes generate --seed 1 --rooms a-b --out p.json", EXIT_USAGE, "rooms must be N or A-B"),
    ("scenes generate --seed 1 --out p.json --show plan.xyz", EXIT_USAGE, "a picture file ends in one of"),
    ("scenes show office --out top.xyz", EXIT_USAGE, "a picture file ends in one of"),
    ("scenes show office --out no/dir/top.png", EXIT_USAGE, "--out no/dir/top.png: its folder no/dir does not exist"),
    ("scenes generate --seed 1 --out no/p.json", EXIT_USAGE, "--out no/p.json: its folder no does not exist"),
    ("scenes generate --seed 1 --out p.json --show no/p.png", EXIT_USAGE, "--show no/p.png: its folder no does not"),
    ("scenes show office --out topnoext", EXIT_USAGE, "a picture file ends in one of"),
    ("scenes info office --y-up", EXIT_USAGE, "--y-up applies to labelled meshes"),
    ("scenes info five_rooms --storey 0", EXIT_USAGE, "--storey applies to .ifc files only"),
    ("scenes info office --units cm", EXIT_USAGE, "IFC files carry their own units, floor plans are metres"),
    ("scenes show five_rooms --storey Erdgeschoss --out t.png", EXIT_USAGE, "--storey applies to .ifc files"),
    # nbs compare
    ("compare --scenes office --policies greedy --seeds -1 --out c", EXIT_USAGE, "seeds are integers >= 0"),
    ("compare --scenes office --policies greedy --seeds x --out c", EXIT_USAGE, "comma-separated integers"),
    ("compare --scenes office --policies greedy --jobs 0 --out c", EXIT_USAGE, "expected an integer >= 1"),
    ("compare --scenes office --policies greedy --max-scans 0 --out c", EXIT_USAGE, "expected an integer >= 1"),
    ("compare --scenes office --policies greedy --wall-search x --out c", EXIT_USAGE, "expected an integer"),
    ("compare --scenes generated:5-2 --policies greedy --out c", EXIT_USAGE, "generated:A-B"),
    # A range is bounded before its seeds are listed: this one was a MemoryError.
    ("compare --scenes generated:0-100000000000 --policies greedy --out c", EXIT_USAGE, "at most 100,000"),
    ("compare --scenes office --policies greedy --jobs 100000 --out c", EXIT_USAGE, "--jobs 100000: this machine has"),
    ("compare --scenes office --policies greedy --resume --force --out c", EXIT_USAGE, "pass one of them"),
    # Every scene's source is found before any run (each once became a failed run and its files).
    ("compare --scenes nope --policies random --out c", EXIT_USAGE, "nope: no bundled scene of that name"),
    ("compare --scenes office,missing.obj --policies random --out c", EXIT_USAGE, "missing.obj: no such file"),
    ("compare --scenes corpus:nope --policies random --out c", EXIT_USAGE, "corpus:nope: no corpus entry"),
    ("compare --scenes plan.txt --policies random --out c", EXIT_USAGE, "unsupported file type '.txt'"),
    ("compare --scenes office --policies information_gain: --out c", EXIT_USAGE, "the option after the colon"),
    ("compare --scenes office --policies nope --out c", EXIT_USAGE, "unknown policy"),
    ("compare --scenes office --policies greedy --storey 0 --out c", EXIT_USAGE, "--storey applies to .ifc files"),
    ("compare --scenes office --policies greedy --units mm --out c", EXIT_USAGE, "--units applies to labelled meshes"),
    ("compare --scenes office --policies greedy --voxel 5 --out c", EXIT_USAGE, "voxel_size must be within"),
    ("compare --scenes office --policies greedy --set robot=1 --out c", EXIT_USAGE, "robot must be a JSON object"),
    # a run counted twice would weigh twice in the table's means
    ("compare --scenes office --policies greedy --seeds 0,0,0 --out c", EXIT_USAGE, "--seeds names 0 (3 times)"),
    ("compare --scenes office --policies greedy --seeds 1,01 --out c", EXIT_USAGE, "--seeds names 1 (2 times)"),
    ("compare --scenes office --policies random,greedy,random --out c", EXIT_USAGE, "--policies names random (2"),
    ("compare --scenes generated:1-3,generated:2 --policies greedy --out c", EXIT_USAGE, "generated:2 (2 times)"),
    # nbs train (its checks live in TrainConfig)
    ("train --envs 0 --out t", EXIT_USAGE, "envs must be an integer >= 1"),
    ("train --n-steps 0 --out t", EXIT_USAGE, "n_steps must be an integer >= 1"),
    ("train --learning-rate nan --out t", EXIT_USAGE, "learning_rate must be a finite number"),
    ("train --learning-rate -1 --out t", EXIT_USAGE, "learning_rate must be within (0, 0.1], got -1"),
    ("train --metre-cost inf --out t", EXIT_USAGE, "metre_cost must be a finite number"),
    ("train --scan-cost -0.5 --out t", EXIT_USAGE, "scan_cost must be within [0, 1,000], got -0.5"),
    ("train --ent-coef nan --out t", EXIT_USAGE, "ent_coef must be a finite number"),
    ("train --wall-search -1 --out t", EXIT_USAGE, "expected an integer >= 0"),
    ("train --storey 0 --out t", EXIT_USAGE, "--storey applies to .ifc files only"),
    ("train --units mm --out t", EXIT_USAGE, "--units applies to labelled meshes"),
    ("train --scanner rtc360:9mm --out t", EXIT_USAGE, "has no setting '9mm'"),
    ("train --completion never --out t", EXIT_USAGE, "--completion: invalid choice: 'never'"),
    ("train --max-episode-steps 0 --out t", EXIT_USAGE, "max_episode_steps must be an integer >= 1"),
    ("train --cell-size 1-2 --out t", EXIT_USAGE, "cell_size must be (A, B) metres with 1.8 <= A <= B <= 10"),
    ("train --cell-size wide --out t", EXIT_USAGE, "--cell-size: expected A-B in metres, got 'wide'"),
    ("train --init nowhere --out t", EXIT_USAGE, "--init: nowhere: no such checkpoint"),
    ("train --rooms 9-12 --out t", EXIT_USAGE, "rooms must be (A, B) with 1 <= A <= B <= 8"),
    ("train --rooms x --out t", EXIT_USAGE, "expected N or A-B"),
    ("train --timesteps -5 --out t", EXIT_USAGE, "timesteps must be an integer >= 1"),
    ("train --seed -1 --out t", EXIT_USAGE, "seed must be an integer >= 0"),
    ("train --eval-storeys 0 --out t", EXIT_USAGE, "eval_storeys must be an integer >= 1"),
    ("train --eval-storeys 99999999999 --out t", EXIT_USAGE, "eval_storeys must be at most 10,000"),
    ("train --n-steps 1 --envs 1 --out t", EXIT_USAGE, "n_steps x envs must be at least 2"),
    ("train --bc-teacher random --out t", EXIT_USAGE, "bc_teacher must name a greedy"),
    ("train --bc-teacher greedy:stop=2 --out t", EXIT_USAGE, "bc_teacher: greedy takes"),
    ("train --bc-teacher nope --out t", EXIT_USAGE, "bc_teacher must name a greedy (greedy or greedy:OPTIONS)"),
    # What the options make a run claim is sized before anything is built (23.8 GiB asked of numpy once).
    ("train --n-steps 100000000 --out t", EXIT_USAGE, "--n-steps 100000000 x --envs 2 asks for rollouts of"),
    ("train --bc-steps 100000000 --out t", EXIT_USAGE, "lower --bc-steps or --envs"),
    ("train --backend ray --address nohost --out t", EXIT_USAGE, "--address 'nohost': expected HOST:PORT"),
    # The run folder, checked before the workers start (it was once found at the first checkpoint).
    ("train --out no/run", EXIT_USAGE, "--out no/run: its folder no does not exist"),
    ("train --out /dev/null", EXIT_USAGE, "--out /dev/null: exists and is not a folder"),
    ("train --out /dev/null/run", EXIT_USAGE, "--out /dev/null/run: /dev/null is not a folder"),
    ("train --out /proc/run", EXIT_USAGE, "--out /proc/run: cannot make a file in /proc"),
]


def run_cli(args: str, capsys) -> tuple[int, str]:
    return run_cli_list(args.split(), capsys)


def run_cli_list(args: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    return code, capsys.readouterr().err


def _case(args: str, code: int, message: str):
    # nbs train needs the rl extra; without it, it says so and exits.
    marks = pytest.mark.skipif(args.startswith("train") and not _has_rl(), reason="needs the rl extra")
    return pytest.param(args, code, message, marks=marks, id=args)


def _has_rl() -> bool:
    import importlib.util

    return importlib.util.find_spec("sb3_contrib") is not None


@pytest.mark.parametrize(("args", "code", "message"), [_case(*c) for c in CASES])
def test_bad_command_lines_say_what_and_exit(tmp_path, monkeypatch, capsys, args, code, message):
    monkeypatch.chdir(tmp_path)
    got, err = run_cli(args, capsys)
    assert (got, message in err) == (code, True), err
    # Refused before any work: nothing was written.
    assert not any(tmp_path.iterdir()), sorted(p.name for p in tmp_path.iterdir())


def test_compare_refuses_an_unwritable_out_before_running(tmp_path, monkeypatch, capsys):
    import train.compare

    def never(*args, **kwargs):
        raise AssertionError("a run started although --out cannot be written")

    monkeypatch.setattr(train.compare, "run_one", never)
    blocker = tmp_path / "file"
    blocker.write_text("")
    for out in (blocker, blocker / "below"):
        code, err = run_cli(f"compare --scenes office --policies greedy --out {out} --quiet", capsys)
        assert code == EXIT_USAGE and f"--out {out}" in err


def _report(folder: Path) -> Path:
    """A folder an earlier ``nbs scan`` left: its metrics.json."""
    folder.mkdir()
    (folder / "metrics.json").write_text('{"old": true}')
    return folder


#: (arguments after ``scan --scene l_room``, a piece of the message): outputs that once were found
#: bad only after the scan (a folder or a path under /proc for --record: rerun's RuntimeError), were
#: quietly made (a recording's missing folders), or were written over (an earlier report, ``--out ''``
#: as the working folder).
OUTPUTS = [
    ("--record {tmp}", "--record {tmp}: is a folder; name a file in it (e.g. {tmp}/run.rrd)"),
    ("--record /proc/r.rrd", "--record /proc/r.rrd: cannot make a file in /proc"),
    ("--record {tmp}/no/dir/r.rrd", "--record {tmp}/no/dir/r.rrd: its folder {tmp}/no/dir does not exist"),
    ("--record {tmp}/old.rrd", "--record {tmp}/old.rrd: exists; pass --force to overwrite it"),
    ("--out {tmp}/no/report", "--out {tmp}/no/report: its folder {tmp}/no does not exist"),
    ("--out /proc/report", "--out /proc/report: cannot make a file in /proc"),
    ("--out {tmp}/report.txt", "--out {tmp}/report.txt: exists and is not a folder"),
    ("--out {tmp}/old", "--out {tmp}/old: is not empty (it holds metrics.json); pass --force to overwrite it"),
]


@pytest.mark.parametrize(("args", "message"), OUTPUTS, ids=[a for a, _ in OUTPUTS])
def test_scan_checks_its_outputs_before_it_scans(tmp_path, monkeypatch, capsys, args, message):
    import train.cli

    if "/proc" in args and not Path("/proc/self").is_dir():
        pytest.skip("no /proc here")
    if args.startswith("--record"):
        pytest.importorskip("rerun")
    monkeypatch.setattr(train.cli, "_scan", lambda *a: pytest.fail("the scan started although an output is bad"))
    monkeypatch.chdir(tmp_path)
    _report(tmp_path / "old")
    (tmp_path / "old.rrd").write_bytes(b"an earlier recording")
    (tmp_path / "report.txt").write_text("")
    before = sorted(tmp_path.rglob("*"))
    args = args.format(tmp=tmp_path)
    code, err = run_cli(f"scan --scene l_room --preset fast --max-scans 3 --no-steps --quiet {args}", capsys)
    assert code == EXIT_USAGE and err.startswith(f"nbs scan: error: {message.format(tmp=tmp_path)}"), err
    assert len(err.strip().splitlines()) == 1, err
    assert sorted(tmp_path.rglob("*")) == before  # nothing made, nothing written over
    assert (tmp_path / "old" / "metrics.json").read_text() == '{"old": true}'


@pytest.mark.parametrize("command", ["scan --scene l_room --out", "compare --scenes l_room --policies greedy --out"])
def test_an_empty_out_is_no_folder(tmp_path, monkeypatch, capsys, command):
    """``--out ''`` once became Path('.'), the working folder."""
    monkeypatch.chdir(tmp_path)
    code, err = run_cli_list([*command.split(), ""], capsys)
    assert code == EXIT_USAGE and "argument --out: an empty path names no file or folder" in err, err
    assert not any(tmp_path.iterdir())


def test_scan_force_writes_over_an_earlier_report(tmp_path, monkeypatch, capsys):
    import train.cli

    ran = []
    monkeypatch.setattr(train.cli, "_scan", lambda args, policy, out, config, stop: ran.append(out) or 0)
    old = _report(tmp_path / "old")
    (tmp_path / "old.rrd").write_bytes(b"an earlier recording")
    code, err = run_cli(f"scan --scene l_room --out {old} --record {tmp_path / 'old.rrd'} --force --quiet", capsys)
    assert code == 0 and ran == [old], err


def test_compare_refuses_an_earlier_comparison_without_resume_or_force(tmp_path, monkeypatch, capsys):
    import train.compare

    class StartedError(Exception):
        pass

    def started(*args, **kwargs):
        raise StartedError

    monkeypatch.setattr(train.compare, "run_one", lambda *a: pytest.fail("a run started"))
    out = tmp_path / "grid"
    out.mkdir()
    (out / "table.csv").write_text("an earlier comparison's table\n")
    command = f"compare --scenes l_room --policies greedy --out {out} --quiet"
    code, err = run_cli(command, capsys)
    assert code == EXIT_USAGE, err
    assert err.strip() == (
        f"nbs compare: error: --out {out}: is not empty (it holds table.csv); pass --resume to continue that "
        "comparison, or --force to write over it, or choose another folder"
    )
    # With either flag the grid starts.
    monkeypatch.setattr(train.compare, "run_grid", started)
    for flag in ("--resume", "--force"):
        with pytest.raises(StartedError):
            main([*command.split(), flag])


@pytest.mark.parametrize(("name", "make"), [("runs", "file"), ("oracle.json", "folder"), ("table.md", "folder")])
def test_compare_refuses_a_folder_whose_parts_are_of_the_wrong_kind_before_running(
    tmp_path, monkeypatch, capsys, name, make
):
    """``runs`` as a file or ``oracle.json`` as a folder were found when the first run was recorded."""
    import train.compare

    monkeypatch.setattr(train.compare, "run_grid", lambda *a, **k: pytest.fail("the grid started"))
    out = tmp_path / "grid"
    out.mkdir()
    (out / name).mkdir() if make == "folder" else (out / name).write_text("")
    code, err = run_cli(f"compare --scenes l_room --policies greedy --out {out} --resume --quiet", capsys)
    what = "is not a folder" if make == "file" else "is a folder"
    assert (code, err) == (
        EXIT_USAGE,
        f"nbs compare: error: --out {out}: {out / name} {what}; move it away or choose another --out\n",
    )


def test_compare_with_a_run_record_turned_folder_says_so_in_one_line(tmp_path, capsys):
    out = tmp_path / "grid"
    command = f"compare --scenes office --policies random --preset fast --max-scans 2 --out {out} --quiet"
    assert run_cli(command, capsys)[0] == 0
    record = out / "runs" / "office" / "random" / "seed0" / "run.json"
    record.unlink()
    record.mkdir()
    code, err = run_cli(command + " --resume", capsys)
    # Refused before any run: found at the write, it cost the run.
    assert code == EXIT_USAGE and err.strip().splitlines() == [
        f"nbs compare: error: --out {out}: {record} is a folder; the comparison's files must be its own: replace it "
        "by the file or remove it, or choose another --out"
    ]


def test_compare_writes_each_run_as_it_finishes_and_keeps_them_when_the_summary_fails(tmp_path, monkeypatch, capsys):
    import train.compare

    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(train.compare, "summarise", broken)
    out = tmp_path / "grid"
    code, err = run_cli(
        f"compare --scenes office --policies random --preset fast --max-scans 2 --out {out} --quiet", capsys
    )
    assert code == EXIT_SCENE_ERROR and "summary failed" in err and "--resume" in err
    run = json.loads((out / "runs" / "office" / "random" / "seed0" / "run.json").read_text())
    assert run["ok"] and (out / "runs" / "office" / "random" / "seed0" / "metrics.json").is_file()
    assert "ZeroDivisionError" in (out / "summary_error.txt").read_text()
    assert json.loads((out / "oracle.json").read_text())["office"]["ok"]


def test_compare_on_a_roomless_mesh_writes_its_table(tmp_path, capsys):
    """A labelled mesh without rooms: the evaluation derives them from the floor's free space, the
    coverage counts by geometry, and the table comes with the oracle's share."""
    import trimesh

    from scenes import SurfaceClass, load_scene

    office = load_scene("office")
    mesh = trimesh.Scene()
    for cls in SurfaceClass:
        faces = np.flatnonzero(office.face_labels == cls)
        if len(faces):
            part = office.mesh.submesh([faces], append=True)
            mesh.add_geometry(part, geom_name=f"{cls.name.lower()}_all", node_name=f"{cls.name.lower()}_all")
    path = tmp_path / "roomless.glb"
    mesh.export(path)
    assert load_scene(str(path)).metadata["rooms"] == "derived"
    out = tmp_path / "grid"
    code, _ = run_cli(
        f"compare --scenes {path} --policies random --preset fast --max-scans 2 --out {out} --quiet", capsys
    )
    assert code == 0
    table = (out / "table.md").read_text()
    assert "roomless.glb" in table
    total = next(line for line in table.splitlines() if "roomless.glb" in line and "| total |" in line)
    assert "–" not in total.split("|")[-4], total  # the share of the oracle's coverage is there


def test_a_mesh_in_millimetres_is_refused_with_the_unit_to_pass(tmp_path, monkeypatch, capsys):
    """Read as metres, a 10 m x 8 m room drawn in millimetres once made the scan ask for 381 GiB; now
    nbs scan and nbs scenes say which --units to pass, in one line, and with it the storey loads."""
    import trimesh

    from scenes import load_scene
    from train.arguments import config_from_arguments
    from train.cli import build_parser

    sc = trimesh.Scene()
    for name, (x, y, z) in {"floor": (10, 8, 0.01), "wall": (0.1, 8, 2.5)}.items():
        box = trimesh.creation.box(extents=(x, y, z))
        box.apply_translation((x / 2, y / 2, z / 2))
        sc.add_geometry(box, node_name=name, geom_name=name)
    metres = tmp_path / "room_m.glb"
    sc.export(metres)
    sc.apply_scale(1000.0)
    path = tmp_path / "room_mm.glb"
    sc.export(path)
    monkeypatch.chdir(tmp_path)
    for command in (f"scan --scene {path} --quiet --out scan", f"scenes info {path}"):
        code, err = run_cli(command, capsys)
        assert code == EXIT_SCENE_ERROR, err
        assert "the storey is 10,000 m across" in err and "pass --units mm" in err, err
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "scan").exists()
    code, _ = run_cli(f"scenes info {path} --units mm", capsys)
    assert code == 0
    # nbs scan hands --units to the storey's loader through the configuration.
    args = build_parser().parse_args(["scan", "--scene", str(path), "--units", "mm"])
    _, overrides = config_from_arguments(args, "default")
    assert overrides["scene_options"] == {"units": "mm"}
    scene = load_scene(str(path), **overrides["scene_options"])
    assert scene.bounds == pytest.approx(load_scene(str(metres)).bounds)


def test_the_unit_names_are_the_loaders():
    from scenes.limits import UNITS
    from train.arguments import UNIT_NAMES

    assert tuple(UNITS) == UNIT_NAMES


def test_a_storey_named_like_an_index_wins_over_the_index():
    """--storey 1 was always read as the index 1, even where a storey is named "1": the option keeps
    the text, a name that matches exactly wins, and only then is an integer an index (its help says so)."""
    from scenes import IfcError
    from scenes.ifc import _select_storey, _Storey
    from train.arguments import STOREY_HELP
    from train.cli import build_parser

    for command in (["scenes", "info", "x.ifc"], ["scan", "--scene", "x.ifc"]):
        assert build_parser().parse_args([*command, "--storey", "1"]).storey == "1"
    assert "a storey named exactly as given wins over the index" in STOREY_HELP
    storeys = [_Storey(None, "1", "", 0.0), _Storey(None, "OG", "Level 2", 3.0)]
    assert _select_storey("x.ifc", storeys, "1") == 0  # the name, not the index 1
    assert _select_storey("x.ifc", storeys, "Level 2") == 1
    assert _select_storey("x.ifc", storeys, "-1") == 1  # no storey of that name: the index
    assert _select_storey("x.ifc", storeys, 1) == 1  # an int (the Python API) is always an index
    with pytest.raises(IfcError, match=r"no storey named '5', and index 5 is out of range; storeys: 0: '1'"):
        _select_storey("x.ifc", storeys, "5")
    with pytest.raises(IfcError, match=r"no storey named 'EG'"):
        _select_storey("x.ifc", storeys, "EG")


def test_an_ifc_storey_named_1_is_the_one_storey_1_loads(tmp_path, capsys):
    """tests/data/two_rooms.ifc with its ground storey (index 0) renamed "1": --storey 1 loads it, where
    the index 1, the upper storey without walls, is refused."""
    pytest.importorskip("ifcopenshell")
    from pathlib import Path

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    path = tmp_path / "named_1.ifc"
    path.write_text(text.replace("$,'EG',$", "$,'1',$", 1))
    assert main(["scenes", "info", str(path), "--storey", "1"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["name"].endswith("#1") and len(info["rooms"]) == 2
    code, err = run_cli(f"scenes info {path} --storey OG", capsys)
    assert code == EXIT_SCENE_ERROR and "no wall faces" in err


# ------------------------------------------------------------- the environment the command runs in
@pytest.mark.parametrize("value", ["100000", "abc", "1.5", "99999999999999999999", "0"])
def test_a_bad_nbs_threads_is_refused_before_any_work(tmp_path, monkeypatch, capsys, value):
    """10⁵ threads once crashed the process (a segfault, a report of metrics.json alone)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NBS_THREADS", value)
    code, err = run_cli(f"scan --scene l_room --preset fast --max-scans 1 --quiet --out {tmp_path / 'r'}", capsys)
    assert code == EXIT_USAGE and err.startswith("nbs: error: NBS_THREADS must be") and err.count("\n") == 1, err
    assert not any(tmp_path.iterdir())


def test_a_bad_mplbackend_is_one_line(monkeypatch, capsys):
    import subprocess
    import sys

    env = {**__import__("os").environ, "MPLBACKEND": "zzz"}
    root = Path(__file__).resolve().parents[1]
    p = subprocess.run(
        [sys.executable, "-m", "train", "scenes", "list"], cwd=root, env=env, capture_output=True, text=True
    )
    assert p.returncode == EXIT_USAGE and p.stderr.startswith("nbs: error: MPLBACKEND='zzz'"), p.stderr
    assert p.stderr.count("\n") == 1 and "Traceback" not in p.stderr


def test_a_closed_pipe_ends_the_command_quietly():
    """`nbs scenes list | head -1`: exit 141 (128 + SIGPIPE) as `cat` does, no error line."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    p = subprocess.Popen(
        [sys.executable, "-m", "train", "scenes", "list"], cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    p.stdout.close()  # the reader is gone before the command writes
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == "", err


def test_warnings_and_long_errors_are_single_bounded_lines(tmp_path, monkeypatch, capsys):
    """A library's warning is one `nbs: warning:` line (not two with a source line); an error that
    quotes a file's content is cut to MAX_STDERR_LINE characters."""
    from train.cli import MAX_STDERR_LINE

    unlabelled = tmp_path / "parts.obj"
    unlabelled.write_text(
        "o floor_a\nv 0 0 0\nv 4 0 0\nv 4 4 0\nv 0 4 0\nf 1 2 3\nf 1 3 4\no lamp\nv 1 1 1\nv 2 1 1\nv 2 2 1\nf 5 6 7\n"
    )
    code, err = run_cli(f"scenes info {unlabelled}", capsys)
    lines = err.splitlines()
    assert code == EXIT_SCENE_ERROR and all(line.startswith("nbs: ") for line in lines), err
    assert any(line.startswith("nbs: warning: ") and "lamp" in line for line in lines), err

    plan = json.loads(json.dumps(_plan()))
    plan["rooms"][0]["name"] = "x" * 100_000
    path = tmp_path / "named.json"
    path.write_text(json.dumps(plan))
    code, err = run_cli(f"scenes info {path}", capsys)
    assert code == EXIT_SCENE_ERROR and err.count("\n") == 1, err[:300]
    assert len(err) <= MAX_STDERR_LINE + 1 and "characters left out" in err


def _plan() -> dict:
    from scenes.generator import generate_storey

    return generate_storey(1)[0].to_dict()
