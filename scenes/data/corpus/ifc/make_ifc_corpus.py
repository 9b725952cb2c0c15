"""Write the authored IFC storeys of the evaluation corpus: six small IFC4 buildings, one ``.ifc`` each.

Usage::

    python scenes/data/corpus/ifc/make_ifc_corpus.py           # write the files beside this script
    python scenes/data/corpus/ifc/make_ifc_corpus.py --check   # write them, then load every storey

The files are built with ``ifcopenshell.api`` the way authoring tools export buildings (storeys in a
building on a site, walls as extruded ``IfcWall`` solids voided by ``IfcOpeningElement`` and filled
by ``IfcDoor``/``IfcWindow``, ``IfcSlab`` floors, ``IfcSpace`` rooms, ``IfcCovering`` ceilings,
``IfcRoof`` roofs, furniture), not through our floor-plan generator. Two follow Revit's habits
(millimetres; storeys "Level 1"/"Level 2" with the slab above filed under "Level 2"; door and window
types whose shapes are mapped into each instance; a wall axis; suspended ceilings), the others
ArchiCAD's (metres; German storey and room names; door shapes on each door; a flat ``IfcRoof`` on
the storey it closes, or the slab above on the storey above).

==========================  =====  =====================================================================
file (storey)               units  what it tests
==========================  =====  =====================================================================
revit_flat_mm (Level 1)     mm     a flat of 5 rooms; IfcCovering ceilings hung 0.33-0.38 m below the
                                   slab; door types with leaves (swing left/right) and plan swings; the
                                   start as an IfcAnnotation with ``Pset_NbsStart``
porch_house (EG)            m      a bungalow of 5 rooms; the entrance opens onto a porch under the
                                   roof (two columns, no walls, no IfcSpace), the living room onto a
                                   raised balcony under the roof (1.0 m railing, an EXTERNAL IfcSpace)
two_dwellings (EG)          m      two flats of 3 rooms each, a party wall and no door between them,
                                   each with its own front door to the open outside; IfcZone per flat
split_level (EG)            m      a living room at 0 and, 0.51 m up, a dining room open to it (railing)
                                   reached by a 3-riser IfcStair/IfcStairFlight, with two rooms off it
u_l_office (Level 1)        mm     a lobby, a U-shaped and an L-shaped office whose arms cannot be seen
                                   from their doors, a meeting room, an archive with no IfcSpace; suspended
                                   ceilings; a double entrance door
garage_house (EG)           m      a house with a 3.7 x 7.7 m garage (2.5 m sectional door to the
                                   outside); one door drawn with its leaf open at 90 deg; the start as
                                   ``Pset_NbsStart`` (StartX, StartY) on the storey
==========================  =====  =====================================================================

The output is deterministic for a given ifcopenshell version: every ``GlobalId`` is derived from the
file's stem and the entity's step id, and the header's time stamp is fixed. The robot's start is
written into two files (an ``IfcAnnotation`` and a storey property set), and ``scenes.ifc`` reads
both; the other files start where :func:`scenes.geometry.auto_start` puts the robot.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import ifcopenshell
import ifcopenshell.guid
import numpy as np
import shapely
from ifcopenshell.api import aggregate, context, feature, geometry, group, pset, root, spatial, unit
from ifcopenshell.api import project as api_project
from ifcopenshell.api import type as api_type
from ifcopenshell.util.shape_builder import ShapeBuilder
from shapely.geometry import Polygon
from shapely.geometry import box as rect

HERE = Path(__file__).resolve().parent
_NAMESPACE = uuid.UUID("3b0f8c52-6a55-4f1e-9d7e-2c4b1a0e9f31")
_TIME_STAMP = "2025-01-01T00:00:00"
_ROUND = 6  # decimals (m) of every computed coordinate, so that float noise never reaches the file

Point = tuple[float, float]
Box = tuple[float, float, float, float, float, float]  # x0, y0, z0, x1, y1, z1 (m, local)


def matrix(x: float, y: float, z: float, angle: float = 0.0) -> np.ndarray:
    """A placement: ``angle`` degrees about z, then a move to (x, y, z) (metres)."""
    m = np.eye(4)
    a = math.radians(angle)
    m[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    m[:3, 3] = (x, y, z)
    return np.round(m, 12)


def ring(polygon: Polygon) -> list[Point]:
    """The exterior of a polygon, counter-clockwise, not closed, rounded."""
    polygon = shapely.geometry.polygon.orient(polygon, 1.0)
    return [(round(x, _ROUND), round(y, _ROUND)) for x, y in list(polygon.exterior.coords)[:-1]]


@dataclass
class Wall:
    """A straight wall centred on its axis ``a`` -> ``b``; ``s0``/``s1`` are where its solid starts and
    ends along the axis (``s0 < 0`` extends it before ``a``)."""

    entity: object
    name: str
    a: np.ndarray
    b: np.ndarray
    thickness: float
    height: float
    z: float
    s0: float = 0.0
    s1: float = 0.0

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.b - self.a))

    @property
    def direction(self) -> np.ndarray:
        return (self.b - self.a) / self.length

    @property
    def angle(self) -> float:
        return math.degrees(math.atan2(self.direction[1], self.direction[0]))

    def local(self, s: float, y: float = 0.0, z: float = 0.0, flip: bool = False) -> np.ndarray:
        """The placement at axis distance ``s``, ``y`` across from the wall's right face, ``z`` above its
        base; ``flip`` turns it 180 degrees (its x along -axis, its y from the left face)."""
        d = self.direction
        n = np.array([-d[1], d[0]])
        p = self.a + d * s + n * (y - self.thickness / 2)
        return matrix(float(p[0]), float(p[1]), self.z + z, self.angle + (180.0 if flip else 0.0))

    def footprint(self) -> Polygon:
        d = self.direction
        n = np.array([-d[1], d[0]]) * self.thickness / 2
        p0, p1 = self.a + d * self.s0, self.a + d * self.s1
        return Polygon([p0 - n, p1 - n, p1 + n, p0 + n])


def _on_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> str | None:
    """Whether ``p`` is an "end" of a-b, lies strictly "inside" it, or neither (None)."""
    if np.allclose(p, a, atol=1e-9) or np.allclose(p, b, atol=1e-9):
        return "end"
    ab, ap = b - a, p - a
    cross = ab[0] * ap[1] - ab[1] * ap[0]
    t = float(np.dot(ap, ab) / np.dot(ab, ab))
    return "inside" if abs(cross) < 1e-9 and 0 < t < 1 else None


class Building:
    """One IFC4 file: project, site, building, storeys, and helpers that add elements the way an
    authoring tool exports them. Coordinates are metres in world axes; the helpers convert to the
    project's length unit where ifcopenshell expects project units."""

    def __init__(self, stem: str, title: str, *, millimetres: bool, revit: bool, description: str) -> None:
        self.stem, self.revit = stem, revit
        self.unit = 1000.0 if millimetres else 1.0  # project units per metre
        f = api_project.create_file(version="IFC4")
        self.f = f
        self.project = root.create_entity(f, ifc_class="IfcProject", name=title)
        self.project.Description = description
        if millimetres:
            unit.assign_unit(f)  # ifcopenshell's default: millimetres, square and cubic metres
        else:
            unit.assign_unit(f, units=[unit.add_si_unit(f, unit_type="LENGTHUNIT")])
        model = context.add_context(f, context_type="Model")
        self.body = context.add_context(
            f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
        )
        self.axis = context.add_context(
            f, context_type="Model", context_identifier="Axis", target_view="GRAPH_VIEW", parent=model
        )
        plan = context.add_context(f, context_type="Plan")
        self.plan_body = context.add_context(
            f, context_type="Plan", context_identifier="Body", target_view="PLAN_VIEW", parent=plan
        )
        self.annotation = context.add_context(
            f, context_type="Plan", context_identifier="Annotation", target_view="PLAN_VIEW", parent=plan
        )
        self.site = root.create_entity(f, ifc_class="IfcSite", name="Site" if revit else "Grundstück")
        self.building = root.create_entity(f, ifc_class="IfcBuilding", name=title)
        aggregate.assign_object(f, products=[self.site], relating_object=self.project)
        aggregate.assign_object(f, products=[self.building], relating_object=self.site)
        geometry.edit_object_placement(f, product=self.site, matrix=matrix(0, 0, 0))
        geometry.edit_object_placement(f, product=self.building, matrix=matrix(0, 0, 0))
        self.builder = ShapeBuilder(f)
        self.types: dict[tuple, object] = {}
        self.footprints: dict[int, list[Polygon]] = {}

    # ------------------------------------------------------------------------------ structure
    def storey(self, name: str, elevation: float, long_name: str | None = None):
        st = root.create_entity(self.f, ifc_class="IfcBuildingStorey", name=name)
        st.LongName = long_name
        st.Elevation = elevation * self.unit
        geometry.edit_object_placement(self.f, product=st, matrix=matrix(0, 0, elevation))
        aggregate.assign_object(self.f, products=[st], relating_object=self.building)
        self.footprints[st.id()] = []
        return st

    def _place(self, product, rep, placement: np.ndarray, container) -> None:
        if rep is not None:
            geometry.assign_representation(self.f, product=product, representation=rep)
        geometry.edit_object_placement(self.f, product=product, matrix=placement)
        if container is not None:
            spatial.assign_container(self.f, products=[product], relating_structure=container)

    def walls(self, storey, specs: Sequence[tuple]) -> dict[str, Wall]:
        """Walls by name from ``(name, a, b, thickness, height[, z[, ends]])``: axis a -> b (m), base z
        above the storey, ``ends`` (e0, e1) overriding how far each end reaches past the axis point
        (None: joined automatically; an end on another wall's side stops at its face, an L corner is
        closed by the wall nearer horizontal)."""
        made: list[Wall] = []
        for spec in specs:
            name, a, b, t, h = spec[:5]
            z = spec[5] if len(spec) > 5 else 0.0
            made.append(Wall(None, name, np.array(a, float), np.array(b, float), t, h, z))
        ends = {spec[0]: (spec[6] if len(spec) > 6 else (None, None)) for spec in specs}
        for w in made:
            horizontal = abs(w.direction[0]) >= abs(w.direction[1])
            reach = []
            for k, p in enumerate((w.a, w.b)):
                if ends[w.name][k] is not None:
                    reach.append(ends[w.name][k])
                    continue
                tee, corner = [], []  # thicknesses of the walls this end meets side-on and end to end
                for o in made:
                    if o is not w and abs(abs(float(np.dot(o.direction, w.direction))) - 1) > 1e-9:
                        where = _on_segment(p, o.a, o.b)
                        (tee if where == "inside" else corner if where == "end" else []).append(o.thickness)
                if tee:
                    reach.append(-max(tee) / 2)
                elif corner:
                    reach.append(max(corner) / 2 if horizontal else -max(corner) / 2)
                else:
                    reach.append(0.0)
            w.s0, w.s1 = -reach[0], w.length + reach[1]
        result = {}
        for w in made:
            wall = root.create_entity(self.f, ifc_class="IfcWall", name=w.name, predefined_type="STANDARD")
            w.entity = wall
            rep = geometry.add_wall_representation(
                self.f, context=self.body, length=w.s1 - w.s0, height=w.height, thickness=w.thickness
            )
            self._place(wall, rep, w.local(w.s0), storey)
            if self.revit:  # Revit and ArchiCAD both export the wall's axis as a 2D curve
                axis = geometry.add_axis_representation(
                    self.f,
                    context=self.axis,
                    axis=[(0.0, w.thickness / 2 * self.unit), ((w.s1 - w.s0) * self.unit, w.thickness / 2 * self.unit)],
                )
                geometry.assign_representation(self.f, product=wall, representation=axis)
            self.footprints[storey.id()].append(w.footprint())
            result[w.name] = w
        return result

    def clear(self, storey, outline: Polygon | Sequence[Point]) -> Polygon:
        """The clear floor of an axis outline: it minus the storey's wall footprints, the largest piece."""
        region = outline if isinstance(outline, Polygon) else Polygon(outline)
        cut = shapely.union_all(self.footprints[storey.id()])
        piece = region.difference(cut)
        if piece.geom_type == "MultiPolygon":
            piece = max(piece.geoms, key=lambda g: g.area)
        return Polygon(ring(piece))

    def _opening(self, wall: Wall, s: float, width: float, height: float, sill: float, name: str) -> object:
        opening = root.create_entity(self.f, ifc_class="IfcOpeningElement", name=name, predefined_type="OPENING")
        rep = geometry.add_wall_representation(
            self.f, context=self.body, length=width, height=height, thickness=wall.thickness + 0.2
        )
        self._place(opening, rep, wall.local(s, -0.1, sill), None)
        feature.add_feature(self.f, feature=opening, element=wall.entity)
        return opening

    def _typed(self, key: tuple, ifc_class: str, name: str, make_reps, **attributes):
        """The element type of ``key``, made on first use with the representations ``make_reps()``."""
        if key not in self.types:
            t = root.create_entity(self.f, ifc_class=ifc_class, name=name)
            for k, v in attributes.items():
                setattr(t, k, v)
            for rep in make_reps():
                geometry.assign_representation(self.f, product=t, representation=rep)
            self.types[key] = t
        return self.types[key]

    def door(
        self,
        storey,
        wall: Wall,
        centre: float,
        width: float = 0.9,
        height: float = 2.1,
        *,
        name: str = "door",
        operation: str = "SINGLE_SWING_LEFT",
        flip: bool = False,
        sill: float = 0.0,
        shape: str = "panel",
    ):
        """A door in ``wall``, centred ``centre`` m along its axis. ``shape``: "panel" (ifcopenshell's
        lining, closed leaf and handle; through a door type when the building is Revit-like), "open90"
        (lining and a leaf drawn open at 90 deg), "sectional" (a garage door: frame and one panel)."""
        u, s = self.unit, centre - width / 2
        opening = self._opening(wall, s, width, height, sill, f"{name} opening")
        door = root.create_entity(self.f, ifc_class="IfcDoor", name=name, predefined_type="DOOR")
        door.OverallWidth, door.OverallHeight = width * u, height * u
        lining = {
            "LiningDepth": wall.thickness * u,
            "LiningThickness": 0.05 * u,
            "CasingThickness": 0.0,
            "ThresholdThickness": 0.0,
        }
        placement = wall.local(s + width, wall.thickness, sill, flip=True) if flip else wall.local(s, 0.0, sill)
        if shape == "panel":
            door.OperationType = operation

            def reps():
                kwargs = dict(overall_width=width * u, overall_height=height * u, operation_type=operation)
                body = geometry.add_door_representation(self.f, context=self.body, lining_properties=lining, **kwargs)
                plan = geometry.add_door_representation(
                    self.f, context=self.plan_body, lining_properties=lining, **kwargs
                )
                return [body, plan]

            if self.revit:
                label = f"M_Single-Flush:{round(width * 1000)} x {round(height * 1000)}mm"
                dtype = self._typed(
                    ("door", width, height, wall.thickness, operation),
                    "IfcDoorType",
                    label,
                    reps,
                    PredefinedType="DOOR",
                    OperationType=operation,
                )
                self._place(door, None, placement, storey)
                api_type.assign_type(self.f, related_objects=[door], relating_type=dtype)
            else:
                body, plan = reps()
                self._place(door, body, placement, storey)
                geometry.assign_representation(self.f, product=door, representation=plan)
        elif shape == "open90":
            door.OperationType = operation
            t, lt = wall.thickness, 0.05
            boxes = [
                (0, 0, 0, lt, t, height),
                (width - lt, 0, 0, width, t, height),
                (0, 0, height - lt, width, t, height),
                # the leaf, 40 mm thick, hinged at the left jamb and swung 90 deg out of the wall's right face
                (lt, -(width - 2 * lt), 0.01, lt + 0.04, 0.0, height - lt - 0.005),
            ]
            self._place(door, self.boxes_rep(boxes), placement, storey)
        elif shape == "sectional":
            door.OperationType = "USERDEFINED"
            door.UserDefinedOperationType = "SECTIONAL"
            t, ft = wall.thickness, 0.06
            boxes = [
                (0, t - 0.1, 0, ft, t, height),
                (width - ft, t - 0.1, 0, width, t, height),
                (0, t - 0.1, height - ft, width, t, height),
                (ft, t - 0.1, 0, width - ft, t - 0.06, height - ft),  # the closed panel behind the lintel
            ]
            self._place(door, self.boxes_rep(boxes), placement, storey)
        else:
            raise ValueError(shape)
        feature.add_filling(self.f, opening=opening, element=door)
        return door

    def window(self, storey, wall: Wall, centre: float, width: float = 1.2, height: float = 1.3, sill: float = 0.9):
        u, s = self.unit, centre - width / 2
        opening = self._opening(wall, s, width, height, sill, "window opening")
        win = root.create_entity(self.f, ifc_class="IfcWindow", name="window", predefined_type="WINDOW")
        win.OverallWidth, win.OverallHeight = width * u, height * u
        win.PartitioningType = "SINGLE_PANEL"
        lining = {"LiningDepth": 0.08 * u, "LiningThickness": 0.06 * u, "LiningOffset": 0.06 * u}

        def reps():
            return [
                geometry.add_window_representation(
                    self.f,
                    context=self.body,
                    overall_width=width * u,
                    overall_height=height * u,
                    lining_properties=lining,
                )
            ]

        placement = wall.local(s, 0.0, sill)
        if self.revit:
            label = f"M_Fixed:{round(width * 1000)} x {round(height * 1000)}mm"
            wtype = self._typed(
                ("window", width, height),
                "IfcWindowType",
                label,
                reps,
                PredefinedType="WINDOW",
                PartitioningType="SINGLE_PANEL",
            )
            self._place(win, None, placement, storey)
            api_type.assign_type(self.f, related_objects=[win], relating_type=wtype)
        else:
            self._place(win, reps()[0], placement, storey)
        feature.add_filling(self.f, opening=opening, element=win)
        return win

    def _prism(self, polygon: Sequence[Point], depth: float):
        return geometry.add_slab_representation(self.f, context=self.body, depth=depth, polyline=list(polygon))

    def slab(self, storey, outline, z: float, thickness: float, *, name: str, predefined: str = "FLOOR", holes=()):
        """An ``IfcSlab`` of ``outline`` from world z ``z - thickness`` to ``z`` (m), voided by an
        opening per hole polygon."""
        slab = root.create_entity(self.f, ifc_class="IfcSlab", name=name, predefined_type=predefined)
        pts = ring(outline) if isinstance(outline, Polygon) else list(outline)
        self._place(slab, self._prism(pts, thickness), matrix(0, 0, z - thickness), storey)
        for hole in holes:
            opening = root.create_entity(self.f, ifc_class="IfcOpeningElement", name=f"{name} opening")
            rep = self._prism(ring(hole), thickness + 0.2)
            self._place(opening, rep, matrix(0, 0, z - thickness - 0.1), None)
            feature.add_feature(self.f, feature=opening, element=slab)
        return slab

    def roof(self, storey, outline, z: float, thickness: float, *, name: str = "Roof"):
        """A flat ``IfcRoof`` made of one ``IfcSlab`` (ROOF) from ``z`` up."""
        roof = root.create_entity(self.f, ifc_class="IfcRoof", name=name, predefined_type="FLAT_ROOF")
        geometry.edit_object_placement(self.f, product=roof, matrix=matrix(0, 0, z))
        spatial.assign_container(self.f, products=[roof], relating_structure=storey)
        slab = root.create_entity(self.f, ifc_class="IfcSlab", name=f"{name} slab", predefined_type="ROOF")
        self._place(slab, self._prism(ring(outline), thickness), matrix(0, 0, z), None)
        aggregate.assign_object(self.f, products=[slab], relating_object=roof)
        return roof

    def space(self, storey, number: str, long_name: str, polygon: Polygon, z0: float, z1: float, kind="INTERNAL"):
        sp = root.create_entity(self.f, ifc_class="IfcSpace", name=number, predefined_type=kind)
        sp.LongName = long_name
        sp.CompositionType = "ELEMENT"
        self._place(sp, self._prism(ring(polygon), z1 - z0), matrix(0, 0, z0), None)
        aggregate.assign_object(self.f, products=[sp], relating_object=storey)
        return sp

    def ceiling(self, storey, space, polygon: Polygon, z: float, thickness: float = 0.02, name="Ceiling"):
        """A suspended ceiling: an ``IfcCovering`` (CEILING) from ``z`` up, covering ``space``."""
        cov = root.create_entity(self.f, ifc_class="IfcCovering", name=name, predefined_type="CEILING")
        self._place(cov, self._prism(ring(polygon), thickness), matrix(0, 0, z), storey)
        if space is not None:
            self.f.create_entity(
                "IfcRelCoversSpaces",
                GlobalId=ifcopenshell.guid.new(),
                RelatingSpace=space,
                RelatedCoverings=[cov],
            )
        return cov

    def boxes_rep(self, boxes: Sequence[Box], context=None):
        u, items = self.unit, []
        for x0, y0, z0, x1, y1, z1 in boxes:
            profile = self.builder.rectangle(size=((x1 - x0) * u, (y1 - y0) * u), position=(x0 * u, y0 * u))
            items.append(self.builder.extrude(profile, (z1 - z0) * u, position=(0.0, 0.0, z0 * u)))
        return self.builder.get_representation(context or self.body, items)

    def element(
        self,
        storey,
        ifc_class: str,
        name: str,
        at: tuple[float, float, float],
        angle: float,
        boxes: Sequence[Box],
        predefined: str | None = None,
    ):
        """Any element made of boxes (local metres), placed at ``at`` turned ``angle`` degrees."""
        kwargs = {"predefined_type": predefined} if predefined else {}
        e = root.create_entity(self.f, ifc_class=ifc_class, name=name, **kwargs)
        self._place(e, self.boxes_rep(boxes), matrix(*at, angle), storey)
        return e

    def furniture(self, storey, kind: str, x: float, y: float, angle: float = 0.0, z: float = 0.0):
        """A piece of furniture from a small catalogue, its local origin at its back-left corner."""
        shapes: dict[str, tuple[str, list[Box], str | None]] = {
            "sofa": ("IfcFurniture", [(0, 0, 0, 2.2, 0.9, 0.42), (0, 0, 0.42, 2.2, 0.2, 0.85)], "CHAIR"),
            "table": ("IfcFurniture", _table(1.6, 0.9, 0.75), "TABLE"),
            "small table": ("IfcFurniture", _table(0.8, 0.8, 0.75), "TABLE"),
            "desk": ("IfcFurniture", _table(1.6, 0.8, 0.74), "TABLE"),
            "meeting table": ("IfcFurniture", _table(3.0, 1.2, 0.74), "TABLE"),
            "bed": ("IfcFurniture", [(0, 0, 0, 1.6, 2.05, 0.5), (0, 0, 0.5, 1.6, 0.08, 1.0)], "BED"),
            "single bed": ("IfcFurniture", [(0, 0, 0, 0.95, 2.05, 0.5)], "BED"),
            "wardrobe": ("IfcFurniture", [(0, 0, 0, 1.8, 0.6, 2.2)], "FILECABINET"),
            "shelf": ("IfcFurniture", [(0, 0, 0, 2.0, 0.4, 2.0)], "SHELF"),
            "counter": ("IfcFurniture", [(0, 0, 0, 2.6, 0.6, 0.9), (0, 0, 1.45, 2.6, 0.35, 2.2)], "SHELF"),
            "cabinet": ("IfcFurniture", [(0, 0, 0, 1.2, 0.45, 1.1)], "FILECABINET"),
            "armchair": ("IfcFurniture", [(0, 0, 0, 0.8, 0.8, 0.45), (0, 0, 0.45, 0.8, 0.15, 0.8)], "CHAIR"),
            "bath": ("IfcSanitaryTerminal", [(0, 0, 0, 1.7, 0.75, 0.58)], "BATH"),
            "washbasin": ("IfcSanitaryTerminal", [(0, 0, 0.7, 0.6, 0.45, 0.85)], "WASHHANDBASIN"),
            "wc": ("IfcSanitaryTerminal", [(0, 0, 0, 0.38, 0.65, 0.42)], "TOILETPAN"),
            "car": ("IfcFurnishingElement", [(0, 0, 0.15, 1.8, 4.4, 1.0), (0.1, 1.2, 1.0, 1.7, 3.4, 1.45)], None),
            "workbench": ("IfcFurnishingElement", _table(2.0, 0.7, 0.9), None),
        }
        ifc_class, boxes, predefined = shapes[kind]
        return self.element(storey, ifc_class, kind, (x, y, z), angle, boxes, predefined)

    def column(self, storey, x: float, y: float, height: float, size: float = 0.2, z: float = 0.0):
        h = size / 2
        return self.element(storey, "IfcColumn", "column", (x, y, z), 0, [(-h, -h, 0, h, h, height)], "COLUMN")

    def railing(self, storey, path: Sequence[Point], height: float = 1.0, z: float = 0.0, name: str = "railing"):
        """A guard rail along ``path``: 40 mm posts at most 1.2 m apart, a top and a knee rail."""
        boxes: list[Box] = []
        for p, q in itertools.pairwise(path):
            p, q = np.array(p, float), np.array(q, float)
            n = max(1, math.ceil(float(np.linalg.norm(q - p)) / 1.2))
            for k in range(n + 1):
                c = p + (q - p) * k / n
                boxes.append((c[0] - 0.02, c[1] - 0.02, 0, c[0] + 0.02, c[1] + 0.02, height))
            lo, hi = np.minimum(p, q) - 0.025, np.maximum(p, q) + 0.025
            boxes.append((lo[0], lo[1], height - 0.05, hi[0], hi[1], height))
            boxes.append((lo[0], lo[1], 0.45, hi[0], hi[1], 0.49))
        boxes = [tuple(round(v, _ROUND) for v in b) for b in boxes]
        return self.element(storey, "IfcRailing", name, (0, 0, z), 0, boxes, "GUARDRAIL")

    def stair(self, storey, x: float, y: float, angle: float, risers: int, rise: float, going: float, width: float):
        """A straight ``IfcStair`` of one ``IfcStairFlight``: its foot at local x = 0 (world (x, y)),
        rising along local +x over ``width`` along local +y; the top riser ends at x = (risers - 1) *
        going, where the upper floor starts (the last tread is that floor)."""
        u = self.unit
        st = root.create_entity(self.f, ifc_class="IfcStair", name="Stair", predefined_type="STRAIGHT_RUN_STAIR")
        geometry.edit_object_placement(self.f, product=st, matrix=matrix(x, y, 0, angle))
        spatial.assign_container(self.f, products=[st], relating_structure=storey)
        flight = root.create_entity(self.f, ifc_class="IfcStairFlight", name="Flight", predefined_type="STRAIGHT")
        flight.NumberOfRisers, flight.NumberOfTreads = risers, risers - 1
        flight.RiserHeight, flight.TreadLength = rise * u, going * u
        # The flight's side profile (x, z), a saw tooth, extruded across its width.
        pts = [(0.0, 0.0)]
        for k in range(risers - 1):
            pts += [(k * going * u, (k + 1) * rise * u), ((k + 1) * going * u, (k + 1) * rise * u)]
        pts += [((risers - 1) * going * u, 0.0)]
        profile = self.builder.polyline([(round(a, 6), round(b, 6)) for a, b in pts], closed=True)
        solid = self.builder.extrude(
            profile,
            width * u,
            position=(0.0, width * u, 0.0),
            position_x_axis=(1.0, 0.0, 0.0),
            position_z_axis=(0.0, -1.0, 0.0),
            extrusion_vector=(0.0, 0.0, 1.0),
        )
        rep = self.builder.get_representation(self.body, [solid])
        self._place(flight, rep, matrix(x, y, 0, angle), None)
        aggregate.assign_object(self.f, products=[flight], relating_object=st)
        return st

    def zone(self, name: str, spaces):
        z = root.create_entity(self.f, ifc_class="IfcZone", name=name)
        group.assign_group(self.f, products=list(spaces), group=z)
        return z

    def start_annotation(self, storey, x: float, y: float, z: float = 0.0):
        """The robot's start as the file says it: an ``IfcAnnotation`` (a plan cross) with ``Pset_NbsStart``."""
        a = root.create_entity(self.f, ifc_class="IfcAnnotation", name="NBS start")
        a.ObjectType = "NBS_START"
        u = self.unit
        lines = [
            self.builder.polyline([(-0.25 * u, 0.0), (0.25 * u, 0.0)]),
            self.builder.polyline([(0.0, -0.25 * u), (0.0, 0.25 * u)]),
        ]
        curves = self.f.create_entity("IfcGeometricCurveSet", Elements=lines)
        rep = self.builder.get_representation(self.annotation, [curves], representation_type="Annotation2D")
        self._place(a, rep, matrix(x, y, z), storey)
        ps = pset.add_pset(self.f, product=a, name="Pset_NbsStart")
        pset.edit_pset(self.f, pset=ps, properties={"Role": "robot start", "Clearance": 0.3 * u})
        return a

    def start_pset(self, storey, x: float, y: float):
        """The robot's start as the file says it: ``Pset_NbsStart`` (StartX, StartY) on the storey."""
        ps = pset.add_pset(self.f, product=storey, name="Pset_NbsStart")
        props = {
            "StartX": self.f.create_entity("IfcLengthMeasure", x * self.unit),
            "StartY": self.f.create_entity("IfcLengthMeasure", y * self.unit),
            "Role": "robot start, on this storey's floor",
        }
        pset.edit_pset(self.f, pset=ps, properties=props)

    def write(self) -> Path:
        # ifcopenshell.api fills the sets of a relationship (contained elements, aggregated parts) in
        # the order of a Python set: sort them by step id so that two runs write the same file.
        for rel in self.f.by_type("IfcRelationship"):
            if rel.is_a("IfcRelNests"):  # an ordered list
                continue
            for k, value in enumerate(rel):
                if (
                    isinstance(value, tuple)
                    and value
                    and all(isinstance(v, ifcopenshell.entity_instance) for v in value)
                ):
                    rel[k] = sorted(value, key=lambda e: e.id())
        for entity in sorted(self.f.by_type("IfcRoot"), key=lambda e: e.id()):
            key = f"{self.stem}/{entity.id()}"
            entity.GlobalId = ifcopenshell.guid.compress(uuid.uuid5(_NAMESPACE, key).hex)
        out = HERE / f"{self.stem}.ifc"
        self.f.header.file_name.name = out.name
        self.f.header.file_name.time_stamp = _TIME_STAMP
        self.f.write(str(out))
        return out


