"""Reproducers of the thirteenth bad-input probe's findings, one test per class of input."""

from __future__ import annotations

import base64
import dataclasses
import json

import pytest

from scenes import load_scene
from tests.test_probe8 import _load_with_buffer_uri, _scan, glb_parts  # noqa: F401  # a fixture
from train.cli import EXIT_USAGE


# ---------------------------------------------------------------------- glTF URIs
@pytest.mark.parametrize(
    "uri, message",
    [
        ("file://[::1/PLAIN", r"is no valid URI"),  # urllib's ValueError came through as a traceback
        ("http://[bad/buf.bin", r"is no valid URI"),
        ("DATA", None),  # RFC 3986 §3.1: a scheme is case-insensitive; refused as "a data: URI, local files only"
        ("data:application/octet-stream,%00%01%02", r"without ;base64"),  # said to be escaped base64
    ],
)
def test_a_buffer_uri_is_read_as_rfc_3986_reads_it_or_named(uri, message, glb_parts, tmp_path):  # noqa: F811
    json_chunk, binary, faces = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    uri = uri.replace("/PLAIN", str(tmp_path / "plain.bin"))
    if uri == "DATA":
        uri = "DATA:application/octet-stream;BASE64," + base64.b64encode(binary).decode()
    _load_with_buffer_uri(json_chunk, uri, faces, message, tmp_path)


def test_an_image_uri_that_is_no_uri_does_not_refuse_the_geometry(glb_parts, tmp_path):  # noqa: F811
    """Images are never read: one whose URI urllib cannot split was a traceback for the geometry."""
    json_chunk, binary, faces = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    doc["images"] = [{"uri": "//[tex/a.png"}]
    (tmp_path / "x.gltf").write_text(json.dumps(doc))
    assert len(load_scene(str(tmp_path / "x.gltf")).mesh.faces) == faces


# ---------------------------------------------------------------------- report folders
@pytest.mark.parametrize("in_the_way", ["metrics.json/", "cloud.laz/", "steps->elsewhere"])
def test_what_the_report_cannot_be_renamed_onto_is_refused_before_the_scan(in_the_way, tmp_path, capsys, monkeypatch):
    """A folder where metrics.json goes failed after the scan and left a report of two runs (the new
    run's cloud files beside the old run's model and pictures); a steps folder that is a link to
    another file system failed after the scan (a rename crosses no file systems), losing the report."""
    import train.cli as cli

    out = tmp_path / "report"
    out.mkdir()
    name = in_the_way.split("/")[0].split("->")[0]
    if in_the_way.endswith("/"):
        (out / name).mkdir()
    else:
        (tmp_path / "elsewhere").mkdir()
        (out / name).symlink_to(tmp_path / "elsewhere")

    def never(*args, **kwargs):
        raise AssertionError("the scan ran")

    monkeypatch.setattr(cli, "_scan", never)
    assert cli.main(_scan(out, "--max-scans", "1", "--force")) == EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out / name) in err, err
    if name == "steps":  # without pictures too: the earlier report's would be renamed out of it
        assert cli.main(_scan(out, "--max-scans", "1", "--force", "--no-steps")) == EXIT_USAGE
        (out / name).unlink()
        (out / name).write_text("x")  # a file named steps is in no one's way without pictures
        monkeypatch.undo()
        assert cli.main(_scan(out, "--max-scans", "1", "--force", "--no-steps")) == 0
        assert (out / name).read_text() == "x"


def test_write_report_renames_nothing_unless_it_can_rename_everything(tmp_path):
    """The API's check, made again before the renames: a folder put in the way during the run."""
    from nbs_env.env import NBSEnv
    from nbs_env.export import write_report

    env = NBSEnv("fast", scene="l_room", max_scans=1, keep_scans=True)
    env.reset(seed=0)
    out = tmp_path / "r"
    write_report(env, out, "l_room", "greedy", 0)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    (out / "metrics.json").unlink()
    (out / "metrics.json").mkdir()
    with pytest.raises(FileExistsError, match=r"metrics\.json is a folder"):
        write_report(env, out, "l_room", "greedy", 1)
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert after == {k: v for k, v in before.items() if k != "metrics.json"}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


