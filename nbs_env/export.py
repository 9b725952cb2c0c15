"""The report of a scanning episode: metrics JSON, point clouds, the structural model, a picture.

:func:`write_report` writes, from an :class:`~nbs_env.env.NBSEnv` after an episode:

================  ====================================================================================
``metrics.json``  :func:`metrics_dict`, the schema below
``structure.ply`` the registered points labelled Structure, of every room model
``cloud.ply``     every registered point of the room models, with a ``label`` (1 Structure, 0 Clutter)
``model.obj``     the recovered structural model (:func:`structural_model`): SE walls, floors, ceilings
``topdown.png``   the env's top-down picture of the end of the episode
================  ====================================================================================

The point clouds are the rooms' 5 cm working copies (the voxel-downsampled clouds that perception
works on, :attr:`nbs_env.robot.RoomModel.points`), not the full-resolution scans, placed with the
robot's own pose estimates.

The metrics schema, ``"nbs-metrics/1"``
---------------------------------------
A stable, versioned format: a later version may add keys, never remove or retype one without
changing the version. Every value is a plain JSON type. Lengths are metres, times seconds,
percentages in 0..100 of the true structural surface (floor, ceiling and wall samples of the
evaluation, :class:`nbs_env.metrics.CoverageMeter`). This is the evaluation side: it reads the
scene's ground truth (true positions, true rooms), which the robot never sees.

.. code-block:: text

    schema                  "nbs-metrics/1"
    scene                   str     the scene as given (bundled name, file, generated:SEED)
    policy                  str     the policy's name
    seed                    int | null
    complete                bool    the storey was completed (False: the scan budget ran out)
    scans                   int     scans taken, door-frame scans included
    structure_sensed_pct    float   true structural surface sensed, % of the storey's
    path_length_m           float   distance driven
    processed_points        int     points the pipeline processed (the paper's measure): the SE
                                    points for a structure-aware policy (ours), every point for
                                    the structure-agnostic compared methods
    measured_points         int     points of all scans
    processing_time_s       float   registration, RoI, classification, voxels, planning, and the
                                    policy's own decision time
    policy_time_s           float   the policy's decision time alone
    acquisition_time_s      float   simulated scanner time
    travel_time_s           float   path_length_m / config.travel_speed
    registration_error      {mean_m, max_m, mean_deg, max_deg}: pose estimate vs true pose,
                            over the scans
    rooms                   list, one per TRUE room of the scene, in scene order:
        id                  int     the scene's room id
        name                str
        scans               int     scans whose true position lies in the room (0: never scanned)
        structure_sensed_pct float  the room's structural surface sensed, % of the room's
        path_length_m       float   the legs driven to the room's scans
        processed_points    int
        processing_time_s   float
    steps                   list, one per scan, in order:
        scan                int     0, 1, ...
        room                int | null  the true room of the scan (see below)
        position            [x, y, z]   true scanner position
        estimated_position  [x, y, z]   the robot's estimate
        predicted_gain      int     predicted Occluded-structure→Structure conversions (0: first scan
                                    of a room)
        structure_sensed_pct float  cumulative
        path_length_m       float   cumulative
        processing_time_s   float
        points              int     points of the scan
        structure_points    int     of which labelled Structure
        door                bool    a scan taken in a door frame on entering a room
        times               {stage: seconds}: scan, registration, roi, classification, voxels,
                            planning, evaluation
    door_events             list of the env's door events (detected, crossed, unreachable)
    config                  the env's EnvConfig as a dict (tuples as lists)

A scan belongs to the true room whose floor polygon (clear floor inside the walls) contains its
true position, with one exception: a door-frame scan (``door``: the first scan of a room, taken
standing in the door) stands on the wall face of the room just left, a few centimetres inside its
polygon, but belongs to the room entered. It goes to the true room that holds most of the other
scans the robot took in the same room; when there are none (the budget ran out on entering), to the
nearest room within 0.5 m that no earlier scan was in. A scan in no polygon (drift at a wall) goes to
the majority room of its robot room, else to the nearest room within 0.5 m, else to none
(``null``). A room's ``path_length_m`` is the sum of the legs driven to its scans, so the drive to a
door counts for the room entered.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
import trimesh
from shapely.geometry import MultiPolygon, Point, Polygon

from nbs_env.robot import RoomModel

if TYPE_CHECKING:
    from nbs_env.env import NBSEnv

__all__ = [
    "FACE_KINDS",
    "REPORT_FILES",
    "SCHEMA",
    "metrics_dict",
    "structural_model",
    "write_model_obj",
    "write_points_ply",
    "write_report",
]

#: The version tag of :func:`metrics_dict`'s output.
SCHEMA = "nbs-metrics/1"

#: Face kinds of :func:`structural_model`, indexed by its ``face_attributes["kind"]``.
FACE_KINDS = ("wall", "floor", "ceiling")

#: The files :func:`write_report` writes, in its output folder.
REPORT_FILES = ("metrics.json", "structure.ply", "cloud.ply", "model.obj", "topdown.png")

#: How far (m) a scan outside every room polygon may lie from a room to be counted in it.
ROOM_TOLERANCE = 0.5


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
    for kind, z, up in (("floor", room.floor_z, True), ("ceiling", room.ceiling_z, False)):
        v, f = _polygon_triangles(room.polygon, z, up)
        if len(f):
            parts.append((kind, v, f))
    return parts


def structural_model(rooms: list[RoomModel]) -> trimesh.Trimesh:
    """The recovered structural model of the rooms as one triangle mesh.

    Every SE wall face of a room (:attr:`RoomModel.se_faces`) is a quad of two triangles; the floor
    and the ceiling are the room's polygon at ``floor_z`` and ``ceiling_z``, triangulated. All
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


