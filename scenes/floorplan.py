"""Floor plans: a versioned JSON format for storeys, and its extrusion into a labelled mesh.

Format ``nbs-floorplan`` version 1
----------------------------------
All lengths in metres, angles in degrees, x/y horizontal, the floor at z = 0::

    {
      "format": "nbs-floorplan",          # required, fixed
      "version": 1,                       # required; the only version so far
      "name": "office",                   # optional
      "ceiling_height": 2.7,              # > 0, at most 30
      "wall_thickness": 0.15,             # > 0, at most 3
      "rooms": [                          # >= 1 rooms
        {"name": "office", "polygon": [[0, 0], [6, 0], [6, 4], [0, 4]]}
      ],
      "doors": [                          # optional
        {"rooms": ["a", "b"], "position": [3, 4], "width": 0.9, "height": 2.05}
      ],
      "windows": [                        # optional, on outside walls
        {"room": "a", "position": [0, 2], "width": 1.2, "height": 1.2, "sill": 0.9}
      ],
      "clutter": [                        # optional
        {"kind": "cabinet", "position": [1, 3.6], "size": [1.2, 0.5, 1.9], "yaw": 0}
      ],
      "start": [3, 2]                     # optional; chosen automatically when absent
    }

- **Room polygons are wall centre lines.** Neighbouring rooms share edges; the building's walls of
  ``wall_thickness`` are centred on them, so a room's clear floor is its polygon inset by half the
  thickness (mitred corners). Polygons may be concave and need not have right angles; they must be
  simple (no self-intersection), and either orientation is accepted.
- **Doors** are openings in the wall shared by their two rooms: ``position`` is the centre of the
  opening on the centre line. The extruded door has jambs, a lintel soffit and a threshold, all
  labelled DOOR; the opening itself is open.
- **Windows** are on a room's outside wall; the opening holds a pane labelled WINDOW, flush with the
  inner face, so no ray leaves the building.
- **Clutter** ``kind`` is one of :data:`CLUTTER_KINDS`. ``position`` is the centre of the footprint;
  ``size`` is ``[length, depth, height]`` in the object's frame; ``yaw`` turns the length axis from +x
  counter-clockwise. Objects that stand against a wall have their back on the local +y side. No
  object may be taller than the ceiling; a ``column`` always reaches it, whatever its height says.
- Only the inner faces of the building are built (no outside faces): nothing outside is ever seen,
  and the structural area must not count surfaces no scanner can reach.
- **Bounds**: coordinates within ±100 km (:data:`MAX_COORDINATE`; :func:`scenes.load_scene` loads
  storeys within 10 km of the origin, :data:`scenes.limits.MAX_ORIGIN_DISTANCE`), sizes and door or window
  dimensions at most 100 m (:data:`MAX_LENGTH`), ceilings at most 30 m (and, when loaded, at least
  1.5 m: :data:`scenes.limits.MIN_STOREY_HEIGHT`), walls at most 3 m thick;
  NaN and infinities are refused with the rest.
"""

from __future__ import annotations

import json
import math
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
import trimesh
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry.polygon import orient

from scenes.errors import FloorPlanError, PlanGeometryError, SceneFileError
from scenes.geometry import STOREY_CLEARANCE
from scenes.jsonio import JSONSizeError, json_text, read_json_file
from scenes.limits import MIN_STOREY_HEIGHT
from scenes.model import Door, Room, Scene, SurfaceClass
from scenes.validation import start_within_check, validate_plan_scene

__all__ = [
    "CLUTTER_KINDS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "PLAN_SCHEMA",
    "ClutterPlan",
    "DoorPlan",
    "FloorPlan",
    "RoomPlan",
    "WindowPlan",
    "extrude",
    "load_plan",
]

FORMAT_NAME = "nbs-floorplan"
FORMAT_VERSION = 1
CLUTTER_KINDS = ("box", "cabinet", "shelf", "table", "chair", "column", "sofa")
#: Kinds that the generator stands with their back against a wall.
WALL_STANDING_KINDS = ("cabinet", "shelf", "sofa", "box")
#: The clear floor kept free of clutter on both sides of a door: the storey's clearance.
DOOR_CLEARANCE = STOREY_CLEARANCE

