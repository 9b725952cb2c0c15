"""Tests of scenes.ifc: IFC storeys as labelled scenes (FZK-Haus and tiny generated models)."""

from __future__ import annotations

import sys
from pathlib import Path

import ifcopenshell
import ifcopenshell.api
import numpy as np
import pytest
import shapely
from ifcopenshell.api import aggregate, geometry, root, spatial
from shapely.geometry import Polygon

from scenes.corpus import corpus_entry
from scenes.errors import IfcError, MissingDependencyError, MissingStructureError, SceneFileError
from scenes.ifc import DEFAULT_CLASS_MAP, load_ifc_scene
from scenes.interior import interior_area, interior_samples
from scenes.model import Scene, SurfaceClass
from tests.data.make_two_rooms_ifc import matrix, new_building

DATA = Path(__file__).parent / "data"
FZK = corpus_entry("fzk_haus_eg").path()
F, C, W, D, WIN, CL = (
    SurfaceClass.FLOOR,
    SurfaceClass.CEILING,
    SurfaceClass.WALL,
    SurfaceClass.DOOR,
    SurfaceClass.WINDOW,
    SurfaceClass.CLUTTER,
)
GROUND_ROOMS = {"Schlafzimmer", "Bad", "Buero", "Wohnen", "Flur", "Küche"}


@pytest.fixture(scope="module")
def ground() -> Scene:
    return load_ifc_scene(FZK)


def signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


# ------------------------------------------------------------------------------------ FZK-Haus
def test_default_storey_is_the_ground_floor(ground):
    assert ground.metadata["storey"] == "Erdgeschoss"
    assert ground.metadata["storey_index"] == 0
    assert ground.metadata["elevation"] == pytest.approx(0.0)
    assert ground.metadata["height"] == pytest.approx(2.7)
    assert ground.metadata["source"] == str(FZK)
    areas = ground.class_areas()
    for cls in (F, C, W, D, WIN):
        assert areas[cls] > 0, cls
    # The 12 x 10 x 0.2 m base slab is the floor: top, bottom and edges.
    assert areas[F] == pytest.approx(2 * 120 + 44 * 0.2, rel=1e-3)
    assert areas[W] == pytest.approx(359.6, rel=0.02)
    # The spiral stair is clutter.
    assert areas[CL] > 1.0
    assert np.all(np.isfinite(ground.mesh.vertices))
    assert ground.bounds[0, 2] == pytest.approx(-0.2, abs=1e-6)  # bottom of the base slab


def test_ground_floor_by_name_matches_default(ground):
    by_name = load_ifc_scene(FZK, storey="Erdgeschoss", name="eg")
    assert by_name.name == "eg"
    assert by_name.metadata["storey"] == "Erdgeschoss"
    assert len(by_name.mesh.faces) == len(ground.mesh.faces)
    for cls, area in ground.class_areas().items():
        assert by_name.class_areas()[cls] == pytest.approx(area, rel=1e-9)
    assert np.array_equal(by_name.face_labels, ground.face_labels)
    assert np.array_equal(by_name.face_rooms, ground.face_rooms)


def test_ground_floor_ceiling_is_the_slab_above(ground):
    # Slab-033 belongs to the upper storey; its underside at 2.5 m closes the ground floor rooms.
    normals = ground.mesh.face_normals
    centres = ground.mesh.triangles_center
    underside = (ground.face_labels == C) & (normals[:, 2] < -0.99) & np.isclose(centres[:, 2], 2.5)
    assert ground.face_areas[underside].sum() > 80
    assert np.all(ground.face_rooms[underside & (ground.face_rooms >= 0)] >= 0)
    assert ground.face_areas[underside & (ground.face_rooms >= 0)].sum() > 60
    # No ceiling below the top of the storey's walls.
    assert centres[ground.face_labels == C][:, 2].min() >= 2.26 - 1e-6  # the downstand beam