# ---------------------------------------------------------------------- metrics
def _jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples and Paths made plain JSON types."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"cannot make a {type(value).__name__} JSON-safe")


def _true_rooms(env: NBSEnv) -> list[int | None]:
    """The true room id of every scan (the module docstring says how door-frame scans are placed)."""
    rooms = env.scene.rooms
    polys = [Polygon(np.asarray(r.polygon, dtype=float)) for r in rooms]
    steps = env.steps
    points = [Point(float(s.true_position[0]), float(s.true_position[1])) for s in steps]
    contained: list[int | None] = []
    for point in points:
        inside = [r.id for r, p in zip(rooms, polys, strict=True) if shapely.contains_xy(p, point.x, point.y)]
        contained.append(int(inside[0]) if inside else None)
    # The true room of each robot room, by the majority of its scans away from doors.
    votes: dict[int, Counter] = {}
    for step, room in zip(steps, contained, strict=True):
        if room is not None and not step.door:
            votes.setdefault(int(step.room), Counter())[room] += 1

    def nearest(point: Point, exclude: set[int | None]) -> int | None:
        best, best_distance = None, ROOM_TOLERANCE
        for room, poly in zip(rooms, polys, strict=True):
            distance = poly.distance(point)
            if room.id not in exclude and distance <= best_distance:
                best, best_distance = int(room.id), distance
        return best

    out: list[int | None] = []
    for i, step in enumerate(steps):
        vote = votes.get(int(step.room))
        majority = int(vote.most_common(1)[0][0]) if vote else None
        if step.door:
            # Taken in a door frame, which stands on the wall face of the room just left: the scan
            # belongs to the room entered, a room no earlier scan was in.
            room = majority if majority is not None else nearest(points[i], set(out))
            out.append(room if room is not None else contained[i])
        elif contained[i] is not None:
            out.append(contained[i])
        else:
            out.append(majority if majority is not None else nearest(points[i], set()))
    return out