#: Largest coordinate magnitude and largest length a plan may hold, metres: beyond them a plan is a
#: mistake (a unit slip, an overflow), and the extrusion would build a mesh of no use.
MAX_COORDINATE = 1e5
MAX_LENGTH = 100.0
_COORDINATE = {"type": "number", "minimum": -MAX_COORDINATE, "maximum": MAX_COORDINATE}
_POINT = {"type": "array", "items": _COORDINATE, "minItems": 2, "maxItems": 2}
#: The shortest length a plan may give (a millimetre): below it a wall strip or a face has no area
#: a float keeps (a 1e-320 m sill made zero-area faces and overflow warnings).
MIN_LENGTH = 0.001
_POSITIVE = {"type": "number", "minimum": MIN_LENGTH, "maximum": MAX_LENGTH}
PLAN_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "nbs-env floor plan, version 1",
    "type": "object",
    "required": ["format", "version", "ceiling_height", "wall_thickness", "rooms"],
    "additionalProperties": False,
    "properties": {
        "format": {"const": FORMAT_NAME},
        "version": {"const": FORMAT_VERSION},
        "name": {"type": "string"},
        "description": {"type": "string"},
        "ceiling_height": {"type": "number", "minimum": MIN_LENGTH, "maximum": 30},
        "wall_thickness": {"type": "number", "minimum": MIN_LENGTH, "maximum": 3},
        "rooms": {
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "object",
                "required": ["name", "polygon"],
                "additionalProperties": False,
                "properties": {
                    "name": {"type": "string", "minLength": 1},
                    "polygon": {"type": "array", "items": _POINT, "minItems": 3},
                },
            },
        },
        "doors": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["rooms", "position", "width", "height"],
                "additionalProperties": False,
                "properties": {
                    "rooms": {
                        "type": "array",
                        "items": {"type": "string"},
                        "minItems": 2,
                        "maxItems": 2,
                    },
                    "position": _POINT,
                    "width": _POSITIVE,
                    "height": _POSITIVE,
                },
            },
        },
        "windows": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["room", "position", "width", "height", "sill"],
                "additionalProperties": False,
                "properties": {
                    "room": {"type": "string"},
                    "position": _POINT,
                    "width": _POSITIVE,
                    "height": _POSITIVE,
                    "sill": {"anyOf": [{"const": 0}, _POSITIVE]},  # at the floor, or a millimetre up
                },
            },
        },
        "clutter": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["kind", "position", "size"],
                "additionalProperties": False,
                "properties": {
                    "kind": {"enum": list(CLUTTER_KINDS)},
                    "position": _POINT,
                    "size": {
                        "type": "array",
                        "items": _POSITIVE,
                        "minItems": 3,
                        "maxItems": 3,
                    },
                    "yaw": {"type": "number", "minimum": -3600, "maximum": 3600},
                },
            },
        },
        "start": _POINT,
    },
}


# ---------------------------------------------------------------------------------------- the plan
@dataclass(frozen=True)
class RoomPlan:
    name: str
    polygon: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class DoorPlan:
    rooms: tuple[str, str]
    position: tuple[float, float]
    width: float = 0.9
    height: float = 2.05


@dataclass(frozen=True)
class WindowPlan:
    room: str
    position: tuple[float, float]
    width: float = 1.2
    height: float = 1.2
    sill: float = 0.9