def test_ground_floor_rooms(ground):
    names = [r.name for r in ground.rooms]
    assert set(names) == GROUND_ROOMS
    assert [r.id for r in ground.rooms] == list(range(6))
    areas = {r.name: r.area for r in ground.rooms}
    assert areas["Flur"] == pytest.approx(11.53, rel=0.01)
    assert areas["Wohnen"] == pytest.approx(25.99, rel=0.01)
    assert sum(areas.values()) == pytest.approx(101.4, rel=0.01)
    for room in ground.rooms:
        assert signed_area(room.polygon) > 0  # counter-clockwise
        assert not np.allclose(room.polygon[0], room.polygon[-1])
        assert room.floor_z == pytest.approx(0.0, abs=1e-6)
        assert room.ceiling_z == pytest.approx(2.5, abs=1e-6)
    assert len(ground.room_by_name("Flur").polygon) == 6  # L-shaped hall


def test_ground_floor_face_rooms(ground):
    normals = ground.mesh.face_normals
    labels, rooms, areas = ground.face_labels, ground.face_rooms, ground.face_areas
    for room in ground.rooms:
        mine = rooms == room.id
        floor = areas[mine & (labels == F)].sum()
        assert floor == pytest.approx(room.area, rel=0.2), room.name
        assert areas[mine & (labels == W)].sum() > 20, room.name
        assert areas[mine & (labels == C)].sum() > 5, room.name
        # A room sees its floor from above and its ceiling (slab underside, beam and the edges of the
        # stair opening) from below or the side, never the top of a slab.
        assert np.all(normals[mine & (labels == F)][:, 2] > 0.99)
        assert np.all(normals[mine & (labels == C)][:, 2] < 0.01)
        assert areas[mine & (labels == C) & (normals[:, 2] < -0.99)].sum() > 5
    # The underside of the base slab and the outside of the exterior walls belong to no room.
    assert np.all(rooms[(labels == F) & (normals[:, 2] < -0.99)] == -1)
    centres = ground.mesh.triangles_center
    outer = (labels == W) & (np.abs(centres[:, 0]) < 1e-6) & (normals[:, 0] < -0.99)
    assert outer.any() and np.all(rooms[outer] == -1)


def test_ground_floor_doors(ground):
    assert len(ground.doors) == 5
    by_id = {r.id: r.name for r in ground.rooms}
    by_id[-1] = "outside"
    pairs = {tuple(sorted(by_id[i] for i in d.rooms)) for d in ground.doors}
    assert pairs == {
        ("Flur", "Schlafzimmer"),
        ("Bad", "Flur"),
        ("Buero", "Flur"),
        ("Flur", "outside"),
        ("Wohnen", "outside"),
    }
    assert sorted(round(d.width, 3) for d in ground.doors) == [0.885, 0.885, 0.885, 1.01, 2.01]
    for door in ground.doors:
        assert np.linalg.norm(door.normal) == pytest.approx(1.0)
        assert min(abs(door.normal)) == pytest.approx(0.0, abs=1e-9)  # FZK's doors are axis-aligned
        assert door.position[2] == pytest.approx(0.0, abs=1e-6)
        assert door.height == pytest.approx(2.375 if door.width > 2 else 2.01)
        # The normal points from rooms[0] to rooms[1].
        a, b = door.rooms
        ahead = door.position[:2] + 0.6 * door.normal
        behind = door.position[:2] - 0.6 * door.normal
        if b >= 0:
            assert _inside(ground.rooms[b].polygon, ahead)
        assert _inside(ground.rooms[a].polygon, behind)


def _inside(polygon: np.ndarray, point: np.ndarray) -> bool:
    import shapely

    return bool(shapely.contains_xy(shapely.Polygon(polygon), *point))


