"""Tests of scenes.importers: labelled OBJ / glTF / PLY meshes in and out."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from scenes.errors import (
    InvalidMeshError,
    MissingStructureError,
    SceneError,
    SceneFileError,
    StoreySizeError,
    UnsupportedFormatError,
)
from scenes.importers import (
    UnlabelledPartsWarning,
    export_scene,
    footprint_polygon,
    load_mesh_scene,
    parse_part_name,
)
from scenes.model import Room, Scene, SurfaceClass

F, C, W, D, WIN, CL = (
    SurfaceClass.FLOOR,
    SurfaceClass.CEILING,
    SurfaceClass.WALL,
    SurfaceClass.DOOR,
    SurfaceClass.WINDOW,
    SurfaceClass.CLUTTER,
)


# ------------------------------------------------------------------------------------ fixtures
def _quad(a, b, c, d) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.array([a, b, c, d], float), [[0, 1, 2], [0, 2, 3]], process=False)


def box_room(x0=0.0, x1=4.0, y0=0.0, y1=3.0, h=2.5) -> dict[str, trimesh.Trimesh]:
    """Floor, ceiling, four walls and a 1 x 1 x 1 clutter box of an x0..x1 by y0..y1 room."""
    parts = {
        "floor": _quad((x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)),
        "ceiling": _quad((x0, y0, h), (x0, y1, h), (x1, y1, h), (x1, y0, h)),
        "wall_s": _quad((x0, y0, 0), (x0, y0, h), (x1, y0, h), (x1, y0, 0)),
        "wall_n": _quad((x0, y1, 0), (x1, y1, 0), (x1, y1, h), (x0, y1, h)),
        "wall_w": _quad((x0, y0, 0), (x0, y1, 0), (x0, y1, h), (x0, y0, h)),
        "wall_e": _quad((x1, y0, 0), (x1, y0, h), (x1, y1, h), (x1, y1, 0)),
    }
    box = trimesh.creation.box(extents=(1, 1, 1))
    box.apply_translation((x0 + 1.0, y0 + 1.0, 0.5))
    parts["clutter_box"] = box
    return parts


def box_areas(w=4.0, d=3.0, h=2.5) -> dict[SurfaceClass, float]:
    return {F: w * d, C: w * d, W: 2 * (w + d) * h, D: 0.0, WIN: 0.0, CL: 6.0}


def obj_text(parts: dict[str, trimesh.Trimesh], keyword="o", transform=None) -> str:
    """OBJ text with one ``keyword`` statement (``o`` or ``g``, or a per-part callable) per part."""
    lines, offset = [], 0
    for i, (name, mesh) in enumerate(parts.items()):
        v = mesh.vertices if transform is None else transform(mesh.vertices)
        lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in v]
        kw = keyword(i) if callable(keyword) else keyword
        lines.append(f"{kw} {name}")
        lines += [f"f {a + offset + 1} {b + offset + 1} {c + offset + 1}" for a, b, c in mesh.faces]
        offset += len(v)
    return "\n".join(lines) + "\n"


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def assert_areas(scene: Scene, expected: dict[SurfaceClass, float], rel=1e-6) -> None:
    got = scene.class_areas()
    for cls in SurfaceClass:
        assert got[cls] == pytest.approx(expected[cls], rel=rel, abs=1e-9), cls


def two_room_parts() -> dict[str, trimesh.Trimesh]:
    """Room 0 (4 x 3, its clutter box without a room) and room 3 (3 x 3, east of it), plus a door."""
    parts = {f"{k}_room0" if not k.startswith("clutter") else k: m for k, m in box_room().items()}
    for k, m in box_room(4.0, 7.0, 0.0, 3.0, h=2.8).items():
        parts[f"{k}_room3"] = m
    parts["door_0"] = _quad((3.9, 1.0, 0), (3.9, 1.9, 0), (3.9, 1.9, 2.0), (3.9, 1.0, 2.0))
    return parts


# ------------------------------------------------------------------------------- name parsing
@pytest.mark.parametrize(
    ("name", "cls", "room"),
    [
        ("wall_north", W, -1),
        ("Floor.001", F, -1),
        ("CEILING", C, -1),
        ("door2", D, -1),
        ("window-3", WIN, -1),
        ("clutter desk", CL, -1),
        ("wall_room3_0", W, 3),
        ("floor.room12", F, 12),
        ("Clutter_ROOM7", CL, 7),
        ("clutter_bedroom2", CL, -1),
        ("wall_room3a", W, -1),
        ("walls", None, -1),
        ("doorway", None, -1),
        ("my_wall", None, -1),
        ("room2_floor", None, 2),
        ("", None, -1),
    ],
)
def test_parse_part_name(name, cls, room):
    assert parse_part_name(name) == (cls, room)


# ----------------------------------------------------------------------------------------- OBJ
def test_obj_reads_objects_and_groups(tmp_path):
    # Alternate o and g statements: both kinds of name must label their faces.
    p = write(tmp_path, "room.obj", obj_text(box_room(), keyword=lambda i: "og"[i % 2]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_mesh_scene(p)
    assert_areas(scene, box_areas())
    assert len(scene.mesh.faces) == 6 * 2 + 12
    assert scene.name == str(p)
    assert scene.metadata["format"] == "obj"
    # No room tags: one room derived from the floor's free space.
    assert scene.metadata["rooms"] == "derived" and len(scene.rooms) == 1


def test_obj_group_beats_object_and_object_ends_group(tmp_path):
    parts = box_room()
    text = obj_text(parts)
    # A labelled group inside an unlabelled object labels the faces ...
    text = text.replace("o clutter_box", "o Mesh.004\ng clutter_box")
    # ... an unlabelled group falls back to a labelled object ...
    text = text.replace("o wall_e", "o wall_e\ng default_material")
    # ... and a new object must not inherit the previous object's group.
    text += "o ceiling_extra\nv 0 0 3\nv 1 0 3\nv 0 1 3\nf -3 -2 -1\n"
    text = text.replace("o ceiling_extra", "g floor_leftover\no ceiling_extra")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_mesh_scene(write(tmp_path, "mixed.obj", text))
    expected = box_areas()
    expected[C] += 0.5
    assert_areas(scene, expected)


def test_obj_polygons_negative_indices_and_ignored_statements(tmp_path):
    text = (
        "mtllib room.mtl\n"
        "o floor\nv 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nvt 0 0\nvn 0 0 1\nusemtl grey\ns off\n"
        "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
        "o wall\nv 0 0 0\nv 2 0 0\nv 2 0 2\nf -3//1 -2//1 \\\n -1//1\n"
    )
    scene = load_mesh_scene(write(tmp_path, "poly.obj", text))
    assert scene.class_areas()[F] == pytest.approx(4.0)
    assert scene.class_areas()[W] == pytest.approx(2.0)
    assert list(scene.face_labels) == [F, F, W]


def test_unlabelled_parts_become_clutter_with_one_warning(tmp_path):
    parts = box_room()
    parts["Chair.001"] = parts.pop("clutter_box")
    parts["lamp"] = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    parts["walls_extra"] = _quad((0, 0, 3), (1, 0, 3), (1, 1, 3), (0, 1, 3))
    with pytest.warns(UnlabelledPartsWarning) as record:
        scene = load_mesh_scene(write(tmp_path, "u.obj", obj_text(parts)))
    unlabelled = [w for w in record if issubclass(w.category, UnlabelledPartsWarning)]
    assert len(unlabelled) == 1
    warning = unlabelled[0].message
    assert warning.names == ("Chair.001", "lamp", "walls_extra")
    text = str(warning)
    assert "u.obj" in text and "Chair.001" in text and "lamp" in text and "walls_extra" in text
    expected = box_areas()
    expected[CL] = 6.0 + 1.5 + 1.0
    assert_areas(scene, expected)


def test_rooms_from_tokens_are_renumbered(tmp_path):
    scene = load_mesh_scene(write(tmp_path, "rooms.obj", obj_text(two_room_parts())))
    assert [r.name for r in scene.rooms] == ["room0", "room3"]
    assert [r.id for r in scene.rooms] == [0, 1]
    r0, r1 = scene.rooms
    assert r0.area == pytest.approx(12.0) and r1.area == pytest.approx(9.0)
    # Counter-clockwise (positive signed area), not closed, collinear points removed.
    for room in scene.rooms:
        x, y = room.polygon[:, 0], room.polygon[:, 1]
        assert 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 0
        assert not np.allclose(room.polygon[0], room.polygon[-1])
        assert len(room.polygon) == 4
    assert np.allclose(sorted(map(tuple, r1.polygon)), [(4, 0), (4, 3), (7, 0), (7, 3)])
    assert (r0.floor_z, r0.ceiling_z) == (0.0, 2.5)
    assert (r1.floor_z, r1.ceiling_z) == (0.0, pytest.approx(2.8))
    assert set(np.unique(scene.face_rooms)) == {-1, 0, 1}
    per_room = np.bincount(scene.face_rooms + 1, weights=scene.face_areas)
    assert per_room[1] == pytest.approx(12 + 12 + 14 * 2.5)  # room0: floor, ceiling, walls
    assert per_room[2] == pytest.approx(9 + 9 + 12 * 2.8 + 6)  # room3 includes its clutter box
    assert per_room[0] == pytest.approx(6 + 0.9 * 2)  # room0's clutter box and the door


def test_room_without_floor_falls_back_to_no_room(tmp_path):
    parts = box_room()
    parts["wall_room5"] = _quad((0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1))
    with pytest.warns(UserWarning, match="room5"):
        scene = load_mesh_scene(write(tmp_path, "orphan.obj", obj_text(parts)))
    assert scene.metadata["rooms"] == "derived"  # no room left with an outline: rooms from geometry


def test_room_ceiling_defaults_to_floor_plus_2_7(tmp_path):
    parts = {"floor_room1": _quad((0, 0, 0.5), (2, 0, 0.5), (2, 2, 0.5), (0, 2, 0.5))}
    parts["wall_room1"] = _quad((0, 0, 0.5), (0, 0, 2), (2, 0, 2), (2, 0, 0.5))
    scene = load_mesh_scene(write(tmp_path, "noceil.obj", obj_text(parts)))
    (room,) = scene.rooms
    assert (room.floor_z, room.ceiling_z) == (0.5, pytest.approx(3.2))


def test_footprint_polygon_keeps_largest_piece_ccw():
    big = [[(0, 0), (4, 0), (4, 4)], [(0, 0), (4, 4), (0, 4)]]
    small = [[(10, 0), (10, 1), (11, 0)]]  # clockwise on purpose
    poly = footprint_polygon(np.array(big + small, float))
    assert len(poly) == 4
    assert shapely_area_signed(poly) == pytest.approx(16.0)
    assert footprint_polygon(np.zeros((0, 3, 2))) is None
    assert footprint_polygon(np.array([[(0, 0, 0), (0, 0, 1), (0, 0, 2)]], float)) is None


def shapely_area_signed(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


# ------------------------------------------------------------------------------------ y_up
def test_y_up_rotates_to_z_up(tmp_path):
    # Write the room as a y-up tool would: (x, y, z)_zup -> (x, z, -y)_yup.
    def to_y_up(v):
        v = np.asarray(v, float)
        return np.column_stack([v[:, 0], v[:, 2], -v[:, 1]])

    p = write(tmp_path, "yup.obj", obj_text(box_room(), transform=to_y_up))
    scene = load_mesh_scene(p, y_up=True)
    assert np.allclose(scene.bounds, [[0, 0, 0], [4, 3, 2.5]])
    assert_areas(scene, box_areas())
    floor = scene.face_labels == F
    # The floor faces face up after the rotation, as they did before it.
    assert np.all(scene.mesh.face_normals[floor][:, 2] > 0.99)
    # Without the flag the room lies on its side: the floor is vertical.
    flat = load_mesh_scene(p)
    assert np.allclose(flat.bounds, [[0, 0, -3], [4, 2.5, 0]])


# ----------------------------------------------------------------------------------- glTF/GLB
def test_glb_applies_node_transforms_and_name_fallbacks(tmp_path):
    parts = box_room()
    moved = trimesh.Scene()
    shift = trimesh.transformations.translation_matrix([10.0, -5.0, 1.0])
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])
    moved.add_geometry(trimesh.Trimesh(), node_name="clutter_things")  # an empty labelled parent
    for i, (name, mesh) in enumerate(parts.items()):
        if name == "wall_e":  # label from the mesh name, node name unlabelled
            moved.add_geometry(mesh, node_name="Node_7", geom_name=name, transform=shift @ turn)
        elif name == "clutter_box":  # label from the parent node
            moved.add_geometry(
                mesh,
                node_name="Box",
                geom_name="Cube.002",
                parent_node_name="clutter_things",
                transform=shift,
            )
        else:
            moved.add_geometry(mesh, node_name=name, geom_name=f"mesh{i}", transform=shift @ turn)
    lamp = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    moved.add_geometry(lamp, node_name="Lamp", geom_name="Cube.003")
    p = tmp_path / "moved.glb"
    moved.export(p)
    with pytest.warns(UnlabelledPartsWarning) as record:
        scene = load_mesh_scene(p)
    assert [w.message.names for w in record if w.category is UnlabelledPartsWarning] == [("Lamp",)]
    expected = box_areas()
    expected[CL] += 1.5
    assert_areas(scene, expected)
    # The room rotated by 90 degrees about z and shifted: x in [10 - 3, 10], y in [-5, -1].
    struct = scene.structural_mask()
    lo = scene.mesh.vertices[scene.mesh.faces[struct]].reshape(-1, 3).min(axis=0)
    hi = scene.mesh.vertices[scene.mesh.faces[struct]].reshape(-1, 3).max(axis=0)
    assert np.allclose(lo, [7, -5, 1]) and np.allclose(hi, [10, -1, 3.5])
    box = (scene.face_labels == CL) & (scene.mesh.triangles_center[:, 0] > 5)
    assert np.allclose(scene.mesh.vertices[scene.mesh.faces[box]].reshape(-1, 3).min(axis=0), [10.5, -4.5, 1])


def test_glb_room_from_parent_node(tmp_path):
    sc = trimesh.Scene()
    sc.add_geometry(trimesh.Trimesh(), node_name="room4")
    for name, mesh in box_room().items():
        sc.add_geometry(mesh, node_name=f"{name}_x", geom_name=name, parent_node_name="room4")
    p = tmp_path / "parent.glb"
    sc.export(p)
    scene = load_mesh_scene(p)
    assert [r.name for r in scene.rooms] == ["room4"]
    assert scene.rooms[0].area == pytest.approx(12.0)
    assert np.all(scene.face_rooms == 0)


# ------------------------------------------------------------------------------------------ PLY
def test_ply_label_and_room_properties(tmp_path):
    meshes = list(box_room().values())
    labels = [F, C, W, W, W, W, CL]
    merged = trimesh.util.concatenate(meshes)
    merged.face_attributes["label"] = np.concatenate(
        [np.full(len(m.faces), lab, np.int32) for m, lab in zip(meshes, labels, strict=True)]
    )
    merged.face_attributes["room"] = np.where(merged.face_attributes["label"] == CL, -1, 6).astype(np.int32)
    for encoding in ("binary", "ascii"):
        p = tmp_path / f"labelled_{encoding}.ply"
        merged.export(p, encoding=encoding, include_attributes=True)
        scene = load_mesh_scene(p)
        assert_areas(scene, box_areas())
        assert [r.name for r in scene.rooms] == ["room6"]
        assert np.array_equal(scene.face_rooms, np.where(scene.face_labels == CL, -1, 0))


def test_ply_mixed_polygons_keep_their_labels(tmp_path):
    # trimesh reorders triangles before quads; the loader must keep each label with its face.
    text = (
        "ply\nformat ascii 1.0\nelement vertex 7\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 3\nproperty list uchar int vertex_indices\nproperty uchar label\nend_header\n"
        "0 0 0\n2 0 0\n2 2 0\n0 2 0\n0 0 1\n2 0 1\n0 0 3\n"
        "4 0 1 2 3 0\n3 0 1 5 2\n3 0 5 6 1\n"
    )
    scene = load_mesh_scene(write(tmp_path, "quad.ply", text))
    assert list(scene.face_labels) == [F, F, W, C]
    assert scene.class_areas()[F] == pytest.approx(4.0)
    assert scene.class_areas()[W] == pytest.approx(1.0)


def test_ply_without_label_property_reports_missing_structure(tmp_path):
    p = tmp_path / "plain.ply"
    trimesh.creation.box().export(p)
    with pytest.raises(MissingStructureError, match="label"):
        load_mesh_scene(p)


def test_ply_label_outside_surface_classes(tmp_path):
    m = trimesh.creation.box()
    m.face_attributes["label"] = np.full(12, 9, np.int32)
    p = tmp_path / "bad_label.ply"
    m.export(p, include_attributes=True)
    with pytest.raises(InvalidMeshError, match=r"bad_label\.ply.*\[9\]"):
        load_mesh_scene(p)


def test_ascii_ply_whose_face_lines_do_not_match_the_header(tmp_path):
    """The label on the next line: trimesh reads no 'label' (once a KeyError from inside the loader)."""
    p = tmp_path / "split.ply"
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    faces = "element face 1\nproperty list uchar int vertex_indices\nproperty uchar label\nend_header\n"
    p.write_text(header + faces + "0 0 0\n1 0 0\n0 1 0\n3 0 1 99\n0\n")
    with pytest.raises(
        InvalidMeshError, match=r"split\.ply.*declares 3 vertex and 1 face records, 4 lines, but the body holds 5"
    ):
        load_mesh_scene(p)


# ------------------------------------------------------------------------------------ round trip
@pytest.mark.parametrize("ext", [".obj", ".glb", ".ply"])
def test_round_trip(tmp_path, ext):
    original = load_mesh_scene(write(tmp_path, "src.obj", obj_text(two_room_parts())))
    out = tmp_path / f"copy{ext}"
    export_scene(original, out)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_mesh_scene(out)
    assert_areas(loaded, original.class_areas())
    # Files store room ids, so the rooms come back named after their ids.
    assert [r.name for r in original.rooms] == ["room0", "room3"]
    assert [r.name for r in loaded.rooms] == ["room0", "room1"]
    for a, b in zip(loaded.rooms, original.rooms, strict=True):
        assert a.id == b.id
        assert a.area == pytest.approx(b.area, rel=1e-6)
        assert a.floor_z == pytest.approx(b.floor_z, abs=1e-6)
        assert a.ceiling_z == pytest.approx(b.ceiling_z, abs=1e-6)
    for room in (-1, 0, 1):
        assert loaded.face_areas[loaded.face_rooms == room].sum() == pytest.approx(
            original.face_areas[original.face_rooms == room].sum(), rel=1e-6
        )
        for cls in SurfaceClass:
            sel_a = (loaded.face_rooms == room) & (loaded.face_labels == cls)
            sel_b = (original.face_rooms == room) & (original.face_labels == cls)
            assert loaded.face_areas[sel_a].sum() == pytest.approx(original.face_areas[sel_b].sum(), rel=1e-6)


def test_export_part_names(tmp_path):
    scene = load_mesh_scene(write(tmp_path, "src.obj", obj_text(two_room_parts())))
    out = tmp_path / "named.obj"
    export_scene(scene, out)
    names = [line[2:] for line in out.read_text().splitlines() if line.startswith("o ")]
    assert names == [
        "floor_room0", "floor_room1", "ceiling_room0", "ceiling_room1", "wall_room0", "wall_room1",
        "door", "clutter", "clutter_room1",
    ]  # fmt: skip


def test_export_scene_built_in_memory(tmp_path):
    parts = box_room()
    mesh = trimesh.util.concatenate(list(parts.values()))
    labels = np.concatenate([np.full(len(m.faces), parse_part_name(n)[0], np.uint8) for n, m in parts.items()])
    rooms = np.where(labels == CL, -1, 0)
    room = Room(0, "kitchen", np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float), 0.0, 2.5)
    scene = Scene(mesh, labels, rooms, rooms=[room], name="mem")
    out = tmp_path / "mem.glb"
    export_scene(scene, out)
    back = load_mesh_scene(out)
    assert_areas(back, box_areas())
    assert back.rooms[0].area == pytest.approx(room.area)
    assert np.array_equal(back.face_rooms[back.face_labels == F], [0, 0])


def test_export_unsupported_extension(tmp_path):
    scene = load_mesh_scene(write(tmp_path, "src.obj", obj_text(box_room())))
    with pytest.raises(UnsupportedFormatError, match=r"x\.stl.*\.obj.*\.glb.*\.ply"):
        export_scene(scene, tmp_path / "x.stl")


def test_export_to_missing_directory(tmp_path):
    scene = load_mesh_scene(write(tmp_path, "src.obj", obj_text(box_room())))
    with pytest.raises(SceneFileError, match="nowhere"):
        export_scene(scene, tmp_path / "nowhere" / "x.obj")


# ----------------------------------------------------------------------------------------- errors
def test_missing_file(tmp_path):
    p = tmp_path / "absent.obj"
    with pytest.raises(SceneFileError, match=r"absent\.obj: no such file"):
        load_mesh_scene(p)


def test_unsupported_extension(tmp_path):
    p = write(tmp_path, "room.stl", "solid x\nendsolid x\n")
    with pytest.raises(UnsupportedFormatError) as info:
        load_mesh_scene(p)
    message = str(info.value)
    assert "room.stl" in message
    for ext in (".obj", ".glb", ".gltf", ".ply"):
        assert ext in message


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb"])
def test_empty_mesh(tmp_path, ext):
    if ext == ".obj":
        p = write(tmp_path, "empty.obj", "# nothing here\no wall\nv 0 0 0\n")
    elif ext == ".ply":
        p = write(
            tmp_path,
            "empty.ply",
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
            "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
        )
    else:
        p = tmp_path / "empty.glb"
        sc = trimesh.Scene()
        sc.add_geometry(trimesh.load_path(np.array([[0, 0, 0], [1, 0, 0]], float)), node_name="wall")
        sc.export(p)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # The glb's one part is a line: the refusal says so (not "empty", which the file is not).
        reason = "every part is drawn as points or lines" if ext == ".glb" else "empty"
        with pytest.raises(InvalidMeshError, match=rf"empty{ext}: .*{reason}"):
            load_mesh_scene(p)
    assert not caught


@pytest.mark.parametrize("ext", [".obj", ".glb", ".ply"])
def test_nan_vertex(tmp_path, ext):
    parts = box_room()
    bad = parts["wall_n"].vertices.copy()
    bad[2, 2] = np.nan
    parts["wall_n"] = trimesh.Trimesh(bad, parts["wall_n"].faces, process=False)
    if ext == ".obj":
        p = write(tmp_path, "nan.obj", obj_text(parts))
        assert "nan" in p.read_text()
    elif ext == ".glb":
        p = tmp_path / "nan.glb"
        sc = trimesh.Scene()
        for name, m in parts.items():
            sc.add_geometry(m, node_name=name, geom_name=name)
        sc.export(p)
    else:
        p = tmp_path / "nan.ply"
        merged = trimesh.util.concatenate(list(parts.values()))
        merged.face_attributes["label"] = np.zeros(len(merged.faces), np.int32)
        merged.export(p, include_attributes=True)
    with pytest.raises(InvalidMeshError, match=rf"nan{ext}: 1 of \d+ vertices are NaN or infinite"):
        load_mesh_scene(p)


def test_infinite_vertex_in_obj(tmp_path):
    text = obj_text(box_room()).replace("v 0 0 0\n", "v 0 0 inf\n", 1)
    with pytest.raises(InvalidMeshError, match="NaN or infinite"):
        load_mesh_scene(write(tmp_path, "inf.obj", text))


@pytest.mark.parametrize(("drop", "missing"), [("floor", "floor"), ("wall_", "wall")])
def test_missing_structure(tmp_path, drop, missing):
    parts = {k: m for k, m in box_room().items() if not k.startswith(drop)}
    p = write(tmp_path, f"no_{missing}.obj", obj_text(parts))
    with pytest.raises(MissingStructureError, match=rf"no_{missing}\.obj: the mesh has no {missing} faces"):
        load_mesh_scene(p, name="some other name")


@pytest.mark.parametrize("ext", [".obj", ".glb", ".gltf", ".ply"])
def test_garbage_bytes(tmp_path, ext):
    p = tmp_path / f"garbage{ext}"
    p.write_bytes(np.random.default_rng(7).bytes(2048))
    with pytest.raises(InvalidMeshError, match=rf"garbage{ext}"):
        load_mesh_scene(p)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\no floor\nf 1 2 9\n", "refer to vertex 9 .*outside 1..3"),
        ("v 0 0 zero\nf 1 1 1\n", "line 1: a vertex has a coordinate that is no ASCII number"),
        ("v 0 0 0\no floor\nf 1 2\n", "line 3: a face needs 3"),
        ("v 0 0 0\no floor\nf 0 1 1\n", "start at 1"),
        # Beyond an int64 (it was an OverflowError) and before the first vertex: the line is named.
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\no floor\nf 1 2 99999999999999999999\n", "line 5: vertex index 9{20} refers to no"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\no floor\nf 1 2 -9\n", "line 5: vertex index -9 refers to no vertex"),
        ("v 0 0\n", "line 1: a vertex needs"),
    ],
)
def test_malformed_obj(tmp_path, text, match):
    with pytest.raises(InvalidMeshError, match=match):
        load_mesh_scene(write(tmp_path, "bad.obj", text))


def test_errors_are_scene_errors():
    for cls in (SceneFileError, UnsupportedFormatError, InvalidMeshError, MissingStructureError, StoreySizeError):
        assert issubclass(cls, SceneError)


@pytest.mark.parametrize(("ext", "exact"), [(".obj", True), (".ply", True), (".glb", False)])
def test_export_keeps_large_coordinates(tmp_path, ext, exact):
    # Georeferenced models sit far from the origin; float32 would move them by centimetres.
    parts = {k: m.copy() for k, m in box_room().items()}
    for m in parts.values():
        m.apply_translation((512345.678, 5412345.678, 0.0))
    original = load_mesh_scene(write(tmp_path, "geo.obj", obj_text(parts)))
    export_scene(original, tmp_path / f"geo_copy{ext}")
    loaded = load_mesh_scene(tmp_path / f"geo_copy{ext}")
    if exact:
        assert np.array_equal(loaded.mesh.triangles, original.mesh.triangles)
    else:
        # GLB lists its parts by node name and stores float32 (0.5 m steps at 5e6 m).
        def ordered(tris):
            flat = tris.reshape(len(tris), -1)
            return flat[np.lexsort(flat.T[::-1])]

        assert np.allclose(ordered(loaded.mesh.triangles), ordered(original.mesh.triangles), atol=0.5)
        assert not np.array_equal(ordered(loaded.mesh.triangles), ordered(original.mesh.triangles))


# ------------------------------------------------------------------- units and the largest storey
def room_in(unit_per_metre: float) -> dict[str, trimesh.Trimesh]:
    """A 10 m x 8 m x 2.5 m room drawn in a unit with ``unit_per_metre`` units to the metre."""
    parts = box_room(0.0, 10.0, 0.0, 8.0, h=2.5)
    for m in parts.values():
        m.apply_scale(unit_per_metre)
    return parts


def glb_of(parts: dict[str, trimesh.Trimesh], path: Path, transforms: dict[str, np.ndarray] | None = None) -> Path:
    sc = trimesh.Scene()
    for name, mesh in parts.items():
        sc.add_geometry(mesh, node_name=name, geom_name=name, transform=(transforms or {}).get(name))
    sc.export(path)
    return path


@pytest.mark.parametrize(("unit", "per_metre"), [("mm", 1000.0), ("cm", 100.0), ("in", 1 / 0.0254), ("ft", 1 / 0.3048)])
@pytest.mark.parametrize("ext", [".obj", ".glb"])
def test_units_scale_the_file_to_the_metre_one(tmp_path, unit, per_metre, ext):
    from scenes import load_scene

    def saved(name, parts):
        return (
            write(tmp_path, name + ".obj", obj_text(parts))
            if ext == ".obj"
            else glb_of(parts, tmp_path / f"{name}.glb")
        )

    metres = load_mesh_scene(saved("m", room_in(1.0)))
    scaled = load_scene(str(saved(unit, room_in(per_metre))), units=unit)
    assert np.allclose(scaled.mesh.vertices, metres.mesh.vertices, atol=1e-5)
    assert scaled.structural_area() == pytest.approx(metres.structural_area(), rel=1e-6)
    assert [r.area for r in scaled.rooms] == pytest.approx([r.area for r in metres.rooms], rel=1e-6)


@pytest.mark.parametrize(
    ("per_metre", "across", "word", "unit"),
    [
        (1000.0, "10,000", "millimetres", "mm"),
        (100.0, "1,000", "centimetres", "cm"),
        (1 / 0.0254, "394", "inches", "in"),
    ],
)
@pytest.mark.parametrize("ext", [".obj", ".glb"])
def test_a_storey_in_another_unit_read_as_metres_is_refused_naming_the_unit(
    tmp_path, per_metre, across, word, unit, ext
):
    # Read as metres, a millimetre storey once made later stages ask for 381 GiB.
    p = tmp_path / f"room{ext}"
    if ext == ".obj":
        p.write_text(obj_text(room_in(per_metre)))
    else:
        glb_of(room_in(per_metre), p)
    with pytest.raises(
        StoreySizeError,
        match=rf"room{ext}: the storey is {across} m across .* is the file in {word}\? pass --units {unit} ",
    ):
        load_mesh_scene(p)


@pytest.mark.parametrize("ext", [".obj", ".glb"])
def test_coordinates_beyond_any_storey_are_refused_before_the_room_outlines(tmp_path, ext):
    # 1e300 is finite: it once reached shapely, which failed deep inside (or loaded a storey 1e300 m wide).
    if ext == ".obj":
        p = write(tmp_path, "far.obj", obj_text(box_room()).replace("v 0 0 0\n", "v 1e300 0 0\n", 1))
    else:
        far = np.eye(4)
        far[0, 3] = 1e300
        p = glb_of(box_room(), tmp_path / "far.glb", {"wall_n": far})
    with pytest.raises(StoreySizeError, match=rf"far{ext}: the storey is 1e\+300 m across .*coordinates broken"):
        load_mesh_scene(p)


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_more_faces_than_the_limit_are_refused(tmp_path, monkeypatch, ext):
    import scenes.limits

    monkeypatch.setattr(scenes.limits, "MAX_FACES", 20)  # the box room has 24
    if ext == ".obj":
        p = write(tmp_path, "many.obj", obj_text(box_room()))
    else:
        p = tmp_path / "many.ply"
        merged = trimesh.util.concatenate(list(box_room().values()))
        merged.face_attributes["label"] = np.full(len(merged.faces), int(W), np.int32)
        merged.export(p, include_attributes=True)
    with pytest.raises(StoreySizeError, match=rf"many{ext}: the mesh has 24 faces \(the most nbs-env loads is 20\)"):
        load_mesh_scene(p)


PLY_LIAR_HEADER = (
    "ply\nformat {encoding} 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2000000000\nproperty list uchar int vertex_indices\nproperty uchar label\nend_header\n"
)


@pytest.mark.parametrize("encoding", ["binary_little_endian", "ascii"])
def test_ply_header_declaring_more_than_the_file_holds(tmp_path, encoding):
    # 2e9 faces in 960 bytes: the counts are checked against the bytes before trimesh allocates.
    header = PLY_LIAR_HEADER.format(encoding=encoding).encode()
    p = tmp_path / "liar.ply"
    p.write_bytes(header + b"0 0 0\n" * ((960 - len(header)) // 6))
    with pytest.raises(
        InvalidMeshError,
        match=r"liar\.ply: the PLY header declares 8 vertex and 2,000,000,000 face records, .*truncated",
    ):
        load_mesh_scene(p)


def _edit_glb(data: bytes, edit) -> bytes:
    """A GLB with its JSON chunk edited by ``edit(document)``, the lengths rewritten to match."""
    import json
    import struct

    (json_length,) = struct.unpack_from("<I", data, 12)
    document = json.loads(data[20 : 20 + json_length])
    text = edit(document) if callable(edit) else None
    raw = (text if isinstance(text, str) else json.dumps(document)).encode()
    raw += b" " * (-len(raw) % 4)
    body = struct.pack("<II", len(raw), 0x4E4F534A) + raw + data[20 + json_length :]
    return data[:8] + struct.pack("<I", 12 + len(body)) + body


def _without_view(document):
    del document["accessors"][0]["bufferView"]
    document["accessors"][0]["count"] = 10**10


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (
            lambda d: d["buffers"][0].update(byteLength=10**12),
            r"buffers\[0\]\.byteLength declares 1,000,000,000,000 bytes",
        ),
        (lambda d: d["bufferViews"][0].update(byteLength=10**12), r"bufferViews\[0\] ends at byte 1,000,000,000,000"),
        (lambda d: d["accessors"][0].update(count=10**10), r"accessors\[0\] declares 10,000,000,000 elements, which"),
        (_without_view, r"accessors\[0\]\.count declares 10,000,000,000 elements with no bufferView"),
        (lambda d: d["accessors"][0].update(count=-1), r"accessors\[0\]\.count must be an integer >= 0"),
        (lambda d: json_nested(5000), r"invalid glTF JSON: nested deeper than 64 levels"),
        (lambda d: d["nodes"][0].update(children=[0]), r"the glTF nodes' children form a cycle"),
        (lambda d: d["nodes"][0].update(children=[99]), r"nodes\[0\]\.children must name nodes"),
        (
            lambda d: d["buffers"].append({"byteLength": 6 << 30, "uri": "big.bin"}),
            r"buffers\[1\]\.byteLength brings the buffers to [\d,]+ bytes; at most 2,147,483,648",
        ),
    ],
    ids=[
        "buffer",
        "view",
        "accessor",
        "accessor-without-data",
        "negative-count",
        "deep-json",
        "node-cycle",
        "node-index",
        "huge-buffers",
    ],
)
def test_glb_declaring_more_than_it_holds(tmp_path, edit, match):
    # An accessor of 1e10 elements without data once made trimesh allocate 37 GiB of zeros.
    p = tmp_path / "liar.glb"
    p.write_bytes(_edit_glb(glb_of(box_room(), tmp_path / "ok.glb").read_bytes(), edit))
    with pytest.raises(InvalidMeshError, match=rf"liar\.glb: {match}"):
        load_mesh_scene(p)


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="needs fifos")
@pytest.mark.parametrize("kind", ["buffers", "images"])
def test_gltf_side_files_must_be_regular_files(tmp_path, kind):
    """A buffer or image uri naming a fifo once hung the parser."""
    import json
    import os

    os.mkfifo(tmp_path / "fifo.bin")
    document = {"asset": {"version": "2.0"}, kind: [{"uri": "fifo.bin", "byteLength": 4}]}
    (tmp_path / "m.gltf").write_text(json.dumps(document))
    with pytest.raises(InvalidMeshError, match=rf"{kind}\[0\]\.uri 'fifo.bin' is not a regular file"):
        load_mesh_scene(tmp_path / "m.gltf")


def json_nested(depth: int) -> str:
    return '{"asset": {"version": "2.0"}, "extras": ' + "[" * depth + "]" * depth + "}"


def test_glb_and_gltf_lengths_are_checked_against_the_file(tmp_path):
    import json
    import struct

    data = glb_of(box_room(), tmp_path / "ok.glb").read_bytes()
    truncated = tmp_path / "truncated.glb"
    truncated.write_bytes(data[:-100])
    with pytest.raises(InvalidMeshError, match=rf"the GLB header declares {len(data):,} bytes, but the file has"):
        load_mesh_scene(truncated)
    chunk = tmp_path / "chunk.glb"
    chunk.write_bytes(data[:12] + struct.pack("<I", 10**9) + data[16:])
    with pytest.raises(InvalidMeshError, match="GLB chunk 0 declares 1,000,000,000 bytes"):
        load_mesh_scene(chunk)
    # A .gltf and its side file: the buffer may not claim more than the side file holds.
    sc = trimesh.Scene()
    for name, mesh in box_room().items():
        sc.add_geometry(mesh, node_name=name, geom_name=name)
    files = sc.export(file_type="gltf")
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
    gltf = tmp_path / "model.gltf"
    assert load_mesh_scene(gltf).structural_area() == pytest.approx(box_areas()[F] * 2 + box_areas()[W])
    document = json.loads(gltf.read_text())
    document["buffers"][0]["byteLength"] = 10**12
    gltf.write_text(json.dumps(document))
    with pytest.raises(InvalidMeshError, match=r"model\.gltf: buffers\[0\]\.byteLength declares 1,000,000,000,000"):
        load_mesh_scene(gltf)