def _table(w: float, d: float, h: float) -> list[Box]:
    leg = 0.05
    return [(0, 0, h - 0.03, w, d, h)] + [
        (x, y, 0, x + leg, y + leg, h - 0.03) for x in (0.03, w - 0.03 - leg) for y in (0.03, d - 0.03 - leg)
    ]


def _outline(x0: float, y0: float, x1: float, y1: float, t: float) -> Polygon:
    """The outer outline of exterior walls of thickness ``t`` on the axis rectangle."""
    return rect(x0 - t / 2, y0 - t / 2, x1 + t / 2, y1 + t / 2)


def _exterior(x0: float, y0: float, x1: float, y1: float, t: float, h: float, z: float = 0.0) -> list[tuple]:
    """Four exterior walls on an axis rectangle, counter-clockwise from the south-west corner."""
    return [
        ("wall south", (x0, y0), (x1, y0), t, h, z),
        ("wall east", (x1, y0), (x1, y1), t, h, z),
        ("wall north", (x1, y1), (x0, y1), t, h, z),
        ("wall west", (x0, y1), (x0, y0), t, h, z),
    ]


# ----------------------------------------------------------------------------------- buildings
def revit_flat_mm() -> Building:
    """A flat of 5 rooms on "Level 1" (11 x 7.5 m axes), millimetres, Revit-like; suspended ceilings."""
    b = Building(
        "revit_flat_mm",
        "Revit-style flat",
        millimetres=True,
        revit=True,
        description="A flat of five rooms exported the way Revit exports: mm, door/window types, ceilings.",
    )
    l1, l2 = b.storey("Level 1", 0.0), b.storey("Level 2", 3.0)
    H, TE, TI = 2.8, 0.3, 0.125
    w = b.walls(
        l1,
        [
            *_exterior(0, 0, 11, 7.5, TE, H),
            ("partition y3", (0, 3), (11, 3), TI, H),
            ("partition living|bedroom", (6, 3), (6, 7.5), TI, H),
            ("partition bath|hall", (2.8, 0), (2.8, 3), TI, H),
            ("partition hall|kitchen", (7.4, 0), (7.4, 3), TI, H),
        ],
    )
    # The entrance from the (unmodelled) stair hall, and the doors off the hall.
    b.door(l1, w["wall south"], 4.9, 1.0, 2.134, name="entrance", operation="SINGLE_SWING_RIGHT", flip=True)
    b.door(l1, w["partition y3"], 4.0, 0.915, 2.134, name="door living", operation="SINGLE_SWING_LEFT")
    b.door(l1, w["partition y3"], 6.7, 0.915, 2.134, name="door bedroom", operation="SINGLE_SWING_RIGHT")
    b.door(l1, w["partition bath|hall"], 1.5, 0.815, 2.134, name="door bath", operation="SINGLE_SWING_LEFT")
    b.door(l1, w["partition hall|kitchen"], 1.6, 0.915, 2.134, name="door kitchen", operation="SINGLE_SWING_RIGHT")
    for wall, centres in [("wall north", (1.8, 5.3, 8.6)), ("wall west", (2.4,)), ("wall east", (5.4, 1.5))]:
        for c in centres:
            b.window(l1, w[wall], c, 1.2, 1.4, 0.9)
    b.window(l1, w["wall south"], 9.2, 1.2, 1.4, 0.9)
    b.window(l1, w["wall west"], 6.0, 0.6, 0.6, 1.6)  # the bath's small high window
    # Floor on Level 1, the structural slab above filed under Level 2 (Revit's floor at Level 2).
    b.slab(l1, _outline(0, 0, 11, 7.5, TE), 0.0, 0.2, name="Floor:Generic 200mm")
    b.slab(l2, _outline(0, 0, 11, 7.5, TE), 3.0, 0.2, name="Floor:Generic 200mm")
    rooms = [
        ("101", "Living", [(0, 3), (6, 3), (6, 7.5), (0, 7.5)], 2.42),
        ("102", "Bedroom", [(6, 3), (11, 3), (11, 7.5), (6, 7.5)], 2.45),
        ("103", "Bath", [(0, 0), (2.8, 0), (2.8, 3), (0, 3)], 2.45),
        ("104", "Hall", [(2.8, 0), (7.4, 0), (7.4, 3), (2.8, 3)], 2.45),
        ("105", "Kitchen", [(7.4, 0), (11, 0), (11, 3), (7.4, 3)], 2.45),
    ]
    for number, name, axes, ceiling in rooms:
        poly = b.clear(l1, axes)
        # Revit bounds a room by its ceiling: the space stops at the suspended ceiling's underside.
        sp = b.space(l1, number, name, poly, 0.0, ceiling)
        b.ceiling(l1, sp, poly, ceiling, 0.0125 if name != "Living" else 0.02, name=f"Compound Ceiling:{name}")
    b.furniture(l1, "sofa", 0.4, 6.9, -90)
    b.furniture(l1, "table", 3.2, 4.4)
    b.furniture(l1, "armchair", 4.9, 6.5)
    b.furniture(l1, "bed", 8.0, 7.15, 180)
    b.furniture(l1, "wardrobe", 10.75, 3.3, 90)
    b.furniture(l1, "bath", 0.2, 0.2)
    b.furniture(l1, "washbasin", 2.65, 2.3, 90)
    b.furniture(l1, "wc", 0.2, 2.0)
    b.furniture(l1, "counter", 10.8, 2.94, 180)  # along the partition, facing south
    b.furniture(l1, "small table", 9.6, 1.6)
    b.furniture(l1, "cabinet", 3.0, 2.8, -90)
    # The start where the surveyor would set up: in the hall, by the entrance.
    b.start_annotation(l1, 5.1, 1.6)
    return b


