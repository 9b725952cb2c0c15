"""``load_scene``: one entry point for every kind of source, and a clear error for every bad one."""

from __future__ import annotations

import json

import pytest

from scenes import (
    FloorPlan,
    FloorPlanError,
    RoomPlan,
    Scene,
    SceneFileError,
    StoreySizeError,
    UnknownSceneError,
    UnsupportedFormatError,
    bundled_plan,
    list_scenes,
    load_scene,
)


@pytest.mark.parametrize("name", ["five_rooms", "l_room", "office"])
def test_bundled_scenes_load_and_validate(name):
    scene = load_scene(name)
    assert isinstance(scene, Scene) and scene.name == name
    assert scene.structural_area() > 0 and len(scene.rooms) >= 1


def test_plan_path_and_plan_object_give_the_same_mesh(tmp_path):
    plan = bundled_plan("l_room")
    path = tmp_path / "l.json"
    plan.to_json(path)
    a, b = load_scene(str(path)), load_scene(plan)
    assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
    assert isinstance(plan, FloorPlan)


def test_unknown_scene_lists_the_bundled_ones():
    with pytest.raises(UnknownSceneError) as info:
        load_scene("five_room")
    message = str(info.value)
    assert message.startswith("five_room: ")
    for name in list_scenes():
        assert name in message


def test_missing_file(tmp_path):
    with pytest.raises(SceneFileError, match="no such file") as info:
        load_scene(str(tmp_path / "house.obj"))
    assert str(tmp_path / "house.obj") in str(info.value)


def test_unsupported_extension(tmp_path):
    path = tmp_path / "house.stl"
    path.write_text("solid x\nendsolid x\n")
    with pytest.raises(UnsupportedFormatError, match=r"unsupported file type '\.stl'; supported: \.json"):
        load_scene(str(path))


def test_generated_seed_must_be_an_integer():
    with pytest.raises(UnknownSceneError, match="not an integer"):
        load_scene("generated:abc")


def test_generated_with_options():
    scene = load_scene("generated:3", rooms=2, clutter_density=0.5)
    assert len(scene.rooms) == 2
    assert scene.metadata["seed"] == 3


def test_options_that_a_source_does_not_take():
    with pytest.raises(TypeError, match=r"\['storey'\]"):
        load_scene("office", storey=1)


# ---------------------------------------------------------------------- sizes and nesting
def test_a_floor_plan_wider_than_any_storey_is_refused_before_a_grid(tmp_path):
    # Within the schema's coordinates (1e5 m), 200 km wide: its samples would once have filled TiB.
    plan = {
        "format": "nbs-floorplan",
        "version": 1,
        "ceiling_height": 2.7,
        "wall_thickness": 0.15,
        "rooms": [{"name": "hall", "polygon": [[-1e5, 0], [1e5, 0], [1e5, 8], [-1e5, 8]]}],
    }
    path = tmp_path / "hall.json"
    path.write_text(json.dumps(plan))
    with pytest.raises(StoreySizeError, match=r"hall\.json: the storey is 200,000 m across and 2\.7 m high"):
        load_scene(str(path))
    # A plan object skips the schema: 10^6 m is refused where the Scene is built.
    wide = FloorPlan(rooms=(RoomPlan("hall", ((0, 0), (1e6, 0), (1e6, 8), (0, 8))),), name="wide")
    with pytest.raises(StoreySizeError, match="the storey is 1,000,000 m across"):
        load_scene(wide)


def test_a_scene_built_in_millimetres_names_the_unit():
    from helpers import box_room

    with pytest.raises(
        StoreySizeError, match=r"10,000 m across .*are its lengths in millimetres\? they must be metres"
    ):
        box_room(10000.0, 8000.0, 2500.0, wall=200.0)


def test_a_floor_plan_nested_thousands_deep_is_refused(tmp_path):
    # It was a RecursionError in json.loads. The 64th "[" (level 65, inside the object) is at column 43 + 64.
    path = tmp_path / "deep.json"
    path.write_text('{"format": "nbs-floorplan", "description": ' + "[" * 5000 + "]" * 5000 + "}")
    with pytest.raises(
        FloorPlanError, match=r"deep\.json: invalid JSON: nested deeper than 64 levels at line 1 column 107"
    ):
        load_scene(str(path))


def test_json_nesting_is_counted_outside_strings_only():
    from scenes.jsonio import MAX_JSON_DEPTH, JSONNestingError, read_json

    deepest = "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH
    assert read_json(deepest) == json.loads(deepest)
    assert read_json('{"a": "' + "[" * 100 + '\\"[", "b": [1]}') == {"a": "[" * 100 + '"[', "b": [1]}
    with pytest.raises(JSONNestingError) as info:
        read_json('\n  {"a": ' + "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH + "}")
    # The object is level 1: its 64th array, from column 9 of line 2, is level 65.
    assert (info.value.lineno, info.value.colno) == (2, 9 + MAX_JSON_DEPTH - 1)
    assert isinstance(info.value, json.JSONDecodeError)


def test_units_are_an_option_of_meshes_only(tmp_path):
    with pytest.raises(TypeError, match=r"\['units'\]"):
        load_scene("office", units="mm")
    from scenes.importers import export_scene

    path = tmp_path / "office.obj"
    export_scene(load_scene("office"), path)
    with pytest.raises(ValueError, match="units must be one of m, cm, mm, ft, in, got 'yd'"):
        load_scene(str(path), units="yd")
