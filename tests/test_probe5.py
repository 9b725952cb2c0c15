"""Probe 5's findings, by class: mesh files whose side files, part names or accessors the readers took
on trust (a PLY's texture a fifo, room numbers beyond any storey, positions that are not 3-D floats,
strides that overlap, a side file far larger than its buffer)."""

from __future__ import annotations

import base64
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from scenes import InvalidMeshError, load_scene
from scenes.headers import SIDE_FILE_SLACK
from scenes.importers import MAX_ROOM_NUMBER, parse_part_name
from scenes.labels import SurfaceClass
from tests.test_scene_probe2 import gltf_doc, position_accessor, room_parts, write_gltf, write_obj

ROOT = Path(__file__).resolve().parents[1]


def _ply(path: Path, comment: str = "") -> Path:
    """A labelled PLY of one room, with ``comment`` as a header line."""
    parts = room_parts()
    mesh = trimesh.util.concatenate(list(parts.values()))
    labels = np.concatenate([np.full(len(m.faces), SurfaceClass[n.split("_")[0].upper()]) for n, m in parts.items()])
    mesh.face_attributes["label"] = labels.astype(np.uint8)
    data = trimesh.exchange.ply.export_ply(mesh, encoding="ascii", include_attributes=True)
    if comment:
        data = data.replace(b"format ascii 1.0\n", f"format ascii 1.0\ncomment {comment}\n".encode(), 1)
    path.write_bytes(data)
    return path


# ---------------------------------------------------------------------- side files
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX fifos")
def test_a_ply_whose_texture_is_a_fifo_loads_without_opening_it(tmp_path):
    """trimesh opened the texture a header comment names: a fifo there hung the load, deaf to SIGTERM."""
    os.mkfifo(tmp_path / "tex.fifo")
    path = _ply(tmp_path / "room.ply", "TextureFile tex.fifo")
    code = f"import sys; from scenes import load_scene; s = load_scene({str(path)!r}); print(len(s.mesh.faces))"
    started = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "12", proc.stderr
    assert time.monotonic() - started < 60


def test_a_gltf_side_file_far_larger_than_its_buffer_is_refused_before_it_is_read(tmp_path):
    doc = gltf_doc(room_parts())
    blob = base64.b64decode(doc["buffers"][0]["uri"].partition(",")[2])
    (tmp_path / "side.bin").write_bytes(blob)
    doc["buffers"][0]["uri"] = "side.bin"
    assert len(load_scene(str(write_gltf(tmp_path / "side.gltf", doc))).mesh.faces) == 12
    with open(tmp_path / "side.bin", "ab") as f:
        f.truncate(len(blob) + SIDE_FILE_SLACK + 1)  # sparse: no disk used
    with pytest.raises(InvalidMeshError, match=r"buffers\[0\]\.uri 'side\.bin' holds [\d,]+ bytes, but .* declares"):
        load_scene(str(tmp_path / "side.gltf"))


# ---------------------------------------------------------------------- part names
@pytest.mark.parametrize("digits", ["9" * 23, "7" * 5000, str(MAX_ROOM_NUMBER + 1)])
def test_a_room_number_beyond_any_storey_is_refused_naming_the_part(digits, tmp_path):
    parts = room_parts()
    parts[f"floor_room{digits}"] = parts.pop("floor")
    for path in (write_obj(tmp_path / "r.obj", parts), write_gltf(tmp_path / "r.gltf", gltf_doc(parts))):
        with pytest.raises(InvalidMeshError, match=rf"part 'floor_room{digits[:20]}.*room numbers go up to 999,999"):
            load_scene(str(path))


def test_room_numbers_up_to_the_bound_and_leading_zeros_are_read():
    assert parse_part_name(f"wall_room{MAX_ROOM_NUMBER}") == (parse_part_name("wall")[0], MAX_ROOM_NUMBER)
    assert parse_part_name("wall_room" + "0" * 40 + "7")[1] == 7


# ---------------------------------------------------------------------- accessors and strides
def test_positions_that_are_not_3d_floats_and_indices_that_are_not_unsigned_scalars_are_refused(tmp_path):
    doc = gltf_doc(room_parts())
    k = position_accessor(doc)
    doc["accessors"][k]["type"] = "VEC2"
    with pytest.raises(InvalidMeshError, match=r"POSITION of meshes\[0\]\.primitives\[0\]\) is 'VEC2' of FLOAT"):
        load_scene(str(write_gltf(tmp_path / "vec2.gltf", doc)))
    doc = gltf_doc(room_parts())
    i = doc["meshes"][0]["primitives"][0]["indices"]
    doc["accessors"][i]["componentType"] = 5126
    with pytest.raises(InvalidMeshError, match=r"indices of .* is 'SCALAR' of FLOAT; .* SCALAR of UNSIGNED_BYTE"):
        load_scene(str(write_gltf(tmp_path / "float_indices.gltf", doc)))


