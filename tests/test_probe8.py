"""Probe 9's findings that remained, each fixed by class: readers that take what the format allows
(GLB chunks), numbers read in a file format's grammar rather than Python's, JSON objects that name a
key twice, records of earlier runs checked before a run continues from them, and reset options named."""

from __future__ import annotations

import json
import struct
import warnings

import pytest

from scenes import InvalidMeshError, load_scene
from tests.test_train_probe3 import _files, _train
from train.cli import EXIT_USAGE


# ---------------------------------------------------------------------- GLB chunks
def _glb(json_chunk: bytes, chunks: list[tuple[bytes, bytes]]) -> bytes:
    def chunk(kind: bytes, payload: bytes, pad: bytes) -> bytes:
        payload += pad * (-len(payload) % 4)
        return struct.pack("<I", len(payload)) + kind + payload

    body = chunk(b"JSON", json_chunk, b" ") + b"".join(chunk(k, p, b"\0") for k, p in chunks)
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def _split_glb(data: bytes) -> tuple[bytes, bytes]:
    (n,) = struct.unpack_from("<I", data, 12)
    json_chunk = data[20 : 20 + n]
    (m,) = struct.unpack_from("<I", data, 20 + n)
    return json_chunk, data[28 + n : 28 + n + m]


@pytest.fixture(scope="module")
def glb_parts(tmp_path_factory) -> tuple[bytes, bytes, int]:
    from scenes.importers import export_scene

    folder = tmp_path_factory.mktemp("glb")
    scene = load_scene("l_room")
    export_scene(scene, folder / "l_room.glb")
    json_chunk, binary = _split_glb((folder / "l_room.glb").read_bytes())
    return json_chunk, binary, len(load_scene(str(folder / "l_room.glb")).mesh.faces)


@pytest.mark.parametrize("where", ["before", "after"])
def test_a_glb_chunk_of_an_unknown_type_is_skipped_wherever_it_stands(where, glb_parts, tmp_path):
    """The glTF specification has readers ignore chunks of types they do not know: one between the
    JSON and the BIN chunk was taken for a missing BIN chunk."""
    json_chunk, binary, faces = glb_parts
    extra = (b"XTRA", b"something an extension wrote")
    chunks = [extra, (b"BIN\0", binary)] if where == "before" else [(b"BIN\0", binary), extra]
    path = tmp_path / "x.glb"
    path.write_bytes(_glb(json_chunk, chunks))
    assert len(load_scene(str(path)).mesh.faces) == faces


def test_a_glb_of_its_header_alone_is_said_to_be_truncated(glb_parts, tmp_path):
    json_chunk, binary, _ = glb_parts
    path = tmp_path / "x.glb"
    path.write_bytes(_glb(json_chunk, [(b"BIN\0", binary)])[:12])
    with pytest.raises(InvalidMeshError, match=r"the GLB file is 12 bytes: a header with no JSON chunk"):
        load_scene(str(path))
    path.write_bytes(b"glTX" + bytes(40))
    with pytest.raises(InvalidMeshError, match=r"does not start with the 'glTF' magic"):
        load_scene(str(path))


# ---------------------------------------------------------------------- JSON keys named twice
def test_a_json_object_naming_a_key_twice_is_refused_wherever_json_is_read(glb_parts, tmp_path):
    """Python keeps the last of two values: a plan edited by hand, or a glTF header, was read as what
    its author did not see first."""
    from scenes import FloorPlanError
    from scenes.jsonio import JSONDuplicateKeyError, read_json

    assert read_json('{"a": 1, "b": {"a": 2}}') == {"a": 1, "b": {"a": 2}}  # one key in two objects
    with pytest.raises(JSONDuplicateKeyError, match=r"the key 'a' appears twice in one object"):
        read_json('{"a": 1, "b": {"a": 2, "a": 3}}')

    from pathlib import Path

    plan = (Path(__file__).parents[1] / "scenes" / "data" / "l_room.json").read_text()
    path = tmp_path / "plan.json"
    path.write_text(plan.replace("{", '{"ceiling_height": 9.0, ', 1))
    with pytest.raises(FloorPlanError, match=r"the key 'ceiling_height' appears twice"):
        load_scene(str(path))

    json_chunk, binary, _ = glb_parts
    doc = json.loads(json_chunk)
    text = json.dumps(doc)
    text = text.replace('"asset": {', '"asset": {"version": "1.0", ', 1)
    path = tmp_path / "x.glb"
    path.write_bytes(_glb(text.encode(), [(b"BIN\0", binary)]))
    with pytest.raises(InvalidMeshError, match=r"the key 'version' appears twice"):
        load_scene(str(path))


