"""Scene loading problems found by the second robustness probe (N7, N15, N16, N20, N22, N24).

Each test builds the offending input in ``tmp_path`` and checks the error's type and message.
"""

from __future__ import annotations

import base64
import json
import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from scenes import (
    FloorPlan,
    IfcError,
    InvalidMeshError,
    MissingStructureError,
    PlanGeometryError,
    RoomPlan,
    StoreySizeError,
    generate_plan,
    load_scene,
)
from scenes.importers import load_mesh_scene
from scenes.limits import MAX_ORIGIN_DISTANCE, MIN_STOREY_HEIGHT, STOREY_GAP, check_storey_shape
from scenes.model import SurfaceClass

DATA = Path(__file__).parent / "data"


# ------------------------------------------------------------------------------------- helpers
def _quad(a, b, c, d) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.array([a, b, c, d], float), [[0, 1, 2], [0, 2, 3]], process=False)


def room_parts(x0=0.0, x1=4.0, y0=0.0, y1=3.0, z=0.0, h=2.5, room: int | None = None) -> dict[str, trimesh.Trimesh]:
    """Floor, ceiling and four walls of a room from x0..x1, y0..y1, its floor at ``z``."""
    tag = "" if room is None else f"_room{room}"
    top = z + h
    return {
        f"floor{tag}": _quad((x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)),
        f"ceiling{tag}": _quad((x0, y0, top), (x0, y1, top), (x1, y1, top), (x1, y0, top)),
        f"wall_s{tag}": _quad((x0, y0, z), (x0, y0, top), (x1, y0, top), (x1, y0, z)),
        f"wall_n{tag}": _quad((x0, y1, z), (x1, y1, z), (x1, y1, top), (x0, y1, top)),
        f"wall_w{tag}": _quad((x0, y0, z), (x0, y1, z), (x0, y1, top), (x0, y0, top)),
        f"wall_e{tag}": _quad((x1, y0, z), (x1, y0, top), (x1, y1, top), (x1, y1, z)),
    }


def write_obj(path: Path, parts: dict[str, trimesh.Trimesh], transform=None) -> Path:
    lines, offset = [], 0
    for name, mesh in parts.items():
        v = np.asarray(mesh.vertices) if transform is None else transform(np.asarray(mesh.vertices))
        lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in v]
        lines.append(f"o {name}")
        lines += [f"f {a + offset + 1} {b + offset + 1} {c + offset + 1}" for a, b, c in mesh.faces]
        offset += len(v)
    path.write_text("\n".join(lines) + "\n")
    return path


def _mesh_of(parts: dict[str, trimesh.Trimesh]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, faces and labels of the named parts (labelled by their names' prefixes)."""
    mesh = trimesh.util.concatenate(list(parts.values()))
    labels = np.concatenate(
        [np.full(len(m.faces), SurfaceClass[name.split("_")[0].upper()].value) for name, m in parts.items()]
    )
    return np.asarray(mesh.vertices), np.asarray(mesh.faces), labels


def gltf_doc(parts: dict[str, trimesh.Trimesh]) -> dict:
    """A glTF JSON document (buffers embedded as data URIs) with one named node per part."""
    scene = trimesh.Scene()
    for name, mesh in parts.items():
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    files = trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)
    return json.loads(files["model.gltf"])


def write_gltf(path: Path, doc: dict) -> Path:
    path.write_text(json.dumps(doc))
    return path


def position_accessor(doc: dict) -> int:
    return doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]


# ------------------------------------------------------------------ N7: far from the origin
def test_a_mesh_far_from_the_origin_is_refused_at_load(tmp_path):
    path = write_obj(tmp_path / "far.obj", room_parts(), lambda v: v + np.array([1e6, 1e6, 0.0]))
    with pytest.raises(StoreySizeError) as info:
        load_scene(str(path))
    message = str(info.value)
    assert message.startswith(f"{path}: the storey lies up to 1,414,2")
    assert f"{MAX_ORIGIN_DISTANCE:,.0f} m" in message and "float32" in message
    assert "move the model near the origin" in message
    # The file loader itself keeps georeferenced coordinates (an export round trip keeps them).
    assert load_mesh_scene(path).bounds[0, 0] == pytest.approx(1e6)


