"""The report of a scanning episode: metrics JSON, point clouds, the structural model, a picture.

:func:`write_report` writes, from an :class:`~nbs_env.env.NBSEnv` after an episode:

================  ====================================================================================
``metrics.json``  :func:`nbs_env.report.metrics_dict` (its schema is documented there)
``scans.e57``     the scan project (ASTM E2807), one structured data3D record per station
                  (:func:`write_e57`): its measured points in the scanner frame with their pattern
                  ``rowIndex``/``columnIndex`` and a simulated ``intensity``, the robot's estimated
                  pose, the scanner's vendor, model and a simulated serial number, the acquisition's
                  start and end; written when the env kept its scans (``EnvConfig.keep_scans``, as
                  ``nbs scan`` does)
``cloud.laz``     LAS 1.4, point format 6 (:func:`write_las`): the room models' 5 cm working copies
                  (or, with ``full_cloud``, every measured point), classified wall, floor, ceiling,
                  clutter as the robot's perception labelled them, with per point its scan
                  (``point_source_id``), GPS time, intensity, normal, Structure label and room
``structure.ply`` the working copies' points labelled Structure, of every room model
``cloud.ply``     every working-copy point of the room models, with a ``label`` (1 Structure, 0 Clutter)
``model.obj``     the recovered structural model (:func:`structural_model`): SE walls, floors, ceilings
``samples.npz``   the evaluation's structural samples with their scan-quality figures
                  (:func:`write_samples`)
``topdown.png``   the env's top-down picture of the end of the episode
================  ====================================================================================

Each file is written whole or not at all (:mod:`nbs_env.atomic`): under a temporary name in the
folder, flushed to the disk and renamed, so that a full disk or a signal leaves the previous file.

Every point is placed with the robot's own pose estimates. The working copies are the rooms' voxel
means (:attr:`nbs_env.belief.RoomModel.points`), about half the measured points of ``five_rooms`` at
the fast preset's 1° pattern; the E57 and ``write_report(full_cloud=True)`` hold every one.

What the files say about each point
-----------------------------------
The simulator casts one ray per direction of a regular azimuth × elevation pattern
(:func:`nbs_env.sensing.scanner.ray_pattern`) and keeps its one return; it has no materials and no
clock of its own. The scan files fill the fields scanning software expects with these models:

- **Returns.** Every point is return 1 of 1 (LAS ``return_number``, ``number_of_returns``).
- **Scan.** A point's scan is the index of its station: the E57 record, ``metrics.json``'s step, the
  LAS ``point_source_id``. A working-copy point is the mean of the points of every scan that hit its
  5 cm voxel; it carries the scan that first measured the voxel (:attr:`RoomModel.scans`).
- **Time** (:func:`pattern_times`). A station starts on the simulated clock of
  ``metrics.json`` (the drives at ``travel_speed``, the processing and acquisition of the scans
  before it) and ends its acquisition time later. Within it the scanner
  sweeps its pattern column by column (azimuth from -180°), each column from the lowest elevation
  up, one direction every ``1 / points_per_second`` seconds whether it returns or not. A pattern the
  rate cannot sweep within the station's acquisition time (the generic scanner's, whose time counts
  the returns only) is spread evenly over that time, so that every point's time lies within its
  station's start and end. A working-copy point takes the time of the pattern direction nearest its
  direction from its scan's position. Times are GPS seconds (from 1980-01-06, 18 s ahead of UTC);
  the LAS file stores Adjusted Standard GPS time (GPS seconds - 10⁹), as its global encoding says.
- **Intensity** (:func:`simulated_intensity`): a Lambertian return, ``65535 · cos θ · (1 m / r)²``
  clipped to 1..65535 (uint16), with ``r`` the range (at least 1 m) and ``θ`` the incidence angle
  between the ray and the surface normal (head-on where the normal is unknown). Every surface has
  the same reflectance (the scenes carry no materials): the intensity shows range and incidence,
  never material. The E57 records and the LAZ points carry the same values.
- **Normals.** The pipeline keeps none for the 5 cm working copies (perception reads no normals;
  S(t)'s are ICP's, at 10 cm, and absent with perfect localisation), so the report estimates them
  on each room's copy with registration's own estimator (the plane through the 20 nearest points
  within 15 cm, 60 cm where sparser: ``nbs_env.sensing.registration``), turned towards the position
  of the point's scan; zero where fewer than three points are near.
- **Classes.** A working-copy point is classified by :func:`classify_points`. A measured point
  takes the class, Structure label and normal (turned towards its own scanner) of the nearest
  working-copy point of the room model its scan went into: it lies in one of that copy's voxels,
  within √3 · 5 cm of the voxel's mean. A point farther than that (none, by construction) would be
  left unclassified (LAS class 1, :data:`LAS_UNCLASSIFIED`). The robot's labels are hard: the SE
  classifier is an uncalibrated SVM, so the files carry the Structure label (1 or 0), not a
  probability.
- **Coordinates.** Metres in the robot's map frame (x, y horizontal, z up), not geo-referenced:
  a local engineering coordinate system, :data:`LOCAL_CRS_WKT`, in the LAS WKT record and as the
  E57 ``coordinateMetadata``.

E57 is what scan-to-BIM tools open as a registered scan project (CloudCompare, Autodesk ReCap, Leica
Cyclone, Trimble RealWorks). It is written with libE57Format's node API (``pye57.libe57``): pye57's
own ``write_scan_raw`` sets placeholders this project cannot leave out (zero temperature, humidity
and pressure, a "pye57" description) and no sensor fields. LAS 1.4 with LAZ compression is written
with laspy (and its lazrs backend). ``tests/test_export_formats.py`` reads both back with readers
other than the writers: the Rust ``e57`` crate, LASzip.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from shapely.geometry import MultiPolygon, Polygon

from nbs_env.atomic import replacing, write_bytes, write_text
from nbs_env.belief import RoomModel
from nbs_env.report import metrics_dict, quaternion_wxyz

if TYPE_CHECKING:
    from nbs_env.config import ScannerConfig
    from nbs_env.env import NBSEnv
    from nbs_env.storey import ScanPoints

__all__ = [
    "FACE_KINDS",
    "INTENSITY_REFERENCE_RANGE",
    "LAS_CLASSES",
    "LAS_UNCLASSIFIED",
    "LOCAL_CRS_WKT",
    "REPORT_FILES",
    "classify_points",
    "pattern_times",
    "simulated_intensity",
    "structural_model",
    "write_e57",
    "write_las",
    "write_model_obj",
    "write_points_ply",
    "write_report",
    "write_samples",
]

#: Face kinds of :func:`structural_model`, indexed by its ``face_attributes["kind"]``.
FACE_KINDS = ("wall", "floor", "ceiling")

#: The files :func:`write_report` writes, in its output folder (``scans.e57`` only when the env kept
#: its scans).
REPORT_FILES = (
    "metrics.json",
    "scans.e57",
    "cloud.laz",
    "structure.ply",
    "cloud.ply",
    "model.obj",
    "samples.npz",
    "topdown.png",
)

#: The classification codes of :func:`write_las`, in LAS 1.4's user-definable range (64-255), with
#: the names its Classification Lookup record carries.
LAS_CLASSES = {64: "wall", 65: "floor", 66: "ceiling", 67: "clutter"}

#: LAS's "unclassified" code: a measured point of the full cloud with no working-copy point near it.
LAS_UNCLASSIFIED = 1

#: The report's coordinate system: the robot's map frame, a local engineering CRS in metres (OGC
#: 01-009 WKT, as LAS 1.4 asks; PROJ reads it as a 3D Cartesian engineering CRS). The axis
#: directions are WKT's names for x, y and z; the frame is not geo-referenced.
LOCAL_CRS_WKT = (
    'LOCAL_CS["nbs-env map frame",LOCAL_DATUM["nbs-env robot map",32767],'
    'UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["X",EAST],AXIS["Y",NORTH],AXIS["Z",UP]]'
)

#: The range (m) at which :func:`simulated_intensity` gives a surface seen head-on the full scale.
INTENSITY_REFERENCE_RANGE = 1.0

# GPS time (E57's dateTimeValue) counts from 1980-01-06 and runs 18 leap seconds ahead of UTC; LAS
# 1.4 stores Adjusted Standard GPS time, GPS seconds less 10⁹.
_GPS_EPOCH_UNIX = 315_964_800.0
_GPS_LEAP_SECONDS = 18.0
_GPS_ADJUSTED_OFFSET = 1e9

# The normals' estimator: S(t)'s (AccumulatedCloud's defaults), registration's plane fit.
_NORMAL_RADIUS = 0.15
_NORMAL_REACH = 0.6
# The LAS normals' components are multiples of 1 / _NORMAL_STEPS (write_las).
_NORMAL_STEPS = 4096.0


# ---------------------------------------------------------------------- point clouds
def _checked_points(points: np.ndarray) -> np.ndarray:
    """``points`` as an (n, 3) float64 array, or ValueError when it is not one or not finite."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be an (n, 3) array, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    return pts


