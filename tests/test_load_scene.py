"""``load_scene``: one entry point for every kind of source, and a clear error for every bad one."""

from __future__ import annotations

import pytest

from scenes import (
    FloorPlan,
    Scene,
    SceneFileError,
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
