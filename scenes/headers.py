"""What a mesh file says about its own size, checked against the bytes it holds before a parser trusts it.

trimesh sizes its arrays from a file's declarations: a PLY header's element counts, a glTF accessor's
``count``. A 960-byte PLY whose header declares 2·10^9 faces, or a GLB accessor of 10^10 elements with
no data behind it, makes it allocate tens of GiB, or fail with an ``AssertionError`` that names nothing.
These checks read the declarations with the standard library (a PLY header is ASCII up to
``end_header``; a GLB is a 12-byte header and length-prefixed chunks, its layout JSON) and refuse a file
whose declarations need more bytes than it has, with an :class:`~scenes.errors.InvalidMeshError` that
says which declaration and how many bytes.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import re
import struct
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from scenes.errors import InvalidMeshError
from scenes.jsonio import json_text, read_json
from scenes.limits import MAX_FACES, check_face_count, is_finite

__all__ = [
    "PlyElement",
    "PlyHeader",
    "PlyProperty",
    "ascii_ply_row_error",
    "check_gltf_layout",
    "check_ply_header",
    "side_file_path",
]

# ------------------------------------------------------------------------------------------ PLY
#: Bytes of a binary PLY scalar, by every type name the format allows.
_PLY_TYPES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}  # fmt: skip
_PLY_FLOAT_TYPES = ("float", "float32", "double", "float64")
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
#: What a PLY header line after the first may start with.
_PLY_KEYWORDS = ("format", "comment", "obj_info", "element", "property")
#: Where a header must have ended: real headers are a few hundred bytes.
_PLY_HEADER_MAX = 1 << 20


@dataclass(frozen=True)
class PlyProperty:
    """One property of a PLY element: ``type`` is its values' PLY type name, ``count_type`` a list's
    count type (None for a scalar)."""

    name: str
    type: str
    count_type: str | None = None


@dataclass(frozen=True)
class PlyElement:
    """One element of a PLY header: its name, its record count and its properties in order."""

    name: str
    count: int
    properties: tuple[PlyProperty, ...]

    def named(self, name: str) -> PlyProperty:
        return next(p for p in self.properties if p.name == name)

    @property
    def least_binary_bytes(self) -> int:
        """The fewest bytes a binary record takes: its scalars', and each list's count (it may be
        empty), except a face's vertex list, which holds three indices at least (a face of fewer is
        none: counted as its count alone, a file short by less than its faces' indices was read on,
        face bytes as vertex bytes)."""
        return sum(
            _PLY_TYPES[p.count_type] + 3 * _PLY_TYPES[p.type]
            if p.count_type and self.name == "face" and p.name in ("vertex_indices", "vertex_index")
            else _PLY_TYPES[p.count_type or p.type]
            for p in self.properties
        )


@dataclass(frozen=True)
class PlyHeader:
    """A PLY header as :func:`check_ply_header` read and checked it; ``body`` is the offset of the
    first byte after ``end_header``'s line."""

    encoding: str
    elements: tuple[PlyElement, ...]
    body: int

    def element(self, name: str) -> PlyElement:
        return next(e for e in self.elements if e.name == name)