def write_points_ply(path: str | Path, points: np.ndarray, labels: np.ndarray | None = None) -> Path:
    """Write points as a binary little-endian PLY file.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder must exist.
    points : (n, 3) float
        Coordinates, stored as float32 properties ``x``, ``y``, ``z``. ``n`` may be 0.
    labels : (n,) integer in 0..255, optional
        Stored as a ``uchar`` property ``label``.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``points`` is not (n, 3) or not finite, or ``labels`` does not match it or is out of 0..255.
    """
    path = Path(path)
    pts = _checked_points(points)
    fields: list[tuple[str, str]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    lab = None
    if labels is not None:
        lab = np.asarray(labels)
        if lab.shape != (len(pts),):
            raise ValueError(f"labels must have shape ({len(pts)},), got {lab.shape}")
        if lab.dtype == bool:
            lab = lab.astype(np.uint8)
        if len(lab) and not (np.issubdtype(lab.dtype, np.integer) or np.all(np.mod(lab, 1) == 0)):
            raise ValueError("labels must be integers")
        if len(lab) and (lab.min() < 0 or lab.max() > 255):
            raise ValueError(f"labels must be in 0..255, got {lab.min()}..{lab.max()}")
        fields.append(("label", "u1"))
    record = np.empty(len(pts), dtype=np.dtype(fields))
    record["x"], record["y"], record["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if lab is not None:
        record["label"] = lab.astype(np.uint8)
    header = [
        "ply",
        "format binary_little_endian 1.0",
        "comment written by nbs_env.export",
        f"element vertex {len(pts)}",
        "property float x",
        "property float y",
        "property float z",
    ]
    if lab is not None:
        header.append("property uchar label")
    header.append("end_header")
    write_bytes(path, ("\n".join(header) + "\n").encode("ascii") + record.tobytes())
    return path


# ---------------------------------------------------------------------- the structural model
def _polygon_triangles(polygon: np.ndarray, z: float, up: bool) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a room outline at height ``z``; faces oriented with normals up (+z) or down."""
    poly = Polygon(np.asarray(polygon, dtype=float))
    if not poly.is_valid:
        poly = poly.buffer(0)
    parts = list(poly.geoms) if isinstance(poly, MultiPolygon) else [poly]
    vertices, faces, offset = [], [], 0
    for part in parts:
        if not isinstance(part, Polygon) or part.is_empty or part.area <= 0:
            continue
        v2, f = trimesh.creation.triangulate_polygon(part, engine="earcut")
        v2, f = np.asarray(v2, dtype=float), np.asarray(f, dtype=np.int64)
        if not len(f):
            continue
        # Orientation: the z of each triangle's cross product, made to match ``up``.
        a, b, c = v2[f[:, 0]], v2[f[:, 1]], v2[f[:, 2]]
        cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        flip = (cross < 0) if up else (cross > 0)
        f[flip] = f[flip][:, ::-1]
        vertices.append(np.column_stack([v2, np.full(len(v2), float(z))]))
        faces.append(f + offset)
        offset += len(v2)
    if not faces:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(vertices), np.concatenate(faces)


def _room_parts(room: RoomModel) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(kind, vertices (v, 3), faces (f, 3)) of one room: its SE walls, floor and ceiling."""
    parts = []
    if room.se_faces:
        corners = np.stack([np.asarray(face.corners(), dtype=float) for face in room.se_faces])  # (k, 4, 3)
        # Two triangles per quad, turned so that their normal points into the room (face.normal).
        quads = np.tile(np.array([[0, 1, 2], [0, 2, 3]]), (len(corners), 1, 1))
        a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
        normal = np.cross(b - a, c - a)[:, :2]
        inward = np.array([np.asarray(face.normal, dtype=float) for face in room.se_faces])
        flip = np.einsum("ij,ij->i", normal, inward) < 0
        quads[flip] = quads[flip][:, :, ::-1]
        faces = (4 * np.arange(len(corners))[:, None, None] + quads).reshape(-1, 3)
        parts.append(("wall", corners.reshape(-1, 3), faces))
    horizontal = [("floor", room.floor_z, True)] + [("ceiling", room.ceiling_z, False)] * room.has_ceiling
    for kind, z, up in horizontal:
        v, f = _polygon_triangles(room.polygon, z, up)
        if len(f):
            parts.append((kind, v, f))
    return parts


def structural_model(rooms: list[RoomModel]) -> trimesh.Trimesh:
    """The recovered structural model of the rooms as one triangle mesh.

    Every SE wall face of a room (:attr:`RoomModel.se_faces`) is a quad of two triangles; the floor
    and the ceiling (of a room that has one) are the room's polygon at ``floor_z`` and ``ceiling_z``, triangulated. All
    normals point into the room (walls inwards, floor up, ceiling down).

    Parameters
    ----------
    rooms : list of RoomModel

    Returns
    -------
    trimesh.Trimesh
        Not processed (no vertex merging). ``face_attributes["room"]`` (F,) int32 is the
        :attr:`RoomModel.index` of each face and ``face_attributes["kind"]`` (F,) uint8 its kind,
        an index into :data:`FACE_KINDS` (0 wall, 1 floor, 2 ceiling). Empty when ``rooms`` is.
    """
    vertices, faces, room_of, kind_of = [], [], [], []
    offset = 0
    for room in rooms:
        for kind, v, f in _room_parts(room):
            vertices.append(v)
            faces.append(f + offset)
            room_of.append(np.full(len(f), room.index, dtype=np.int32))
            kind_of.append(np.full(len(f), FACE_KINDS.index(kind), dtype=np.uint8))
            offset += len(v)
    if not faces:
        return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)
    return trimesh.Trimesh(
        np.concatenate(vertices),
        np.concatenate(faces),
        face_attributes={"room": np.concatenate(room_of), "kind": np.concatenate(kind_of)},
        process=False,
    )


def write_model_obj(path: str | Path, rooms: list[RoomModel]) -> Path:
    """Write :func:`structural_model` as a Wavefront OBJ, one object per room and kind.

    The objects are named ``room<index>_<kind>`` (e.g. ``room0_wall``, ``room0_floor``,
    ``room0_ceiling``). With no faces at all the file holds only a comment.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder must exist.
    rooms : list of RoomModel

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    TypeError
        ``rooms`` is no list of RoomModel (``env.storey.room_models()``).
    """
    if not isinstance(rooms, (list, tuple)) or not all(isinstance(room, RoomModel) for room in rooms):
        shown = type(rooms).__name__ if not isinstance(rooms, (list, tuple)) else "a list holding other things"
        raise TypeError(f"rooms must be a list of RoomModel (env.storey.room_models()), got {shown}")
    path = Path(path)
    scene = trimesh.Scene()
    for room in rooms:
        for kind, v, f in _room_parts(room):
            name = f"room{room.index}_{kind}"
            scene.add_geometry(trimesh.Trimesh(v, f, process=False), geom_name=name, node_name=name)
    if scene.geometry:
        text = scene.export(file_type="obj", header="nbs_env structural model")
    else:
        text = "# nbs_env structural model: no faces\n"
    write_text(path, text if isinstance(text, str) else text.decode())
    return path


# ---------------------------------------------------------------------- simulated returns
def simulated_intensity(ranges: np.ndarray, cos_incidence: np.ndarray) -> np.ndarray:
    """The simulated intensity of returns: a Lambertian surface, the same reflectance everywhere.

    Parameters
    ----------
    ranges : (n,) float
        Metres from the scanner.
    cos_incidence : (n,) float
        Cosine of the incidence angle (between the ray and the surface normal), clipped to [0, 1].

    Returns
    -------
    (n,) uint16
        ``65535 · cos θ · (r0 / max(r, r0))²``, ``r0`` = :data:`INTENSITY_REFERENCE_RANGE` (1 m),
        rounded and clipped to 1..65535: a return is never of zero intensity. The reflectance is a
        constant of the model (the scenes carry no materials), so the value shows range and
        incidence only.
    """
    r0 = INTENSITY_REFERENCE_RANGE
    r = np.maximum(np.asarray(ranges, dtype=np.float64), r0)
    value = 65535.0 * np.clip(np.asarray(cos_incidence, dtype=np.float64), 0.0, 1.0) * (r0 / r) ** 2
    return np.clip(np.rint(value), 1, 65535).astype(np.uint16)


def pattern_times(
    rows: np.ndarray, cols: np.ndarray, scanner: ScannerConfig, acquisition_time: float | np.ndarray
) -> np.ndarray:
    """Seconds from a station's start at which the scanner measured directions of its pattern.

    The scanner sweeps the pattern column by column (azimuth from -180°), each column from the lowest
    elevation up, one direction every ``1 / points_per_second`` seconds whether it returns or not;
    a pattern that rate cannot sweep within the station's acquisition time is spread evenly over it.

    Parameters
    ----------
    rows, cols : (n,) int
        Pattern row (elevation index from ``elevation_min`` up) and column (azimuth index from -180°),
        as :func:`nbs_env.sensing.scanner.ray_pattern` numbers them.
    scanner : ScannerConfig
        The scanner that cast the pattern.
    acquisition_time : float or (n,) float
        The station's acquisition time in seconds (:attr:`nbs_env.sensing.scanner.Scan.acquisition_time`),
        per direction where they come from several stations.

    Returns
    -------
    (n,) float64
        ``(col · n_rows + row) · step`` with ``step`` the shorter of ``1 / points_per_second`` and
        ``acquisition_time / n_rays``: within [0, acquisition_time).
    """
    step = np.minimum(1.0 / scanner.points_per_second, np.asarray(acquisition_time, dtype=np.float64) / scanner.n_rays)
    order = np.asarray(cols, dtype=np.int64) * scanner.n_rows + np.asarray(rows, dtype=np.int64)
    return order * step


def _pattern_cells(local: np.ndarray, scanner: ScannerConfig) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols), (n,) int64 each: the pattern direction nearest each (n, 3) scanner-frame point."""
    azimuth = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
    elevation = np.degrees(np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1])))
    cols = np.rint((azimuth + 180.0) / (360.0 / scanner.n_cols)).astype(np.int64) % scanner.n_cols
    rows = np.rint((elevation - scanner.elevation_min) / scanner.angular_step).astype(np.int64)
    return np.clip(rows, 0, scanner.n_rows - 1), cols


def _working_normals(points: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """(n, 3) float unit normals of a room's (n, 3) working copy, turned towards ``origins`` (n, 3),
    each point's scanner position; zero where fewer than three points lie near (module docstring)."""
    from nbs_env import threads
    from nbs_env.sensing.registration import _MIN_NORMAL_NEIGHBOURS, _NORMAL_NEIGHBOURS, _plane_normals, _small_gicp

    points = np.ascontiguousarray(points, dtype=np.float64)
    if len(points) < 3:
        return np.zeros_like(points)
    workers = threads.cores()
    tree = _small_gicp().KdTree(points, num_threads=workers)
    idx, sq = tree.batch_knn_search(points, min(_NORMAL_NEIGHBOURS, len(points)), num_threads=workers)
    normals = _plane_normals(
        points,
        np.ascontiguousarray(np.asarray(idx), dtype=np.int64),
        np.ascontiguousarray(sq, dtype=np.float64),
        _NORMAL_RADIUS**2,
        _NORMAL_REACH**2,
        _MIN_NORMAL_NEIGHBOURS,
    )
    away = np.einsum("ij,ij->i", normals, origins - points) < 0
    normals[away] *= -1.0
    return normals


