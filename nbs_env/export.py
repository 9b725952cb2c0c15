"""The report of a scanning episode: metrics JSON, point clouds, the structural model, a picture.

:func:`write_report` writes, from an :class:`~nbs_env.env.NBSEnv` after an episode:

================  ====================================================================================
``metrics.json``  :func:`nbs_env.report.metrics_dict` (its schema is documented there)
``scans.e57``     every scan as measured, one E57 data3D record per station (:func:`write_e57`):
                  points in the scanner frame, the robot's estimated pose as the record's pose;
                  written when the env kept its scans (``EnvConfig.keep_scans``, as ``nbs scan`` does)
``cloud.laz``     the registered room models' points, classified (:func:`write_las`): wall, floor,
                  ceiling, clutter, as the robot's perception labelled them
``structure.ply`` the registered points labelled Structure, of every room model
``cloud.ply``     every registered point of the room models, with a ``label`` (1 Structure, 0 Clutter)
``model.obj``     the recovered structural model (:func:`structural_model`): SE walls, floors, ceilings
``samples.npz``   the evaluation's structural samples with their scan-quality figures
                  (:func:`write_samples`)
``topdown.png``   the env's top-down picture of the end of the episode
================  ====================================================================================

The merged point clouds (LAZ, PLY) are the rooms' 5 cm working copies (the voxel-downsampled clouds
that perception works on, :attr:`nbs_env.belief.RoomModel.points`), placed with the robot's own
pose estimates; the E57 holds the full-resolution scans.

E57 (ASTM E2807) is what scan-to-BIM tools open as a registered scan project (CloudCompare, Autodesk
ReCap, Leica Cyclone, Trimble RealWorks); it is written with pye57 (libE57Format). LAS 1.4 with
LAZ compression is written with laspy (and its lazrs backend).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from shapely.geometry import MultiPolygon, Polygon

from nbs_env.belief import RoomModel
from nbs_env.report import metrics_dict, quaternion_wxyz

if TYPE_CHECKING:
    from nbs_env.env import NBSEnv
    from nbs_env.storey import ScanPoints

__all__ = [
    "FACE_KINDS",
    "LAS_CLASSES",
    "REPORT_FILES",
    "classify_points",
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

# GPS time (E57's dateTimeValue) counts from 1980-01-06 and runs 18 leap seconds ahead of UTC.
_GPS_EPOCH_UNIX = 315_964_800.0
_GPS_LEAP_SECONDS = 18.0


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
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(record.tobytes())
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
    """
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
    path.write_text(text if isinstance(text, str) else text.decode())
    return path


# ---------------------------------------------------------------------- scan projects: E57, LAS
def write_e57(
    path: str | Path,
    scans: list[ScanPoints],
    names: list[str] | None = None,
    times: list[tuple[float, float]] | None = None,
) -> Path:
    """Write scans as an E57 file: one data3D record per station.

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
        Each record's acquisition start and end, GPS seconds (E57's ``dateTimeValue``).

    Returns
    -------
    Path
        ``path``.

    Notes
    -----
    Each record stores ``cartesianX/Y/Z`` in the scanner frame, ``rowIndex`` and ``columnIndex``
    (the scan pattern's grid, so that tools can rebuild the panorama), and the pose as the record's
    ``pose`` (rotation quaternion w, x, y, z and translation, scanner frame to the robot's map
    frame). The simulator has no intensity and one return per ray, so neither is written. Its
    ``cartesianBounds`` are in the scanner frame, as the E57 standard defines them.
    """
    import pye57

    path = Path(path)
    names = names or [f"scan_{k:03d}" for k in range(len(scans))]
    if len(names) != len(scans) or (times is not None and len(times) != len(scans)):
        raise ValueError(f"{len(scans)} scans need as many names and times, got {len(names)} and {len(times or [])}")
    if path.exists():
        path.unlink()  # libE57 refuses to open an existing file for writing
    e57 = pye57.E57(str(path), mode="w")
    try:
        for k, scan in enumerate(scans):
            points = np.asarray(scan.points, dtype=np.float32).reshape(-1, 3)
            pose = np.asarray(scan.pose, dtype=float)
            low = points.min(axis=0) if len(points) else np.zeros(3)
            high = points.max(axis=0) if len(points) else np.zeros(3)
            start, end = times[k] if times is not None else (0.0, 0.0)
            header = SimpleNamespace(
                name=names[k],
                rotation=quaternion_wxyz(pose),
                translation=pose[:3, 3].copy(),
                xMinimum=float(low[0]),
                xMaximum=float(high[0]),
                yMinimum=float(low[1]),
                yMaximum=float(high[1]),
                zMinimum=float(low[2]),
                zMaximum=float(high[2]),
                acquisitionStart_dateTimeValue=float(start),
                acquisitionEnd_dateTimeValue=float(end),
            )
            data = {
                "cartesianX": points[:, 0].astype(np.float64),
                "cartesianY": points[:, 1].astype(np.float64),
                "cartesianZ": points[:, 2].astype(np.float64),
                "rowIndex": np.asarray(scan.rows, dtype=np.int32),
                "columnIndex": np.asarray(scan.cols, dtype=np.int32),
            }
            e57.write_scan_raw(data, scan_header=header)
    finally:
        e57.close()
    return path


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