def check_ply_header(source: str, data: bytes) -> PlyHeader:
    """Read a PLY header, refusing one a reader would misread or that declares more records than the
    bytes after it can hold.

    Each record of an element takes at least: in a binary file, the bytes of its scalar properties
    and of each list's count (a list may be empty); in an ASCII file, two characters per property (a
    digit and a separator). The face count is checked against :data:`~scenes.limits.MAX_FACES` too.

    Returns
    -------
    PlyHeader
        The header, for the readers of the body.

    Raises
    ------
    InvalidMeshError
        No ``end_header`` near the start, an unknown format or property type, or counts that need
        more bytes than follow the header.
    StoreySizeError
        More faces declared than :data:`~scenes.limits.MAX_FACES`.
    """
    end = data.find(b"end_header", 0, _PLY_HEADER_MAX)
    if not data.startswith(b"ply"):
        raise InvalidMeshError(source, "not a PLY file: no 'ply' ... 'end_header' header at its start")
    if end < 0:
        raise InvalidMeshError(
            source, f"no 'end_header' in the PLY file's first {_PLY_HEADER_MAX:,} bytes (a header is a few hundred)"
        )
    if b"\n" not in data[:end] and b"\r" in data[:end]:
        raise InvalidMeshError(
            source,
            "the PLY file's lines end in a carriage return alone (old Mac line endings), which PLY readers take "
            "for no line end: save it with LF or CRLF line endings",
        )
    if end > 0 and data[end - 1 : end] != b"\n":
        # Readers end the header at the first "end_header" anywhere on a line (trimesh does).
        lineno = data.count(b"\n", 0, end) + 1
        raise InvalidMeshError(
            source, f"PLY header line {lineno} holds 'end_header' within it; readers end the header there"
        )
    newline = data.find(b"\n", end)
    body = len(data) - newline - 1 if newline >= 0 else 0
    # Keywords are ASCII; a comment in another encoding must not stop the check.
    # Lines end at \n (a lone \r ends none, as in PLY readers); the last piece is what precedes end_header.
    lines = data[:end].decode("ascii", errors="replace").split("\n")[:-1]
    encoding = None
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    for lineno, line in enumerate(lines, start=1):
        words = line.split()
        if lineno == 1:
            if line.strip() != "ply":
                raise InvalidMeshError(source, f"PLY header line 1 is {line.strip()[:40]!r}, not 'ply'")
            continue
        if words and words[0] not in _PLY_KEYWORDS:
            # trimesh skips a line it does not know: a "ply" twice read the body from the wrong
            # place, a property without its keyword left the vertices without a coordinate.
            raise InvalidMeshError(
                source,
                f"PLY header line {lineno}: {line.strip()[:60]!r} is no header line (they start with "
                f"{', '.join(_PLY_KEYWORDS)})",
            )
        if words[:1] == ["format"]:
            encoding = words[1] if len(words) > 1 else ""
            if encoding not in _PLY_FORMATS:
                raise InvalidMeshError(source, f"PLY header line {lineno}: unknown format {encoding!r}")
            if words[2:] != ["1.0"]:
                # The format defines version 1.0 only: trimesh reads past another, plyfile refuses it.
                shown = line.strip()[:60]
                raise InvalidMeshError(
                    source, f"PLY header line {lineno}: {shown!r}, where PLY has 'format {encoding} 1.0' only"
                )
        elif words[:1] == ["element"]:
            if encoding is None:
                raise InvalidMeshError(source, f"PLY header line {lineno}: an element before the 'format' line")
            if len(words) != 3 or not words[2].isdigit():
                raise InvalidMeshError(source, f"PLY header line {lineno}: expected 'element NAME COUNT', got {line!r}")
            if any(e[0] == words[1] for e in elements):
                raise InvalidMeshError(source, f"PLY header line {lineno}: a second element {words[1]!r}")
            elements.append((words[1], int(words[2]), []))
        elif not words:  # a reader splits each line into words: trimesh's ended in an IndexError
            raise InvalidMeshError(source, f"PLY header line {lineno} is blank")
        elif words[:1] == ["property"] and not elements:
            raise InvalidMeshError(source, f"PLY header line {lineno}: a property before any element")
        elif words[:1] == ["property"]:
            # A list takes its count's bytes at least (it may be empty); a scalar its own.
            kind = words[2] if len(words) == 5 and words[1] == "list" else words[1] if len(words) == 3 else None
            if kind not in _PLY_TYPES or (words[1] == "list" and words[3] not in _PLY_TYPES):
                raise InvalidMeshError(source, f"PLY header line {lineno}: bad property {line!r}")
            if words[1] == "list" and words[2] in _PLY_FLOAT_TYPES:
                raise InvalidMeshError(
                    source, f"PLY header line {lineno}: a list's count is an integer type, got {words[2]!r}"
                )
            if any(p.name == words[-1] for p in elements[-1][2]):
                # Readers keep one of the two columns (which, they differ) or fail inside.
                raise InvalidMeshError(
                    source, f"PLY header line {lineno}: the {elements[-1][0]} element's property {words[-1]!r} again"
                )
            listed = words[1] == "list"
            elements[-1][2].append(PlyProperty(words[-1], words[3] if listed else kind, kind if listed else None))
    if encoding is None:
        raise InvalidMeshError(source, "the PLY header has no 'format' line")
    for name, count, props in elements:
        if not props and count:
            # Its records hold nothing (no bytes, or blank lines): readers disagree on it (trimesh
            # fails inside with "data type '' not understood"), and it holds nothing to read.
            raise InvalidMeshError(
                source, f"the PLY element {name!r} has no properties: remove it (readers disagree on empty records)"
            )
    header = PlyHeader(
        encoding,
        tuple(PlyElement(name, count, tuple(props)) for name, count, props in elements),
        newline + 1 if newline >= 0 else len(data),
    )
    # trimesh reads what it finds: without these it returned no faces or failed inside.
    names = {e.name: {p.name: p.count_type is not None for p in e.properties} for e in header.elements}
    for element in ("vertex", "face"):
        if element not in names:
            raise InvalidMeshError(source, f"the PLY header declares no {element} element: no mesh")
    missing = [axis for axis in "xyz" if names["vertex"].get(axis, True)]
    if missing:
        raise InvalidMeshError(source, f"the PLY vertex element has no {', '.join(missing)} number property")
    if not any(names["face"].get(p) for p in ("vertex_indices", "vertex_index")):
        raise InvalidMeshError(source, "the PLY face element has no vertex_indices list")
    need = 0
    for k, element in enumerate(header.elements):
        least = 2 * len(element.properties) if encoding == "ascii" else element.least_binary_bytes
        need += element.count * max(least, 1)  # a record takes a byte at least (an ASCII newline)
        if need > body:
            declared = " and ".join(f"{e.count:,} {e.name}" for e in header.elements[: k + 1])
            raise InvalidMeshError(
                source,
                f"the PLY header declares {declared} records, at least {need:,} bytes, but {body:,} bytes "
                "follow the header: the file is truncated or its header is wrong",
            )
    if encoding == "ascii":
        # More lines than records: trimesh reads the declared ones and drops the rest without a word.
        last = len(data)
        while last > newline + 1 and data[last - 1 : last].isspace():
            last -= 1
        rows = data.count(b"\n", newline + 1, last) + 1 if last > newline + 1 else 0
        records = sum(e.count for e in header.elements)
        blank = re.compile(rb"\n[ \t\r]*\n").search(data, newline, last)
        if blank is not None:
            lineno = data.count(b"\n", 0, blank.start()) + 2
            raise InvalidMeshError(
                source, f"line {lineno:,} of the PLY body is blank: readers take each line for a record"
            )
        if rows > records:
            declared = " and ".join(f"{e.count:,} {e.name}" for e in header.elements)
            raise InvalidMeshError(
                source,
                f"the PLY header declares {declared} records, {records:,} lines, but the body holds {rows:,} lines: "
                "its counts are wrong",
            )
    # The bytes are there: a storey too large to load, told before trimesh reads it.
    check_face_count(source, header.element("face").count)
    return header


# The words and numbers of an ASCII PLY body, as C readers (and numpy's, which trimesh uses) read them.
_PLY_BLANKS = re.compile(r"[ \t]+")
_ASCII_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)", re.I)