def _cos_incidence(normals: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(n,) float |cos| of the angle between (n, 3) normals and rays; 1 (head-on) where either is zero."""
    length = np.linalg.norm(normals, axis=1) * np.linalg.norm(rays, axis=1)
    dot = np.abs(np.einsum("ij,ij->i", normals, rays))
    return np.divide(dot, length, out=np.ones(len(rays)), where=length > 0)


@dataclass(frozen=True)
class _Points:
    """Points of the report's clouds with their fields (module docstring)."""

    #: (n, 3) float64, the robot's map frame.
    points: np.ndarray
    #: (n,) uint8, :data:`LAS_CLASSES` or :data:`LAS_UNCLASSIFIED`.
    classes: np.ndarray
    #: (n,) bool, the robot's Structure label.
    structure: np.ndarray
    #: (n,) int64, the robot's room number.
    rooms: np.ndarray
    #: (n,) int64, the index of the point's scan.
    scans: np.ndarray
    #: (n, 3) float64 unit normals facing the point's scanner, zero where unknown.
    normals: np.ndarray
    #: (n,) uint16, :func:`simulated_intensity`.
    intensity: np.ndarray
    #: (n,) float64, Adjusted Standard GPS seconds.
    gps_time: np.ndarray


class _Stations:
    """The episode's scans as the report's clock and placement need them, (k, ...) arrays: the
    estimated ``poses`` (4, 4), ``rooms`` (the robot's number), ``acquisition`` seconds (the scan's,
    without the station's set-up) and the acquisition ``start`` and ``end``, GPS seconds."""

    def __init__(self, env: NBSEnv, run_started: float) -> None:
        records = env.storey.scans
        setup = env.storey.config.robot.scanner.setup_time
        self.poses = np.stack([np.asarray(r.estimated_pose, dtype=float) for r in records])
        self.rooms = np.array([int(r.room) for r in records], dtype=np.int64)
        self.acquisition = np.array([float(r.acquisition_time) - setup for r in records])
        self.times = _station_times(env, run_started)
        self.start = np.array([t[0] for t in self.times])
        self.end = np.array([t[1] for t in self.times])

    @property
    def origins(self) -> np.ndarray:
        """(k, 3) float: the estimated scanner positions."""
        return self.poses[:, :3, 3]


def _working_points(models: list[RoomModel], stations: _Stations, scanner: ScannerConfig) -> _Points:
    """The room models' working copies with every field of the report's clouds."""
    models = [m for m in models if len(np.asarray(m.points).reshape(-1, 3))]
    if any(m.scans is None for m in models):
        raise ValueError("the room models carry no scan index (RoomModel.scans): not a robot's")
    points = np.concatenate(
        [np.asarray(m.points, dtype=np.float64).reshape(-1, 3) for m in models] or [np.zeros((0, 3))]
    )
    scans = np.concatenate([np.asarray(m.scans, dtype=np.int64) for m in models] or [np.zeros(0, dtype=np.int64)])
    if len(scans) != len(points) or (len(scans) and not 0 <= scans.min() <= scans.max() < len(stations.start)):
        raise ValueError(f"the room models' scan indices do not match the episode's {len(stations.start)} scans")
    origins = stations.origins[scans]
    normals = np.concatenate(
        [
            _working_normals(np.asarray(m.points, dtype=np.float64).reshape(-1, 3), stations.origins[m.scans])
            for m in models
        ]
        or [np.zeros((0, 3))]
    )
    rays = points - origins
    # The scanner-frame direction of each point from its scan, R^T (p - t): its pattern cell.
    local = np.einsum("nji,nj->ni", stations.poses[scans, :3, :3], rays)
    rows, cols = _pattern_cells(local, scanner)
    gps_time = (stations.start[scans] - _GPS_ADJUSTED_OFFSET) + pattern_times(
        rows, cols, scanner, stations.acquisition[scans]
    )
    fields = {
        "points": points,
        "classes": np.concatenate([classify_points(m) for m in models] or [np.zeros(0, dtype=np.uint8)]),
        "structure": np.concatenate(
            [np.asarray(m.structure, dtype=bool).reshape(-1) for m in models] or [np.zeros(0, bool)]
        ),
        "rooms": np.concatenate(
            [np.full(len(m.points), m.index, dtype=np.int64) for m in models] or [np.zeros(0, np.int64)]
        ),
        "scans": scans,
        "normals": normals,
        "intensity": simulated_intensity(np.linalg.norm(rays, axis=1), _cos_incidence(normals, rays)),
        "gps_time": gps_time,
    }
    # In acquisition order, as a scanner records its points: neighbours along a column follow each
    # other, and LAZ compresses the copy to 0.82 of its size in voxel order (five_rooms, fast preset).
    order = np.argsort(gps_time, kind="stable")
    return _Points(**{key: value[order] for key, value in fields.items()})


def _measured_points(
    log: list[ScanPoints], stations: _Stations, working: _Points, scanner: ScannerConfig, voxel: float = 0.05
) -> _Points:
    """Every measured point of the kept scans, placed with its scan's estimated pose, with the class,
    Structure label and normal of the nearest working-copy point of its scan's room (within the
    ``voxel``'s diagonal, else unclassified with no normal), its intensity and time."""
    from scipy.spatial import cKDTree

    from nbs_env import threads

    if len(log) != len(stations.start):
        raise ValueError(f"{len(log)} kept scans for {len(stations.start)} scans: the log is not the episode's")
    reach = float(np.sqrt(3.0) * voxel) * (1.0 + 1e-6)
    trees: dict[int, tuple[Any, np.ndarray]] = {}
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("points", "classes", "structure", "normals", "rays")}
    for k, scan in enumerate(log):
        local = np.asarray(scan.points, dtype=np.float64).reshape(-1, 3)
        pose = stations.poses[k]
        rays = local @ pose[:3, :3].T
        world = rays + pose[:3, 3]
        room = int(stations.rooms[k])
        if room not in trees:
            members = np.flatnonzero(working.rooms == room)
            trees[room] = (cKDTree(working.points[members]) if len(members) else None, members)
        tree, members = trees[room]
        classes = np.full(len(world), LAS_UNCLASSIFIED, dtype=np.uint8)
        structure = np.zeros(len(world), dtype=bool)
        normals = np.zeros((len(world), 3))
        if tree is not None and len(world):
            distance, i = tree.query(world, distance_upper_bound=reach, workers=threads.cores())
            near = np.isfinite(distance)
            j = members[i[near]]
            classes[near], structure[near], normals[near] = working.classes[j], working.structure[j], working.normals[j]
        # The copy's normal faces its voxel's first scanner; this point's faces its own.
        away = np.einsum("ij,ij->i", normals, rays) > 0
        normals[away] *= -1.0
        parts["points"].append(world)
        parts["classes"].append(classes)
        parts["structure"].append(structure)
        parts["normals"].append(normals)
        parts["rays"].append(rays)
    counts = np.array([len(p) for p in parts["points"]], dtype=np.int64)
    scans = np.repeat(np.arange(len(log), dtype=np.int64), counts)
    rays = np.concatenate(parts["rays"] or [np.zeros((0, 3))])
    normals = np.concatenate(parts["normals"] or [np.zeros((0, 3))])
    rows = np.concatenate([np.asarray(s.rows) for s in log] or [np.zeros(0, np.int64)])
    cols = np.concatenate([np.asarray(s.cols) for s in log] or [np.zeros(0, np.int64)])
    return _Points(
        points=np.concatenate(parts["points"] or [np.zeros((0, 3))]),
        classes=np.concatenate(parts["classes"] or [np.zeros(0, np.uint8)]),
        structure=np.concatenate(parts["structure"] or [np.zeros(0, bool)]),
        rooms=stations.rooms[scans],
        scans=scans,
        normals=normals,
        intensity=simulated_intensity(np.linalg.norm(rays, axis=1), _cos_incidence(normals, rays)),
        gps_time=(stations.start[scans] - _GPS_ADJUSTED_OFFSET)
        + pattern_times(rows, cols, scanner, stations.acquisition[scans]),
    )


