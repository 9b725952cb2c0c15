"""Reproducers of the eighteenth bad-input probe's findings (and two of the seventeenth's), one test per
class of input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scenes import load_scene
from tests.test_probe8 import glb_parts  # noqa: F401  # a fixture

_PLAN = {"positions": [[1.0, 2.0, 1.2], [3.0, 2.0, 1.2]], "coverage_pct": [40.0, 50.0], "max_coverage_pct": 90.0,
         "candidates": 4, "samples": 100}  # fmt: skip


# ---------------------------------------------------------------------- oracle records
@pytest.mark.parametrize(
    "edit, message",
    [
        ({"positions": [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]}, r"\(m, 3\).*\(3, 2\)"),  # regrouped as 2 triples
        ({"positions": [1.0, 2.0, 1.2, 3.0, 2.0, 1.2]}, r"\(m, 3\).*\(6,\)"),
        ({"positions": [[[1.0, 2.0, 1.2]], [[3.0, 2.0, 1.2]]]}, "nested at most twice"),
        ({"room_max_pct": {"1": 30.0, "01": 40.0}}, "key '01' is not a room id"),  # both read as room 1
        ({"room_max_pct": {"\u0661": 30.0}}, "is not a room id"),  # an Arabic-Indic 1, int() reads it
        ({"room_max_pct": {" 2 ": 30.0}}, "is not a room id"),
        ({"room_max_pct": {"-1": 30.0}}, "is not a room id"),
        ({"candidates": 0, "positions": [[1.0, 2.0, 0.0]], "coverage_pct": [5.0]}, "of 0 candidates"),
    ],
)
def test_an_oracle_record_is_read_as_to_dict_writes_it_or_refused(edit, message):
    """Positions of any shape were regrouped into triples, room keys "1" and "01" collapsed to one
    room, and a scan of no candidate was taken."""
    from policies.oracle import OraclePlan

    plan = OraclePlan.from_dict({**_PLAN, "room_max_pct": {"0": 80.0, "12": 70.0}})
    assert plan.positions.shape == (2, 3) and plan.room_max_pct == {0: 80.0, 12: 70.0}
    assert OraclePlan.from_dict(plan.to_dict()).to_dict() == plan.to_dict()
    empty = OraclePlan.from_dict({**_PLAN, "positions": [], "coverage_pct": [], "candidates": 0})
    assert empty.positions.shape == (0, 3)
    with pytest.raises(ValueError, match=message):
        OraclePlan.from_dict({**_PLAN, **edit})


def test_an_oracle_record_nested_without_end_is_a_value_error():
    """5,000 nested lists were a RecursionError (the CLI's JSON reader stops at 64 levels; the API did not)."""
    from policies.oracle import OraclePlan

    deep: object = 0.0
    for _ in range(5000):
        deep = [deep]
    with pytest.raises(ValueError, match="nested at most twice"):
        OraclePlan.from_dict({**_PLAN, "positions": deep})


# ---------------------------------------------------------------------- glTF nodes and scenes
def _gltf(glb_parts, tmp_path, edit) -> str:  # noqa: F811
    json_chunk, binary, _faces = glb_parts
    doc = json.loads(json_chunk)
    (tmp_path / "plain.bin").write_bytes(binary)
    doc["buffers"] = [dict(doc["buffers"][0], uri="plain.bin")]
    edit(doc)
    (tmp_path / "x.gltf").write_text(json.dumps(doc))
    return str(tmp_path / "x.gltf")


_C, _S = math.cos(math.pi / 2), math.sin(math.pi / 2)


@pytest.mark.parametrize(
    "node, message",
    [
        ({"matrix": [1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}, r"last row is 0\.5, 0, 0, 1"),  # projective
        ({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 2]}, r"last row is 0, 0, 0, 2"),  # half size if /w
        ({"matrix": [1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}, "a shear"),
        ({"rotation": [0.5, 0, 0, 0.5]}, r"not a unit quaternion \(length 0\.7071\)"),  # was normalised silently
        ({"rotation": [0, 0, 0, 2]}, r"not a unit quaternion \(length 2\)"),
    ],
)
def test_a_node_transform_that_is_no_translation_rotation_and_scale_is_refused(node, message, glb_parts, tmp_path):  # noqa: F811
    """glTF 2.0 §5.25: a matrix must decompose into TRS and a rotation be a unit quaternion; the reader
    dropped a projective row, applied a shear and normalised a quaternion without a word."""
    from scenes import InvalidMeshError

    with pytest.raises(InvalidMeshError, match=message):
        load_scene(_gltf(glb_parts, tmp_path, lambda doc: doc["nodes"][0].update(node)))


@pytest.mark.parametrize(
    "node",
    [
        {"matrix": [_C, _S, 0, 0, -_S, _C, 0, 0, 0, 0, 1, 0, 3, 4, 0, 1]},  # a quarter turn and a move
        {"matrix": [-1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1.0000001]},  # a mirror, a stretch, float32 w
        {"rotation": [0, 0, 0.70710677, 0.70710677]},  # float32's unit quaternion
    ],
)
def test_a_node_transform_that_is_one_is_read(node, glb_parts, tmp_path):  # noqa: F811
    assert len(load_scene(_gltf(glb_parts, tmp_path, lambda doc: doc["nodes"][0].update(node))).mesh.faces) > 0


def test_a_scene_lists_each_root_once_and_only_roots(glb_parts, tmp_path):  # noqa: F811
    """A root listed twice, or a child listed as a root, drew its meshes twice without a word."""
    from scenes import InvalidMeshError

    def twice(doc):
        doc["scenes"][0]["nodes"] = doc["scenes"][0]["nodes"] * 2

    def child(doc):
        doc["nodes"].append({"children": [doc["scenes"][0]["nodes"][0]]})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)

    with pytest.raises(InvalidMeshError, match="lists node 0 twice"):
        load_scene(_gltf(glb_parts, tmp_path, twice))
    with pytest.raises(InvalidMeshError, match="the child of another node"):
        load_scene(_gltf(glb_parts, tmp_path, child))


# ---------------------------------------------------------------------- options named where they are the cause
def test_a_storey_read_with_the_wrong_options_names_them(tmp_path):
    """A z-up file read with --y-up said "cannot choose a start: no floor area"; with --units cm as
    well it advised feet, naming neither option given."""
    from scenes import StoreySizeError, StoreyValidationError
    from scenes.importers import export_scene

    export_scene(load_scene("l_room"), tmp_path / "l.obj")
    with pytest.raises(StoreyValidationError, match=r"floor faces cover no floor area: .*--y-up"):
        load_scene(str(tmp_path / "l.obj"), y_up=True)
    with pytest.raises(StoreySizeError, match=r"read with --units cm and --y-up"):
        load_scene(str(tmp_path / "l.obj"), units="cm", y_up=True)
    assert len(load_scene(str(tmp_path / "l.obj")).mesh.faces) > 0


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("robot.navigation.max_candidates", 100_000, r"robot\.navigation\.max_candidates=100000"),
        ("observation.shape", (2000, 1, 1), r"observation\.shape=\[2000, 1, 1\]"),
        ("observation.shape", (True, 32, 16), r"observation\.shape must be three positive integers"),
    ],
)
def test_a_training_setting_no_network_takes_is_named_by_its_key(key, value, message):
    """The error named the network's fields (`candidates`, `voxel_shape`), not the key the user set."""
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    with pytest.raises(ConfigError, match=message):
        _ = TrainConfig(completion="policy", overrides={key: value}).network