def porch_house() -> Building:
    """A bungalow of 5 rooms (10 x 8 m axes) with a porch and a balcony under one flat roof."""
    b = Building(
        "porch_house",
        "Bungalow with porch",
        millimetres=False,
        revit=False,
        description="A bungalow whose entrance opens onto a porch and whose living room opens onto a "
        "raised balcony, both under the roof.",
    )
    eg = b.storey("EG", 0.0, "Erdgeschoss")
    H, TE, TI = 2.8, 0.3, 0.12
    w = b.walls(
        eg,
        [
            *_exterior(0, 0, 10, 8, TE, H),
            ("wall y3.5", (0, 3.5), (10, 3.5), TI, H),
            ("wall hall|bath", (4.5, 0), (4.5, 3.5), TI, H),
            ("wall bath|bedroom", (6.5, 0), (6.5, 3.5), TI, H),
            ("wall kitchen|living", (3.0, 3.5), (3.0, 8), TI, H),
        ],
    )
    b.door(eg, w["wall south"], 2.0, 1.0, 2.1, name="front door", operation="SINGLE_SWING_LEFT", flip=True)
    b.door(eg, w["wall y3.5"], 1.5, 0.9, 2.1, name="door kitchen", operation="SINGLE_SWING_RIGHT")
    b.door(eg, w["wall y3.5"], 3.75, 0.9, 2.1, name="door living", operation="SINGLE_SWING_LEFT")
    b.door(eg, w["wall y3.5"], 8.2, 0.9, 2.1, name="door bedroom", operation="SINGLE_SWING_RIGHT", flip=True)
    b.door(eg, w["wall hall|bath"], 1.75, 0.8, 2.1, name="door bath", operation="SINGLE_SWING_LEFT")
    # wall north runs east to west: axis distance 4.0 is x = 6.0
    b.door(eg, w["wall north"], 4.0, 1.0, 2.2, name="balcony door", operation="SINGLE_SWING_RIGHT")
    b.window(eg, w["wall west"], 1.2, 1.0, 1.3)  # kitchen, y = 6.8 (wall west runs north to south)
    b.window(eg, w["wall north"], 8.5, 1.0, 1.3)  # kitchen, x = 1.5
    b.window(eg, w["wall north"], 1.5, 1.6, 1.4)  # living, x = 8.5
    b.window(eg, w["wall east"], 5.75, 1.6, 1.4)  # living
    b.window(eg, w["wall south"], 8.25, 1.2, 1.3)  # bedroom
    b.window(eg, w["wall south"], 5.5, 0.6, 0.6, 1.5)  # bath
    house = _outline(0, 0, 10, 8, TE)
    porch = rect(0.5, -2.2, 3.5, -TE / 2)
    balcony = rect(4.0, 8 + TE / 2, 9.0, 10.2)
    b.slab(eg, house, 0.0, 0.25, name="Bodenplatte")
    b.slab(eg, porch, 0.0, 0.2, name="Podest Eingang")  # the porch floor, level with the hall
    b.slab(eg, balcony, 0.0, 0.2, name="Balkonplatte")  # the raised deck (the ground falls away behind)
    roof = shapely.union_all([house, porch.buffer(0.01, join_style="mitre"), balcony.buffer(0.01, join_style="mitre")])
    b.roof(eg, Polygon(ring(roof)), H, 0.25, name="Flachdach")
    for x, y in [(0.6, -2.1), (3.4, -2.1)]:
        b.column(eg, x, y, H)
    b.railing(eg, [(4.05, 8 + TE / 2), (4.05, 10.15), (8.95, 10.15), (8.95, 8 + TE / 2)], 1.0, name="Balkongeländer")
    rooms = [
        ("0.01", "Diele", [(0, 0), (4.5, 0), (4.5, 3.5), (0, 3.5)]),
        ("0.02", "Bad", [(4.5, 0), (6.5, 0), (6.5, 3.5), (4.5, 3.5)]),
        ("0.03", "Schlafen", [(6.5, 0), (10, 0), (10, 3.5), (6.5, 3.5)]),
        ("0.04", "Küche", [(0, 3.5), (3, 3.5), (3, 8), (0, 8)]),
        ("0.05", "Wohnen", [(3, 3.5), (10, 3.5), (10, 8), (3, 8)]),
    ]
    for number, name, axes in rooms:
        b.space(eg, number, name, b.clear(eg, axes), 0.0, H)
    # ArchiCAD zones outdoor areas too: the balcony has an EXTERNAL space (up to the railing's inside),
    # the porch has none.
    b.space(eg, "0.06", "Balkon", rect(4.1, 8 + TE / 2, 8.9, 10.1), 0.0, H, kind="EXTERNAL")
    b.furniture(eg, "counter", 0.15, 6.2, -90)
    b.furniture(eg, "small table", 1.2, 5.0)
    b.furniture(eg, "sofa", 6.5, 5.4, 180)
    b.furniture(eg, "table", 4.2, 6.2)
    b.furniture(eg, "armchair", 9.0, 6.8)
    b.furniture(eg, "bed", 9.85, 0.9, 90)  # its head against the east wall
    b.furniture(eg, "wardrobe", 6.56, 3.44, -90)
    b.furniture(eg, "bath", 4.6, 2.65)
    b.furniture(eg, "wc", 6.0, 0.2)
    b.furniture(eg, "cabinet", 0.15, 2.8, -90)
    b.furniture(eg, "small table", 5.0, 8.8)  # on the balcony
    return b