# ---------------------------------------------------------------------- scan projects: E57, LAS
def _gps_now() -> float:
    """GPS seconds now."""
    return time.time() - _GPS_EPOCH_UNIX + _GPS_LEAP_SECONDS


def _sensor(scanner: ScannerConfig | None) -> dict[str, str]:
    """An E57 record's sensor fields, and a ``title`` for its description, from a scanner preset."""
    from nbs_env import __version__
    from nbs_env.config.scanners import SCANNERS

    preset = None if scanner is None else scanner.preset
    name, _, setting = (preset or "").partition(":")
    model = SCANNERS.get(name.strip().lower()) if preset else None
    if model is not None:
        title = f"{model.title}, setting {setting or model.default_setting}"
        vendor, model_name, serial = model.vendor or model.title.split()[0], model.title, f"SIM-{model.name}-0001"
    elif preset:  # a preset name set by hand, which no datasheet model has
        title = f"scanner {preset!r}"
        vendor, model_name, serial = "unknown", f"simulated scanner {preset!r}", f"SIM-{name.strip()}-0001"
    else:
        title = "the generic simulated scanner (METHOD §1)"
        vendor, model_name, serial = "nbs-env", "generic simulated scanner", "SIM-generic-0001"
    return {
        "sensorVendor": vendor,
        "sensorModel": model_name,
        "sensorSerialNumber": serial,
        "sensorSoftwareVersion": f"nbs-env {__version__}",
        "title": title,
    }