# ---------------------------------------------------------------------- IFC start
def test_an_ifc_start_in_a_property_set_definition_set_is_read(tmp_path):
    """IFC4 lets IfcRelDefinesByProperties relate an IfcPropertySetDefinitionSet of several sets: the
    property reader found the start there, the check of its measures did not, and refused it as
    "6.0 (float)", no IfcLengthMeasure, which it is."""
    pytest.importorskip("ifcopenshell")
    from tests.test_probe8 import _ifc_with_start

    path = _ifc_with_start(tmp_path, "IFCLENGTHMEASURE(6.)")
    text = path.read_text().replace("(#14),#5002);", "(#14),IFCPROPERTYSETDEFINITIONSET((#5002)));")
    assert "IFCPROPERTYSETDEFINITIONSET" in text
    path.write_text(text)
    assert load_scene(str(path), storey="EG").start[:2].tolist() == [6.0, 2.0]


# ---------------------------------------------------------------------- training run folders
@pytest.mark.parametrize("content", ["checkpoint", "policy.json", "checkpoint_3/"])
def test_a_new_run_writes_over_no_checkpoint_and_no_run_s_file(content, tiny_run, tmp_path, capsys):
    """`--init t4 --out t4` (a checkpoint folder) wrote the new run's policy over the checkpoint it
    started from, beside the old run's files: only a training_state.json counted as a run."""
    import shutil

    from tests.test_train_probe3 import _files, _train
    from train.ppo import TrainConfig, train

    out = tmp_path / "t4"
    if content == "checkpoint":
        shutil.copytree(tiny_run / "checkpoint_8", out)
        (out / "training_state.json").unlink()  # a checkpoint as shipped: policy.json and policy.pt
    elif content.endswith("/"):
        (out / content).mkdir(parents=True)
    else:
        out.mkdir()
        (out / content).write_text("{}")
    before = _files(out)
    argv = ["--timesteps", "8", "--n-steps", "8", "--envs", "1", "--completion", "policy", "--out", str(out)]
    code, err = _train([*argv, *(["--init", str(out)] if content == "checkpoint" else [])], capsys)
    assert code == 2 and "which this run would write over" in err and len(err.strip().splitlines()) == 1, err
    with pytest.raises(FileExistsError, match="which this run would write over"):
        train(TrainConfig(timesteps=8, envs=1, n_steps=8, batch_size=8, completion="policy"), out, progress=False)
    assert _files(out) == before