# ---------------------------------------------------------------------- a damaged learning curve
@pytest.mark.parametrize(
    "line, message",
    [
        ('{"timesteps": 8}', r"line 2 has no learned figures"),
        ('{"timesteps": "8", "learned": {}}', r'line 2 has timesteps "8", not a count of steps'),
        (
            '{"timesteps": 8, "learned": {"structure_sensed_pct": 1, "scans": 2, "path_length_m": NaN}}',
            r"line 2 has learned\.path_length_m NaN, not a finite number",
        ),
        ("[1, 2]", r"line 2 is not a record"),
        ('{"timesteps": 8, "timesteps": 9}', r"line 2 is not JSON \(the key 'timesteps' appears twice"),
    ],
)
def test_a_damaged_learning_curve_is_refused_before_a_resumed_run_trains(line, message, tiny_run, tmp_path, capsys):
    """The curve was read whole only by the plot at the end: the run trained, then ended in a traceback."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    curve = run / "learning_curve.jsonl"
    good = {"timesteps": 0, "learned": {"structure_sensed_pct": 50.0, "scans": 3, "path_length_m": 4.5}}
    curve.write_text(json.dumps(good) + "\n" + line + "\n")
    before = _files(run)
    code, err = _train(["--resume", str(run), "--timesteps", "24", "--quiet"], capsys)
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert f"{curve}: " in err and "remove it to continue" in err, err
    assert __import__("re").search(message, err), err
    assert _files(run) == before  # nothing trained, nothing written


# ---------------------------------------------------------------------- numbers in the format's grammar
_ROOM_OBJ = (
    "v 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n"
    "g floor\nf 1 2 3 4\ng ceiling\nf 5 8 7 6\ng wall\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n"
)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("v 4 0 0", "v 4_0 0 0", r"line 2: a vertex has a coordinate that is no ASCII number: 'v 4_0 0 0'"),
        ("v 4 0 0", "v \u0664 0 0", r"line 2: a vertex has a coordinate that is no ASCII number: 'v \u0664 0 0'"),
        ("v 4 0 0", "v 4\u00a00 0", r"line 2: a vertex needs x y z"),  # a no-break space separates nothing
        ("f 1 2 3 4", "f 1 2 3 4_0", r"line 10: bad vertex reference '4_0'"),
        ("f 1 2 3 4", "f 1 2 3 \u0664", r"line 10: bad vertex reference '\u0664'"),
    ],
)
def test_obj_numbers_are_read_in_the_format_s_grammar_not_python_s(old, new, message, tmp_path):
    """Python's float and int read "4_0" as 40 and Arabic-Indic digits as digits, and its split
    breaks at a no-break space: files every other reader refuses (or reads otherwise) loaded."""
    path = tmp_path / "room.obj"
    path.write_text(_ROOM_OBJ)
    assert len(load_scene(str(path)).mesh.faces) == 12
    path.write_text(_ROOM_OBJ.replace(old, new, 1))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


@pytest.mark.parametrize("ending", ["\n", "\r\n", "\r"])
def test_an_obj_with_a_byte_order_mark_or_any_line_ending_keeps_every_vertex(ending, tmp_path):
    """A byte-order mark hid the first "v" line's keyword: the vertex was dropped, and the faces that
    use it named others."""
    path = tmp_path / "room.obj"
    path.write_bytes(b"\xef\xbb\xbf" + _ROOM_OBJ.replace("\n", ending).encode())
    scene = load_scene(str(path))
    assert len(scene.mesh.vertices) == 8 and len(scene.mesh.faces) == 12
    assert scene.mesh.vertices.min(axis=0).tolist() == [0, 0, 0]


@pytest.mark.parametrize("old, new", [("4 0 0", "4_0 0 0"), ("4 0 0", "\u0664 0 0"), ("4 0 0", "4\u00a00 0")])
def test_an_ascii_ply_value_in_another_grammar_is_named_with_its_record(old, new, tmp_path):
    from tests.test_probe6 import GOOD_FACES, _ply_text

    path = tmp_path / "room.ply"
    path.write_text(_ply_text(GOOD_FACES).replace(old, new, 1), encoding="utf-8")
    with pytest.raises(InvalidMeshError, match=r"element 'vertex' record 1 \(line 13\) holds a value that is no ASCII"):
        load_scene(str(path))


# ---------------------------------------------------------------------- records of earlier runs
@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    from tests.test_compare_resume_records import nbs

    out = tmp_path_factory.mktemp("compare") / "out"
    args = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0", "--preset", "fast"]
    done = nbs(*args, "--max-scans", "1", "--quiet", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


def _grid():
    from train.compare import grid

    return grid("l_room", "random", "0", "fast", {"max_scans": 1})


@pytest.mark.parametrize(
    "edit",
    [
        lambda p: p["coverage_pct"].append(100.0),  # a curve longer than the positions
        lambda p: p.update(positions=p["positions"][:-1]),
        lambda p: p["coverage_pct"].reverse(),  # coverage that falls
        lambda p: p.update(max_coverage_pct=p["coverage_pct"][-1] / 2),  # the curve above the best
        lambda p: p.update(candidates=0),
        lambda p: p.update(samples=-1),
    ],
)
def test_resume_runs_the_oracle_again_when_its_record_is_none_it_could_have_written(edit, compared, tmp_path):
    """An oracle.json whose coverage curve had more values than positions was reused: the table's
    "scans the oracle needs" read from a curve no plan had."""
    import shutil

    from policies.oracle import OraclePlan
    from train.compare import load_finished

    out = tmp_path / "out"
    shutil.copytree(compared, out)
    assert "l_room" in load_finished(out, _grid())["oracles"]
    stored = json.loads((out / "oracle.json").read_text())
    OraclePlan.from_dict(stored["l_room"])  # the record as written is one
    edit(stored["l_room"])
    with pytest.raises(ValueError):
        OraclePlan.from_dict(stored["l_room"])
    (out / "oracle.json").write_text(json.dumps(stored))
    assert "l_room" not in load_finished(out, _grid())["oracles"]


@pytest.mark.parametrize("in_the_way", ["runs/l_room", "runs/l_room/random", "runs/l_room/random/seed1"])
def test_a_file_where_a_run_s_folder_goes_is_refused_before_any_run(in_the_way, tmp_path, capsys, monkeypatch):
    """Found when the run was written: the run (and with a file high up, every run) was lost."""
    import train.compare as compare
    from train.cli import main as nbs

    def never(*args, **kwargs):
        raise AssertionError("a run started")

    monkeypatch.setattr(compare, "run_grid", never)
    out = tmp_path / "out"
    (out / in_the_way).parent.mkdir(parents=True)
    (out / in_the_way).write_text("mine")
    argv = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0,1", "--preset", "fast"]
    code = nbs([*argv, "--max-scans", "1", "--quiet", "--out", str(out), "--resume"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert f"{out / in_the_way} is a file where the folder of the run of scene 'l_room', policy 'random'" in err
    assert (out / in_the_way).read_text() == "mine"


# ---------------------------------------------------------------------- reset options
@pytest.fixture(scope="module")
def l_room_env():
    from nbs_env import NBSEnv

    env = NBSEnv("fast", scene="l_room")
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("start", [["3", "4.5"], [True, 4.5], "34", [[3, 4.5]], [3, None]])
def test_a_start_of_anything_but_numbers_is_refused_by_name(start, l_room_env):
    """numpy turned "3" into 3.0 and True into 1.0: a start read from a text file kept its strings."""
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match=r"options\['start'\] must be 2 or 3 finite numbers"):
        l_room_env.reset(seed=0, options={"start": start})


def test_a_start_off_the_floor_is_refused_naming_the_start(l_room_env):
    """A start 100 m up put the scanner above the ceiling: the error came from the region of
    interest and named no start."""
    import numpy as np

    from nbs_env.errors import InvalidPoseError

    x, y, z = l_room_env.storey.scene.start
    for given, height in (([x, y], z), ((x, y, z + 0.2), z + 0.2), (np.array([x, y, z]), z)):  # on the floor or near
        l_room_env.reset(seed=0, options={"start": given})
        assert l_room_env.storey.scene.start[2] == pytest.approx(height)
    with pytest.raises(InvalidPoseError, match=r"start \[3\.0, 4\.5, 100\.0\] is \+100\.00 m from the floor under it"):
        l_room_env.reset(seed=0, options={"start": [x, y, 100]})


# ---------------------------------------------------------------------- probe 10
def _hall(side: float) -> dict:
    from pathlib import Path

    plan = json.loads((Path(__file__).parents[1] / "scenes" / "data" / "l_room.json").read_text())
    plan["rooms"] = [{"name": "hall", "polygon": [[0, 0], [side, 0], [side, side], [0, side]]}]
    for key in ("clutter", "doors", "windows"):
        plan.pop(key, None)
    plan["start"] = [5, 5]
    return plan


def test_a_storey_whose_ground_truth_samples_would_not_fit_is_refused_with_the_spacing_that_fits(monkeypatch):
    """A 490 m hall is within the extent bounds, but its 1.9e8 samples asked for 1.45 GiB in one array
    (and many times that in all); the advice was to coarsen the voxel, which changes nothing. The
    spacing advised meets the memory bound too (0.16 m asked for 9.1 GiB of a process with 2.9)."""
    import scenes.limits as limits
    from scenes import StoreySizeError
    from scenes.floorplan import FloorPlan

    scene = load_scene(FloorPlan.from_dict(_hall(490), source="hall.json"))
    monkeypatch.setattr(limits, "memory_left", lambda: None)
    with pytest.raises(StoreySizeError, match=r"would sample it at 194,000,194 points .* coverage_spacing=0\.16"):
        scene.structure_samples(0.05)
    monkeypatch.setattr(limits, "memory_left", lambda: (3 << 30, "its limit"))
    with pytest.raises(StoreySizeError, match=r"coverage_spacing=0\.28\)"):
        scene.structure_samples(0.05)
    with pytest.raises(StoreySizeError, match=r"takes about [\d.]+ GiB.*coverage_spacing=0\.32\)"):
        scene.structure_samples(0.16)
    small = load_scene(FloorPlan.from_dict(_hall(12), source="hall.json"))
    assert len(small.structure_samples(0.05).points) == round(small.structural_area() / 0.05**2)


def _scan(out, *extra: str) -> list[str]:
    return ["scan", "--scene", "l_room", "--preset", "fast", "--out", str(out), "--quiet", *extra]


def test_a_scan_that_fails_writing_its_report_keeps_the_earlier_report_with_its_own_pictures(
    tmp_path, capsys, monkeypatch
):
    """The step pictures were written into --out/steps during the run: a report that then failed
    (a full disk) left the earlier report with the failed run's pictures, and a run into a new
    folder left a folder a rerun refused as an earlier report."""
    import errno

    import nbs_env.export as export
    from train.cli import main as nbs

    out = tmp_path / "report"
    assert nbs(_scan(out, "--max-scans", "2")) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert {str(p) for p in before if p.parts[0] == "steps"} == {"steps/step_000.png", "steps/step_001.png"}

    def full(env, folder, *args, **kwargs):
        (folder / "metrics.json").write_text("{")
        raise OSError(errno.ENOSPC, "No space left on device", str(folder / "cloud.laz"))

    monkeypatch.setattr(export, "_write_report_files", full)
    capsys.readouterr()
    assert nbs(_scan(out, "--max-scans", "3", "--seed", "1", "--force")) != 0
    assert "No space left on device" in capsys.readouterr().err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the earlier report whole, its own pictures, nothing of the failed run
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []

    fresh = tmp_path / "fresh"
    assert nbs(_scan(fresh, "--max-scans", "2")) != 0
    assert not fresh.exists()  # a rerun is not refused as onto an earlier report


@pytest.mark.parametrize(
    "name, uri, folder",
    [
        ("escaped.gltf", "buf%20one.bin", "."),  # RFC 3986 escapes, as Blender writes names with blanks
        ("up.gltf", "../plain.bin", "sub"),  # a buffer shared by the glTFs of several folders
        ("url.gltf", "FILE_URI", "."),
    ],
)
def test_a_gltf_buffer_named_by_any_uri_reference_to_a_local_file_loads(name, uri, folder, glb_parts, tmp_path):
    """trimesh's resolver neither decodes %20 nor follows ../: valid files were refused with its
    advice to pass `FilePathResolver(path, allow_anywhere=True)`."""
    json_chunk, binary, faces = glb_parts
    (tmp_path / "buf one.bin").write_bytes(binary)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri=uri.replace("FILE_URI", (tmp_path / "plain.bin").as_uri()))]
    path = tmp_path / folder / name
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps(doc))
    assert len(load_scene(str(path)).mesh.faces) == faces


@pytest.mark.parametrize(
    "uri, message",
    [
        ("http://example.com/b.bin", r"uri 'http://example\.com/b\.bin' is a http: URI; nbs-env reads local"),
        ("data:,abc", r"buffers\[0\]\.uri is a data: URI without ;base64"),
    ],
)
def test_a_gltf_buffer_uri_nbs_env_cannot_read_is_named(uri, message, glb_parts, tmp_path):
    json_chunk, _, _ = glb_parts
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri=uri)]
    path = tmp_path / "x.gltf"
    path.write_text(json.dumps(doc))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("4 0 4 5 1 2 0", "4 0 4 5 1 256 0", r"record 2 \(line 22\): its 'label' value 256 is no 'uchar'"),
        ("4 0 4 5 1 2 0", "4 0 4 5 1 -1 0", r"record 2 \(line 22\): its 'label' value -1 is no 'uchar'"),
        ("4 0 1 2 3 0 0", "4 0 4294967296 2 3 0 0", r"PLY face 0 has vertex index 4294967296, which its header's type"),
        ("4 0 1 2 3 0 0", "4 0 1 2 3 0 2147483648", r"record 0 \(line 20\): its 'room' value 2147483648 is no 'int'"),
        ("4 0 0\n", "300 0 0\n", None),  # a uchar x of 300 was 44 (trimesh casts), then 300 (read wide)
        ("4 0 0\n", "4.5 0 0\n", None),  # an int x of 4.5
    ],
)
def test_an_ascii_ply_value_its_declared_type_cannot_hold_is_refused(old, new, message, tmp_path):
    """Read as float64 and cast to the declared type, a uchar label of 256 became 0: a wall was read
    as floor without a word, and an index of 2^32 named another vertex."""
    from tests.test_probe6 import GOOD_FACES, _ply_text

    path = tmp_path / "room.ply"
    text = _ply_text(GOOD_FACES)
    assert old in text
    if message is None:  # a vertex coordinate of an integer type
        kind = "uchar" if new.startswith("300") else "int"
        text = text.replace("property float x", f"property {kind} x")
        message = rf"element 'vertex' record 1 \(line 13\): its 'x' value {new.split()[0]} is no '{kind}'"
    path.write_text(text.replace(old, new, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's "invalid value encountered in cast" was printed too
        with pytest.raises(InvalidMeshError, match=message):
            load_scene(str(path))


def test_more_env_workers_than_the_machine_takes_are_refused_before_any_starts(tmp_path, capsys, monkeypatch):
    """500 spawn workers, each importing torch, were killed for memory with no message."""
    import os

    import train.ppo as ppo

    def never(*args, **kwargs):
        raise AssertionError("a worker started")

    monkeypatch.setattr(ppo, "make_training_envs", never)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    code, err = _train(["--out", str(tmp_path / "run"), "--envs", "5", "--timesteps", "32", "--quiet"], capsys)
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert "--envs 5: this machine has 2 cores" in err and "pass at most --envs 4" in err, err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("kind", ["on a straight wall", "written twice", "a nanometre apart", "closing the ring"])
def test_a_room_corner_that_adds_nothing_to_the_outline_is_dropped(kind):
    """A point where a neighbour's wall meets (a T junction, as plans traced from drawings have), or a
    corner written twice, made the walls' offset drop a corner: the room was refused as "too narrow"."""
    from pathlib import Path

    from scenes.floorplan import FloorPlan

    plan = json.loads((Path(__file__).parents[1] / "scenes" / "data" / "five_rooms.json").read_text())
    faces = len(load_scene(FloorPlan.from_dict(plan, source="five_rooms.json")).mesh.faces)
    ring = plan["rooms"][0]["polygon"]
    (x0, y0), (x1, y1) = ring[0], ring[1]
    plan["rooms"][0]["polygon"] = {
        "on a straight wall": [ring[0], [(x0 + x1) / 2, (y0 + y1) / 2], *ring[1:]],
        "written twice": [ring[0], ring[0], *ring[1:]],
        "a nanometre apart": [ring[0], [x0 + 1e-9, y0], *ring[1:]],
        "closing the ring": [*ring, ring[0]],
    }[kind]
    assert len(load_scene(FloorPlan.from_dict(plan, source="edited.json")).mesh.faces) == faces


