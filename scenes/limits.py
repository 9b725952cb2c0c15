"""The largest (and the smallest) storey nbs-env loads, stated once, and the units a mesh file's coordinates may be in.

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
:data:`BYTES_PER_FACE`, the memory a mesh's load takes per face
    Measured on the most demanding storey met: ``l_room`` subdivided to 348,160 faces (a binary PLY
    of triangles and quads) peaked at 1.42 GB in ``nbs scenes info`` (about 3 KB a face beyond the
    libraries' 0.4 GB), where a 4.9-million-face PLY of simpler geometry peaked at 3.7 GB. A file whose
    declared faces need more than the process may still allocate (its address-space limit,
    ``ulimit -v``, or the memory the machine has available) is refused before it is read: at 800
    bytes a face a 1.4-million-face storey passed the check and aborted inside the OpenMP runtime
    with no message.
:data:`MAX_STRUCTURE_SAMPLES`, 20 million, and :data:`BYTES_PER_SAMPLE`, the ground truth's samples
    The evaluation samples the structural surface at one point per ``coverage_spacing``² (400 per m²
    at the default 5 cm): a 150 m by 150 m open hall (50,000 m² of floor, ceiling and walls) is 20
    million samples. Finding which face the interior (:func:`scenes.interior.interior_samples`) peaked
    at 410 to 460 bytes a sample, measured on square halls of 30 and 60 m. A storey within the
    extent bounds can still need more (a 490 m hall, 1.9·10^8 samples, asked for 1.45 GiB in one
    array and many times that in all): it is refused, with the spacing that fits, before the samples
    are made.
:data:`BYTES_PER_NEIGHBOUR`, 64, the scan-quality neighbourhoods (checked by :func:`check_sample_count`)
    The quality's density (:meth:`nbs_env.evaluation.CoverageMeter.quality`) counts, for every
    sample, the samples within ``quality.density_radius``: on a surface about π r² / s² of them at
    spacing s. Building that sparse matrix peaked at 44 bytes a neighbour (200,000 samples of a plane
    at 5 cm, radii 0.2 and 0.3 m); 64 leaves room. At the finest spacing (1 cm) or the largest radius
    (1 m) an office storey needed 3 to 18 GB, asked for after the run, which then lost its report:
    refused before the first scan (:func:`check_sample_count` with ``density_radius``), with a spacing
    and a radius that fit.
:data:`MAX_MESH_FILE_BYTES`, 1 GiB, a mesh file read whole (checked by :func:`check_file_size`)
    An OBJ of the largest storey (5 million faces) takes some 300 MB of text; a binary file less. A
    file is read into memory before it is parsed, so one of gigabytes (a point cloud, a disk image
    given by mistake) is refused before it is read, as is one whose reading (about
    :data:`READ_FACTOR` times its size) needs more memory than the process may still allocate.
:data:`MIN_STOREY_WIDTH`, 1 m across, for files (mesh, IFC)
    No room is under a metre across; a file in metres read as millimetres (or an IFC file whose
    ``IfcUnitAssignment`` says millimetres for coordinates in metres) is a thousand times too small.
:data:`MAX_ORIGIN_DISTANCE`, 10 km from the origin (every source, checked by :func:`scenes.load_scene`)
    The simulator casts rays and bins points in float32 and on voxel grids of at most 2^20 cells
    from the origin: at 10 km a float32 step is about 1 mm, beyond it the scans lose millimetres and
    a 1 cm grid runs out of cells. Georeferenced files (coordinates of 10^5 to 10^6 m) must be moved
    near the origin first. :func:`scenes.importers.load_mesh_scene` and
    :func:`scenes.ifc.load_ifc_scene` keep the coordinates as they are (an export round trip keeps
    them exactly); :func:`scenes.load_scene` refuses them.
:data:`MIN_STOREY_HEIGHT`, 1.5 m from the floor to the top of the walls and ceilings (checked, with
:data:`STOREY_GAP`, by :func:`scenes.load_scene` for every source)
    Nothing lower is a storey a robot scans (a flattened model, z and y swapped); nor is one whose
    walls have no area (:func:`check_storey_shape`).
:data:`STOREY_GAP`, 2 m, and :data:`STOREY_SHARE`, 10%
    A storey's floor faces may lie on several levels (split levels, a sunken room, stairs and ramps
    labelled floor), but floor levels more than :data:`STOREY_GAP` apart with no floor between them,
    each holding at least :data:`STOREY_SHARE` of the floor area, are two storeys in one file.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.errors import MissingStructureError, StoreySizeError
from scenes.labels import SurfaceClass
from scenes.memory import machine_memory, memory_left

__all__ = [
    "BYTES_PER_FACE",
    "BYTES_PER_NEIGHBOUR",
    "BYTES_PER_SAMPLE",
    "MAX_FACES",
    "MAX_MESH_FILE_BYTES",
    "MAX_ORIGIN_DISTANCE",
    "MAX_STOREY_HEIGHT",
    "MAX_STOREY_WIDTH",
    "MAX_STRUCTURE_SAMPLES",
    "MIN_STOREY_HEIGHT",
    "MIN_STOREY_WIDTH",
    "READ_FACTOR",
    "STOREY_GAP",
    "STOREY_SHARE",
    "UNITS",
    "check_face_count",
    "check_file_size",
    "check_origin_distance",
    "check_sample_count",
    "check_storey_shape",
    "check_storey_size",
    "is_finite",
    "machine_memory",
    "memory_left",
    "unit_scale",
]

MAX_STOREY_WIDTH = 500.0
#: The most digits a seed has (a generated storey's, an episode's): numpy seeds its generator from
#: any integer, no one types more, and a run's folder is named by its seed (``seed{N}``).
MAX_SEED_DIGITS = 100
MAX_STOREY_HEIGHT = 50.0
MAX_FACES = 5_000_000
BYTES_PER_FACE = 3072
MIN_STOREY_WIDTH = 1.0
MAX_STRUCTURE_SAMPLES = 20_000_000
BYTES_PER_SAMPLE = 512
BYTES_PER_NEIGHBOUR = 64
MAX_MESH_FILE_BYTES = 1 << 30
#: The memory a mesh file's bytes take while it is read and parsed, per byte of the file: its bytes,
#: their text and the parser's lists (an OBJ's lines), before the faces are counted.
READ_FACTOR = 4
MAX_ORIGIN_DISTANCE = 10_000.0
MIN_STOREY_HEIGHT = 1.5
STOREY_GAP = 2.0
STOREY_SHARE = 0.10

#: Length units of a mesh file's coordinates: metres per unit.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048, "in": 0.0254}
_UNIT_WORDS = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "ft": "feet", "in": "inches"}
#: The height of an ordinary storey, metres: the unit that brings a storey's height nearest to it is
#: the likely one of a file that is too large.
_TYPICAL_HEIGHT = 3.0
#: The likely cause of a storey lower than MIN_STOREY_HEIGHT, unless the caller knows better.
_LOW_HINT = "is the model flattened?"


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
    """Raise :class:`StoreySizeError` when ``n_faces`` exceeds :data:`MAX_FACES`, or when loading
    them (:data:`BYTES_PER_FACE` each) needs more memory than the process may still allocate."""
    if n_faces > MAX_FACES:
        raise StoreySizeError(
            source,
            f"the mesh has {n_faces:,} faces (the most nbs-env loads is {MAX_FACES:,}): simplify or split the model",
        )
    _check_memory(
        source,
        n_faces * BYTES_PER_FACE,
        f"loading the mesh's {n_faces:,} faces",
        "simplify or split the model, or free memory",
    )


def check_sample_count(source: str, area: float, spacing: float, density_radius: float | None = None) -> None:
    """Raise :class:`StoreySizeError` when sampling ``area`` m² of structural surface every ``spacing``
    metres makes more than :data:`MAX_STRUCTURE_SAMPLES` samples, or needs more than the memory the
    process may still allocate: :data:`BYTES_PER_SAMPLE` a sample and, with ``density_radius``, the
    scan-quality neighbourhoods of the samples within it (:data:`BYTES_PER_NEIGHBOUR` a neighbour,
    about π r² / s² + 1 a sample). The message gives a spacing that meets every bound and, with
    ``density_radius``, the radius that fits at this spacing."""
    n = area / spacing**2
    r2 = 0.0 if density_radius is None else math.pi * density_radius**2

    def bytes_per_sample(s: float) -> float:
        return BYTES_PER_SAMPLE + (0.0 if density_radius is None else BYTES_PER_NEIGHBOUR * (r2 / s**2 + 1))

    fit = math.sqrt(area / MAX_STRUCTURE_SAMPLES)
    radius_fit = ""
    left = memory_left()
    if left is not None:  # the spacing advised must meet the memory bound too, not the count's alone
        budget = max(float(left[0]), 1.0)
        # area/s² × (B_s + B_n + B_n π r²/s²) <= budget, a quadratic in u = 1/s².
        a, b = area * BYTES_PER_NEIGHBOUR * r2, area * bytes_per_sample(math.inf)
        u = budget / b if a == 0 else (-b + math.sqrt(b * b + 4 * a * budget)) / (2 * a)
        fit = max(fit, 1 / math.sqrt(u))
        if density_radius is not None:
            per_sample = (budget / n - BYTES_PER_SAMPLE) / BYTES_PER_NEIGHBOUR - 1
            radius = math.floor(100 * spacing * math.sqrt(max(per_sample, 0.0) / math.pi)) / 100
            if radius > 0:
                radius_fit = (
                    f", or a smaller quality.density_radius than {density_radius:g} m "
                    f"(--set quality.density_radius={radius:g})"
                )
    fits = math.ceil(100 * fit) / 100
    advice = (
        f"the storey's structural surface is {area:,.0f} m²: set a coarser coverage_spacing than {spacing:g} m "
        f"(--set coverage_spacing={max(fits, spacing * 2):g}){radius_fit}, or split the storey"
    )
    if n > MAX_STRUCTURE_SAMPLES:
        raise StoreySizeError(
            source,
            f"the evaluation would sample it at {n:,.0f} points (the most nbs-env makes is {MAX_STRUCTURE_SAMPLES:,}): "
            + advice,
        )
    what = f"sampling its structural surface ({n:,.0f} points)"
    if density_radius is not None:
        what = f"{what} and their scan-quality neighbourhoods within {density_radius:g} m"
    _check_memory(source, int(n * bytes_per_sample(spacing)), what, advice)


def _check_memory(source: str, need: int, what: str, advice: str) -> None:
    """Raise :class:`StoreySizeError` when ``what`` needs ``need`` bytes and the process may allocate fewer."""
    if need < 2**28:  # a quarter of a GiB: any machine that runs the simulator has it
        return
    left = memory_left()
    if left is not None and need > left[0]:
        raise StoreySizeError(
            source,
            f"{what} takes about {need / 2**30:.1f} GiB, and this process may allocate "
            f"{max(left[0], 0) / 2**30:.1f} GiB more ({left[1]}): {advice}",
        )


def check_file_size(source: str, size: int, limit: int = MAX_MESH_FILE_BYTES) -> None:
    """Raise :class:`StoreySizeError` for a file of ``size`` bytes beyond ``limit``, or one whose reading
    (:data:`READ_FACTOR` times its size) needs more memory than the process may still allocate."""
    if size > limit:
        raise StoreySizeError(
            source,
            f"the file holds {size:,} bytes; nbs-env reads building files of up to {limit:,} bytes (the largest "
            f"storey it loads, {MAX_FACES:,} faces, takes about a third of that): is it the file you meant?",
        )
    _check_memory(
        source, size * READ_FACTOR, f"reading the file's {size:,} bytes", "free memory, or simplify the model"
    )


#: Where the machine's memory cannot be read (not Linux nor another POSIX system): a workstation's.
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
    # Too small only for files: a unit slip. Scenes built in code (tests, tools) may be any size.
    too_small = (units is not None or stated) and width < MIN_STOREY_WIDTH
    if width <= MAX_STOREY_WIDTH and height <= MAX_STOREY_HEIGHT and not too_small:
        return
    if too_small:
        sizes = (
            f"the storey is {_metres(width)} across and {_metres(height)} high (the least nbs-env loads is "
            f"{MIN_STOREY_WIDTH:g} m across)"
        )
    else:
        sizes = (
            f"the storey is {_metres(width)} across and {_metres(height)} high (the most nbs-env loads is "
            f"{MAX_STOREY_WIDTH:g} m across and {MAX_STOREY_HEIGHT:g} m high)"
        )
    guess = _likely_unit(width, height, units or "m")
    if stated:
        doubt = "is the file's unit right? " if too_small else ""
        cause = f"{doubt}the coordinates were read in the length unit the file states: check its IfcUnitAssignment"
    elif units is not None and guess is not None:
        cause = f"is the file in {_UNIT_WORDS[guess]}? pass --units {guess} (load_scene's units={guess!r})"
    elif guess is not None:
        cause = f"are its lengths in {_UNIT_WORDS[guess]}? they must be metres"
    elif too_small:
        cause = f"is the file's unit right? its coordinates were read as {_UNIT_WORDS[units or 'm']}"
    else:
        cause = "is there geometry far from the building, or are the coordinates broken?"
    raise StoreySizeError(source, f"{sizes}: {cause}")


def is_finite(value: float) -> bool:
    """``math.isfinite``, and False for an integer no float holds (``math.isfinite(10**400)`` raises
    OverflowError; JSON and Python integers have no bound)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def check_origin_distance(source: str, vertices: np.ndarray) -> None:
    """Refuse a storey farther than :data:`MAX_ORIGIN_DISTANCE` from the origin (a georeferenced file).

    The distance is that of the bounding box's farthest corner: every surface point must lie within
    the limit for the ray caster's float32 to keep millimetres.

    Raises
    ------
    StoreySizeError
        Naming the distance, the limit, why, and the fix (move the model near the origin).
    """
    v = np.asarray(vertices, dtype=float).reshape(-1, 3)
    if len(v) == 0:
        return
    with np.errstate(over="ignore", invalid="ignore"):
        corner = np.maximum(np.abs(v.min(axis=0)), np.abs(v.max(axis=0)))
        distance = float(np.linalg.norm(corner))
    if distance <= MAX_ORIGIN_DISTANCE:
        return
    raise StoreySizeError(
        source,
        f"the storey lies up to {_metres(distance)} from the origin (nbs-env loads storeys within "
        f"{MAX_ORIGIN_DISTANCE:,.0f} m of it: beyond that float32 ray casting loses millimetres); "
        "move the model near the origin (subtract its site or survey offset) and load it again",
    )