# ---------------------------------------------------------------------- memory of the evaluation
def test_the_quality_neighbourhoods_are_sized_before_the_first_scan(monkeypatch, tmp_path, capsys):
    """quality.density_radius at its documented 1 m (or coverage_spacing at 1 cm) asked for gigabytes
    at the run's end: the scan ran, then failed out of memory with advice about the voxel, and the
    report was lost."""
    import scenes.limits as limits
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from scenes import StoreySizeError
    from train.cli import main as nbs

    monkeypatch.setattr(limits, "memory_left", lambda: (2**30, "a test's limit"))
    env = NBSEnv(make_config("fast", scene="l_room", **{"quality.density_radius": 1.0}))
    with pytest.raises(StoreySizeError, match=r"quality\.density_radius=0\.\d+\)") as caught:
        env.reset(seed=0)
    fits = float(str(caught.value).split("quality.density_radius=")[1].split(")")[0])
    env = NBSEnv(make_config("fast", scene="l_room", max_scans=1, **{"quality.density_radius": fits}))
    env.reset(seed=0)  # the radius advised fits, and the figures are made with it
    report = env.storey.meter.quality(env.config.quality)
    assert len(report.quality_pct) == 1 and report.density.max() > 0
    # The spacing advised fits the samples and their neighbourhoods both (it once sized the samples alone).
    env = NBSEnv(make_config("fast", scene="l_room", coverage_spacing=0.01))
    with pytest.raises(StoreySizeError, match=r"coverage_spacing=0\.\d+\)") as caught:
        env.reset(seed=0)
    spacing = float(str(caught.value).split("coverage_spacing=")[1].split(")")[0])
    NBSEnv(make_config("fast", scene="l_room", max_scans=1, coverage_spacing=spacing)).reset(seed=0)

    def never(*args, **kwargs):
        raise AssertionError("a scan was taken")

    monkeypatch.setattr("nbs_env.robot.Robot.scan", never)
    out = tmp_path / "r"
    code = nbs(_scan(out, "--max-scans", "1", "--set", "quality.density_radius=1"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and "quality.density_radius" in err[-1] and not out.exists()


# ---------------------------------------------------------------------- OBJ statements
def test_a_backslash_continues_a_statement_but_never_a_comment(tmp_path):
    """A comment ending in a Windows path's backslash swallowed the next line (`g wall`): the walls
    were labelled as the ceiling without a word. A statement continued on the next line still reads
    as one, and a line's number in a message is the line in the file."""
    from tests.test_probe8 import _ROOM_OBJ

    def areas(text: str) -> dict[str, float]:
        path = tmp_path / "room.obj"
        path.write_text(text)
        return {k.name: round(v, 6) for k, v in load_scene(str(path)).class_areas().items()}

    plain = areas(_ROOM_OBJ)
    assert areas(_ROOM_OBJ.replace("g wall\n", "# exported from D:\\export\\\ng wall\n")) == plain
    assert areas(_ROOM_OBJ.replace("f 1 2 3 4\n", "f 1 2 \\\n3 4\n")) == plain
    from scenes import InvalidMeshError

    with pytest.raises(InvalidMeshError, match=r"line 15: bad vertex reference 'x'"):
        areas(_ROOM_OBJ.replace("f 1 2 3 4\n", "f 1 2 \\\n3 4\n").replace("f 1 5 6 2", "f 1 5 6 x"))


def test_a_ply_of_carriage_returns_alone_is_named_for_its_line_endings(tmp_path):
    """Said to hold 'end_header' within its line 1: true only as the whole file was one line."""
    from scenes import InvalidMeshError
    from tests.test_probe6 import GOOD_FACES, _ply_text

    path = tmp_path / "cr.ply"
    text = _ply_text(GOOD_FACES)
    path.write_bytes(text.replace("\n", "\r\n").encode())
    assert len(load_scene(str(path)).mesh.faces) > 0  # CRLF is read
    path.write_bytes(text.replace("\n", "\r").encode())
    with pytest.raises(InvalidMeshError, match="carriage return alone"):
        load_scene(str(path))


# ---------------------------------------------------------------------- probe 14
def test_a_resumed_run_s_behaviour_cloning_record_is_checked_before_it_trains(tmp_path, capsys):
    """An edited behaviour_cloning.json was read with a bare json.loads on --resume (a traceback); with
    --hold-coverage its teacher figure is what the run holds, and a nonsense one was taken."""
    pytest.importorskip("sb3_contrib")
    from tests.test_train_probe3 import _train
    from train.ppo import TrainConfig, train

    out = tmp_path / "run"
    config = TrainConfig(
        timesteps=8, envs=1, n_steps=8, batch_size=8, rooms=(1, 1), completion="policy", bc_steps=24, hold_coverage=0.1
    )
    train(config, out, progress=False)
    record = out / "behaviour_cloning.json"
    good = record.read_text()
    for text, message in [
        ('{"mapped": 5,', "behaviour_cloning.json: not JSON"),
        ("\xff", "behaviour_cloning.json: not JSON"),
        (good.replace('"mapped": ', '"mapped": -'), "mapped is -"),
        ('{"mapped": null}', "mapped is None"),
    ]:
        record.write_bytes(text.encode("latin-1") if text == "\xff" else text.encode())
        code, err = _train(["--resume", str(out), "--timesteps", "16"], capsys)
        assert code != 0 and message in err and len(err.strip().splitlines()) == 1, err
    record.unlink()
    code, err = _train(["--resume", str(out), "--timesteps", "16"], capsys)
    assert code != 0 and "behaviour_cloning.json: missing" in err, err


def test_an_obj_statement_continued_at_the_end_of_the_file_reads_as_with_a_last_newline(tmp_path):
    from tests.test_probe8 import _ROOM_OBJ

    path = tmp_path / "room.obj"
    for text in (_ROOM_OBJ + "f 1 2 3 \\", _ROOM_OBJ + "f 1 2 3 \\\n"):
        path.write_text(text)
        assert len(load_scene(str(path)).mesh.faces) == 13


@pytest.mark.parametrize("swap", [("+", "-"), ("/", "_"), ("A", "=")])
def test_base64_data_of_another_alphabet_is_named(swap, glb_parts, tmp_path):  # noqa: F811
    """URL-safe base64's '-' and '_' were skipped by the decoder: every later byte shifted, and the
    faces were said to name vertices outside the file."""
    json_chunk, binary, faces = glb_parts
    data = base64.b64encode(binary).decode()
    assert swap[0] in data
    uri = "data:application/octet-stream;base64," + data.replace(swap[0], swap[1], 1)
    _load_with_buffer_uri(json_chunk, uri, faces, r"at character \d+ of its base64 data", tmp_path)


def test_a_run_in_a_subfolder_is_named_where_it_can_be_resumed(tiny_run, tmp_path, capsys):
    import shutil

    from tests.test_train_probe3 import _train

    shutil.copytree(tiny_run, tmp_path / "w" / "run1")
    argv = ["--timesteps", "8", "--n-steps", "8", "--envs", "1", "--out", str(tmp_path / "w")]
    code, err = _train(argv, capsys)
    assert code == 2 and f"continue it with --resume {tmp_path / 'w' / 'run1'}," in err, err
    code, err = _train([*argv[:-1], str(tmp_path / "w" / "run1")], capsys)
    assert code == 2 and f"holds a run already; continue it with --resume {tmp_path / 'w' / 'run1'}," in err, err


def test_a_run_named_like_a_checkpoint_is_a_run_of_its_own_not_a_checkpoint_of_its_folder(tiny_run, tmp_path, capsys):
    """W/checkpoint_7, a whole run (its own curve), was taken for W's newest checkpoint: `--resume W`
    continued it as W, and `--out W` advised exactly that."""
    import shutil

    from tests.test_train_probe3 import _train

    folder = tmp_path / "w"
    shutil.copytree(tiny_run, folder / "checkpoint_7")
    code, err = _train(["--timesteps", "8", "--n-steps", "8", "--envs", "1", "--out", str(folder)], capsys)
    assert code == 2 and f"--resume {folder / 'checkpoint_7'}," in err, err
    code, err = _train(["--resume", str(folder), "--timesteps", "32"], capsys)
    assert code != 0 and "no resumable state" in err, err
    assert not (folder / "training_state.json").exists()


@pytest.mark.parametrize("edit", ["drop", "upper"])
def test_a_checkpoint_s_recorded_digest_is_read_as_a_sha256(edit, tiny_run, tmp_path):
    """A description without its sha256 blamed the intact weights ("checksum does not match"); the
    same digest in upper-case hex is the same SHA-256."""
    import shutil

    from policies.learned import ModelFileError, load_checkpoint

    folder = tmp_path / "ck"
    shutil.copytree(tiny_run / "checkpoint_8", folder)
    document = json.loads((folder / "policy.json").read_text())
    if edit == "drop":
        del document["sha256"]
    else:
        document["sha256"] = document["sha256"].upper()
    (folder / "policy.json").write_text(json.dumps(document))
    if edit == "drop":
        with pytest.raises(ModelFileError, match=r"policy\.json: sha256 is none"):
            load_checkpoint(folder)
    else:
        load_checkpoint(folder)


def test_a_floor_plan_is_written_only_under_a_json_name(tmp_path, capsys):
    """`nbs scenes generate --out mesh.obj` replaced the mesh with JSON, without a word."""
    from train.cli import main

    mesh = tmp_path / "mesh.obj"
    mesh.write_text("v 0 0 0\n")
    for name in ("mesh.obj", "top.png", "plan"):
        with pytest.raises(SystemExit) as stopped:
            main(["scenes", "generate", "--seed", "3", "--out", str(tmp_path / name)])
        code = stopped.value.code
        err = capsys.readouterr().err
        assert code == EXIT_USAGE and "a floor plan is JSON" in err.strip().splitlines()[-1], err
    assert mesh.read_text() == "v 0 0 0\n" and sorted(p.name for p in tmp_path.iterdir()) == ["mesh.obj"]
    assert main(["scenes", "generate", "--seed", "3", "--out", str(tmp_path / "plan.JSON")]) == 0
    assert len(load_scene(str(tmp_path / "plan.JSON")).rooms) >= 1


@pytest.mark.parametrize("how", ["failure", "stopped while cloning"])
def test_a_run_that_ends_before_its_first_state_leaves_nothing_a_rerun_trips_on(how, tmp_path, monkeypatch):
    """A run that failed (out of memory in its workers) or was stopped during behaviour cloning left
    an empty learning_curve.jsonl: the same command again was refused ("holds learning_curve.jsonl"),
    and --resume found no state. It said to run the command again."""
    pytest.importorskip("sb3_contrib")
    import train.ppo as ppo

    config = ppo.TrainConfig(timesteps=8, envs=1, n_steps=8, batch_size=8, rooms=(1, 1), bc_steps=4)
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "notes.txt").write_text("mine")
    for out in (tmp_path / "new", tmp_path / "kept"):
        if how == "failure":  # in the workers while cloning: the curve is written by then

            def fail(*args, folder=out, **kwargs):
                assert (folder / "learning_curve.jsonl").is_file()
                raise MemoryError("out of memory")

            monkeypatch.setattr(ppo, "behaviour_clone", fail)
            with pytest.raises(MemoryError):
                ppo.train(config, out, progress=False)
        else:
            monkeypatch.setattr(ppo, "behaviour_clone", lambda *args, **kwargs: None)
            assert ppo.train(config, out, progress=False)[0] is None
        monkeypatch.undo()
        assert ppo.run_folder_problem(out) is None
    assert not (tmp_path / "new").exists()
    assert [p.name for p in (tmp_path / "kept").iterdir()] == ["notes.txt"]
    assert ppo.train(dataclasses.replace(config, bc_steps=0), tmp_path / "kept", progress=False)[0] is not None


# ---------------------------------------------------------------------- IFC numbers, glTF versions and counts
@pytest.mark.parametrize(
    "point, message",
    [
        ("(1.E300,0.,3.)", r"the point #32 lies 1e\+300 m from its placement's origin"),  # a ceiling dropped silently
        ("(0.,0.,1.E999)", r"line \d+: '1\.E999' is no valid STEP token"),  # "Syntax error during parse, check logs"
    ],
)
def test_an_ifc_number_no_building_has_is_named(point, message, tmp_path):
    pytest.importorskip("ifcopenshell")
    from pathlib import Path

    from scenes import IfcError

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    assert "#32=IFCCARTESIANPOINT((0.,0.,3.));" in text
    path = tmp_path / "far.ifc"
    path.write_text(text.replace("#32=IFCCARTESIANPOINT((0.,0.,3.));", f"#32=IFCCARTESIANPOINT({point});"))
    with pytest.raises(IfcError, match=message):
        load_scene(str(path))


@pytest.mark.parametrize(
    "edit, message",
    [
        ({"asset": {"version": "2.1", "minVersion": "2.1"}}, r"asset\.minVersion is '2\.1'"),
        ({"accessors": {0: {"count": 0}}}, r"accessors\[0\]\.count is 0"),  # said to be "points or lines"
    ],
)
def test_a_gltf_a_2_0_reader_must_refuse_is_refused_by_name(edit, message, glb_parts, tmp_path):  # noqa: F811
    json_chunk, binary, faces = glb_parts
    doc = json.loads(json_chunk)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    path = tmp_path / "x.gltf"
    path.write_text(json.dumps(doc))
    assert len(load_scene(str(path)).mesh.faces) == faces
    for key, value in edit.items():
        if isinstance(value, dict) and all(isinstance(k, int) for k in value):
            for index, fields in value.items():
                doc[key][index].update(fields)
        else:
            doc[key] = value
    path.write_text(json.dumps(doc))
    from scenes import InvalidMeshError

    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))
    doc["asset"] = {"version": "2.0", "minVersion": "2.0"}
    if "accessors" not in edit:
        path.write_text(json.dumps(doc))
        assert len(load_scene(str(path)).mesh.faces) == faces