def two_dwellings() -> Building:
    """Two flats of 3 rooms each (14 x 8 m axes), a party wall, each its own front door; slab above on OG."""
    b = Building(
        "two_dwellings",
        "Two dwellings",
        millimetres=False,
        revit=False,
        description="Ground floor of a house of flats: two dwellings with no door between them.",
    )
    eg, og = b.storey("EG", 0.0, "Erdgeschoss"), b.storey("OG", 2.8, "Obergeschoss")
    H, TE, TI, TP = 2.6, 0.3, 0.115, 0.25
    w = b.walls(
        eg,
        [
            *_exterior(0, 0, 14, 8, TE, H),
            ("party wall", (7.2, 0), (7.2, 8), TP, H),
            ("west y3.5", (0, 3.5), (7.2, 3.5), TI, H),
            ("west bed|bath", (4.0, 0), (4.0, 3.5), TI, H),
            ("east y3.5", (7.2, 3.5), (14, 3.5), TI, H),
            ("east bath|bed", (10.2, 0), (10.2, 3.5), TI, H),
        ],
    )
    # West flat: front door in the west wall (runs north to south: 1.6 m along is y = 6.4).
    b.door(eg, w["wall west"], 1.6, 1.0, 2.1, name="W front door", operation="SINGLE_SWING_LEFT", flip=True)
    b.door(eg, w["west y3.5"], 2.0, 0.9, 2.1, name="W door bedroom", operation="SINGLE_SWING_RIGHT")
    b.door(eg, w["west y3.5"], 5.6, 0.8, 2.1, name="W door bath", operation="SINGLE_SWING_LEFT")
    # East flat: front door in the east wall (south to north: 6.4 m along is y = 6.4).
    b.door(eg, w["wall east"], 6.4, 1.0, 2.1, name="E front door", operation="SINGLE_SWING_RIGHT", flip=True)
    b.door(eg, w["east y3.5"], 4.9, 0.9, 2.1, name="E door bedroom", operation="SINGLE_SWING_LEFT")
    b.door(eg, w["east y3.5"], 1.6, 0.8, 2.1, name="E door bath", operation="SINGLE_SWING_RIGHT")
    for c in (1.8, 5.6):
        b.window(eg, w["wall south"], c, 1.2, 1.3)  # west bedroom, west bath
    for c in (8.8, 12.2):
        b.window(eg, w["wall south"], c, 1.2, 1.3)  # east bath, east bedroom
    for c in (2.0, 5.2, 8.8, 12.0):  # north wall runs east to west
        b.window(eg, w["wall north"], c, 1.6, 1.4)
    b.slab(eg, _outline(0, 0, 14, 8, TE), 0.0, 0.2, name="Bodenplatte")
    b.slab(og, _outline(0, 0, 14, 8, TE), 2.8, 0.2, name="Decke über EG")
    spaces = {}
    rooms = [
        ("W", "W.01", "Wohnen/Kochen West", [(0, 3.5), (7.2, 3.5), (7.2, 8), (0, 8)]),
        ("W", "W.02", "Schlafen West", [(0, 0), (4.0, 0), (4.0, 3.5), (0, 3.5)]),
        ("W", "W.03", "Bad West", [(4.0, 0), (7.2, 0), (7.2, 3.5), (4.0, 3.5)]),
        ("E", "E.01", "Wohnen/Kochen Ost", [(7.2, 3.5), (14, 3.5), (14, 8), (7.2, 8)]),
        ("E", "E.02", "Bad Ost", [(7.2, 0), (10.2, 0), (10.2, 3.5), (7.2, 3.5)]),
        ("E", "E.03", "Schlafen Ost", [(10.2, 0), (14, 0), (14, 3.5), (10.2, 3.5)]),
    ]
    for flat, number, name, axes in rooms:
        spaces.setdefault(flat, []).append(b.space(eg, number, name, b.clear(eg, axes), 0.0, H))
    b.zone("Wohnung West", spaces["W"])
    b.zone("Wohnung Ost", spaces["E"])
    for _flat, x_sofa, x_table, counter, bed, wardrobe, x_bath, x_wc in [
        ("W", 3.1, 3.4, (7.075, 4.9, 90), (0.15, 2.6, -90), (3.94, 0.3, 90), 4.2, 6.6),
        ("E", 13.1, 9.0, (7.325, 7.5, -90), (13.85, 1.0, 90), (10.26, 2.1, -90), 8.3, 7.4),
    ]:
        b.furniture(eg, "sofa", x_sofa, 7.85, 180)  # its back against the north wall
        b.furniture(eg, "table", x_table, 5.0)
        b.furniture(eg, "counter", *counter)  # along the party wall
        b.furniture(eg, "bed", *bed)  # its head against the outside wall
        b.furniture(eg, "wardrobe", *wardrobe)
        b.furniture(eg, "bath", x_bath, 0.15)
        b.furniture(eg, "wc", x_wc, 1.5)
    return b


