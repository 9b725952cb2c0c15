"""The largest storey nbs-env loads, stated once, and the units a mesh file's coordinates may be in.

A building drawn in millimetres and read as metres is a thousand times too large in every direction:
the ground-truth samples of its surfaces (one per 25 cm²) and the grids sized from its bounds would
need hundreds of GiB, and a coordinate of 1e300 makes the geometry library fail deep inside. Every
:class:`~scenes.model.Scene` is checked against these limits when it is built, before anything is
sized from it, and the mesh importers check them as soon as the vertices are read, before any room
outline is computed. The message names the likely cause (a unit) and the option that fixes it.

Limits
------
:data:`MAX_STOREY_WIDTH`, 500 m across (x or y)
    The largest interiors a scanning robot surveys (exhibition halls, factory floors, terminals) are a
    few hundred metres across; at 500 m by 500 m the ground truth alone is some 10^8 samples. A 10 m
    room in millimetres is 10,000 m across, in centimetres 1,000 m.
:data:`MAX_STOREY_HEIGHT`, 50 m from the lowest to the highest point
    A storey is 2.2 to 6 m high, a hall or an atrium up to some 40 m. Any storey of ordinary height
    drawn in millimetres (2,500), centimetres (250) or inches (98) exceeds it, so this limit finds
    the unit slips of small buildings too; one in feet (8.2) does not, and loads 3.3 times too small.
:data:`MAX_FACES`, 5 million triangles
    A detailed storey is 10^4 to 10^6 triangles; the per-face work of loading (room outlines,
    interior probes, the ray caster's tree) grows with the count, and beyond this it runs to minutes
    and gigabytes for a model no scan plan needs at that detail.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.errors import StoreySizeError

__all__ = [
    "MAX_FACES",
    "MAX_STOREY_HEIGHT",
    "MAX_STOREY_WIDTH",
    "UNITS",
    "check_face_count",
    "check_storey_size",
    "unit_scale",
]

MAX_STOREY_WIDTH = 500.0
MAX_STOREY_HEIGHT = 50.0
MAX_FACES = 5_000_000

#: Length units of a mesh file's coordinates: metres per unit.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048, "in": 0.0254}
_UNIT_WORDS = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "ft": "feet", "in": "inches"}
#: The height of an ordinary storey, metres: the unit that brings a storey's height nearest to it is
#: the likely one of a file that is too large.
_TYPICAL_HEIGHT = 3.0


def unit_scale(units: str) -> float:
    """Metres per unit of ``units`` (one of :data:`UNITS`).

    Raises
    ------
    ValueError
        An unknown unit; the message lists the known ones.
    """
    if units not in UNITS:
        raise ValueError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    return UNITS[units]


def check_face_count(source: str, n_faces: int) -> None:
    """Raise :class:`StoreySizeError` when ``n_faces`` exceeds :data:`MAX_FACES`."""
    if n_faces > MAX_FACES:
        raise StoreySizeError(
            source,
            f"the mesh has {n_faces:,} faces (the most nbs-env loads is {MAX_FACES:,}): simplify or split the model",
        )


def check_storey_size(
    source: str, vertices: np.ndarray, n_faces: int, *, units: str | None = None, stated: bool = False
) -> None:
    """Refuse a storey beyond the limits (see the module docstring) before anything is sized from it.

    Parameters
    ----------
    source : str
        Where the storey came from, for the message.
    vertices : (V, 3) float
        Finite vertex coordinates in metres, z up.
    n_faces : int
        Number of triangles.
    units : str, optional
        The unit the coordinates were read in, when the source has a ``units`` option (mesh files):
        the message then suggests the unit that fits. None for sources in metres by definition.
    stated : bool
        The coordinates were scaled to metres by the unit the file states (IFC's
        ``IfcUnitAssignment``): the message then doubts that unit.

    Raises
    ------
    StoreySizeError
        Too many faces, too wide or too tall; the message gives the sizes, the limits and the
        likely cause.
    """
    check_face_count(source, n_faces)
    v = np.asarray(vertices, dtype=float).reshape(-1, 3)
    if len(v) == 0:
        return
    with np.errstate(over="ignore", invalid="ignore"):  # 1e308 - (-1e308) is inf: still too large
        extent = v.max(axis=0) - v.min(axis=0)
    width, height = float(max(extent[0], extent[1])), float(extent[2])
    if width <= MAX_STOREY_WIDTH and height <= MAX_STOREY_HEIGHT:
        return
    sizes = (
        f"the storey is {_metres(width)} across and {_metres(height)} high (the most nbs-env loads is "
        f"{MAX_STOREY_WIDTH:g} m across and {MAX_STOREY_HEIGHT:g} m high)"
    )
    guess = _likely_unit(width, height, units or "m")
    if stated:
        cause = "read in the length unit the file states: check its IfcUnitAssignment"
    elif units is not None and guess is not None:
        cause = f"is the file in {_UNIT_WORDS[guess]}? pass --units {guess} (load_scene's units={guess!r})"
    elif guess is not None:
        cause = f"are its lengths in {_UNIT_WORDS[guess]}? they must be metres"
    else:
        cause = "is there geometry far from the building, or are the coordinates broken?"
    raise StoreySizeError(source, f"{sizes}: {cause}")


def _likely_unit(width: float, height: float, read_as: str) -> str | None:
    """The unit, other than ``read_as``, that brings the storey within the limits with a height
    nearest an ordinary storey's; None when no unit does."""
    if not (math.isfinite(width) and math.isfinite(height)):
        return None
    best, best_score = None, math.inf
    for name, scale in UNITS.items():
        factor = scale / UNITS[read_as]
        w, h = width * factor, height * factor
        # A unit that leaves the storey under a metre high is not the file's.
        if w > MAX_STOREY_WIDTH or h > MAX_STOREY_HEIGHT or h < 1.0:
            continue
        score = abs(math.log(h / _TYPICAL_HEIGHT))
        if score < best_score:
            best, best_score = name, score
    return None if best == read_as else best


def _metres(value: float) -> str:
    if not math.isfinite(value):
        return "an unbounded number of metres"
    return f"{value:,.0f} m" if 100 <= value < 1e15 else f"{value:.3g} m"
