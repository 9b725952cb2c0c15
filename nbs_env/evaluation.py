"""Evaluation against ground truth (METHOD §9): the coverage meter, the true room of every scan, and
the ``metrics.json`` schema.

With the scanner, the only part of ``nbs_env`` that reads a scene's labels, rooms and true poses: it
scores the robot, it never informs it.

The metrics schema, ``"nbs-metrics/1"``
---------------------------------------
A stable, versioned format: a later version may add keys, never remove or retype one without
changing the version. Every value is a plain JSON type. Lengths are metres, times seconds,
percentages in 0..100 of the true structural surface (floor, ceiling and wall samples of the
evaluation, :class:`CoverageMeter`). This is the evaluation side: it reads the
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
        registration_refused str    why ICP's pose was refused and the odometry's kept ("" when
                            accepted)
    door_events             list of the env's door events: detected (with exterior, covered),
                            crossed, abandoned (with reason)
    room_ends               list, one per room the robot completed: {room (the robot's number),
                            scans, reason: "gain" | "declared" | "cap" | "no NVP"}
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

import math
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Point, Polygon

from scenes import Scene, SurfaceClass
from scenes.interior import interior_samples

if TYPE_CHECKING:
    from nbs_env.storey import Storey

__all__ = ["ROOM_TOLERANCE", "SCHEMA", "CoverageMeter", "json_safe", "metrics_dict", "true_rooms_of"]

#: The version tag of :func:`metrics_dict`'s output.
SCHEMA = "nbs-metrics/1"

#: How far (m) a scan outside every room polygon may lie from a room to be counted in it.
ROOM_TOLERANCE = 0.5


class CoverageMeter:
    """Share of the true structural surface sensed, overall and per room.

    A ground-truth sample (one per ``spacing``² of floor, ceiling and wall) counts as sensed when a
    registered point lies within ``radius`` of it. The denominator is always the full surface.

    Parameters
    ----------
    scene : Scene
        The true building.
    spacing : float
        Sample spacing in metres (0.05: one sample per 25 cm²).
    radius : float
        Sensing radius in metres.
    interior_only : bool
        Count only the SE surface that faces the building's interior, decided by geometry
        (:func:`scenes.interior.interior_samples`): never the far sides of walls or the undersides
        of slabs, and the same whether or not the file names its rooms.
    """

    def __init__(self, scene: Scene, spacing: float = 0.05, radius: float = 0.05, interior_only: bool = True) -> None:
        self.samples = interior_samples(scene, spacing) if interior_only else scene.structure_samples(spacing)
        self.radius = radius
        self.sensed = np.zeros(len(self.samples), dtype=bool)
        self.room_ids = sorted({int(r) for r in self.samples.rooms})

    def add(self, points: np.ndarray) -> int:
        """Mark the samples the (n, 3) registered points sense; returns how many were newly sensed."""
        points = np.asarray(points, dtype=float)
        todo = np.flatnonzero(~self.sensed)
        if not len(points) or not len(todo):
            return 0
        distance, _ = cKDTree(points).query(self.samples.points[todo], distance_upper_bound=self.radius)
        hit = todo[np.isfinite(distance)]
        self.sensed[hit] = True
        return len(hit)

    def percent(self, room: int | None = None, label: SurfaceClass | None = None) -> float:
        """Sensed share in % of all samples, of one room's, and/or of one class's."""
        mask = np.ones(len(self.samples), dtype=bool)
        if room is not None:
            mask &= self.samples.rooms == room
        if label is not None:
            mask &= self.samples.labels == label
        total = int(mask.sum())
        return 100.0 * float(self.sensed[mask].sum()) / total if total else 0.0


def json_safe(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples and Paths made plain JSON types."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
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


def true_rooms_of(storey: Storey) -> list[int | None]:
    """The true room id of every scan of the storey session (the module docstring says how
    door-frame scans are placed)."""
    rooms = storey.scene.rooms
    polys = [Polygon(np.asarray(r.polygon, dtype=float)) for r in rooms]
    steps = storey.scans
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
    storey: Storey,
    scene_name: str,
    policy: str,
    seed: int | None,
    policy_times: dict[int, float] | None = None,
    structure_aware: bool | None = None,
) -> dict[str, Any]:
    """The ``metrics.json`` content of an episode (schema ``"nbs-metrics/1"``, module docstring).

    Parameters
    ----------
    storey : Storey
        A storey session (an env's ``storey`` after ``reset`` and any number of steps).
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
    steps = storey.scans
    if not steps:
        raise ValueError("the storey has no scans: call reset() first")

    def processed(s) -> int:
        return int(s.structure_points if structure_aware else s.points)

    def processing(i: int) -> float:
        return float(steps[i].processing_time + policy_times.get(i, 0.0))

    policy_name = str(getattr(policy, "name", policy))
    meter = storey.meter
    true_rooms = true_rooms_of(storey)
    cumulative = np.array([float(s.path_length) for s in steps])
    legs = np.diff(cumulative, prepend=0.0)
    path_length = float(cumulative[-1])
    reg = np.array([s.registration_error for s in steps], dtype=float).reshape(-1, 2)

    rooms = []
    for room in storey.scene.rooms:
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
            "registration_refused": str(s.registration_refused),
        }
        for k, (s, room) in enumerate(zip(steps, true_rooms, strict=True))
    ]

    metrics = {
        "schema": SCHEMA,
        "scene": str(scene_name),
        "policy": policy_name,
        "seed": None if seed is None else int(seed),
        "complete": bool(storey.complete),
        "scans": len(steps),
        "structure_sensed_pct": float(meter.percent()),
        "path_length_m": path_length,
        "processed_points": int(sum(processed(s) for s in steps)),
        "measured_points": int(sum(s.points for s in steps)),
        "processing_time_s": float(sum(processing(i) for i in range(len(steps)))),
        "policy_time_s": float(sum(policy_times.values())),
        "acquisition_time_s": float(sum(s.acquisition_time for s in steps)),
        "travel_time_s": path_length / float(storey.config.travel_speed),
        "registration_error": {
            "mean_m": float(reg[:, 0].mean()),
            "max_m": float(reg[:, 0].max()),
            "mean_deg": float(reg[:, 1].mean()),
            "max_deg": float(reg[:, 1].max()),
        },
        "rooms": rooms,
        "steps": step_rows,
        "door_events": storey.door_events,
        "room_ends": storey.room_ends,
        "config": storey.config.to_dict(),
    }
    return json_safe(metrics)