def split_level() -> Building:
    """A house (12 x 7 m axes): a living room at 0, a dining room 0.51 m up open to it above a 3-riser
    stair and a railing, a bedroom and a bath off the dining room."""
    b = Building(
        "split_level",
        "Split-level house",
        millimetres=False,
        revit=False,
        description="A split-level house: half the storey three risers (0.51 m) above the other half.",
    )
    eg = b.storey("EG", 0.0, "Erdgeschoss")
    H, TE, TI, UP = 3.0, 0.3, 0.12, 0.51
    w = b.walls(
        eg,
        [
            *_exterior(0, 0, 12, 7, TE, H),
            # Between the living room and the bedroom: full height from the lower floor, through the
            # corner with the raised partition below.
            ("wall living|bedroom", (5.5, 0), (5.5, 3.5), TI, H, 0.0, (None, TI / 2)),
            ("wall y3.5 upper", (5.5, 3.5), (12, 3.5), TI, H - UP, UP, (-TI / 2, None)),
            ("wall bedroom|bath", (9.0, 0), (9.0, 3.5), TI, H - UP, UP),
        ],
    )
    b.door(eg, w["wall south"], 2.5, 1.0, 2.1, name="front door", operation="SINGLE_SWING_LEFT", flip=True)
    b.door(eg, w["wall y3.5 upper"], 1.6, 0.9, 2.1, name="door bedroom", operation="SINGLE_SWING_RIGHT", sill=0)
    b.door(eg, w["wall y3.5 upper"], 5.0, 0.8, 2.1, name="door bath", operation="SINGLE_SWING_LEFT", sill=0)
    b.window(eg, w["wall west"], 3.5, 1.6, 1.5)  # living (wall west runs north to south)
    b.window(eg, w["wall south"], 4.4, 1.2, 1.5)  # living
    b.window(eg, w["wall north"], 2.0, 1.6, 1.4, 0.9 + UP)  # dining (north wall east to west: x = 10)
    b.window(eg, w["wall north"], 5.0, 1.6, 1.4, 0.9 + UP)  # dining, x = 7
    b.window(eg, w["wall north"], 9.5, 1.6, 1.5)  # living, x = 2.5
    b.window(eg, w["wall south"], 7.25, 1.2, 1.3, 0.9 + UP)  # bedroom
    b.window(eg, w["wall east"], 1.75, 0.8, 0.8, 1.4 + UP)  # bath
    outline = _outline(0, 0, 12, 7, TE)
    b.slab(eg, outline, 0.0, 0.25, name="Bodenplatte")
    # The raised level: one thick slab on the base slab east of the split, under its partitions.
    upper = rect(5.5, 0, 12, 7).difference(
        shapely.union_all([w[n].footprint() for n in ("wall south", "wall east", "wall north", "wall living|bedroom")])
    )
    b.slab(eg, Polygon(ring(upper)), UP, UP, name="Podest Split-Level")
    b.roof(eg, outline, H, 0.3, name="Flachdach")
    # Three risers of 0.17 m up from the living room, at the open edge x = 5.5, y 4.6..5.8.
    b.stair(eg, 5.5 - 2 * 0.26, 4.6, 0, 3, 0.17, 0.26, 1.2)
    b.railing(eg, [(5.53, 3.56), (5.53, 4.6)], 0.9, UP, name="Geländer Süd")
    b.railing(eg, [(5.53, 5.8), (5.53, 6.84)], 0.9, UP, name="Geländer Nord")
    rooms = [
        ("0.01", "Wohnen", [(0, 0), (5.5, 0), (5.5, 7), (0, 7)], 0.0),
        ("0.02", "Essen", [(5.5, 3.5), (12, 3.5), (12, 7), (5.5, 7)], UP),
        ("0.03", "Schlafen", [(5.5, 0), (9, 0), (9, 3.5), (5.5, 3.5)], UP),
        ("0.04", "Bad", [(9, 0), (12, 0), (12, 3.5), (9, 3.5)], UP),
    ]
    for number, name, axes, z0 in rooms:
        b.space(eg, number, name, b.clear(eg, axes), z0, H)
    b.furniture(eg, "sofa", 0.15, 3.2, -90)
    b.furniture(eg, "armchair", 3.6, 0.4)
    b.furniture(eg, "small table", 1.8, 2.4)
    b.furniture(eg, "cabinet", 0.2, 6.8, -90)
    b.furniture(eg, "table", 8.0, 4.8, 0, UP)
    b.furniture(eg, "counter", 11.85, 3.7, 90, UP)
    b.furniture(eg, "bed", 5.56, 2.4, -90, UP)
    b.furniture(eg, "wardrobe", 8.94, 1.3, 90, UP)
    b.furniture(eg, "bath", 10.1, 0.2, 0, UP)
    b.furniture(eg, "wc", 11.4, 2.4, 0, UP)
    return b


