"""Load and save labelled triangle meshes (OBJ, glTF/GLB, PLY) as :class:`~scenes.model.Scene`.

Labelling conventions
---------------------
*Names (OBJ, glTF/GLB).* Every part of the file carries a name, and the name's **prefix** gives
the :class:`~scenes.model.SurfaceClass` of all its faces, case-insensitively:

====================  =====================================================================
prefix                class
====================  =====================================================================
``wall``              WALL
``floor``             FLOOR
``ceiling``           CEILING
``door``              DOOR
``window``            WINDOW
``clutter``           CLUTTER
====================  =====================================================================

The prefix must end the name or be followed by ``_``, ``-``, ``.``, a space or a digit, so
``wall_north``, ``Floor.001``, ``door2`` and ``clutter-desk`` are labelled while ``walls`` and
``doorway`` are not. Parts whose names match no prefix become CLUTTER, and one
:class:`UnlabelledPartsWarning` lists them all.

An optional ``room<N>`` token gives the faces room ``N``: it starts the name or follows a
``_``, ``-``, ``.`` or space, and ends the name or is followed by one (``wall_room3_0``,
``floor.room12``; not ``clutter_bedroom2``). Faces without one get room -1. The room numbers in a
file need not be contiguous: they are renumbered 0..k-1 in increasing order, and each room keeps its
file number in its name (``room3``).

* **OBJ**: a part is a run of faces under an ``o`` (object) and/or ``g`` (group) statement. When
  both are set, the group name is tried first and the object name second, for the class and for
  the room token alike; an ``o`` statement ends the current group. Polygons are fan-triangulated;
  texture and normal indices are ignored.
  The file is read by a small parser here rather than by trimesh, because trimesh 5.2 names split
  parts ``<object>_<group>`` (so ``o wall`` + ``g floor`` became a *wall*), lets an ``o`` inherit
  the previous ``g``, and de-duplicates repeated names with suffixes.
* **glTF/GLB**: each node of the scene graph that instances a mesh is a part, placed with its world
  transform. The class and room come from the node name, then the mesh name, then the names of the
  node's ancestors (nearest first), so an empty parent ``room2`` can give its children a room.

*Per-face properties (PLY).* A PLY file holds one mesh; its ``face`` element carries an integer
property ``label`` (a :class:`~scenes.model.SurfaceClass` value) and optionally ``room`` (a room
number, negative for none), renumbered like the room tokens.

Axes and units
--------------
Coordinates are metres with z up. A file in another unit loads with ``units`` (``"cm"``, ``"mm"``,
``"ft"``, ``"in"``; :data:`scenes.limits.UNITS`), which scales it to metres. A storey beyond
:mod:`scenes.limits` (500 m across, 50 m high: what a storey in millimetres read as metres is) is
refused with a :class:`~scenes.errors.StoreySizeError` that names the likely unit. Files authored y up
(the glTF convention, Blender's glTF exporter) load with ``y_up=True``, which rotates +90 degrees
about x: ``(x, y, z) -> (x, -z, y)``. Files written by :func:`export_scene` are z up (and metres).

Sizes a file declares (a PLY header's counts, a glTF buffer's length, an accessor's count) are checked
against the bytes it has before it is parsed (:mod:`scenes.headers`).

Ground truth
------------
When any face carries a room, every room gets a :class:`~scenes.model.Room`: its polygon is the
largest piece of the union of its FLOOR triangles projected to xy (counter-clockwise, not closed),
``floor_z`` the lowest z of those triangles and ``ceiling_z`` the highest z of its CEILING faces
(``floor_z + 2.7`` without any). A room with faces but no floor faces has no outline; its faces
fall back to room -1 with a warning. Meshes carry no door ground truth.
"""

from __future__ import annotations

import base64
import re
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import shapely
import trimesh

from scenes.errors import InvalidMeshError, MissingStructureError, SceneFileError, UnsupportedFormatError
from scenes.geometry import CrossingPolygonError, triangulate_polygons
from scenes.headers import (
    PlyElement,
    PlyHeader,
    ascii_ply_row_error,
    check_gltf_layout,
    check_ply_header,
    side_file_path,
)
from scenes.interior import with_derived_rooms
from scenes.limits import MAX_FACES, check_face_count, check_file_size, check_storey_size, unit_scale
from scenes.model import Room, Scene, SurfaceClass

__all__ = [
    "EXPORT_EXTENSIONS",
    "SUPPORTED_EXTENSIONS",
    "SurfacelessPartsWarning",
    "UnlabelledPartsWarning",
    "export_scene",
    "footprint_polygon",
    "load_mesh_scene",
    "parse_part_name",
]

#: Extensions :func:`load_mesh_scene` reads.
SUPPORTED_EXTENSIONS: tuple[str, ...] = (".obj", ".glb", ".gltf", ".ply")
#: Extensions :func:`export_scene` writes (a ``.gltf`` would need side files for its buffers).
EXPORT_EXTENSIONS: tuple[str, ...] = (".obj", ".glb", ".ply")

#: Ceiling height assumed for a room whose faces include no ceiling.
DEFAULT_ROOM_HEIGHT = 2.7

_PREFIXES = {c.name.lower(): c for c in SurfaceClass}
_PREFIX_RE = re.compile(r"^(" + "|".join(_PREFIXES) + r")(?=$|[_\-. 0-9])", re.IGNORECASE)
# ASCII digits only: \d reads Arabic-Indic and full-width digits, which other readers of the name do not.
_ROOM_RE = re.compile(r"(?:^|[_\-. ])room([0-9]+)(?=$|[_\-. ])", re.IGNORECASE)
#: The largest room number a part name may give (``wall_room12``): numbers name rooms, and no storey
#: has a million of them; a longer one overflowed the arrays of room ids.
MAX_ROOM_NUMBER = 999_999


class UnlabelledPartsWarning(UserWarning):
    """Parts of a mesh file whose names carry no class prefix; they were loaded as CLUTTER.

    Attributes
    ----------
    source : str
        The file.
    names : tuple of str
        The unlabelled part names, in file order.
    """

    def __init__(self, source: str, names: Sequence[str]) -> None:
        self.source = str(source)
        self.names = tuple(names)
        prefixes = ", ".join(_PREFIXES)
        super().__init__(
            f"{self.source}: {len(self.names)} part(s) have no class prefix ({prefixes}) and were "
            f"loaded as clutter: {', '.join(repr(n) for n in self.names)}"
        )