# ---------------------------------------------------------------------- probe 16
def test_an_output_linked_to_a_file_of_another_kind_is_refused(tmp_path, capsys):
    """`q.json -> mesh.obj` passed the name's check and the plan replaced the mesh."""
    from train.cli import main

    (tmp_path / "mesh.obj").write_text("v 0 0 0\n")
    (tmp_path / "q.json").symlink_to(tmp_path / "mesh.obj")
    code = main(["scenes", "generate", "--seed", "2", "--out", str(tmp_path / "q.json")])
    assert code == EXIT_USAGE and "a file of another kind" in capsys.readouterr().err
    assert (tmp_path / "mesh.obj").read_text() == "v 0 0 0\n"
    (tmp_path / "old.json").write_text("{}")
    (tmp_path / "p.json").symlink_to(tmp_path / "old.json")
    # A plan for a plan, with --force (probe 42: an existing plan is not replaced without it).
    assert main(["scenes", "generate", "--seed", "2", "--out", str(tmp_path / "p.json"), "--force"]) == 0


@pytest.mark.parametrize("asset", [None, {"version": 2.0}, {"version": "2.0", "minVersion": 2.0}, {"version": "20"}])
def test_a_gltf_asset_without_its_version_string_is_refused(asset, glb_parts, tmp_path):  # noqa: F811
    from scenes import InvalidMeshError

    json_chunk, binary, _faces = glb_parts
    doc = json.loads(json_chunk)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    if asset is None:
        del doc["asset"]
    else:
        doc["asset"] = asset
    (tmp_path / "x.gltf").write_text(json.dumps(doc))
    with pytest.raises(InvalidMeshError, match=r"asset\.(min)?[vV]ersion is"):
        load_scene(str(tmp_path / "x.gltf"))


