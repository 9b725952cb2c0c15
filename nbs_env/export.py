"""The report of a scanning episode: metrics JSON, point clouds, the structural model, a picture.

:func:`write_report` writes, from an :class:`~nbs_env.env.NBSEnv` after an episode:

================  ====================================================================================
``metrics.json``  :func:`nbs_env.evaluation.metrics_dict` (its schema is documented there)
``structure.ply`` the registered points labelled Structure, of every room model
``cloud.ply``     every registered point of the room models, with a ``label`` (1 Structure, 0 Clutter)
``model.obj``     the recovered structural model (:func:`structural_model`): SE walls, floors, ceilings
``topdown.png``   the env's top-down picture of the end of the episode
================  ====================================================================================

The point clouds are the rooms' 5 cm working copies (the voxel-downsampled clouds that perception
works on, :attr:`nbs_env.belief.RoomModel.points`), not the full-resolution scans, placed with the
robot's own pose estimates.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from shapely.geometry import MultiPolygon, Polygon

from nbs_env.belief import RoomModel
from nbs_env.evaluation import metrics_dict

if TYPE_CHECKING:
    from nbs_env.env import NBSEnv

__all__ = [
    "FACE_KINDS",
    "REPORT_FILES",
    "structural_model",
    "write_model_obj",
    "write_points_ply",
    "write_report",
]

#: Face kinds of :func:`structural_model`, indexed by its ``face_attributes["kind"]``.
FACE_KINDS = ("wall", "floor", "ceiling")

#: The files :func:`write_report` writes, in its output folder.
REPORT_FILES = ("metrics.json", "structure.ply", "cloud.ply", "model.obj", "topdown.png")


# ---------------------------------------------------------------------- point clouds
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
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be an (n, 3) array, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
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


# ---------------------------------------------------------------------- the report
def write_report(
    env: NBSEnv,
    out_dir: str | Path,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
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
        As for :func:`nbs_env.evaluation.metrics_dict`.

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

    mode = env.render_mode
    env.render_mode = "rgb_array"
    try:
        image = env.render()
    finally:
        env.render_mode = mode
    plt.imsave(out / "topdown.png", np.asarray(image))
    return metrics
