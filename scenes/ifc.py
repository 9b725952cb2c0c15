"""Load one storey of an IFC building model as a :class:`~scenes.model.Scene` (needs ifcopenshell).

Conventions
-----------
*Storeys.* The file's ``IfcBuildingStorey`` entities are sorted by elevation: the world z of the
storey's placement (its ``Elevation`` attribute when it has no placement), in metres. A storey is
chosen by ``Name`` or ``LongName``, or by index into that list (negative indices count from the
top); by default the storey whose elevation is nearest 0 (the lower one on a tie). The storey spans
from its elevation to the next storey's elevation, or to the top of its walls if it is the highest.

*Elements.* The scene holds the elements contained in the storey (directly, through a space, or as
parts of a contained element) plus, from other storeys, the slabs, coverings and roofs that bound it:
those whose bottom lies within :data:`BOUNDING_TOLERANCE` of the storey's top become CEILING, those
whose top lies within it of the storey's floor become FLOOR, provided they overlap the storey's walls
in plan. ``IfcSite``, ``IfcSpace`` and ``IfcOpeningElement`` are never meshed (door and window
openings are already cut from the walls by the geometry engine).

*Classes.* :data:`DEFAULT_CLASS_MAP` maps IFC classes to :class:`~scenes.model.SurfaceClass`;
``class_map`` entries are merged over it. A key is an IFC class name, optionally with a predefined
type (``"IfcCovering.CEILING"``), matched case-insensitively; an element takes the entry of its
most specific class, a ``Class.TYPE`` key beating the plain ``Class`` key. A value of ``None`` leaves
the element out of the mesh. Three rules refine the table:

* an element aggregated into another element (a slab of an ``IfcRoof``, a member or plate of an
  ``IfcCurtainWall``, a flight of an ``IfcStair``) takes the class of that whole;
* an ``IfcSlab`` on the storey mapped to FLOOR or CEILING is a FLOOR when its middle lies in the lower
  half of the storey and a CEILING otherwise, because ArchiCAD, Revit and others file the slab between
  two storeys under either of them;
* a slab, covering or roof from another storey is FLOOR or CEILING by where it bounds the storey (see
  above).

*Ground truth.* Rooms come from the storey's ``IfcSpace`` entities: the polygon is the largest piece
of the union of the space geometry's triangles projected to xy (counter-clockwise), the name its
``LongName`` (else ``Name``), ``floor_z``/``ceiling_z`` its z range. A face belongs to the room whose
prism (polygon x [floor_z, ceiling_z], :data:`ROOM_Z_TOLERANCE` slack) contains the point 0.1 m in
front of the face's centroid along its normal, else room -1, so the outside of exterior walls, the
underside of the floor slab and the top of the ceiling slab belong to no room. Faces longer than
:data:`MAX_FACE_EDGE` are split first, so that the single pair of triangles of a slab's top or a long
wall's side is shared out among the rooms along it. Doors come from the storey's ``IfcDoor``
entities: ``OverallWidth``/``OverallHeight`` (else the geometry's extent); of the two horizontal axes
of the door's placement (of the smallest rectangle around its plan if it has none), the one along
which the geometry is thinner is the normal; the rooms are those containing the centre of the door's
plan -/+ 0.6 m along the normal (-1 = outside), listed room before outside, else lower id first,
with the normal pointing from the first to the second; ``position`` is that centre at the door's
lowest z.

An ``IfcSpace`` the file marks external (``PredefinedType`` ``EXTERNAL``, or ``Pset_SpaceCommon``'s
``IsExternal``: the zone of a balcony, a terrace or a porch) is no room: its floor is outside, and a
door onto it is a door to the outside.

*Start.* A file may place the robot's start: a ``Pset_NbsStart`` on the storey with ``StartX`` and
``StartY`` (lengths in the storey's placement), or an ``IfcAnnotation`` on the storey that carries a
``Pset_NbsStart`` (its placement's origin). Without one, the scene's start is
:func:`scenes.geometry.auto_start`'s.

*Doors.* Models draw doors closed, and a ray (or robot) cannot pass a closed leaf, so by default
(``doors="open"``) a door keeps only its frame: the triangles of the ``IfcDoor`` element that lie
within :data:`DOOR_FRAME` of the element's sides or top (along its width and height); the leaf, the
panels and the handle between them are left out, and the opening is free. ``doors="closed"`` meshes
the door as drawn. Either way the ``Door`` ground truth is kept; ``class_map={"IfcDoor": None}``
leaves the whole element out.
"""

from __future__ import annotations

import codecs
import contextlib
import math
import os
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import shapely
import trimesh

from scenes.errors import IfcError, MissingDependencyError, MissingStructureError, SceneFileError
from scenes.geometry import split_long_faces
from scenes.importers import footprint_polygon
from scenes.interior import derive_rooms, rooms_by_probe
from scenes.labels import STRUCTURAL_CLASSES
from scenes.limits import MAX_ORIGIN_DISTANCE, check_file_size, check_storey_size
from scenes.model import Door, Room, Scene, SurfaceClass
from scenes.stepgraph import check_chains, check_references

__all__ = [
    "BOUNDING_TOLERANCE",
    "DEFAULT_CLASS_MAP",
    "MAX_FACE_EDGE",
    "ROOM_Z_TOLERANCE",
    "UnbuiltElementsWarning",
    "load_ifc_scene",
]

_S = SurfaceClass

#: IFC class (optionally ``.PREDEFINEDTYPE``) -> SurfaceClass, or None to leave the element out.
#: The most specific entry wins, so ``IfcElement`` is the catch-all for anything not listed.
#:
#: Choices beyond the obvious ones: columns and curtain-wall plates are WALL (vertical structure that
#: bounds the free space); beams are CEILING (they hang under it); stairs, ramps, railings and members
#: (rafters, studs, mullions outside a curtain wall) are CLUTTER, obstacles rather than the building's
#: envelope; coverings are CEILING, FLOOR or WALL by predefined type and CLUTTER otherwise; footings
#: and piles lie below the floor and are left out, as are virtual and feature elements.
DEFAULT_CLASS_MAP: Mapping[str, SurfaceClass | None] = MappingProxyType(
    {
        "IfcWall": _S.WALL,
        "IfcWallStandardCase": _S.WALL,
        "IfcCurtainWall": _S.WALL,
        "IfcColumn": _S.WALL,
        "IfcPlate": _S.WALL,
        "IfcSlab": _S.FLOOR,
        "IfcSlab.ROOF": _S.CEILING,
        "IfcRoof": _S.CEILING,
        "IfcBeam": _S.CEILING,
        "IfcCovering": _S.CLUTTER,
        "IfcCovering.CEILING": _S.CEILING,
        "IfcCovering.FLOORING": _S.FLOOR,
        "IfcCovering.CLADDING": _S.WALL,
        "IfcDoor": _S.DOOR,
        "IfcWindow": _S.WINDOW,
        "IfcStair": _S.CLUTTER,
        "IfcStairFlight": _S.CLUTTER,
        "IfcRamp": _S.CLUTTER,
        "IfcRampFlight": _S.CLUTTER,
        "IfcRailing": _S.CLUTTER,
        "IfcMember": _S.CLUTTER,
        "IfcFurnishingElement": _S.CLUTTER,
        "IfcBuildingElementProxy": _S.CLUTTER,
        "IfcDistributionElement": _S.CLUTTER,
        "IfcTransportElement": _S.CLUTTER,
        "IfcElement": _S.CLUTTER,
        "IfcFooting": None,
        "IfcPile": None,
        "IfcFeatureElement": None,
        "IfcVirtualElement": None,
        "IfcGeographicElement": None,
    }
)