# ---------------------------------------------------------------------- probe 19: numbers no float holds
_HUGE = 10**400  # a JSON integer has no bound; float() of it raises OverflowError


def test_json_refuses_an_integer_no_float_holds_and_names_its_place():
    import json as json_module

    from scenes.jsonio import read_json

    assert read_json('{"a": 1' + "0" * 300 + "}")["a"] == 10**300  # a float holds it
    with pytest.raises(json_module.JSONDecodeError, match="an integer of 401 digits") as info:
        read_json('{"a": [0, 1' + "0" * 400 + "]}")
    assert info.value.pos == 10


def test_a_setting_no_float_holds_is_a_config_error_not_an_overflow():
    """`--set robot.voxel_size=1000...0` (401 digits) and a checkpoint recording one were tracebacks."""
    from nbs_env.config import ObservationConfig
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match="cell must be a finite number"):
        ObservationConfig(cell=_HUGE)
    with pytest.raises(ConfigError, match=r"about 10\^400 cells"):  # a float product was inf, then int(inf)
        ObservationConfig(shape=(10**200, 10**200, 1))


@pytest.mark.parametrize(
    "edit",
    [{"max_coverage_pct": _HUGE}, {"positions": [[_HUGE, 2.0, 1.2], [3.0, 2.0, 1.2]]}, {"room_max_pct": {"0": _HUGE}}],
)
def test_an_oracle_record_of_a_number_no_float_holds_is_a_value_error(edit):
    from policies.oracle import OraclePlan

    with pytest.raises(ValueError, match="not an oracle plan"):
        OraclePlan.from_dict({**_PLAN, **edit})