def metrics_dict(
    env: NBSEnv,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
    structure_aware: bool | None = None,
) -> dict[str, Any]:
    """The ``metrics.json`` content of an episode (schema ``"nbs-metrics/1"``, module docstring).

    Parameters
    ----------
    env : NBSEnv
        After ``reset`` and any number of steps.
    scene_name : str
        The scene as the user named it.
    policy : str
        The policy's name (an object with a ``name`` attribute is also taken).
    seed : int or None
        The seed given to ``reset``.
    policy_times : dict of int to float, optional
        Seconds the policy spent deciding, by the index of the scan its decision led to; added to
        that scan's processing time (the greedy's gains are already in the env's planning stage).
    structure_aware : bool, optional
        Whether the policy's pipeline keeps only the SE points (the paper's method) or processes
        every point (the structure-agnostic methods), for ``processed_points``; by default the
        policy object's ``structure_aware`` attribute, else True.

    Returns
    -------
    dict
        Plain JSON types only.
    """
    if structure_aware is None:
        structure_aware = bool(getattr(policy, "structure_aware", True))
    policy_times = policy_times or {}
    steps = env.steps
    if not steps:
        raise ValueError("the env has no scans: call reset() first")

    def processed(s) -> int:
        return int(s.structure_points if structure_aware else s.points)

    def processing(i: int) -> float:
        return float(steps[i].processing_time + policy_times.get(i, 0.0))

    policy_name = str(getattr(policy, "name", policy))
    meter = env.meter
    true_rooms = _true_rooms(env)
    cumulative = np.array([float(s.path_length) for s in steps])
    legs = np.diff(cumulative, prepend=0.0)
    path_length = float(cumulative[-1])
    reg = np.array([s.registration_error for s in steps], dtype=float).reshape(-1, 2)

    rooms = []
    for room in env.scene.rooms:
        mine = [i for i, r in enumerate(true_rooms) if r == room.id]
        rooms.append(
            {
                "id": int(room.id),
                "name": str(room.name),
                "scans": len(mine),
                "structure_sensed_pct": float(meter.percent(room=room.id)),
                "path_length_m": float(sum(legs[i] for i in mine)),
                "processed_points": int(sum(processed(steps[i]) for i in mine)),
                "processing_time_s": float(sum(processing(i) for i in mine)),
            }
        )

    step_rows = [
        {
            "scan": int(s.scan),
            "room": room,
            "position": [float(v) for v in s.true_position[:3]],
            "estimated_position": [float(v) for v in s.estimated_position[:3]],
            "predicted_gain": int(s.predicted_gain),
            "structure_sensed_pct": float(s.structure_sensed_pct),
            "path_length_m": float(s.path_length),
            "processing_time_s": processing(k),
            "points": int(s.points),
            "structure_points": int(s.structure_points),
            "door": bool(s.door),
            "times": {str(k): float(v) for k, v in s.times.items()},
        }
        for k, (s, room) in enumerate(zip(steps, true_rooms, strict=True))
    ]

    metrics = {
        "schema": SCHEMA,
        "scene": str(scene_name),
        "policy": policy_name,
        "seed": None if seed is None else int(seed),
        "complete": bool(env.complete),
        "scans": len(steps),
        "structure_sensed_pct": float(meter.percent()),
        "path_length_m": path_length,
        "processed_points": int(sum(processed(s) for s in steps)),
        "measured_points": int(sum(s.points for s in steps)),
        "processing_time_s": float(sum(processing(i) for i in range(len(steps)))),
        "policy_time_s": float(sum(policy_times.values())),
        "acquisition_time_s": float(sum(s.acquisition_time for s in steps)),
        "travel_time_s": path_length / float(env.config.travel_speed),
        "registration_error": {
            "mean_m": float(reg[:, 0].mean()),
            "max_m": float(reg[:, 0].max()),
            "mean_deg": float(reg[:, 1].mean()),
            "max_deg": float(reg[:, 1].max()),
        },
        "rooms": rooms,
        "steps": step_rows,
        "door_events": env.door_events,
        "config": env.config.to_dict(),
    }
    return _jsonable(metrics)


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
        As for :func:`metrics_dict`.

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
    metrics = metrics_dict(env, scene_name, policy, seed, policy_times)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1) + "\n")

    models = env.room_models()
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