def write_las(path: str | Path, points: np.ndarray, classes: np.ndarray, rooms: np.ndarray | None = None) -> Path:
    """Write classified points as LAS 1.4 (point format 6); a ``.laz`` path is LAZ-compressed.

    Parameters
    ----------
    path : str or Path
        The file to write; ``.laz`` compresses (laspy's lazrs backend), ``.las`` does not.
    points : (n, 3) float
        Coordinates, stored at millimetre scale.
    classes : (n,) uint8
        Classification codes (:data:`LAS_CLASSES`; the header's Classification Lookup names them).
    rooms : (n,) int, optional
        The robot's room number of each point, as the extra byte dimension ``room`` (uint16).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``points`` is not (n, 3) or not finite, or ``classes`` or ``rooms`` does not match it.
    """
    import laspy

    path = Path(path)
    pts = _checked_points(points)
    classes = np.asarray(classes)
    if classes.shape != (len(pts),):
        raise ValueError(f"classes must have shape ({len(pts)},), got {classes.shape}")
    if rooms is not None:
        rooms = np.asarray(rooms)
        if rooms.shape != (len(pts),):
            raise ValueError(f"rooms must have shape ({len(pts)},), got {rooms.shape}")
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(pts.min(axis=0)) if len(pts) else np.zeros(3)
    header.generating_software = "nbs-env"
    if rooms is not None:
        header.add_extra_dim(laspy.ExtraBytesParams(name="room", type=np.uint16, description="robot's room number"))
    header.vlrs.append(_classification_lookup())
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.classification = classes.astype(np.uint8)
    if rooms is not None:
        las.room = rooms.astype(np.uint16)
    las.write(str(path))
    return path


def write_samples(path: str | Path, env: NBSEnv) -> Path:
    """Write the evaluation's structural samples and their scan-quality figures as NPZ.

    Arrays: ``points`` (n, 3) float32, ``labels`` (n,) uint8 (SurfaceClass), ``rooms`` (n,) int32
    (true room id), ``sensed`` (n,) bool, ``density`` (n,) float32 (points per m²),
    ``incidence`` (n,) float32 (best incidence angle, degrees; NaN when never seen) and ``range``
    (n,) float32 (shortest range, metres; NaN when never seen); see
    :meth:`nbs_env.evaluation.CoverageMeter.quality`. Ground truth: for evaluation only.
    """
    meter = env.storey.meter
    quality = meter.quality(env.storey.config.quality)
    np.savez_compressed(
        Path(path),
        points=meter.samples.points.astype(np.float32),
        labels=meter.samples.labels.astype(np.uint8),
        rooms=meter.samples.rooms.astype(np.int32),
        sensed=meter.sensed.copy(),
        density=quality.density.astype(np.float32),
        incidence=quality.incidence.astype(np.float32),
        range=quality.range.astype(np.float32),
    )
    return Path(path)


def _station_times(env: NBSEnv, start: float) -> list[tuple[float, float]]:
    """Each scan's acquisition start and end on the simulated clock, GPS seconds from ``start``
    (Unix time): the processing and acquisition of the scans before it and the travel to it."""
    config = env.storey.config
    clock, out = 0.0, []
    gps = start - _GPS_EPOCH_UNIX + _GPS_LEAP_SECONDS
    for record in env.storey.scans:
        begin = clock + record.path_length / config.travel_speed
        out.append((gps + begin, gps + begin + record.acquisition_time))
        clock += record.processing_time + record.acquisition_time
    return out


# ---------------------------------------------------------------------- the report
def write_report(
    env: NBSEnv,
    out_dir: str | Path,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
    run_started: float | None = None,
) -> dict[str, Any]:
    """Write the episode's report files (:data:`REPORT_FILES`) into ``out_dir``.

    Parameters
    ----------
    env : NBSEnv
        After an episode. Its top-down picture is drawn as with ``render_mode="rgb_array"``
        whatever the env's render mode.
    out_dir : str or Path
        Created if missing; existing report files are overwritten.
    scene_name, policy, seed, policy_times
        As for :func:`nbs_env.report.metrics_dict`.
    run_started : float, optional
        Unix time the episode started, the origin of the E57 records' acquisition times (default:
        now).

    Returns
    -------
    dict
        The metrics written to ``metrics.json``.

    Notes
    -----
    ``structure.ply`` holds the points labelled Structure of every room model, ``cloud.ply`` all of
    them with ``label`` 1 (Structure) or 0 (Clutter). Both are the rooms' 5 cm working copies
    (:attr:`RoomModel.points`), not the full-resolution scans.
    """
    import matplotlib.pyplot as plt

    run_started = time.time() if run_started is None else float(run_started)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = metrics_dict(env.storey, scene_name, policy, seed, policy_times)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1) + "\n")

    models = env.storey.room_models()
    if models:
        points = np.concatenate([np.asarray(m.points, dtype=float).reshape(-1, 3) for m in models])
        structure = np.concatenate([np.asarray(m.structure, dtype=bool).reshape(-1) for m in models])
    else:
        points, structure = np.zeros((0, 3)), np.zeros(0, dtype=bool)
    write_points_ply(out / "structure.ply", points[structure])
    write_points_ply(out / "cloud.ply", points, structure.astype(np.uint8))
    write_model_obj(out / "model.obj", models)
    codes = [classify_points(m) for m in models]
    write_las(
        out / "cloud.laz",
        points,
        np.concatenate(codes) if codes else np.zeros(0, dtype=np.uint8),
        np.concatenate([np.full(len(c), m.index) for m, c in zip(models, codes, strict=True)]) if codes else None,
    )
    write_samples(out / "samples.npz", env)
    log = env.storey.scan_log
    if log:
        write_e57(out / "scans.e57", log, times=_station_times(env, run_started))

    mode = env.render_mode
    env.render_mode = "rgb_array"
    try:
        image = env.render()
    finally:
        env.render_mode = mode
    plt.imsave(out / "topdown.png", np.asarray(image))
    return metrics