def test_an_svm_file_says_what_its_json_reader_refused(tmp_path):
    """A key named twice was "truncated or not JSON" without the reader's reason; a 401-digit gamma
    an OverflowError."""
    from nbs_env.errors import ModelFileError
    from nbs_env.perception.structure import SEClassifier

    text = SEClassifier.load_default().save(tmp_path / "se.json").read_text()
    (tmp_path / "twice.json").write_text(text.replace("{", '{"format": "x", ', 1))
    with pytest.raises(ModelFileError, match="appears twice"):
        SEClassifier.load(tmp_path / "twice.json")
    (tmp_path / "huge.json").write_text(text.replace('"gamma":', f'"gamma": {_HUGE}, "g":', 1))
    with pytest.raises(ModelFileError, match="401 digits"):
        SEClassifier.load(tmp_path / "huge.json")


# ---------------------------------------------------------------------- probe 19: glTF meshes and names
@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda doc: doc["meshes"][0].update(primitives={}), r"primitives is \{\}, not a list"),  # mesh dropped
        (lambda doc: doc["meshes"][0].update(primitives=[]), r"primitives is \[\], not a list"),
        (lambda doc: doc["meshes"][0].update(primitives=[5]), r"primitives\[0\] is 5, not a primitive"),
        (lambda doc: doc["meshes"][0].pop("primitives"), "primitives is null"),
        (lambda doc: doc["nodes"][0].update(name=5), r"nodes\[0\]\.name is 5, not a string"),
        (lambda doc: doc["meshes"][0].update(name=["floor"]), r'meshes\[0\]\.name is \["floor"\], not a string'),
    ],
)
def test_a_mesh_without_primitives_or_a_name_that_is_no_string_is_refused(edit, message, glb_parts, tmp_path):  # noqa: F811
    """An empty or non-list `primitives` dropped the mesh without a word; a primitive or name of
    another type was an error from inside the reader (AttributeError, TypeError)."""
    from scenes import InvalidMeshError

    with pytest.raises(InvalidMeshError, match=message):
        load_scene(_gltf(glb_parts, tmp_path, edit))


def test_a_plan_start_outside_every_room_is_said_to_be_outside(tmp_path):
    """It was said to be "not 0.45 m clear of walls and clutter"."""
    from importlib import resources

    from scenes import StoreyValidationError

    plan = json.loads((resources.files("scenes") / "data" / "l_room.json").read_text())
    (tmp_path / "p.json").write_text(json.dumps({**plan, "start": [-50.0, -50.0]}))
    with pytest.raises(StoreyValidationError, match=r"the start \(-50, -50\) lies in no room"):
        load_scene(str(tmp_path / "p.json"))