def ascii_ply_row_error(data: bytes, header: PlyHeader) -> str | None:
    """Say which record of an ASCII PLY body does not hold what its element's properties need.

    Called after a parse failed, to replace numpy's "setting an array element with a sequence" by
    the element, the record and its line. Rows are read as trimesh reads them: one record per line,
    ``str.splitlines``, ASCII numbers separated by blanks and tabs.

    Parameters
    ----------
    data : bytes
        The whole file.
    header : PlyHeader
        :func:`check_ply_header`'s reading of it.

    Returns
    -------
    str or None
        The first mismatch, or ``None`` if every record holds its properties (the failure lay
        elsewhere).
    """
    header_lines = data[: header.body].count(b"\n")
    rows = data[header.body :].decode("utf-8", errors="replace").splitlines()
    row = 0
    for element in header.elements:
        name, count = element.name, element.count
        is_list = [p.count_type is not None for p in element.properties]
        for k in range(count):
            if row >= len(rows):
                return f"element '{name}' declares {count:,} records, the body ends at record {k:,}"
            words = _PLY_BLANKS.split(rows[row].strip(" \t\r"))
            where = f"element '{name}' record {k:,} (line {header_lines + row + 1:,})"
            if not all(_ASCII_NUMBER.fullmatch(w) for w in words if w):
                # numpy's reader stops there, Python's float would read "1_0" and Arabic-Indic digits
                return f"{where} holds a value that is no ASCII number: {rows[row].strip()[:80]!r}"
            words = [w for w in words if w]
            need, at = 0, 0
            for listed in is_list:
                if not listed:
                    need += 1
                    at += 1
                    continue
                try:
                    count_value = float(words[at])
                except (IndexError, ValueError):
                    count_value = math.nan
                if not (math.isfinite(count_value) and count_value >= 0 and count_value.is_integer()):
                    return f"{where} has no whole number >= 0 where a list's count should be, at value {at + 1}"
                length = int(count_value)
                need += 1 + length
                at += 1 + length
            if len(words) != need:
                return f"{where} holds {len(words)} values; its header's properties need {need}"
            row += 1
    return None


# ------------------------------------------------------------------------------------- glTF/GLB
_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
#: Bytes of a glTF accessor component, by ``componentType``.
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
#: The names of the component types, for messages.
_COMPONENT_NAMES = {
    5120: "BYTE",
    5121: "UNSIGNED_BYTE",
    5122: "SHORT",
    5123: "UNSIGNED_SHORT",
    5125: "UNSIGNED_INT",
    5126: "FLOAT",
}
#: What a mesh primitive's positions and indices may be: (``type``, ``componentType``).
_ROLE_TYPES = {
    "POSITION": {("VEC3", 5126)},
    "indices": {("SCALAR", 5121), ("SCALAR", 5123), ("SCALAR", 5125)},
}
#: Components of an accessor element, by ``type``.
_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: Most elements an accessor without data may declare (it is zeros or sparse): the indices of the
#: largest storey, three per face.
_MAX_EMPTY_ACCESSOR = 3 * MAX_FACES
#: Most bytes a glTF's buffers may declare in all: the largest storey's vertices, indices and normals
#: (5 million faces) fit in a tenth of it. The buffers are read whole, so a file declaring (and
#: holding, sparse) 6 GiB once reached memory.
MAX_BUFFER_BYTES = 2 << 30
#: How many bytes a buffer's side file may hold beyond its ``byteLength`` (padding, a trailing
#: newline): the reader reads side files whole.
SIDE_FILE_SLACK = 1 << 20
#: Prefixes of the glTF extensions a file may require: they change only how it looks (materials,
#: textures, lights), and only its geometry is read.
APPEARANCE_EXTENSIONS = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_", "EXT_lights_")