def test_upper_storey_by_index():
    upper = load_ifc_scene(FZK, storey=1)
    assert upper.metadata["storey"] == "Dachgeschoss"
    assert upper.metadata["elevation"] == pytest.approx(2.7)
    # The top storey reaches up to the top of its gable walls.
    assert upper.metadata["height"] == pytest.approx(6.0868 - 2.7, abs=1e-3)
    assert [r.name for r in upper.rooms] == ["Galerie"]
    assert upper.doors == ()
    areas = upper.class_areas()
    assert areas[W] > 0 and areas[C] > 0 and areas[CL] > 0 and areas[D] == 0
    # Its floor is Slab-033, whose top lies at the storey's elevation.
    floor_top = (upper.face_labels == F) & (upper.mesh.face_normals[:, 2] > 0.99)
    assert np.allclose(upper.mesh.triangles_center[floor_top][:, 2], 2.7)
    # The base slab of the ground floor is not part of it.
    assert upper.bounds[0, 2] >= 2.5 - 1e-6


def test_class_map_override_relabels(ground):
    areas = ground.class_areas()
    as_wall = load_ifc_scene(FZK, class_map={"IfcDoor": SurfaceClass.WALL})
    relabelled = as_wall.class_areas()
    assert relabelled[D] == 0.0
    assert relabelled[W] == pytest.approx(areas[W] + areas[D], rel=1e-9)
    assert relabelled[F] == pytest.approx(areas[F], rel=1e-9)
    assert len(as_wall.doors) == 5  # the ground truth does not depend on the labels
    assert DEFAULT_CLASS_MAP["IfcDoor"] == D  # the default table is untouched


def test_class_map_none_leaves_elements_out(ground):
    open_doors = load_ifc_scene(FZK, class_map={"ifcdoor": None, "IfcStair": SurfaceClass.WALL})
    areas = open_doors.class_areas()
    assert areas[D] == 0.0
    assert areas[W] == pytest.approx(ground.class_areas()[W] + ground.class_areas()[CL], rel=1e-9)
    assert areas[CL] == 0.0
    assert len(open_doors.mesh.faces) < len(ground.mesh.faces)
    assert len(open_doors.doors) == 5


def test_unknown_storey_name_lists_storeys():
    with pytest.raises(IfcError) as info:
        load_ifc_scene(FZK, storey="Keller")
    message = str(info.value)
    assert str(FZK) in message and "'Keller'" in message
    assert "Erdgeschoss" in message and "Dachgeschoss" in message


@pytest.mark.parametrize("bad", [2, -3, 99])
def test_storey_index_out_of_range(bad):
    with pytest.raises(IfcError, match=r"out of range.*Erdgeschoss.*Dachgeschoss"):
        load_ifc_scene(FZK, storey=bad)


def test_unknown_class_in_class_map():
    with pytest.raises(IfcError, match="IfcWal"):
        load_ifc_scene(FZK, class_map={"IfcWal": SurfaceClass.WALL})


def test_licence_note_travels_with_the_model():
    note = (FZK.parent / "README.md").read_text(encoding="utf-8")
    assert "AC20-FZK-Haus.ifc" in note and "KIT" in note


# ------------------------------------------------------------------------------- tiny models
def tiny_ifc(
    path: Path,
    storeys: tuple[tuple[str, float], ...] = (("EG", 0.0),),
    *,
    walls: bool = True,
    slab: bool = True,
    host: int = 0,
) -> Path:
    """A 4 x 3 m room (four 0.2 m thick, 3 m high walls and a 0.2 m slab) in millimetre units.

    The elements go on storey ``host`` (index into ``storeys``) at that storey's elevation, or on the
    building when there is no storey.
    """
    f, body, building = new_building("tiny", millimetres=True)  # so the loader must convert
    created = []
    for i, (name, z) in enumerate(storeys):
        st = root.create_entity(f, ifc_class="IfcBuildingStorey", name=name)
        st.LongName = f"Level {i}"
        st.Elevation = z * 1000.0
        geometry.edit_object_placement(f, product=st, matrix=matrix(0, 0, z))
        aggregate.assign_object(f, products=[st], relating_object=building)
        created.append(st)
    container = created[host] if created else building
    z0 = storeys[host][1] if storeys else 0.0
    if walls:
        for x, y, angle, length in [(0, 0, 0, 4), (4, 0, 90, 3), (4, 3, 180, 4), (0, 3, 270, 3)]:
            wall = root.create_entity(f, ifc_class="IfcWall", name=f"wall-{angle}")
            rep = geometry.add_wall_representation(f, context=body, length=length, height=3.0, thickness=0.2)
            geometry.assign_representation(f, product=wall, representation=rep)
            geometry.edit_object_placement(f, product=wall, matrix=matrix(x, y, z0, angle))
            spatial.assign_container(f, products=[wall], relating_structure=container)
    if slab:
        plate = root.create_entity(f, ifc_class="IfcSlab", name="slab")
        rep = geometry.add_slab_representation(f, context=body, depth=0.2, polyline=[(0, 0), (4, 0), (4, 3), (0, 3)])
        geometry.assign_representation(f, product=plate, representation=rep)
        geometry.edit_object_placement(f, product=plate, matrix=matrix(0, 0, z0 - 0.2))
        spatial.assign_container(f, products=[plate], relating_structure=container)
    f.write(str(path))
    return path