def test_a_start_no_float_holds_is_the_start_error():
    """`start=(10**400, 1)` was a bare OverflowError from numpy (an infinite start was named)."""
    from nbs_env import NBSEnv
    from nbs_env.errors import ConfigError
    from scenes import InvalidMeshError

    with pytest.raises(InvalidMeshError, match="start must be a finite"):
        load_scene("l_room", start=(_HUGE, 1.0))
    env = NBSEnv(scene="l_room", preset="fast")
    try:
        with pytest.raises(ConfigError, match=r"options\['start'\] must be 2 or 3 finite numbers"):
            env.reset(seed=0, options={"start": [_HUGE, 1.0]})
    finally:
        env.close()


def test_a_generated_seed_of_thousands_of_digits_is_named():
    """5,000 digits passed the digit check and Python's int refused them with a traceback."""
    from scenes import UnknownSceneError

    with pytest.raises(UnknownSceneError, match="the seed has 5,000 digits"):
        load_scene("generated:" + "9" * 5000)


def test_a_set_value_of_thousands_of_digits_is_said_to_be_too_long():
    """It was taken as a string, then "max_scans must be an integer >= 1, got '999...'"."""
    import argparse

    from train.arguments import _assignment as parse_override

    with pytest.raises(argparse.ArgumentTypeError, match="max_scans: the value holds a number of more than 4,300"):
        parse_override("max_scans=" + "9" * 5000)
    with pytest.raises(argparse.ArgumentTypeError, match="an integer of 401 digits"):
        parse_override("robot.voxel_size=1" + "0" * 400)
    assert parse_override("rooms.completion_fraction=0.05") == ("rooms.completion_fraction", 0.05)


def test_which_gltf_scene_is_read_is_said(glb_parts, tmp_path):  # noqa: F811
    """No scenes gave "the mesh is empty"; two and no `scene` read the first without a word."""
    from scenes import InvalidMeshError

    def none(doc):
        doc.pop("scenes", None)
        doc.pop("scene", None)

    def two(doc):
        doc.pop("scene", None)
        doc["scenes"] = [doc["scenes"][0], {"nodes": []}]

    with pytest.raises(InvalidMeshError, match="lists no scenes, so nothing"):
        load_scene(_gltf(glb_parts, tmp_path, none))
    with pytest.warns(UserWarning, match=r"2 scenes and names none \('scene'\): scenes\[0\] is read"):
        assert len(load_scene(_gltf(glb_parts, tmp_path, two)).mesh.faces) > 0


# ---------------------------------------------------------------------- probe 20
@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: __import__("nbs_env.config", fromlist=["x"]).ObservationConfig(shape=5), "ObservationConfig: a field"),
        (lambda: __import__("nbs_env.config", fromlist=["x"]).EnvConfig(robot=0), "robot must be a RobotConfig, got 0"),
        (
            lambda: __import__("nbs_env.config", fromlist=["x"]).EnvConfig.from_dict(
                {"robot": {"doors": {"min_behind_points": _HUGE}}}
            ),
            "min_behind_points must be at most .*, got an integer of 401 digits",
        ),
    ],
)
def test_a_configuration_of_a_field_of_the_wrong_kind_is_a_config_error(build, message):
    """`ObservationConfig(shape=5)` was a TypeError from `len`, a 401-digit bound an OverflowError
    from the message's own formatting."""
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        build()


def test_a_set_object_naming_a_key_twice_says_so():
    import argparse

    from train.arguments import _assignment

    with pytest.raises(argparse.ArgumentTypeError, match="rooms: the key 'completion_fraction' appears twice"):
        _assignment('rooms={"completion_fraction": 0.05, "completion_fraction": 0.5}')


@pytest.mark.parametrize("seconds", ['"nan"', "1" + "0" * 400, "-5", "true"])
def test_a_run_s_recorded_seconds_that_are_no_count_are_taken_as_none(seconds, tmp_path):
    """A string "nan" went into the next policy.json as NaN (not JSON); 401 digits were an
    OverflowError after the resumed session's work, which was then lost."""
    from train.ppo import _previous_seconds

    (tmp_path / "policy.json").write_text('{"training": {"seconds": ' + seconds + "}}")
    assert _previous_seconds(tmp_path) == 0.0
    (tmp_path / "policy.json").write_text('{"training": {"seconds": 12.5}}')
    assert _previous_seconds(tmp_path) == 12.5