#: How close (m) a slab's bottom must come to a storey's top, or its top to the storey's floor, to
#: bound that storey.
BOUNDING_TOLERANCE = 0.5
#: Faces with a longer edge (m) are split before rooms are assigned.
MAX_FACE_EDGE = 1.0
#: Slack (m) on a room's z range when testing which room a face belongs to. Less than the 0.1 m probe
#: distance, so that a face lying on the room's floor or ceiling plane but facing away from the room
#: (the top of a beam against the slab) stays out of it.
ROOM_Z_TOLERANCE = 0.05
#: With ``doors="open"``, door triangles within this distance (m) of the door's sides or top are its
#: frame (a lining is 5-10 cm); the rest is the leaf.
DOOR_FRAME = 0.1
#: What ``load_ifc_scene(doors=...)`` takes.
DOOR_MODES = ("open", "closed")
#: Distance (m) in front of a face at which its room is tested.
_FACE_PROBE = 0.1
#: Distance (m) either side of a door's centre at which its two rooms are looked up.
_DOOR_PROBE = 0.6

#: The deepest extrusion of an element, metres: a building's elements are at most a storey's width
#: (:data:`scenes.limits.MAX_STOREY_WIDTH`, a wall extruded along its length) and nowhere near 10 km.
MAX_EXTRUSION = 10_000.0
#: The shallowest, metres: a hundredth of a millimetre, below any element a scan could see (a unit of
#: 1e-300 m collapsed every wall to nothing, reported as "no wall faces").
MIN_EXTRUSION = 1e-5
#: The farthest a point may lie from its placement's origin, metres: survey coordinates (a UTM
#: northing is some 5,000 km, an easting with its zone in front up to 61,000 km) are within it;
#: 1e300 m is not a building's, and the geometry engine dropped what was placed there without a word.
MAX_COORDINATE = 1e8
_INSTALL_HINT = "reading IFC needs ifcopenshell: pip install 'nbs-env[ifc]'"
_BOUNDING_CLASSES = ("IfcSlab", "IfcCovering", "IfcRoof")


@dataclass(frozen=True)
class _Storey:
    entity: Any
    name: str
    long_name: str
    elevation: float

    def describe(self, index: int) -> str:
        long = f" / {self.long_name!r}" if self.long_name and self.long_name != self.name else ""
        return f"{index}: {self.name!r}{long} at {self.elevation:.2f} m"


def _check_complete(source: str, path: Path) -> None:
    """A STEP file (ISO 10303-21) must end with its end marker: ifcopenshell reads a truncated one
    without a word and loses whatever the missing part held (ceilings, spaces, whole storeys)."""
    with open(path, "rb") as fh:
        # Before the magic: a byte-order mark, blanks and comments (a file may open with a
        # /* comment */, and its truncation must not pass for "not a STEP file").
        head = re.sub(rb"^(?:\s|\xef\xbb\xbf|/\*.*?\*/)*", b"", fh.read(1 << 16), flags=re.DOTALL)
        if not head.startswith(b"ISO-10303-21;"):
            return  # not a STEP text file; ifcopenshell says what it is or is not
        fh.seek(0, 2)
        size = fh.tell()
        fh.seek(max(0, size - 4096))
        tail = fh.read().rstrip()
    if not tail.endswith(b"END-ISO-10303-21;"):
        ending = "the file does not end with END-ISO-10303-21; (an incomplete copy?)"
        raise IfcError(source, f"cannot read as IFC: truncated, {ending}")


def _check_placements(source: str, model: Any) -> None:
    """Every ``IfcLocalPlacement`` chain (``PlacementRelTo``) ends: one that comes back on itself
    sent ifcopenshell's placement into a RecursionError."""
    ended: set[int] = set()
    for placement in model.by_type("IfcLocalPlacement"):
        chain: list[int] = []
        node = placement
        while node is not None and node.id() not in ended:
            if node.id() in chain:
                raise IfcError(
                    source, f"the placement #{node.id()} is relative to itself: PlacementRelTo forms a cycle"
                )
            chain.append(node.id())
            parent = getattr(node, "PlacementRelTo", None)
            # A reference of another type (an IfcBuilding where a placement belongs) passes the reader
            # and ended in an AttributeError inside ifcopenshell's placement.
            if parent is not None and not parent.is_a("IfcObjectPlacement"):
                raise IfcError(
                    source,
                    f"the placement #{node.id()} is relative to #{parent.id()}, an {parent.is_a()}, not a placement",
                )
            relative = getattr(node, "RelativePlacement", None)
            if node.is_a("IfcLocalPlacement") and (relative is None or not relative.is_a("IfcPlacement")):
                shown = "nothing" if relative is None else f"#{relative.id()}, an {relative.is_a()}"
                raise IfcError(source, f"the placement #{node.id()} places by {shown}, not an axis placement")
            node = parent
        ended.update(chain)


#: How far from the origin a storey may lie, in metres: the deepest mine shaft and the highest
#: building are within a few kilometres, and a float of 1e300 sorted a storey out of its place.
MAX_ELEVATION = 10_000.0
#: The relations that make a building's tree (whole → parts), with their attributes, as
#: ``ifcopenshell.util.element`` walks them: aggregation, nesting, containment, openings and fillings.
_DECOMPOSITIONS = (
    ("IfcRelAggregates", "RelatingObject", "RelatedObjects"),
    ("IfcRelNests", "RelatingObject", "RelatedObjects"),
    ("IfcRelContainedInSpatialStructure", "RelatingStructure", "RelatedElements"),
    ("IfcRelVoidsElement", "RelatingBuildingElement", "RelatedOpeningElement"),
    ("IfcRelFillsElement", "RelatingOpeningElement", "RelatedBuildingElement"),
)
#: The deepest chain of decompositions in the corpus's IFC files (project, site, building, storey,
#: wall, opening, door, ...), and the bound: a chain of 20,000 aggregated parts took every element
#: through the whole chain (quadratic), and a part of itself looped forever.
CORPUS_DECOMPOSITION_DEPTH = 6
MAX_DECOMPOSITION_DEPTH = 64


