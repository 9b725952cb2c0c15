"""Bad input found by the seventh hostile probe, kept as tests (each broke the one-line-error rule)."""

from __future__ import annotations

import pytest

from scenes import InvalidMeshError, load_scene
from tests.test_probe6 import GOOD_FACES, _ply_text


@pytest.mark.parametrize(
    "edit, message",
    [
        # numpy's "setting an array element with a sequence" named no record
        (lambda t: t.replace("\n4 0 0\n", "\n4 0\n"), r"element 'vertex' record 1 \(line 13\) holds 2 values"),
        (lambda t: t.replace("4 1 5 6 2 2 0", "4 1 5 6 2 2"), r"element 'face' record 3 \(line 23\) holds 6 values"),
        (lambda t: t.replace("4 1 5 6 2 2 0", "4 1 5 six 2 2 0"), r"element 'face' record 3 \(line 23\) holds a value"),
        (lambda t: t.rsplit("\n", 3)[0] + "\n", r"element 'face' declares 6 records, the body ends at record 4"),
    ],
)
def test_an_ascii_ply_record_that_does_not_fit_its_header_is_named_with_its_line(edit, message, tmp_path):
    path = tmp_path / "bad.ply"
    text = _ply_text(GOOD_FACES)
    path.write_text(text)
    assert len(load_scene(str(path)).mesh.faces) == 12
    path.write_text(edit(text))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


def test_an_index_outside_the_vertices_is_numbered_as_the_format_numbers_vertices(tmp_path):
    """PLY counts vertices from 0: its index -5 was reported as "vertex -4 ... outside 1..8"."""
    path = tmp_path / "bad.ply"
    path.write_text(_ply_text(["4 0 1 2 -5 0 0", *GOOD_FACES[1:]]))
    with pytest.raises(InvalidMeshError, match=r"refer to vertex -5 or other vertices outside 0\.\.7"):
        load_scene(str(path))
    obj = tmp_path / "bad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\no floor\nf 1 2 9\n")
    with pytest.raises(InvalidMeshError, match=r"refer to vertex 9 or other vertices outside 1\.\.3"):
        load_scene(str(obj))