def test_a_mesh_drawn_with_morph_targets_is_refused(glb_parts, tmp_path):  # noqa: F811
    """The reader drew the undeformed mesh where other readers add the weighted targets (a wall 3 m out)."""
    from scenes import InvalidMeshError

    def morph(weight):
        def edit(doc):
            primitive = doc["meshes"][0]["primitives"][0]
            primitive["targets"] = [{"POSITION": primitive["attributes"]["POSITION"]}]
            doc["meshes"][0]["weights"] = [weight]

        return edit

    with pytest.raises(InvalidMeshError, match=r"morph targets drawn at meshes\[0\]\.weights \[1\.0\]"):
        load_scene(_gltf(glb_parts, tmp_path, morph(1.0)))
    assert len(load_scene(_gltf(glb_parts, tmp_path, morph(0.0))).mesh.faces) > 0  # weight 0 changes nothing


@pytest.mark.parametrize("easting, shown", [("600000.", "600,000"), ("32600000.", "32,600,000")])  # zone in front
def test_an_ifc_storey_at_survey_coordinates_is_moved_near_the_origin(easting, shown, tmp_path):
    """Storeys exported at "shared" survey coordinates were refused ("move the model near the origin"):
    IFC bounds no placement, and only the geometry's relative positions matter."""
    from tests.test_probe8 import _ifc_with_start

    # The file's own start (StartX 6, StartY 2 in the storey's frame) moves with the storey.
    original = _ifc_with_start(tmp_path, "IFCLENGTHMEASURE(6.)").read_text()
    moved = original.replace("#21=IFCCARTESIANPOINT((0.,0.,0.));", f"#21=IFCCARTESIANPOINT(({easting},5800000.,0.));")
    moved = moved.replace("#32=IFCCARTESIANPOINT((0.,0.,3.));", f"#32=IFCCARTESIANPOINT(({easting},5800000.,3.));")
    assert moved.count("5800000.") == 2
    (tmp_path / "utm.ifc").write_text(moved)
    plain = load_scene(str(tmp_path / "start.ifc"))
    with pytest.warns(UserWarning, match=rf"survey coordinates \({shown}, 5,800,000\) m"):
        scene = load_scene(str(tmp_path / "utm.ifc"))
    # The walls' lowest corner was the file's (0, 0): moved by exactly the survey offset.
    assert scene.metadata["offset"] == [float(easting), 5800000.0]
    assert np.allclose(np.sort(scene.mesh.vertices, axis=0), np.sort(plain.mesh.vertices, axis=0), atol=1e-6)
    assert [round(r.area, 6) for r in scene.rooms] == [round(r.area, 6) for r in plain.rooms]
    assert np.allclose([d.position for d in scene.doors], [d.position for d in plain.doors], atol=1e-6)
    assert np.allclose(scene.start, plain.start, atol=1e-6) and plain.start[:2].tolist() == [6.0, 2.0]
    if easting == "600000.":  # the report says where the scan lies in the file's frame
        from nbs_env import NBSEnv
        from nbs_env.report import metrics_dict

        env = NBSEnv(preset="fast")
        try:
            env.reset(seed=0, options={"scene": scene})
            assert metrics_dict(env.storey, "utm.ifc", "greedy", 0)["scene_offset_m"] == [600000.0, 5800000.0]
        finally:
            env.close()
    assert plain.metadata["offset"] is None


