"""The Scene model: checks on entry, areas, and the ground-truth samples for the coverage metric."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from scenes import InvalidMeshError, MissingStructureError, Scene, SurfaceClass, load_scene


def box_room(size=(4.0, 3.0, 2.5)) -> tuple[trimesh.Trimesh, np.ndarray]:
    """An inward box: 2 floor, 2 ceiling and 8 wall triangles."""
    mesh = trimesh.creation.box(extents=size, transform=trimesh.transformations.translation_matrix(np.array(size) / 2))
    mesh.invert()
    n = mesh.face_normals
    labels = np.where(
        n[:, 2] > 0.5, SurfaceClass.FLOOR, np.where(n[:, 2] < -0.5, SurfaceClass.CEILING, SurfaceClass.WALL)
    )
    return mesh, labels.astype(np.uint8)


def test_surface_classes_and_structural_flag():
    assert [c.name for c in SurfaceClass] == ["FLOOR", "CEILING", "WALL", "DOOR", "WINDOW", "CLUTTER"]
    assert {c for c in SurfaceClass if c.is_structural} == {SurfaceClass.FLOOR, SurfaceClass.CEILING, SurfaceClass.WALL}


def test_class_and_structural_areas_of_a_box():
    mesh, labels = box_room((4.0, 3.0, 2.5))
    scene = Scene(mesh, labels)
    areas = scene.class_areas()
    assert areas[SurfaceClass.FLOOR] == pytest.approx(12.0)
    assert areas[SurfaceClass.CEILING] == pytest.approx(12.0)
    assert areas[SurfaceClass.WALL] == pytest.approx(2 * (4 + 3) * 2.5)
    assert scene.structural_area() == pytest.approx(24 + 35)
    assert scene.face_labels.dtype == np.uint8 and scene.face_rooms.tolist() == [-1] * len(mesh.faces)


def test_structure_samples_are_deterministic_uniform_and_on_se_faces():
    scene = load_scene("office")
    a, b = scene.structure_samples(), scene.structure_samples()
    assert np.array_equal(a.points, b.points)
    # About one sample per 25 cm² of structural surface.
    assert len(a) == pytest.approx(scene.structural_area() / 0.0025, abs=1)
    assert set(np.unique(a.labels)) == {SurfaceClass.FLOOR, SurfaceClass.CEILING, SurfaceClass.WALL}
    assert np.all(np.isin(scene.face_labels[a.faces], [0, 1, 2]))
    # Every sample lies on its face: distance to the face plane ~ 0 and inside the triangle.
    tri = scene.mesh.vertices[scene.mesh.faces[a.faces]]
    bary = trimesh.triangles.points_to_barycentric(tri, a.points)
    assert np.all(bary > -1e-9) and np.all(bary < 1 + 1e-9)
    # Per class, the share of samples matches the share of area (uniform density).
    areas = scene.class_areas()
    for cls in (SurfaceClass.FLOOR, SurfaceClass.WALL):
        share = np.mean(a.labels == cls)
        assert share == pytest.approx(areas[cls] / scene.structural_area(), abs=0.002)
    # Uniform within a big face: samples on the floor fill a 1 m grid evenly.
    floor = a.points[a.labels == SurfaceClass.FLOOR]
    counts, _, _ = np.histogram2d(floor[:, 0], floor[:, 1], bins=[np.arange(1, 6), np.arange(1, 4)])
    assert counts.min() > 0.85 * 400 and counts.max() < 1.15 * 400
    # Coarser spacing gives proportionally fewer samples.
    assert len(scene.structure_samples(0.1)) == pytest.approx(len(a) / 4, rel=0.01)


def test_structure_samples_rejects_bad_spacing():
    with pytest.raises(ValueError, match="spacing"):
        load_scene("office").structure_samples(0.0)


def test_empty_mesh_is_rejected():
    with pytest.raises(InvalidMeshError, match="empty"):
        Scene(trimesh.Trimesh(), np.zeros(0, dtype=np.uint8), name="empty.obj")


def test_nan_vertices_are_rejected():
    mesh, labels = box_room()
    mesh.vertices[3] = [np.nan, 0, 0]
    with pytest.raises(InvalidMeshError, match="NaN or infinite") as info:
        Scene(mesh, labels, name="bad.obj")
    assert "bad.obj" in str(info.value)


def test_label_shape_mismatch_is_rejected():
    mesh, labels = box_room()
    with pytest.raises(InvalidMeshError, match="face_labels has shape"):
        Scene(mesh, labels[:-1])
    with pytest.raises(InvalidMeshError, match="no SurfaceClass"):
        Scene(mesh, np.full(len(labels), 9))


@pytest.mark.parametrize("missing", [SurfaceClass.FLOOR, SurfaceClass.WALL])
def test_scene_without_floor_or_walls_is_rejected(missing):
    mesh, labels = box_room()
    labels = labels.copy()
    labels[labels == missing] = SurfaceClass.CLUTTER
    with pytest.raises(MissingStructureError, match=f"no {missing.name.lower()} faces"):
        Scene(mesh, labels, name="box.obj")


def test_auto_start_is_free_and_inside_largest_room():
    from shapely.geometry import Point, Polygon

    from scenes.geometry import STOREY_CLEARANCE, point_is_free

    scene = load_scene("office")  # its plan has no start
    start = scene.start
    assert Polygon(scene.rooms[0].polygon).contains(Point(start[:2]))
    assert point_is_free(scene, start[:2], 0.0, STOREY_CLEARANCE)
    # "Well inside": clearly more than the bare clearance from every obstacle.
    assert point_is_free(scene, start[:2], 0.0, clearance=STOREY_CLEARANCE + 0.3)


def test_start_override():
    scene = load_scene("office", start=(5.0, 1.0))
    assert scene.start.tolist() == [5.0, 1.0, 0.0]
    with pytest.raises(InvalidMeshError, match="start"):
        scene.start = (np.nan, 1.0)