def write_e57(
    path: str | Path,
    scans: list[ScanPoints],
    names: list[str] | None = None,
    times: list[tuple[float, float]] | None = None,
    *,
    intensity: list[np.ndarray] | None = None,
    scanner: ScannerConfig | None = None,
    created: float | None = None,
) -> Path:
    """Write scans as an E57 scan project: one structured data3D record per station.

    Parameters
    ----------
    path : str or Path
        The file to write (overwritten); its folder must exist.
    scans : list of ScanPoints
        Each station's measured points in the scanner frame (float32), their pattern ``rows`` and
        ``cols``, and the estimated scanner ``pose`` (4, 4).
    names : list of str, optional
        Record names (default ``scan_000``, ``scan_001``, ...).
    times : list of (float, float), optional
        Each record's acquisition start and end, GPS seconds (E57's ``dateTimeValue``); default 0.
    intensity : list of (n_k,) uint16, optional
        Each station's point intensities (:func:`simulated_intensity`), written as the ``intensity``
        field (Integer, 0..65535) with the record's ``intensityLimits``.
    scanner : ScannerConfig, optional
        The scanner that took them: the records' ``sensorVendor``, ``sensorModel`` and (simulated,
        ``SIM-<name>-0001``) ``sensorSerialNumber`` from its preset (:mod:`nbs_env.config.scanners`;
        a generic scanner's without one), and the ``indexBounds`` of its whole pattern. Without it
        the bounds are the points' own.
    created : float, optional
        The file's ``creationDateTime``, GPS seconds (default: now).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``names``, ``times`` or ``intensity`` does not match ``scans``.

    Notes
    -----
    Each record stores ``cartesianX/Y/Z`` (single-precision floats) in the scanner frame,
    ``cartesianInvalidState`` (0: every point is a return; pye57's ``read_scan`` asks for it),
    ``rowIndex`` and ``columnIndex`` (the scan pattern's grid, so that tools rebuild the panorama),
    the pose as the record's ``pose`` (rotation quaternion w, x, y, z and translation, scanner frame
    to the robot's map frame), ``cartesianBounds`` in the scanner frame (as the standard defines
    them), a ``description`` naming nbs-env and its version, ``sensorSoftwareVersion`` (nbs-env) and
    no temperature, humidity or pressure (the simulator has none). One return per ray: no return
    index. The file's ``coordinateMetadata`` is :data:`LOCAL_CRS_WKT`. Written with libE57Format's
    node API through ``pye57.libe57``: pye57's ``write_scan_raw`` writes placeholder temperature,
    humidity and pressure (0) and its own description, and no sensor fields.
    """
    path = Path(path)
    names = names or [f"scan_{k:03d}" for k in range(len(scans))]
    for label, given in (("names", names), ("times", times), ("intensity", intensity)):
        if given is not None and len(given) != len(scans):
            raise ValueError(f"{len(scans)} scans need as many {label}, got {len(given)}")
    if intensity is not None:
        for k, (scan, values) in enumerate(zip(scans, intensity, strict=True)):
            if np.shape(values) != (len(scan.points),):
                raise ValueError(f"scan {k}: intensity must have shape ({len(scan.points)},), got {np.shape(values)}")
    sensor = _sensor(scanner)
    # Under a temporary name, renamed onto ``path`` once whole (nbs_env.atomic): a failure or a
    # signal leaves the previous file (and libE57 opens no existing file for writing).
    from pye57 import libe57

    with replacing(path, writer_errors=(libe57.E57Exception,)) as temporary:
        _write_e57_file(temporary, scans, names, times, intensity, scanner, sensor, created)
    return path