def u_l_office() -> Building:
    """An office floor (16 x 11 m axes, mm, Revit-like): lobby, U-shaped and L-shaped offices, an office,
    and an archive without an IfcSpace; suspended ceilings."""
    b = Building(
        "u_l_office",
        "Office floor",
        millimetres=True,
        revit=True,
        description="An office floor with a U-shaped and an L-shaped room and an archive without a space.",
    )
    l1, l2 = b.storey("Level 1", 0.0), b.storey("Level 2", 3.25)
    H, TE, TI = 3.0, 0.3, 0.15
    w = b.walls(
        l1,
        [
            *_exterior(0, 0, 16, 11, TE, H),
            ("partition lobby", (0, 3.6), (16, 3.6), TI, H),
            ("partition U|L", (8, 3.6), (8, 11), TI, H),
            ("archive west", (2.6, 6.0), (2.6, 11), TI, H),
            ("archive south", (2.6, 6.0), (5.4, 6.0), TI, H),
            ("archive east", (5.4, 6.0), (5.4, 11), TI, H),
            ("office south", (8, 6.6), (12.4, 6.6), TI, H),
            ("office east", (12.4, 6.6), (12.4, 11), TI, H),
        ],
    )
    entrance = b.door(
        l1, w["wall south"], 8.0, 1.8, 2.2, name="entrance", operation="DOUBLE_DOOR_SINGLE_SWING", flip=True
    )
    entrance.Name = "Double-Flush:1800 x 2200mm"
    b.door(l1, w["partition lobby"], 4.0, 1.0, 2.2, name="door U", operation="SINGLE_SWING_LEFT")
    b.door(l1, w["partition lobby"], 9.2, 1.0, 2.2, name="door L", operation="SINGLE_SWING_RIGHT")
    b.door(l1, w["archive south"], 1.4, 0.9, 2.2, name="door archive", operation="SINGLE_SWING_LEFT", flip=True)
    b.door(l1, w["office south"], 2.2, 1.0, 2.2, name="door office", operation="SINGLE_SWING_RIGHT")
    for c in (2.0, 5.0, 11.0, 14.0):
        b.window(l1, w["wall south"], c, 1.5, 1.5, 0.9)
    for c in (1.0, 4.0):  # wall west runs north to south: y = 10.0, 7.0 (the U's west arm)
        b.window(l1, w["wall west"], c, 1.5, 1.5, 0.9)
    for c in (1.2, 4.0, 6.7, 9.5, 14.7):  # wall north runs east to west: x = 14.8, 12.0, 9.3, 6.5, 1.3
        b.window(l1, w["wall north"], c, 1.5, 1.5, 0.9)
    for c in (5.0, 8.5):  # the L's east side
        b.window(l1, w["wall east"], c, 1.5, 1.5, 0.9)
    outline = _outline(0, 0, 16, 11, TE)
    b.slab(l1, outline, 0.0, 0.25, name="Floor:Concrete 250mm")
    b.slab(l2, outline, 3.25, 0.25, name="Floor:Concrete 250mm")
    rooms = [
        ("1.01", "Lobby", [(0, 0), (16, 0), (16, 3.6), (0, 3.6)]),
        ("1.02", "Open office U", [(0, 3.6), (8, 3.6), (8, 11), (5.4, 11), (5.4, 6.0), (2.6, 6.0), (2.6, 11), (0, 11)]),
        ("1.03", "Open office L", [(8, 3.6), (16, 3.6), (16, 11), (12.4, 11), (12.4, 6.6), (8, 6.6)]),
        ("1.04", "Meeting", [(8, 6.6), (12.4, 6.6), (12.4, 11), (8, 11)]),
    ]
    for number, name, axes in rooms:
        poly = b.clear(l1, axes)
        sp = b.space(l1, number, name, poly, 0.0, 2.6)
        b.ceiling(l1, sp, poly, 2.6, 0.02, name=f"Compound Ceiling:600x600mm Grid:{name}")
    # The archive in the U's notch: walls, a door, shelves, no IfcSpace and no suspended ceiling.
    for y in (6.3, 7.6, 8.9, 10.2):
        b.furniture(l1, "shelf", 3.0, y)
    # Desks in the U's arms and in the L's arm, where they cannot be seen from the doors.
    for x in (0.4, 6.0):
        for y in (7.2, 9.2):
            b.furniture(l1, "desk", x, y)
    for x, y in ((1.0, 4.2), (4.6, 4.2)):
        b.furniture(l1, "desk", x, y)
    for y in (7.5, 9.5):
        b.furniture(l1, "desk", 13.2, y)
    for x in (11.2, 13.8):  # along the lobby partition, clear of the doors
        b.furniture(l1, "desk", x, 3.9)
    b.furniture(l1, "meeting table", 8.7, 8.2)
    b.furniture(l1, "cabinet", 15.8, 0.9, 90)
    b.furniture(l1, "sofa", 1.0, 0.35)
    return b