def check_gltf_layout(source: str, path: Path, data: bytes) -> None:
    """Refuse a GLB or glTF file whose declared sizes exceed the bytes it has.

    Checked first: every extension the file requires is one that changes only its look
    (:data:`APPEARANCE_EXTENSIONS`), and no mesh's positions or indices are a sparse accessor. Then:
    the GLB header's length and every chunk's length against the file; every buffer's
    ``byteLength`` against the bytes behind it (the GLB's BIN chunk, a ``data:`` URI, a side file);
    every bufferView within its buffer; every accessor within its bufferView, or, without one, at
    most three elements per face of the largest storey. The JSON is read with bounded nesting.

    Raises
    ------
    InvalidMeshError
        Naming the declaration (``accessors[3].count``) and the bytes it needs and has, the
        extension required, or the sparse accessor.
    """
    if path.suffix.lower() == ".glb":
        text, bin_length = _glb_chunks(source, data)
    else:
        text, bin_length = data, None
    if text.startswith(b"\xef\xbb\xbf"):
        # glTF 2.0 requires UTF-8 without a BOM, and trimesh's reader fails on one (naming a file the
        # input never names).
        raise InvalidMeshError(
            source, "the glTF JSON starts with a byte-order mark, which glTF 2.0 forbids: save it as UTF-8 without one"
        )
    try:
        doc = read_json(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise InvalidMeshError(source, "the glTF JSON is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise InvalidMeshError(source, f"invalid glTF JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise InvalidMeshError(source, "the glTF JSON is not an object")
    asset = doc.get("asset")
    if not isinstance(asset, dict) or not isinstance(asset.get("version"), str):
        # glTF 2.0 requires asset.version, a string ("2.0"): a number 3 passed the check of strings.
        shown = "missing" if not isinstance(asset, dict) or "version" not in asset else json_text(asset["version"], 20)
        raise InvalidMeshError(source, f'asset.version is {shown}; a glTF 2.0 file names its version as "2.0"')
    version = asset["version"]
    if not re.fullmatch(r"2\.[0-9]+", version):  # ASCII digits, as the schema's pattern ("2.\u0660" passed \d)
        raise InvalidMeshError(source, f"asset.version is {version[:20]!r}: nbs-env reads glTF 2.0, export it so")
    least = asset.get("minVersion")
    if "minVersion" in asset and not (isinstance(least, str) and re.fullmatch(r"[0-9]+\.[0-9]+", least)):
        raise InvalidMeshError(
            source, f'asset.minVersion is {json_text(least, 20)}, not a version string such as "2.0"'
        )
    if least is not None and tuple(int(n) for n in least.split(".")) < (2, 0):
        raise InvalidMeshError(
            source, f"asset.minVersion is {json_text(least)}, below 2.0, which glTF 2.0 does not allow"
        )
    if least is not None and tuple(int(n) for n in least.split(".")) != (2, 0):
        # glTF 2.0 §3.2: a reader that does not support an asset's minVersion refuses it (Khronos's
        # glTF-Asset-Generator: a 2.1 minVersion "should fail to load on a 2.0 client").
        raise InvalidMeshError(
            source,
            f"asset.minVersion is {str(least)[:20]!r}: the file needs a reader of that version; nbs-env reads 2.0",
        )
    # Before anything is read: trimesh skips what it cannot decode (printing a line of its own) and
    # would load the file's fallback or placeholder data as the geometry.
    _check_extensions(source, doc)
    _check_primitives(source, doc)
    _check_sparse(source, doc)
    buffers = _items(source, doc, "buffers")
    views = _items(source, doc, "bufferViews")
    for i, image in enumerate(_items(source, doc, "images")):
        uri = image.get("uri")
        # Images are never read (only the geometry is): a remote one is skipped, a local one is
        # checked to be a file (a fifo there once hung the reader), a missing one allowed.
        if isinstance(uri, str) and (_scheme(uri) in ("", "file") or _DRIVE.match(uri)):
            _side_file(source, path, uri, f"images[{i}]", required=False)
    nodes = _items(source, doc, "nodes")
    _check_node_tree(source, nodes)
    drawn = _check_scenes_and_modes(source, doc, nodes)
    _check_morph_targets(source, doc)  # on a checked node forest and scenes
    _check_skins(source, doc)
    buffer_length = []
    for i, buffer in enumerate(buffers):
        declared = _natural(source, buffer, "byteLength", f"buffers[{i}]")
        have = _buffer_bytes(source, path, buffer, i, bin_length)
        if have is not None and declared > have:
            raise InvalidMeshError(
                source, f"buffers[{i}].byteLength declares {declared:,} bytes, but the file holds {have:,}"
            )
        side = isinstance(buffer.get("uri"), str) and not _is_data(buffer["uri"])
        if side and have is not None and have > declared + SIDE_FILE_SLACK:
            # The reader takes a side file whole, whatever its byteLength says: a 2.5 GB file behind
            # a buffer of 7 kB was read into memory before anything else was checked.
            raise InvalidMeshError(
                source,
                f"buffers[{i}].uri {buffer['uri'][:80]!r} holds {have:,} bytes, but buffers[{i}].byteLength "
                f"declares {declared:,}: not the file this buffer was written to",
            )
        if sum(buffer_length) + declared > MAX_BUFFER_BYTES:
            raise InvalidMeshError(
                source,
                f"buffers[{i}].byteLength brings the buffers to {sum(buffer_length) + declared:,} bytes; at most "
                f"{MAX_BUFFER_BYTES:,} are read (five million faces need a tenth of it)",
            )
        if have is None:  # a side file that is not there, named after the sizes are
            _side_file(source, path, buffer["uri"], f"buffers[{i}]")
        buffer_length.append(declared)
    view_length = []
    for i, view in enumerate(views):
        where = f"bufferViews[{i}]"
        buffer = _natural(source, view, "buffer", where)
        if buffer >= len(buffer_length):
            raise InvalidMeshError(source, f"{where}.buffer is {buffer}, but there are {len(buffer_length)} buffers")
        length = _natural(source, view, "byteLength", where)
        end = _natural(source, view, "byteOffset", where, 0) + length
        if end > buffer_length[buffer]:
            raise InvalidMeshError(
                source, f"{where} ends at byte {end:,} of buffers[{buffer}], which has {buffer_length[buffer]:,}"
            )
        stride = view.get("byteStride")
        if stride is not None and (
            not isinstance(stride, int) or isinstance(stride, bool) or not 4 <= stride <= 252 or stride % 4
        ):
            raise InvalidMeshError(
                source, f"{where}.byteStride must be a multiple of 4 within [4, 252] (glTF 2.0), got {stride!r}"
            )
        view_length.append((length, stride))
    for i, accessor in enumerate(_items(source, doc, "accessors")):
        where = f"accessors[{i}]"
        count = _natural(source, accessor, "count", where)
        if count == 0:  # an empty part was left out as "drawn as points or lines"
            raise InvalidMeshError(source, f"{where}.count is 0; an accessor holds at least one element (glTF 2.0)")
        component, kind = accessor.get("componentType"), accessor.get("type")
        size = _COMPONENT_BYTES.get(component, 0) if isinstance(component, int) else 0
        size *= _TYPE_COMPONENTS.get(kind, 0) if isinstance(kind, str) else 0
        if size == 0:
            raise InvalidMeshError(source, f"{where}: unknown componentType or type")
        if "bufferView" not in accessor:
            if count > _MAX_EMPTY_ACCESSOR:
                raise InvalidMeshError(
                    source,
                    f"{where}.count declares {count:,} elements with no bufferView behind them "
                    f"(at most {_MAX_EMPTY_ACCESSOR:,}, three per face of the largest storey)",
                )
            continue
        view = _natural(source, accessor, "bufferView", where)
        if view >= len(view_length):
            raise InvalidMeshError(source, f"{where}.bufferView is {view}, but there are {len(view_length)}")
        length, stride = view_length[view]
        if stride is not None and stride < size:
            raise InvalidMeshError(
                source,
                f"{where}'s elements take {size} bytes, but bufferViews[{view}].byteStride is {stride}: "
                "they would overlap",
            )
        stride = stride or size
        need = _natural(source, accessor, "byteOffset", where, 0) + max(count - 1, 0) * stride + size
        if need > length:
            raise InvalidMeshError(
                source,
                f"{where} declares {count:,} elements, which need {need:,} bytes, but bufferViews[{view}] "
                f"has {length:,}",
            )
    # Instances multiply a mesh's faces: 100,000 nodes of one small mesh, a 7.7 MB file, were built
    # into 31 million faces before the face bound was met (and the memory ran out first).
    _check_triangle_lists(source, doc)
    check_face_count(source, drawn)


def _check_extensions(source: str, doc: dict) -> None:
    """Refuse a file that requires an extension the reader cannot apply to the geometry.

    Required extensions that only change the look (materials, textures, lights) are fine, since only
    the geometry is read; any other (``KHR_draco_mesh_compression``, ``EXT_meshopt_compression``,
    ``KHR_mesh_quantization``, ...) changes what the buffers mean, and trimesh's reader ignores it.
    """
    required = doc.get("extensionsRequired", [])
    if not isinstance(required, list) or not all(isinstance(x, str) for x in required):
        raise InvalidMeshError(source, "extensionsRequired must be a list of extension names")
    unsupported = [x for x in required if not x.startswith(APPEARANCE_EXTENSIONS)]
    if unsupported:
        names = ", ".join(repr(x[:80]) for x in unsupported[:5]) + (" ..." if len(unsupported) > 5 else "")
        raise InvalidMeshError(
            source,
            f"the file requires glTF extension(s) {names}, which nbs-env cannot read (compressed or "
            "quantized geometry); export it without them",
        )


def _check_primitives(source: str, doc: dict) -> None:
    """glTF 2.0: a mesh holds a list of at least one primitive, each an object; ``{}`` or ``[]``
    dropped the mesh without a word, and ``[5]`` was an AttributeError inside the reader."""
    for m, mesh in enumerate(_items(source, doc, "meshes")):
        primitives = mesh.get("primitives")
        if not isinstance(primitives, list) or not primitives:
            raise InvalidMeshError(
                source, f"meshes[{m}].primitives is {json_text(primitives, 40)}, not a list of one or more primitives"
            )
        for p, primitive in enumerate(primitives):
            if not isinstance(primitive, dict):
                raise InvalidMeshError(
                    source, f"meshes[{m}].primitives[{p}] is {json_text(primitive, 40)}, not a primitive (an object)"
                )


def _drawn_nodes(source: str, doc: dict) -> set[int]:
    """The nodes the scene read draws: its roots and their descendants (on a node forest and scenes
    :func:`_check_scenes_and_modes` has checked)."""
    nodes = _items(source, doc, "nodes")
    scenes = _items(source, doc, "scenes")
    k = doc.get("scene", 0)
    roots = scenes[k].get("nodes", []) if isinstance(k, int) and 0 <= k < len(scenes) else []
    drawn, todo = set(), list(roots)
    while todo:
        n = todo.pop()
        drawn.add(n)
        todo.extend(nodes[n].get("children", []))
    return drawn


def _check_skins(source: str, doc: dict) -> None:
    """glTF 2.0 §3.7.3: a skinned mesh is drawn by its joints' transforms, not its node's; the
    reader applies neither, so a drawn skinned node would be another storey than other readers show:
    refused. A skinned node no scene draws changes nothing."""
    nodes = _items(source, doc, "nodes")
    skinned = [i for i, node in enumerate(nodes) if "mesh" in node and "skin" in node]
    if not skinned:
        return
    drawn = _drawn_nodes(source, doc)
    for i in skinned:
        if i in drawn:
            raise InvalidMeshError(
                source,
                f"nodes[{i}] draws its mesh with a skin (skins), which nbs-env does not apply: export the mesh "
                "with its pose applied",
            )


def _check_morph_targets(source: str, doc: dict) -> None:
    """glTF 2.0 §3.7.2.2: a primitive's drawn positions are its own plus its POSITION morph targets
    times the drawing node's weights (the node's own, else the mesh's). trimesh reads the base alone,
    so a mesh a drawn node shows at non-zero weights would be another storey than the one other
    readers show: refused. Targets at weight 0, targets that move no position (NORMAL alone) and
    nodes no scene draws change nothing."""
    meshes = _items(source, doc, "meshes")
    nodes = _items(source, doc, "nodes")
    moving = {
        m
        for m, mesh in enumerate(meshes)
        if any(
            isinstance(p, dict)
            and isinstance(p.get("targets"), list)
            and any(isinstance(t, dict) and "POSITION" in t for t in p["targets"])
            for p in mesh["primitives"]
        )
    }
    if not moving:
        return
    for i in sorted(_drawn_nodes(source, doc)):
        m = nodes[i].get("mesh")
        if m not in moving:
            continue
        where = f"nodes[{i}].weights" if "weights" in nodes[i] else f"meshes[{m}].weights"
        value = nodes[i].get("weights", meshes[m].get("weights"))
        if value is None:
            continue
        if not (isinstance(value, list) and all(type(w) in (int, float) and is_finite(w) for w in value)):
            raise InvalidMeshError(source, f"{where} must be a list of finite numbers, got {json_text(value, 40)}")
        if any(w != 0 for w in value):
            raise InvalidMeshError(
                source,
                f"meshes[{m}] has morph targets drawn at {where} {value[:4]}, which nbs-env does not apply "
                "(it would read the undeformed mesh): export the mesh with the morph applied",
            )


def _check_sparse(source: str, doc: dict) -> None:
    """Refuse sparse accessors among a mesh's positions or indices: trimesh reads only the dense base
    (zeros, or the bufferView) and drops the sparse values, so the geometry would be wrong. Refuse
    positions that are not VEC3 floats and indices that are not unsigned integer scalars."""
    accessors = _items(source, doc, "accessors")
    for m, mesh in enumerate(_items(source, doc, "meshes")):
        for p, primitive in enumerate(mesh["primitives"]):  # lists of objects (_check_primitives)
            attributes = primitive.get("attributes")
            used = {"indices": primitive.get("indices")}
            if isinstance(attributes, dict):
                used["POSITION"] = attributes.get("POSITION")
            for role, index in used.items():
                if not (isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(accessors)):
                    continue
                accessor = accessors[index]
                where = f"accessors[{index}] ({role} of meshes[{m}].primitives[{p}])"
                if "sparse" in accessor:
                    raise InvalidMeshError(
                        source,
                        f"{where} is sparse, which nbs-env cannot read (its sparse values would be dropped); "
                        "export the file without sparse accessors",
                    )
                # What the glTF 2.0 specification allows a mesh's positions and indices to be (without
                # KHR_mesh_quantization, refused above): anything else was read as other geometry or
                # failed inside the reader.
                kind, component = accessor.get("type"), accessor.get("componentType")
                allowed = _ROLE_TYPES[role]
                if (kind, component) not in allowed:
                    names = " or ".join(f"{t} of {_COMPONENT_NAMES[c]}" for t, c in sorted(allowed, key=lambda a: a[1]))
                    shown = (
                        _COMPONENT_NAMES.get(component, repr(component))
                        if isinstance(component, int)
                        else repr(component)
                    )
                    raise InvalidMeshError(
                        source, f"{where} is {kind!r} of {shown}; the glTF specification has {names}"
                    )


def _glb_chunks(source: str, data: bytes) -> tuple[bytes, int]:
    """The JSON chunk of a GLB and the length of its BIN chunk (0 without one)."""
    if data[:4] != _GLB_MAGIC:
        raise InvalidMeshError(source, "not a GLB file: it does not start with the 'glTF' magic")
    if len(data) < 20:
        raise InvalidMeshError(
            source, f"the GLB file is {len(data)} bytes: a header with no JSON chunk after it (it is truncated)"
        )
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InvalidMeshError(source, f"a GLB of version {version} (glTF 2.0 is version 2): export it as glTF 2.0")
    if length > len(data):
        raise InvalidMeshError(
            source, f"the GLB header declares {length:,} bytes, but the file has {len(data):,}: it is truncated"
        )
    if length < len(data):
        raise InvalidMeshError(
            source,
            f"the GLB header declares {length:,} bytes, but the file has {len(data):,}: bytes follow its end "
            "(two files joined, or a header written before the file grew)",
        )
    chunks = []
    offset = 12
    while offset + 8 <= length:
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        if offset + 8 + chunk_length > length:
            raise InvalidMeshError(
                source,
                f"GLB chunk {len(chunks)} declares {chunk_length:,} bytes, but {length - offset - 8:,} follow it",
            )
        chunks.append((chunk_type, data[offset + 8 : offset + 8 + chunk_length]))
        offset += 8 + chunk_length
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise InvalidMeshError(source, "the GLB file's first chunk is not its JSON")
    if any(kind == _CHUNK_JSON for kind, _ in chunks[1:]):
        # The specification allows exactly one: readers differ in which they would take.
        raise InvalidMeshError(source, "the GLB file holds a second JSON chunk (a GLB holds one)")
    # The specification has readers skip chunks of types they do not know, wherever they stand, and
    # the reader takes the first BIN chunk after the JSON as buffer 0.
    return chunks[0][1], next((len(c) for t, c in chunks[1:] if t == _CHUNK_BIN), 0)


def _buffer_bytes(source: str, path: Path, buffer: dict, index: int, bin_length: int | None) -> int | None:
    """Bytes behind a buffer; None where it cannot be told here (a side file that is missing: the
    parser reports it)."""
    uri = buffer.get("uri")
    if uri is None:
        if bin_length is None or index != 0:
            raise InvalidMeshError(source, f"buffers[{index}] has no uri and no GLB BIN chunk to hold it")
        return bin_length
    if not isinstance(uri, str):
        raise InvalidMeshError(source, f"buffers[{index}].uri is not a string")
    if _is_data(uri):
        if not uri.partition(",")[0].lower().endswith(";base64"):
            raise InvalidMeshError(
                source,
                f"buffers[{index}].uri is a data: URI without ;base64 (glTF's buffers are base64; nbs-env reads "
                "no other encoding)",
            )
        if "%" in uri.partition(",")[2]:
            # trimesh decodes the base64 as written, skipping the escapes: other bytes, silently.
            raise InvalidMeshError(
                source, f"buffers[{index}].uri is a data: URI with percent-escapes in its base64: write it unescaped"
            )
        odd = _NOT_BASE64.search(uri.partition(",")[2])
        if odd is not None:
            # Skipped by the decoder, they shift every byte after them (URL-safe "-" and "_" included):
            # the faces were then said to name vertices outside the file.
            what = "padding ('=') before its end" if odd.group()[0] == "=" else f"{odd.group()!r}, which base64 has not"
            raise InvalidMeshError(
                source,
                f"buffers[{index}].uri holds {what}, at character {odd.start()} of its base64 data (URL-safe base64 "
                "writes '-' and '_' for '+' and '/'; glTF's is the standard one)",
            )
        try:
            return len(base64.b64decode(uri.partition(",")[2], validate=False))
        except (binascii.Error, ValueError):
            raise InvalidMeshError(source, f"buffers[{index}].uri is not base64 data") from None
    side = _side_file(source, path, uri, f"buffers[{index}]", required=False)
    return side.stat().st_size if side is not None else None


_DRIVE = re.compile(r"[A-Za-z]:[\\/]")


#: The first character of base64 data that is no part of the standard alphabet (RFC 4648 §4), its
#: padding at the end only.
_NOT_BASE64 = re.compile(r"[^A-Za-z0-9+/=]|=+(?=[^=])")


def _is_data(uri: str) -> bool:
    """A ``data:`` URI, its scheme in any case (RFC 3986 §3.1: schemes are case-insensitive)."""
    return uri[:5].lower() == "data:"


def _scheme(uri: str) -> str:
    """The scheme of ``uri`` in lower case; "?" for text that is no URI (an image's is never read)."""
    try:
        return urlsplit(uri).scheme.lower()
    except ValueError:  # an unbalanced "[" in a host
        return "?"


def side_file_path(source: str, path: Path, uri: str, where: str = "a uri") -> Path:
    """The local file a glTF ``uri`` that is no ``data:`` URI names.

    The ``uri`` is a URI reference (glTF 2.0, RFC 3986): percent-escapes are decoded (``buf%20one.bin``
    is ``buf one.bin``), a relative reference is resolved against the glTF file's folder (``../b.bin``
    included, as exporters write shared buffers), and a ``file:`` URI names its path.

    Raises
    ------
    InvalidMeshError
        A URI of another scheme (``http:``): nbs-env reads local files only.
    """
    try:
        parts = urlsplit(uri)
    except ValueError as exc:  # "file://[::1/x.bin": an unbalanced "[" in the host
        raise InvalidMeshError(source, f"{where}.uri {uri[:80]!r} is no valid URI ({exc})") from None
    scheme = parts.scheme.lower()
    name = unquote(parts.path)  # a query or a fragment names no part of a file
    if "\0" in name:
        raise InvalidMeshError(source, f"{where}.uri {uri[:80]!r} holds a NUL character, which no file name has")
    if scheme and scheme != "file" and len(scheme) > 1:  # one letter: a Windows drive, as some exporters write
        raise InvalidMeshError(
            source,
            f"{where}.uri {uri[:80]!r} is a {scheme}: URI; nbs-env reads local files only (save it beside the glTF)",
        )
    if parts.netloc and parts.netloc.lower() != "localhost" and len(scheme) != 1:
        # file://server/share/x.bin (and //server/...) names a file on another machine: without the
        # host, a local /share/x.bin would be read in its place.
        raise InvalidMeshError(
            source,
            f"{where}.uri {uri[:80]!r} names a file on host {parts.netloc[:40]!r}; nbs-env reads local files",
        )
    if scheme == "file":
        return path.parent / name  # an absolute path stays one
    return path.parent / (uri if len(scheme) == 1 else name)


def _side_file(source: str, path: Path, uri: str, where: str, required: bool = True) -> Path | None:
    """The file a ``uri`` names (:func:`side_file_path`); a missing one is refused where ``required``
    (a buffer), else None (an image, which is not read). A fifo or a device would hang the parser or
    feed it without end: refused."""
    side = side_file_path(source, path, uri, where)
    try:
        if not side.exists():
            if required:
                raise InvalidMeshError(source, f"{where}.uri {uri[:80]!r} names {side}, which does not exist")
            return None
        regular = side.is_file()
    except OSError as exc:
        raise InvalidMeshError(source, f"{where}.uri {uri!r}: {exc.strerror or exc}") from None
    if not regular:
        raise InvalidMeshError(source, f"{where}.uri {uri!r} is not a regular file (a folder, a fifo or a device)")
    return side


def _check_scenes_and_modes(source: str, doc: dict, nodes: list[dict]) -> int:
    """``scene`` names a scene and each scene's ``nodes`` name nodes (an IndexError in the reader);
    a node with a mesh holds no camera (the reader keeps the camera and drops the mesh without a
    word); a node's mesh and a primitive's accessors exist (a missing one was dropped without a word,
    -1 read as the last); a primitive's ``mode`` is one of glTF's seven (99 made the part vanish),
    and not a fan (the reader drops fans). Returns the faces the nodes draw, instances counted."""
    scenes = _items(source, doc, "scenes")
    if "scenes" in doc and not scenes:
        raise InvalidMeshError(source, "the file's scenes list is empty: it shows nothing")
    if "scene" in doc:
        k = doc["scene"]
        if not (isinstance(k, int) and not isinstance(k, bool) and 0 <= k < len(scenes)):
            raise InvalidMeshError(source, f"scene is {json_text(k, 40)}, but the file has {len(scenes)} scene(s)")
    children = {k for node in nodes for k in node.get("children", [])}  # once: a scene per node was quadratic
    if not scenes and _items(source, doc, "meshes"):
        # glTF 2.0 allows a file of no scene (a library of parts); the reader then draws nothing, and
        # "the mesh is empty" named no cause.
        raise InvalidMeshError(
            source,
            f"the file lists no scenes, so nothing of its {len(nodes)} node(s) and "
            f"{len(_items(source, doc, 'meshes'))} mesh(es) is drawn: export it with a scene",
        )
    if len(scenes) > 1 and "scene" not in doc:
        warnings.warn(
            f"{source}: the file has {len(scenes)} scenes and names none ('scene'): scenes[0] is read", stacklevel=4
        )
    for i, scene in enumerate(scenes):
        roots = scene.get("nodes", [])
        if not isinstance(roots, list) or not all(
            isinstance(n, int) and not isinstance(n, bool) and 0 <= n < len(nodes) for n in roots
        ):
            raise InvalidMeshError(source, f"scenes[{i}].nodes must name nodes 0..{len(nodes) - 1}")
        # glTF 2.0: a scene lists root nodes, each once; a repeat or a child drew its meshes twice.
        twice = [n for n, count in Counter(roots).items() if count > 1]
        if twice:
            raise InvalidMeshError(source, f"scenes[{i}].nodes lists node {twice[0]} twice")
        inner = [n for n in roots if n in children]
        if inner:
            raise InvalidMeshError(
                source, f"scenes[{i}].nodes lists node {inner[0]}, the child of another node: a scene lists roots"
            )
    meshes = _items(source, doc, "meshes")
    accessors = _items(source, doc, "accessors")
    for key in ("scenes", "nodes", "meshes", "materials"):
        # The reader keys its geometry by these names: a list as a name was a TypeError from inside it.
        for i, item in enumerate(_items(source, doc, key)):
            if "name" in item and not isinstance(item["name"], str):
                raise InvalidMeshError(source, f"{key}[{i}].name is {json_text(item['name'], 40)}, not a string")
    for i, node in enumerate(nodes):
        if "mesh" in node and "camera" in node:
            raise InvalidMeshError(
                source,
                f"nodes[{i}] holds both a mesh and a camera, and the reader keeps only the camera: give the "
                "camera a node of its own",
            )
        # A mesh the reader cannot find is dropped without a word (and -1 is the last one in Python).
        if "mesh" in node and _natural(source, node, "mesh", f"nodes[{i}]") >= len(meshes):
            raise InvalidMeshError(
                source, f"nodes[{i}].mesh is {node['mesh']}, but the file has {len(meshes)} mesh(es)"
            )
    faces: list[int] = []  # each mesh's triangles, for the instances' total below
    for m, mesh in enumerate(meshes):
        faces.append(0)
        for p, primitive in enumerate(mesh["primitives"]):  # lists of objects (_check_primitives)
            where = f"meshes[{m}].primitives[{p}]"
            mode = primitive.get("mode", 4)
            if not (isinstance(mode, int) and not isinstance(mode, bool) and 0 <= mode <= 6):
                raise InvalidMeshError(source, f"{where}.mode is {json_text(mode, 40)}; glTF's modes are 0 to 6")
            if mode == 6:
                # trimesh drops a fan whole, silently: the part vanished from the storey.
                raise InvalidMeshError(
                    source, f"{where} is a triangle fan (mode 6), which the reader does not read: export triangles"
                )
            attributes = primitive.get("attributes")
            if not isinstance(attributes, dict) or "POSITION" not in attributes:
                raise InvalidMeshError(source, f"{where}.attributes has no POSITION")
            for role, value in (
                *attributes.items(),
                *([("indices", primitive["indices"])] if "indices" in primitive else []),
            ):
                if not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value < len(accessors)):
                    shown = f"{where}.{role}" if role == "indices" else f"{where}.attributes.{role}"
                    raise InvalidMeshError(
                        source, f"{shown} is {json_text(value, 40)}, but the file has {len(accessors)} accessor(s)"
                    )
            counted = accessors[primitive["indices"] if "indices" in primitive else attributes["POSITION"]]
            count = counted.get("count", 0) if isinstance(counted, dict) else 0
            if isinstance(count, int) and mode in (4, 5):  # triangles, or a strip's count - 2
                faces[m] += count // 3 if mode == 4 else max(count - 2, 0)
    return sum(faces[node["mesh"]] for node in nodes if "mesh" in node)


def _check_triangle_lists(source: str, doc: dict) -> None:
    """glTF 2.0: a triangle list's index (or vertex) count is a multiple of three; trimesh failed
    inside on another ("cannot reshape array of size 35"). On primitives and accessors checked."""
    accessors = doc.get("accessors", [])
    for m, mesh in enumerate(doc.get("meshes", [])):
        for p, primitive in enumerate(mesh["primitives"]):
            if primitive.get("mode", 4) != 4:
                continue
            role = "indices" if "indices" in primitive else "attributes.POSITION"
            count = accessors[primitive["indices"] if "indices" in primitive else primitive["attributes"]["POSITION"]][
                "count"
            ]
            if count % 3:
                raise InvalidMeshError(
                    source,
                    f"meshes[{m}].primitives[{p}].{role}'s accessor counts {count:,}, not a multiple of 3 as a "
                    "triangle list's (mode 4)",
                )


#: A node's transform: its properties and their number of components (glTF 2.0).
_TRANSFORM_LENGTHS = {"matrix": 16, "translation": 3, "rotation": 4, "scale": 3}
#: How far from 1 a quaternion's length, and from 0 a matrix's bottom row or its columns' cosines, may
#: lie: float32 exporters land within 1e-6; 1e-3 is a transform no exporter meant.
UNIT_TOLERANCE = 1e-3


def _not_trs(matrix: list[float]) -> str | None:
    """Why a node's column-major 4x4 matrix is not decomposable to translation, rotation and scale
    (glTF 2.0 §5.25), or None: its last row must be 0, 0, 0, 1 (readers that divide by w and those that
    drop the row read different storeys) and its columns orthogonal (no shear)."""
    bottom = (matrix[3], matrix[7], matrix[11], matrix[15] - 1.0)
    if max(abs(v) for v in bottom) > UNIT_TOLERANCE:
        return f"its last row is {matrix[3]:g}, {matrix[7]:g}, {matrix[11]:g}, {matrix[15]:g}, not 0, 0, 0, 1"
    columns = [matrix[0:3], matrix[4:7], matrix[8:11]]
    for a, b in ((0, 1), (0, 2), (1, 2)):
        dot = sum(x * y for x, y in zip(columns[a], columns[b], strict=True))
        norms = math.sqrt(sum(x * x for x in columns[a]) * sum(y * y for y in columns[b]))
        if norms > 0 and abs(dot) > UNIT_TOLERANCE * norms:
            return f"columns {a} and {b} are not at right angles: a shear"
    return None


def _check_node_tree(source: str, nodes: list[dict]) -> None:
    """The nodes' ``children`` must name nodes and form a forest: a node that is its own descendant
    once sent the scene graph's walk round without end."""
    children: list[list[int]] = []
    for i, node in enumerate(nodes):
        for key, length in _TRANSFORM_LENGTHS.items():
            # A transform of strings was read as zeros: a storey "0 m high", not the file's mistake.
            value = node.get(key)
            if value is not None and not (
                isinstance(value, list)
                and len(value) == length
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) and is_finite(v) for v in value)
            ):
                raise InvalidMeshError(
                    source, f"nodes[{i}].{key} must be {length} finite numbers, got {json_text(value, 60)}"
                )
        trs = [key for key in ("translation", "rotation", "scale") if key in node]
        if "matrix" in node and trs:
            # glTF 2.0 §5.25: a matrix or translation/rotation/scale, not both; readers differ (three.js
            # takes the matrix alone, the reader here both: walls lifted by the translation).
            raise InvalidMeshError(
                source, f"nodes[{i}] has both a matrix and {', '.join(trs)}; a glTF node has one or the other"
            )
        rotation = node.get("rotation")
        if rotation is not None and abs(math.sqrt(sum(v * v for v in rotation)) - 1.0) > UNIT_TOLERANCE:
            # glTF 2.0 §5.25: a unit quaternion. Readers differ on others (normalised here, used as a
            # scaled rotation by some), so the file's storey is not one thing; glTF-Validator refuses it too.
            length = math.sqrt(sum(v * v for v in rotation))
            raise InvalidMeshError(source, f"nodes[{i}].rotation is not a unit quaternion (length {length:.4g})")
        if "matrix" in node:
            problem = _not_trs(node["matrix"])
            if problem:
                raise InvalidMeshError(
                    source, f"nodes[{i}].matrix is not a translation, rotation and scale ({problem}), as glTF requires"
                )
        kids = node.get("children", [])
        if not isinstance(kids, list) or not all(
            isinstance(k, int) and not isinstance(k, bool) and 0 <= k < len(nodes) for k in kids
        ):
            raise InvalidMeshError(source, f"nodes[{i}].children must name nodes 0..{len(nodes) - 1}")
        children.append(kids)
    parents = [0] * len(nodes)
    for kids in children:
        for k in kids:
            parents[k] += 1
    shared = [k for k, n in enumerate(parents) if n > 1]
    if shared:
        raise InvalidMeshError(
            source, f"nodes[{shared[0]}] is the child of {parents[shared[0]]} nodes; a node has one parent"
        )
    # With one parent each, the nodes form a forest unless some lie on a cycle: those are never
    # reached from the roots (the nodes without a parent).
    seen = 0
    stack = [k for k, n in enumerate(parents) if n == 0]
    while stack:
        k = stack.pop()
        seen += 1
        stack.extend(children[k])
    if seen < len(nodes):
        raise InvalidMeshError(source, "the glTF nodes' children form a cycle (a node is its own descendant)")


def _items(source: str, doc: dict, key: str) -> list[dict]:
    items = doc.get(key, [])
    if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
        raise InvalidMeshError(source, f"the glTF {key!r} is not a list of objects")
    return items


def _natural(source: str, obj: dict, key: str, where: str, default: int | None = None) -> int:
    """``obj[key]`` as an integer >= 0 (``default`` when absent and a default is given)."""
    value: Any = obj.get(key, default)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise InvalidMeshError(source, f"{where}.{key} must be an integer >= 0, got {value!r}")
    return value