def check_storey_shape(
    source: str, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, *, low_hint: str = _LOW_HINT
) -> None:
    """Refuse what is no single storey: lower than :data:`MIN_STOREY_HEIGHT`, walls of no area, or
    floors on two levels more than :data:`STOREY_GAP` apart (module docstring).

    Parameters
    ----------
    vertices : (V, 3) float
        Metres, z up.
    faces : (F, 3) int
    labels : (F,) int
        One :class:`~scenes.labels.SurfaceClass` per face.
    low_hint : str
        The likely cause of a storey that is too low, for the message.

    Raises
    ------
    StoreySizeError
        The storey is too low, or holds several storeys (the message lists the floor levels).
    MissingStructureError
        The wall faces have no area.
    """
    v = np.asarray(vertices, dtype=float).reshape(-1, 3)
    tri = v[np.asarray(faces, dtype=np.int64).reshape(-1, 3)]
    labels = np.asarray(labels).reshape(-1)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    area = 0.5 * norm
    z = tri[..., 2].mean(axis=1)
    floor = labels == SurfaceClass.FLOOR
    if not floor.any():
        return  # the loaders refuse it with their own message
    # The floor's levels: its level faces (either way up: files do not agree on normals), by height.
    level = floor & (np.abs(cross[:, 2]) > 0.5 * norm) & (area > 0)
    if not level.any():
        level = floor
    order = np.flatnonzero(level)[np.argsort(z[level], kind="stable")]
    breaks = np.flatnonzero(np.diff(z[order]) > STOREY_GAP) + 1
    groups = np.split(order, breaks)
    total = float(area[order].sum())
    main = max(groups, key=lambda g: float(area[g].sum()))
    floor_z = _weighted_median(z[main], area[main])
    top_faces = np.isin(labels, [SurfaceClass.WALL, SurfaceClass.CEILING])
    top = float(tri[top_faces][..., 2].max()) if top_faces.any() else floor_z
    if top - floor_z < MIN_STOREY_HEIGHT:
        raise StoreySizeError(
            source,
            f"the storey is {_metres(max(top - floor_z, 0.0))} high from its floor (at {floor_z:.2f} m) to the top "
            f"of its walls and ceilings (at least {MIN_STOREY_HEIGHT:g} m): {low_hint}",
        )
    walls = labels == SurfaceClass.WALL
    if walls.any() and float(area[walls].sum()) <= 1e-6:
        raise MissingStructureError(
            source,
            f"the {int(walls.sum()):,} wall faces have no area (every one is a line or a point): nothing to scan",
        )
    if total > 0 and len(groups) > 1:
        shares = [(float(area[g].sum()) / total, _weighted_median(z[g], area[g])) for g in groups]
        storeys = [(share, at) for share, at in shares if share >= STOREY_SHARE]
        if len(storeys) > 1:
            found = "; ".join(f"{at:.2f} m: {share:.0%}" for share, at in storeys)
            raise StoreySizeError(
                source,
                f"the floor faces lie on {len(storeys)} levels more than {STOREY_GAP:g} m apart (elevation: share "
                f"of the floor area; {found}): the file holds several storeys; load one storey per file (the "
                f"floors of a split level or a stair rise less than {STOREY_GAP:g} m from one face to the next)",
            )


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    if cumulative[-1] <= 0:
        return float(np.median(values))
    return float(values[order[np.searchsorted(cumulative, 0.5 * cumulative[-1])]])


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
        if w > MAX_STOREY_WIDTH or h > MAX_STOREY_HEIGHT or h < 1.0 or w < MIN_STOREY_WIDTH:
            continue
        score = abs(math.log(h / _TYPICAL_HEIGHT))
        if score < best_score:
            best, best_score = name, score
    return None if best == read_as else best


def _metres(value: float) -> str:
    if not math.isfinite(value):
        return "an unbounded number of metres"
    return f"{value:,.0f} m" if 100 <= value < 1e15 else f"{value:.3g} m"