def garage_house() -> Building:
    """A house (13 x 8 m axes) with a 4 x 8 m garage (2.5 m sectional door), one door drawn open."""
    b = Building(
        "garage_house",
        "House with garage",
        millimetres=False,
        revit=False,
        description="A house with an integral garage whose 2.5 m sectional door opens to the outside.",
    )
    eg = b.storey("EG", 0.0, "Erdgeschoss")
    H, TE, TI = 2.6, 0.3, 0.175
    w = b.walls(
        eg,
        [
            *_exterior(0, 0, 13, 8, TE, H),
            ("wall garage|house", (4, 0), (4, 8), TE, H),  # a fire wall as thick as the outside walls
            ("wall y3", (4, 3), (13, 3), TI, H),
            ("wall utility|hall", (6.5, 0), (6.5, 3), TI, H),
            ("wall hall|kitchen", (9.5, 0), (9.5, 3), TI, H),
        ],
    )
    b.door(eg, w["wall south"], 2.0, 2.5, 2.125, name="garage door", shape="sectional")
    b.door(eg, w["wall garage|house"], 1.5, 0.875, 2.0, name="fire door", operation="SINGLE_SWING_RIGHT")
    b.door(eg, w["wall utility|hall"], 1.5, 0.875, 2.0, name="door utility", operation="SINGLE_SWING_LEFT")
    b.door(eg, w["wall south"], 8.0, 1.0, 2.1, name="front door", operation="SINGLE_SWING_LEFT", flip=True)
    # axis distance 4.0 along wall y3 (from x = 4) is x = 8.0: the leaf drawn open into the hall
    b.door(eg, w["wall y3"], 4.0, 1.0, 2.0, name="door living", operation="SINGLE_SWING_RIGHT", shape="open90")
    b.door(eg, w["wall hall|kitchen"], 1.5, 0.875, 2.0, name="door kitchen", operation="SINGLE_SWING_LEFT", flip=True)
    b.window(eg, w["wall west"], 4.0, 0.8, 0.6, 1.6)  # garage (wall west runs north to south)
    for c in (2.5, 6.0, 9.5):  # wall north runs east to west: x = 10.5, 7.0, 3.5... the living room
        b.window(eg, w["wall north"], c, 1.6, 1.4)
    b.window(eg, w["wall east"], 5.5, 1.6, 1.4)
    b.window(eg, w["wall south"], 11.2, 1.2, 1.3)  # kitchen
    b.window(eg, w["wall south"], 5.25, 0.8, 1.0, 1.2)  # utility
    outline = _outline(0, 0, 13, 8, TE)
    b.slab(eg, outline, 0.0, 0.25, name="Bodenplatte")
    b.roof(eg, outline, H, 0.3, name="Flachdach")
    rooms = [
        ("0.01", "Garage", [(0, 0), (4, 0), (4, 8), (0, 8)]),
        ("0.02", "Hauswirtschaft", [(4, 0), (6.5, 0), (6.5, 3), (4, 3)]),
        ("0.03", "Diele", [(6.5, 0), (9.5, 0), (9.5, 3), (6.5, 3)]),
        ("0.04", "Küche", [(9.5, 0), (13, 0), (13, 3), (9.5, 3)]),
        ("0.05", "Wohnen", [(4, 3), (13, 3), (13, 8), (4, 8)]),
    ]
    for number, name, axes in rooms:
        b.space(eg, number, name, b.clear(eg, axes), 0.0, H)
    b.furniture(eg, "car", 1.1, 1.6)
    b.furniture(eg, "workbench", 0.15, 7.85, -90)
    b.furniture(eg, "shelf", 3.85, 5.6, 90)
    b.furniture(eg, "cabinet", 4.35, 2.8, -90)
    b.furniture(eg, "counter", 12.85, 0.3, 90)
    b.furniture(eg, "small table", 10.3, 1.0)
    b.furniture(eg, "sofa", 5.0, 4.9)
    b.furniture(eg, "table", 9.5, 5.8)
    b.furniture(eg, "armchair", 11.8, 4.0)
    b.furniture(eg, "cabinet", 7.0, 7.85, 180)
    b.start_pset(eg, 8.0, 1.2)  # in the hall, behind the front door
    return b