class SurfacelessPartsWarning(UserWarning):
    """Parts of a glTF file drawn as points or lines (primitive modes 0-3): they hold no surface a
    scan could sense, and were left out.

    Attributes
    ----------
    source : str
        The file.
    names : tuple of str
        The parts' node names, in file order.
    """

    def __init__(self, source: str, names: Sequence[str]) -> None:
        self.source = str(source)
        self.names = tuple(names)
        shown = ", ".join(repr(n) for n in self.names[:5]) + (" ..." if len(self.names) > 5 else "")
        super().__init__(
            f"{self.source}: {len(self.names)} part(s) are drawn as points or lines, not surfaces, and were left "
            f"out: {shown}"
        )


def parse_part_name(name: str) -> tuple[SurfaceClass | None, int]:
    """Class and room number encoded in a part name.

    Parameters
    ----------
    name : str
        An object, group or node name such as ``"wall_room3_0"``.

    Returns
    -------
    cls : SurfaceClass or None
        The class given by the name's prefix, None when it has no recognised prefix.
    room : int
        ``N`` of the first ``room<N>`` token, -1 when there is none.

    Raises
    ------
    ValueError
        A room number above :data:`MAX_ROOM_NUMBER`.
    """
    m = _PREFIX_RE.match(name.strip())
    r = _ROOM_RE.search(name)
    room = -1
    if r:
        digits = r.group(1).lstrip("0") or "0"
        if len(digits) > len(str(MAX_ROOM_NUMBER)) or int(digits) > MAX_ROOM_NUMBER:
            shown = digits if len(digits) <= 20 else f"{digits[:20]}… ({len(digits):,} digits)"
            raise ValueError(f"part {name[:80]!r} names room {shown}; room numbers go up to {MAX_ROOM_NUMBER:,}")
        room = int(digits)
    return (_PREFIXES[m.group(1).lower()] if m else None), room


def _classify(source: str, candidates: Sequence[str | None]) -> tuple[SurfaceClass | None, int]:
    """First class and first room found among ``candidates``, tried in order."""
    cls, room = None, -1
    for cand in candidates:
        if not cand:
            continue
        try:
            c, r = parse_part_name(cand)
        except ValueError as exc:
            raise InvalidMeshError(source, str(exc)) from None
        if cls is None:
            cls = c
        if room < 0:
            room = r
    return cls, room


# ---------------------------------------------------------------------------------------- loading
def load_mesh_scene(path: str | Path, *, y_up: bool = False, units: str = "m", name: str | None = None) -> Scene:
    """Load a labelled mesh file as a :class:`~scenes.model.Scene`.

    Parameters
    ----------
    path : str or Path
        An ``.obj``, ``.glb``, ``.gltf`` or ``.ply`` file labelled as the module docstring describes.
    y_up : bool
        The file's up axis is +y; rotate to z up with ``(x, y, z) -> (x, -z, y)``.
    units : str
        The unit of the file's coordinates, one of :data:`scenes.limits.UNITS` (``"m"``, ``"cm"``,
        ``"mm"``, ``"ft"``, ``"in"``); the mesh is scaled to metres.
    name : str, optional
        Name of the scene; defaults to the path. Error messages always name the file.

    Returns
    -------
    Scene
        ``face_labels`` (F,) uint8 from the names or the PLY ``label`` property, ``face_rooms`` (F,)
        int32 renumbered room ids or -1, ``rooms`` derived from the floor faces, no doors, and
        ``metadata`` ``{"source": str(path), "format": "obj" | "glb" | "gltf" | "ply"}``.

    Raises
    ------
    SceneFileError
        The file does not exist or cannot be read.
    UnsupportedFormatError
        The extension is none of :data:`SUPPORTED_EXTENSIONS`.
    InvalidMeshError
        The file cannot be parsed, declares more data than it holds, holds no faces, has NaN or
        infinite vertices, or bad labels.
    StoreySizeError
        The storey is larger than :mod:`scenes.limits` allows (the message suggests a unit) or has
        too many faces.
    MissingStructureError
        No floor or no wall faces.
    ValueError
        ``units`` is not one of :data:`scenes.limits.UNITS`.

    Warns
    -----
    UnlabelledPartsWarning
        Once, listing every part whose name has no class prefix (loaded as CLUTTER).
    """
    scale = unit_scale(units)
    path = Path(path)
    source = str(path)
    ext = path.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise UnsupportedFormatError(
            source,
            f"unsupported mesh format {path.suffix or '(no extension)'!r}; "
            f"supported: {', '.join(SUPPORTED_EXTENSIONS)}",
        )
    if not path.is_file():
        raise SceneFileError(source, "no such file" if not path.exists() else "not a regular file")
    try:
        check_file_size(source, path.stat().st_size)  # read whole: sized first
        data = path.read_bytes()
    except OSError as exc:
        raise SceneFileError(source, f"cannot read the file: {exc.strerror or exc}") from exc

    # What the file declares is checked against its bytes before trimesh allocates from it.
    if ext == ".obj":
        vertices, faces, labels, rooms, unlabelled = _read_obj(source, data)
    elif ext == ".ply":
        vertices, faces, labels, rooms, unlabelled = _read_ply(source, data, check_ply_header(source, data))
    else:
        check_gltf_layout(source, path, data)
        vertices, faces, labels, rooms, unlabelled = _read_gltf(source, path, ext)

    if unlabelled:
        warnings.warn(UnlabelledPartsWarning(source, unlabelled), stacklevel=2)
    if len(faces) == 0:
        raise InvalidMeshError(source, "the mesh is empty (no faces)")
    out_of_range = (faces < 0) | (faces >= len(vertices))
    if out_of_range.any():
        # Numbered as the file numbers them: OBJ from 1, PLY and glTF from 0.
        first = 1 if ext == ".obj" else 0
        bad = int(faces[out_of_range][0]) + first
        raise InvalidMeshError(
            source,
            f"{int(out_of_range.any(axis=1).sum())} face(s) refer to vertex {bad} or other "
            f"vertices outside {first}..{len(vertices) - 1 + first}",
        )
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        # Checked over every vertex of the file, used or not: a NaN anywhere means a broken export.
        raise InvalidMeshError(
            source, f"{int(np.count_nonzero(~finite))} of {len(vertices)} vertices are NaN or infinite"
        )
    if y_up:
        vertices = vertices[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0])
    vertices = vertices * scale

    # Drop vertices no face uses so that bounds describe the surfaces only.
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    # Before the room outlines: shapely fails deep inside on 1e300, and a file in millimetres would
    # reach the grids at a thousand times its size. Here the message can suggest the units option.
    check_storey_size(source, vertices[used], len(faces), units=units)
    mesh = trimesh.Trimesh(vertices[used], inverse.reshape(-1, 3), process=False, validate=False)
    labels = labels.astype(np.uint8)
    _require_structure(source, labels, hint=_STRUCTURE_HINT[ext])
    face_rooms, room_list = _rooms_from_faces(source, mesh, labels, rooms)
    scene = Scene(
        mesh,
        labels,
        face_rooms,
        rooms=room_list,
        name=name if name is not None else source,
        metadata={"source": source, "format": ext[1:], "rooms": "file" if room_list else "none"},
    )
    return with_derived_rooms(scene)


