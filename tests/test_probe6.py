"""Probe 6's findings, by class: names no output can hold, openings counted twice, and IFC units that
convert to themselves or by what is not a number."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from scenes import FloorPlanError, PlanGeometryError, load_scene
from scenes.loader import bundled_plan
from tests.test_probe5 import _fzk

ROOT = Path(__file__).resolve().parents[1]


def _plan(tmp_path: Path, edit) -> Path:
    document = bundled_plan("l_room").to_dict()
    edit(document)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(document))
    return path


# ---------------------------------------------------------------------- names
def test_a_room_named_by_a_lone_surrogate_is_refused(tmp_path):
    """ "\\ud800" is valid JSON and no character: the scan's report was written, then its summary
    ended in a UnicodeEncodeError traceback."""

    def edit(document):
        old = document["rooms"][0]["name"]
        document["rooms"][0]["name"] = "\ud800"
        for window in document.get("windows", []):
            if window["room"] == old:
                window["room"] = "\ud800"

    with pytest.raises(FloorPlanError, match=r"rooms\[0\]\.name: a name may not hold the lone surrogate U\+D800"):
        load_scene(str(_plan(tmp_path, edit)))


def test_what_no_encoding_can_write_is_escaped_on_the_command_lines_output():
    code = (
        "import sys; from train import cli; "
        "cli._checked_main = lambda argv: print('room \\ud800') or print('warn \\udfff', file=sys.stderr) or 0; "
        "sys.exit(cli.main(['scenes', 'list']))"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == b"room \\ud800\n" and proc.stderr == b"warn \\udfff\n"


# ---------------------------------------------------------------------- openings
def test_windows_over_one_stretch_of_wall_are_refused(tmp_path):
    """Forty copies of one window counted forty panes in one opening: 67.2 m² of window for 1.68."""

    def edit(document):
        document["windows"] = document["windows"] * 2

    with pytest.raises(PlanGeometryError, match=r"windows\[1\]\.position: window at .* overlaps another window"):
        load_scene(str(_plan(tmp_path, edit)))


# ---------------------------------------------------------------------- IFC units
@pytest.mark.parametrize(
    "factor, extra, message",
    [
        (  # a cycle of references, refused before the units are read
            "#990001",
            "#990001= IFCMEASUREWITHUNIT(IFCLENGTHMEASURE(2.),#13);",
            r"references form a cycle: #13 \(IFCCONVERSIONBASEDUNIT\) -> #990001 \(IFCMEASUREWITHUNIT\) -> #13",
        ),
        (
            "#990001",
            "#990001= IFCMEASUREWITHUNIT(IFCLABEL('x'),#990002);\n#990002= IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);",
            r"the unit #13 converts by 'x', not a positive number",
        ),
        (
            "#990001",
            "#990001= IFCMEASUREWITHUNIT(IFCLENGTHMEASURE(1.E-300),#990002);\n"
            "#990002= IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);",
            r"the extrusion #\d+ is .* deep; .* \(the file's length unit is 1e-300 m: is it right\?\)",
        ),
    ],
)
def test_a_length_unit_that_converts_to_itself_or_by_no_number_is_refused(factor, extra, message, tmp_path):
    """A unit converting to itself ran for ever inside ifcopenshell, deaf to SIGTERM; a factor that is
    a string ended in a TypeError traceback; one of 1e-300 m collapsed every wall ("no wall faces")."""
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError
    from scenes.corpus import corpus_entry

    text = corpus_entry("fzk_haus_eg").path().read_text(encoding="utf-8", errors="surrogateescape")
    unit = next(line for line in text.splitlines() if line.startswith("#13="))
    assert "IFCSIUNIT" in unit and ".LENGTHUNIT." in unit
    path = _fzk(tmp_path, unit, f"#13= IFCCONVERSIONBASEDUNIT(#18,.LENGTHUNIT.,'ODD',{factor});\n{extra}")
    with pytest.raises(IfcError, match=message):
        load_scene(str(path), storey=0)


# ---------------------------------------------------------------------- PLY faces and glTF scenes
def _ply_text(faces: list[str], header_extra: str = "", index_type: str = "int") -> str:
    vertices = ["0 0 0", "4 0 0", "4 3 0", "0 3 0", "0 0 2.5", "4 0 2.5", "4 3 2.5", "0 3 2.5"]
    return (
        "ply\nformat ascii 1.0\n"
        f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar {index_type} vertex_indices\nproperty uchar label\n"
        f"property int room\n{header_extra}end_header\n" + "\n".join(vertices + faces) + "\n"
    )


GOOD_FACES = ["4 0 1 2 3 0 0", "4 4 7 6 5 1 0", "4 0 4 5 1 2 0", "4 1 5 6 2 2 0", "4 2 6 7 3 2 0", "4 3 7 4 0 2 0"]


@pytest.mark.parametrize(
    "faces, index_type, message",
    [
        (["3 1 2", *GOOD_FACES[1:]], "int", r"element 'face' record 0 \(line 20\) holds 3 values; its header's prop"),
        (["4 0.5 1.5 2.5 3.5 0 0", *GOOD_FACES[1:]], "float", r"PLY face 0 has a vertex index that is not a whole"),
        (["4 0 1 2 3 0 -7", *GOOD_FACES[1:]], "int", r"face 0's 'room' is -7; a room is -1 \(none\) or a number"),
        (["4 0 1 2 3 0 2147483647", *GOOD_FACES[1:]], "int", r"face 0's 'room' is 2147483647"),
    ],
)
def test_ply_faces_whose_values_are_not_what_the_header_means_are_refused(faces, index_type, message, tmp_path):
    """A short face row ended in a numpy traceback; fractional indices were truncated; a room of -7
    was read as none and 2147483647 as a new room."""
    from scenes import InvalidMeshError

    good = tmp_path / "good.ply"
    good.write_text(_ply_text(GOOD_FACES, index_type=index_type))
    assert len(load_scene(str(good)).mesh.faces) == 12
    path = tmp_path / "bad.ply"
    path.write_text(_ply_text(faces, index_type=index_type))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


def test_ply_headers_with_a_blank_line_or_a_float_list_count_are_refused_naming_the_line(tmp_path):
    from scenes import InvalidMeshError

    path = tmp_path / "blank.ply"
    path.write_text(_ply_text(GOOD_FACES, header_extra="\n"))
    with pytest.raises(InvalidMeshError, match=r"PLY header line 11 is blank"):
        load_scene(str(path))
    path.write_text(_ply_text(GOOD_FACES).replace("list uchar int", "list double int"))
    with pytest.raises(InvalidMeshError, match=r"PLY header line 8: a list's count is an integer type, got 'double'"):
        load_scene(str(path))
    path.write_text(_ply_text(GOOD_FACES).replace("\n", "\r\n"))  # CRLF: lines end at \n, as readers read them
    assert len(load_scene(str(path)).mesh.faces) == 12


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.update(scene=5), r"scene is 5, but the file has 1 scene\(s\)"),
        (lambda d: d.update(scenes=[]), r"the file's scenes list is empty"),
        (lambda d: d["scenes"][0].update(nodes=[99]), r"scenes\[0\]\.nodes must name nodes"),
        (
            lambda d: d["meshes"][0]["primitives"][0].update(mode=99),
            r"primitives\[0\]\.mode is 99; glTF's modes are 0 to 6",
        ),
        (
            lambda d: (
                d.update(cameras=[{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.1}}]),
                d["nodes"][0].update(camera=0),
            ),
            r"nodes\[0\] holds both a mesh and a camera",
        ),
    ],
)
def test_gltf_scenes_modes_and_cameras_the_reader_mishandles_are_refused(edit, message, tmp_path):
    """An IndexError from the reader, a part that vanished (mode 99), a mesh dropped for the camera
    of its node."""
    from scenes import InvalidMeshError
    from tests.test_scene_probe2 import gltf_doc, room_parts, write_gltf

    doc = gltf_doc(room_parts())
    edit(doc)
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(write_gltf(tmp_path / "x.gltf", doc)))


# ---------------------------------------------------------------------- a stop that waits too long
def test_a_stop_not_reached_in_time_is_escalated_unless_the_work_is_holding():
    """A training step on a storey of 10 m cells took minutes: the stop, waiting for it, outlasted a
    supervisor's grace, and SIGKILL left no state. With escalate_after the first signal is delivered
    again as a second one (a KeyboardInterrupt the run answers by saving its last update's state)."""
    import os
    import signal
    import time

    from train.stopping import StopRequest

    with pytest.raises(KeyboardInterrupt), StopRequest(escalate_after=0.2) as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:  # a step that does not look at the stop
            time.sleep(0.01)
    assert stop.signal == signal.SIGTERM and time.monotonic() < deadline
    with StopRequest(escalate_after=0.2) as stop, stop.hold():  # writing what it keeps: not interrupted
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.6)
    with StopRequest(escalate_after=0.2) as stop:  # the work stopped in time: nothing more comes
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)
    time.sleep(0.4)
    assert stop.signal == signal.SIGTERM