@pytest.mark.parametrize("seed", [-1, 1.5, True, "3"])
def test_a_reset_seed_that_is_no_count_is_a_config_error(seed):
    from nbs_env.env import NBSEnv
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match="seed must be None or an integer >= 0"):
        NBSEnv("fast", scene="l_room").reset(seed=seed)


def test_an_oracle_record_placed_where_no_storey_is_is_not_reused():
    from policies.oracle import OraclePlan

    record = {"positions": [[1.0, 2.0, 1.2]], "coverage_pct": [50.0], "max_coverage_pct": 90.0, "candidates": 4,
              "samples": 100}  # fmt: skip
    assert OraclePlan.from_dict(record).positions.shape == (1, 3)
    with pytest.raises(ValueError, match="beyond 10,000 m"):
        OraclePlan.from_dict({**record, "positions": [[1e300, 0.0, 0.0]]})


def test_notes_named_checkpoint_something_are_no_checkpoint(tmp_path):
    from train.ppo import run_folder_problem

    (tmp_path / "checkpoint_notes.txt").write_text("n")
    assert run_folder_problem(tmp_path) is None
    (tmp_path / "checkpoint_12").mkdir()
    assert "checkpoint_12" in run_folder_problem(tmp_path)


def test_a_unit_given_is_named_when_the_storey_comes_out_too_low(tmp_path):
    from scenes import StoreySizeError
    from scenes.importers import export_scene

    export_scene(load_scene("l_room"), tmp_path / "l.obj")
    with pytest.raises(StoreySizeError, match=r"are its coordinates in ft \(it was read with --units ft\)"):
        load_scene(str(tmp_path / "l.obj"), units="ft")


