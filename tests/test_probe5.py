"""Probe 5's findings, by class: mesh files whose side files, part names or accessors the readers took
on trust (a PLY's texture a fifo, room numbers beyond any storey, positions that are not 3-D floats,
strides that overlap, a side file far larger than its buffer)."""

from __future__ import annotations

import base64
import os
import subprocess
import sys
import time
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
