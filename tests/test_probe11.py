"""Reproducers of the twenty-third bad-input probe's findings, one test per class of input."""

from __future__ import annotations

import json
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from scenes import load_scene
from train.cli import EXIT_USAGE
from train.cli import main as nbs


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return err.strip().splitlines()[-1]


@pytest.fixture
def run(tiny_run, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(tiny_run, copy)
    return copy


def _edit_run(run: Path, edit) -> None:
    path = run / "training_state.json"
    document = json.loads(path.read_text())
    edit(document["run"])
    path.write_text(json.dumps(document))


# ---------------------------------------------------------------------- resumed runs
def test_a_resume_whose_new_envs_leave_a_minibatch_of_one_is_refused_in_one_line(run, capsys):
    """``replace(config, envs=...)`` raised the minibatch check's ConfigError as a traceback."""
    from train.ppo import main

    _edit_run(run, lambda r: r.update(batch_size=3))  # 8 steps x 1 env in minibatches of 3: valid
    assert main(["--resume", str(run), "--timesteps", "48", "--envs", "2", "--quiet"]) == EXIT_USAGE
    err = _err(capsys)
    assert err.startswith(f"nbs train: error: --resume {run} --envs 2: n_steps x envs = 16"), err
    assert json.loads((run / "training_state.json").read_text())["timesteps"] == 16  # nothing trained


def test_a_resumed_state_missing_a_setting_is_refused_naming_it(run, capsys):
    """A state without ``run.n_steps`` was resumed with the default 64 in place of its 8."""
    from nbs_env.errors import ModelFileError
    from train.ppo import load_model, main, resume_config

    _edit_run(run, lambda r: r.pop("n_steps"))
    with pytest.raises(ModelFileError, match=r"training_state.json: its run settings lack n_steps, which every"):
        resume_config(run)
    with pytest.raises(ModelFileError, match="lack n_steps"):
        load_model(run)
    assert main(["--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert "lack n_steps" in _err(capsys)


def test_a_resumed_state_refused_says_what_a_resume_can_do(run):
    """The datasheet check's advice (``--scanner``, ``--set``) is no option on ``--resume``."""
    from nbs_env.config.scanners import scanner_config
    from nbs_env.errors import ModelFileError
    from train.ppo import resume_config

    scanner = {**scanner_config("rtc360:12mm").to_dict(), "max_range": 120.0}
    _edit_run(run, lambda r: r["overrides"].update({"robot.scanner": scanner}))
    with pytest.raises(
        ModelFileError, match=r"max_range 120\.0 .*correct them in the file, or start a new run .*--init"
    ):
        resume_config(run)


# ---------------------------------------------------------------------- training settings
def test_training_overrides_take_numpy_numbers_and_steps_are_bounded():
    """Numpy numbers in ``overrides`` failed ``json.dumps`` at the first checkpoint (the run lost);
    ``--timesteps 10**400`` overflowed stable-baselines3's float count after the first rollout."""
    from nbs_env.errors import ConfigError
    from train.ppo import MAX_STATE_TIMESTEPS, TrainConfig

    config = TrainConfig(
        overrides={
            "max_scans": np.int64(20),
            "rooms.wall_search.heights": (np.int32(1), np.float64(2)),
            "keep_scans": np.False_,
        }
    )
    assert json.loads(json.dumps(config.to_dict()["overrides"])) == {
        "max_scans": 20,
        "rooms.wall_search.heights": [1, 2.0],
        "keep_scans": False,
    }
    assert type(config.overrides["max_scans"]) is int and config.env_config().max_scans == 20
    for name in ("timesteps", "eval_every", "checkpoint_every", "bc_steps"):
        with pytest.raises(ConfigError, match=f"{name} must be at most 1,000,000,000,000"):
            TrainConfig(**{name: 10**400})
    assert TrainConfig(timesteps=MAX_STATE_TIMESTEPS).timesteps == MAX_STATE_TIMESTEPS


# ---------------------------------------------------------------------- configuration merges
def test_a_section_given_as_a_dict_merges_at_every_depth():
    """``robot={"scanner": {"height": 1.2}}`` put the default scanner back (fast's 1° step lost), and
    ``rooms={"wall_search": {}}`` gave the paper preset three search scans a room."""
    from nbs_env.config import make_config

    fast = make_config("fast")
    config = make_config("fast", robot={"scanner": {"height": 1.2}})
    assert config.robot.scanner.height == 1.2
    assert config.robot.scanner.angular_step == fast.robot.scanner.angular_step == 1.0
    assert config.robot.odometry == fast.robot.odometry
    assert make_config("paper", rooms={"wall_search": {}}).rooms == make_config("paper").rooms
    assert make_config("fast", scene_options={"units": "cm"}).scene_options == {"units": "cm"}  # free-form: taken


def test_the_height_of_a_datasheet_scanner_is_the_users(tmp_path, capsys):
    """``--scanner rtc360 --set robot.scanner.height=1.2`` was refused as two options setting one field."""
    import argparse

    from train.arguments import add_robot_arguments, config_from_arguments

    parser = argparse.ArgumentParser()
    add_robot_arguments(parser)

    def given(*argv: str) -> dict:
        return config_from_arguments(parser.parse_args(["--preset", "fast", *argv]), "default")[1]

    scanner = given("--scanner", "rtc360", "--set", "robot.scanner.height=1.2")["robot.scanner"]
    assert scanner["height"] == 1.2 and scanner["preset"] == "rtc360:6mm" and scanner["angular_step"] == 1.0
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match="holds max_range 50"):  # a datasheet value: the preset would lie
        given("--scanner", "rtc360", "--set", "robot.scanner.max_range=50")
    odd = given("--scanner", "rtc360", "--set", "robot.scanner.max_range=50", "--set", "robot.scanner.preset=null")
    assert odd["robot.scanner"]["max_range"] == 50 and odd["robot.scanner"]["preset"] is None
    with pytest.raises(ConfigError, match="is given twice"):
        given("--scanner", "rtc360", "--set", "robot.scanner.height=1.2", "--set", "robot.scanner.height=1.3")
    with pytest.raises(ConfigError, match="and --resolution both set"):
        given("--scanner", "rtc360", "--resolution", "2", "--set", "robot.scanner.angular_step=1")


def test_a_resumed_comparison_of_another_scanner_names_the_field_that_differs():
    """Both sides were cut at 40 characters of the scanner's dict and read the same."""
    from nbs_env.config.scanners import scanner_config
    from train.compare import _settings_apart

    def spec(name: str) -> dict:
        return {"preset": "fast", "overrides": {"robot.scanner": scanner_config(name).to_dict(), "max_scans": 3}}

    theirs, mine = _settings_apart(spec("rtc360:12mm"), spec("rtc360:3mm"))
    assert 'robot.scanner.preset "rtc360:12mm"' in theirs and 'robot.scanner.preset "rtc360:3mm"' in mine
    assert "robot.scanner.station_time 5.8" in theirs and "max_scans" not in theirs


# ---------------------------------------------------------------------- seeds
def test_a_seed_of_more_digits_than_a_folder_name_holds_is_refused_before_the_work(tmp_path, capsys):
    """``nbs compare --seeds 1e305`` ran the grid, then failed on "File name too long" and left a
    folder the same command then refused."""
    from nbs_env import NBSEnv
    from nbs_env.errors import ConfigError

    huge = "1" + "0" * 305
    out = tmp_path / "c"
    argv = ["compare", "--scenes", "office", "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--seeds", huge, "--out", str(out), "--quiet"]) == EXIT_USAGE
    assert "seeds have at most 100 digits" in _err(capsys) and not out.exists()
    with pytest.raises(SystemExit):
        nbs(["scan", "--scene", "office", "--seed", huge, "--out", str(tmp_path / "s")])
    assert "at most 100 digits" in _err(capsys)
    with pytest.raises(ConfigError, match="at most 100 digits"):
        NBSEnv(scene="office", preset="fast").reset(seed=10**5000)


# ---------------------------------------------------------------------- files
def test_a_floor_plan_length_below_a_millimetre_is_refused(tmp_path):
    """A 1e-320 m sill made zero-area faces and bare numpy overflow warnings."""
    from scenes.errors import FloorPlanError

    plan = {
        "format": "nbs-floorplan", "version": 1, "name": "o", "ceiling_height": 2.7, "wall_thickness": 0.15,
        "rooms": [{"name": "o", "polygon": [[0, 0], [7, 0], [7, 5], [0, 5]]}],
        "windows": [{"room": "o", "position": [3.5, 0], "width": 1.5, "height": 1.2, "sill": 0}],
    }  # fmt: skip
    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan))
    assert load_scene(str(path)).name  # a window at the floor
    for field, value in (("sill", 1e-320), ("sill", 0.0005), ("width", 1e-320)):
        window = {**plan["windows"][0], field: value}
        path.write_text(json.dumps({**plan, "windows": [window]}))
        with pytest.raises(FloorPlanError, match=rf"windows\[0\]\.{field}"):
            load_scene(str(path))


def test_an_ascii_ply_number_beyond_its_type_is_named_as_written(tmp_path, recwarn):
    """A float32 vertex of 1e305 warned "overflow encountered in cast" and was named "infinite"; an
    index of 1e305 was printed as 306 digits the file does not hold."""
    from scenes import InvalidMeshError

    def ply(vertex: str, face: str) -> str:
        head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        body = f"0 0 0\n{vertex}\n0 1 0\n{face}\n"
        return head + "element face 1\nproperty list uchar int vertex_indices\nend_header\n" + body

    path = tmp_path / "m.ply"
    path.write_text(ply("1e305 0 0", "3 0 1 2"))
    with pytest.raises(InvalidMeshError, match=r"'x' value 1e\+305 is beyond what its header's type 'float' holds"):
        load_scene(str(path))
    path.write_text(ply("1 0 0", "3 0 1 1e305"))
    with pytest.raises(InvalidMeshError, match=r"vertex index 1e\+305, which its header's type 'int' cannot hold"):
        load_scene(str(path))
    assert not [w for w in recwarn if "overflow" in str(w.message)]