# Four walls: two 4 m and two 3 m long, 0.2 m thick, 3 m high, all faces.
TINY_WALL_AREA = 2 * (2 * 4 * 3 + 2 * 0.2 * 3 + 2 * 4 * 0.2) + 2 * (2 * 3 * 3 + 2 * 0.2 * 3 + 2 * 3 * 0.2)
TINY_FLOOR_AREA = 2 * 12 + 14 * 0.2


def test_tiny_model_in_millimetres(tmp_path):
    scene = load_ifc_scene(tiny_ifc(tmp_path / "tiny.ifc"))
    areas = scene.class_areas()
    assert areas[W] == pytest.approx(TINY_WALL_AREA, rel=1e-6)
    assert areas[F] == pytest.approx(TINY_FLOOR_AREA, rel=1e-6)
    assert np.allclose(scene.bounds, [[0, 0, -0.2], [4, 3, 3]], atol=1e-6)
    # No IfcSpace: the evaluation's rooms come from the floor's free space, one room here.
    assert scene.metadata["rooms"] == "derived" and len(scene.rooms) == 1 and scene.doors == ()
    assert scene.rooms[0].area == pytest.approx(Polygon(scene.rooms[0].polygon).area)
    # Faces longer than 1 m were split so that rooms can be told apart along them.
    edges = np.linalg.norm(scene.mesh.triangles - np.roll(scene.mesh.triangles, 1, axis=1), axis=2)
    assert edges.max() <= 1.0 + 1e-9


def test_default_storey_nearest_zero_lower_on_tie(tmp_path):
    p = tiny_ifc(tmp_path / "levels.ifc", (("Basement", -3.0), ("Upper", 3.0), ("Top", 6.0)), host=0)
    scene = load_ifc_scene(p)
    assert scene.metadata["storey"] == "Basement"
    assert scene.metadata["height"] == pytest.approx(6.0)


def test_storey_by_long_name_and_negative_index(tmp_path):
    p = tiny_ifc(tmp_path / "levels.ifc", (("Top", 6.0), ("Ground", 0.0), ("Upper", 3.0)), host=2)
    # Sorted by elevation: Ground (0), Upper (1), Top (2); "Level 2" is Upper's LongName.
    assert load_ifc_scene(p, storey="Level 2").metadata["storey"] == "Upper"
    assert load_ifc_scene(p, storey=1).metadata["storey"] == "Upper"
    assert load_ifc_scene(p, storey=-2).metadata["storey"] == "Upper"
    with pytest.raises(IfcError, match=r"no wall faces.*'Ground'.*'Upper'.*'Top'"):
        load_ifc_scene(p, storey="Top")