@pytest.mark.parametrize(
    "stride, message",
    [
        (4, r"elements take 12 bytes, but bufferViews\[\d+\]\.byteStride is 4: they would overlap"),
        (12.5, r"byteStride must be a multiple of 4 within \[4, 252\] \(glTF 2\.0\), got 12\.5"),
        ("12", r"byteStride must be a multiple of 4 within \[4, 252\] \(glTF 2\.0\), got '12'"),
        (256, r"byteStride must be a multiple of 4 within \[4, 252\]"),
    ],
)
def test_a_stride_that_overlaps_or_breaks_the_specification_is_refused(stride, message, tmp_path):
    """A stride of 4 for 12-byte positions loaded a floor of 124 m² for one of 12 m² (glTF-Validator:
    ACCESSOR_SMALL_BYTESTRIDE)."""
    doc = gltf_doc(room_parts())
    view = doc["accessors"][position_accessor(doc)]["bufferView"]
    doc["bufferViews"][view]["byteStride"] = stride
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(write_gltf(tmp_path / "stride.gltf", doc)))


def test_a_stride_of_the_element_size_loads(tmp_path):
    doc = gltf_doc(room_parts())
    view = doc["accessors"][position_accessor(doc)]["bufferView"]
    doc["bufferViews"][view]["byteStride"] = 12
    assert len(load_scene(str(write_gltf(tmp_path / "stride12.gltf", doc))).mesh.faces) == 12


# ---------------------------------------------------------------------- files read whole
def _sparse(path: Path, size: int) -> Path:
    with open(path, "wb") as f:
        f.truncate(size)  # no disk used
    return path