@dataclass(frozen=True)
class ClutterPlan:
    kind: str
    position: tuple[float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0

    def footprint(self) -> Polygon:
        """The object's rotated footprint rectangle."""
        return _rectangle(self.position, self.size[0], self.size[1], self.yaw)


@dataclass(frozen=True)
class FloorPlan:
    """A storey as a plan; see the module docstring for the JSON format it reads and writes."""

    rooms: tuple[RoomPlan, ...]
    ceiling_height: float = 2.7
    wall_thickness: float = 0.15
    doors: tuple[DoorPlan, ...] = ()
    windows: tuple[WindowPlan, ...] = ()
    clutter: tuple[ClutterPlan, ...] = ()
    start: tuple[float, float] | None = None
    name: str = "plan"
    description: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict, compare=False)

    # -------------------------------------------------------------- JSON
    def to_dict(self) -> dict[str, Any]:
        """The plan as a JSON-safe dict in format version 1."""
        out: dict[str, Any] = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "name": self.name}
        if self.description:
            out["description"] = self.description
        out["ceiling_height"] = self.ceiling_height
        out["wall_thickness"] = self.wall_thickness
        out["rooms"] = [{"name": r.name, "polygon": [list(p) for p in r.polygon]} for r in self.rooms]
        out["doors"] = [
            {"rooms": list(d.rooms), "position": list(d.position), "width": d.width, "height": d.height}
            for d in self.doors
        ]
        if self.windows:
            out["windows"] = [asdict(w) | {"position": list(w.position)} for w in self.windows]
        out["clutter"] = [
            {"kind": c.kind, "position": list(c.position), "size": list(c.size), "yaw": c.yaw} for c in self.clutter
        ]
        if self.start is not None:
            out["start"] = list(self.start)
        return out

    def to_json(self, path: str | Path | None = None, *, indent: int | None = 1) -> str:
        """Serialise to JSON text; also write it to ``path`` when given."""
        text = json.dumps(self.to_dict(), indent=indent) + "\n"
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_dict(cls, data: Any, *, source: str = "<plan>") -> FloorPlan:
        """Validate ``data`` against :data:`PLAN_SCHEMA` and build the plan.

        Raises
        ------
        FloorPlanError
            With ``path`` set to the offending field (e.g. ``rooms[1].polygon[2]``).
        """
        _validate_schema(data, source)
        named = [("name", data.get("name", ""))]
        named += [(f"rooms[{i}].name", r["name"]) for i, r in enumerate(data["rooms"])]
        for where, text in named:
            bad = next((c for c in text if unicodedata.category(c) in ("Cc", "Cs") or c in _BIDI_CONTROLS), None)
            if bad is not None:
                # A name is printed in tables and messages: a newline or a NUL there breaks them, and a
                # lone surrogate ("\ud800", valid JSON) is no character: no UTF-8 output can hold it.
                what = "the lone surrogate" if unicodedata.category(bad) == "Cs" else "the control character"
                raise FloorPlanError(source, f"a name may not hold {what} U+{ord(bad):04X}", path=where)
        rooms = tuple(RoomPlan(r["name"], tuple((float(x), float(y)) for x, y in r["polygon"])) for r in data["rooms"])
        names = [r.name for r in rooms]
        for i, name in enumerate(names):
            if names.index(name) != i:
                raise FloorPlanError(source, f"duplicate room name {name!r}", path=f"rooms[{i}].name")
        for i, d in enumerate(data.get("doors", [])):
            for j, name in enumerate(d["rooms"]):
                if name not in names:
                    raise FloorPlanError(
                        source, f"unknown room {name!r}; rooms: {names}", path=f"doors[{i}].rooms[{j}]"
                    )
            if d["rooms"][0] == d["rooms"][1]:
                raise FloorPlanError(source, "a door must join two different rooms", path=f"doors[{i}].rooms")
        for i, w in enumerate(data.get("windows", [])):
            if w["room"] not in names:
                raise FloorPlanError(source, f"unknown room {w['room']!r}; rooms: {names}", path=f"windows[{i}].room")
        return cls(
            name=str(data.get("name", Path(source).stem)),
            description=str(data.get("description", "")),
            ceiling_height=float(data["ceiling_height"]),
            wall_thickness=float(data["wall_thickness"]),
            rooms=rooms,
            doors=tuple(
                DoorPlan(tuple(d["rooms"]), _pt(d["position"]), float(d["width"]), float(d["height"]))
                for d in data.get("doors", [])
            ),
            windows=tuple(
                WindowPlan(w["room"], _pt(w["position"]), float(w["width"]), float(w["height"]), float(w["sill"]))
                for w in data.get("windows", [])
            ),
            clutter=tuple(
                ClutterPlan(c["kind"], _pt(c["position"]), tuple(float(s) for s in c["size"]), float(c.get("yaw", 0.0)))
                for c in data.get("clutter", [])
            ),
            start=None if "start" not in data else _pt(data["start"]),
        )

    def to_scene(self, *, source: str | None = None, validate: bool = True) -> Scene:
        """Extrude into a labelled :class:`Scene` (see :func:`extrude`)."""
        return extrude(self, source=source, validate=validate)


def _pt(p: Sequence[float]) -> tuple[float, float]:
    return (float(p[0]), float(p[1]))


#: The most elements of each list a plan may hold, checked before the schema walks them: a storey of
#: 500 rooms is a campus, not a storey; 300,000 clutter objects once took minutes to check and extrude.
MAX_ITEMS = {"rooms": 500, "doors": 2_000, "windows": 2_000, "clutter": 10_000}
#: The most corners of one room's polygon.
MAX_CORNERS = 1_000


def _check_counts(data: Any, source: str) -> None:
    if not isinstance(data, dict):
        return  # the schema says what it should be
    for key, most in MAX_ITEMS.items():
        items = data.get(key)
        if isinstance(items, list) and len(items) > most:
            raise FloorPlanError(source, f"{len(items):,} {key}; a plan holds at most {most:,}", path=key)
    for i, room in enumerate(data.get("rooms") or [] if isinstance(data.get("rooms"), list) else []):
        corners = room.get("polygon") if isinstance(room, dict) else None
        if isinstance(corners, list) and len(corners) > MAX_CORNERS:
            raise FloorPlanError(
                source, f"{len(corners):,} corners; a room has at most {MAX_CORNERS:,}", path=f"rooms[{i}].polygon"
            )


