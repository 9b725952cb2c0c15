"""Floor-plan JSON and its extrusion into a labelled mesh."""

from __future__ import annotations

import json

import numpy as np
import pytest
from shapely.geometry import Polygon

from scenes import FloorPlan, FloorPlanError, PlanGeometryError, SceneFileError, SurfaceClass, load_plan, load_scene
from scenes._open3d import open3d
from scenes.floorplan import PLAN_SCHEMA, extrude


def cast(scene, origins, directions):
    o3d = open3d()
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(
        o3d.core.Tensor(scene.mesh.vertices.astype(np.float32)), o3d.core.Tensor(scene.mesh.faces.astype(np.uint32))
    )
    rays = np.concatenate([np.broadcast_to(origins, directions.shape), directions], axis=1).astype(np.float32)
    out = rc.cast_rays(o3d.core.Tensor(rays))
    return out["t_hit"].numpy(), out["primitive_ids"].numpy()


def test_round_trip_json(plan_dict, tmp_path):
    plan = FloorPlan.from_dict(plan_dict)
    again = load_plan(tmp_path / "p.json") if plan.to_json(tmp_path / "p.json") else None
    assert again == plan
    assert json.loads(plan.to_json())["version"] == 1


def test_bundled_plans_satisfy_the_schema():
    import jsonschema

    from scenes import bundled_plan, list_scenes

    assert {"five_rooms", "l_room", "office"} <= set(list_scenes())
    for name in list_scenes():
        jsonschema.validate(bundled_plan(name).to_dict(), PLAN_SCHEMA)


def test_rectangle_room_areas_are_exact(plan_dict):
    scene = extrude(FloorPlan.from_dict(plan_dict))
    t, h = 0.2, 2.6
    # Centre-line rectangles 5x4 and 4x4; the clear floor is inset by half a wall on every side.
    expected = [(5 - t) * (4 - t), (4 - t) * (4 - t)]
    for room, area in zip(scene.rooms, expected, strict=True):
        floor = (scene.face_labels == SurfaceClass.FLOOR) & (scene.face_rooms == room.id)
        assert scene.face_areas[floor].sum() == pytest.approx(area, rel=1e-9)
        assert room.area == pytest.approx(area, rel=1e-9)
        ceiling = (scene.face_labels == SurfaceClass.CEILING) & (scene.face_rooms == room.id)
        assert scene.face_areas[ceiling].sum() == pytest.approx(area, rel=1e-9)
    # Walls: both rooms' perimeters times the height, minus the door opening on each side.
    perimeters = 2 * (4.8 + 3.8) + 2 * (3.8 + 3.8)
    walls = scene.class_areas()[SurfaceClass.WALL]
    assert walls == pytest.approx(perimeters * h - 2 * 0.9 * 2.0, rel=1e-9)
    # The door passage: two jambs (t x 2.0), soffit and threshold (t x 0.9).
    assert scene.class_areas()[SurfaceClass.DOOR] == pytest.approx(2 * t * 2.0 + 2 * t * 0.9, rel=1e-9)
    assert scene.class_areas()[SurfaceClass.CLUTTER] > 0


def test_faces_point_into_the_rooms_and_rays_stay_inside(plan_dict):
    scene = extrude(FloorPlan.from_dict(plan_dict))
    from scenes.validation import fibonacci_sphere

    dirs = fibonacci_sphere(2000)
    origin = np.array([2.5, 1.0, 1.5])
    t_hit, prim = cast(scene, origin[None, :], dirs)
    assert np.all(np.isfinite(t_hit))
    normals = scene.mesh.face_normals[prim]
    # Every surface the scanner sees faces it.
    assert np.all(np.einsum("ij,ij->i", normals, dirs) < 0)