@pytest.mark.parametrize("start", [0, 2, 3])
@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_a_concave_polygon_face_is_triangulated_within_its_outline(start, fmt, tmp_path):
    """An L-shaped floor written as one face was fanned from its first corner: from some corners the
    fan covers the L's missing quarter, and the floor was a third larger, silently."""
    import numpy as np

    from scenes.labels import SurfaceClass

    outline = [[0, 0], [8, 0], [8, 4], [4, 4], [4, 8], [0, 8]]
    ring = list(range(6))[start:] + list(range(6))[:start]
    vertices = [[x, y, 0] for x, y in outline] + [[x, y, 2.5] for x, y in outline]
    walls = [[k, (k + 1) % 6, 6 + (k + 1) % 6, 6 + k] for k in range(6)]
    ceiling = [6 + k for k in reversed(ring)]
    faces = [("floor", ring), ("ceiling", ceiling)] + [("wall", w) for w in walls]
    path = tmp_path / f"l.{fmt}"
    if fmt == "obj":
        text = "".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
        text += "".join(f"o {name}_{k}\nf {' '.join(str(i + 1) for i in f)}\n" for k, (name, f) in enumerate(faces))
    else:
        label = {"floor": 0, "ceiling": 1, "wall": 2}
        text = (
            f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\n"
            "property uchar label\nend_header\n"
        )
        text += "".join(f"{x} {y} {z}\n" for x, y, z in vertices)
        text += "".join(f"{len(f)} {' '.join(map(str, f))} {label[name]}\n" for name, f in faces)
    path.write_text(text)
    scene = load_scene(str(path))
    for cls in (SurfaceClass.FLOOR, SurfaceClass.CEILING):
        mask = scene.face_labels == cls.value
        assert scene.mesh.area_faces[mask].sum() == pytest.approx(48.0)
        normals = scene.mesh.face_normals[mask][:, 2]
        assert np.all(normals > 0.99) if cls is SurfaceClass.FLOOR else np.all(normals < -0.99)