def _check_decomposition(source: str, model: Any) -> None:
    """The building's tree has no cycle (a wall part of itself, a building under its own storey)
    and no chain deeper than :data:`MAX_DECOMPOSITION_DEPTH`."""
    parts: dict[int, list[int]] = {}
    kinds: dict[int, str] = {}
    for relation, whole_name, parts_name in _DECOMPOSITIONS:
        try:
            relations = model.by_type(relation)
        except RuntimeError:  # not in this schema
            continue
        for rel in relations:
            whole = getattr(rel, whole_name, None)
            related = getattr(rel, parts_name, None)
            related = related if isinstance(related, (list, tuple)) else [related]
            if whole is None:
                continue
            for part in related:
                if part is None:
                    continue
                parts.setdefault(whole.id(), []).append(part.id())
                parts.setdefault(part.id(), [])
                kinds[whole.id()], kinds[part.id()] = whole.is_a(), part.is_a()
    check_chains(source, parts, kinds, "decompositions", MAX_DECOMPOSITION_DEPTH, CORPUS_DECOMPOSITION_DEPTH)


class UnbuiltElementsWarning(UserWarning):
    """Structural elements of the storey (walls, slabs) whose body geometry ifcopenshell could not
    build: they are left out of the scene, and the message names them.

    Attributes
    ----------
    source : str
        The file.
    elements : tuple of str
        ``#ID IfcClass 'Name'`` of each element left out.
    """

    def __init__(self, source: str, elements: Iterable[Any]) -> None:
        self.source = str(source)
        self.elements = tuple(f"#{e.id()} {e.is_a()} {getattr(e, 'Name', None)!r}" for e in elements)
        shown = ", ".join(self.elements[:5]) + (f" and {len(self.elements) - 5} more" if len(self.elements) > 5 else "")
        super().__init__(
            f"{self.source}: {len(self.elements)} structural element(s) have a body the geometry engine could not "
            f"build and were left out: {shown}"
        )


def _has_body(element: Any) -> bool:
    """Whether ``element`` has a body representation (an axis-only wall has none, and is not missed)."""
    shape = getattr(element, "Representation", None)
    return shape is not None and any(
        (r.RepresentationIdentifier or "").lower() == "body" for r in shape.Representations or ()
    )


#: IfcDimensionalExponents' attributes, in order (a length is 1, 0, 0, 0, 0, 0, 0).
_EXPONENTS = (
    "LengthExponent",
    "MassExponent",
    "TimeExponent",
    "ElectricCurrentExponent",
    "ThermodynamicTemperatureExponent",
    "AmountOfSubstanceExponent",
    "LuminousIntensityExponent",
)
#: What a length unit's conversion factor may be measured in (Revit writes a ratio, ArchiCAD a length).
_LENGTH_FACTORS = (
    "IfcLengthMeasure",
    "IfcPositiveLengthMeasure",
    "IfcRatioMeasure",
    "IfcPositiveRatioMeasure",
    "IfcNormalisedRatioMeasure",
    "IfcReal",
    "IfcNumericMeasure",
)


def _check_units(source: str, model: Any) -> None:
    """Every conversion-based unit converts by a positive number to a unit that does not lead back
    to it: ifcopenshell follows the chain without a cycle check (a unit converting to itself ran for
    ever, deaf to SIGTERM) and multiplies whatever the factor holds (a string: a TypeError)."""
    for unit in model.by_type("IfcConversionBasedUnit"):
        seen: list[int] = []
        node = unit
        while node is not None and node.is_a("IfcConversionBasedUnit"):
            if node.id() in seen:
                raise IfcError(source, f"the unit #{unit.id()} converts to itself (through #{node.id()})")
            seen.append(node.id())
            factor = getattr(node, "ConversionFactor", None)
            if factor is None or not factor.is_a("IfcMeasureWithUnit"):
                raise IfcError(source, f"the unit #{node.id()} has no conversion factor")
            value = getattr(factor.ValueComponent, "wrappedValue", factor.ValueComponent)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not (math.isfinite(value) and value > 0)
            ):
                raise IfcError(source, f"the unit #{node.id()} converts by {repr(value)[:40]}, not a positive number")
            if node.UnitType == "LENGTHUNIT":
                # A length converts by a length or a ratio to another length: an area's factor or
                # exponents were read as metres without a word.
                dims = getattr(node, "Dimensions", None)
                exponents = None if dims is None else [getattr(dims, n, 0) for n in _EXPONENTS]
                measure = factor.ValueComponent.is_a() if hasattr(factor.ValueComponent, "is_a") else None
                target = getattr(factor, "UnitComponent", None)
                # (All zero, as exporters copy an angle's, says nothing: ifcopenshell reads past it.)
                if exponents is not None and exponents not in ([1, 0, 0, 0, 0, 0, 0], [0] * 7):
                    raise IfcError(
                        source, f"the length unit #{node.id()} has the dimensions {exponents}, not a length's"
                    )
                if measure is not None and measure not in _LENGTH_FACTORS:
                    raise IfcError(
                        source, f"the length unit #{node.id()} converts by an {measure}, not a length or a ratio"
                    )
                if target is not None and getattr(target, "UnitType", "LENGTHUNIT") != "LENGTHUNIT":
                    raise IfcError(
                        source,
                        f"the length unit #{node.id()} converts to #{target.id()} ({target.UnitType}), no length unit",
                    )
            node = factor.UnitComponent
    for unit in model.by_type("IfcSIUnit"):
        # ifcopenshell's unit scale failed inside on another name ("'NoneType' object has no attribute").
        name = getattr(unit, "Name", None)
        if getattr(unit, "UnitType", None) == "LENGTHUNIT" and name != "METRE":
            shown = f"named {name[:40]}" if isinstance(name, str) else "not named by an SI name"
            raise IfcError(
                source,
                f"the SI length unit #{unit.id()} is {shown}, where IFC's is METRE (feet and inches are an "
                "IfcConversionBasedUnit)",
            )
    # The project's own assignment: a project library (IFC4) may hold one of areas alone.
    projects = model.by_type("IfcProject")
    if len(projects) > 1:  # IFC has one; which one's units a reader takes is its own choice
        raise IfcError(
            source,
            f"the file holds {len(projects)} IfcProject ({', '.join(f'#{p.id()}' for p in projects)}); IFC has one",
        )
    assignments = [p.UnitsInContext for p in projects if getattr(p, "UnitsInContext", None) is not None]
    for assignment in assignments:
        lengths = [u for u in assignment.Units or () if getattr(u, "UnitType", None) == "LENGTHUNIT"]
        if len(lengths) > 1:
            # The last was taken without a word: which unit the coordinates are in is the file's to say.
            raise IfcError(
                source,
                f"the unit assignment #{assignment.id()} names {len(lengths)} length units "
                f"({', '.join(f'#{u.id()}' for u in lengths)}); a project has one",
            )
        if not lengths:
            warnings.warn(
                f"{source}: the unit assignment #{assignment.id()} names no length unit; read in metres",
                stacklevel=3,
            )


