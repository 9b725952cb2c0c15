"""Probe 9's findings that remained, each fixed by class: readers that take what the format allows
(GLB chunks), numbers read in a file format's grammar rather than Python's, JSON objects that name a
key twice, records of earlier runs checked before a run continues from them, and reset options named."""

from __future__ import annotations

import json
import struct

import pytest

from scenes import InvalidMeshError, load_scene
from tests.test_train_probe3 import _files, _train, run, tiny_run  # noqa: F401  (fixtures)
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
        ('{"timesteps": "8", "learned": {}}', r"line 2 has timesteps 8, not a count of steps"),
        (
            '{"timesteps": 8, "learned": {"structure_sensed_pct": 1, "scans": 2, "path_length_m": NaN}}',
            r"line 2 has learned\.path_length_m nan, not a finite number",
        ),
        ("[1, 2]", r"line 2 is not a record"),
        ('{"timesteps": 8, "timesteps": 9}', r"line 2 is not JSON \(the key 'timesteps' appears twice"),
    ],
)
def test_a_damaged_learning_curve_is_refused_before_a_resumed_run_trains(line, message, run, capsys):
    """The curve was read whole only by the plot at the end: the run trained, then ended in a traceback."""
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