# ---------------------------------------------------------------------- the twenty-fourth probe
def test_an_override_of_a_field_the_run_sets_itself_is_refused(capsys, tmp_path):
    """``nbs train --set reward.scan_cost=9`` trained at the default 0.5 (the run's own --scan-cost
    won) while policy.json recorded 9."""
    from nbs_env.errors import ConfigError
    from train.ppo import RUN_FIELDS, TrainConfig, main

    for path, (field, option) in RUN_FIELDS.items():
        section, leaf = path.split(".")
        for overrides in ({path: 1}, {section: {leaf: 1}}):
            with pytest.raises(ConfigError, match=rf"{path} is the run's own {field} \(nbs train {option}\)"):
                TrainConfig(overrides=overrides)
    assert TrainConfig(overrides={"reward": {"invalid_action_penalty": 2.0}}).env_config().reward.scan_cost == 0.5
    out = tmp_path / "r"
    argv = ["--timesteps", "16", "--n-steps", "16", "--envs", "1", "--out", str(out), "--set", "reward.scan_cost=9"]
    assert main(argv) == EXIT_USAGE
    assert "reward.scan_cost is the run's own scan_cost (nbs train --scan-cost)" in _err(capsys) and not out.exists()


def test_training_overrides_take_numpy_arrays_and_refuse_deep_nesting():
    """An array in ``overrides`` trained the whole run and then failed ``json.dumps`` (the run lost);
    a value nested 900 lists deep was a RecursionError; ``rooms=np.array([1, 2])`` was refused with
    a message its value met."""
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    config = TrainConfig(overrides={"rooms.wall_search.heights": np.array([1.0, 1.5]), "scene_options": {}})
    assert config.overrides["rooms.wall_search.heights"] == [1.0, 1.5] and json.dumps(config.to_dict())
    deep: object = 1.0
    for _ in range(900):
        deep = [deep]
    with pytest.raises(ConfigError, match="nested more than 64 levels deep"):
        TrainConfig(overrides={"rooms.wall_search.heights": deep})
    assert TrainConfig(rooms=np.array([1, 2]), cell_size=np.array([2.0, 3.0])).rooms == (1, 2)


def test_a_resumed_total_beyond_the_bound_names_the_option(run, capsys):
    """The state file was blamed ("correct them in the file") for a --timesteps the user typed."""
    from train.ppo import MAX_STATE_TIMESTEPS, main

    assert main(["--resume", str(run), "--timesteps", str(MAX_STATE_TIMESTEPS + 1), "--quiet"]) == EXIT_USAGE
    assert _err(capsys) == "nbs train: error: --timesteps 1000000000001: must be at most 1,000,000,000,000"


def test_a_wall_thinner_than_a_millimetre_is_refused(tmp_path):
    """A 1e-300 m wall made 40 zero-area faces, the defect the sill's bound was added against."""
    import scenes
    from scenes.errors import FloorPlanError

    plan = json.loads((Path(scenes.__file__).parent / "data" / "five_rooms.json").read_text())
    for field in ("wall_thickness", "ceiling_height"):
        path = tmp_path / f"{field}.json"
        path.write_text(json.dumps({**plan, field: 1e-300}))
        with pytest.raises(FloorPlanError, match=rf"{field}: 1e-300 is less than the minimum of 0.001"):
            load_scene(str(path))


def test_a_resumed_comparison_of_the_same_configuration_is_the_same_run():
    """``--preset fast --resolution 1`` is fast's own step: a resume with it was refused, the
    preset's value shown as 'unset'; an edited seed of "0" was "other settings"."""
    from train.compare import _settings_apart, same_spec

    def spec(**overrides) -> dict:
        return {"scene": "l_room", "policy": "random", "seed": 0, "preset": "fast", "overrides": overrides}

    assert same_spec(spec(), spec(**{"robot.scanner.angular_step": 1.0, "robot.voxel_size": 0.1}))
    assert not same_spec(spec(), spec(**{"robot.scanner.angular_step": 2.0}))
    assert not same_spec(spec(), {**spec(), "seed": "0"})
    assert _settings_apart(spec(), spec(**{"robot.scanner.angular_step": 2.0})) == (
        "robot.scanner.angular_step not given",
        "robot.scanner.angular_step 2.0",
    )
    assert _settings_apart({**spec(), "seed": "0"}, spec()) == ('seed "0"', "seed 0")


# ---------------------------------------------------------------------- the twenty-fifth probe
def test_a_run_field_by_its_own_name_or_in_a_configuration_is_named_or_taken():
    """``overrides={"scan_cost": 9}`` (make_config's short name) gave "'reward.scan_cost' and another
    name both set"; ``{"generator": GeneratorConfig(clutter_density=0.5)}`` was refused for rooms no
    one set."""
    from nbs_env.errors import ConfigError
    from scenes.generator import GeneratorConfig
    from train.ppo import TrainConfig

    with pytest.raises(ConfigError, match=r"reward.scan_cost is the run's own scan_cost \(nbs train --scan-cost\)"):
        TrainConfig(overrides={"scan_cost": 9})
    config = TrainConfig(rooms=(2, 3), overrides={"generator": GeneratorConfig(clutter_density=0.5)})
    assert config.env_config().generator.clutter_density == 0.5 and config.env_config().generator.rooms == (2, 3)
    with pytest.raises(ConfigError, match=r"generator\.rooms is the run's own rooms"):
        TrainConfig(overrides={"generator": GeneratorConfig(rooms=(2, 2))})


def test_numpy_arrays_are_taken_by_every_override_and_deep_values_refused():
    """``make_config(**{"generator.clutter_density": np.array(0.5)})`` said "got 0.5" of a value within
    its range; a value nested 1,200 levels deep was a RecursionError from a message's repr."""
    from nbs_env.config import EnvConfig, make_config
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    config = make_config(
        "fast", **{"generator.clutter_density": np.array(0.5), "generator.cell_size": np.array([2, 3.6])}
    )
    assert config.generator.clutter_density == 0.5 and config.generator.cell_size == (2, 3.6)
    deep: object = 1
    for _ in range(1200):
        deep = {"a": deep}
    with pytest.raises(ConfigError, match="nested more than 64 levels"):
        TrainConfig(overrides={"robot": deep})
    with pytest.raises(ConfigError, match="nested more than 64 levels"):
        make_config("fast", scene_options={"storey": deep})
    with pytest.raises(ConfigError, match="nested too deep to check"):
        EnvConfig(scene_options={"storey": deep})


def test_a_checkpoint_whose_room_vector_size_is_no_integer_is_refused(run):
    """``network.room_features: 0.0`` passed ``in (0, 5)`` and torch's Linear raised a traceback."""
    from nbs_env.errors import ConfigError, ModelFileError
    from policies.learned import NetworkConfig, load_checkpoint

    with pytest.raises(ConfigError, match="room_features must be an integer"):
        NetworkConfig(room_features=0.0)
    description = run / "policy.json"
    document = json.loads(description.read_text())
    document["network"]["room_features"] = float(document["network"]["room_features"])
    description.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match="room_features"):
        load_checkpoint(run)


def test_a_network_whose_scores_overflow_cannot_choose(run):
    """Weights of 1e38 made every logit NaN and ``act`` returned action 0 without a word."""
    import hashlib

    torch = pytest.importorskip("torch")
    from nbs_env import NBSEnv
    from nbs_env.errors import ModelFileError
    from policies.learned import LearnedPolicy

    tensors = torch.load(run / "policy.pt", weights_only=True)
    first = next(k for k, v in tensors.items() if k.endswith("weight") and v.dim() > 1)
    tensors[first].fill_(1e38)
    torch.save(tensors, run / "policy.pt")
    description = run / "policy.json"
    document = json.loads(description.read_text())
    document["sha256"] = hashlib.sha256((run / "policy.pt").read_bytes()).hexdigest()
    description.write_text(json.dumps(document))
    policy = LearnedPolicy(run)
    obs, info = NBSEnv(scene="l_room", preset="fast", **{"rooms.completion": "policy"}).reset(seed=0)
    with pytest.raises(ModelFileError, match="scores are not finite"):
        policy.act(obs, info)


def test_a_resumed_comparison_spelling_a_run_otherwise_says_so():
    """``generated:01`` for ``generated:1`` (one storey) was "runs this comparison leaves out"."""
    from train.compare import RunSpec, _spelled_otherwise

    stored = {"scene": "generated:1", "policy": "greedy", "seed": 0}
    spelled = _spelled_otherwise(stored, [RunSpec("generated:01", "greedy", 0)])
    assert spelled is not None and spelled.scene == "generated:01"
    assert _spelled_otherwise(stored, [RunSpec("generated:2", "greedy", 0)]) is None
    assert _spelled_otherwise({**stored, "policy": "no-such"}, [RunSpec("generated:1", "greedy", 0)]) is None


# ---------------------------------------------------------------------- the twenty-sixth probe
def test_a_value_nested_thousands_deep_is_a_config_error_at_every_entry():
    """A repr of a value nested 3,000 levels deep raised RecursionError from GeneratorConfig,
    ``_check_field_kinds``, ``from_dict`` and ``make_config``'s own messages."""
    from nbs_env.config import EnvConfig, make_config
    from nbs_env.config.robot import RobotConfig
    from nbs_env.errors import ConfigError
    from scenes import GeneratorConfig, SceneError

    deep: object = 1
    for _ in range(3000):
        deep = [deep]
    for build in (
        lambda: EnvConfig(robot=deep),
        lambda: EnvConfig(keep_scans=deep),
        lambda: RobotConfig(scanner=deep),
        lambda: EnvConfig.from_dict({"robot": deep}),
        lambda: EnvConfig.from_dict({"generator": {"rooms": deep}}),
        lambda: make_config(deep),
    ):
        with pytest.raises(ConfigError, match="nested too deep"):
            build()
    with pytest.raises(ValueError, match="nested too deep"):
        GeneratorConfig(rooms=deep)
    with pytest.raises(SceneError, match="nested too deep"):
        load_scene("generated:1", rooms=deep)