def _check_si_prefixes(source: str, data: bytes) -> None:
    """Every SI unit's prefix is one IFC defines: ifcopenshell reads an unknown one as none at all,
    so a file in millimetres with a misspelt ``.MILI.`` was read in metres, without a word."""
    # Only the file's instances: not text inside a STEP string or a comment, which may say anything.
    data = _STEP_TEXT.sub(b" ", data)
    for found in _SI_UNIT.finditer(data):
        prefix = found.group(2).decode("ascii", "replace").upper()
        if prefix not in _SI_PREFIXES:
            unit = found.group(1).decode()
            raise IfcError(source, f"the unit #{unit} has the prefix {prefix[:20]!r}, which IFC does not define")


#: An SI unit's instance and its prefix, where it has one (``#2=IFCSIUNIT(*,.LENGTHUNIT.,.MILLI.,.METRE.)``).
_SI_UNIT = re.compile(rb"#(\d+)\s*=\s*IFCSIUNIT\s*\(\s*[^,]*,\s*\.\w+\.\s*,\s*\.(\w+)\.", re.IGNORECASE)
#: A STEP string ('...', a quote written twice) or comment (/* ... */) (ISO 10303-21).
# A string or comment never closed runs to the end (the last two branches): without them each later quote
# was tried as a start and scanned to the end, quadratic in the file.
_STEP_TEXT = re.compile(rb"'(?:[^']|'')*'|/\*.*?\*/|'[\s\S]*|/\*[\s\S]*", re.DOTALL)
#: IFC's SI prefixes (IfcSIPrefix).
_SI_PREFIXES = frozenset(
    ("EXA", "PETA", "TERA", "GIGA", "MEGA", "KILO", "HECTO", "DECA", "DECI", "CENTI", "MILLI", "MICRO", "NANO",
     "PICO", "FEMTO", "ATTO")
)  # fmt: skip


def _parse_error(ifcopenshell: Any, path: Path, exc: Exception) -> str:
    """What ifcopenshell's parser refused, from its log (its exception says "check logs", a log the
    user does not have): the token and its line where the log names an offset."""
    try:
        errors = [line for line in ifcopenshell.get_log().splitlines() if line.startswith("[error]")]
    except Exception:  # an ifcopenshell without the log
        errors = []
    if not errors:
        return f"{type(exc).__name__}: {exc}"
    last = re.sub(r"^\[error\]\s*(\[[^\]]*\])?\s*", "", errors[-1]).strip()
    found = re.search(r"token (\S+) at offset (\d+)", last)
    if found is None:
        return last[:200]
    with contextlib.suppress(OSError):
        data = path.read_bytes()  # sized before it was parsed
        line = data.count(b"\n", 0, int(found.group(2))) + 1
        return f"line {line}: {found.group(1)[:40]!r} is no valid STEP token (a number beyond the float range?)"
    return last[:200]


def _check_geometry_values(source: str, model: Any, scale: float) -> None:
    """Directions that point somewhere, finite points, and extrusions of a building's size: a zero
    axis divided by its length (a NaN storey and a misleading "no wall faces"), and a wall extruded
    1e300 m was dropped by the geometry engine without a word."""
    for direction in model.by_type("IfcDirection"):
        ratios = [float(r) for r in direction.DirectionRatios or ()]
        if not ratios or not all(math.isfinite(r) for r in ratios) or not any(ratios):
            raise IfcError(source, f"the direction #{direction.id()} {tuple(ratios)} points nowhere")
        if len(ratios) not in (2, 3):
            raise IfcError(source, f"the direction #{direction.id()} has {len(ratios)} components, not 2 or 3")
    for point in model.by_type("IfcCartesianPoint"):
        if not all(math.isfinite(float(c)) for c in point.Coordinates or ()):
            raise IfcError(source, f"the point #{point.id()} has a coordinate that is not a finite number")
        far = max((abs(float(c)) for c in point.Coordinates or ()), default=0.0) * scale
        if far > MAX_COORDINATE:
            # The geometry engine dropped what was placed there without a word (a storey's ceiling).
            raise IfcError(
                source,
                f"the point #{point.id()} lies {far:g} m from its placement's origin; a building's coordinates, "
                f"survey coordinates included, lie within {MAX_COORDINATE:,.0f} m (the file's length unit is "
                f"{scale:g} m: is it right?)",
            )
        if len(point.Coordinates or ()) not in (2, 3):
            raise IfcError(
                source, f"the point #{point.id()} has {len(point.Coordinates or ())} coordinates, not 2 or 3"
            )
    for solid in model.by_type("IfcExtrudedAreaSolid"):
        along = solid.ExtrudedDirection
        if along is not None and len(along.DirectionRatios or ()) != 3:
            # The engine read a 2-component direction as lying in the plan: a wall extruded sideways.
            raise IfcError(
                source,
                f"the extrusion #{solid.id()} runs along #{along.id()}, a direction of "
                f"{len(along.DirectionRatios or ())} components; an extrusion's has 3",
            )
    for operator in model.by_type("IfcCartesianTransformationOperator"):
        for name in ("Scale", "Scale2", "Scale3"):
            try:
                value = getattr(operator, name)
            except AttributeError:  # a 2-D operator has no third
                continue
            if value is not None and not (math.isfinite(float(value)) and float(value) > 0):
                raise IfcError(
                    source, f"the transformation #{operator.id()} scales by {float(value):g}; a scale is a number > 0"
                )
    for solid in model.by_type("IfcExtrudedAreaSolid"):
        depth = float(solid.Depth) * scale
        if not (math.isfinite(depth) and MIN_EXTRUSION <= depth <= MAX_EXTRUSION):
            raise IfcError(
                source,
                f"the extrusion #{solid.id()} is {float(solid.Depth):g} units ({depth:g} m) deep; an element of a "
                f"storey is {MIN_EXTRUSION:g} to {MAX_EXTRUSION:,.0f} m deep (the file's length unit is {scale:g} m: "
                "is it right?)",
            )