def _validate_schema(data: Any, source: str) -> None:
    import jsonschema

    _check_counts(data, source)

    validator = jsonschema.Draft202012Validator(PLAN_SCHEMA)
    errors = sorted(validator.iter_errors(data), key=lambda e: (len(e.absolute_path), list(map(str, e.absolute_path))))
    if not errors:
        _check_finite(data, source)
        return
    err = jsonschema.exceptions.best_match(errors)
    path = _json_path(err.absolute_path) or "(top level)"
    if err.validator == "const" and list(err.absolute_path) == ["version"]:
        message = f"unsupported format version {json_text(err.instance)}; this nbs-env reads version {FORMAT_VERSION}"
    else:
        message = err.message
        # jsonschema's messages open with the value as Python spells it (None, True): the file's is JSON.
        python = repr(err.instance)
        if message.startswith(python):
            message = json_text(err.instance) + message[len(python) :]
    raise FloorPlanError(source, message, path=path)


def _check_finite(data: Any, source: str, path: tuple = ()) -> None:
    if isinstance(data, float) and not math.isfinite(data):
        raise FloorPlanError(source, f"{data} is not a finite number", path=_json_path(path))
    if isinstance(data, dict):
        for k, v in data.items():
            _check_finite(v, source, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            _check_finite(v, source, (*path, i))


def _json_path(parts: Sequence[Any]) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def load_plan(path: str | Path) -> FloorPlan:
    """Read a floor-plan JSON file.

    Raises
    ------
    SceneFileError
        The file is missing or unreadable.
    FloorPlanError
        Invalid JSON (with line and column; nesting deeper than :data:`scenes.jsonio.MAX_JSON_DEPTH`
        included) or a schema violation (with the field path).
    """
    path = Path(path)
    try:
        # Size and nesting are bounded: a 1.5 GB file ran out of memory, a thousand levels would end in
        # a RecursionError in the decoder.
        data = read_json_file(path, parse_constant=_reject_constant)
    except JSONSizeError as exc:
        raise FloorPlanError(str(path), str(exc)) from None
    except UnicodeDecodeError as exc:
        raise FloorPlanError(str(path), f"invalid JSON: not UTF-8 text (byte {exc.start})") from None
    except FileNotFoundError:
        raise SceneFileError(str(path), "no such file") from None
    except OSError as exc:
        raise SceneFileError(str(path), f"cannot read: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise FloorPlanError(str(path), f"invalid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except ValueError as exc:
        raise FloorPlanError(str(path), f"invalid JSON: {exc}") from None
    return FloorPlan.from_dict(data, source=str(path))


#: Characters that reorder the text printed after them (a name could make a table read backwards).
_BIDI_CONTROLS = frozenset("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


# ---------------------------------------------------------------------------------------- geometry
def _rectangle(center: Sequence[float], length: float, depth: float, yaw_deg: float) -> Polygon:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]) * [length, depth]
    rot = corners @ np.array([[c, s], [-s, c]])
    return Polygon(rot + np.asarray(center, dtype=float))


#: Metres within which two corners of a room are one, and a corner lies on the wall of its neighbours.
CORNER_TOLERANCE = 1e-6


def _simple_polygon(points: Sequence[Sequence[float]], source: str, path: str) -> Polygon:
    pts = _corners(np.asarray(points, dtype=float))
    if len(pts) < 3:
        raise PlanGeometryError(source, "a polygon needs at least 3 distinct points", path=path)
    poly = Polygon(pts)
    if not poly.is_valid or poly.area <= 1e-9:
        reason = shapely.is_valid_reason(poly)
        raise PlanGeometryError(source, f"the polygon is not simple ({reason})", path=path)
    return orient(poly, 1.0)


def _corners(pts: np.ndarray) -> np.ndarray:
    """A room outline's corners: a corner written twice (or closing the ring) once, and a point on a
    straight wall (where a neighbour's wall meets it, as plans traced from drawings have) none. Left
    in, the walls' offset drops them and the room was refused as "too narrow"."""
    while len(pts) >= 3:
        following = np.roll(pts, -1, axis=0)
        previous = np.roll(pts, 1, axis=0)
        repeated = np.linalg.norm(following - pts, axis=1) <= CORNER_TOLERANCE
        span = following - previous
        length = np.linalg.norm(span, axis=1)
        along = pts - previous
        off_line = np.abs(span[:, 0] * along[:, 1] - span[:, 1] * along[:, 0]) / np.where(length > 0, length, 1.0)
        # 180 degrees, not a spike back along the wall (that stays, and is refused as not simple)
        straight = (off_line <= CORNER_TOLERANCE) & (np.einsum("ij,ij->i", along, following - pts) > 0)
        drop = repeated | straight
        if not drop.any():
            break
        pts = pts[~(np.arange(len(pts)) == int(np.flatnonzero(drop)[0]))]  # one at a time: neighbours change
    return pts


@dataclass(frozen=True)
class _Edge:
    """An edge of a room's clear (inner) outline."""

    room: int
    index: int
    p0: np.ndarray
    p1: np.ndarray

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.p1 - self.p0))

    @property
    def direction(self) -> np.ndarray:
        return (self.p1 - self.p0) / self.length

    @property
    def inward(self) -> np.ndarray:
        # Outlines are counter-clockwise, so the room lies to the left of every edge.
        d = self.direction
        return np.array([-d[1], d[0]])


