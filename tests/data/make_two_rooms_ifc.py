"""Write ``two_rooms.ifc``: a tiny IFC4 building whose ground storey holds two rooms joined by one door.

Usage::

    python tests/data/make_two_rooms_ifc.py

The file is written beside this script. Units are metres. The model, in world coordinates:

* storeys ``EG`` (elevation 0) and ``OG`` (elevation 3.0), in one building on one site;
* on EG: an 8 x 4 m outline of four exterior ``IfcWall`` (0.2 m thick, 2.7 m high, standing inside
  the outline), an interior ``IfcWall`` at x = 4 (x 3.9..4.1) splitting it into two rooms, an
  ``IfcDoor`` (0.9 x 2.1 m, centred at y = 2.0) filling an ``IfcOpeningElement`` that voids the
  interior wall, the floor ``IfcSlab`` (8 x 4 m, z -0.2..0) and one ``IfcSpace`` per room,
  aggregated into EG ("Room A": x 0.2..3.9, "Room B": x 4.1..7.8; both y 0.2..3.8, z 0..2.7). The
  door's lining is as deep as the wall, with no casing and no threshold; ifcopenshell's door shape
  always has a handle, which reaches 1.5 cm out of the wall on Room B's side;
* on OG: the ceiling ``IfcSlab`` (8 x 4 m, z 2.7..2.9). OG holds no walls, so it cannot be loaded as
  a storey of its own; the loader takes its slab as EG's ceiling (its underside lies within
  ``scenes.ifc.BOUNDING_TOLERANCE`` of OG's elevation, EG's top).

The output is deterministic for a given ifcopenshell version: every ``GlobalId`` is derived from the
entity's step id and the header's time stamp is fixed (the header still names the ifcopenshell
version that wrote it).
"""

from __future__ import annotations

import uuid
from pathlib import Path

import ifcopenshell
import ifcopenshell.guid
import numpy as np
from ifcopenshell.api import aggregate, context, feature, geometry, root, spatial, unit
from ifcopenshell.api import project as api_project

OUT = Path(__file__).with_name("two_rooms.ifc")

LENGTH, DEPTH = 8.0, 4.0  # outline (m)
WALL_T, WALL_H = 0.2, 2.7
SLAB_T = 0.2
OG_ELEVATION = 3.0
DOOR_W, DOOR_H, DOOR_Y = 0.9, 2.1, 2.0  # door width, height, centre along the interior wall
_NAMESPACE = uuid.UUID("6f1c1b1e-2d0a-4c55-9a51-7e0f3b7a2c10")


def new_building(name: str, *, millimetres: bool) -> tuple[ifcopenshell.file, object, object]:
    """An IFC4 file with a project, a model's body context, a site and a building called ``name``.

    Returns
    -------
    file, body, building
        The file, the body context representations go in, and the ``IfcBuilding``.
    """
    f = api_project.create_file(version="IFC4")
    project = root.create_entity(f, ifc_class="IfcProject", name=name)
    # Millimetres (ifcopenshell's default unit) make the loader convert; metres do not.
    if millimetres:
        unit.assign_unit(f)
    else:
        unit.assign_unit(f, units=[unit.add_si_unit(f, unit_type="LENGTHUNIT")])
    model = context.add_context(f, context_type="Model")
    body = context.add_context(
        f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
    )
    site = root.create_entity(f, ifc_class="IfcSite", name="site")
    building = root.create_entity(f, ifc_class="IfcBuilding", name=name)
    aggregate.assign_object(f, products=[site], relating_object=project)
    aggregate.assign_object(f, products=[building], relating_object=site)
    return f, body, building