def test_a_polygon_face_that_crosses_itself_is_named(tmp_path):
    path = tmp_path / "bow.obj"
    path.write_text(
        "v 0 0 0\nv 8 0 0\nv 8 4 0\nv 0 8 0\nv 0 0 2.5\nv 8 0 2.5\nv 8 8 2.5\n"
        "o floor\nf 1 2 3\no wall\nf 1 3 2 4\no ceiling\nf 5 6 7\n"
    )
    with pytest.raises(InvalidMeshError, match=r"line 11: the face.s outline crosses itself"):
        load_scene(str(path))


def _ifc_with_start(folder, start_x: str | None, unit: str = "$", extra: str = ""):
    """tests/data/two_rooms.ifc with a Pset_NbsStart on storey EG: StartX ``start_x`` (left out when
    None) in ``unit`` (``$``: the file's), StartY 2 m; ``extra`` lines before it."""
    from pathlib import Path

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    x = f"#5000=IFCPROPERTYSINGLEVALUE('StartX',$,{start_x},{unit});\n" if start_x else ""
    props = "(#5000,#5001)" if start_x else "(#5001)"
    added = (
        f"{extra}{x}#5001=IFCPROPERTYSINGLEVALUE('StartY',$,IFCLENGTHMEASURE(2.),$);\n"
        f"#5002=IFCPROPERTYSET('0aaaaaaaaaaaaaaaaaaaa1',$,'Pset_NbsStart',$,{props});\n"
        "#5003=IFCRELDEFINESBYPROPERTIES('0aaaaaaaaaaaaaaaaaaaa2',$,$,$,(#14),#5002);\n"
    )
    at = text.rindex("ENDSEC;")
    path = folder / "start.ifc"
    path.write_text(text[:at] + added + text[at:])
    return path