@dataclass
class _Piece:
    vertices: np.ndarray
    faces: np.ndarray
    label: SurfaceClass
    room: int


class _Builder:
    """Collects labelled triangle pieces and joins them into one mesh with per-face arrays."""

    def __init__(self) -> None:
        self.pieces: list[_Piece] = []

    def add(
        self, vertices: np.ndarray, faces: np.ndarray, label: SurfaceClass, room: int, normal: np.ndarray | None
    ) -> None:
        vertices = np.asarray(vertices, dtype=float)
        faces = np.asarray(faces, dtype=np.int64)
        if len(faces) == 0:
            return
        if normal is not None:
            tri = vertices[faces]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            flip = n @ np.asarray(normal, dtype=float) < 0
            faces = faces.copy()
            faces[flip] = faces[flip][:, ::-1]
        self.pieces.append(_Piece(vertices, faces, label, room))

    def add_quad(self, corners: np.ndarray, label: SurfaceClass, room: int, normal: np.ndarray) -> None:
        self.add(corners, np.array([[0, 1, 2], [0, 2, 3]]), label, room, normal)

    def add_mesh(self, mesh: trimesh.Trimesh, label: SurfaceClass, room: int) -> None:
        self.add(mesh.vertices, mesh.faces, label, room, None)

    def build(self) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray]:
        offsets = np.cumsum([0] + [len(p.vertices) for p in self.pieces])
        vertices = np.concatenate([p.vertices for p in self.pieces])
        faces = np.concatenate([p.faces + o for p, o in zip(self.pieces, offsets[:-1], strict=True)])
        labels = np.concatenate([np.full(len(p.faces), p.label, dtype=np.uint8) for p in self.pieces])
        rooms = np.concatenate([np.full(len(p.faces), p.room, dtype=np.int32) for p in self.pieces])
        # process=False keeps the face order, so labels stay aligned with faces.
        return trimesh.Trimesh(vertices=vertices, faces=faces, process=False), labels, rooms