def load_ifc_scene(
    path: str | Path,
    *,
    storey: str | int | None = None,
    class_map: Mapping[str, SurfaceClass | None] | None = None,
    name: str | None = None,
    doors: str = "open",
) -> Scene:
    """Load one storey of an IFC file as a labelled scene with rooms and doors.

    Parameters
    ----------
    path : str or Path
        An IFC file (any schema ifcopenshell reads: IFC2X3, IFC4, IFC4X3).
    storey : str or int, optional
        ``Name`` or ``LongName`` of the storey, or its index in the storeys sorted by elevation
        (negative counts from the top). Default: the storey nearest elevation 0. A string names a
        storey first: ``"1"`` is the storey named ``1`` where there is one, else the index 1 (the
        command line's ``--storey`` passes its text so); an int is always an index. A name that
        several storeys carry is refused: pass the index.
    class_map : mapping, optional
        Entries merged over :data:`DEFAULT_CLASS_MAP` (IFC class or ``Class.PREDEFINEDTYPE`` ->
        SurfaceClass, or None to leave such elements out).
    name : str, optional
        Name of the scene; default ``"<path>#<storey name>"``.
    doors : {"open", "closed"}
        ``"open"`` keeps only each door's frame (module docstring), ``"closed"`` meshes doors as drawn.

    Returns
    -------
    Scene
        World coordinates in metres, z up. ``face_labels`` (F,) uint8, ``face_rooms`` (F,) int32
        indexing ``rooms`` (from ``IfcSpace``) or -1, ``doors`` (from ``IfcDoor``), and ``metadata``
        with ``source``, ``format`` ("ifc"), ``schema``, ``storey`` (its name), ``storey_index``,
        ``elevation`` and ``height`` (m).

    Raises
    ------
    MissingDependencyError
        ifcopenshell is not installed.
    SceneFileError
        The file does not exist.
    IfcError
        The file is not IFC, has no storey, the storey is unknown or its name ambiguous, ``class_map`` names an unknown
        class, or the storey has no wall faces.
    MissingStructureError
        The storey has walls but no floor faces.
    """
    path = Path(path)
    source = str(path)
    if doors not in DOOR_MODES:
        raise IfcError(source, f"doors must be one of {', '.join(DOOR_MODES)}, got {doors!r}")
    try:
        import ifcopenshell
        import ifcopenshell.geom
        import ifcopenshell.util.element
        import ifcopenshell.util.placement
        import ifcopenshell.util.unit
    except ImportError as exc:
        raise MissingDependencyError(source, _INSTALL_HINT) from exc
    if not path.is_file():
        raise SceneFileError(source, "no such file" if not path.exists() else "not a regular file")
    _check_complete(source, path)
    try:
        check_file_size(source, path.stat().st_size)
        # Cycles and deep chains of references are refused before ifcopenshell follows them.
        data = path.read_bytes()
        check_references(source, data)
        _check_si_prefixes(source, data)
    except OSError as exc:
        raise SceneFileError(source, f"cannot read the file: {exc.strerror or exc}") from exc
    try:
        if data.startswith(codecs.BOM_UTF8):
            # Editors on Windows write a UTF-8 byte-order mark before "ISO-10303-21;"; ifcopenshell
            # then found no schema ("No support for file schema encountered ()"). Read past it.
            try:
                text = data[len(codecs.BOM_UTF8) :].decode("utf-8")
            except UnicodeDecodeError as exc:
                raise IfcError(source, f"starts with a UTF-8 byte-order mark but is not UTF-8 text ({exc})") from None
            model = ifcopenshell.file.from_string(text)
        else:
            model = ifcopenshell.open(str(path))
    except IfcError:
        raise
    except Exception as exc:  # ifcopenshell raises its own error types, or OSError, for bad input
        raise IfcError(source, f"cannot read as IFC: {_parse_error(ifcopenshell, path, exc)}") from exc
    del data
    _check_placements(source, model)
    _check_decomposition(source, model)

    _check_units(source, model)
    try:
        scale = float(ifcopenshell.util.unit.calculate_unit_scale(model))
    except Exception as exc:  # ifcopenshell's own errors for a unit it cannot follow
        raise IfcError(source, f"the length unit cannot be read: {type(exc).__name__}: {exc}") from None
    if not (math.isfinite(scale) and scale > 0):
        raise IfcError(source, f"the length unit is {scale:g} metres, not a length")
    _check_geometry_values(source, model, scale)
    mapping = _merge_class_map(source, model, class_map)
    storeys = _sorted_storeys(source, model, scale)
    if not storeys:
        raise IfcError(source, "no storey: the file has no IfcBuildingStorey")
    index = _select_storey(source, storeys, storey)
    chosen = storeys[index]
    elevation = chosen.elevation

    decomposition = ifcopenshell.util.element.get_decomposition(chosen.entity)
    on_storey = {e.id(): e for e in decomposition if e.is_a("IfcProduct")}
    classes: dict[int, SurfaceClass] = {}
    for eid, element in on_storey.items():
        if element.is_a("IfcElement") and (cls := _element_class(element, mapping, model)) is not None:
            classes[eid] = cls
    horizontal = (SurfaceClass.FLOOR, SurfaceClass.CEILING)
    others = [
        e
        for e in model.by_type("IfcElement")
        if e.id() not in on_storey and _is_bounding_kind(e) and _element_class(e, mapping, model) in horizontal
    ]
    spaces = [e for e in on_storey.values() if e.is_a("IfcSpace") and not _is_external(e)]
    door_elements = [e for e in on_storey.values() if e.is_a("IfcDoor")]
    # Doors are meshed even when left out of the scene: their geometry gives the Door ground truth.
    wanted = {e.id(): e for e in [*(on_storey[i] for i in classes), *others, *spaces, *door_elements]}
    shapes = _triangulate(source, ifcopenshell, model, wanted.values())
    offset = _survey_offset(source, chosen, shapes, classes)
    if offset is not None:
        shapes = {i: (verts - [offset[0], offset[1], 0.0], tris) for i, (verts, tris) in shapes.items()}
    unbuilt = [
        on_storey[i]
        for i, c in classes.items()
        if c in STRUCTURAL_CLASSES and i not in shapes and _has_body(on_storey[i])
    ]
    if unbuilt:
        warnings.warn(UnbuiltElementsWarning(source, unbuilt), stacklevel=2)

    wall_ids = [i for i, c in classes.items() if c == SurfaceClass.WALL and i in shapes]
    if not wall_ids:
        raise IfcError(
            source,
            f"storey {chosen.name!r} has no wall faces (no IfcWall, or none with body geometry); "
            f"storeys: {'; '.join(s.describe(i) for i, s in enumerate(storeys))}",
        )
    if index + 1 < len(storeys):
        top = storeys[index + 1].elevation
    else:
        top = max(float(shapes[i][0][:, 2].max()) for i in wall_ids)
    plan = shapely.convex_hull(shapely.multipoints(np.concatenate([shapes[i][0][:, :2] for i in wall_ids])))
    _place_slabs(classes, on_storey, shapes, elevation, top)
    classes.update(_bounding_elements(others, shapes, plan, elevation, top))

    meshed = dict(shapes)
    if doors == "open":
        for door in door_elements:
            if door.id() in meshed and door.id() in classes:
                meshed[door.id()] = _door_frame(door, *shapes[door.id()])
    vertices, faces, labels = _assemble(meshed, classes)
    if not np.any(labels == SurfaceClass.FLOOR):
        raise MissingStructureError(
            source, f"storey {chosen.name!r} has no floor faces (no slab at its elevation {elevation:.2f} m)"
        )
    # Before splitting long faces: a storey kilometres wide (a file whose units say kilometres) would
    # be cut into more triangles than memory holds before the scene's own check saw its size.
    check_storey_size(source, vertices[np.unique(faces)] if len(faces) else vertices[:0], len(faces), stated=True)
    structural = np.isin(labels, [c.value for c in SurfaceClass if c.is_structural])
    vertices, faces, origin = split_long_faces(vertices, faces, MAX_FACE_EDGE, structural)
    labels = labels[origin]
    mesh = trimesh.Trimesh(vertices, faces, process=False, validate=False)

    rooms = _rooms(spaces, shapes)
    spaces_used = bool(rooms)
    if not rooms:
        # Files that name no spaces get rooms from the floor's free space, and their doors those.
        rooms = derive_rooms(Scene(mesh, labels, name=source))
    face_rooms = (
        _face_rooms(mesh, rooms) if spaces_used else rooms_by_probe(rooms, mesh.triangles_center, mesh.face_normals)
    )
    door_list = _doors(door_elements, shapes, rooms, scale)
    start = _file_start(source, chosen, on_storey.values(), scale)
    return Scene(
        mesh,
        labels,
        face_rooms,
        rooms=rooms,
        doors=door_list,
        start=None if start is None else start - (0.0 if offset is None else offset),
        name=name if name is not None else f"{source}#{chosen.name}",
        metadata={
            "source": source,
            "format": "ifc",
            "schema": str(model.schema),
            "storey": chosen.name,
            "storey_index": index,
            "elevation": elevation,
            "height": top - elevation,
            "rooms": "file" if spaces_used else "derived" if rooms else "none",
            # Where the file's frame lies in the scene's: file xy = scene xy + offset (metres).
            "offset": None if offset is None else [float(v) for v in offset],
        },
    )


