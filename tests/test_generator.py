"""The seeded storey generator: determinism, validity over many seeds, variety, options."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from scenes import GeneratorConfig, SurfaceClass, generate_plan, load_scene
from scenes.geometry import STOREY_CLEARANCE, point_is_free
from scenes.validation import count_escaping_rays

N_SEEDS = 50


@pytest.fixture(scope="module")
def storeys():
    return {seed: generate_plan(seed) for seed in range(N_SEEDS)}


def test_same_seed_same_mesh_bytes():
    a = load_scene("generated:11", rooms=4)
    b = load_scene("generated:11", rooms=4)
    assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
    assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()
    assert a.face_labels.tobytes() == b.face_labels.tobytes()
    assert a.face_rooms.tobytes() == b.face_rooms.tobytes()
    c = load_scene("generated:12", rooms=4)
    assert c.mesh.vertices.tobytes() != a.mesh.vertices.tobytes()


def _connected(n_rooms, doors):
    seen, todo = {0}, [0]
    while todo:
        r = todo.pop()
        for d in doors:
            if r in d.rooms:
                other = d.rooms[1] if d.rooms[0] == r else d.rooms[0]
                if other not in seen:
                    seen.add(other)
                    todo.append(other)
    return len(seen) == n_rooms


def test_fifty_seeds_are_all_valid(storeys):
    for seed, plan in storeys.items():
        scene = plan.to_scene(validate=True)  # raises on an invalid storey
        assert 1 <= len(scene.rooms) <= 8
        assert _connected(len(scene.rooms), scene.doors), seed
        # Checks independent of the validator: the start is free by the mesh, and nothing leaks.
        assert point_is_free(scene, scene.start[:2], 0.0, STOREY_CLEARANCE), seed
        origins = [np.append(scene.start[:2], 1.5)] + [
            [*Polygon(r.polygon).representative_point().coords[0], 1.0] for r in scene.rooms
        ]
        assert count_escaping_rays(scene, np.array(origins), 1024).sum() == 0, seed
        # Per-room floor area equals the room polygon's area.
        for room in scene.rooms:
            floor = (scene.face_labels == SurfaceClass.FLOOR) & (scene.face_rooms == room.id)
            assert scene.face_areas[floor].sum() == pytest.approx(room.area, rel=0.01)
            assert all(0.8 <= d.width <= 1.0 for d in scene.doors)


def test_room_shapes_vary(storeys):
    shapes: Counter[str] = Counter()
    non_right = 0
    for plan in storeys.values():
        for room in plan.rooms:
            poly = np.asarray(room.polygon)
            n = len(poly)
            shapes[{4: "rect", 6: "L"}.get(n, "T/U/irregular")] += 1
            a, b = np.roll(poly, 1, axis=0) - poly, np.roll(poly, -1, axis=0) - poly
            cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
            non_right += bool(np.any(np.abs(cos) > 0.05))
    assert shapes["rect"] > 0 and shapes["L"] > 0 and shapes["T/U/irregular"] > 0, shapes
    assert non_right >= 5
    counts = Counter(len(p.rooms) for p in storeys.values())
    assert min(counts) <= 2 and max(counts) >= 7, counts


def test_room_count_option_is_respected():
    for seed in range(3):
        assert len(generate_plan(seed, rooms=3).rooms) == 3
    assert 2 <= len(generate_plan(5, rooms=(2, 3)).rooms) <= 3


def test_clutter_density_scales_clutter():
    area = lambda p: sum(Polygon(r.polygon).area for r in p.rooms)  # noqa: E731
    none = [generate_plan(s, rooms=3, clutter_density=0.0) for s in range(5)]
    some = [generate_plan(s, rooms=3, clutter_density=1.0) for s in range(5)]
    lots = [generate_plan(s, rooms=3, clutter_density=2.5) for s in range(5)]
    assert all(len(p.clutter) == 0 for p in none)
    per_m2 = lambda ps: sum(len(p.clutter) for p in ps) / sum(area(p) for p in ps)  # noqa: E731
    assert per_m2(lots) > 1.5 * per_m2(some) > 0


def test_clutter_stands_against_walls(storeys):
    against = 0
    for plan in list(storeys.values())[:10]:
        polys = [Polygon(r.polygon).buffer(-plan.wall_thickness / 2, join_style="mitre") for r in plan.rooms]
        for c in plan.clutter:
            foot = c.footprint()
            room = next(p for p in polys if p.buffer(1e-6).contains(foot))
            against += room.exterior.distance(foot) < 0.05
    assert against >= 20


def test_start_is_in_a_room(storeys):
    for plan in storeys.values():
        assert plan.start is not None
        assert any(Polygon(r.polygon).contains(Point(plan.start)) for r in plan.rooms)


def test_bad_generator_options():
    with pytest.raises(ValueError, match=r"rooms must be within 1\.\.8"):
        GeneratorConfig(rooms=9)
    with pytest.raises(ValueError, match="clutter_density"):
        GeneratorConfig(clutter_density=-1)
    with pytest.raises(TypeError, match=r"do not apply to this source \(generated storey\)"):
        load_scene("generated:1", colour="red")


@pytest.mark.parametrize("seed", [0, 7])
def test_the_storey_generated_with_its_plan_is_the_plan_extruded(seed):
    """generate_storey hands back the scene its plan was validated on instead of extruding again:
    it must be the plan's extrusion, mesh, labels, rooms, doors, start and all."""
    from scenes.generator import generate_storey

    plan, scene = generate_storey(seed, rooms=3)
    assert plan == generate_plan(seed, rooms=3)
    again = plan.to_scene(source=plan.name, validate=False)
    np.testing.assert_array_equal(scene.mesh.vertices, again.mesh.vertices)
    np.testing.assert_array_equal(scene.mesh.faces, again.mesh.faces)
    np.testing.assert_array_equal(scene.face_labels, again.face_labels)
    np.testing.assert_array_equal(scene.face_rooms, again.face_rooms)
    np.testing.assert_array_equal(scene.start, again.start)
    assert scene.name == again.name == f"generated:{seed}"
    assert len(scene.rooms) == len(again.rooms) and len(scene.doors) == len(again.doors)
    assert scene.metadata["seed"] == seed and scene.metadata["attempts"] >= 1