@pytest.mark.parametrize("name", ["plan.json", "mesh.gltf", "mesh.obj", "mesh.ply", "mesh.glb"])
def test_a_file_read_whole_is_sized_before_it_is_read(name, tmp_path, capsys):
    """A 1.5 GB file given as a plan (or a .gltf) was read, decoded and re-encoded: a MemoryError."""
    from scenes.jsonio import MAX_JSON_BYTES
    from scenes.limits import MAX_MESH_FILE_BYTES
    from train.cli import main as nbs

    limit = MAX_JSON_BYTES if name.endswith(".json") else MAX_MESH_FILE_BYTES
    path = _sparse(tmp_path / name, limit + 1)
    assert nbs(["scenes", "info", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"nbs: error: {path}: ") and f"a file of {limit + 1:,} bytes" in err.replace(
        "the file holds", "a file of"
    ), err
    assert err.count("\n") == 1 and "is it the file you meant?" in err


def test_a_checkpoint_description_too_large_is_refused_before_it_is_read(tmp_path):
    import shutil

    from nbs_env.errors import ModelFileError
    from policies import make_policy
    from policies.learned import BUNDLED
    from scenes.jsonio import MAX_JSON_BYTES

    folder = tmp_path / "ck"
    shutil.copytree(BUNDLED["reference"], folder)
    _sparse(folder / "policy.json", MAX_JSON_BYTES + 1)
    with pytest.raises(ModelFileError, match=rf"a file of {MAX_JSON_BYTES + 1:,} bytes, more than the"):
        make_policy(f"ppo:{folder}")


def test_json_nesting_is_found_at_its_character_beyond_ascii():
    from scenes.jsonio import JSONNestingError, read_json

    text = '{"é€😀": ' + "[" * 70 + "]" * 70 + "}"
    with pytest.raises(JSONNestingError) as nested:
        read_json(text)
    assert nested.value.pos == text.index("[") + 63  # the 65th level, counted in characters, not bytes


# ---------------------------------------------------------------------- numbers that overflow
@pytest.mark.parametrize(
    "option, message",
    [
        (["--learning-rate", "1e300"], "learning_rate must be within (0, 0.1], got 1e+300"),
        (["--ent-coef", "1e300"], "ent_coef must be within [0, 1], got 1e+300"),
        (["--scan-cost", "1e9"], "scan_cost must be within [0, 1,000]"),
    ],
)
def test_training_numbers_that_turn_the_network_to_nan_are_refused_before_the_run(option, message, tmp_path, capsys):
    """--learning-rate 1e300 or --ent-coef 1e300 ended the first update in a torch traceback."""
    from train.cli import main as nbs

    assert nbs(["train", "--timesteps", "64", "--out", str(tmp_path / "t"), *option]) == 2
    err = capsys.readouterr().err
    assert err == f"nbs train: error: {message}\n" or err.startswith(f"nbs train: error: {message}"), err
    assert not (tmp_path / "t").exists()


def test_a_start_beyond_any_storey_is_refused_in_the_cli_and_the_env(capsys, tmp_path):
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.errors import ConfigError
    from train.cli import main as nbs

    with pytest.raises(SystemExit):
        nbs(["scan", "--scene", "l_room", "--start=1e308,0", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err
    assert "expected X,Y within 10,000 m of the origin" in err and "warning" not in err
    env = NBSEnv(make_config("fast", scene="l_room"))
    with pytest.raises(ConfigError, match=r"options\['start'\] must lie within 10,000 m of the origin"):
        env.reset(seed=0, options={"start": (1e308, 0.0)})


# ---------------------------------------------------------------------- options and outputs
@pytest.mark.parametrize(
    "sets, message",
    [
        (
            ["robot.voxel_size=0.05", "robot.voxel_size=0.06"],
            "--set robot.voxel_size is given twice; give each field once",
        ),
        (["max_scans=1", "max_scans=2"], "--set max_scans is given twice"),
        (["robot.scanner.height=1", "robot.scanner={}"], "--set robot.scanner and --set robot.scanner.height both set"),
    ],
)
def test_a_field_set_twice_by_set_names_the_sets_not_an_option_never_given(sets, message, tmp_path, capsys):
    from train.cli import main as nbs

    argv = ["scan", "--scene", "l_room", "--preset", "fast", "--out", str(tmp_path / "s")]
    for item in sets:
        argv += ["--set", item]
    assert nbs(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"nbs scan: error: {message}") and "--voxel" not in err and "--max-scans" not in err, err


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["scan", "--scene", "l_room", "--max-scans", "1", "--out", "{tmp}/o", "--record", "{link}.rrd"], "--record"),
        (["scenes", "show", "l_room", "--out", "{link}.png"], "--out"),
        (["scenes", "generate", "--seed", "1", "--out", "{link}.json"], "--out"),
        (["scan", "--scene", "l_room", "--max-scans", "1", "--out", "{link}"], "--out"),
    ],
)
def test_an_output_through_a_loop_of_links_is_refused_before_the_work(argv, flag, tmp_path, capsys):
    """pathlib's RuntimeError for a loop escaped as a traceback; a folder --out through one ran the scans first."""
    from train.cli import main as nbs

    suffix = Path(argv[-1]).suffix
    link = tmp_path / "a"
    os.symlink(tmp_path / f"b{suffix}", tmp_path / f"a{suffix}")
    os.symlink(tmp_path / f"a{suffix}", tmp_path / f"b{suffix}")
    argv = [a.replace("{tmp}", str(tmp_path)).replace("{link}", str(link)) for a in argv]
    assert nbs(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{flag} {link}{suffix}: cannot be used (Too many levels of symbolic links)" in err
    assert not (tmp_path / "o").exists()


def test_a_report_folder_that_is_a_dangling_link_is_refused_before_the_scans(tmp_path, capsys):
    from train.cli import main as nbs

    os.symlink(tmp_path / "nowhere" / "dir", tmp_path / "dangling")
    assert nbs(["scan", "--scene", "l_room", "--max-scans", "1", "--out", str(tmp_path / "dangling")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"nbs scan: error: --out {tmp_path / 'dangling'}: is a link to {tmp_path}/nowhere/dir, ")


# ---------------------------------------------------------------------- scene options in the configuration
@pytest.mark.parametrize(
    "options, message",
    [
        (5, r"scene_options must be a dict of scenes\.load_scene's options"),
        ({"units": "km"}, r"scene_options\['units'\] must be one of m, cm, mm, ft, in, got \"km\""),
        ({"storey": True}, r"scene_options\['storey'\] must be a storey's name or index"),
        ({"zz": 3}, r"scene_options \['zz'\] are not options of scenes\.load_scene"),
    ],
)
def test_scene_options_are_checked_when_the_configuration_is_made(options, message):
    from nbs_env.config import make_config
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        make_config("fast", scene="l_room", scene_options=options)


def test_a_scene_option_the_source_does_not_take_is_a_config_error_when_made_or_at_reset():
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.errors import ConfigError

    # The configuration's own scene is known when it is made: refused there.
    with pytest.raises(ConfigError, match=r"scene_options \['units'\] do not apply to scene 'l_room' \(bundled"):
        make_config("fast", scene="l_room", scene_options={"units": "mm"})
    with pytest.raises(ConfigError, match=r"\['storey'\] do not apply to scene 'a/b\.obj' \(mesh file\)"):
        make_config("fast", scene="a/b.obj", scene_options={"storey": 0})
    assert make_config("fast", scene="a/b.ifc", scene_options={"storey": 0}).scene_options == {"storey": 0}
    # A scene a reset names: refused at that reset.
    env = NBSEnv(make_config("fast", scene_options={"units": "mm"}))
    with pytest.raises(ConfigError, match=r"scene_options: load_scene: options \['units'\] do not apply to this"):
        env.reset(seed=0, options={"scene": "l_room"})


# ---------------------------------------------------------------------- signals at the end, fifos in result folders
def test_a_stop_signal_after_the_command_is_done_is_ignored_by_the_process():
    """Python restores the default handlers while it shuts down: a SIGTERM then killed a finished
    `nbs scan` silently with 143. The command line's own main() ignores them once its work is said;
    main() called with arguments (a test, a notebook) leaves the process's handlers alone."""
    code = (
        "import signal, sys; sys.argv = ['nbs', 'scenes', 'list']; from train.cli import main; c = main(); "
        "assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN, signal.getsignal(signal.SIGTERM); "
        "main(['scenes', 'list']); sys.exit(c)"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    import signal

    from train.cli import main

    before = signal.getsignal(signal.SIGTERM)
    assert main(["scenes", "list"]) == 0 and signal.getsignal(signal.SIGTERM) == before


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX fifos")
@pytest.mark.parametrize(
    "make, what", [(os.mkfifo, "not a regular file (a fifo, a socket or a device)"), (os.mkdir, "a folder")]
)
def test_a_fifo_or_folder_in_a_comparisons_folder_is_refused_before_resume_reads_it(make, what, tmp_path, capsys):
    """A fifo as a run's metrics.json blocked --resume for ever, deaf to SIGTERM and SIGINT; a folder
    there made the run run again and fail at its write."""
    from train.cli import main as nbs

    out = tmp_path / "grid"
    argv = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0", "--preset", "fast"]
    argv += ["--max-scans", "1", "--quiet", "--out", str(out)]
    assert nbs(argv) == 0
    metrics = out / "runs" / "l_room" / "random" / "seed0" / "metrics.json"
    metrics.unlink()
    make(metrics)
    capsys.readouterr()
    assert nbs([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"nbs compare: error: --out {out}: {metrics} is {what}; the comparison's files must be its own: "
        "replace it by the file or remove it, or choose another --out\n"
    )


def test_a_record_of_another_schema_or_an_oracle_with_nan_is_not_reused():
    from train.compare import _oracle_usable, record_problem

    record = {"spec": {"scene": "l_room", "policy": "random", "seed": 0}, "metrics": {"schema": 99}}
    assert record_problem(record) == "its schema is 99, not 'nbs-metrics/1'"
    plan = {
        "positions": [[1.0, 1.0, 0.0], [2.0, 1.0, 0.0]],
        "coverage_pct": [50.0, 90.0],
        "max_coverage_pct": 90.0,
        "candidates": 10,
        "samples": 100,
        "room_max_pct": {"0": 90.0},
    }
    assert _oracle_usable(plan)
    assert not _oracle_usable({**plan, "positions": [[float("nan"), 0.0, 0.0]]})
    assert not _oracle_usable({**plan, "coverage_pct": [50.0, 190.0]})


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX fifos")
def test_json_files_that_are_not_regular_files_are_refused_unread(tmp_path):
    from scenes.jsonio import read_json_file

    os.mkfifo(tmp_path / "f.json")
    with pytest.raises(OSError, match="not a regular file"):
        read_json_file(tmp_path / "f.json")


# ---------------------------------------------------------------------- IFC values
def _fzk(tmp_path: Path, old: str, new: str) -> Path:
    from scenes.corpus import corpus_entry

    text = corpus_entry("fzk_haus_eg").path().read_text(encoding="utf-8", errors="surrogateescape")
    assert old in text
    path = tmp_path / "edited.ifc"
    path.write_text(text.replace(old, new), encoding="utf-8", errors="surrogateescape")
    return path


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "#432= IFCLOCALPLACEMENT(#115,#431);",
            "#432= IFCLOCALPLACEMENT(#12,#431);",
            r"the placement #432 is relative to #12, an IfcOwnerHistory, not a placement",
        ),
        (  # relative to the building it places: a cycle of references
            "#432= IFCLOCALPLACEMENT(#115,#431);",
            "#432= IFCLOCALPLACEMENT(#434,#431);",
            r"references form a cycle: #432 \(IFCLOCALPLACEMENT\) -> #434 \(IFCBUILDING\) -> #432",
        ),
        ("#472= IFCDIRECTION((0.,0.,1.));", "#472= IFCDIRECTION((0.,0.,0.));", r"the direction #472 .* points nowhere"),
        (
            "#15006= IFCEXTRUDEDAREASOLID(#14994,#15003,#15004,2.5);",
            "#15006= IFCEXTRUDEDAREASOLID(#14994,#15003,#15004,1.E300);",
            r"the extrusion #15006 is 1e\+300 units \(1e\+300 m\) deep",
        ),
    ],
)
def test_ifc_values_that_break_the_geometry_are_refused_naming_the_entity(old, new, message, tmp_path):
    """A placement relative to a building ended in an AttributeError traceback inside ifcopenshell; a
    zero axis in a divide warning and "no wall faces"; a wall extruded 1e300 m was dropped silently."""
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(IfcError, match=message):
            load_scene(str(_fzk(tmp_path, old, new)), storey=0)


# ---------------------------------------------------------------------- the environment and the viewer
@pytest.mark.parametrize("value", ["", "abc", "0", "4,0"])
def test_an_omp_thread_count_libgomp_refuses_is_refused_before_it_loads(value):
    """libgomp printed a blank line and its complaint on stderr of an otherwise successful run."""
    env = {**os.environ, "OMP_NUM_THREADS": value}
    proc = subprocess.run(
        [sys.executable, "-m", "train", "scenes", "list"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and proc.stderr.startswith(f"nbs: error: OMP_NUM_THREADS={value!r} is not a thread")
    assert proc.stderr.count("\n") == 1 and "libgomp" not in proc.stderr


def test_an_address_the_viewer_cannot_serve_on_is_named(tmp_path):
    from nbs_env.replay import NoViewerError, serve_web

    rr = pytest.importorskip("rerun")
    recording = tmp_path / "r.rrd"
    stream = rr.RecordingStream(application_id="nbs_env_test")
    stream.save(recording)
    stream.log("x", rr.Points3D([[0.0, 0.0, 0.0]]))
    stream.flush()
    del stream
    for bind in ("999.1.1.1", "localhost:80"):
        with pytest.raises(NoViewerError, match=rf"the address to serve on \(--bind\) '{bind}': "):
            serve_web(recording, port=0, web_port=0, bind=bind)


@pytest.mark.parametrize(
    "key, value", [("matrix", ["1"] * 16), ("matrix", [float("nan")] * 16), ("translation", [0, 0]), ("scale", "x")]
)
def test_a_node_transform_that_is_not_finite_numbers_is_refused(key, value, tmp_path):
    """A matrix of strings was read as zeros: "the storey is 0 m high"."""
    doc = gltf_doc(room_parts())
    doc["nodes"][0][key] = value
    with pytest.raises(InvalidMeshError, match=rf"nodes\[0\]\.{key} must be \d+ finite numbers"):
        load_scene(str(write_gltf(tmp_path / "t.gltf", doc)))


def test_a_wall_whose_body_cannot_be_built_is_named_in_a_warning(tmp_path):
    """ifcopenshell leaves out an element whose geometry fails; it was dropped without a word."""
    pytest.importorskip("ifcopenshell")
    from scenes.ifc import UnbuiltElementsWarning

    path = _fzk(
        tmp_path,
        "#14992= IFCPOLYLINE((#14984,#14986,#14988,#14990,#14984));",
        "#14992= IFCPOLYLINE((#14984,#14984,#14984));",  # a profile of no area
    )
    with pytest.warns(UnbuiltElementsWarning, match=r"1 structural element\(s\) .* #15042 IfcWallStandardCase"):
        load_scene(str(path), storey=0)