def test_a_mesh_just_inside_the_limit_loads(tmp_path):
    shift = np.array([MAX_ORIGIN_DISTANCE * 0.7, MAX_ORIGIN_DISTANCE * 0.7, 0.0]) - 5.0
    path = write_obj(tmp_path / "near.obj", room_parts(), lambda v: v + shift)
    assert load_scene(path).bounds[1, 0] < MAX_ORIGIN_DISTANCE


def test_a_floor_plan_far_from_the_origin_is_refused_too():
    x = 2 * MAX_ORIGIN_DISTANCE
    plan = FloorPlan(rooms=(RoomPlan("hall", ((x, 0), (x + 6, 0), (x + 6, 4), (x, 4))),), name="far")
    with pytest.raises(StoreySizeError, match=r"far: the storey lies up to 20,00\d m from the origin"):
        load_scene(plan)


# --------------------------------------------------------------- N15: glTF extensions, sparse
@pytest.mark.parametrize(
    "extension", ["KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_mesh_quantization", "ACME_unknown"]
)
def test_a_gltf_requiring_an_unsupported_extension_is_refused(tmp_path, capfd, extension):
    doc = gltf_doc(room_parts())
    doc["extensionsUsed"] = doc["extensionsRequired"] = [extension]
    doc["meshes"][0]["primitives"][0]["extensions"] = {extension: {"bufferView": 0, "attributes": {"POSITION": 0}}}
    path = write_gltf(tmp_path / "ext.gltf", doc)
    with pytest.raises(InvalidMeshError, match=rf"requires glTF extension\(s\) '{extension}'"):
        load_scene(str(path))
    out, err = capfd.readouterr()
    assert "failed to process" not in out + err  # refused before the parser says a word


def test_a_gltf_requiring_only_an_appearance_extension_loads(tmp_path):
    doc = gltf_doc(room_parts())
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_materials_unlit", "KHR_texture_transform"]
    scene = load_scene(str(write_gltf(tmp_path / "unlit.gltf", doc)))
    assert len(scene.mesh.faces) == 12