def _triangulate(poly: Polygon) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a 2-D polygon (holes allowed) with earcut."""
    verts, faces = trimesh.creation.triangulate_polygon(poly, engine="earcut")
    return np.asarray(verts, dtype=float), np.asarray(faces, dtype=np.int64)


def _find_edge(edges: Sequence[_Edge], c: np.ndarray, offset: float, half_width: float) -> tuple[_Edge, float] | None:
    """The inner-outline edge lying ``offset`` from centre-line point ``c``, with room for the opening."""
    best = None
    for e in edges:
        rel = c - e.p0
        s = float(rel @ e.direction)
        dist = float(rel @ e.inward)  # negative: c is outside the clear outline, behind the wall face
        if abs(-dist - offset) < 1e-3 and half_width - 1e-9 <= s <= e.length - half_width + 1e-9:
            gap = abs(-dist - offset)
            if best is None or gap < best[2]:
                best = (e, s, gap)
    return None if best is None else (best[0], best[1])


@dataclass(frozen=True)
class _Opening:
    s0: float
    s1: float
    z0: float
    z1: float
    pane: bool  # a window holds a pane; a door is open


def extrude(plan: FloorPlan, *, source: str | None = None, validate: bool = True) -> Scene:
    """Turn a floor plan into a labelled scene.

    Parameters
    ----------
    plan : FloorPlan
        The storey.
    source : str, optional
        Name used in error messages (defaults to the plan's name).
    validate : bool
        Run :func:`scenes.validation.validate_plan_scene` (reachability, free start, no leaks).

    Returns
    -------
    Scene
        Faces labelled FLOOR/CEILING/WALL per room, DOOR (jambs, soffit, threshold; room -1),
        WINDOW panes and CLUTTER; ``rooms`` hold the clear floor outlines.

    Raises
    ------
    PlanGeometryError
        A ceiling lower than :data:`scenes.limits.MIN_STOREY_HEIGHT`, a self-intersecting or too
        narrow room, a door not on a wall shared by its two rooms, a window not on an outside wall,
        clutter taller than the ceiling, outside every room or blocking a door.
    StoreyValidationError
        When ``validate`` and the storey fails a check.
    """
    src = source or plan.name
    t = plan.wall_thickness
    height = plan.ceiling_height
    if height < MIN_STOREY_HEIGHT:
        raise PlanGeometryError(
            src,
            f"the ceiling is {height:g} m high; a storey is at least {MIN_STOREY_HEIGHT:g} m high "
            "(scenes.limits.MIN_STOREY_HEIGHT): raise the plan's ceiling_height",
            path="ceiling_height",
        )
    names = [r.name for r in plan.rooms]
    centre = [_simple_polygon(r.polygon, src, f"rooms[{i}].polygon") for i, r in enumerate(plan.rooms)]
    for i in range(len(centre)):
        for j in range(i):
            if centre[i].intersection(centre[j]).area > 1e-6:
                raise PlanGeometryError(
                    src, f"room {names[i]!r} overlaps room {names[j]!r}", path=f"rooms[{i}].polygon"
                )
    inner: list[Polygon] = []
    edges: list[list[_Edge]] = []
    for i, poly in enumerate(centre):
        clear = poly.buffer(-t / 2, join_style="mitre", mitre_limit=100.0)
        if clear.geom_type != "Polygon" or len(clear.exterior.coords) != len(poly.exterior.coords):
            raise PlanGeometryError(src, f"room {names[i]!r} is too narrow for {t} m walls", path=f"rooms[{i}].polygon")
        clear = orient(clear, 1.0)
        inner.append(clear)
        pts = np.asarray(clear.exterior.coords)[:-1]
        edges.append([_Edge(i, k, pts[k], pts[(k + 1) % len(pts)]) for k in range(len(pts))])

    openings: dict[tuple[int, int], list[_Opening]] = {}
    builder = _Builder()
    doors: list[Door] = []
    door_zones: list[Polygon] = []
    up = np.array([0.0, 0.0, 1.0])
    for k, d in enumerate(plan.doors):
        path = f"doors[{k}]"
        a, b = names.index(d.rooms[0]), names.index(d.rooms[1])
        c = np.asarray(d.position, dtype=float)
        if d.height > height - 0.05:
            raise PlanGeometryError(
                src, f"door height {d.height} m leaves no lintel under the {height} m ceiling", path=f"{path}.height"
            )
        shared = centre[a].boundary.intersection(centre[b].boundary)
        if shared.is_empty or shared.length < 1e-6 or shared.distance(Point(c)) > 1e-3:
            raise PlanGeometryError(
                src,
                f"door at {_xy(c)} is not on a wall shared by {d.rooms[0]!r} and {d.rooms[1]!r}",
                path=f"{path}.position",
            )
        found_a = _find_edge(edges[a], c, t / 2, d.width / 2)
        found_b = _find_edge(edges[b], c, t / 2, d.width / 2)
        if found_a is None or found_b is None:
            raise PlanGeometryError(
                src,
                f"door at {_xy(c)} ({d.width} m wide) does not fit on the wall shared by "
                f"{d.rooms[0]!r} and {d.rooms[1]!r} (too close to a corner, or the wall is too short)",
                path=f"{path}.position",
            )
        (ea, sa), (eb, sb) = found_a, found_b
        seg = LineString([c - ea.direction * d.width / 2, c + ea.direction * d.width / 2])
        for j, other in enumerate(plan.doors[:k]):
            # Two openings in one stretch of wall would cut one hole twice (a duplicated door, or two
            # drawn over each other): the faces between them overlap.
            if set(other.rooms) == set(d.rooms):
                gap = float(np.linalg.norm(np.asarray(other.position, dtype=float) - c))
                if gap < (other.width + d.width) / 2:
                    raise PlanGeometryError(
                        src,
                        f"door at {_xy(c)} overlaps doors[{j}] at {_xy(other.position)} on the wall shared by "
                        f"{d.rooms[0]!r} and {d.rooms[1]!r}",
                        path=f"{path}.position",
                    )
        if not shared.buffer(1e-4).contains(seg):
            raise PlanGeometryError(
                src,
                f"door at {_xy(c)} runs past the wall shared by {d.rooms[0]!r} and {d.rooms[1]!r}",
                path=f"{path}.position",
            )
        openings.setdefault((a, ea.index), []).append(
            _Opening(sa - d.width / 2, sa + d.width / 2, 0.0, d.height, False)
        )
        openings.setdefault((b, eb.index), []).append(
            _Opening(sb - d.width / 2, sb + d.width / 2, 0.0, d.height, False)
        )
        # The passage through the wall: jambs, soffit and threshold.
        pa = ea.p0 + ea.direction * sa
        pb = eb.p0 + eb.direction * sb
        u = ea.direction
        half = u * d.width / 2
        a0, a1, b0, b1 = pa - half, pa + half, pb - half, pb + half

        def v3(p: np.ndarray, z: float) -> np.ndarray:
            return np.array([p[0], p[1], z])

        u3 = np.array([u[0], u[1], 0.0])
        builder.add_quad(
            np.array([v3(a0, 0), v3(b0, 0), v3(b0, d.height), v3(a0, d.height)]), SurfaceClass.DOOR, -1, u3
        )
        builder.add_quad(
            np.array([v3(a1, 0), v3(b1, 0), v3(b1, d.height), v3(a1, d.height)]), SurfaceClass.DOOR, -1, -u3
        )
        builder.add_quad(
            np.array([v3(a0, d.height), v3(a1, d.height), v3(b1, d.height), v3(b0, d.height)]),
            SurfaceClass.DOOR,
            -1,
            -up,
        )
        builder.add_quad(np.array([v3(a0, 0), v3(a1, 0), v3(b1, 0), v3(b0, 0)]), SurfaceClass.DOOR, -1, up)
        across = ea.inward  # points into room a
        doors.append(
            Door(rooms=(a, b), position=np.array([c[0], c[1], 0.0]), width=d.width, height=d.height, normal=-across)
        )
        door_zones.append(_rectangle(c, d.width, t + 2 * DOOR_CLEARANCE, math.degrees(math.atan2(u[1], u[0]))))

    for k, w in enumerate(plan.windows):
        path = f"windows[{k}]"
        r = names.index(w.room)
        c = np.asarray(w.position, dtype=float)
        if w.sill + w.height > height - 0.02:
            raise PlanGeometryError(src, f"window top {w.sill + w.height} m reaches the {height} m ceiling", path=path)
        found = _find_edge(edges[r], c, t / 2, w.width / 2)
        if found is None or centre[r].exterior.distance(Point(c)) > 1e-3:
            raise PlanGeometryError(
                src, f"window at {_xy(c)} does not fit on a wall of room {w.room!r}", path=f"{path}.position"
            )
        if any(j != r and centre[j].boundary.distance(Point(c)) < 1e-3 for j in range(len(centre))):
            raise PlanGeometryError(
                src, f"window at {_xy(c)} is on an inside wall; windows go on outside walls", path=f"{path}.position"
            )
        e, s = found
        new = _Opening(s - w.width / 2, s + w.width / 2, w.sill, w.sill + w.height, True)
        for other in openings.get((r, e.index), []):
            # Two openings over one stretch of wall: a pane counted twice (forty copies of one window
            # made its area forty times what the wall lost), or a window in a door.
            if new.s0 < other.s1 and other.s0 < new.s1 and new.z0 < other.z1 and other.z0 < new.z1:
                kind = "another window" if other.pane else "a door"
                raise PlanGeometryError(
                    src,
                    f"window at {_xy(c)} overlaps {kind} on the same wall of room {w.room!r}",
                    path=f"{path}.position",
                )
        openings.setdefault((r, e.index), []).append(new)

    # Floors, ceilings and the wall faces of every room, with their openings.
    rooms_gt: list[Room] = []
    for i, clear in enumerate(inner):
        v2, f = _triangulate(clear)
        builder.add(np.column_stack([v2, np.zeros(len(v2))]), f, SurfaceClass.FLOOR, i, up)
        builder.add(np.column_stack([v2, np.full(len(v2), height)]), f, SurfaceClass.CEILING, i, -up)
        for e in edges[i]:
            holes = openings.get((i, e.index), [])
            face = Polygon([(0, 0), (e.length, 0), (e.length, height), (0, height)])
            for o in holes:
                face = face.difference(Polygon([(o.s0, o.z0), (o.s1, o.z0), (o.s1, o.z1), (o.s0, o.z1)]))
            inward3 = np.array([e.inward[0], e.inward[1], 0.0])
            d3 = np.array([e.direction[0], e.direction[1], 0.0])
            origin = np.array([e.p0[0], e.p0[1], 0.0])
            for part in getattr(face, "geoms", [face]):
                v2, f = _triangulate(part)
                builder.add(origin + v2[:, :1] * d3 + v2[:, 1:] * up, f, SurfaceClass.WALL, i, inward3)
            for o in holes:
                if o.pane:
                    corners = [
                        origin + s * d3 + z * up for s, z in ((o.s0, o.z0), (o.s1, o.z0), (o.s1, o.z1), (o.s0, o.z1))
                    ]
                    builder.add_quad(np.array(corners), SurfaceClass.WINDOW, i, inward3)
        rooms_gt.append(
            Room(
                id=i,
                name=names[i],
                polygon=np.asarray(clear.exterior.coords)[:-1].copy(),
                floor_z=0.0,
                ceiling_z=height,
            )
        )

    for k, c in enumerate(plan.clutter):
        path = f"clutter[{k}]"
        # Before the footprint test: a tall piece is no wall-crosser, and saying so would mislead.
        if c.kind != "column" and c.size[2] > height:
            raise PlanGeometryError(
                src,
                f"{c.kind} at {c.position} is {c.size[2]:g} m high, taller than the {height:g} m ceiling",
                path=f"{path}.size[2]",
            )
        foot = c.footprint()
        inside = [i for i, clear in enumerate(inner) if clear.buffer(1e-6).contains(foot)]
        if not inside:
            raise PlanGeometryError(
                src, f"{c.kind} at {c.position} is not inside any room (it crosses a wall?)", path=path
            )
        for j, zone in enumerate(door_zones):
            if zone.intersection(foot).area > 1e-9:
                raise PlanGeometryError(
                    src,
                    f"{c.kind} at {c.position} blocks door doors[{j}] (keep {DOOR_CLEARANCE} m clear on both sides)",
                    path=path,
                )
        h = c.size[2] if c.kind != "column" else height
        builder.add_mesh(
            clutter_mesh(c.kind, c.size[0], c.size[1], h, c.position, c.yaw), SurfaceClass.CLUTTER, inside[0]
        )

    mesh, labels, face_rooms = builder.build()
    scene = Scene(
        mesh,
        labels,
        face_rooms,
        rooms=rooms_gt,
        doors=doors,
        start=plan.start,
        name=src,
        metadata={"source": "floorplan", "format_version": FORMAT_VERSION, "plan": plan.name},
    )
    if validate:
        if plan.start is None:
            start_within_check(plan, scene)  # (the generator's storeys, drawn unvalidated, keep theirs)
        validate_plan_scene(plan, scene)
    return scene


# ---------------------------------------------------------------------------------------- clutter
def clutter_mesh(
    kind: str, length: float, depth: float, height: float, position: Sequence[float], yaw_deg: float
) -> trimesh.Trimesh:
    """A piece of furniture as boxes, in its place.

    Parameters
    ----------
    kind : str
        One of :data:`CLUTTER_KINDS`.
    length, depth, height : float
        Extents along the object's x (length), y (depth, back on +y) and z.
    position : (2,) float
        Centre of the footprint.
    yaw_deg : float
        Rotation of the length axis from +x, counter-clockwise.
    """
    L, D, H = length, depth, height
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = []  # (extents, centre)

    def add(ex: float, ey: float, ez: float, cx: float, cy: float, z0: float) -> None:
        boxes.append(((ex, ey, ez), (cx, cy, z0 + ez / 2)))

    if kind in ("box", "cabinet", "column"):
        add(L, D, H, 0, 0, 0)
    elif kind == "shelf":
        board = 0.03
        add(board, D, H, -L / 2 + board / 2, 0, 0)
        add(board, D, H, L / 2 - board / 2, 0, 0)
        add(L - 2 * board, board, H, 0, D / 2 - board / 2, 0)
        n = max(2, int(H / 0.4))
        for k in range(n + 1):
            z = min(k * H / n, H - board)
            add(L - 2 * board, D - board, board, 0, -board / 2, z)
    elif kind == "table":
        top, leg = 0.04, 0.06
        add(L, D, top, 0, 0, H - top)
        for sx in (-1, 1):
            for sy in (-1, 1):
                add(leg, leg, H - top, sx * (L / 2 - leg), sy * (D / 2 - leg), 0)
    elif kind == "chair":
        seat_z, leg = min(0.45, 0.6 * H), 0.04
        add(L, D, 0.05, 0, 0, seat_z - 0.05)
        add(L, 0.05, H - seat_z, 0, D / 2 - 0.025, seat_z)
        for sx in (-1, 1):
            for sy in (-1, 1):
                add(leg, leg, seat_z - 0.05, sx * (L / 2 - leg), sy * (D / 2 - leg), 0)
    elif kind == "sofa":
        base = 0.45 * H
        arm = min(0.2, L / 6)
        back = min(0.25, D / 3)
        add(L - 2 * arm, D - back, base, 0, -back / 2, 0)
        add(L, back, H, 0, D / 2 - back / 2, 0)
        for sx in (-1, 1):
            add(arm, D - back, 0.7 * H, sx * (L / 2 - arm / 2), -back / 2, 0)
    else:
        raise ValueError(f"unknown clutter kind {kind!r}; kinds: {CLUTTER_KINDS}")
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    place = np.array([[c, -s, 0, position[0]], [s, c, 0, position[1]], [0, 0, 1, 0], [0, 0, 0, 1]])
    parts = []
    for extents, centre in boxes:
        local = np.eye(4)
        local[:3, 3] = centre
        parts.append(trimesh.creation.box(extents=extents, transform=place @ local))
    return trimesh.util.concatenate(parts)


def _xy(point) -> str:
    """``(x, y)`` as a user wrote it, for a message: plain numbers, not numpy's reprs."""
    return "(" + ", ".join(f"{float(v):g}" for v in point) + ")"