# ------------------------------------------------------------------------------------- storeys
def _sorted_storeys(source: str, model: Any, scale: float) -> list[_Storey]:
    import ifcopenshell.util.placement

    storeys = []
    for order, entity in enumerate(model.by_type("IfcBuildingStorey")):
        if entity.ObjectPlacement is not None:
            # The placement's world z agrees with the world-coordinate geometry even when the
            # building itself is placed above the project origin; Elevation need not.
            z = float(ifcopenshell.util.placement.get_local_placement(entity.ObjectPlacement)[2, 3]) * scale
        else:
            z = float(entity.Elevation or 0.0) * scale
        if not (math.isfinite(z) and abs(z) <= MAX_ELEVATION):
            # It would sort first or last and shift every index (--storey 0 another storey).
            raise IfcError(
                source,
                f"the storey #{entity.id()} {entity.Name!r:.40} lies at {z:g} m; storeys lie within "
                f"{MAX_ELEVATION:,.0f} m of the origin (the file's length unit is {scale:g} m: is it right?)",
            )
        storeys.append((z, order, _Storey(entity, entity.Name or f"#{entity.id()}", entity.LongName or "", z)))
    return [s for _, _, s in sorted(storeys, key=lambda t: (t[0], t[1]))]


def _select_storey(source: str, storeys: list[_Storey], storey: str | int | None) -> int:
    listing = "; ".join(s.describe(i) for i, s in enumerate(storeys))
    if storey is None:
        # Nearest to 0; sorted ascending, so min() keeps the lower storey on a tie.
        return min(range(len(storeys)), key=lambda i: abs(storeys[i].elevation))
    if isinstance(storey, bool) or not isinstance(storey, (str, int, np.integer)):
        raise IfcError(source, f"storey must be a name or an index, got {storey!r}; storeys: {listing}")
    if isinstance(storey, str):
        # A name that matches exactly wins; only then is text that reads as an integer an index, so that
        # "--storey 1" reaches a storey named "1" and the second storey of a file that names none so.
        named = [i for i, s in enumerate(storeys) if storey in (s.name, s.long_name)]
        if len(named) > 1:
            raise IfcError(
                source,
                f"{len(named)} storeys are named {storey!r}, indices {', '.join(map(str, named))}: pass the index "
                f"instead (--storey {named[0]}, load_scene's storey={named[0]}); storeys: {listing}",
            )
        if named:
            return named[0]
        try:
            index = int(storey)
        except ValueError:
            raise IfcError(source, f"no storey named {storey!r}; storeys: {listing}") from None
        if not -len(storeys) <= index < len(storeys):
            raise IfcError(source, f"no storey named {storey!r}, and index {index} is out of range; storeys: {listing}")
        return index % len(storeys)
    n = len(storeys)
    if not -n <= int(storey) < n:
        raise IfcError(source, f"storey index {storey} is out of range; storeys: {listing}")
    return int(storey) % n


# ------------------------------------------------------------------------------------- classes
def _merge_class_map(
    source: str, model: Any, class_map: Mapping[str, SurfaceClass | None] | None
) -> dict[str, SurfaceClass | None]:
    """The lower-cased merged table; user keys are checked against the file's schema."""
    import ifcopenshell.ifcopenshell_wrapper as wrapper

    schema = wrapper.schema_by_name(model.schema_identifier)
    merged: dict[str, SurfaceClass | None] = {k.lower(): v for k, v in DEFAULT_CLASS_MAP.items()}
    for key, value in (class_map or {}).items():
        cls_name = str(key).split(".", 1)[0]
        try:
            schema.declaration_by_name(cls_name)
        except Exception:
            raise IfcError(source, f"class_map: {key!r} is no IFC class of schema {model.schema_identifier}") from None
        if value is not None and not isinstance(value, SurfaceClass):
            try:
                value = SurfaceClass(value)
            except ValueError:
                raise IfcError(source, f"class_map[{key!r}] = {value!r} is no SurfaceClass") from None
        merged[str(key).lower()] = value
    return merged


def _class_chain(model: Any, ifc_class: str) -> list[str]:
    """``ifc_class`` and its supertypes, most specific first."""
    import ifcopenshell.ifcopenshell_wrapper as wrapper

    decl = wrapper.schema_by_name(model.schema_identifier).declaration_by_name(ifc_class)
    chain = []
    while decl is not None:
        chain.append(decl.name())
        decl = decl.supertype()
    return chain


def _lookup(element: Any, mapping: Mapping[str, SurfaceClass | None], model: Any) -> SurfaceClass | None:
    import ifcopenshell.util.element

    ptype = ifcopenshell.util.element.get_predefined_type(element)
    for cls_name in _class_chain(model, element.is_a()):
        if ptype and f"{cls_name}.{ptype}".lower() in mapping:
            return mapping[f"{cls_name}.{ptype}".lower()]
        if cls_name.lower() in mapping:
            return mapping[cls_name.lower()]
    return None


def _whole(element: Any) -> Any:
    """The outermost element that ``element`` is (recursively) an aggregated part of, or itself."""
    import ifcopenshell.util.element

    whole = element
    while (parent := ifcopenshell.util.element.get_aggregate(whole)) is not None and parent.is_a("IfcElement"):
        whole = parent
    return whole


def _element_class(element: Any, mapping: Mapping[str, SurfaceClass | None], model: Any) -> SurfaceClass | None:
    """The class of an element: that of the element it is part of, if any, else its own entry."""
    return _lookup(_whole(element), mapping, model)


def _is_bounding_kind(element: Any) -> bool:
    """Slabs, coverings and roofs, or parts of one: the elements that may close another storey."""
    return any(e.is_a(c) for e in (element, _whole(element)) for c in _BOUNDING_CLASSES)