# ---------------------------------------------------------------------- names in tables and messages
def test_a_pipe_in_a_name_does_not_split_a_markdown_row():
    """`l_room|x` wrote a row of 12 cells under an 11-column header: the numbers under the wrong headings."""
    from train.compare import _md_row

    row = _md_row(["pl/we|ird.json", "random", 'r,1|"x\nnext', 1.5])
    assert row == '| pl/we\\|ird.json | random | r,1\\|"x next | 1.5 |'
    assert row.replace("\\|", "").count("|") == 5


def test_a_name_too_long_for_the_file_system_leaves_room_for_the_reason(tmp_path, capsys):
    """The 5,000-character name came first and the line was cut before the reason ("File name too long")."""
    from nbs_env.errors import ModelFileError
    from policies import make_policy
    from train.cli import main as nbs

    name = "a" * 5000
    with pytest.raises(ModelFileError, match=r"… \(5,000 characters\): cannot be a checkpoint \(File name too long\)"):
        make_policy(f"ppo:{name}")
    assert nbs(["scenes", "info", f"{name}.obj"]) == 1
    err = capsys.readouterr().err
    assert err.endswith("(5,004 characters): File name too long\n") and len(err) < 400, err


def test_gltf_parts_drawn_as_points_or_lines_are_named_in_a_warning(tmp_path):
    """Modes 0-3 hold no surfaces: such a part vanished from the storey without a notice."""
    from scenes.importers import SurfacelessPartsWarning
    from tests.test_scene_probe2 import gltf_doc, room_parts, write_gltf

    parts = room_parts()
    parts["clutter_box"] = parts["wall_s"].copy()
    doc = gltf_doc(parts)
    k = next(i for i, node in enumerate(doc["nodes"]) if node.get("name") == "clutter_box")
    doc["meshes"][doc["nodes"][k]["mesh"]]["primitives"][0]["mode"] = 1  # lines
    with pytest.warns(SurfacelessPartsWarning, match=r"1 part\(s\) are drawn as points or lines.*'clutter_box'"):
        scene = load_scene(str(write_gltf(tmp_path / "lines.gltf", doc)))
    assert len(scene.mesh.faces) == 12