def matrix(x: float, y: float, z: float, angle: float = 0.0) -> np.ndarray:
    """A placement: ``angle`` degrees about z, then a move to (x, y, z)."""
    m = np.eye(4)
    a = np.radians(angle)
    m[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    m[:3, 3] = (x, y, z)
    return m


def build() -> ifcopenshell.file:
    f, body, building = new_building("two rooms", millimetres=False)
    storeys = {}
    for name, z in (("EG", 0.0), ("OG", OG_ELEVATION)):
        storey = root.create_entity(f, ifc_class="IfcBuildingStorey", name=name)
        storey.Elevation = z
        geometry.edit_object_placement(f, product=storey, matrix=matrix(0, 0, z))
        aggregate.assign_object(f, products=[storey], relating_object=building)
        storeys[name] = storey
    eg, og = storeys["EG"], storeys["OG"]

    def place(product, rep, matrix, container):
        geometry.assign_representation(f, product=product, representation=rep)
        geometry.edit_object_placement(f, product=product, matrix=matrix)
        if container is not None:
            spatial.assign_container(f, products=[product], relating_structure=container)

    # Exterior walls run counter-clockwise; each one's thickness lies to its left, inside the outline.
    L, D, T = LENGTH, DEPTH, WALL_T
    for name, x, y, angle, length in [
        ("wall south", 0, 0, 0, L),
        ("wall east", L, 0, 90, D),
        ("wall north", L, D, 180, L),
        ("wall west", 0, D, 270, D),
    ]:
        wall = root.create_entity(f, ifc_class="IfcWall", name=name)
        rep = geometry.add_wall_representation(f, context=body, length=length, height=WALL_H, thickness=T)
        place(wall, rep, matrix(x, y, 0, angle), eg)
    # The interior wall runs north between the exterior walls; at 90 degrees its thickness lies to -x.
    x_mid = L / 2 + T / 2
    inner = root.create_entity(f, ifc_class="IfcWall", name="wall interior")
    rep = geometry.add_wall_representation(f, context=body, length=D - 2 * T, height=WALL_H, thickness=T)
    place(inner, rep, matrix(x_mid, T, 0, 90), eg)

    # The opening is 0.1 m deeper than the wall on each side, so that the void cuts cleanly through it.
    y0 = DOOR_Y - DOOR_W / 2
    opening = root.create_entity(f, ifc_class="IfcOpeningElement", name="door opening")
    rep = geometry.add_wall_representation(f, context=body, length=DOOR_W, height=DOOR_H, thickness=T + 0.2)
    place(opening, rep, matrix(x_mid + 0.1, y0, 0, 90), None)
    feature.add_feature(f, feature=opening, element=inner)
    door = root.create_entity(f, ifc_class="IfcDoor", name="door")
    door.OverallWidth, door.OverallHeight = DOOR_W, DOOR_H
    # A lining as deep as the wall, no casing on the wall faces, no threshold on the floor.
    lining = {"LiningDepth": T, "CasingThickness": 0.0, "ThresholdThickness": 0.0}
    rep = geometry.add_door_representation(
        f, context=body, overall_width=DOOR_W, overall_height=DOOR_H, lining_properties=lining
    )
    place(door, rep, matrix(x_mid, y0, 0, 90), eg)
    feature.add_filling(f, opening=opening, element=door)

    outline = [(0, 0), (L, 0), (L, D), (0, D)]
    for name, z, container in (("floor slab", -SLAB_T, eg), ("ceiling slab", WALL_H, og)):
        slab = root.create_entity(f, ifc_class="IfcSlab", name=name)
        rep = geometry.add_slab_representation(f, context=body, depth=SLAB_T, polyline=outline)
        place(slab, rep, matrix(0, 0, z), container)

    for name, x0, x1 in (("Room A", T, L / 2 - T / 2), ("Room B", L / 2 + T / 2, L - T)):
        space = root.create_entity(f, ifc_class="IfcSpace", name=name[-1], predefined_type="INTERNAL")
        space.LongName = name
        polygon = [(x0, T), (x1, T), (x1, D - T), (x0, D - T)]
        rep = geometry.add_slab_representation(f, context=body, depth=WALL_H, polyline=polygon)
        place(space, rep, matrix(0, 0, 0), None)
        aggregate.assign_object(f, products=[space], relating_object=eg)

    # Deterministic ids and header.
    for entity in sorted(f.by_type("IfcRoot"), key=lambda e: e.id()):
        entity.GlobalId = ifcopenshell.guid.compress(uuid.uuid5(_NAMESPACE, f"two_rooms/{entity.id()}").hex)
    f.header.file_name.name = OUT.name
    f.header.file_name.time_stamp = "2025-01-01T00:00:00"
    return f


def main() -> None:
    build().write(str(OUT))
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