def test_a_start_whose_scores_overflow_is_refused_before_training(tmp_path, capsys):
    """``nbs train --init`` of a checkpoint whose scores are NaN raised torch's ValueError after the
    first rollout began."""
    torch = pytest.importorskip("torch")
    import hashlib

    from policies.learned import BUNDLED
    from train.ppo import main

    start = tmp_path / "start"
    shutil.copytree(BUNDLED["reference"], start)
    tensors = torch.load(start / "policy.pt", weights_only=True)
    for key in [k for k in tensors if k.endswith("weight")]:
        tensors[key] = tensors[key] * 1e30
    torch.save(tensors, start / "policy.pt")
    document = json.loads((start / "policy.json").read_text())
    document["sha256"] = hashlib.sha256((start / "policy.pt").read_bytes()).hexdigest()
    (start / "policy.json").write_text(json.dumps(document))
    out = tmp_path / "run"
    argv = ["--timesteps", "16", "--n-steps", "16", "--envs", "1", "--completion", "policy", "--rooms", "1-1"]
    argv += ["--init", str(start), "--out", str(out), "--quiet"]
    assert main(argv) == EXIT_USAGE
    assert "scores are not finite for an observation" in _err(capsys) and not out.exists()


def test_small_refusals_of_the_twenty_sixth_probe(run, tmp_path, capsys):
    """A 300-character weights name was a bare OSError; ``wall_room1١`` was room 11; ``--set
    scan_cost`` said no such field; a comparison's oracle.json wrote over the plan it read."""
    from nbs_env.errors import ModelFileError
    from policies.learned import load_checkpoint
    from scenes.importers import parse_part_name

    document = json.loads((run / "policy.json").read_text())
    (run / "policy.json").write_text(json.dumps({**document, "weights": "a" * 300}))
    with pytest.raises(ModelFileError, match="weights must name a file beside"):
        load_checkpoint(run)
    assert parse_part_name("wall_room1\u0661")[1] == -1 and parse_part_name("wall_room12")[1] == 12
    assert nbs(["scan", "--scene", "office", "--set", "scan_cost=9", "--out", str(tmp_path / "s")]) == EXIT_USAGE
    assert _err(capsys).endswith("--set scan_cost: give the field's dotted name (reward.scan_cost)")
    import scenes

    out = tmp_path / "c"
    out.mkdir()
    plan = out / "oracle.json"
    shutil.copy(Path(scenes.__file__).parent / "data" / "l_room.json", plan)
    before = plan.read_bytes()
    argv = ["compare", "--scenes", str(plan), "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(out), "--force", "--quiet"]) == EXIT_USAGE
    assert "writes oracle.json in" in _err(capsys) and plan.read_bytes() == before


def test_a_training_run_refuses_scene_options_its_generated_storeys_never_read():
    """``TrainConfig(overrides={"scene_options": {"rooms": 8}})`` trained on 1-5-room storeys without a word."""
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    with pytest.raises(ConfigError, match="scene_options, which a run's generated storeys do not read"):
        TrainConfig(overrides={"scene_options": {"rooms": 8}})
    assert TrainConfig(overrides={"scene_options": {}}).env_config().scene_options == {}


def test_an_oracle_being_planned_stops_at_the_next_candidate():
    """SIGTERM to ``nbs compare --jobs 1`` while an oracle was planned waited for every candidate's
    scan (25 s; a signal to the process group was not answered in 30 s)."""
    from policies.oracle import PlanningStoppedError, oracle_plan
    from train.compare import _oracle

    asked: list[int] = []

    def stop() -> bool:
        asked.append(1)
        return len(asked) > 2

    with pytest.raises(PlanningStoppedError, match="stopped after 2 of"):
        oracle_plan(load_scene("l_room"), stop=stop)
    assert _oracle("l_room", "fast", {}, stop=lambda: True) is None  # nothing kept: --resume plans it again
    assert _oracle("no_such_scene", "fast", {}, stop=lambda: True)["ok"] is False  # errors stay records


def test_the_twenty_sixth_probes_minor_findings(tmp_path, capsys):
    """GeneratorConfig raised a bare ValueError; a scene path of parts within 255 bytes made a run
    folder name of 300 and the comparison failed after its run; a PLY element without properties was
    called a truncated file (trimesh fails on one inside)."""
    import scenes
    from scenes import GeneratorConfigError, InvalidMeshError

    with pytest.raises(GeneratorConfigError, match=r"GeneratorConfig: rooms must be within 1\.\.8"):
        scenes.GeneratorConfig(rooms="x")
    with pytest.raises(scenes.SceneError, match="generated:1: bad generator option: rooms must be"):
        load_scene("generated:1", rooms="x")

    deep = tmp_path / ("a" * 120) / ("b" * 120)
    deep.mkdir(parents=True)
    plan = deep / "l_room.json"
    shutil.copy(Path(scenes.__file__).parent / "data" / "l_room.json", plan)
    out = tmp_path / "c"
    argv = ["compare", "--scenes", str(plan), "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    (folder,) = (out / "runs").iterdir()
    assert len(folder.name) <= 120 and folder.name.split("-")[0].endswith("l_room.json")

    head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    path = tmp_path / "m.ply"
    face = "element face 1\nproperty list uchar int vertex_indices\n"
    path.write_text(head + face + "element junk 2\nend_header\n" + body)
    with pytest.raises(InvalidMeshError, match="the PLY element 'junk' has no properties"):
        load_scene(str(path))


def test_the_twenty_seventh_probes_findings(run, tmp_path, capsys):
    """A non-string weights name lost its message to a slice; an override keyed by a number named
    no key; a plan of 1 m corridors refused the start it chose itself; a resumed run whose state file
    had become a folder trained all its steps before saying so; a record's seed ``false`` was shown
    as a spelling of seed 0."""
    import scenes
    from nbs_env.errors import ConfigError, ModelFileError
    from policies.learned import load_checkpoint
    from train.ppo import TrainConfig

    document = json.loads((run / "policy.json").read_text())
    for weights, kind in ((123, "a number"), ({"a": 1}, "an object")):
        (run / "policy.json").write_text(json.dumps({**document, "weights": weights}))
        with pytest.raises(ModelFileError, match=f"weights must name a file beside policy.json, got {kind}"):
            load_checkpoint(run)
    (run / "policy.json").write_text(json.dumps(document))
    with pytest.raises(ConfigError, match="overrides' keys are field names"):
        TrainConfig(overrides={1: 3})

    plan = json.loads((Path(scenes.__file__).parent / "data" / "l_room.json").read_text())
    plan.update(wall_thickness=3, windows=[], clutter=[])
    plan.pop("start", None)
    (tmp_path / "narrow.json").write_text(json.dumps(plan))
    scene = load_scene(str(tmp_path / "narrow.json"))  # the L's arms are 1 m wide inside 3 m walls
    assert 1.95 <= scene.start[0] <= 2.05 and 1.95 <= scene.start[1] <= 2.05

    (run / "training_state.json").unlink()
    (run / "training_state.json").mkdir()
    before = sorted(p.name for p in run.iterdir())
    assert nbs(["train", "--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert "training_state.json is a folder where the run writes its file" in _err(capsys)
    assert sorted(p.name for p in run.iterdir()) == before

    out = tmp_path / "c"
    argv = ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(out), "--quiet"]) == 0
    record = out / "runs" / "l_room" / "greedy" / "seed0" / "run.json"
    stored = json.loads(record.read_text())
    stored["spec"]["seed"] = False
    record.write_text(json.dumps(stored))
    assert nbs([*argv, "--out", str(out), "--quiet", "--resume"]) == 0  # not seed 0's record: run again
    assert 'it is the record of scene "l_room", policy "greedy", seed false, not of the run' in _err(capsys)
    assert json.loads(record.read_text())["spec"]["seed"] == 0


def test_the_twenty_eighth_probes_findings(run, tmp_path, capsys):
    """A run's stop_lr_scale edited in its record trained at the tensors' old scale; 1e-320 froze the
    head; an override keyed None named no key; a PLY element of no records and no properties was
    refused; a record's seed other than its folder's was "a run left out"; a ``tb`` file failed the
    resume after the model was built; a glTF of lines was "empty"; --init of another completion
    dumped two networks."""
    import scenes
    from nbs_env.errors import ConfigError, ModelFileError
    from scenes import InvalidMeshError
    from train.ppo import TrainConfig, load_model, train

    out = tmp_path / "r"
    train(TrainConfig(**{**_TINY, "stop_lr_scale": 3.0}), out, progress=False)
    path = out / "training_state.json"
    document = json.loads(path.read_text())
    assert load_model(out).policy.optimizer.param_groups[1]["lr_scale"] == 3.0  # the run's, as recorded
    document["run"]["stop_lr_scale"] = 5.0
    path.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match=r"stop_lr_scale 5\.0 against 3\.0\); a resumed run keeps its own"):
        load_model(out)  # probe 40: a setting edited after the state was saved is not trained with
    with pytest.raises(ConfigError, match=r"stop_lr_scale must be within \[0\.001, 100\]"):
        TrainConfig(completion="policy", stop_lr_scale=1e-320)
    with pytest.raises(ConfigError, match="completion must be 'policy' or 'gain'"):
        TrainConfig(completion="x", stop_lr_scale=2.0)
    with pytest.raises(ConfigError, match="got None"):
        TrainConfig(overrides={None: 3})

    head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    face = "element face 1\nproperty list uchar int vertex_indices\nproperty uchar label\n"
    (tmp_path / "e.ply").write_text(head + "element empty 0\n" + face + "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1\n")
    with pytest.raises(scenes.SceneError) as caught:
        load_scene(str(tmp_path / "e.ply"))
    assert not isinstance(caught.value, InvalidMeshError), caught.value  # read: only the lone floor is wrong
    (tmp_path / "v.ply").write_text(head.replace("1.0", "2.0") + face + "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1\n")
    with pytest.raises(InvalidMeshError, match=r"where PLY has 'format ascii 1\.0' only"):
        load_scene(str(tmp_path / "v.ply"))  # plyfile refuses another version; trimesh read it as 1.0

    import base64

    points = base64.b64encode(np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], "<f4").tobytes()).decode()
    lines = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 36, "uri": f"data:application/octet-stream;base64,{points}"}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "max": [1, 1, 0], "min": [0, 0, 0]}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 1}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    (tmp_path / "lines.gltf").write_text(json.dumps(lines))
    with pytest.raises(InvalidMeshError, match="every part is drawn as points or lines"):
        load_scene(str(tmp_path / "lines.gltf"))

    compare = tmp_path / "c"
    argv = ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(compare), "--quiet"]) == 0
    record = compare / "runs" / "l_room" / "greedy" / "seed0" / "run.json"
    stored = json.loads(record.read_text())
    stored["spec"]["seed"] = 1
    record.write_text(json.dumps(stored))
    assert nbs([*argv, "--out", str(compare), "--quiet", "--resume"]) == 0  # (not "a run left out")
    assert 'it is the record of scene "l_room", policy "greedy", seed 1, not of the run' in _err(capsys)

    if (run / "tb").is_dir():
        shutil.rmtree(run / "tb")
    (run / "tb").write_text("")
    assert nbs(["train", "--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert "tb is a file where the run keeps its TensorBoard folder" in _err(capsys)

    argv = ["train", "--init", str(out), "--timesteps", "8", "--n-steps", "8", "--envs", "1"]
    assert nbs([*argv, "--out", str(tmp_path / "t"), "--quiet"]) == EXIT_USAGE
    assert _err(capsys).endswith("it was trained with --completion policy")


_TINY = {"timesteps": 8, "envs": 1, "rooms": (1, 1), "n_steps": 8, "batch_size": 8, "completion": "policy"}


def test_the_twenty_ninth_probes_findings(tmp_path):
    """A triangle list of 35 indices failed inside trimesh; a bad generator option through
    ``load_scene`` was an UnknownSceneError (a LookupError), an unknown option a bare TypeError."""
    import base64

    import scenes

    with pytest.raises(scenes.GeneratorConfigError, match="generated:3: bad generator option: rooms must be"):
        load_scene("generated:3", rooms=0)
    with pytest.raises(scenes.SceneOptionError, match=r"\['nope'\] do not apply to this source \(generated storey\)"):
        load_scene("generated:3", nope=1)

    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], "<f4").tobytes()
    indices = np.array([0, 1, 2, 1, 3], "<u2").tobytes() + b"\0\0"  # five indices: no triangle list
    data = base64.b64encode(corners + indices).decode()
    document = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 60, "uri": f"data:application/octet-stream;base64,{data}"}],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 10}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "max": [1, 1, 0], "min": [0, 0, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 5, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0, "name": "floor"}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    (tmp_path / "five.gltf").write_text(json.dumps(document))
    with pytest.raises(scenes.InvalidMeshError, match=r"indices's accessor counts 5, not a multiple of 3"):
        load_scene(str(tmp_path / "five.gltf"))