# ---------------------------------------------------------------------- probe 21
@pytest.mark.parametrize(
    "make, message",
    [
        (lambda c: c.EnvConfig(observation=0), "observation must be a ObservationConfig, got 0"),
        (lambda c: c.EnvConfig(generator=5), "generator must be a GeneratorConfig, got 5"),
        (lambda c: c.RobotConfig(scanner=None), "scanner must be a ScannerConfig, got null"),
        (lambda c: c.EnvConfig(keep_scans="no"), r'keep_scans must be a bool \(true or false\), got "no"'),
        (lambda c: c.EnvConfig.from_dict({"keep_scans": 0.5}), "keep_scans must be a bool \\(true or false\\)"),
    ],
)
def test_a_configuration_field_holds_its_declared_kind(make, message):
    """`EnvConfig(observation=0)` was taken and failed in the env; `keep_scans="no"` kept every scan."""
    import numpy

    from nbs_env import config
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        make(config)
    kept = config.EnvConfig(keep_scans=numpy.True_)
    assert kept.keep_scans is True and config.EnvConfig.from_dict(kept.to_dict()) == kept


@pytest.mark.parametrize(
    "edit",
    [
        # a node's weights 0 override the mesh's 1 (glTF 2.0 §5.25)
        lambda doc, acc: (doc["meshes"][0].update(weights=[1.0]), doc["nodes"][0].update(weights=[0.0])),
        # a node no scene draws
        lambda doc, acc: doc["nodes"].append({"mesh": 0, "weights": [1.0]}),
        # targets that move no position
        lambda doc, acc: (
            doc["meshes"][0]["primitives"][0].update(targets=[{"NORMAL": acc}]),
            doc["meshes"][0].update(weights=[1.0]),
        ),
    ],
)
def test_morph_targets_that_move_nothing_drawn_are_read(edit, glb_parts, tmp_path):  # noqa: F811
    """Three files that draw the base geometry were refused as "morph targets drawn"."""

    def apply(doc):
        primitive = doc["meshes"][0]["primitives"][0]
        accessor = primitive["attributes"]["POSITION"]
        primitive["targets"] = [{"POSITION": accessor}]
        edit(doc, accessor)

    assert len(load_scene(_gltf(glb_parts, tmp_path, apply)).mesh.faces) > 0


def test_a_resumed_run_s_settings_that_ask_too_much_memory_name_its_file(tiny_run, tmp_path):
    """ "--n-steps 10...0 x --envs 1 asks for ... TiB" named options the user never typed."""
    import shutil

    from nbs_env.errors import ModelFileError
    from train.ppo import resume_config

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    for state in run.rglob("training_state.json"):
        document = json.loads(state.read_text())
        document["run"]["n_steps"] = 10**30
        state.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match=r"training_state\.json: its run settings are refused \(.*n.steps"):
        resume_config(run)


def test_a_binary_ply_shorter_than_its_faces_indices_is_named_truncated(tmp_path):
    """A file short by less than its faces' indices was read on, face bytes as vertex bytes ("the
    mesh is empty", or "8 bytes follow the last record" for a file 4 bytes short)."""
    import struct

    from scenes import InvalidMeshError

    header = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty float y\n"
        b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nproperty uchar label\n"
        b"end_header\n"
    )
    body = b"".join(struct.pack("<dff", *v) for v in ((0, 0, 0), (1, 0, 0), (0, 1, 0)))
    body += struct.pack("<B3iB", 3, 0, 1, 2, 1)
    (tmp_path / "short.ply").write_bytes(header + body[:-5])
    with pytest.raises(InvalidMeshError, match="at least 62 bytes, but 57 bytes follow the header"):
        load_scene(str(tmp_path / "short.ply"))


# ---------------------------------------------------------------------- probe 22
def test_a_dotted_field_inside_a_section_set_to_no_section_is_a_config_error():
    """`make_config(robot=5, **{"robot.scanner.height": 2.0})` was a TypeError from inside; a
    GeneratorConfig instance with a dotted generator field one of item assignment."""
    from nbs_env.config import make_config
    from nbs_env.errors import ConfigError
    from scenes.generator import GeneratorConfig

    with pytest.raises(ConfigError, match=r"robot is set to 5, not a section, and robot\.scanner\.height inside it"):
        make_config(**{"robot": 5, "robot.scanner.height": 2.0})
    assert make_config(generator=GeneratorConfig(), **{"generator.rooms": 3}).generator.rooms == 3