@pytest.mark.parametrize(
    "value, shown",
    [("IFCLABEL('6.0')", r"'6\.0' \(IfcLabel\)"), ("IFCBOOLEAN(.T.)", r"True \(IfcBoolean\)"), (None, "missing")],
)
def test_an_ifc_start_that_is_no_pair_of_lengths_is_refused_naming_the_property(value, shown, tmp_path):
    """A label '6.0' was dropped for the automatic start without a word, a boolean taken as 1 m."""
    pytest.importorskip("ifcopenshell")

    from scenes import IfcError

    path = _ifc_with_start(tmp_path, value)
    with pytest.raises(IfcError, match=rf"storey 'EG': Pset_NbsStart\.StartX is {shown}; the start is two lengths"):
        load_scene(str(path), storey="EG")
    if value:
        path = _ifc_with_start(tmp_path, "IFCLENGTHMEASURE(6.)")
        assert load_scene(str(path), storey="EG").start[:2].tolist() == [6.0, 2.0]


def test_no_two_runs_of_a_comparison_share_a_folder(tmp_path, monkeypatch):
    """`:` became `_`: `ppo:ck_x:y` and `ppo:ck_x_y` wrote one folder, each run over the other's records."""
    import train.compare as compare
    from train.compare import CompareError, folder_name, grid

    assert folder_name("ppo:ck_x:y") != folder_name("ppo:ck_x_y") == "ppo_ck_x_y"
    assert [folder_name(n) for n in ("ppo:reference", "generated:7", "greedy")] == [
        "ppo_reference",
        "generated_7",
        "greedy",
    ]
    monkeypatch.setattr(compare, "folder_name", lambda name: "same")
    with pytest.raises(CompareError, match=r"policy 'greedy' and of scene 'l_room', policy 'random' would keep"):
        grid("l_room", "greedy,random", "0")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["scan", "--scene", "l_room", "--max-scans", "\u0661"], "argument --max-scans: expected an integer, got"),
        (["scan", "--scene", "l_room", "--seed", "1_0"], "argument --seed: expected an integer, got"),
        (["scan", "--scene", "l_room", "--start", "\u0663,3"], "argument --start: expected X,Y in metres"),
        (["scenes", "generate", "--seed", "3", "--rooms", "\uff12", "--out", "g.json"], "argument --rooms"),
        (["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "1_0", "--out", "c"], "seeds must be"),
        (["scan", "--scene", "l_room", "--policy", "greedy:0.9+stop=\u0660.1"], "greedy takes NEAR"),
        (["scan", "--scene", "l_room", "--resolution", "0_5"], "argument --resolution: expected a number"),
    ],
)
def test_command_line_numbers_are_ascii_as_in_every_file_nbs_env_reads(argv, message, tmp_path, monkeypatch, capsys):
    """Python's int and float took Arabic-Indic and full-width digits and `_` separators."""
    from train.cli import main as nbs

    monkeypatch.chdir(tmp_path)
    try:
        code = nbs(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and message in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        ("image", "pixel", 1e-9, r"'image\.pixel': expected within \[0\.005, 1\] metres, got 1e-09"),
        ("image", "band", 1e9, r"'image\.band': expected within \[0, 1\] metres, got 1e\+09"),
        ("svm", "gamma", 1e308, r"'svm\.gamma': expected within \(0, 1e\+06\], got 1e\+308"),
    ],
)
def test_a_classifier_file_whose_image_or_kernel_no_face_could_use_is_refused_at_load(section, key, value, message):
    """A pixel of 1e-9 m (its checksum recomputed) loaded, then a face's image was a bare numpy
    ValueError ("array is too big"); a gamma of 1e308 overflowed and every face was clutter."""
    from importlib import resources

    from nbs_env.errors import ModelFileError
    from nbs_env.perception.structure import SEClassifier, _checksum

    document = json.loads(resources.files("nbs_env.perception").joinpath("data/se_svm.json").read_text())
    document[section][key] = value
    del document["sha256"]
    document["sha256"] = _checksum(document)
    with pytest.raises(ModelFileError, match=message):
        SEClassifier.from_text(json.dumps(document), source="edited.json")


def test_the_preset_may_be_named_by_keyword_where_the_configuration_is_made():
    """`NBSEnv(scene="office", preset="fast")` ended in a bare TypeError (make_config got the preset twice)."""
    from nbs_env import NBSEnv
    from nbs_env.config import make_config
    from nbs_env.errors import ConfigError

    assert make_config(preset="fast", scene="l_room") == make_config("fast", scene="l_room")
    assert NBSEnv(scene="l_room", preset="fast").config == make_config("fast", scene="l_room")
    with pytest.raises(ConfigError, match=r"preset 'paper' given as a field, but the configuration starts from 'fast'"):
        NBSEnv("fast", preset="paper")
    with pytest.raises(ConfigError, match=r"starts from a configuration of preset 'fast'"):
        make_config(make_config("fast"), preset="paper")


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda b: b + b"GARBAGE!", r"but the file has [\d,]+: bytes follow its end"),
        (lambda b: b[:4] + struct.pack("<I", 1) + b[8:], r"a GLB of version 1 \(glTF 2\.0 is version 2\)"),
    ],
)
def test_a_glb_framed_otherwise_than_its_header_says_is_named(damage, message, glb_parts, tmp_path):
    """Bytes after the declared end gave trimesh's "chunk was not expected length!", a version-1
    header its NotImplementedError."""
    json_chunk, binary, _ = glb_parts
    path = tmp_path / "x.glb"
    path.write_bytes(damage(_glb(json_chunk, [(b"BIN\0", binary)])))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


def test_a_glb_with_two_json_chunks_or_a_gltf_1_header_is_refused(glb_parts, tmp_path):
    json_chunk, binary, _ = glb_parts
    path = tmp_path / "x.glb"
    path.write_bytes(_glb(json_chunk, [(b"BIN\0", binary), (b"JSON", json_chunk)]))
    with pytest.raises(InvalidMeshError, match=r"holds a second JSON chunk"):
        load_scene(str(path))
    doc = json.loads(json_chunk)
    doc["asset"]["version"] = "1.0"
    path.write_bytes(_glb(json.dumps(doc).encode(), [(b"BIN\0", binary)]))
    with pytest.raises(InvalidMeshError, match=r"asset\.version is '1\.0': nbs-env reads glTF 2\.0"):
        load_scene(str(path))