def test_the_thirtieth_probes_findings(run, tmp_path):
    """A checkpoint of version true (== 1 in Python) was read, an input_layout of 1 shown as '1'; an
    IFC SI length unit named FOOT failed inside ifcopenshell; ``g wall_0 floor_9`` was read as the
    wall alone (OBJ puts the faces in both groups)."""
    import scenes
    from nbs_env.errors import ModelFileError
    from policies.learned import load_checkpoint

    document = json.loads((run / "policy.json").read_text())
    for change, message in (({"version": True}, "version true"), ({"input_layout": 1}, "'zxy', got 1$")):
        (run / "policy.json").write_text(json.dumps({**document, **change}))
        with pytest.raises(ModelFileError, match=message):
            load_checkpoint(run)

    ifc = (Path(scenes.__file__).parent / "data" / "corpus" / "ifc" / "split_level.ifc").read_text()
    (tmp_path / "feet.ifc").write_text(ifc.replace(".LENGTHUNIT.,$,.METRE.)", ".LENGTHUNIT.,$,.FOOT.)"))
    with pytest.raises(scenes.IfcError, match="the SI length unit #2 is not named by an SI name, where IFC's is METRE"):
        load_scene(str(tmp_path / "feet.ifc"))

    obj = "v 0 0 0\nv 4 0 0\nv 0 4 0\nv 0 0 3\ng floor\nf 1 2 3\ng wall_0 floor_9\nf 1 2 4\n"
    (tmp_path / "two.obj").write_text(obj)
    with pytest.raises(scenes.InvalidMeshError, match="line 7: 'g wall_0 floor_9' puts its faces in 2 groups"):
        load_scene(str(tmp_path / "two.obj"))


def test_an_ifc_length_unit_of_an_area_is_named(tmp_path):
    """Probe 30 T4: a foot converting by an IfcAreaMeasure, with an area's exponents or to an area
    unit was read as metres without a word."""
    import scenes

    ifc = (Path(scenes.__file__).parent / "data" / "corpus" / "ifc" / "split_level.ifc").read_text()
    foot = "#2=IFCCONVERSIONBASEDUNIT(#9901,.LENGTHUNIT.,'FOOT',#9902);#9901=IFCDIMENSIONALEXPONENTS({});"
    foot += "#9902=IFCMEASUREWITHUNIT({}(0.3048),#9903);#9903=IFCSIUNIT(*,{},$,{});"
    metre = "#2=IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.);"
    assert metre in ifc
    for values, message in (
        (("2,0,0,0,0,0,0", "IFCLENGTHMEASURE", ".LENGTHUNIT.", ".METRE."), r"dimensions \[2, 0, 0, 0, 0, 0, 0\]"),
        (("1,0,0,0,0,0,0", "IFCAREAMEASURE", ".LENGTHUNIT.", ".METRE."), "converts by an IfcAreaMeasure"),
        (("1,0,0,0,0,0,0", "IFCRATIOMEASURE", ".AREAUNIT.", ".SQUARE_METRE."), r"#9903 \(AREAUNIT\), no length unit"),
    ):
        (tmp_path / "f.ifc").write_text(ifc.replace(metre, foot.format(*values)))
        with pytest.raises(scenes.IfcError, match=message):
            load_scene(str(tmp_path / "f.ifc"))
    # A foot converting by a length to metres passes the check (the storey, now 0.3048 of its size, is too low).
    (tmp_path / "f.ifc").write_text(
        ifc.replace(metre, foot.format("1,0,0,0,0,0,0", "IFCRATIOMEASURE", ".LENGTHUNIT.", ".METRE."))
    )
    with pytest.raises(scenes.StoreySizeError, match="is the file's unit right"):
        load_scene(str(tmp_path / "f.ifc"))


def test_the_thirty_first_probes_records_are_compared_as_json(run, tmp_path, capsys):
    """A training state of version true, a comparison record of max_scans true and an oracle whose
    ok was 1 (or whose scene was another) were taken: equal in Python, not in the record; a second
    IfcProject's units were dropped without a word."""
    import scenes
    from nbs_env.errors import ModelFileError
    from train.ppo import latest_state

    path = run / "training_state.json"
    path.write_text(path.read_text().replace('"version": 1', '"version": true', 1))
    with pytest.raises(ModelFileError, match="not an 'nbs-env-training-state' file of version 1"):
        latest_state(run)

    out = tmp_path / "c"
    argv = ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(out), "--quiet"]) == 0
    record = out / "runs" / "l_room" / "greedy" / "seed0" / "run.json"
    stored = json.loads(record.read_text())
    stored["spec"]["overrides"]["max_scans"] = True
    record.write_text(json.dumps(stored))
    assert nbs([*argv, "--out", str(out), "--quiet", "--resume"]) == EXIT_USAGE
    assert "holds a finished run with" in _err(capsys)
    stored["spec"]["overrides"]["max_scans"] = 1
    record.write_text(json.dumps(stored))
    oracle = json.loads((out / "oracle.json").read_text())
    oracle["l_room"]["scene"] = "office"
    (out / "oracle.json").write_text(json.dumps(oracle))
    from train.compare import RunSpec, load_finished

    assert "l_room" not in load_finished(out, [RunSpec("l_room", "greedy", 0, "fast", {"max_scans": 1})])["oracles"]

    ifc = (Path(scenes.__file__).parent / "data" / "corpus" / "ifc" / "split_level.ifc").read_text()
    project = next(line for line in ifc.splitlines() if "IFCPROJECT(" in line)
    number = project.split("=", 1)[0]
    (tmp_path / "two.ifc").write_text(ifc.replace(project, project + "\n" + project.replace(number, "#99999", 1), 1))
    with pytest.raises(scenes.IfcError, match="holds 2 IfcProject"):
        load_scene(str(tmp_path / "two.ifc"))