@pytest.mark.parametrize("n_steps, envs, batch_size", [(65, 1, 64), (43, 3, 64), (8, 2, 1)])
def test_a_rollout_that_leaves_a_minibatch_of_one_sample_is_refused_before_the_work(n_steps, envs, batch_size):
    """PPO normalises each minibatch's advantages by their spread: one of a single sample gave NaN
    logits and a traceback after the first rollout, and the run was lost."""
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    with pytest.raises(ConfigError, match="leaves a minibatch of one sample"):
        TrainConfig(n_steps=n_steps, envs=envs, batch_size=batch_size)
    assert TrainConfig(n_steps=64, envs=envs, batch_size=64).n_steps == 64


def test_a_training_configuration_takes_numpy_numbers():
    import numpy

    from train.ppo import TrainConfig

    config = TrainConfig(rooms=(numpy.int64(1), numpy.int64(3)), cell_size=(numpy.float32(2.0), numpy.float32(3.0)))
    assert config.rooms == (1, 3) and type(config.rooms[0]) is int and type(config.cell_size[0]) is float
    assert TrainConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config


def test_a_skinned_mesh_is_refused(glb_parts, tmp_path):  # noqa: F811
    """glTF 2.0 §3.7.3: a skinned mesh is drawn by its joints' transforms; it was read unposed without a word."""
    from scenes import InvalidMeshError

    def skin(doc):
        doc["nodes"].append({"name": "bone", "translation": [0, 0, 1.5]})
        doc["skins"] = [{"joints": [len(doc["nodes"]) - 1]}]
        doc["nodes"][0]["skin"] = 0

    with pytest.raises(InvalidMeshError, match=r"nodes\[0\] draws its mesh with a skin"):
        load_scene(_gltf(glb_parts, tmp_path, skin))

    def undrawn(doc):  # a skinned copy of mesh 0 that no scene draws: the storey is the plain one
        doc["nodes"].append({"name": "bone"})
        doc["skins"] = [{"joints": [len(doc["nodes"]) - 1]}]
        doc["nodes"].append({"name": "library", "mesh": 0, "skin": 0})

    plain = load_scene(_gltf(glb_parts, tmp_path, lambda doc: None))
    scene = load_scene(_gltf(glb_parts, tmp_path, undrawn))
    assert len(scene.mesh.triangles) == len(plain.mesh.triangles)


# ---------------------------------------------------------------------- scanner presets
def test_a_scanner_preset_name_must_describe_the_values_the_scanner_holds():
    """``--set robot.scanner.preset=rtc360:6mm`` ran the generic scanner while metrics.json and the E57
    header named the RTC360."""
    from dataclasses import replace

    from nbs_env.config import make_config
    from nbs_env.config.scanners import scanner_config
    from nbs_env.errors import ConfigError

    with pytest.raises(ConfigError, match=r"'rtc360:6mm' records the Leica RTC360.*max_range 350\.0 .*130\.0"):
        make_config("fast", **{"robot.scanner.preset": "rtc360:6mm"})
    sheet = scanner_config("rtc360:6mm", simulated_step=1.0, height=1.2).to_dict()
    assert make_config("fast", **{"robot.scanner": sheet}).robot.scanner.preset == "rtc360:6mm"
    with pytest.raises(ConfigError, match=r"station_time .*use --scanner rtc360:6mm"):  # one value changed
        make_config("fast", **{"robot.scanner": {**sheet, "station_time": 5.0}})
    config = make_config("fast", **{"robot.scanner": {**sheet, "station_time": 5.0, "preset": None}})
    assert config.robot.scanner.station_time == 5.0  # a scanner set by hand names no datasheet
    with pytest.raises(ConfigError, match=r"holds station_time 5\.0 \(the datasheet.s 22\.9\):"):
        replace(config, robot=replace(config.robot, scanner=replace(config.robot.scanner, preset="rtc360:6mm")))