def test_scenes_info_says_when_nbs_scan_would_refuse_the_start():
    """A file's start 60 m away was printed by `nbs scenes info` as any other, and refused by `nbs scan`."""
    from train.cli import _scene_summary

    scene = load_scene("l_room")
    assert _scene_summary(scene)["start_problem"] is None
    scene.start = (60.0, 2.0)
    assert "start [60.0, 2.0] is not free floor" in _scene_summary(scene)["start_problem"]


def test_two_spellings_of_one_scene_or_checkpoint_are_one_run(monkeypatch):
    """`generated:1,generated:01` ran and tabled one storey twice; `ppo:tr,ppo:./tr` one checkpoint."""
    from policies.learned import BUNDLED
    from train.compare import CompareError, grid

    with pytest.raises(CompareError, match=r"--scenes names generated:1 and generated:01: one run each"):
        grid("generated:1,generated:01", "random", "0")
    folder = BUNDLED["reference"]
    monkeypatch.chdir(folder.parent)
    with pytest.raises(CompareError, match=r"--policies names ppo:reference and ppo:\./ppo_reference: one run"):
        grid("l_room", f"ppo:reference,ppo:./{folder.name}", "0")
    with pytest.raises(CompareError, match=r"--policies names ppo:reference and ppo:[^ ]*policy\.json"):
        grid("l_room", f"ppo:reference,ppo:{folder / 'policy.json'}", "0")
    assert len(grid("generated:1,generated:2", "random", "0")) == 2
    from scenes import UnknownSceneError, load_scene

    for name in ("generated:+1", "generated: 1", "generated:\u0661", "generated:-1"):
        with pytest.raises(UnknownSceneError, match=r"is not an integer >= 0 in digits"):
            load_scene(name)


# ---------------------------------------------------------------------- probe 11
def _load_with_buffer_uri(json_chunk: bytes, uri: str, faces: int, message: str | None, folder) -> None:
    """A glTF of the GLB's JSON with its buffer at ``uri``: it loads its ``faces``, or is refused with ``message``."""
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri=uri)]
    path = folder / "x.gltf"
    path.write_text(json.dumps(doc))
    if message is None:
        assert len(load_scene(str(path)).mesh.faces) == faces
    else:
        with pytest.raises(InvalidMeshError, match=message):
            load_scene(str(path))


@pytest.mark.parametrize(
    "polygon, area",
    [
        ([0, 1, 1, 2, 3, 4, 5], 48.0),  # a corner written twice: a collapsed edge, not a crossing
        ([0, 1, 2, 3, 4, 5, 0], 48.0),  # the first corner closing the ring
        ([0, 1, 1, 0], 0.0),  # collapsed to an edge: no surface, no triangle
    ],
)
def test_a_corner_repeated_next_to_itself_is_one_corner(polygon, area):
    import numpy as np

    from scenes.geometry import triangulate_polygons

    v = np.array([[0, 0, 0], [8, 0, 0], [8, 4, 0], [4, 4, 0], [4, 8, 0], [0, 8, 0]], float)
    tris, source = triangulate_polygons(v, [polygon])
    a, b, c = (v[tris[:, k]] for k in range(3))
    assert 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() == pytest.approx(area)
    assert (source == 0).all() and all(len(set(t)) == 3 for t in tris.tolist())


@pytest.mark.parametrize(
    "points, polygon",
    [
        ("star", [0, 2, 4, 1, 3]),  # every turn the same way, twice round
        ("square", [0, 1, 2, 3, 0, 1, 2, 3]),  # a ring written twice
        ("square", [0, 2, 1, 3]),  # a bow-tie, its lobes cancelling
    ],
)
def test_a_polygon_that_goes_round_twice_or_not_at_all_is_refused(points, polygon):
    """A ring written twice and a pentagram turn one way at every corner: fanned, a floor counted twice."""
    import numpy as np

    from scenes.geometry import CrossingPolygonError, triangulate_polygons

    if points == "star":
        angle = np.pi / 2 + np.arange(5) * 2 * np.pi / 5
        v = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(5)])
    else:
        v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    with pytest.raises(CrossingPolygonError):
        triangulate_polygons(v, [polygon])
    assert len(triangulate_polygons(v, [list(range(len(v)))])[0]) == len(v) - 2


@pytest.mark.parametrize(
    "uri, message",
    [
        ("missing.bin", r"buffers\[0\]\.uri 'missing\.bin' names .*missing\.bin, which does not exist"),
        ("buf%00one.bin", r"holds a NUL character"),
        ("plain.bin#x", None),
        ("plain.bin?v=2", None),
        ("file:plain.bin", None),
        ("BASE64", None),
    ],
)
def test_gltf_side_files_are_found_as_uri_references_or_named(uri, message, glb_parts, tmp_path):
    """A missing side file was Python's FileNotFoundError, a %00 "embedded null byte"; a query or a
    fragment was part of the name; a data: URI's marker in capitals was not base64."""
    import base64

    json_chunk, binary, faces = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    if uri == "BASE64":
        uri = "data:application/octet-stream;BASE64," + base64.b64encode(binary).decode()
    _load_with_buffer_uri(json_chunk, uri, faces, message, tmp_path)


def test_a_gltf_with_a_byte_order_mark_is_refused_by_name(glb_parts, tmp_path):
    """The layout check took it, trimesh's reader did not, naming a file the input never names."""
    json_chunk, binary, _ = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    path = tmp_path / "x.gltf"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(doc).encode())
    with pytest.raises(InvalidMeshError, match=r"starts with a byte-order mark, which glTF 2\.0 forbids"):
        load_scene(str(path))


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda d: d["scaler"].update(scale=[1e-300, 1, 1]), "scaler.scale"),
        (lambda d: d["scaler"].update(mean=[1e308, 0, 0]), "scaler.mean"),
        (
            lambda d: d["svm"].update(support_vectors=[[1e300, 0, 0]] * len(d["svm"]["support_vectors"])),
            "svm.support_vectors",
        ),
    ],
)
def test_a_classifier_whose_scaler_or_vectors_would_overflow_is_refused_at_load(edit, field):
    """Each loaded, and the decision overflowed at the first face: every face clutter, silently."""
    from importlib import resources

    from nbs_env.errors import ModelFileError
    from nbs_env.perception.structure import SEClassifier, _checksum

    document = json.loads(resources.files("nbs_env.perception").joinpath("data/se_svm.json").read_text())
    edit(document)
    del document["sha256"]
    document["sha256"] = _checksum(document)
    with pytest.raises(ModelFileError, match=rf"field '{field}'"):
        SEClassifier.from_text(json.dumps(document), source="edited.json")