def _place_slabs(
    classes: dict[int, SurfaceClass],
    on_storey: Mapping[int, Any],
    shapes: Mapping[int, tuple[np.ndarray, np.ndarray]],
    elevation: float,
    top: float,
) -> None:
    """Make the storey's own slabs FLOOR below the storey's middle height and CEILING above it."""
    middle = 0.5 * (elevation + top)
    for eid, cls in list(classes.items()):
        element = on_storey[eid]
        if cls not in (SurfaceClass.FLOOR, SurfaceClass.CEILING) or eid not in shapes:
            continue
        # A slab that is part of a roof or another whole keeps the class of that whole.
        if element.is_a("IfcSlab") and _whole(element).id() == element.id():
            z = shapes[eid][0][:, 2]
            classes[eid] = SurfaceClass.FLOOR if 0.5 * (z.min() + z.max()) < middle else SurfaceClass.CEILING


def _bounding_elements(
    others: list[Any],
    shapes: Mapping[int, tuple[np.ndarray, np.ndarray]],
    plan: shapely.Geometry,
    elevation: float,
    top: float,
) -> dict[int, SurfaceClass]:
    """Elements of other storeys that close this one: CEILING from above, FLOOR from below."""
    found = {}
    for element in others:
        if element.id() not in shapes:
            continue
        verts = shapes[element.id()][0]
        if not _overlaps_in_plan(verts, plan):
            continue
        if abs(float(verts[:, 2].min()) - top) <= BOUNDING_TOLERANCE:
            found[element.id()] = SurfaceClass.CEILING
        elif abs(float(verts[:, 2].max()) - elevation) <= BOUNDING_TOLERANCE:
            found[element.id()] = SurfaceClass.FLOOR
    return found