# ---------------------------------------------------------------------- probe 17
def test_a_numpy_integer_seed_is_a_seed():
    """The seed check let numpy integers through to gymnasium, which refuses them ("a python integer")."""
    import numpy as np

    from nbs_env.env import NBSEnv

    env = NBSEnv("fast", scene="l_room", max_scans=1)
    first = env.reset(seed=np.int64(3))[0]["voxels"].copy()
    np.testing.assert_array_equal(env.reset(seed=3)[0]["voxels"], first)
    env.reset(seed=np.uint32(3))


@pytest.mark.parametrize(
    "asset, message",
    [
        ({"version": "2.\u0660"}, r"asset\.version is"),
        ({"version": "2.0", "minVersion": None}, r"asset\.minVersion is null"),
        ({"version": "2.0", "minVersion": "1.0"}, r"below 2\.0"),
        ({"version": "2.0", "minVersion": "2.00"}, None),  # 2.0, as the schema's pattern allows it
    ],
)
def test_gltf_versions_are_read_as_the_schema_writes_them(asset, message, glb_parts, tmp_path):  # noqa: F811
    from scenes import InvalidMeshError

    json_chunk, binary, faces = glb_parts
    doc = json.loads(json_chunk)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    doc["asset"] = asset
    (tmp_path / "x.gltf").write_text(json.dumps(doc))
    if message is None:
        assert len(load_scene(str(tmp_path / "x.gltf")).mesh.faces) == faces
    else:
        with pytest.raises(InvalidMeshError, match=message):
            load_scene(str(tmp_path / "x.gltf"))