def _write_e57_file(
    path: Path,
    scans: list[ScanPoints],
    names: list[str],
    times: list[tuple[float, float]] | None,
    intensity: list[np.ndarray] | None,
    scanner: ScannerConfig | None,
    sensor: dict[str, str],
    created: float | None,
) -> None:
    """:func:`write_e57`'s records, checked, into the new file ``path``."""
    from pye57 import libe57

    from nbs_env import __version__

    imf = libe57.ImageFile(str(path), "w")
    writer = buffers = compressed = None
    try:

        def string(text: str) -> Any:
            return libe57.StringNode(imf, text)

        def number(value: float) -> Any:
            return libe57.FloatNode(imf, float(value))

        def integer(value: int) -> Any:
            return libe57.IntegerNode(imf, int(value))

        def structure(**children: Any) -> Any:
            node = libe57.StructureNode(imf)
            for key, child in children.items():
                node.set(key, child)
            return node

        imf.extensionsAdd("", libe57.E57_V1_0_URI)
        root = imf.root()
        root.set("formatName", string("ASTM E57 3D Imaging Data File"))
        root.set("guid", string(f"{{{uuid.uuid4()}}}"))
        root.set("versionMajor", integer(libe57.E57_FORMAT_MAJOR))
        root.set("versionMinor", integer(libe57.E57_FORMAT_MINOR))
        root.set("e57LibraryVersion", string(libe57.E57_LIBRARY_ID))
        root.set("coordinateMetadata", string(LOCAL_CRS_WKT))
        root.set(
            "creationDateTime",
            structure(
                dateTimeValue=number(_gps_now() if created is None else created), isAtomicClockReferenced=integer(0)
            ),
        )
        data3d = libe57.VectorNode(imf, True)
        root.set("data3D", data3d)
        root.set("images2D", libe57.VectorNode(imf, True))
        for k, scan in enumerate(scans):
            points = np.asarray(scan.points, dtype=np.float64).reshape(-1, 3)
            # pye57's buffers take 8, 16 and 64-bit integers, and read numpy's int64 (format "l" on
            # Linux) as 32-bit values; "q" (longlong) is read as 64-bit. uint16 holds any pattern
            # of up to 65,536 rows and columns.
            index = (
                np.uint16 if max(np.max(scan.rows, initial=0), np.max(scan.cols, initial=0)) <= 65535 else np.longlong
            )
            rows = np.asarray(scan.rows).astype(index)
            cols = np.asarray(scan.cols).astype(index)
            pose = np.asarray(scan.pose, dtype=float)
            n = len(points)
            low = points.min(axis=0) if n else np.zeros(3)
            high = points.max(axis=0) if n else np.zeros(3)
            if scanner is not None:
                row_bounds, col_bounds = (0, scanner.n_rows - 1), (0, scanner.n_cols - 1)
            else:
                row_bounds = (int(rows.min()), int(rows.max())) if n else (0, 0)
                col_bounds = (int(cols.min()), int(cols.max())) if n else (0, 0)
            start, end = times[k] if times is not None else (0.0, 0.0)
            rotation = quaternion_wxyz(pose)
            setting = f", cast at a {scanner.angular_step:g}° step" if scanner is not None else ""
            node = structure(
                guid=string(f"{{{uuid.uuid4()}}}"),
                name=string(names[k]),
                description=string(
                    f"nbs-env {__version__}: simulated station {k} of {len(scans)} by {sensor['title']}{setting}; "
                    "the serial number is simulated, not an instrument's"
                ),
                sensorVendor=string(sensor["sensorVendor"]),
                sensorModel=string(sensor["sensorModel"]),
                sensorSerialNumber=string(sensor["sensorSerialNumber"]),
                sensorSoftwareVersion=string(sensor["sensorSoftwareVersion"]),
                indexBounds=structure(
                    rowMinimum=integer(row_bounds[0]),
                    rowMaximum=integer(row_bounds[1]),
                    columnMinimum=integer(col_bounds[0]),
                    columnMaximum=integer(col_bounds[1]),
                    returnMinimum=integer(0),
                    returnMaximum=integer(0),
                ),
                cartesianBounds=structure(
                    xMinimum=number(low[0]),
                    xMaximum=number(high[0]),
                    yMinimum=number(low[1]),
                    yMaximum=number(high[1]),
                    zMinimum=number(low[2]),
                    zMaximum=number(high[2]),
                ),
                pose=structure(
                    rotation=structure(
                        w=number(rotation[0]), x=number(rotation[1]), y=number(rotation[2]), z=number(rotation[3])
                    ),
                    translation=structure(x=number(pose[0, 3]), y=number(pose[1, 3]), z=number(pose[2, 3])),
                ),
                acquisitionStart=structure(dateTimeValue=number(start), isAtomicClockReferenced=integer(0)),
                acquisitionEnd=structure(dateTimeValue=number(end), isAtomicClockReferenced=integer(0)),
            )
            fields: dict[str, np.ndarray] = {}
            prototype = libe57.StructureNode(imf)
            for axis, name in enumerate(("cartesianX", "cartesianY", "cartesianZ")):
                prototype.set(
                    name,
                    libe57.FloatNode(imf, float(low[axis]), libe57.E57_SINGLE, float(low[axis]), float(high[axis])),
                )
                fields[name] = np.ascontiguousarray(points[:, axis])
            prototype.set("cartesianInvalidState", libe57.IntegerNode(imf, 0, 0, 0))
            fields["cartesianInvalidState"] = np.zeros(n, dtype=np.int8)
            if intensity is not None:
                node.set("intensityLimits", structure(intensityMinimum=number(0), intensityMaximum=number(65535)))
                prototype.set("intensity", libe57.IntegerNode(imf, 0, 0, 65535))
                fields["intensity"] = np.ascontiguousarray(intensity[k], dtype=np.uint16)
            prototype.set("rowIndex", libe57.IntegerNode(imf, row_bounds[0], row_bounds[0], row_bounds[1]))
            prototype.set("columnIndex", libe57.IntegerNode(imf, col_bounds[0], col_bounds[0], col_bounds[1]))
            fields["rowIndex"], fields["columnIndex"] = np.ascontiguousarray(rows), np.ascontiguousarray(cols)
            compressed = libe57.CompressedVectorNode(imf, prototype, libe57.VectorNode(imf, True))
            node.set("points", compressed)
            data3d.append(node)  # a compressed vector is written once attached to the file's tree
            buffers = libe57.VectorSourceDestBuffer()
            for name, array in fields.items():
                buffers.append(libe57.SourceDestBuffer(imf, name, array, max(n, 1), True, False))
            writer = compressed.writer(buffers)
            if n:
                writer.write(n)
            writer.close()
    except BaseException:
        # A writer left open when the file is cancelled crashes the process (a segmentation fault)
        # when Python frees it: close it first (it raises the same error again) and drop it.
        if writer is not None:
            with contextlib.suppress(Exception):
                writer.close()
        writer = buffers = compressed = None
        imf.cancel()  # libE57 removes the partial file
        path.unlink(missing_ok=True)
        raise
    imf.close()


def classify_points(room: RoomModel, distance: float = 0.10) -> np.ndarray:
    """The :data:`LAS_CLASSES` code of each of a room model's points.

    A point labelled Structure is floor or ceiling when it lies within ``distance`` of the room's
    floor or ceiling height (the distance :func:`nbs_env.perception.structure.label_points` used
    to label it), else wall; every other point is clutter. Perception's labels, not the truth.

    Returns
    -------
    (m,) uint8
    """
    points = np.asarray(room.points, dtype=float).reshape(-1, 3)
    structure = np.asarray(room.structure, dtype=bool).reshape(-1)
    z = points[:, 2]
    codes = np.full(len(points), 67, dtype=np.uint8)
    codes[structure] = 64
    codes[structure & (np.abs(z - room.floor_z) <= distance)] = 65
    if room.has_ceiling:
        codes[structure & (np.abs(z - room.ceiling_z) <= distance)] = 66
    return codes


def _classification_lookup() -> Any:
    """LAS 1.4's Classification Lookup VLR (LASF_Spec, record 0) naming :data:`LAS_CLASSES`."""
    from laspy.vlrs.known import ClassificationLookupVlr

    lookup = ClassificationLookupVlr()
    for code, name in LAS_CLASSES.items():
        lookup[code] = name
    return lookup