# ------------------------------------------------------------------------------------ geometry
def _triangulate(
    source: str, ifcopenshell: Any, model: Any, elements: Iterable[Any]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """World-coordinate triangles of each element: id -> (vertices (n, 3) float, faces (m, 3) int)."""
    elements = list(elements)
    if not elements:
        return {}
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    shapes: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    try:
        iterator = ifcopenshell.geom.iterator(settings, model, max(1, os.cpu_count() or 1), include=elements)
        if not iterator.initialize():
            return shapes
        while True:
            shape = iterator.get()
            verts = np.asarray(shape.geometry.verts, dtype=float).reshape(-1, 3)
            faces = np.asarray(shape.geometry.faces, dtype=np.int64).reshape(-1, 3)
            if len(faces):
                shapes[int(shape.id)] = (verts, faces)
            if not iterator.next():
                break
    except Exception as exc:
        raise IfcError(source, f"the geometry engine failed: {type(exc).__name__}: {exc}") from exc
    return shapes


def _assemble(
    shapes: Mapping[int, tuple[np.ndarray, np.ndarray]], classes: Mapping[int, SurfaceClass]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate the classified elements in id order (the iterator's order depends on threads)."""
    verts, faces, labels = [], [], []
    offset = 0
    for eid in sorted(i for i in classes if i in shapes):
        v, f = shapes[eid]
        verts.append(v)
        faces.append(f + offset)
        labels.append(np.full(len(f), classes[eid].value, dtype=np.uint8))
        offset += len(v)
    if not faces:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.uint8)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(labels)


def _overlaps_in_plan(verts: np.ndarray, plan: shapely.Geometry) -> bool:
    """Whether an element's plan hull covers at least a quarter of the smaller of it and ``plan``."""
    hull = shapely.convex_hull(shapely.multipoints(verts[:, :2]))
    if hull.area <= 0 or plan.area <= 0:
        return False
    return hull.intersection(plan).area >= 0.25 * min(hull.area, plan.area)


# ------------------------------------------------------------------------------- ground truth
def _is_external(space: Any) -> bool:
    """Whether the file marks an ``IfcSpace`` as outside (module docstring)."""
    import ifcopenshell.util.element

    if str(getattr(space, "PredefinedType", None) or "").upper() == "EXTERNAL":
        return True
    common = ifcopenshell.util.element.get_psets(space).get("Pset_SpaceCommon", {})
    return common.get("IsExternal") is True


def _survey_offset(
    source: str, chosen: _Storey, shapes: Mapping[int, tuple[np.ndarray, np.ndarray]], classes: Mapping[int, Any]
) -> np.ndarray | None:
    """The plan offset that brings a storey placed at survey coordinates near the origin, or None.

    Authoring tools export "shared" or survey coordinates (a storey at UTM 600,000, 5,800,000 m):
    IFC bounds no placement, and the geometry is relative, but float32 ray casting loses millimetres
    beyond :data:`~scenes.limits.MAX_ORIGIN_DISTANCE`. Such a storey is moved by whole metres (its
    walls' lowest corner) and a warning says by how much; ``Scene.metadata["offset"]`` keeps it.
    """
    walls = [shapes[i][0] for i, c in classes.items() if c == SurfaceClass.WALL and i in shapes]
    if not walls:
        return None
    points = np.concatenate(walls)
    if np.abs(points[:, :2]).max() <= MAX_ORIGIN_DISTANCE:
        return None
    offset = np.floor(points[:, :2].min(axis=0))
    warnings.warn(
        f"{source}: storey {chosen.name!r} lies at survey coordinates ({offset[0]:,.0f}, {offset[1]:,.0f}) m, "
        f"beyond {MAX_ORIGIN_DISTANCE:,.0f} m of the origin: it is moved by that offset, and every position "
        "nbs-env reports for it is in the moved frame (Scene.metadata['offset'], metrics.json's scene_offset_m)",
        stacklevel=3,
    )
    return offset


def _file_start(source: str, chosen: _Storey, elements: Iterable[Any], scale: float) -> np.ndarray | None:
    """The robot's start the file places on the storey (module docstring), world metres, or None.

    Raises
    ------
    IfcError
        The storey's ``Pset_NbsStart`` lacks ``StartX`` or ``StartY``, or one is no number (a label
        ``'6.0'`` was dropped for the automatic start, a boolean taken as 1 m).
    """
    import ifcopenshell.util.element
    import ifcopenshell.util.placement

    def placement(entity: Any) -> np.ndarray:
        if entity.ObjectPlacement is None:
            return np.eye(4)
        return np.asarray(ifcopenshell.util.placement.get_local_placement(entity.ObjectPlacement), dtype=float)

    storey = chosen.entity
    props = ifcopenshell.util.element.get_psets(storey).get("Pset_NbsStart")
    if props is not None:
        measures = _start_measures(storey)
        for key in ("StartX", "StartY"):
            value = props.get(key)
            kind = measures.get(key)
            if type(value) not in (int, float) or not math.isfinite(value) or kind not in _START_MEASURES:
                shown = "missing" if value is None else f"{value!r} ({kind or type(value).__name__})"
                raise IfcError(
                    source,
                    f"storey {chosen.name!r}: Pset_NbsStart.{key} is {shown}; the start is two lengths, "
                    "StartX and StartY (IfcLengthMeasure), in the storey's coordinates",
                )
        local = np.array([props["StartX"], props["StartY"], 0.0, 1.0], dtype=float)
        return (placement(storey) @ local)[:2] * scale
    for element in elements:
        if element.is_a("IfcAnnotation") and "Pset_NbsStart" in ifcopenshell.util.element.get_psets(element):
            return placement(element)[:2, 3] * scale
    return None


#: The IFC types a start coordinate may be written in: lengths, and a plain real (read in the file's length unit).
_START_MEASURES = (
    "IfcLengthMeasure",
    "IfcPositiveLengthMeasure",
    "IfcNonNegativeLengthMeasure",
    "IfcReal",
)


def _start_measures(storey: Any) -> dict[str, str]:
    """The IFC type of each value of the storey's ``Pset_NbsStart`` (``{"StartX": "IfcLengthMeasure"}``):
    an angle, an area or a time comes back from the property reader a float like a length."""
    kinds: dict[str, str] = {}
    for rel in getattr(storey, "IsDefinedBy", None) or ():
        if not rel.is_a("IfcRelDefinesByProperties"):
            continue
        for pset in _property_sets(rel.RelatingPropertyDefinition):
            if not pset.is_a("IfcPropertySet") or pset.Name != "Pset_NbsStart":
                continue
            for prop in pset.HasProperties or ():
                value = getattr(prop, "NominalValue", None)
                if value is not None:
                    # A unit of its own (feet, millimetres) is not the file's length unit the start is
                    # read in: 6 ft was taken as 6 m.
                    unit = getattr(prop, "Unit", None)
                    kinds[prop.Name] = value.is_a() if unit is None else f"{value.is_a()} in a unit of its own"
    return kinds


def _property_sets(definition: Any) -> list[Any]:
    """The property sets a relation's ``RelatingPropertyDefinition`` holds: one, or, in IFC4, an
    ``IfcPropertySetDefinitionSet`` of several (as the property reader finds them)."""
    if isinstance(definition, (tuple, list)):
        return list(definition)
    if definition is not None and definition.is_a("IfcPropertySetDefinitionSet"):
        return list(definition.wrappedValue)
    return [] if definition is None else [definition]


def _rooms(spaces: list[Any], shapes: Mapping[int, tuple[np.ndarray, np.ndarray]]) -> list[Room]:
    rooms: list[Room] = []
    for space in sorted(spaces, key=lambda s: s.id()):
        if space.id() not in shapes:
            continue
        verts, faces = shapes[space.id()]
        polygon = footprint_polygon(verts[faces])
        if polygon is None:
            continue
        label = space.LongName or space.Name or f"space #{space.id()}"
        rooms.append(Room(len(rooms), label, polygon, float(verts[:, 2].min()), float(verts[:, 2].max())))
    return rooms


def _face_rooms(mesh: trimesh.Trimesh, rooms: list[Room]) -> np.ndarray:
    """Room of each face: the room whose prism holds the point 0.1 m in front of its centroid."""
    result = np.full(len(mesh.faces), -1, dtype=np.int32)
    probe = mesh.triangles_center + _FACE_PROBE * mesh.face_normals
    for room in rooms:
        inside = shapely.contains_xy(shapely.Polygon(room.polygon), probe[:, 0], probe[:, 1])
        inside &= (probe[:, 2] >= room.floor_z - ROOM_Z_TOLERANCE) & (probe[:, 2] <= room.ceiling_z + ROOM_Z_TOLERANCE)
        result[inside & (result < 0)] = room.id
    return result


def _room_at(rooms: list[Room], xy: np.ndarray) -> int:
    for room in rooms:
        if shapely.contains_xy(shapely.Polygon(room.polygon), float(xy[0]), float(xy[1])):
            return room.id
    return -1


def _door_axes(door: Any, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two horizontal unit axes for a door: its placement's x axis and the perpendicular.

    The placement gives exact axes where the smallest rectangle around the geometry can tilt by a
    degree for a handle or an asymmetric frame; that rectangle is only the fallback.
    """
    import ifcopenshell.util.placement

    if door.ObjectPlacement is not None:
        x_axis = ifcopenshell.util.placement.get_local_placement(door.ObjectPlacement)[:2, 0]
        if np.linalg.norm(x_axis) > 0.5:
            u = x_axis / np.linalg.norm(x_axis)
            return u, np.array([-u[1], u[0]])
    rect = shapely.minimum_rotated_rectangle(shapely.multipoints(verts[:, :2]))
    corners = np.asarray(getattr(rect, "exterior", rect).coords)
    edge = corners[1] - corners[0] if len(corners) > 1 else np.array([1.0, 0.0])
    if np.linalg.norm(edge) == 0:
        edge = np.array([1.0, 0.0])
    u = edge / np.linalg.norm(edge)
    return u, np.array([-u[1], u[0]])


def _door_frame(door: Any, verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frame of a door element: its triangles within :data:`DOOR_FRAME` of its sides or top."""
    u, _ = _door_axes(door, verts)
    pu = verts[:, :2] @ u
    normal_extent = np.ptp(verts[:, :2] @ np.array([-u[1], u[0]]))
    if np.ptp(pu) < normal_extent:  # the placement's x axis runs across the wall: width is the other
        u = np.array([-u[1], u[0]])
        pu = verts[:, :2] @ u
    tri_u, tri_z = pu[faces], verts[faces][..., 2]
    lo, hi, top = pu.min(), pu.max(), verts[:, 2].max()
    side = (tri_u.max(axis=1) <= lo + DOOR_FRAME) | (tri_u.min(axis=1) >= hi - DOOR_FRAME)
    keep = side | (tri_z.min(axis=1) >= top - DOOR_FRAME)
    return verts, faces[keep]


def _doors(
    doors: list[Any], shapes: Mapping[int, tuple[np.ndarray, np.ndarray]], rooms: list[Room], scale: float
) -> list[Door]:
    result = []
    for door in sorted(doors, key=lambda d: d.id()):
        if door.id() not in shapes:
            continue
        verts = shapes[door.id()][0]
        u, v = _door_axes(door, verts)
        pu, pv = verts[:, :2] @ u, verts[:, :2] @ v
        centre = u * 0.5 * (pu.min() + pu.max()) + v * 0.5 * (pv.min() + pv.max())
        extent_u, extent_v = float(np.ptp(pu)), float(np.ptp(pv))
        # The door's normal is its horizontal axis of least extent: across the wall.
        normal, geometric_width = (v, extent_u) if extent_u >= extent_v else (u, extent_v)
        width = float(door.OverallWidth) * scale if door.OverallWidth else geometric_width
        z0, z1 = float(verts[:, 2].min()), float(verts[:, 2].max())
        height = float(door.OverallHeight) * scale if door.OverallHeight else z1 - z0
        a = _room_at(rooms, centre - _DOOR_PROBE * normal)
        b = _room_at(rooms, centre + _DOOR_PROBE * normal)
        # Canonical order: a room before the outside, else the lower id first.
        if (a < 0 <= b) or (0 <= b < a):
            a, b, normal = b, a, -normal
        result.append(Door((a, b), np.array([centre[0], centre[1], z0]), width, height, normal + 0.0))
    return result