@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")  # the writer thread's traceback
def test_a_full_disk_under_tensorboard_is_one_line_naming_the_event_file(run, tmp_path, capsys, monkeypatch):
    """TensorBoard writes from its own thread: a full disk printed that thread's traceback beside the
    error, named no file, left an empty event file per try, and a new run was told to ``--resume``
    a folder never made. A disk with no room for one saved state is refused before the work."""
    pytest.importorskip("tensorboard")
    from collections import namedtuple

    from tensorboard.compat.tensorflow_stub.io import gfile

    import train.ppo

    def full(self, filename, content, mode):  # as a full disk: the file is made, its bytes are not written
        open(filename, "ab").close()
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(gfile.LocalFileSystem, "_write", full)
    events = sorted(p.name for p in run.rglob("events.out.tfevents.*"))
    code = nbs(["train", "--resume", str(run), "--timesteps", "24", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"nbs train: error: {run / 'tb'}") and "events.out.tfevents." in err, err
    assert "No space left on device; the run keeps its last saved state (16 timesteps)" in err, err
    assert sorted(p.name for p in run.rglob("events.out.tfevents.*")) == events, "an empty event file was left"

    fresh = tmp_path / "fresh"
    code = nbs(["train", "--out", str(fresh), "--timesteps", "8", "--n-steps", "8", "--envs", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "nothing was saved to continue from: make room and run the command again" in err, err
    assert "--resume" not in err and not fresh.exists(), err
    monkeypatch.undo()

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(train.ppo.shutil, "disk_usage", lambda folder: usage(4 << 20, 3 << 20, 1 << 20))
    code = nbs(["train", "--resume", str(run), "--timesteps", "24", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith(f"nbs train: error: {run}: No space left on device: 1.0 MiB free"), err
    assert "continue it with nbs train --resume" in err and len(err.strip().splitlines()) == 1, err


def test_the_thirty_first_probes_minor_findings(tmp_path, capsys):
    """A run record's odd ``wall_s`` or field was kept and its ``ok: 1`` run again without a word;
    messages spelt JSON values as Python does; ``--rooms 3-2`` was told of 0 <= A; a plan saved with
    a byte-order mark was refused with Python's advice; a 5,001-digit number was placed at line 1."""
    import scenes
    from nbs_env.errors import ConfigError
    from scenes.jsonio import JSONNumberError, read_json
    from train.compare import RunSpec, load_finished
    from train.ppo import TrainConfig

    out = tmp_path / "c"
    argv = ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "fast", "--max-scans", "1"]
    assert nbs([*argv, "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    record = out / "runs" / "l_room" / "greedy" / "seed0" / "run.json"
    whole = json.loads(record.read_text())
    spec = [RunSpec("l_room", "greedy", 0, "fast", {"max_scans": 1})]
    assert spec[0].key in load_finished(out, spec)["runs"]
    for edit, said in [
        ({"wall_s": "1.4"}, 'wall_s is "1.4", not a run\'s seconds'),
        ({"wall_s": -5}, "wall_s is -5, not a run's seconds"),
        ({"zzz": 1}, 'holds the field "zzz", which no run writes'),
        ({"ok": 1}, "ok is 1, not true or false"),
    ]:
        record.write_text(json.dumps({**whole, **edit}))
        assert spec[0].key not in load_finished(out, spec)["runs"], edit
        assert capsys.readouterr().err == f"nbs compare: {record}: {said}; running it again\n", edit

    with pytest.raises(ConfigError, match=r"got \[true, 5\]"):
        TrainConfig(rooms=(True, 5))
    with pytest.raises(ConfigError, match=r"max_scans must be an integer .*, got true$"):
        from nbs_env.config import make_config

        make_config("fast", max_scans=True)
    with pytest.raises(SystemExit) as refused:  # argparse's own exit, as every refused option
        nbs(["scenes", "generate", "--seed", "1", "--rooms", "3-2", "--out", str(tmp_path / "g.json")])
    assert refused.value.code == EXIT_USAGE
    assert "rooms must be N or A-B with integers 1 <= A <= B <= 8, got '3-2'" in _err(capsys)

    plan = (Path(scenes.__file__).parent / "data" / "l_room.json").read_bytes()
    (tmp_path / "bom.json").write_bytes(b"\xef\xbb\xbf" + plan)
    assert len(load_scene(str(tmp_path / "bom.json")).mesh.faces) == len(load_scene("l_room").mesh.faces)
    with pytest.raises(JSONNumberError, match="line 3 column 7"):
        read_json('{\n "a": 1,\n "b": ' + "2" * 5001 + "\n}")


def test_the_thirty_second_probes_findings(run, tmp_path):
    """A learning curve's figures out of their meaning (250 %, -5 scans, steps out of order) were
    taken and steered the resumed run's baseline; a comparison record's total that is not its last
    step's, or its scans beyond the budget, were tabled; a byte-order mark before an IFC, an SVM or a
    curve was refused; an empty scene name was "a folder"; values were spelt as Python does."""
    import scenes
    from nbs_env.errors import ConfigError, ModelFileError
    from nbs_env.perception.roi import RoIError, RoIScan, compute_roi
    from nbs_env.perception.structure import SEClassifier
    from train.compare import record_problem
    from train.ppo import TrainConfig, _curve

    curve = tmp_path / "learning_curve.jsonl"
    line = {"timesteps": 16, "learned": {"structure_sensed_pct": 50, "scans": 3, "path_length_m": 4}}
    for edit, said in [
        ({"timesteps": True}, "line 1 has timesteps true, not a count"),
        ({"learned": {**line["learned"], "structure_sensed_pct": "50"}}, 'learned.structure_sensed_pct "50", not'),
        (
            {"learned": {**line["learned"], "structure_sensed_pct": 250.0}},
            "structure_sensed_pct 250.0, outside [0, 100]",
        ),
        ({"greedy": {**line["learned"], "scans": -5}}, "greedy.scans -5, outside [0,"),
    ]:
        curve.write_text(json.dumps({**line, **edit}) + "\n")
        with pytest.raises(ModelFileError, match=re.escape(said)):
            _curve(curve)
    curve.write_text(json.dumps(line) + "\n" + json.dumps({**line, "timesteps": 8}) + "\n")
    with pytest.raises(ModelFileError, match="line 2 has timesteps 8, before the line above's 16"):
        _curve(curve)
    curve.write_bytes(b"\xef\xbb\xbf" + json.dumps(line).encode() + b"\n")
    assert _curve(curve) == [line]

    # Evaluations after the last saved state are taken again when the run resumes, not kept.
    log = run / "learning_curve.jsonl"
    log.write_text(log.read_text() + json.dumps({**line, "timesteps": 5000}) + "\n")
    assert nbs(["train", "--resume", str(run), "--timesteps", "24", "--quiet"]) == 0
    assert all(r["timesteps"] <= 24 for r in _curve(log)), log.read_text()

    with pytest.raises(ConfigError, match=r"got \[true, 3\]"):
        TrainConfig(cell_size=(True, 3))
    svm = Path(__import__("nbs_env.perception.structure", fromlist=["x"]).__file__).parent / "data" / "se_svm.json"
    (tmp_path / "svm.json").write_bytes(b"\xef\xbb\xbf" + svm.read_bytes())
    SEClassifier.load(tmp_path / "svm.json")
    document = json.loads(svm.read_text())
    (tmp_path / "v.json").write_text(json.dumps({**document, "version": True}))
    with pytest.raises(ModelFileError, match="got true"):
        SEClassifier.load(tmp_path / "v.json")

    plan = json.loads((Path(scenes.__file__).parent / "data" / "l_room.json").read_text())
    for edit, said in [
        ({"version": True}, "unsupported format version true"),
        ({"start": None}, "null is not of type"),
    ]:
        (tmp_path / "p.json").write_text(json.dumps({**plan, **edit}))
        with pytest.raises(scenes.FloorPlanError, match=said):
            load_scene(str(tmp_path / "p.json"))
    with pytest.raises(scenes.UnknownSceneError, match=r"^'': the scene's name is empty"):
        load_scene("")

    ifc = (Path(__file__).parent / "data" / "two_rooms.ifc").read_bytes()
    (tmp_path / "bom.ifc").write_bytes(b"\xef\xbb\xbf" + ifc)
    (tmp_path / "plain.ifc").write_bytes(ifc)
    assert len(load_scene(str(tmp_path / "bom.ifc")).mesh.faces) == len(
        load_scene(str(tmp_path / "plain.ifc")).mesh.faces
    )

    # Floor and ceiling seen, no wall within the outline's reach: the message says so and what to raise.
    grid = np.stack(np.meshgrid(np.linspace(-5, 5, 60), np.linspace(-5, 5, 60)), -1).reshape(-1, 2)
    points = np.vstack([np.c_[grid, np.zeros(len(grid))], np.c_[grid, np.full(len(grid), 2.6)]])
    with pytest.raises(RoIError, match=r"reach of 30 m from every stop \(robot\.roi\.max_range\)"):
        compute_roi([RoIScan(points=points, origin=np.array([0.0, 0.0, 1.5]))])

    out = tmp_path / "c"
    argv = ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "fast", "--max-scans", "3"]
    assert nbs([*argv, "--out", str(out), "--quiet"]) == 0
    folder = out / "runs" / "l_room" / "greedy" / "seed0"
    record = {
        **json.loads((folder / "run.json").read_text()),
        "metrics": json.loads((folder / "metrics.json").read_text()),
    }
    assert record_problem(record) is None
    metrics = record["metrics"]
    for edit, said in [
        ({"structure_sensed_pct": 100.0}, "is not its last step's"),
        (
            {"scans": 30, "steps": [metrics["steps"][0]] * (30 - len(metrics["steps"])) + metrics["steps"]},
            "30 scans, more than the run's budget of 3",
        ),
        (
            {"steps": [*metrics["steps"][:-1], {**metrics["steps"][-1], "structure_sensed_pct": 0.0}]},
            "below the step before's",
        ),
        # Probe 37: an emptied part was reused and its measured figures tabled as "-"; odd values kept.
        ({"quality": {}}, "quality.min_density_per_m2 is missing"),
        ({"quality": {**metrics["quality"], "dense_pct": "48"}}, 'quality.dense_pct is "48", not a number'),
        ({"registrability": {}}, "registrability.scans is missing"),
        ({"measured_points": -5}, "measured_points is -5, not within"),
        ({"policy_time_s": 1e308}, "policy_time_s is 1e+308, not within"),
        ({"config": {}}, "config lacks"),
        ({"scene_offset_m": [1, 2]}, "scene_offset_m is [1, 2], not null or three finite numbers"),
    ]:
        assert said in (record_problem({**record, "metrics": {**metrics, **edit}}) or ""), edit


def test_a_checkpoint_that_cannot_be_saved_whole_leaves_no_folder(run, capsys, monkeypatch):
    """A full disk at a checkpoint's training state left ``checkpoint_N/`` with the policy alone (or
    empty): a folder that looks like a checkpoint but cannot be resumed."""
    import errno

    import train.ppo

    save = train.ppo.save_training_state

    def full(model, folder, *args, **kwargs):
        if Path(folder).name.startswith("checkpoint_"):
            raise OSError(errno.ENOSPC, "No space left on device", str(Path(folder) / "training_state.pt"))
        return save(model, folder, *args, **kwargs)

    monkeypatch.setattr(train.ppo, "save_training_state", full)
    assert nbs(["train", "--resume", str(run), "--timesteps", "24", "--quiet"]) == 1
    assert "training_state.pt: No space left on device" in _err(capsys)
    assert sorted(p.name for p in run.glob("checkpoint_*")) == ["checkpoint_16", "checkpoint_8"]


def test_the_thirty_third_probes_findings(capsys, monkeypatch):
    """A generated corpus entry (``corpus:edge_8rooms_1``, in ``suite:unseen``) made ``nbs compare``
    a traceback: it has no file to resolve; in a working folder that was removed, every command said
    ``[Errno 2] No such file or directory``; a NaN was spelt ``nan``."""
    from nbs_env.config import make_config
    from nbs_env.errors import ConfigError
    from train.compare import grid

    specs = grid("corpus:edge_8rooms_1,generated:3", "random", "0", "fast")
    assert [s.scene for s in specs] == ["corpus:edge_8rooms_1", "generated:3"]
    with pytest.raises(ConfigError, match="got NaN"):
        make_config("fast", **{"robot.voxel_size": float("nan")})

    import train.cli

    def gone() -> str:
        raise FileNotFoundError(2, "No such file or directory")

    monkeypatch.setattr(train.cli.os, "getcwd", gone)
    assert nbs(["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1"]) == EXIT_USAGE
    assert _err(capsys).startswith("nbs: error: the working folder no longer exists (removed or moved since")


def test_a_training_runs_evaluation_keeps_its_scan_budget():
    """``nbs train --max-scans 2`` trained with 2 scans and drew its learning curve with 40."""
    from nbs_env.config import make_config
    from policies import GreedyPolicy
    from train.ppo import evaluate

    config = make_config("fast", max_scans=2)
    assert evaluate(GreedyPolicy().act, [3], 40, config)["scans"] <= 2


def test_the_thirty_fourth_probes_minor_findings(run, tmp_path):
    """``ppo:RUN/policy.pt`` was "not JSON" (a codec error); ``--y-up`` on a corpus mesh was "for
    labelled meshes only"; ``--storey`` on a corpus IFC was refused as a bundled scene's option; a
    curve's ``train_return`` of "abc" was kept."""
    from nbs_env.config import make_config
    from nbs_env.errors import ModelFileError
    from policies.learned import load_checkpoint
    from train.arguments import scene_option_error
    from train.ppo import _curve

    with pytest.raises(ModelFileError, match=r"the checkpoint.s weights, read through its description"):
        load_checkpoint(run / "policy.pt")
    said = scene_option_error("corpus:enfilade", None, True)
    assert said is not None and said.startswith("--y-up: corpus:enfilade is read with its corpus entry's own options")
    config = make_config("fast", scene="corpus:fzk_haus_eg", scene_options={"storey": "Dachgeschoss"})
    assert config.scene_options == {"storey": "Dachgeschoss"}
    line = {"timesteps": 16, "learned": {"structure_sensed_pct": 50, "scans": 3, "path_length_m": 4}}
    (tmp_path / "c.jsonl").write_text(json.dumps({**line, "train_return": "abc"}) + "\n")
    with pytest.raises(ModelFileError, match='line 1 has train_return "abc", not a finite number or null'):
        _curve(tmp_path / "c.jsonl")


def test_the_thirty_fifth_probes_findings(run, capsys):
    """A finished run resumed with ``--envs 2`` and no new total took no step but recorded 2 envs;
    a checkpoint's required ``--set`` was advised as ``--set KEY VALUE``, which ``--set`` refuses."""
    from nbs_env.errors import ConfigError
    from train.arguments import adopt_requirements

    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert nbs(["train", "--resume", str(run), "--envs", "2", "--quiet"]) == EXIT_USAGE
    assert (
        _err(capsys)
        == f"nbs train: error: --resume {run}: the run has done its 16 steps; ask for more (e.g. --timesteps 32)"
    )
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before

    with pytest.raises(ConfigError, match=r"pass --set observation\.cell=0\.2 or leave it out"):
        adopt_requirements({"observation.cell": 0.4}, {"observation.cell": (0.2, "ppo:x")})


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (lambda d: d.update(training=[]), "training must be a JSON object, got a list"),
        (lambda d: d["training"].update(config=None), "training.config must be a JSON object, got null"),
        (lambda d: d["training"].update(config="fast"), "training.config must be a JSON object, got a string"),
        (lambda d: d["training"]["config"].update(rooms=[]), "training.config.rooms is a list, not a JSON object"),
        (lambda d: d["training"]["config"]["observation"].update(cell="0.2"), "training.config.observation.cell is a"),
        (lambda d: d["training"].update(wall_search=True), "training.wall_search must be an integer"),
        # Probe 37: an empty or missing section dropped the requirements it records just the same.
        (lambda d: d["training"]["config"].update(observation={}), "training.config.observation.cell is missing"),
        (lambda d: d["training"]["config"].update(rooms={}), "training.config.rooms.completion_fraction is missing"),
        (lambda d: d["training"]["config"].pop("rooms"), "training.config.rooms is missing"),
        (lambda d: d["training"].pop("config"), "training.config is missing from a training run's record"),
    ],
)
def test_a_description_whose_training_record_is_of_another_type_is_refused(run, tmp_path, edit, said):
    """Probe 36: ``"training": []`` or ``training.config`` null or a string dropped the requirements
    the policy was trained with (observation.cell, the room rules) without a word, so a network
    trained on 0.2 m cells ran on 0.4 m ones; probe 37: so did an empty or missing section. A
    checkpoint that records no training (saved by a user's own code) is read as one with none."""
    from nbs_env.errors import ModelFileError
    from policies.learned import LearnedPolicy, load_checkpoint

    assert LearnedPolicy(run).requires["observation.cell"] == 0.2  # the run as written
    path = run / "policy.json"
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match=rf"policy\.json: malformed checkpoint description \({re.escape(said)}"):
        load_checkpoint(run)
    document.pop("training")
    path.write_text(json.dumps(document))
    assert "observation.cell" not in LearnedPolicy(run).requires


def test_an_output_another_command_is_writing_is_refused(run, tmp_path, capsys):
    """Probe 37: two commands given one ``--out`` at once both ran and both said they had written
    it: one scan's report replaced the other's, a grid tabled another grid's runs as its own, and two
    runs left one run's state with both runs' logs. The second is now refused before it looks at
    the folder, naming the process that holds it; the claim ends with its holder, however it ends."""
    import subprocess
    import sys

    from train.outputs import Output, OutputBusyError, claimed
    from train.ppo import resume_config, train

    out = tmp_path / "busy"
    hold = (
        "import sys, time\nfrom train.outputs import Output, claimed\n"
        "with claimed([Output('--out', sys.argv[1], sys.argv[2])]):\n    print('held', flush=True)\n"
        "    time.sleep(120)\n"
    )
    root = Path(__file__).resolve().parents[1]
    record = tmp_path / "r.rrd"
    holders = []
    try:
        for path, kind in ((out, "folder"), (run, "folder"), (record, "file")):
            (tmp_path / f"tmp-{kind}").mkdir(exist_ok=True)  # a batch job's TMPDIR of its own: the same claim
            holder = subprocess.Popen(
                [sys.executable, "-c", hold, str(path), kind], stdout=subprocess.PIPE, text=True, cwd=root,
                env={**__import__("os").environ, "PYTHONPATH": str(root), "TMPDIR": str(tmp_path / f"tmp-{kind}")},
            )  # fmt: skip
            holders.append(holder)
            assert holder.stdout.readline().strip() == "held"
        assert out.is_dir()  # made for the claim, as the command makes its --out
        said = f"{out}: another nbs command (process {holders[0].pid}) is writing it; wait for it to end, or choose"
        scan = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1", "--quiet", "--out", str(out)]
        assert nbs(scan) == EXIT_USAGE
        assert _err(capsys) == f"nbs scan: error: --out {said} another --out"
        compare = ["compare", "--scenes", "l_room", "--policies", "greedy", "--max-scans", "1", "--out", str(out)]
        assert nbs([*compare, "--quiet"]) == EXIT_USAGE
        assert _err(capsys) == f"nbs compare: error: --out {said} another --out"
        link = tmp_path / "link"
        link.symlink_to(out, target_is_directory=True)  # the same folder by another name
        assert nbs(["train", "--out", str(link), "--timesteps", "16", "--n-steps", "8", "--quiet"]) == EXIT_USAGE
        assert f"another nbs command (process {holders[0].pid}) is writing it" in _err(capsys)
        assert not any(out.iterdir()) and out.is_dir()  # nothing written, and nothing of the holder's removed
        before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
        with pytest.raises(OutputBusyError, match=f"--resume {re.escape(str(run))}: another nbs command"):
            train(resume_config(run, timesteps=32), run, progress=False, resume=True)
        assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before
        other = tmp_path / "other"
        assert nbs([*scan[:-1], str(other), "--record", str(tmp_path / "." / "r.rrd")]) == EXIT_USAGE
        assert f"--record {tmp_path / '.' / 'r.rrd'}: another nbs command (process {holders[2].pid})" in _err(capsys)
        assert not other.exists()  # the folder made for its claim is gone with it
    finally:
        for holder in holders:
            holder.kill()  # as the kernel's out-of-memory killer would: the claims go with the process
            holder.wait()
    with claimed([Output("--out", out)]), claimed([Output("--out", out)]):  # free again; claimed twice by one
        pass
    assert out.is_dir() and not any(out.iterdir())  # a killed holder's folder stays, empty: a valid new --out


def test_a_recording_the_disk_cannot_hold_is_one_line_and_the_report_stays(tmp_path, monkeypatch):
    """Probe 37: ``--record`` onto a full disk ended in rerun's RuntimeError (a traceback and rerun's
    own log lines), and rerun's flush can wait for ever there. The recorder waits while the file
    grows, then raises an OSError naming the recording (a full disk called so); nothing is left."""
    pytest.importorskip("rerun")
    import errno

    from nbs_env import replay

    recorder = replay.RunRecorder(tmp_path / "x.rrd", "l_room")
    real = recorder._rec

    class Failing:
        calls = 0

        def flush(self, timeout_sec: float) -> None:
            self.calls += 1
            if self.calls < 3:  # growing: a large recording on a slow disk is waited for
                recorder._partial.write_bytes(b"x" * (1000 * self.calls))
                raise RuntimeError("Flush timed out - not all log messages were sent")
            raise RuntimeError("File-writer thread shut down prematurely")

        def disconnect(self) -> None:
            pass

    recorder._rec = failing = Failing()
    monkeypatch.setattr(replay, "_nearly_full", lambda folder: True)
    with pytest.raises(OSError) as caught:
        recorder.close(keep=True)
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(tmp_path / "x.rrd")
    assert failing.calls == 3 and not list(tmp_path.iterdir())
    real.disconnect()

    stuck = replay.RunRecorder(tmp_path / "y.rrd", "l_room")
    real = stuck._rec

    class Stuck(Failing):
        def flush(self, timeout_sec: float) -> None:  # rerun's flush on a full disk: no progress
            self.calls += 1
            raise RuntimeError("Flush timed out - not all log messages were sent")

    stuck._rec = Stuck()
    monkeypatch.setattr(replay, "_nearly_full", lambda folder: False)
    with pytest.raises(OSError, match="the recording could not be written"):
        stuck.close(keep=True)
    assert stuck._rec.calls <= 2 and not list(tmp_path.iterdir())
    real.disconnect()


def test_a_resumed_run_with_more_envs_than_the_machine_takes_names_its_file(run, capsys, monkeypatch):
    """Probe 37: a state's ``run.envs`` of 1000 was refused as ``--envs 1000``, a flag never typed."""
    from train.ppo import main

    monkeypatch.setattr("os.cpu_count", lambda: 2)
    _edit_run(run, lambda r: r.update(envs=1000, batch_size=8))
    assert main(["--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert _err(capsys) == (
        f"nbs train: error: --resume: {run / 'training_state.json'}: its run.envs is 1000, more env workers than "
        "this machine takes (at most 4); continue with --envs 4 or fewer, or on a cluster with --backend ray --address"
    )


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_grid_s_workers_end_when_their_parent_is_killed(tmp_path):
    """Probe 38: ``nbs compare --jobs 2`` killed with SIGKILL (the out-of-memory killer) left its two
    workers, 0.4 GB each, running on for minutes. A worker started as the grid starts them now ends
    when its parent dies."""
    import os
    import signal
    import subprocess
    import sys
    import time

    parent = (
        "import multiprocessing, os, time\n"
        "from concurrent.futures import ProcessPoolExecutor\n"
        "from train.stopping import ignore_interrupts\n"
        "if __name__ == '__main__':\n"
        "    spawn = multiprocessing.get_context('spawn')\n"
        "    pool = ProcessPoolExecutor(1, mp_context=spawn, initializer=ignore_interrupts)\n"
        "    print(pool.submit(os.getpid).result(), flush=True)\n"
        "    pool.submit(time.sleep, 600)\n"
        "    time.sleep(600)\n"
    )
    script = tmp_path / "grid.py"
    script.write_text(parent)
    root = Path(__file__).resolve().parents[1]
    process = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(root)}
    )
    worker = int(process.stdout.readline())
    os.kill(worker, 0)  # alive
    process.send_signal(signal.SIGKILL)
    process.wait()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            os.kill(worker, 0)
        except ProcessLookupError:
            break
        # A zombie until its new parent reaps it: ended all the same.
        if Path(f"/proc/{worker}/stat").read_text().split(")")[-1].split()[0] == "Z":
            break
        time.sleep(0.2)
    else:
        os.kill(worker, signal.SIGKILL)
        pytest.fail("the worker outlived its killed parent by 20 s")


def test_an_output_inside_or_around_another_command_s_is_refused(tmp_path, capsys):
    """Probe 39: a scan whose ``--out`` was a folder inside a running grid's ``runs/`` wrote its report
    there, and the grid then wrote its run into the same folder: an output's folders are claimed too
    (shared), so neither a command inside another's output nor one around it runs meanwhile; two
    commands writing side by side in one folder still do."""
    import os
    import subprocess
    import sys

    from train.outputs import Output, OutputBusyError, claimed

    grid, beside = tmp_path / "grid", tmp_path / "beside"
    hold = (
        "import sys, time\nfrom train.outputs import Output, claimed\n"
        "with claimed([Output('--out', sys.argv[1])]):\n    print('held', flush=True)\n    time.sleep(120)\n"
    )
    root = Path(__file__).resolve().parents[1]
    holder = subprocess.Popen(
        [sys.executable, "-c", hold, str(grid)], stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(root)},
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        inside = grid / "runs" / "five_rooms"
        inside.mkdir(parents=True)
        run = inside / "seed13"
        scan = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1", "--quiet", "--out", str(run)]
        assert nbs(scan) == EXIT_USAGE
        assert _err(capsys) == (
            f"nbs scan: error: --out {run}: another nbs command (process {holder.pid}) is writing {grid}, which "
            "holds it; wait for it to end, or choose another --out"
        )
        assert not run.exists()
        with claimed([Output("--out", beside)]):  # side by side in one folder: both run
            pass
    finally:
        holder.kill()
        holder.wait()
    holder = subprocess.Popen(
        [sys.executable, "-c", hold, str(inside / "seed13")], stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(root)},
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        busy = pytest.raises(OutputBusyError, match=rf"--out {re.escape(str(grid))}: another nbs command")
        with busy, claimed([Output("--out", grid)]):  # a grid around a scan that is writing
            pass
    finally:
        holder.kill()
        holder.wait()


def test_a_resume_refuses_settings_edited_after_the_state_and_another_run_s_state(run, tmp_path, capsys):
    """Probe 40: ``n_steps`` and ``seed`` edited in ``training_state.json`` were trained with and
    recorded as the whole run's; another run's state pair copied into a run folder resumed that run
    beside this one's curve and logs. The tensors keep the settings and the run's id under their
    checksum, and the curve's records the run's id."""
    from train.ppo import main

    untouched = (run / "training_state.json").read_text()
    _edit_run(run, lambda r: r.update(n_steps=16, seed=7))
    assert main(["--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert _err(capsys) == (
        f"nbs train: error: --resume: {run / 'training_state.json'}: its run settings are not those the state was "
        "saved with (n_steps 16 against 8, seed 7 against 0); a resumed run keeps its own settings: restore the "
        "file, or start a new run from its weights with --init"
    )
    (run / "training_state.json").write_text(untouched)
    other = tmp_path / "other"
    shutil.copytree(run, other)
    document = json.loads((other / "training_state.json").read_text())
    document["run_id"] = "0123456789abcdef"
    (other / "training_state.json").write_text(json.dumps(document))
    assert main(["--resume", str(other), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert "its run_id is not the one the state was saved with" in _err(capsys)
    # Records of another run's id in the curve beside a state are refused; its own go on.
    state_id = json.loads(untouched)["run_id"]
    assert isinstance(state_id, str) and len(state_id) == 16
    figures = {"structure_sensed_pct": 90.0, "scans": 5.0, "path_length_m": 20.0}

    def record(run_id: str) -> str:
        return json.dumps({"timesteps": 8, "run": run_id, "learned": figures, "greedy": figures}) + "\n"

    (run / "learning_curve.jsonl").write_text(record("fedcba9876543210"))
    assert main(["--resume", str(run), "--timesteps", "32", "--quiet"]) == EXIT_USAGE
    assert "records are of another run (fedcba9876543210) than the training state beside it" in _err(capsys)
    (run / "learning_curve.jsonl").write_text(record(state_id))
    assert main(["--resume", str(run), "--timesteps", "32", "--quiet"]) == 0
    assert json.loads((run / "training_state.json").read_text())["run_id"] == state_id  # the same run goes on


def test_scenes_info_names_its_positional_scene_without_an_option(capsys):
    """Probe 40: ``nbs scenes info`` and ``show`` take the scene as a positional argument, and a name
    that is not UTF-8 was refused as ``--scene NAME``, an option they do not have."""
    assert nbs(["scenes", "info", "p_\udcff.json"]) == EXIT_USAGE
    assert _err(capsys) == "nbs scenes info: error: p_\ufffd.json: the name is not valid UTF-8; rename it"
    assert nbs(["scenes", "show", "p_\udcff.json", "--out", "x.png"]) == EXIT_USAGE
    assert _err(capsys).startswith("nbs scenes show: error: p_\ufffd.json: the name")


def test_a_run_says_where_whole_rollouts_take_it_past_its_timesteps(run, tmp_path, capsys):
    """Probe 41: ``--timesteps 10`` with rollouts of 32 steps trained 32 without a word (policy.json's
    ``timesteps_done`` said so, its ``timesteps`` the 10 asked for)."""
    from train.ppo import TrainConfig, _rounding

    assert _rounding(TrainConfig(timesteps=10, n_steps=32, envs=1), tmp_path / "new", resume=False) == (
        "nbs train: note: PPO trains whole rollouts of n_steps 32 x 1 env(s) = 32 steps: --timesteps 10 ran to 32"
    )
    assert _rounding(TrainConfig(timesteps=64, n_steps=16, envs=2), tmp_path / "new", resume=False) == ""
    # A resumed run rounds from the steps it has done (16 of the tiny run's rollouts of 8).
    note = _rounding(TrainConfig(timesteps=20, n_steps=8, envs=1, batch_size=8), run, resume=True)
    assert note.endswith("= 8 steps: --timesteps 20 ran to 24")
    from train.ppo import main

    assert main(["--resume", str(run), "--timesteps", "20", "--quiet"]) == 0
    assert capsys.readouterr().err.strip() == note  # said once the run is done


def test_a_plan_door_lower_than_the_robot_is_refused_and_a_missed_door_is_said(tmp_path, capsys):
    """Probe 42: a plan's doors of 1.5 m (or 1 mm) were accepted, and the robot, which could never
    pass them, scanned its first room and said "storey complete: yes". Doors taller than its door
    detection's lintels (2.6 m) are a building it meets: the summary now says which rooms got no scan."""
    from scenes import StoreyValidationError
    from train.cli import scan_summary

    assert nbs(["scenes", "generate", "--seed", "5", "--out", str(tmp_path / "p.json")]) == 0
    plan = json.loads((tmp_path / "p.json").read_text())
    for door in plan["doors"]:
        door["height"] = 1.5
    (tmp_path / "low.json").write_text(json.dumps(plan))
    with pytest.raises(StoreyValidationError, match=r"door doors\[0\] is 1\.5 m high; the robot needs 1\.8 m"):
        load_scene(str(tmp_path / "low.json"))
    rooms = [{"name": f"room{k}", "scans": s, "structure_sensed_pct": 50.0, "path_length_m": 1.0,
              "processed_points": 10, "processing_time_s": 1.0} for k, s in enumerate((0, 6, 0))]  # fmt: skip
    metrics = {
        "scene": "p", "policy": "greedy", "seed": 0, "rooms": rooms, "steps": [], "scans": 6, "complete": True,
        "structure_sensed_pct": 40.0, "path_length_m": 3.0, "processed_points": 30, "processing_time_s": 3.0,
        "acquisition_time_s": 1.0, "travel_time_s": 1.0,
        "config": {"max_scans": 60, "travel_speed": 0.5, "robot": {"scanner": {"points_per_second": 1e6}}},
        "quality": {"quality_pct": 1.0, "min_density_per_m2": 400, "dense_pct": 1.0, "max_incidence_deg": 70,
                    "incidence_pct": 1.0},
        "registrability": {}, "registration_error": {"mean_m": 0.0, "mean_deg": 0.0, "max_m": 0.0, "max_deg": 0.0},
    }  # fmt: skip
    text = scan_summary(metrics, tmp_path, ["metrics.json"])
    assert "storey complete: yes by the robot's account (no door it found is left), but 2 of the storey's 3" in text
    rooms[0]["scans"] = rooms[2]["scans"] = 1
    assert "storey complete: yes\n" in scan_summary(metrics, tmp_path, ["metrics.json"])


def test_scenes_generate_and_show_write_over_a_file_only_with_force(tmp_path, capsys):
    """Probe 42: ``nbs scenes generate --out`` replaced a hand-edited plan (or a checkpoint's
    ``policy.json``) without a word, and ``scenes show --out`` a report's picture."""
    plan, picture = tmp_path / "p.json", tmp_path / "top.png"
    plan.write_text('{"edited": true}')
    picture.write_bytes(b"mine")
    assert nbs(["scenes", "generate", "--seed", "5", "--out", str(plan)]) == EXIT_USAGE
    assert _err(capsys) == (
        f"nbs scenes generate: error: --out {plan}: exists; pass --force to write over it, or choose another name"
    )
    assert nbs(["scenes", "show", "l_room", "--out", str(picture)]) == EXIT_USAGE
    assert "--out" in _err(capsys) and picture.read_bytes() == b"mine" and plan.read_text() == '{"edited": true}'
    assert nbs(["scenes", "generate", "--seed", "5", "--out", str(tmp_path / "q.json"), "--show", str(picture)]) == 2
    assert not (tmp_path / "q.json").exists()  # refused before anything was written
    assert nbs(["scenes", "generate", "--seed", "5", "--out", str(plan), "--force"]) == 0
    assert nbs(["scenes", "show", "l_room", "--out", str(picture), "--force"]) == 0
    assert json.loads(plan.read_text())["doors"] and picture.read_bytes()[:4] == b"\x89PNG"


def test_a_scene_path_ending_in_a_separator_is_refused(tmp_path, capsys):
    """Probe 43: ``p.json/`` was read as ``p.json`` (pathlib drops the slash), and the report then
    recorded a name the system refuses to open ("Not a directory")."""
    from scenes import SceneFileError

    assert nbs(["scenes", "generate", "--seed", "5", "--out", str(tmp_path / "p.json")]) == 0
    with pytest.raises(SceneFileError, match="a name ending in a separator names a folder"):
        load_scene(f"{tmp_path / 'p.json'}/")
    assert nbs(["scenes", "info", f"{tmp_path / 'p.json'}/"]) != 0
    assert "a name ending in a separator names a folder" in _err(capsys)
    assert load_scene(str(tmp_path / "p.json")).rooms  # the file itself, as before


def test_a_mesh_room_with_a_floor_and_no_walls_is_warned_of(tmp_path):
    """Probe 43: an OBJ with one room's wall group left out (or a glTF wall node at scale 0) was
    taken without a word, and its coverage rose (the missing walls left the total)."""
    from scenes.importers import _write_ply
    from scenes.labels import SurfaceClass

    scene = load_scene("five_rooms")
    vertices, faces = np.asarray(scene.mesh.vertices), np.asarray(scene.mesh.faces)
    labels, rooms = np.asarray(scene.face_labels), np.asarray(scene.face_rooms)
    _write_ply(tmp_path / "whole.ply", vertices, faces, labels, rooms)
    keep = ~((labels == SurfaceClass.WALL) & (rooms == 0))
    _write_ply(tmp_path / "open.ply", vertices, faces[keep], labels[keep], rooms[keep])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_scene(str(tmp_path / "whole.ply"))  # every room walled: no warning
    with pytest.warns(UserWarning, match=r"room0 has a floor but no wall faces of its own; walls missing"):
        load_scene(str(tmp_path / "open.ply"))
    # Probe 44: a glTF wall node at scale 0 keeps its faces, of no area (here: each collapsed onto
    # its first corner); they are no walls either.
    collapsed = faces.copy()
    walls = (labels == SurfaceClass.WALL) & (rooms == 0)
    collapsed[walls] = collapsed[walls][:, :1]
    _write_ply(tmp_path / "flat.ply", vertices, collapsed, labels, rooms)
    with pytest.warns(UserWarning, match=r"room0 has a floor but no wall faces of its own"):
        load_scene(str(tmp_path / "flat.ply"))


def test_scan_force_names_a_recording_left_in_the_report_folder(tmp_path, capsys):
    """Probe 43: ``--force`` replaced an earlier report but kept its ``--record OUT/x.rrd`` beside
    the new one, which replays a run the report is not about; the scan now says so."""
    out = tmp_path / "rep"
    out.mkdir()
    (out / "metrics.json").write_text("{}")
    (out / "earlier.rrd").write_bytes(b"an earlier run's recording")
    args = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1", "--quiet", "--no-steps"]
    assert nbs([*args, "--out", str(out), "--force"]) == 0
    err = capsys.readouterr().err
    assert f"nbs scan: note: {out / 'earlier.rrd'} is kept; it is not this run's recording" in err, err
    assert (out / "earlier.rrd").read_bytes() == b"an earlier run's recording"  # the user's to remove


def test_a_storey_of_tall_doors_is_scanned_room_by_room(tmp_path):
    """Probe 42: five_rooms with 2.6 m doors under a 3.1 m ceiling was scanned in its first room
    only (METHOD's doors are 1.8-2.3 m high); every room gets its scans now, at the defaults."""
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv
    from nbs_env.report import metrics_dict
    from policies import make_policy
    from train.episode import run_episode

    plan = json.loads((Path(__file__).parents[1] / "scenes" / "data" / "five_rooms.json").read_text())
    plan["ceiling_height"] = 3.1
    for door in plan["doors"]:
        door["height"] = 2.6
    (tmp_path / "tall.json").write_text(json.dumps(plan))
    env = NBSEnv(make_config("fast", scene=str(tmp_path / "tall.json")))
    run_episode(env, make_policy("greedy", 0), 0, {}, lambda info: None)
    scans = [room["scans"] for room in metrics_dict(env.storey, "tall.json", "greedy", 0)["rooms"]]
    assert len(scans) == 5 and min(scans) >= 1, scans


def test_a_bundled_name_and_the_path_of_its_plan_are_one_scene(tmp_path, capsys):
    """Probe 44: ``--scenes office,scenes/data/office.json`` ran one storey twice, and the
    all-scenes means weighed it twice (two spellings of one path were refused already)."""
    plan = Path(__file__).parents[1] / "scenes" / "data" / "office.json"
    code = nbs(["compare", "--scenes", f"office,{plan}", "--policies", "greedy", "--out", str(tmp_path / "c")])
    assert code == EXIT_USAGE
    assert f"--scenes names office and {plan}" in _err(capsys)
    assert not (tmp_path / "c").exists()


def test_a_report_folder_of_another_command_is_refused_even_with_force(tmp_path, capsys):
    """Probe 44: ``nbs scan --force --out`` a comparison's folder mixed a scan report into it (only
    the scan's own files were replaced), and ``compare --resume`` then took the mixed folder."""
    comparison, report = tmp_path / "cmp", tmp_path / "rep"
    comparison.mkdir()
    (comparison / "table.md").write_text("| a comparison |\n")
    report.mkdir()
    (report / "metrics.json").write_text("{}")
    scan = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1", "--quiet", "--no-steps", "--force"]
    assert nbs([*scan, "--out", str(comparison)]) == EXIT_USAGE
    assert _err(capsys) == f"nbs scan: error: --out {comparison}: holds a comparison (table.md); choose another folder"
    compare = ["compare", "--scenes", "l_room", "--policies", "greedy", "--max-scans", "1", "--quiet"]
    for flag in ("--force", "--resume"):
        assert nbs([*compare, "--out", str(report), flag]) == EXIT_USAGE
        assert "holds a scan report (metrics.json); choose another folder" in _err(capsys)
    assert sorted(p.name for p in comparison.iterdir()) == ["table.md"]
    assert sorted(p.name for p in report.iterdir()) == ["metrics.json"]