def test_door_is_open_and_walls_are_closed(plan_dict):
    scene = extrude(FloorPlan.from_dict(plan_dict))
    # Through the door's centre at 1 m: the ray crosses into room b and hits its far wall at x = 8.9.
    t_hit, prim = cast(scene, np.array([[3.0, 2.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert t_hit[0] == pytest.approx(8.9 - 3.0, abs=1e-4)
    assert scene.face_rooms[prim[0]] == 1 and scene.face_labels[prim[0]] == SurfaceClass.WALL
    # Above the lintel the shared wall blocks: hit at x = 4.9 on room a's side.
    t_hit, prim = cast(scene, np.array([[3.0, 2.0, 2.3]]), np.array([[1.0, 0.0, 0.0]]))
    assert t_hit[0] == pytest.approx(1.9, abs=1e-4)
    assert scene.face_rooms[prim[0]] == 0
    # Beside the opening too.
    t_hit, _ = cast(scene, np.array([[3.0, 0.8, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert t_hit[0] == pytest.approx(1.9, abs=1e-4)
    # A jamb is labelled DOOR.
    t_hit, prim = cast(scene, np.array([[5.0, 2.0, 1.0]]), np.array([[0.0, 1.0, 0.0]]))
    assert t_hit[0] == pytest.approx(0.45, abs=1e-4) and scene.face_labels[prim[0]] == SurfaceClass.DOOR
    door = scene.doors[0]
    assert door.rooms == (0, 1) and door.width == 0.9 and np.allclose(door.normal, [1, 0])


def test_windows_hold_a_pane(plan_dict):
    plan_dict["windows"] = [{"room": "a", "position": [2.5, 0], "width": 1.2, "height": 1.0, "sill": 1.0}]
    scene = extrude(FloorPlan.from_dict(plan_dict))
    assert scene.class_areas()[SurfaceClass.WINDOW] == pytest.approx(1.2)
    t_hit, prim = cast(scene, np.array([[2.5, 2.0, 1.5]]), np.array([[0.0, -1.0, 0.0]]))
    assert t_hit[0] == pytest.approx(1.9, abs=1e-4) and scene.face_labels[prim[0]] == SurfaceClass.WINDOW
    plan_dict["windows"][0]["position"] = [5, 2]  # on the wall between a and b
    with pytest.raises(PlanGeometryError, match="inside wall"):
        extrude(FloorPlan.from_dict(plan_dict))


def test_every_face_has_a_class_and_a_room():
    scene = load_scene("five_rooms")
    assert len(scene.face_labels) == len(scene.face_rooms) == len(scene.mesh.faces)
    se = scene.structural_mask()
    assert np.all(scene.face_rooms[se] >= 0)
    assert np.all(scene.face_rooms[scene.face_labels == SurfaceClass.DOOR] == -1)
    assert np.all(scene.face_rooms[scene.face_labels == SurfaceClass.CLUTTER] >= 0)


def test_five_rooms_is_as_demanding_as_the_papers_scene():
    from scenes import bundled_plan
    from scenes.floorplan import WALL_STANDING_KINDS

    plan = bundled_plan("five_rooms")
    scene = load_scene("five_rooms")
    assert len(scene.rooms) == 5
    assert 150 <= sum(r.area for r in scene.rooms) <= 250
    angles = []
    for room in scene.rooms:
        poly = Polygon(room.polygon)
        assert poly.convex_hull.area > poly.area + 0.5, f"{room.name} is not concave"
        assert len(room.polygon) > 4, f"{room.name} is a rectangle"
        p = room.polygon
        a, b = np.roll(p, 1, axis=0) - p, np.roll(p, -1, axis=0) - p
        cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    assert any(np.any(np.abs(a - 90) > 5) for a in angles), "no room has a non-right angle"
    assert all(0.8 <= d.width <= 1.0 for d in scene.doors)
    for room in scene.rooms:
        poly = Polygon(room.polygon)
        inside = [c for c in plan.clutter if poly.contains(c.footprint().centroid)]
        assert len(inside) >= 4, room.name
        # Against a wall: its back within 5 cm of the room outline, and at least 0.8 m tall.
        against = [
            c
            for c in inside
            if c.kind in WALL_STANDING_KINDS and poly.exterior.distance(c.footprint()) < 0.05 and c.size[2] >= 0.8
        ]
        assert len(against) >= 2, room.name


# ------------------------------------------------------------------------------------- bad input
def test_invalid_json_names_file_and_position(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{"format": "nbs-floorplan", "version": 1,,}')
    with pytest.raises(FloorPlanError, match=r"broken\.json: invalid JSON: .* line 1 column"):
        load_plan(path)


@pytest.mark.parametrize(
    ("mutate", "field", "message"),
    [
        (lambda d: d.pop("wall_thickness"), "(top level)", "wall_thickness"),
        (lambda d: d["rooms"][1].update(polygon=[[5, 0], [9, "x"], [9, 4]]), "rooms[1].polygon[1][1]", "not of type"),
        (lambda d: d["doors"][0].update(width=-1), "doors[0].width", "less than the minimum of 0.001"),
        (lambda d: d["clutter"][0].update(kind="piano"), "clutter[0].kind", "piano"),
        (lambda d: d.update(version=7), "version", "unsupported format version 7"),
        (lambda d: d.update(colour="red"), "(top level)", "colour"),
        (lambda d: d["doors"][0].update(rooms=["a", "c"]), "doors[0].rooms[1]", "unknown room 'c'"),
        # Sizes no storey has: a unit slip or an overflow, refused rather than extruded.
        (lambda d: d.update(ceiling_height=1e6), "ceiling_height", "greater than the maximum of 30"),
        (lambda d: d.update(wall_thickness=5), "wall_thickness", "greater than the maximum of 3"),
        (lambda d: d["clutter"][0].update(size=[1, 1, 1e4]), "clutter[0].size[2]", "greater than the maximum"),
        (lambda d: d["rooms"][0]["polygon"][0].__setitem__(0, 1e9), "rooms[0].polygon[0][0]", "greater than"),
    ],
)
def test_schema_violations_name_the_field(plan_dict, write_json, mutate, field, message):
    mutate(plan_dict)
    path = write_json(plan_dict)
    with pytest.raises(FloorPlanError, match=message) as info:
        load_plan(path)
    assert info.value.path == field
    assert str(info.value).startswith(f"{path}: {field}: ")


def test_nan_in_plan_is_rejected(plan_dict, tmp_path):
    path = tmp_path / "nan.json"
    path.write_text(json.dumps(plan_dict).replace("2.6", "NaN", 1))
    with pytest.raises(FloorPlanError, match="NaN"):
        load_plan(path)


def test_missing_plan_file(tmp_path):
    with pytest.raises(SceneFileError, match="no such file"):
        load_plan(tmp_path / "nope.json")


def test_self_intersecting_room(plan_dict, write_json):
    plan_dict["rooms"][0]["polygon"] = [[0, 0], [5, 4], [5, 0], [0, 4]]  # a bow tie
    plan_dict["doors"] = []
    with pytest.raises(PlanGeometryError, match=r"not simple.*Self-intersection") as info:
        load_scene(str(write_json(plan_dict)))
    assert info.value.path == "rooms[0].polygon"


def test_door_not_on_a_shared_wall(plan_dict, write_json):
    plan_dict["doors"][0]["position"] = [2.5, 4]  # on an outside wall of room a
    with pytest.raises(PlanGeometryError, match="not on a wall shared by 'a' and 'b'") as info:
        load_scene(str(write_json(plan_dict)))
    assert info.value.path == "doors[0].position"


def test_door_too_close_to_a_corner(plan_dict, write_json):
    plan_dict["doors"][0]["position"] = [5, 0.3]
    with pytest.raises(PlanGeometryError, match="does not fit"):
        load_scene(str(write_json(plan_dict)))


def test_clutter_blocking_a_door(plan_dict, write_json):
    plan_dict["clutter"].append({"kind": "box", "position": [4.5, 2.0], "size": [0.5, 0.5, 1.0], "yaw": 0})
    with pytest.raises(PlanGeometryError, match=r"blocks door doors\[0\]") as info:
        load_scene(str(write_json(plan_dict)))
    assert info.value.path == "clutter[1]"


def test_clutter_through_a_wall(plan_dict, write_json):
    plan_dict["clutter"][0]["position"] = [5.0, 0.6]
    with pytest.raises(PlanGeometryError, match="not inside any room"):
        load_scene(str(write_json(plan_dict)))


def test_overlapping_rooms(plan_dict, write_json):
    plan_dict["rooms"][1]["polygon"] = [[4, 0], [9, 0], [9, 4], [4, 4]]
    with pytest.raises(PlanGeometryError, match="overlaps"):
        load_scene(str(write_json(plan_dict)))


def test_messages_give_positions_as_plain_numbers():
    """numpy's reprs once reached the user: ``door at (np.float64(50.0), np.float64(50.0))``."""
    from helpers import two_room_plan

    plan = two_room_plan()
    plan["doors"][0]["position"] = [50, 50.5]
    with pytest.raises(PlanGeometryError, match=r"door at \(50, 50\.5\) is not on a wall") as raised:
        FloorPlan.from_dict(plan).to_scene()
    assert "np." not in str(raised.value)


@pytest.mark.parametrize(("key", "most"), [("clutter", 10_000), ("doors", 2_000), ("rooms", 500)])
def test_a_plan_s_lists_are_counted_before_they_are_checked(key, most):
    """300,000 clutter objects or 100,000 doors once took minutes; refused at once, naming the list."""
    import time

    from helpers import two_room_plan

    plan = two_room_plan()
    plan[key] = [plan[key][0] if plan.get(key) else {}] * (most + 1)
    start = time.perf_counter()
    with pytest.raises(FloorPlanError, match=rf"{most + 1:,} {key}; a plan holds at most {most:,}"):
        FloorPlan.from_dict(plan)
    assert time.perf_counter() - start < 1.0


def test_a_number_too_long_to_read_is_bad_json(tmp_path):
    """An integer of 100,000 digits: Python refuses to convert it (a ValueError from inside)."""
    path = tmp_path / "long.json"
    path.write_text('{"format": "nbs-floorplan", "version": ' + "9" * 100_000 + "}")
    with pytest.raises(FloorPlanError, match="a number of more than 4,300 digits"):
        load_plan(path)


def test_two_doors_over_one_stretch_of_wall_are_refused():
    """A door duplicated, or two drawn over each other, cut one opening twice (accepted silently)."""
    from helpers import two_room_plan

    plan = two_room_plan()
    door = plan["doors"][0]
    plan["doors"].append({**door, "position": [door["position"][0], door["position"][1] + door["width"] / 2]})
    with pytest.raises(PlanGeometryError, match=r"doors\[1\]\.position: door at .* overlaps doors\[0\]"):
        FloorPlan.from_dict(plan).to_scene()