@pytest.mark.parametrize("measure", ["IFCPLANEANGLEMEASURE(6.)", "IFCAREAMEASURE(6.)", "IFCINTEGER(6)"])
def test_an_ifc_start_of_another_measure_than_a_length_is_refused(measure, tmp_path):
    """An angle, an area or a count came back a number like a length: taken as 6 m."""
    pytest.importorskip("ifcopenshell")

    from scenes import IfcError

    path = _ifc_with_start(tmp_path, measure)
    with pytest.raises(IfcError, match=r"Pset_NbsStart\.StartX is 6(\.0)? \(Ifc\w+\)"):
        load_scene(str(path), storey="EG")


@pytest.mark.parametrize(
    "policies", ["greedy:0.8,greedy:0.80", "greedy,greedy:1", "greedy:0.8+stop=0.08,greedy:stop=0.08+0.8"]
)
def test_two_spellings_of_one_policy_are_one_run(policies):
    from train.compare import CompareError, grid

    with pytest.raises(CompareError, match=r"--policies names .* and .*: one run each"):
        grid("l_room", policies, "0")
    assert len(grid("l_room", "greedy,greedy:0.8", "0")) == 2


def test_a_resumed_run_refuses_options_it_would_not_apply_and_applies_envs(tiny_run, tmp_path, capsys, monkeypatch):
    """`--n-steps 8 --seed 5` were dropped without a word; `--envs 2` (the default) was not applied,
    so a run recorded with 500 envs was refused for its own number after the user lowered it."""
    import shutil

    import train.ppo as ppo

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    before = _files(run)
    code, err = _train(["--resume", str(run), "--timesteps", "48", "--n-steps", "8", "--seed", "5", "--quiet"], capsys)
    assert code == EXIT_USAGE and "--n-steps, --seed apply to a new run" in err, err
    assert _files(run) == before
    seen = {}

    def stop(config, *args, **kwargs):
        seen["envs"] = config.envs
        raise SystemExit(0)

    monkeypatch.setattr(ppo, "_run", stop)
    state = json.loads((run / "training_state.json").read_text())
    state["run"]["envs"] = 500
    (run / "training_state.json").write_text(json.dumps(state))
    _train(["--resume", str(run), "--timesteps", "48", "--envs", "2", "--quiet"], capsys)
    assert seen == {"envs": 2}


def test_the_staged_step_pictures_get_the_mode_of_any_folder_made_there(tmp_path):
    """mkdtemp's folder is its owner's alone: moved in as steps/, the pictures were unreadable to the
    others who read the rest of the report."""
    import os

    from train.cli import main as nbs

    out = tmp_path / "report"
    umask = os.umask(0o022)
    try:
        assert nbs(_scan(out, "--max-scans", "1")) == 0
    finally:
        os.umask(umask)
    assert (out / "steps").stat().st_mode & 0o777 == 0o755


def test_a_first_signal_mid_rollout_saves_the_last_update_s_count(tmp_path, monkeypatch):
    """stable-baselines3 drops the rollout under way at a stop but counts its steps: the state said
    84 steps of a 16-step rollout, and a resumed total of 160 ended at 164."""
    pytest.importorskip("sb3_contrib")
    import os
    import signal

    from stable_baselines3.common.vec_env import DummyVecEnv

    from tests.test_training import _tiny
    from train.ppo import latest_state, train

    original, calls = DummyVecEnv.step_wait, []

    def step_wait(self):
        calls.append(1)
        if len(calls) == 8 + 3:  # 3 steps into the second rollout of 8
            os.kill(os.getpid(), signal.SIGINT)
        return original(self)

    monkeypatch.setattr(DummyVecEnv, "step_wait", step_wait)
    _, model = train(_tiny(n_steps=8, timesteps=64, checkpoint_every=0, eval_every=0), tmp_path / "run")
    assert model.interrupted == signal.SIGINT
    folder, state = latest_state(tmp_path / "run")
    assert folder == tmp_path / "run" and state["timesteps"] == 8


def test_a_report_written_over_keeps_the_user_s_own_files_in_its_steps_folder(tmp_path):
    """--force replaced steps/ whole: a note of the user's in it was deleted with the old pictures."""
    from train.cli import main as nbs

    out = tmp_path / "report"
    assert nbs(_scan(out, "--max-scans", "3")) == 0
    (out / "steps" / "notes.txt").write_text("mine")
    assert nbs(_scan(out, "--max-scans", "2", "--force")) == 0
    assert sorted(p.name for p in (out / "steps").iterdir()) == ["notes.txt", "step_000.png", "step_001.png"]
    assert nbs(_scan(out, "--max-scans", "1", "--force", "--no-steps")) == 0
    assert sorted(p.name for p in (out / "steps").iterdir()) == ["notes.txt"]


