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
        ("#9001", "#9001= IFCMEASUREWITHUNIT(IFCLENGTHMEASURE(2.),#13);", r"the unit #13 converts to itself"),
        (
            "#9001",
            "#9001= IFCMEASUREWITHUNIT(IFCLABEL('x'),#9002);\n#9002= IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);",
            r"the unit #13 converts by 'x', not a positive number",
        ),
        (
            "#9001",
            "#9001= IFCMEASUREWITHUNIT(IFCLENGTHMEASURE(1.E-300),#9002);\n#9002= IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);",
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