def test_slab_of_the_storey_below_closes_from_above(tmp_path):
    # A slab filed under the upper storey whose underside lies 0.2 m below that storey's elevation
    # closes the ground floor from above: it must come in as the ground floor's ceiling.
    p = tiny_ifc(tmp_path / "two.ifc", (("Ground", 0.0), ("Upper", 3.2)), host=0)
    f = ifcopenshell.open(str(p))
    body = next(c for c in f.by_type("IfcGeometricRepresentationSubContext") if c.ContextIdentifier == "Body")
    upper = next(s for s in f.by_type("IfcBuildingStorey") if s.Name == "Upper")
    roof = root.create_entity(f, ifc_class="IfcSlab", name="roof")
    rep = geometry.add_slab_representation(f, context=body, depth=0.2, polyline=[(0, 0), (4, 0), (4, 3), (0, 3)])
    geometry.assign_representation(f, product=roof, representation=rep)
    geometry.edit_object_placement(f, product=roof, matrix=matrix(0, 0, 3.0))
    spatial.assign_container(f, products=[roof], relating_structure=upper)
    f.write(str(p))
    scene = load_ifc_scene(p, storey="Ground")
    assert scene.class_areas()[C] == pytest.approx(TINY_FLOOR_AREA, rel=1e-6)
    assert scene.class_areas()[F] == pytest.approx(TINY_FLOOR_AREA, rel=1e-6)


def test_no_storey(tmp_path):
    p = tiny_ifc(tmp_path / "nostorey.ifc", storeys=())
    with pytest.raises(IfcError, match=r"nostorey\.ifc: no storey"):
        load_ifc_scene(p)


def test_no_walls(tmp_path):
    p = tiny_ifc(tmp_path / "nowalls.ifc", walls=False)
    with pytest.raises(IfcError, match=r"nowalls\.ifc: storey 'EG' has no wall faces"):
        load_ifc_scene(p)


def test_no_floor(tmp_path):
    p = tiny_ifc(tmp_path / "nofloor.ifc", slab=False)
    with pytest.raises(MissingStructureError, match=r"nofloor\.ifc: storey 'EG' has no floor faces"):
        load_ifc_scene(p, name="other name")


def test_missing_file(tmp_path):
    with pytest.raises(SceneFileError, match=r"absent\.ifc: no such file"):
        load_ifc_scene(tmp_path / "absent.ifc")


@pytest.mark.parametrize(
    "content",
    [b"\x00\xff garbage \x13\x37" * 50, b"solid cube\nendsolid cube\n", b"ISO-10303-21;\nHEADER;\nbroken"],
)
def test_not_ifc(tmp_path, content):
    p = tmp_path / "bad.ifc"
    p.write_bytes(content)
    with pytest.raises(IfcError, match=r"bad\.ifc: cannot read as IFC"):
        load_ifc_scene(p)