#: Every building: maker, and the storeys (name, expected room count from IfcSpace) the corpus loads.
BUILDINGS = {
    "revit_flat_mm": (revit_flat_mm, [("Level 1", 5)]),
    "porch_house": (porch_house, [("EG", 6)]),
    "two_dwellings": (two_dwellings, [("EG", 6)]),
    "split_level": (split_level, [("EG", 4)]),
    "u_l_office": (u_l_office, [("Level 1", 4)]),
    "garage_house": (garage_house, [("EG", 5)]),
}


def check(path: Path, storey: str, rooms: int) -> str:
    from scenes.ifc import load_ifc_scene

    t0 = time.perf_counter()
    scene = load_ifc_scene(path, storey=storey)
    seconds = time.perf_counter() - t0
    if len(scene.rooms) != rooms:
        raise SystemExit(f"{path.name}#{storey}: {len(scene.rooms)} rooms, expected {rooms}")
    names = ", ".join(r.name for r in scene.rooms)
    return f"{path.name}#{storey}: {len(scene.rooms)} rooms ({names}), {len(scene.doors)} doors, {seconds:.1f} s"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="load every storey after writing the files")
    args = parser.parse_args(argv)
    for make, storeys in BUILDINGS.values():
        out = make().write()
        print(f"wrote {out} ({out.stat().st_size} bytes)")
        if args.check:
            for storey, rooms in storeys:
                print("  " + check(out, storey, rooms))
    return 0


if __name__ == "__main__":
    sys.exit(main())
