"""The ``nbs`` command line: outputs, and errors as a message and an exit code, never a traceback."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from scenes import load_plan
from train.cli import EXIT_SCENE_ERROR, EXIT_USAGE, main


def nbs(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "train", *args], capture_output=True, text=True, timeout=120)


def test_scenes_list(capsys):
    assert main(["scenes", "list"]) == 0
    out = capsys.readouterr().out
    assert "five_rooms" in out and "l_room" in out and "office" in out


def test_scenes_show_writes_a_png(tmp_path):
    out = tmp_path / "top.png"
    assert main(["scenes", "show", "l_room", "--out", str(out)]) == 0
    from PIL import Image

    image = Image.open(out)
    assert image.size[0] > 500 and image.size[1] > 400
    # Not blank: the walls and furniture make dark pixels.
    import numpy as np

    assert np.asarray(image.convert("L")).min() < 80


def test_scenes_generate_writes_a_valid_plan(tmp_path):
    out = tmp_path / "plan.json"
    assert main(["scenes", "generate", "--seed", "4", "--rooms", "3", "--out", str(out)]) == 0
    plan = load_plan(out)
    assert len(plan.rooms) == 3
    plan.to_scene(validate=True)


def test_scenes_info_prints_areas(capsys):
    assert main(["scenes", "info", "office"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["class_areas_m2"]["wall"] == pytest.approx(61.38, abs=0.01)


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["scenes", "show", "nowhere", "--out", "x.png"], EXIT_SCENE_ERROR, "nbs: error: nowhere: no bundled scene"),
        (["scenes", "show", "missing.obj", "--out", "x.png"], EXIT_SCENE_ERROR, "missing.obj: no such file"),
        (
            ["scenes", "generate", "--seed", "1", "--rooms", "12", "--out", "p.json"],
            EXIT_USAGE,
            "integers 1 <= A <= B <= 8",
        ),
        (
            ["scenes", "show", "office", "--colour", "red", "--out", "x.png"],
            EXIT_USAGE,
            "unrecognized arguments: --colour",
        ),
        (["scenes", "frobnicate"], EXIT_USAGE, "invalid choice: 'frobnicate'"),
    ],
)
def test_errors_exit_non_zero_without_traceback(tmp_path, args, code, message):
    proc = subprocess.run(
        [sys.executable, "-m", "train", *args], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    assert proc.returncode == code
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_bad_plan_file_error_names_the_field(tmp_path, plan_dict):
    plan_dict["doors"][0]["width"] = "wide"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(plan_dict))
    proc = nbs("scenes", "show", str(path), "--out", str(tmp_path / "x.png"))
    assert proc.returncode == EXIT_SCENE_ERROR
    assert f"{path}: doors[0].width: \"wide\" is not of type 'number'" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_compare_help_names_every_registered_policy():
    from policies import POLICIES
    from train.cli import build_parser

    compare = next(
        action.choices["compare"]
        for action in build_parser()._actions
        if isinstance(action, argparse._SubParsersAction)
    )
    help_text = next(a.help for a in compare._actions if "--policies" in a.option_strings)
    assert all(name in help_text for name in POLICIES), help_text


def test_the_command_line_names_every_preset():
    from nbs_env.config import PRESETS
    from train.arguments import PRESET_NAMES

    assert tuple(PRESETS) == PRESET_NAMES


def _subparser(name: str) -> argparse.ArgumentParser:
    from train.cli import build_parser

    return next(
        action.choices[name] for action in build_parser()._actions if isinstance(action, argparse._SubParsersAction)
    )


def test_scan_compare_and_train_share_one_group_of_robot_options():
    """The robot's options are one group, the same flags with the same choices and defaults on the
    three commands that run a robot."""
    from train.ppo import build_parser as train_parser

    def robot_options(parser: argparse.ArgumentParser) -> dict:
        group = next(g for g in parser._action_groups if g.title == "robot and building")
        return {
            tuple(a.option_strings): (a.default, a.choices, getattr(a.type, "__qualname__", a.type), a.help)
            for a in group._group_actions
        }

    scan, compare, train = (
        robot_options(_subparser("scan")),
        robot_options(_subparser("compare")),
        robot_options(train_parser()),
    )
    assert scan == compare == train
    flags = {flag for option in scan for flag in option}
    assert {
        "--preset",
        "--scanner",
        "--storey",
        "--ifc-doors",
        "--y-up",
        "--wall-search",
        "--set",
        "--max-scans",
    } <= flags
