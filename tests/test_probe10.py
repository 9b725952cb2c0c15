"""Reproducers of the eighteenth bad-input probe's findings (and two of the seventeenth's), one test per
class of input."""

from __future__ import annotations

import json
import math

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