def test_resume_refuses_to_write_over_runs_of_other_settings(compared, tmp_path, capsys):
    """A slip in one option of `--resume` replaced every record of the earlier comparison, unasked."""
    import shutil

    from train.cli import main as nbs

    out = tmp_path / "out"
    shutil.copytree(compared, out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    argv = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0", "--preset", "fast"]
    assert nbs([*argv, "--max-scans", "2", "--quiet", "--out", str(out), "--resume"]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "holds a finished run with max_scans 1, where this comparison has max_scans 2" in err, err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("value, ok", [("25e-1", True), ("2.0-3.6", True), ("2.0-", False), ("2-3e0", True)])
def test_the_cell_size_range_is_split_where_a_range_is(value, ok, tmp_path, capsys, monkeypatch):
    """`25e-1` (2.5 m) was split at its exponent's minus and refused; `2.0-` trained as 2.0 m."""
    import train.ppo as ppo

    seen = {}

    def stop(config, *args, **kwargs):
        seen["cell"] = config.cell_size
        return 0

    monkeypatch.setattr(ppo, "_run", stop)
    code, err = _train(["--out", str(tmp_path / "run"), "--cell-size", value, "--quiet"], capsys)
    if ok:
        assert code == 0 and seen["cell"][0] == pytest.approx(float(value.split("-")[0] if "e-" not in value else 2.5))
    else:
        assert code == EXIT_USAGE and "--cell-size: expected A-B in metres, got '2.0-'" in err, err


def test_a_remote_texture_does_not_refuse_the_geometry(glb_parts, tmp_path):
    """Images are never read, yet an https: image refused the file (a missing local one loaded)."""
    json_chunk, binary, faces = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    doc = json.loads(json_chunk)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    doc["images"] = [{"uri": "https://example.com/tex.png"}, {"uri": "textures/missing.png"}]
    path = tmp_path / "x.gltf"
    path.write_text(json.dumps(doc))
    assert len(load_scene(str(path)).mesh.faces) == faces


def test_a_configuration_and_the_same_preset_by_keyword_agree():
    from nbs_env.config import make_config

    fast = make_config("fast")
    assert make_config(fast, preset="fast") == fast
    assert make_config("fast", preset="fast") == fast


@pytest.mark.parametrize("name", ["../other/training_state.pt", "/etc/passwd", ""])
def test_a_training_state_names_its_tensors_beside_it(name, tiny_run, tmp_path, capsys):
    """`tensors` naming another run's file resumed that run's state; an absolute path was read whole."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    state = json.loads((run / "training_state.json").read_text())
    state["tensors"] = name
    (run / "training_state.json").write_text(json.dumps(state))
    code, err = _train(["--resume", str(run), "--timesteps", "48", "--quiet"], capsys)
    assert code == EXIT_USAGE and "tensors must name a file beside it" in err, err


# ---------------------------------------------------------------------- probe 12
def test_a_short_row_beside_a_long_one_is_no_pair_of_records(tmp_path):
    """Read as one stream and reshaped, `x y` then `x y z w` made two whole vertices of other values."""
    from tests.test_probe6 import GOOD_FACES, _ply_text

    text = _ply_text(GOOD_FACES)
    assert "\n4 0 0\n4 3 0\n" in text
    path = tmp_path / "room.ply"
    path.write_text(text.replace("\n4 0 0\n4 3 0\n", "\n4 0\n4 3 0 0\n", 1))
    with pytest.raises(InvalidMeshError, match=r"element 'vertex' record 1 \(line 13\) holds 2 values"):
        load_scene(str(path))


@pytest.mark.parametrize(
    "uri, message",
    [
        ("file://otherhost/PLAIN", r"names a file on host 'otherhost'"),
        ("//otherhost/PLAIN", r"names a file on host 'otherhost'"),
        ("file://localhost/PLAIN", None),
        ("PERCENT", r"a data: URI with percent-escapes in its base64"),
    ],
)
def test_a_buffer_on_another_host_or_escaped_base64_is_named(uri, message, glb_parts, tmp_path):
    """The host of file://server/share/x.bin was dropped and the local /share/x.bin read; trimesh
    decodes escaped base64 as written, skipping the escapes."""
    import base64
    from urllib.parse import quote

    json_chunk, binary, faces = glb_parts
    (tmp_path / "plain.bin").write_bytes(binary)
    uri = uri.replace("/PLAIN", str(tmp_path / "plain.bin"))
    if uri == "PERCENT":
        uri = "data:application/octet-stream;base64," + quote(base64.b64encode(binary).decode(), safe="")
    _load_with_buffer_uri(json_chunk, uri, faces, message, tmp_path)


def test_a_file_where_the_step_pictures_go_is_refused_before_the_scan(tmp_path, capsys, monkeypatch):
    """Found after the scan, it cost the scan (and the message named the staging folder)."""
    import train.cli as cli

    out = tmp_path / "report"
    out.mkdir()
    (out / "steps").write_text("x")

    def never(*args, **kwargs):
        raise AssertionError("the scan ran")

    monkeypatch.setattr(cli, "_scan", never)
    assert cli.main(_scan(out, "--max-scans", "1", "--force")) == EXIT_USAGE
    assert f"{out / 'steps'} is a file where the folder of the step pictures goes" in capsys.readouterr().err


def test_resume_continues_one_comparison_not_another(compared, tmp_path):
    """`--resume` with other policies rewrote the earlier comparison's oracle and tables without its
    runs; a grid that names all of them and more continues it."""
    import shutil

    from train.compare import CompareError, grid, load_finished

    out = tmp_path / "out"
    shutil.copytree(compared, out)
    with pytest.raises(CompareError, match=r"holds runs this comparison leaves out \(scene 'l_room', policy 'random'"):
        load_finished(out, grid("l_room", "greedy", "0", "fast", {"max_scans": 1}))
    more = grid("l_room", "random,greedy", "0,1", "fast", {"max_scans": 1})
    assert "l_room|random|0" in load_finished(out, more)["runs"]
    shutil.rmtree(out / "runs")
    with pytest.raises(CompareError, match=r"oracle\.json: holds the oracle of 'l_room' with max_scans 1"):
        load_finished(out, grid("l_room", "random", "0", "fast", {"max_scans": 2}))


def test_an_ifc_start_in_a_unit_of_its_own_is_refused(tmp_path):
    """A StartX in feet was taken as metres (6 ft as 6 m)."""
    pytest.importorskip("ifcopenshell")

    from scenes import IfcError

    feet = (
        "#4996=IFCDIMENSIONALEXPONENTS(1,0,0,0,0,0,0);\n"
        "#4997=IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);\n"
        "#4998=IFCMEASUREWITHUNIT(IFCLENGTHMEASURE(0.3048),#4997);\n"
        "#4999=IFCCONVERSIONBASEDUNIT(#4996,.LENGTHUNIT.,'FOOT',#4998);\n"
    )
    path = _ifc_with_start(tmp_path, "IFCLENGTHMEASURE(6.)", unit="#4999", extra=feet)
    with pytest.raises(IfcError, match=r"StartX is 6\.0 \(IfcLengthMeasure in a unit of its own\)"):
        load_scene(str(path), storey="EG")