_STRUCTURE_HINT = {
    ".obj": "name the objects or groups wall_*, floor_*, ...",
    ".glb": "name the nodes or meshes wall_*, floor_*, ...",
    ".gltf": "name the nodes or meshes wall_*, floor_*, ...",
    ".ply": "give the faces an integer 'label' property (0 = floor, 2 = wall, ...)",
}


def _require_structure(source: str, labels: np.ndarray, *, hint: str) -> None:
    """Raise :class:`MissingStructureError` naming the file when floor or wall faces are missing."""
    counts = np.bincount(labels, minlength=len(SurfaceClass))
    for required in (SurfaceClass.FLOOR, SurfaceClass.WALL):
        if counts[required] == 0:
            found = ", ".join(f"{c.name.lower()}: {counts[c]}" for c in SurfaceClass if counts[c]) or "none"
            raise MissingStructureError(
                source,
                f"the mesh has no {required.name.lower()} faces (faces per class: {found}); {hint}",
            )


# ------------------------------------------------------------------------------------------ OBJ
def _read_obj(source: str, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Parse OBJ text into vertices (V, 3), faces (F, 3), labels (F,), raw rooms (F,), unlabelled names."""
    if b"\0" in data:
        raise InvalidMeshError(source, "binary data: not an OBJ text file")
    # The format's grammar, not Python's: lines end at \n, \r\n or \r (not at the other characters
    # str.splitlines breaks at), words are separated by blanks and tabs (not by a no-break space), and
    # numbers are ASCII (Python's int and float read "1_0" as 10 and Arabic-Indic digits as digits,
    # where every other OBJ reader fails or reads another number). A byte-order mark is no part of the
    # first line: it hid a first "v" line's keyword, and the vertex was dropped.
    text = data.decode("utf-8-sig", errors="replace").replace("\r\n", "\n").replace("\r", "\n")
    coords: list[str] = []
    coord_lines: list[int] = []
    polygons: list[list[int]] = []
    polygon_part: list[int] = []
    polygon_lines: list[int] = []
    triangles = 0
    parts: dict[tuple[str | None, str | None], int] = {}
    obj: str | None = None
    group: str | None = None
    # str.split is the format's split on ASCII text without the separators only Python counts as
    # blanks (\x1c-\x1f), and three times as fast as the expression's.
    split = str.split if text.isascii() and not _PYTHON_ONLY_BLANKS.search(text) else _obj_split
    for lineno, raw in _obj_statements(text):
        line = raw.strip(_OBJ_BLANKS)
        if not line or line[0] == "#":
            continue
        key, *tail = split(line, None, 1)
        rest = tail[0] if tail else ""
        if key == "v":
            xyz = split(rest)
            if len(xyz) < 3:
                raise InvalidMeshError(source, f"line {lineno}: a vertex needs x y z, got {line!r}")
            coords.append(" ".join(xyz[:3]))
            coord_lines.append(lineno)
        elif key == "f":
            refs = split(rest)
            if len(refs) < 3:
                raise InvalidMeshError(source, f"line {lineno}: a face needs 3 or more vertices: {line!r}")
            idx = []
            for ref in refs:
                number = ref.split("/", 1)[0]
                try:
                    # On ASCII text without "_", int reads the format's integers and nothing else.
                    if not number.isascii() or "_" in number:
                        raise ValueError(number)
                    i = int(number)
                except ValueError:
                    raise InvalidMeshError(source, f"line {lineno}: bad vertex reference {ref!r}") from None
                if i == 0:
                    raise InvalidMeshError(source, f"line {lineno}: vertex indices start at 1, got 0")
                # A file of n bytes has fewer than n vertices: a larger index (which may not even fit
                # an int64) refers to none. Negative indices count back from the latest vertex.
                if i > len(data) or -i > len(coords):
                    raise InvalidMeshError(
                        source, f"line {lineno}: vertex index {ref.split('/', 1)[0]} refers to no vertex of the file"
                    )
                idx.append(i - 1 if i > 0 else len(coords) + i)
            polygons.append(idx)
            polygon_part.append(parts.setdefault((obj, group), len(parts)))
            polygon_lines.append(lineno)
            triangles += len(idx) - 2
            if triangles > MAX_FACES:  # refused while the lists are still small
                check_face_count(source, triangles)
        elif key == "o":
            # A new object ends the group: a group left over from the previous object must not
            # label this one.
            obj, group = rest.strip() or None, None
        elif key == "g":
            group = rest.strip() or None
            names = split(rest)
            if len({parse_part_name(n) for n in names}) > 1:
                # OBJ puts the faces in every group the line names: which part they are is not one answer.
                raise InvalidMeshError(
                    source,
                    f"line {lineno}: 'g {' '.join(names)[:60]}' puts its faces in {len(names)} groups that name "
                    "different parts: name one group per part",
                )
        # Everything else (vt, vn, usemtl, mtllib, s, l, ...) does not matter for labelled geometry.

    joined = "\n".join(coords)
    odd = _NOT_A_NUMBER.search(joined)
    try:
        if odd is not None:
            raise ValueError(odd.group())
        vertices = np.array([c.split(" ") for c in coords], dtype=float).reshape(-1, 3)
    except ValueError:
        k = (
            joined.count("\n", 0, odd.start())
            if odd is not None
            else next(k for k, c in enumerate(coords) if not _floats_ok(c))
        )
        raise InvalidMeshError(
            source,
            f"line {coord_lines[k]}: a vertex has a coordinate that is no ASCII number: {('v ' + coords[k])[:80]!r}",
        ) from None
    faces, polygon_of = _triangulated(source, vertices, polygons, lambda k: f"line {polygon_lines[k]}: the face's")
    part_of = np.asarray(polygon_part, dtype=np.int64)[polygon_of]

    n_parts = len(parts)
    part_cls = np.full(n_parts, SurfaceClass.CLUTTER.value, dtype=np.int64)
    part_room = np.full(n_parts, -1, dtype=np.int64)
    unlabelled = []
    for (o, g), i in parts.items():
        cls, room = _classify(source, (g, o))
        if cls is None:
            unlabelled.append(" / ".join(n for n in (o, g) if n) or "(unnamed)")
        else:
            part_cls[i] = cls.value
        part_room[i] = room
    return vertices, faces, part_cls[part_of], part_room[part_of], unlabelled


def _triangulated(
    source: str, vertices: np.ndarray, polygons: Sequence[Sequence[int]], face: Callable[[int], str]
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~scenes.geometry.triangulate_polygons`, a crossing polygon named as ``face(index)`` names it."""
    try:
        return triangulate_polygons(vertices, polygons)
    except CrossingPolygonError as exc:
        raise InvalidMeshError(source, f"{face(exc.index)} outline crosses itself; split it into simple faces") from exc


def _obj_statements(text: str) -> Iterator[tuple[int, str]]:
    """The OBJ text's statements with the number of the line each starts on: a line ending in ``\\``
    continues its statement on the next line, but a comment is no statement (a Windows path at the
    end of one, ``# from D:\\export\\``, swallowed the next line's ``o wall_room0``)."""
    lines = text.split("\n")
    if "\\\n" not in text and not text.endswith("\\"):  # the last line needs no line end
        yield from enumerate(lines, start=1)
        return
    pending: tuple[int, str] | None = None
    for lineno, line in enumerate(lines, start=1):
        start, line = (lineno, line) if pending is None else (pending[0], pending[1] + " " + line)
        if line.endswith("\\") and not line.lstrip(_OBJ_BLANKS).startswith("#"):
            pending = (start, line[:-1])
            continue
        pending = None
        yield start, line
    if pending is not None:
        yield pending


def _floats_ok(text: str) -> bool:
    try:
        [float(t) for t in text.split(" ")]
    except ValueError:
        return False
    return True


# The OBJ grammar's blanks (ASCII: not a no-break space).
_OBJ_BLANKS = " \t\v\f"
_OBJ_SPLIT = re.compile(r"[ \t\v\f]+")
_PYTHON_ONLY_BLANKS = re.compile(r"[\x1c-\x1f]")


def _obj_split(text: str, sep: None = None, maxsplit: int = -1) -> list[str]:
    """``text.split()`` with the OBJ format's blanks (not a no-break space)."""
    words = _OBJ_SPLIT.split(text.strip(_OBJ_BLANKS), maxsplit=max(maxsplit, 0))
    return [w for w in words if w]


#: What no ASCII number of a text mesh (OBJ, ASCII PLY) holds: nan and inf pass, to the finite checks.
_NOT_A_NUMBER = re.compile(r"[^0-9+\-.eEnaiftyNAIFTY \t\n]")


# ------------------------------------------------------------------------------------- glTF/GLB
class _SideFiles(trimesh.resolvers.Resolver):
    """The buffers a glTF names, found as :func:`scenes.headers.side_file_path` finds them (trimesh's
    own resolver neither decodes ``%20`` nor follows ``../``), and read only."""

    def __init__(self, source: str, path: Path) -> None:
        self.source, self.path = source, path

    def get(self, key: str) -> bytes:
        if key[:5].lower() == "data:":  # trimesh decodes "base64," itself, not the marker in capitals
            return base64.b64decode(key.partition(",")[2])
        return side_file_path(self.source, self.path, key).read_bytes()

    def write(self, name: str, data: Any) -> None:
        raise PermissionError("a glTF is read, never written, here")

    def namespaced(self, namespace: str) -> _SideFiles:
        return _SideFiles(self.source, self.path.parent / namespace / self.path.name)

    def keys(self) -> list[str]:
        return []


def _read_gltf(source: str, path: Path, ext: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Flatten a glTF scene graph into world-space vertices, faces, labels and raw rooms."""
    try:
        # Without materials: no texture is read (a file of the geometry only is what is scanned).
        scene = trimesh.load(
            str(path),
            file_type=ext[1:],
            force="scene",
            process=False,
            skip_materials=True,
            resolver=_SideFiles(source, path),
        )
    except Exception as exc:  # trimesh raises many types for malformed files
        raise InvalidMeshError(source, f"cannot parse as {ext[1:]}: {type(exc).__name__}: {exc}") from exc
    parents = scene.graph.transforms.parents
    verts, faces, labels, rooms, unlabelled = [], [], [], [], []
    surfaceless: list[str] = []
    drawn_otherwise = False  # a part of points or lines, not a triangle mesh of no faces
    offset = 0
    for node in sorted(scene.graph.nodes_geometry):
        transform, geom_name = scene.graph[node]
        geom = scene.geometry.get(geom_name)
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            # Point clouds and paths (primitive modes 0-3) have no surfaces to scan: left out, and
            # said, since a part drawn so vanishes from the storey.
            if geom is not None:
                surfaceless.append(str(node))
                drawn_otherwise |= not isinstance(geom, trimesh.Trimesh)
            continue
        names = [node, geom_name]
        parent = parents.get(node)
        while parent is not None and parent != scene.graph.base_frame:
            names.append(parent)
            parent = parents.get(parent)
        cls, room = _classify(source, names)
        if cls is None:
            unlabelled.append(str(node))
            cls = SurfaceClass.CLUTTER
        v = np.asarray(geom.vertices, dtype=float)
        verts.append(v @ transform[:3, :3].T + transform[:3, 3])
        faces.append(np.asarray(geom.faces, dtype=np.int64) + offset)
        labels.append(np.full(len(geom.faces), cls.value, dtype=np.int64))
        rooms.append(np.full(len(geom.faces), room, dtype=np.int64))
        offset += len(v)
    if not faces and drawn_otherwise:
        shown = ", ".join(repr(n) for n in surfaceless[:5]) + (" ..." if len(surfaceless) > 5 else "")
        raise InvalidMeshError(
            source,
            f"every part is drawn as points or lines (glTF primitive modes 0-3), not triangles: no surface to "
            f"scan ({shown}); export the meshes as triangles",
        )
    if surfaceless:
        warnings.warn(SurfacelessPartsWarning(source, surfaceless), stacklevel=3)
    if not faces:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), []
    return (
        np.concatenate(verts),
        np.concatenate(faces),
        np.concatenate(labels),
        np.concatenate(rooms),
        unlabelled,
    )


# ------------------------------------------------------------------------------------------ PLY
def _read_ply(
    source: str, data: bytes, header: PlyHeader
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Read a PLY mesh with per-face ``label`` (and optional ``room``) properties, its header read."""
    if header.encoding == "ascii":
        # Read here, every value against its declared type: trimesh reads ASCII values as float64
        # and casts them, so a uchar label of 256 became 0 (a wall read as floor) and a uchar x of
        # 300 was 44, and it fails on lists of several lengths read wide.
        vertices, columns, props, n_raw = _read_ascii_ply(source, data, header)
    else:
        try:
            # From the bytes already read and checked, with no resolver and no materials: a header's
            # "comment TextureFile NAME" made trimesh open NAME, and a fifo there hung the load.
            mesh = trimesh.load(
                trimesh.util.wrap_as_stream(data), file_type="ply", force="mesh", process=False, skip_materials=True
            )
        except Exception:
            # trimesh reads binary lists of one length only: a file mixing triangles and quads, as
            # most exporters write, is read record by record here (and its damage named).
            vertices, columns, props, n_raw = _read_binary_ply(source, data, header)
        else:
            if not isinstance(mesh, trimesh.Trimesh):
                return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), []
            vertices = np.asarray(mesh.vertices, dtype=float)
            raw = mesh.metadata.get("_ply_raw", {}).get("face", {})
            columns = raw.get("data")
            props = list(raw.get("properties", {}))
            n_raw = int(raw.get("length", 0) or 0)
            if columns is None or "label" not in props:
                faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
                # Without labels every face is clutter, which the structure check then reports with a hint.
                n = len(faces)
                return vertices, faces, np.full(n, SurfaceClass.CLUTTER.value), np.full(n, -1), []
    # trimesh reorders mixed triangles and polygons, so triangulate the raw polygons here to keep
    # each face next to its own label.
    index_prop = next((p for p in props if p in ("vertex_indices", "vertex_index")), None)
    if index_prop is None:
        raise InvalidMeshError(source, "the PLY face element has no vertex_indices list")
    try:
        polys = _ply_polygons(columns[index_prop], n_raw, header.element("face").named(index_prop).type)
        label_raw = (
            _ply_integers(columns["label"], n_raw, "label")
            if "label" in props
            else np.full(n_raw, SurfaceClass.CLUTTER.value)  # unlabelled: the structure check says so
        )
        room_raw = _ply_integers(columns["room"], n_raw, "room") if "room" in props else np.full(n_raw, -1)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        # The header declares the property, the body does not hold it where it should (an ASCII face
        # line with fewer or more values than the header lists): name the record where one is to blame.
        row = ascii_ply_row_error(data, header) if header.encoding == "ascii" else None
        if row is None and isinstance(exc, _PlyValueError):
            row = str(exc)
        raise InvalidMeshError(
            source,
            row or f"the face element's values do not match its header's properties ({type(exc).__name__}: {exc})",
        ) from None
    if not np.all(np.isin(label_raw, [c.value for c in SurfaceClass])):
        bad = np.unique(label_raw[~np.isin(label_raw, [c.value for c in SurfaceClass])])
        raise InvalidMeshError(
            source,
            f"face 'label' values {bad.tolist()} are no SurfaceClass "
            f"({', '.join(f'{c.value} = {c.name.lower()}' for c in SurfaceClass)})",
        )
    odd = (room_raw < -1) | (room_raw > MAX_ROOM_NUMBER)
    if odd.any():
        raise InvalidMeshError(
            source,
            f"face {int(np.flatnonzero(odd)[0])}'s 'room' is {int(room_raw[odd][0])}; a room is -1 (none) or a "
            f"number up to {MAX_ROOM_NUMBER:,}",
        )
    for i, poly in enumerate(polys):
        if len(poly) < 3:
            raise InvalidMeshError(source, f"PLY face {i} has {len(poly)} vertices; a face needs 3 or more")
    triangles, src_arr = _triangulated(source, vertices, polys, lambda k: f"PLY face {k}'s")
    room_arr = room_raw.astype(np.int64)[src_arr] if len(src_arr) else np.zeros(0, np.int64)
    return (
        vertices,
        triangles,
        label_raw.astype(np.int64)[src_arr] if len(src_arr) else np.zeros(0, np.int64),
        np.where(room_arr < 0, -1, room_arr),
        [],
    )


#: numpy's and struct's codes of the PLY scalar types.
_PLY_NUMPY = {
    "char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1",
    "short": "i2", "ushort": "u2", "int16": "i2", "uint16": "u2",
    "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}


def _read_binary_ply(source: str, data: bytes, header: PlyHeader) -> tuple[np.ndarray, dict[str, Any], list[str], int]:
    """A binary PLY read record by record (lists of any length), from a header
    :func:`~scenes.headers.check_ply_header` has read and checked.

    Returns
    -------
    vertices : (N, 3) float64
    columns : dict
        The face element's properties: a list property as an object array of index arrays, a
        scalar as an array.
    properties : list of str
        The face element's property names, in order.
    faces : int
        The face records.

    Raises
    ------
    InvalidMeshError
        A list's count that runs past the file's end, or bytes left over after the last record.
    """
    import struct

    offset = header.body
    endian = "<" if header.encoding == "binary_little_endian" else ">"

    def numpy_codes(element: PlyElement) -> list[tuple[str, str, str | None]]:
        return [(p.name, _PLY_NUMPY[p.type], p.count_type and _PLY_NUMPY[p.count_type]) for p in element.properties]

    elements = [(e.name, e.count, numpy_codes(e)) for e in header.elements]
    read: dict[str, dict[str, Any]] = {}
    for name, count, props in elements:
        if all(counter is None for _, _, counter in props):  # fixed-size records: one read
            dtype = np.dtype([(p, endian + kind) for p, kind, _ in props])
            if offset + count * dtype.itemsize > len(data):
                raise InvalidMeshError(source, f"the PLY {name} records run past the end of the file")
            records = np.frombuffer(data, dtype, count, offset)
            offset += count * dtype.itemsize
            read[name] = {p: records[p] for p, _, _ in props}
            continue
        columns: dict[str, list] = {p: [] for p, _, _ in props}
        for i in range(count):
            for prop, kind, counter in props:
                try:
                    if counter is None:
                        columns[prop].append(struct.unpack_from(endian + _STRUCT[kind], data, offset)[0])
                        offset += int(kind[1])
                        continue
                    (n,) = struct.unpack_from(endian + _STRUCT[counter], data, offset)
                    offset += int(counter[1])
                    if n < 0 or offset + n * int(kind[1]) > len(data):
                        raise struct.error("past the end")
                    columns[prop].append(np.frombuffer(data, endian + kind, n, offset))
                    offset += n * int(kind[1])
                except struct.error:
                    raise InvalidMeshError(
                        source,
                        f"PLY {name} {i}'s '{prop}' runs past the end of the file ({len(data) - offset:,} bytes "
                        "are left): the file is truncated or its counts are wrong",
                    ) from None
        read[name] = columns
    if offset != len(data):
        raise InvalidMeshError(
            source, f"{len(data) - offset:,} bytes follow the last record the PLY header declares: its counts are wrong"
        )
    vertex, face = read["vertex"], read["face"]
    vertices = np.column_stack([np.asarray(vertex[a], dtype=float) for a in "xyz"]).reshape(-1, 3)
    faces = next(count for name, count, _ in elements if name == "face")
    out: dict[str, Any] = {}
    for prop, values in face.items():
        if isinstance(values, list) and values and isinstance(values[0], np.ndarray):
            column = np.empty(len(values), dtype=object)
            column[:] = values
            out[prop] = column
        else:
            out[prop] = np.asarray(values)
    return vertices, out, list(face), faces


class _PlyValueError(ValueError):
    """A PLY face element's values that are not what its header says they mean."""


def _read_ascii_ply(source: str, data: bytes, header: PlyHeader) -> tuple[np.ndarray, dict[str, Any], list[str], int]:
    """An ASCII PLY read element by element, as :func:`_read_binary_ply` reads a binary one: one
    record a line, ASCII numbers, every integer value (a scalar, a list's count) whole and within its
    declared type, every ``float`` rounded to float32 as other readers make it.

    Returns
    -------
    As :func:`_read_binary_ply`; the face element's values as float64 (checked against their types
    by :func:`_ply_polygons` for the vertex indices).

    Raises
    ------
    InvalidMeshError
        Naming the element, the record and its line (:func:`~scenes.headers.ascii_ply_row_error`), or
        the value its type cannot hold.
    """
    rows = data[header.body :].decode("ascii", errors="replace").splitlines()
    first_line = data[: header.body].count(b"\n") + 1
    read: dict[str, dict[str, Any]] = {}
    at = 0
    for element in header.elements:
        block = rows[at : at + element.count]
        try:
            columns = _ascii_records(block, element)
        except (ValueError, IndexError):
            raise InvalidMeshError(
                source, ascii_ply_row_error(data, header) or f"the PLY {element.name} records do not fit its header"
            ) from None
        for prop in element.properties:
            values = columns[prop.name]
            if prop.count_type is not None:
                lengths = [len(v) for v in values] if isinstance(values, list) else [values.shape[1]] * element.count
                checked, kind = (np.asarray(lengths, dtype=float), prop.count_type), "count"
            else:
                checked, kind = (values, prop.type), "value"
            odd = _outside(np.asarray(checked[0], dtype=float), checked[1], whole=True)
            if odd.any():
                k = int(np.flatnonzero(odd)[0])
                value = float(np.asarray(checked[0])[k])
                shown = f"{value:.0f}" if value.is_integer() and abs(value) < 1e18 else f"{value:g}"
                raise InvalidMeshError(
                    source,
                    f"element '{element.name}' record {k:,} (line {first_line + at + k:,}): its '{prop.name}' {kind} "
                    f"{shown} is no {checked[1]!r}, its header's type",
                )
            if prop.count_type is None and _PLY_NUMPY[prop.type] == "f4":
                # A value beyond float32's range became inf with a bare numpy warning before.
                big = np.isfinite(values) & (np.abs(values) > np.finfo(np.float32).max)
                if big.any():
                    k = int(np.flatnonzero(big)[0])
                    raise InvalidMeshError(
                        source,
                        f"element '{element.name}' record {k:,} (line {first_line + at + k:,}): its '{prop.name}' "
                        f"value {values[k]:g} is beyond what its header's type 'float' holds (3.4e38)",
                    )
                columns[prop.name] = values.astype(np.float32).astype(float)  # as every reader of a float
        at += element.count
        read[element.name] = columns
    vertex, face = read["vertex"], read["face"]
    vertices = np.column_stack([np.asarray(vertex[a], dtype=float) for a in "xyz"]).reshape(-1, 3)
    out: dict[str, Any] = {}
    for prop, values in face.items():
        if isinstance(values, list):
            column = np.empty(len(values), dtype=object)
            column[:] = values
            out[prop] = column
        else:
            out[prop] = values
    return vertices, out, list(face), header.element("face").count


def _ascii_records(block: list[str], element: PlyElement) -> dict[str, Any]:
    """The values of one element's rows: a scalar as an (n,) array, a list as an (n, k) array where
    every record's list is k long, else as a list of arrays.

    Raises
    ------
    ValueError, IndexError
        A row that is short, long, or holds what is no ASCII number.
    """
    props = element.properties
    n = element.count
    if n == 0:
        return {p.name: np.zeros(0) if p.count_type is None else np.zeros((0, 0)) for p in props}
    text = " ".join(block)
    if len(block) != n or _NOT_A_NUMBER.search(text):
        raise ValueError("rows")
    lists = [k for k, p in enumerate(props) if p.count_type is not None]
    widths = [len(line.split()) for line in block]  # one record a line: a short row beside a long one
    width = widths[0] if widths else 0  # must not pass as two whole records read as one stream
    if len(lists) <= 1:  # one parse when every record has the same length (all triangles, say)
        values = np.array(text.split(), dtype=float)
        if n and values.size == n * width and widths.count(width) == n:
            table = values.reshape(n, width)
            scalars_before = lists[0] if lists else len(props)
            length = width - len(props)
            if not lists or (length >= 0 and (table[:, scalars_before] == length).all()):
                out: dict[str, Any] = {}
                k = 0
                for p in props:
                    if p.count_type is None:
                        out[p.name] = table[:, k]
                        k += 1
                    else:
                        out[p.name] = table[:, k + 1 : k + 1 + length]
                        k += 1 + length
                return out
        elif not lists:
            raise ValueError("rows")
    columns: dict[str, list] = {p.name: [] for p in props}
    for line in block:
        words, k = line.split(), 0
        for p in props:
            if p.count_type is None:
                columns[p.name].append(float(words[k]))
                k += 1
                continue
            count = float(words[k])
            if not (count.is_integer() and 0 <= count <= len(words)):
                raise ValueError("count")
            end = k + 1 + int(count)
            if end > len(words):
                raise IndexError("list")
            columns[p.name].append(np.array(words[k + 1 : end], dtype=float))
            k = end
        if k != len(words):
            raise ValueError("row")
    return {
        p.name: np.asarray(v, dtype=float) if p.count_type is None else v
        for p, v in zip(props, columns.values(), strict=True)
    }


def _outside(values: np.ndarray, kind: str, whole: bool = False) -> np.ndarray:
    """Which ``values`` do not fit the PLY integer type ``kind`` (none for a float type); with
    ``whole``, a fraction does not fit either."""
    code = _PLY_NUMPY[kind]
    if code[0] == "f":
        return np.zeros(values.shape, bool)
    info = np.iinfo(code)
    with np.errstate(invalid="ignore"):
        odd = ~((values >= info.min) & (values <= info.max))  # NaN fits no integer type
        return odd | (values != np.round(values)) if whole else odd


def _ply_polygons(column: np.ndarray, n: int, kind: str = "int") -> list[np.ndarray]:
    """The vertex lists of the raw PLY face element, whatever layout trimesh left them in; their
    indices must be whole numbers (a list of floats is allowed by the format, 15.5 names no vertex)
    within their declared type ``kind``. Checked in one pass over all the indices."""
    if n == 0:
        return []
    col = np.asarray(column)
    if col.dtype.names and "f1" in col.dtype.names:  # binary: (count, indices) records
        col = np.asarray(col["f1"]).reshape(n, -1)
    if col.dtype == object:
        lists = [np.asarray(p).reshape(-1) for p in col]
        lengths = np.fromiter((len(p) for p in lists), np.int64, len(lists))
        flat = np.concatenate(lists) if lists else np.zeros(0)
    else:
        col = col.reshape(n, -1)
        lengths, flat = np.full(n, col.shape[1]), col.reshape(-1)
    ends = np.cumsum(lengths)

    def face_of(position: int) -> int:
        return int(np.searchsorted(ends, position, side="right"))

    if flat.dtype.kind not in "iuf":
        raise _PlyValueError("PLY faces' vertex indices are not numbers")
    if flat.dtype.kind == "f":
        with np.errstate(invalid="ignore"):
            fraction = ~np.isfinite(flat) | (flat != np.round(flat))
        if fraction.any():
            i = face_of(int(np.flatnonzero(fraction)[0]))
            shown = flat[ends[i] - lengths[i] : ends[i]].tolist()[:6]
            raise _PlyValueError(f"PLY face {i} has a vertex index that is not a whole number: {shown}")
        outside = _outside(flat, kind)
        if outside.any():
            at = int(np.flatnonzero(outside)[0])
            raise _PlyValueError(
                f"PLY face {face_of(at)} has vertex index {flat[at]:.15g}, which its header's type {kind!r} cannot hold"
            )
    indices = flat.astype(np.int64)
    if col.dtype != object:
        return list(indices.reshape(n, -1))
    return np.split(indices, ends[:-1])


def _ply_integers(column: Any, n: int, name: str) -> np.ndarray:
    """A per-face scalar property as (n,) int64; one value a face, whole numbers (an ASCII value's
    declared type is checked as it is read, a binary one's holds it)."""
    values = np.asarray(column)
    if values.dtype == object or values.size != n:  # a face line short of its values, or with more
        raise _PlyValueError(f"the face element's '{name}' values do not match its header (one a face, {n:,} faces)")
    values = values.reshape(-1)
    if values.dtype.kind == "f" and not (np.isfinite(values).all() and (values == np.round(values)).all()):
        raise _PlyValueError(f"face '{name}' values must be whole numbers")
    if values.dtype.kind not in "iuf":
        raise _PlyValueError(f"face '{name}' values are not numbers")
    return values.astype(np.int64)


# ---------------------------------------------------------------------------------------- rooms
def footprint_polygon(triangles: np.ndarray) -> np.ndarray | None:
    """Outline of the union of triangles projected to xy.

    Parameters
    ----------
    triangles : (n, 3, 2 or 3) float
        Triangle corners; z, if present, is ignored.

    Returns
    -------
    (m, 2) float or None
        Exterior of the largest polygon of the union, counter-clockwise, without the closing point
        and without collinear vertices; None when the triangles cover no area.
    """
    tris = np.asarray(triangles, dtype=float)[..., :2]
    if len(tris) == 0:
        return None
    polys = shapely.polygons(tris)
    polys = polys[shapely.area(polys) > 1e-12]
    if len(polys) == 0:
        return None
    union = shapely.union_all(polys)
    pieces = list(getattr(union, "geoms", [union]))
    pieces = [p for p in pieces if isinstance(p, shapely.Polygon) and p.area > 0]
    if not pieces:
        return None
    largest = max(pieces, key=lambda p: p.area)
    # A tiny tolerance removes the collinear vertices left where triangles met along an edge.
    outline = shapely.Polygon(largest.exterior).simplify(1e-9, preserve_topology=True)
    outline = shapely.geometry.polygon.orient(outline, sign=1.0)
    return np.asarray(outline.exterior.coords, dtype=float)[:-1]


#: Less wall than this in a room's own faces, m², and the room is named as having none (a sliver
#: of wall is no wall).
MIN_ROOM_WALL_AREA = 0.01


def _rooms_from_faces(
    source: str, mesh: trimesh.Trimesh, labels: np.ndarray, raw_rooms: np.ndarray
) -> tuple[np.ndarray, list[Room]]:
    """Renumber raw room numbers to 0..k-1 and derive each room's ground truth from its faces."""
    raw_rooms = np.asarray(raw_rooms, dtype=np.int64)
    face_rooms = np.full(len(raw_rooms), -1, dtype=np.int32)
    triangles = mesh.vertices[mesh.faces]
    areas = np.asarray(mesh.area_faces)
    rooms: list[Room] = []
    orphans = []
    wall_less = []
    for number in np.unique(raw_rooms[raw_rooms >= 0]):
        members = raw_rooms == number
        floor = members & (labels == SurfaceClass.FLOOR)
        polygon = footprint_polygon(triangles[floor]) if floor.any() else None
        if polygon is None:
            orphans.append(f"room{number}")
            continue
        # By area, not by count: a glTF wall node at scale 0 leaves its faces, of no area.
        if float(areas[members & (labels == SurfaceClass.WALL)].sum()) < MIN_ROOM_WALL_AREA:
            wall_less.append(f"room{number}")
        floor_z = float(triangles[floor][..., 2].min())
        ceiling = members & (labels == SurfaceClass.CEILING)
        ceiling_z = float(triangles[ceiling][..., 2].max()) if ceiling.any() else floor_z + DEFAULT_ROOM_HEIGHT
        face_rooms[members] = len(rooms)
        rooms.append(Room(len(rooms), f"room{number}", polygon, floor_z, ceiling_z))
    if orphans:
        warnings.warn(
            f"{source}: {', '.join(orphans)} have no floor faces to outline them; their faces get room -1",
            UserWarning,
            stacklevel=3,
        )
    if wall_less:
        # A wall group left out of the export, or hidden by a scale of 0: the storey is open there,
        # and the coverage's total lacks those walls (probe: 32.0% sensed became 38.1%).
        warnings.warn(
            f"{source}: {', '.join(wall_less)} {'has' if len(wall_less) == 1 else 'have'} a floor but no wall "
            "faces of its own; walls missing from the file are neither scanned nor counted in the coverage",
            UserWarning,
            stacklevel=3,
        )
    return face_rooms, rooms


# ---------------------------------------------------------------------------------------- export
def export_scene(scene: Scene, path: str | Path) -> None:
    """Write a scene as a labelled mesh that :func:`load_mesh_scene` reads back.

    OBJ and GLB get one part per (class, room) pair, named ``<class>`` or ``<class>_room<id>`` with
    the scene's room ids; PLY gets per-face ``label`` (uchar) and ``room`` (int) properties. The
    coordinates are z up; OBJ (17 digits) and PLY (double) keep them exactly, GLB stores float32 as
    glTF requires. Room outlines are re-derived from the floor faces when loading, so they
    match the scene's rooms when those are the outlines of their floors; room names, doors, the
    start position and metadata are not stored.

    Parameters
    ----------
    scene : Scene
        The scene to write.
    path : str or Path
        Destination; the extension (``.obj``, ``.glb`` or ``.ply``) picks the format.

    Raises
    ------
    UnsupportedFormatError
        The extension is none of :data:`EXPORT_EXTENSIONS`.
    SceneFileError
        The file cannot be written.
    """
    path = Path(path)
    source = str(path)
    ext = path.suffix.lower()
    if ext not in EXPORT_EXTENSIONS:
        raise UnsupportedFormatError(
            source,
            f"cannot export to {path.suffix or '(no extension)'!r}; supported: {', '.join(EXPORT_EXTENSIONS)}",
        )
    vertices = np.asarray(scene.mesh.vertices, dtype=float)
    faces = np.asarray(scene.mesh.faces, dtype=np.int64)
    try:
        if ext == ".ply":
            _write_ply(path, vertices, faces, scene.face_labels, scene.face_rooms)
            return
        parts = _export_parts(scene)
        if ext == ".obj":
            _write_obj(path, vertices, faces, parts)
        else:
            out = trimesh.Scene()
            for part_name, sel in parts:
                used, inverse = np.unique(faces[sel].reshape(-1), return_inverse=True)
                sub = trimesh.Trimesh(vertices[used], inverse.reshape(-1, 3), process=False, validate=False)
                out.add_geometry(sub, node_name=part_name, geom_name=part_name)
            out.export(str(path), file_type="glb")
    except OSError as exc:
        raise SceneFileError(source, f"cannot write the file: {exc.strerror or exc}") from exc


def _export_parts(scene: Scene) -> list[tuple[str, np.ndarray]]:
    """(name, face indices) for every (class, room) pair present, classes in enum order."""
    parts = []
    for cls in SurfaceClass:
        of_class = scene.face_labels == cls.value
        for room in np.unique(scene.face_rooms[of_class]):
            sel = np.flatnonzero(of_class & (scene.face_rooms == room))
            parts.append((cls.name.lower() if room < 0 else f"{cls.name.lower()}_room{room}", sel))
    return parts


def _write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, rooms: np.ndarray) -> None:
    """Write a binary little-endian PLY with double coordinates and per-face ``label``/``room``.

    Written here because trimesh 5.2 stores PLY coordinates as float32, which moves georeferenced
    models (coordinates of 1e5 m and more) by centimetres, and would store the int64 attributes
    as "int64", which is no PLY type.
    """
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "comment labelled scene written by nbs-env: face label = SurfaceClass, room = id or -1; z up\n"
        f"element vertex {len(vertices)}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
        "property uchar label\nproperty int room\nend_header\n"
    )
    records = np.zeros(
        len(faces), dtype=[("n", "u1"), ("vertex_indices", "<i4", (3,)), ("label", "u1"), ("room", "<i4")]
    )
    records["n"] = 3
    records["vertex_indices"] = faces
    records["label"] = labels
    records["room"] = rooms
    with path.open("wb") as out:
        out.write(header.encode("ascii"))
        out.write(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
        out.write(records.tobytes())


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, parts: list[tuple[str, np.ndarray]]) -> None:
    """Write an OBJ with every vertex once and an ``o`` statement before each part's faces."""
    lines = ["# labelled scene written by nbs-env: part names give the class (and room), z up"]
    # 17 significant digits round-trip float64 exactly.
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in vertices.tolist()]
    for part_name, sel in parts:
        lines.append(f"o {part_name}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces[sel].tolist()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