def test_missing_ifcopenshell(monkeypatch):
    # A None entry makes `import ifcopenshell` raise ImportError, as if it were not installed.
    monkeypatch.setitem(sys.modules, "ifcopenshell", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'nbs-env\[ifc\]'") as info:
        load_ifc_scene(FZK)
    assert str(FZK) in str(info.value)
    assert isinstance(info.value, ImportError)


def test_interior_only_structure_leaves_out_hidden_faces(ground):
    scene = ground
    inner = interior_area(scene)
    assert 0 < inner < 0.6 * scene.structural_area()
    samples = interior_samples(scene, 0.1)
    assert len(samples) == pytest.approx(inner / 0.01, rel=0.02)
    # Interior by geometry, not by IfcSpace: nearly all of it lies in a space; the rest is the
    # stair and the hall parts the file's spaces leave out.
    assert np.mean(samples.rooms >= 0) > 0.85
    # No exterior wall face counts: every interior sample lies inside the walls' plan hull, by 10 cm.
    every = scene.structure_samples(0.1)
    walls = every.points[every.labels == SurfaceClass.WALL]
    hull = shapely.convex_hull(shapely.multipoints(walls[:, :2])).buffer(-0.1)
    wall_samples = samples.points[samples.labels == SurfaceClass.WALL]
    assert shapely.contains_xy(hull, wall_samples[:, 0], wall_samples[:, 1]).mean() > 0.99


def test_a_truncated_file_is_refused(tmp_path):
    """ifcopenshell reads a cut-off STEP file without a word and loses what the rest held."""
    cut = tmp_path / "cut.ifc"
    data = FZK.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(IfcError, match=r"cut\.ifc: cannot read as IFC: truncated, .*END-ISO-10303-21"):
        load_ifc_scene(cut, storey="Erdgeschoss")
    # The whole file, with trailing blank lines, loads.
    whole = tmp_path / "whole.ifc"
    whole.write_bytes(data + b"\r\n\r\n")
    assert len(load_ifc_scene(whole, storey="Erdgeschoss").rooms) == 6


# ---------------------------------------------------------------------- what the file says
def _tiny_with(tmp_path: Path, edit) -> Scene:
    """The tiny model with ``edit(f, storey, body)`` applied before it is written and loaded."""
    path = tiny_ifc(tmp_path / "tiny.ifc")
    f = ifcopenshell.open(str(path))
    edit(f, f.by_type("IfcBuildingStorey")[0], f.by_type("IfcGeometricRepresentationSubContext")[0])
    f.write(str(path))
    return load_ifc_scene(path)


def test_the_file_places_the_start_by_a_storey_property_set_in_its_units(tmp_path):
    from ifcopenshell.api import pset

    def edit(f, storey, body):
        ps = pset.add_pset(f, product=storey, name="Pset_NbsStart")
        pset.edit_pset(f, pset=ps, properties={"StartX": 1500.0, "StartY": 1000.0})  # millimetres

    scene = _tiny_with(tmp_path, edit)
    assert scene.has_explicit_start and np.allclose(scene.start[:2], [1.5, 1.0])
    assert not load_ifc_scene(tiny_ifc(tmp_path / "plain.ifc")).has_explicit_start  # none: auto_start's


def test_the_file_places_the_start_by_an_annotation(tmp_path):
    from ifcopenshell.api import pset

    def edit(f, storey, body):
        mark = root.create_entity(f, ifc_class="IfcAnnotation", name="start")
        geometry.edit_object_placement(f, product=mark, matrix=matrix(2.5, 1.2, 0.0))
        spatial.assign_container(f, products=[mark], relating_structure=storey)
        pset.add_pset(f, product=mark, name="Pset_NbsStart")

    assert np.allclose(_tiny_with(tmp_path, edit).start[:2], [2.5, 1.2])


@pytest.mark.parametrize("how", ["predefined_type", "pset"])
def test_a_space_the_file_marks_external_is_no_room(tmp_path, how):
    from ifcopenshell.api import pset

    def edit(f, storey, body):
        balcony = "INTERNAL" if how == "pset" else "EXTERNAL"
        for name, x0, kind in [("inside", 0.0, "INTERNAL"), ("balcony", 2000.0, balcony)]:
            space = root.create_entity(f, ifc_class="IfcSpace", name=name, predefined_type=kind)
            outline = [(x0, 0.0), (x0 + 2000.0, 0.0), (x0 + 2000.0, 3000.0), (x0, 3000.0)]  # millimetres
            rep = geometry.add_slab_representation(f, context=body, depth=2800.0, polyline=outline)
            geometry.assign_representation(f, product=space, representation=rep)
            geometry.edit_object_placement(f, product=space, matrix=matrix(0, 0, 0))
            aggregate.assign_object(f, products=[space], relating_object=storey)
            if how == "pset" and name == "balcony":
                ps = pset.add_pset(f, product=space, name="Pset_SpaceCommon")
                pset.edit_pset(f, pset=ps, properties={"IsExternal": True})

    scene = _tiny_with(tmp_path, edit)
    assert [r.name for r in scene.rooms] == ["inside"]


def test_a_storey_kilometres_wide_by_its_stated_unit_is_refused_before_it_is_meshed(tmp_path):
    """The length unit said kilometres: long faces were split into more triangles than memory held
    before the storey's size was checked."""
    from scenes.errors import StoreySizeError

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    assert "IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.)" in text
    path = tmp_path / "km.ifc"
    path.write_text(text.replace("IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.)", "IFCSIUNIT(*,.LENGTHUNIT.,.KILO.,.METRE.)"))
    with pytest.raises(StoreySizeError, match=r"km\.ifc: the storey is [\d,]+ m across.*check its IfcUnitAssignment"):
        load_ifc_scene(path)