def _matching(name: str, values: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """``values`` as an array of ``shape``, or ValueError naming ``name``; None stays None."""
    if values is None:
        return None
    array = np.asarray(values)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    return array


def _lazrs_errors() -> tuple[type[Exception], ...]:
    try:
        import lazrs
    except ImportError:
        return ()
    return (lazrs.LazrsError,)


def write_las(
    path: str | Path,
    points: np.ndarray,
    classes: np.ndarray,
    rooms: np.ndarray | None = None,
    *,
    scans: np.ndarray | None = None,
    gps_time: np.ndarray | None = None,
    intensity: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    structure: np.ndarray | None = None,
    system: str = "nbs-env simulation",
) -> Path:
    """Write classified points as LAS 1.4 (point format 6); a ``.laz`` path is LAZ-compressed.

    Every point is return 1 of 1 (the simulator keeps one return per ray). The header carries a WKT
    coordinate system record, :data:`LOCAL_CRS_WKT` (with the global encoding's WKT bit, as LAS 1.4
    asks of point format 6), and a Classification Lookup record naming :data:`LAS_CLASSES`.

    Parameters
    ----------
    path : str or Path
        The file to write; ``.laz`` compresses (laspy's lazrs backend), ``.las`` does not.
    points : (n, 3) float
        Coordinates, stored at millimetre scale.
    classes : (n,) uint8
        Classification codes (:data:`LAS_CLASSES`, or :data:`LAS_UNCLASSIFIED`).
    rooms : (n,) int, optional
        The robot's room number of each point, as the extra byte dimension ``room`` (uint16).
    scans : (n,) int in 0..65535, optional
        The index of each point's scan, as its ``point_source_id`` (0 for every point without).
    gps_time : (n,) float, optional
        Adjusted Standard GPS time (GPS seconds - 10⁹) of each point; the global encoding says so.
    intensity : (n,) uint16, optional
    normals : (n, 3) float, optional
        Unit normals, as the float32 extra byte dimensions ``NormalX``, ``NormalY``, ``NormalZ``
        (PDAL's names, which CloudCompare's LAS plugin loads as normals), each component rounded
        to a multiple of 1/4096: a direction within 0.02°, whose float32 bits LAZ compresses better
        (the whole file to 0.67 of its size with unrounded normals for five_rooms' working copies
        at the fast preset, 0.59 for its full cloud).
    structure : (n,) bool, optional
        The robot's Structure label, as the extra byte dimension ``structure`` (uint8, 1 or 0).
    system : str
        The header's system identifier (at most 32 characters).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``points`` is not (n, 3) or not finite, another array does not match it, or a scan index is
        outside 0..65535.
    """
    import laspy
    from laspy.vlrs.known import WktCoordinateSystemVlr

    from nbs_env import __version__

    path = Path(path)
    pts = _checked_points(points)
    n = len(pts)
    classes = _matching("classes", classes, (n,))
    rooms = _matching("rooms", rooms, (n,))
    scans = _matching("scans", scans, (n,))
    gps_time = _matching("gps_time", gps_time, (n,))
    intensity = _matching("intensity", intensity, (n,))
    normals = _matching("normals", normals, (n, 3))
    structure = _matching("structure", structure, (n,))
    if scans is not None and n and (scans.min() < 0 or scans.max() > 65535):
        raise ValueError(f"scan indices must be in 0..65535 (LAS point_source_id), got {scans.min()}..{scans.max()}")
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(pts.min(axis=0)) if n else np.zeros(3)
    header.generating_software = f"nbs-env {__version__}"[:32]
    header.system_identifier = system[:32]
    header.global_encoding.wkt = True
    if gps_time is not None:
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    extra = []
    if rooms is not None:
        extra.append(laspy.ExtraBytesParams(name="room", type=np.uint16, description="robot's room number"))
    if structure is not None:
        extra.append(laspy.ExtraBytesParams(name="structure", type=np.uint8, description="Structure 1, Clutter 0"))
    if normals is not None:
        extra += [
            laspy.ExtraBytesParams(name=f"Normal{axis}", type=np.float32, description=f"unit normal, {axis.lower()}")
            for axis in "XYZ"
        ]
    if extra:
        header.add_extra_dims(extra)
    header.vlrs.append(WktCoordinateSystemVlr(LOCAL_CRS_WKT))
    header.vlrs.append(_classification_lookup())
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.classification = classes.astype(np.uint8)
    las.return_number = np.ones(n, dtype=np.uint8)
    las.number_of_returns = np.ones(n, dtype=np.uint8)
    if scans is not None:
        las.point_source_id = scans.astype(np.uint16)
    if gps_time is not None:
        las.gps_time = gps_time.astype(np.float64)
    if intensity is not None:
        las.intensity = intensity.astype(np.uint16)
    if rooms is not None:
        las.room = rooms.astype(np.uint16)
    if structure is not None:
        las.structure = structure.astype(np.uint8)
    if normals is not None:
        rounded = np.rint(np.asarray(normals, dtype=np.float64) * _NORMAL_STEPS) / _NORMAL_STEPS
        las.NormalX, las.NormalY, las.NormalZ = (rounded[:, i].astype(np.float32) for i in range(3))
    with replacing(path, writer_errors=(laspy.errors.LaspyException, *_lazrs_errors())) as temporary:
        # The suffix (.laz or .las) tells laspy to compress or not.
        las.write(str(temporary))
    return path


def write_samples(path: str | Path, env: NBSEnv) -> Path:
    """Write the evaluation's structural samples and their scan-quality figures as NPZ.

    Arrays: ``points`` (n, 3) float32, ``labels`` (n,) uint8 (SurfaceClass), ``rooms`` (n,) int32
    (true room id), ``sensed`` (n,) bool, ``density`` (n,) float32 (points per m²),
    ``incidence`` (n,) float32 (best incidence angle, degrees; NaN when never seen) and ``range``
    (n,) float32 (shortest range, metres; NaN when never seen); see
    :meth:`nbs_env.evaluation.CoverageMeter.quality`. Ground truth: for evaluation only.
    """
    path = Path(path)
    if path.suffix != ".npz":  # as numpy names the file it writes
        path = path.with_name(path.name + ".npz")
    meter = env.storey.meter
    quality = meter.quality(env.storey.config.quality)
    buffer = io.BytesIO()  # written whole by write_bytes, as every file of the report
    np.savez_compressed(
        buffer,
        points=meter.samples.points.astype(np.float32),
        labels=meter.samples.labels.astype(np.uint8),
        rooms=meter.samples.rooms.astype(np.int32),
        sensed=meter.sensed.copy(),
        density=quality.density.astype(np.float32),
        incidence=quality.incidence.astype(np.float32),
        range=quality.range.astype(np.float32),
    )
    write_bytes(path, buffer.getbuffer())
    return path


def _station_times(env: NBSEnv, start: float) -> list[tuple[float, float]]:
    """Each scan's acquisition start and end on the simulated clock, GPS seconds from ``start``
    (Unix time): the processing and acquisition of the scans before it, the travel to it and its
    station's set-up."""
    config = env.storey.config
    setup = config.robot.scanner.setup_time
    clock, out = 0.0, []
    gps = start - _GPS_EPOCH_UNIX + _GPS_LEAP_SECONDS
    for record in env.storey.scans:
        begin = clock + record.path_length / config.travel_speed + setup
        out.append((gps + begin, gps + begin + record.acquisition_time - setup))
        clock += record.processing_time + record.acquisition_time
    return out


# ---------------------------------------------------------------------- the report
#: The name of ``nbs scan``'s picture of each step in ``steps/``.
STEP_PICTURE = re.compile(r"step_\d{3,}\.png")


def report_path_problem(out_dir: str | Path, steps: bool = False, pictures: bool = True) -> str | None:
    """Why the report cannot be renamed into ``out_dir`` (None when it can). Found before the work,
    and again before the renames, so that a report is never left half renamed in, one of mixed runs.

    Parameters
    ----------
    out_dir : str or Path
    steps : bool
        The report brings a folder of step pictures (:func:`write_report`'s ``steps``), which
        replaces an earlier report's: a ``steps`` that is a link is refused (the pictures are renamed,
        and a rename crosses no file systems).
    pictures : bool
        That folder holds pictures: a file named ``steps`` is then in their way.

    Returns
    -------
    str or None
        A folder where one of the report's files goes (a rename does not replace a folder), or a
        ``steps`` that is a link or, with ``pictures``, a file.
    """
    final = Path(out_dir)
    for name in REPORT_FILES:
        if (final / name).is_dir() and not (final / name).is_symlink():
            return f"{final / name} is a folder where the report's {name} goes; move it"
    folder = final / "steps"
    if steps and folder.is_symlink():
        return f"{folder} is a link where the report's folder of step pictures goes; move it"
    if steps and pictures and os.path.lexists(folder) and not folder.is_dir():
        return f"{folder} is a file where the folder of the step pictures goes; move it, or pass --no-steps"
    return None


def write_report(
    env: NBSEnv,
    out_dir: str | Path,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
    run_started: float | None = None,
    full_cloud: bool = False,
    steps: str | Path | None = None,
) -> dict[str, Any]:
    """Write the episode's report files (:data:`REPORT_FILES`) into ``out_dir``.

    Parameters
    ----------
    env : NBSEnv
        After an episode. Its top-down picture is drawn as with ``render_mode="rgb_array"``
        whatever the env's render mode.
    out_dir : str or Path
        Created if missing; existing report files are replaced. The files are written into a
        temporary folder inside it, then renamed over the earlier ones: a full disk or an error
        part way leaves the earlier report as it was (the folder needs room for both meanwhile).
    scene_name, policy, seed, policy_times
        As for :func:`nbs_env.report.metrics_dict`.
    run_started : float, optional
        Unix time the episode started, the origin of the simulated clock (the E57 records'
        acquisition times, the LAZ points' GPS times; default: now).
    full_cloud : bool
        ``cloud.laz`` holds every measured point of the kept scans (the E57's, placed with their
        estimated poses, classified by the nearest working-copy point of their room: module
        docstring) instead of the rooms' 5 cm working copies. Needs the env's kept scans.
    steps : str or Path, optional
        A folder of pictures drawn during the episode (``nbs scan``'s ``step_NNN.png``), moved in as
        ``out_dir/steps`` with the report files, in place of an earlier report's pictures
        (:data:`STEP_PICTURE`; files of other names stay): the pictures and the report are one run's,
        whatever stopped it.

    Returns
    -------
    dict
        The metrics written to ``metrics.json``.

    Raises
    ------
    ValueError
        ``full_cloud`` for an env that kept no scans (``EnvConfig.keep_scans``).
    FileExistsError
        A path of ``out_dir`` the report cannot be renamed onto (:func:`report_path_problem`),
        before anything is written or moved.

    Notes
    -----
    ``structure.ply`` holds the points labelled Structure of every room model, ``cloud.ply`` all of
    them with ``label`` 1 (Structure) or 0 (Clutter). Both are the rooms' 5 cm working copies
    (:attr:`RoomModel.points`), whatever ``full_cloud``, in acquisition order (by the time of each
    point's direction in the scan that first measured it), as ``cloud.laz`` holds them by default.
    The full cloud is in the scans' order, each scan's points in its pattern's (as the E57 records).
    """
    log = env.storey.scan_log
    if full_cloud and not log:
        raise ValueError("full_cloud needs the env's kept scans: make the env with keep_scans=True")
    run_started = time.time() if run_started is None else float(run_started)
    final = Path(out_dir)
    pictures = steps is not None and any(Path(steps).iterdir())
    _check_report_paths(final, steps is not None, pictures)
    final.mkdir(parents=True, exist_ok=True)
    # The files are written beside the folder's, then renamed over them together: a full disk or an
    # error part way leaves the earlier report whole, never one of mixed runs.
    out = Path(tempfile.mkdtemp(prefix=".report-", dir=final))
    try:
        try:
            metrics = _write_report_files(env, out, scene_name, policy, seed, policy_times, run_started, full_cloud)
        except OSError as exc:  # named as the report's file, not the temporary folder's
            if exc.filename is not None and Path(exc.filename).parent == out:
                exc.filename = str(final / Path(exc.filename).name)
            raise
        written = {p.name for p in out.iterdir()}
        _check_report_paths(final, steps is not None, pictures)  # again: nothing is renamed unless all can be
        if steps is not None:
            # The earlier pictures leave with the earlier report, and only they: a file of the user's
            # in steps/ stays. Renames only, which a full disk does not stop.
            old_steps, pictures = final / "steps", sorted(Path(steps).iterdir())
            if old_steps.is_dir():
                trash = out / ".old-steps"
                trash.mkdir()
                for old in old_steps.iterdir():
                    if STEP_PICTURE.fullmatch(old.name):
                        os.replace(old, trash / old.name)
                for picture in pictures:
                    os.replace(picture, old_steps / picture.name)
                with contextlib.suppress(OSError):
                    old_steps.rmdir()  # only when nothing is left in it
            elif pictures:
                os.replace(steps, old_steps)
        for name in sorted(written):
            os.replace(out / name, final / name)
        for name in set(REPORT_FILES) - written:  # an earlier report's scans.e57, not this run's
            with contextlib.suppress(FileNotFoundError):
                (final / name).unlink()
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return metrics


def _check_report_paths(final: Path, steps: bool, pictures: bool) -> None:
    problem = report_path_problem(final, steps, pictures)
    if problem is not None:
        raise FileExistsError(problem)


def _write_report_files(
    env: NBSEnv,
    out: Path,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None,
    run_started: float,
    full_cloud: bool,
) -> dict[str, Any]:
    """:func:`write_report`'s files, into the empty folder ``out``."""
    import matplotlib.pyplot as plt

    log = env.storey.scan_log
    metrics = metrics_dict(env.storey, scene_name, policy, seed, policy_times)
    write_text(out / "metrics.json", json.dumps(metrics, indent=1) + "\n")

    scanner = env.storey.config.robot.scanner
    stations = _Stations(env, run_started)
    models = env.storey.room_models()
    working = _working_points(models, stations, scanner)
    write_points_ply(out / "structure.ply", working.points[working.structure])
    write_points_ply(out / "cloud.ply", working.points, working.structure.astype(np.uint8))
    write_model_obj(out / "model.obj", models)
    measured = _measured_points(log, stations, working, scanner) if log else None
    cloud = measured if full_cloud else working
    write_las(
        out / "cloud.laz",
        cloud.points,
        cloud.classes,
        cloud.rooms,
        scans=cloud.scans,
        gps_time=cloud.gps_time,
        intensity=cloud.intensity,
        normals=cloud.normals,
        structure=cloud.structure,
        system=f"nbs-env {scanner.preset or 'generic'} simulated"[:32],
    )
    write_samples(out / "samples.npz", env)
    if measured is not None:
        ends = np.cumsum([len(s.points) for s in log])[:-1]
        write_e57(
            out / "scans.e57",
            log,
            times=stations.times,
            intensity=np.split(measured.intensity, ends),
            scanner=scanner,
        )

    mode = env.render_mode
    env.render_mode = "rgb_array"
    try:
        image = env.render()
    finally:
        env.render_mode = mode
    with replacing(out / "topdown.png") as temporary:
        plt.imsave(temporary, np.asarray(image))
    return metrics