def test_an_output_linked_to_nothing_of_another_kind_is_refused(tmp_path, capsys):
    """`pic.png -> gone.obj` made matplotlib pick the format by the target (a traceback), and a plan
    was written as missing.obj."""
    from train.cli import main

    (tmp_path / "pic.png").symlink_to(tmp_path / "gone.obj")
    (tmp_path / "p.json").symlink_to(tmp_path / "missing.obj")
    assert main(["scenes", "show", "l_room", "--out", str(tmp_path / "pic.png")]) == EXIT_USAGE
    assert main(["scenes", "generate", "--seed", "1", "--out", str(tmp_path / "p.json")]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("a file of another kind") == 2 and "Traceback" not in err
    assert not (tmp_path / "gone.obj").exists() and not (tmp_path / "missing.obj").exists()


@pytest.mark.parametrize(
    "field, value",
    [("max_coverage_pct", "99.9"), ("coverage_pct", ["50.0"]), ("room_max_pct", {"0": "99.9"})],
)
def test_an_oracle_record_of_numbers_written_as_strings_is_not_reused(field, value):
    """float() read "99.9", the summary then compared the string: a resume that failed every time."""
    from policies.oracle import OraclePlan

    record = {"positions": [[1.0, 2.0, 1.2]], "coverage_pct": [50.0], "max_coverage_pct": 90.0, "candidates": 4,
              "samples": 100}  # fmt: skip
    OraclePlan.from_dict(record)
    with pytest.raises(ValueError, match="JSON numbers"):
        OraclePlan.from_dict({**record, field: value})


def test_the_trained_network_reads_the_window_and_candidates_its_envs_have():
    """`--set observation.shape=[32,32,16]` trained on 32-cell windows and recorded 64; a
    `max_candidates` of 32 was a traceback from torch."""
    from train.ppo import TrainConfig

    config = TrainConfig(
        completion="policy",
        overrides={"observation.shape": (32, 32, 16), "robot.navigation.max_candidates": 32},
    )
    assert config.network.voxel_shape == (32, 32, 16)
    assert (config.network.candidates, config.network.actions) == (32, 33)
    assert TrainConfig().network.voxel_shape == (64, 64, 16) and TrainConfig().network.actions == 64


def test_a_scan_whose_report_fails_keeps_the_earlier_recording(tmp_path, monkeypatch, capsys):
    """The recording was renamed into place before the report was written: a report that then failed
    left the earlier report beside the failed run's recording."""
    pytest.importorskip("rerun")
    import errno

    import nbs_env.export as export
    from train.cli import main as nbs

    out, record = tmp_path / "r", tmp_path / "run.rrd"
    assert nbs(_scan(out, "--max-scans", "1", "--record", str(record))) == 0
    before = record.read_bytes()

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "cloud.laz"))

    monkeypatch.setattr(export, "_write_report_files", full)
    assert nbs(_scan(out, "--max-scans", "2", "--seed", "1", "--force", "--record", str(record))) != 0
    assert record.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r", "run.rrd"]