def test_a_sparse_position_accessor_is_refused(tmp_path):
    doc = gltf_doc(room_parts())
    k = position_accessor(doc)
    # Two sparse values over the positions: indices and values in a new buffer.
    indices = np.array([0, 1], "<u4").tobytes()
    values = np.array([[9, 9, 9], [8, 8, 8]], "<f4").tobytes()
    blob = indices + values
    doc["buffers"].append(
        {"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
    )
    b = len(doc["buffers"]) - 1
    doc["bufferViews"] += [
        {"buffer": b, "byteOffset": 0, "byteLength": len(indices)},
        {"buffer": b, "byteOffset": len(indices), "byteLength": len(values)},
    ]
    v = len(doc["bufferViews"])
    doc["accessors"][k]["sparse"] = {
        "count": 2,
        "indices": {"bufferView": v - 2, "componentType": 5125},
        "values": {"bufferView": v - 1},
    }
    path = write_gltf(tmp_path / "sparse.gltf", doc)
    with pytest.raises(
        InvalidMeshError, match=rf"accessors\[{k}\] \(POSITION of meshes\[0\]\.primitives\[0\]\) is sparse"
    ):
        load_scene(str(path))


# ----------------------------------------------------------- N16: flat storeys, two storeys
def test_a_flattened_mesh_is_refused_at_load(tmp_path):
    path = write_obj(tmp_path / "flat.obj", room_parts(), lambda v: v * np.array([1.0, 1.0, 0.0]))
    with pytest.raises(StoreySizeError) as info:
        load_scene(str(path))
    message = str(info.value)
    assert "the storey is 0 m high" in message and f"at least {MIN_STOREY_HEIGHT:g} m" in message
    assert "--y-up" in message


def test_a_storey_whose_walls_have_no_area_is_refused(tmp_path):
    parts = room_parts()
    for name in [n for n in parts if n.startswith("wall")]:
        v = np.asarray(parts[name].vertices)
        parts[name] = trimesh.Trimesh(v, [[0, 1, 1], [2, 3, 3]], process=False)  # lines, not faces
    with pytest.raises(MissingStructureError, match=r"the 8 wall faces have no area"):
        load_scene(str(write_obj(tmp_path / "nowallarea.obj", parts)))


def test_a_low_plan_ceiling_is_refused_with_a_plan_hint():
    plan = FloorPlan(rooms=(RoomPlan("cellar", ((0, 0), (6, 0), (6, 4), (0, 4))),), ceiling_height=1.2, name="crawl")
    with pytest.raises(
        PlanGeometryError, match=r"crawl: ceiling_height: the ceiling is 1\.2 m high; .*at least 1\.5 m"
    ):
        load_scene(plan)
    # Built without validation, the load's own check refuses it still.
    with pytest.raises(StoreySizeError, match=r"the storey is 1\.2 m high .*raise the plan's ceiling_height"):
        check_storey_shape("crawl", *_mesh_of(room_parts(h=1.2)), low_hint="raise the plan's ceiling_height")


def test_two_storeys_in_one_mesh_are_refused_naming_the_levels(tmp_path):
    parts = room_parts(room=0) | {f"{k}_upper": m for k, m in room_parts(z=3.5, room=1).items()}
    with pytest.raises(StoreySizeError) as info:
        load_scene(str(write_obj(tmp_path / "two.obj", parts)))
    message = str(info.value)
    assert f"2 levels more than {STOREY_GAP:g} m apart" in message
    assert "0.00 m: 50%; 3.50 m: 50%" in message and "one storey per file" in message


def test_a_split_level_and_a_small_gallery_still_load(tmp_path):
    # A split level: a third of the floor 1.2 m up (less than the storey gap).
    parts = room_parts(0, 6, 0, 4, h=3.5)
    parts["floor_platform"] = _quad((4, 0, 1.2), (6, 0, 1.2), (6, 4, 1.2), (4, 4, 1.2))
    assert load_scene(str(write_obj(tmp_path / "split.obj", parts))).bounds[1, 2] == pytest.approx(3.5)
    # A gallery 2.5 m up holding under a tenth of the floor area is no second storey.
    parts = room_parts(0, 10, 0, 6, h=5.0)
    parts["floor_gallery"] = _quad((0, 0, 2.5), (1, 0, 2.5), (1, 5, 2.5), (0, 5, 2.5))
    assert load_scene(str(write_obj(tmp_path / "gallery.obj", parts))).bounds[1, 2] == pytest.approx(5.0)


def test_a_stair_of_floor_faces_between_two_levels_still_loads(tmp_path):
    # Treads labelled floor, 0.18 m apart, from the ground to a landing 1.8 m up.
    parts = room_parts(0, 8, 0, 4, h=4.0)
    for k in range(1, 11):
        x0, z = 4.0 + 0.25 * (k - 1), 0.18 * k
        parts[f"floor_step{k}"] = _quad((x0, 0, z), (x0 + 0.25, 0, z), (x0 + 0.25, 1, z), (x0, 1, z))
    parts["floor_landing"] = _quad((6.5, 0, 1.8), (8, 0, 1.8), (8, 4, 1.8), (6.5, 4, 1.8))
    assert len(load_scene(str(write_obj(tmp_path / "stair.obj", parts))).mesh.faces) > 12


@pytest.mark.parametrize("name", ["corpus:stairwell", "corpus:ifc_split_level", "l_room"])
def test_stairwells_and_split_levels_of_the_corpus_still_load(name):
    load_scene(name)


# ----------------------------------------------------------------- N20: ambiguous IFC storey
def _mutated_ifc(tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = (DATA / "two_rooms.ifc").read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path


def test_an_ambiguous_ifc_storey_name_is_refused_with_the_indices(tmp_path):
    pytest.importorskip("ifcopenshell")
    path = _mutated_ifc(tmp_path, "dup.ifc", ",'OG',", ",'EG',")
    with pytest.raises(IfcError) as info:
        load_scene(str(path), storey="EG")
    message = str(info.value)
    assert "2 storeys are named 'EG', indices 0, 1: pass the index instead (--storey 0" in message
    assert "\n" not in message
    assert load_scene(str(path), storey=0).metadata["storey_index"] == 0


# ------------------------------------------------------------- N22: unit hints, tall clutter
def test_an_ifc_whose_unit_makes_the_storey_tiny_gets_a_unit_hint(tmp_path):
    pytest.importorskip("ifcopenshell")
    path = _mutated_ifc(
        tmp_path, "mm.ifc", "IFCSIUNIT(*,.LENGTHUNIT.,$,.METRE.)", "IFCSIUNIT(*,.LENGTHUNIT.,.MILLI.,.METRE.)"
    )
    with pytest.raises(
        StoreySizeError,
        match=r"m across .*the least nbs-env loads is 1 m across\): is the file's unit right\?.*IfcUnitAssignment",
    ):
        load_scene(str(path))


def test_a_mesh_read_in_too_small_a_unit_gets_a_unit_hint(tmp_path):
    path = write_obj(tmp_path / "room.obj", room_parts())
    with pytest.raises(StoreySizeError, match=r"is the file in metres\? pass --units m"):
        load_scene(str(path), units="mm")
    tiny = write_obj(tmp_path / "tiny.obj", room_parts(), lambda v: v * 1e-3)
    with pytest.raises(StoreySizeError, match=r"is the file's unit right\? its coordinates were read as metres"):
        load_scene(str(tiny))


def test_clutter_taller_than_the_ceiling_says_so(plan_dict, write_json):
    plan_dict["clutter"] = [{"kind": "shelf", "position": [1.0, 1.0], "size": [1.0, 0.4, 50.0], "yaw": 0.0}]
    plan_dict["clutter"][0]["position"] = list(np.mean(plan_dict["rooms"][0]["polygon"], axis=0))
    with pytest.raises(PlanGeometryError) as info:
        load_scene(str(write_json(plan_dict)))
    message = str(info.value)
    assert "clutter[0].size[2]" in message and "50 m high, taller than the" in message
    assert "crosses a wall" not in message


def test_generated_storeys_with_a_low_ceiling_keep_their_clutter_under_it():
    # Cabinets and shelves are drawn up to 2.2 m high: under a 2 m ceiling they stop at it.
    options = {"ceiling_height": (2.0, 2.0), "door_height": (1.7, 1.7), "clutter_density": 2.0}
    plan = generate_plan(4, **options)
    assert max(c.size[2] for c in plan.clutter) == pytest.approx(2.0)
    assert load_scene("generated:4", **options).bounds[1, 2] == pytest.approx(2.0)


# ------------------------------------------------------------------------ N24: os.PathLike
class _PathLike:
    def __init__(self, path: Path) -> None:
        self._path = path

    def __fspath__(self) -> str:
        return str(self._path)


def test_any_path_like_object_is_a_scene_spec(tmp_path):
    path = write_obj(tmp_path / "room.obj", room_parts())
    assert isinstance(_PathLike(path), os.PathLike)
    scene = load_scene(_PathLike(path))
    assert scene.name == str(path) and len(scene.mesh.faces) == 12
    with pytest.raises(TypeError, match=r"str, os\.PathLike or FloorPlan, got int"):
        load_scene(3)


def test_an_obj_separated_by_tabs_loads_as_with_spaces(tmp_path):
    """Tabs are whitespace in OBJ; the file was refused as "empty (no faces)"."""
    from scenes import load_scene
    from scenes.importers import export_scene

    spaced = tmp_path / "l.obj"
    export_scene(load_scene("l_room"), spaced)
    tabbed = tmp_path / "tabs.obj"
    tabbed.write_text(spaced.read_text().replace(" ", "\t"))
    a, b = load_scene(spaced), load_scene(tabbed)
    assert len(b.mesh.faces) == len(a.mesh.faces) > 0
    assert np.allclose(b.mesh.vertices, a.mesh.vertices)


@pytest.mark.parametrize("name", ["a\nb", "nul\u0000", "tab\there", "rtl\u202eevil"])
def test_a_plan_name_with_a_control_character_is_refused(name):
    """A newline or a NUL in a room name broke the room table of nbs scan and reached the terminal."""
    from scenes.errors import FloorPlanError
    from scenes.floorplan import FloorPlan
    from scenes.generator import generate_storey

    plan = generate_storey(1)[0].to_dict()
    plan["rooms"][0]["name"] = name
    with pytest.raises(FloorPlanError, match="control character"):
        FloorPlan.from_dict(plan)


def test_an_ifc_placement_cycle_is_refused(tmp_path):
    """ifcopenshell's placement recursed without end (a 57-line RecursionError)."""
    import ifcopenshell

    from scenes.errors import IfcError

    source = Path(__file__).parent / "data" / "two_rooms.ifc"
    model = ifcopenshell.open(str(source))
    placements = [p for p in model.by_type("IfcLocalPlacement") if p.PlacementRelTo is not None]
    inner = placements[0]
    inner.PlacementRelTo.PlacementRelTo = inner  # two placements relative to each other
    broken = tmp_path / "cycle.ifc"
    model.write(str(broken))
    with pytest.raises(
        IfcError, match=r"references form a cycle: #\d+ \(IFCLOCALPLACEMENT\) -> #\d+ \(IFCLOCALPLACEMENT\)"
    ):
        load_scene(broken)


def test_a_mesh_whose_faces_need_more_memory_than_is_left_is_refused_before_reading(monkeypatch):
    """A 4.9 M-face PLY, under MAX_FACES, aborted inside glibc under a 4 GB address-space limit."""
    import scenes.limits as limits
    from scenes.errors import StoreySizeError

    monkeypatch.setattr(limits, "memory_left", lambda: (2**30, "its address-space limit, ulimit -v"))
    need = 4_000_000 * limits.BYTES_PER_FACE / 2**30
    with pytest.raises(StoreySizeError, match=rf"4,000,000 faces takes about {need:.1f} GiB.*1\.0 GiB more"):
        limits.check_face_count("big.ply", 4_000_000)
    limits.check_face_count("small.ply", 2**30 // limits.BYTES_PER_FACE - 1)  # just fits


@pytest.mark.skipif(not Path("/proc/meminfo").is_file(), reason="reads Linux's /proc")
def test_the_memory_left_is_read_from_the_system():
    from scenes.limits import memory_left

    left, why = memory_left()
    assert left > 2**26 and why


def test_a_containers_memory_limit_bounds_the_memory_left(monkeypatch, tmp_path):
    """cgroup v2: a container may hold far less than the machine has free."""
    import scenes.memory as limits

    (tmp_path / "memory.max").write_text(f"{3 * 2**30}\n")
    (tmp_path / "memory.current").write_text(f"{2**30}\n")
    monkeypatch.setattr(limits, "CGROUP", tmp_path)
    assert limits.machine_memory() <= 3 * 2**30
    if Path("/proc/meminfo").is_file():
        assert limits.memory_left() == (2 * 2**30, "its container's memory limit")
    (tmp_path / "memory.max").write_text("max\n")  # no limit set
    assert limits.memory_left() is None or limits.memory_left()[1] != "its container's memory limit"
