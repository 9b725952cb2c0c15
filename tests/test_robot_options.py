"""One set of robot options on every command: `nbs scan`, `nbs compare` and `nbs train` read them the
same way and record the configuration they ran with (an IFC storey, a datasheet scanner, the fast
preset and room rules set from the command line)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from train.cli import main

IFC = Path(__file__).parent / "data" / "two_rooms.ifc"
#: The robot's options every command gets: the fast preset, a datasheet scanner, room rules.
ROBOT = [
    "--preset", "fast", "--scanner", "rtc360", "--wall-search", "1", "--max-scans", "8",
    "--set", "rooms.completion_fraction=0.05", "--set", "robot.doors.cross_exterior=true",
]  # fmt: skip


def check_robot(config: dict) -> None:
    """The configuration ROBOT asks for, as recorded."""
    assert config["preset"] == "fast"
    scanner = config["robot"]["scanner"]
    # The RTC360's datasheet, cast at the fast preset's simulated 1° step.
    assert scanner["preset"] == "rtc360:6mm" and scanner["angular_step"] == 1.0
    assert (scanner["max_range"], scanner["station_time"]) == (130.0, 22.9)
    assert config["robot"]["voxel_size"] == 0.1 and config["robot"]["perfect_localisation"] is True
    assert config["rooms"]["wall_search"]["scans"] == 1 and config["rooms"]["completion_fraction"] == 0.05
    assert config["robot"]["doors"]["cross_exterior"] is True
    assert config["max_scans"] == 8


def test_scan_and_compare_of_an_ifc_storey_record_the_same_robot(tmp_path, capsys):
    scan = tmp_path / "scan"
    assert (
        main(["scan", "--scene", str(IFC), "--storey", "EG", *ROBOT, "--no-steps", "--quiet", "--out", str(scan)]) == 0
    )
    metrics = json.loads((scan / "metrics.json").read_text())
    check_robot(metrics["config"])
    assert metrics["config"]["scene_options"] == {"storey": "EG"}
    assert any(e["event"] == "crossed" for e in metrics["door_events"])  # both rooms were scanned
    # Every station took the RTC360's 22.9 s after its 10 s set-up, not the simulated pattern's points over the rate.
    assert metrics["acquisition_time_s"] == pytest.approx((10.0 + 22.9) * metrics["scans"])

    out = tmp_path / "compare"
    args = ["compare", "--scenes", str(IFC), "--policies", "greedy", "--storey", "EG", *ROBOT, "--out", str(out)]
    assert main([*args, "--quiet"]) == 0
    capsys.readouterr()
    run = next((out / "runs").rglob("metrics.json"))
    compared = json.loads(run.read_text())
    check_robot(compared["config"])
    # The same robot on the same storey: the same configuration (the report's kept scans aside) and scans.
    assert {**compared["config"], "keep_scans": True} == metrics["config"]
    assert compared["scans"] == metrics["scans"]
    oracle = json.loads((out / "oracle.json").read_text())[str(IFC)]
    assert (
        oracle["ok"] and oracle["preset"] == "fast" and oracle["overrides"]["robot.scanner"]["preset"] == "rtc360:6mm"
    )


def test_an_option_that_does_not_apply_to_a_scene_is_refused_on_every_command(capsys):
    for command in (["scan", "--scene", "l_room"], ["compare", "--scenes", "l_room", "--policies", "greedy"]):
        assert main([*command, "--storey", "EG", "--out", "never"]) == 2
        assert "--storey applies to .ifc files only" in capsys.readouterr().err
    assert not Path("never").exists()


@pytest.mark.expensive
def test_train_takes_the_same_robot_options_and_its_checkpoint_records_them(tmp_path, capsys):
    pytest.importorskip("sb3_contrib")
    from policies import make_policy

    out = tmp_path / "train"
    args = ["train", "--timesteps", "32", "--envs", "1", "--n-steps", "32", "--rooms", "1-1", *ROBOT]
    assert main([*args, "--quiet", "--out", str(out)]) == 0
    document = json.loads((out / "policy.json").read_text())
    config = document["training"]["config"]
    check_robot(config)
    assert config["generator"]["rooms"] == [1, 1] and config["rooms"]["completion"] == "gain"
    # The policy requires the room rules it was trained with.
    policy = make_policy(f"ppo:{out}")
    assert policy.requires["rooms.wall_search.scans"] == 1 and policy.requires["rooms.completion_fraction"] == 0.05
    assert (
        main(
            [
                "compare",
                "--scenes",
                "l_room",
                "--policies",
                f"greedy,ppo:{out}",
                "--wall-search",
                "0",
                "--out",
                str(tmp_path / "c"),
            ]
        )
        == 2
    )
    assert "requires rooms.wall_search.scans=1" in capsys.readouterr().err
    # On the robot it was trained on (the same options), it runs.
    args = ["compare", "--scenes", "l_room", "--policies", f"ppo:{out}", *ROBOT, "--max-scans", "2"]
    assert main([*args, "--quiet", "--out", str(tmp_path / "same")]) == 0, capsys.readouterr().err