@pytest.mark.parametrize(
    "node, message",
    [
        ({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1], "translation": [0, 0, 5]}, "both a matrix"),
        ({"rotation": [0, 0, 0, 0]}, r"not a unit quaternion \(length 0\)"),
    ],
)
def test_a_gltf_node_other_readers_read_otherwise_is_refused(node, message, glb_parts, tmp_path):  # noqa: F811
    """A node with both a matrix and a translation had both applied (three.js applies the matrix)."""
    from scenes import InvalidMeshError

    json_chunk, binary, _faces = glb_parts
    doc = json.loads(json_chunk)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    doc["nodes"][0].update(node)
    (tmp_path / "x.gltf").write_text(json.dumps(doc))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(tmp_path / "x.gltf"))


@pytest.mark.parametrize(
    "units, message",
    [
        ("#2=IFCSIUNIT(*,.LENGTHUNIT.,.BOGUS.,.METRE.);", "prefix 'BOGUS'"),
        ("#2=IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);\n#9001=IFCSIUNIT(*,.LENGTHUNIT.,.MILLI.,.METRE.);", "2 length units"),
    ],
)
def test_an_ifc_length_unit_that_is_unclear_is_refused(units, message, tmp_path):
    """An unknown prefix and a second length unit were read without a word (as metres, as the last)."""
    pytest.importorskip("ifcopenshell")
    from pathlib import Path

    from scenes import IfcError

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    text = text.replace("#2=IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);", units)
    if "#9001=" in units:
        text = text.replace("#3=IFCUNITASSIGNMENT((#2));", "#3=IFCUNITASSIGNMENT((#2,#9001));")
        assert "#9001=" not in (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    (tmp_path / "u.ifc").write_text(text)
    with pytest.raises(IfcError, match=message):
        load_scene(str(tmp_path / "u.ifc"))


@pytest.mark.parametrize("rooms", [None, ["room"]])
def test_the_model_writer_names_what_it_takes(rooms, tmp_path):
    from nbs_env.export import write_model_obj

    with pytest.raises(TypeError, match="rooms must be a list of RoomModel"):
        write_model_obj(tmp_path / "m.obj", rooms)
    assert not (tmp_path / "m.obj").exists()


@pytest.mark.parametrize(
    "extra",
    [
        "/* old: #99=IFCSIUNIT(*,.LENGTHUNIT.,.MILIMETER.,.METRE.); */\n",  # a comment (ISO 10303-21)
        "#9004=IFCSIUNIT(*,.AREAUNIT.,$,.SQUARE_METRE.);\n#9002=IFCUNITASSIGNMENT((#9004));\n",  # not the project's
    ],
)
def test_unit_checks_read_the_project_s_units_not_its_text(extra, tmp_path):
    """The prefix check read a comment's text as an instance, and the length-unit check read every
    assignment, a project library's of areas alone included."""
    pytest.importorskip("ifcopenshell")
    import warnings
    from pathlib import Path

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    at = text.rindex("ENDSEC;")
    (tmp_path / "u.ifc").write_text(text[:at] + extra + text[at:])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(load_scene(str(tmp_path / "u.ifc")).mesh.faces) == 3716
