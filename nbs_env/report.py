"""The episode's report, ``metrics.json``: one job, to turn a storey session into the versioned
metrics document (:func:`metrics_dict`), with the true room of every scan (:func:`true_rooms_of`).

It reads the coverage meter's figures (:mod:`nbs_env.evaluation`) and the scene's ground truth;
:mod:`nbs_env.export` writes it with the report's other files.

The metrics schema, ``"nbs-metrics/1"``
---------------------------------------
A stable, versioned format: a later version may add keys, never remove or retype one without
changing the version. Every value is a plain JSON type. Lengths are metres, times seconds,
percentages in 0..100 of the true structural surface (floor, ceiling and wall samples of the
evaluation, :class:`~nbs_env.evaluation.CoverageMeter`). This is the evaluation side: it reads the
scene's ground truth (true positions, true rooms), which the robot never sees.

.. code-block:: text

    schema                  "nbs-metrics/1"
    scene                   str     the scene as given (bundled name, file, generated:SEED)
    scene_offset_m          [x, y] | null   where the file's plan frame lies in the scene's (file xy =
                                    scene xy + offset): an IFC storey at survey coordinates is moved
                                    near the origin, and every position here is in the moved frame
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
    acquisition_time_s      float   scanner time: the scanner preset's station time per scan, else
                                    the points over the configured acquisition rate
    travel_time_s           float   path_length_m / config.travel_speed
    registration_error      {mean_m, max_m, mean_deg, max_deg}: pose estimate vs true pose,
                            over the scans
    quality                 the scan-quality figures (:meth:`~nbs_env.evaluation.CoverageMeter.quality`):
        min_density_per_m2, max_incidence_deg, density_radius_m   the thresholds (config.quality)
        dense_pct           float   % of the structural samples with a point density >= the least
        incidence_pct       float   % seen at least once at an incidence <= the largest
        quality_pct         float   % meeting both
        median_density_per_m2, median_incidence_deg, median_range_m   over the samples sensed
                                    (null when none): the density around them, the best incidence
                                    angle and the shortest range each was seen at
    registrability          {scans, mean_overlap, min_overlap, mean_fitness, min_fitness,
                            refused}: over the scans registered to the cloud before them (all but
                            the first; none without registration, then null): overlap is the
                            share of the scan the cloud before it explains, fitness ICP's, refused
                            the count of poses refused
    rooms                   list, one per TRUE room of the scene, in scene order:
        id                  int     the scene's room id
        name                str
        scans               int     scans whose true position lies in the room (0: never scanned)
        structure_sensed_pct float  the room's structural surface sensed, % of the room's
        path_length_m       float   the legs driven to the room's scans
        processed_points    int
        processing_time_s   float
        quality_pct         float   the room's structural samples meeting both quality thresholds, %
    steps                   list, one per scan, in order:
        scan                int     0, 1, ...
        room                int | null  the true room of the scan (see below)
        position            [x, y, z]   true scanner position
        estimated_position  [x, y, z]   the robot's estimate
        estimated_rotation  [w, x, y, z]   the robot's estimate of the scanner's orientation, a unit
                            quaternion (scanner frame to map frame, as an E57 pose)
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
        registration_overlap, registration_fitness   float | null   the scan's overlap with the
                            cloud before it and ICP's fitness (null for the first scan)
        dense_pct, incidence_pct, quality_pct   float   the quality shares after this scan
    door_events             list of the env's door events: detected (with exterior, covered),
                            crossed, abandoned (with reason)
    room_ends               list, one per room the robot completed: {room (the robot's number),
                            scans, roi_m2 (its RoI's area), reason: "gain" | "declared" | "cap" |
                            "no NVP" | "earlier room" (no NVP, its RoI mostly in rooms scanned
                            before)}
    wall_searches           list, one per wall-search scan (RoomRules.wall_search.scans > 0):
                            {scan (its index in steps), room (the robot's number)}
    scanner                 {name, setting, model} | null: the datasheet scanner preset that ran
                            (``--scanner NAME[:SETTING]``, :attr:`~nbs_env.config.ScannerConfig.preset`,
                            :mod:`nbs_env.config.scanners`): its name (``"rtc360"``), resolution setting
                            (``"6mm"``) and manufacturer and model (``"Leica RTC360"``; null for a
                            name no preset has); null for the method's generic simulated scanner
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
from shapely.geometry import Point, Polygon

if TYPE_CHECKING:
    from nbs_env.storey import Storey

__all__ = [
    "ROOM_TOLERANCE",
    "SCHEMA",
    "json_safe",
    "metrics_dict",
    "quaternion_wxyz",
    "scanner_preset",
    "true_rooms_of",
]

#: The version tag of :func:`metrics_dict`'s output.
SCHEMA = "nbs-metrics/1"

#: How far (m) a scan outside every room polygon may lie from a room to be counted in it.
ROOM_TOLERANCE = 0.5


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


def _share(flags: np.ndarray, mask: np.ndarray | None = None) -> float:
    """% of the samples (of ``mask``'s) whose flag is set; 0 with none."""
    flags = flags if mask is None else flags[mask]
    return 100.0 * float(np.count_nonzero(flags)) / len(flags) if len(flags) else 0.0


def scanner_preset(preset: str | None) -> dict[str, str | None] | None:
    """``metrics.json``'s ``scanner``: the datasheet preset a scanner's values came from.

    Parameters
    ----------
    preset : str or None
        :attr:`nbs_env.config.ScannerConfig.preset` (``"rtc360:6mm"``), None for the generic scanner.

    Returns
    -------
    dict or None
        ``{"name", "setting", "model"}``: the preset's name and setting (None when the spec names
        none), and its manufacturer and model from :data:`nbs_env.config.scanners.SCANNERS` (None
        for a name it lacks); None for ``preset`` None.
    """
    if preset is None:
        return None
    from nbs_env.config.scanners import SCANNERS

    name, colon, setting = str(preset).partition(":")
    model = SCANNERS.get(name.strip().lower())
    return {"name": name, "setting": setting if colon else None, "model": None if model is None else model.title}


def quaternion_wxyz(pose: np.ndarray) -> np.ndarray:
    """The rotation of a (4, 4) pose as a unit quaternion ``[w, x, y, z]`` (E57's order), w >= 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(pose, dtype=float)[:3, :3]).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


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

    quality_config = storey.config.quality
    quality = meter.quality(quality_config)
    good = (quality.density >= quality_config.min_density) & (quality.incidence <= quality_config.max_incidence)
    if len(quality.dense_pct) != len(steps):  # scans added without their origin: no curves
        quality_rows = [{"dense_pct": None, "incidence_pct": None, "quality_pct": None} for _ in steps]
    else:
        quality_rows = [
            {"dense_pct": float(d), "incidence_pct": float(a), "quality_pct": float(q)}
            for d, a, q in zip(quality.dense_pct, quality.incidence_pct, quality.quality_pct, strict=True)
        ]
    seen = np.isfinite(quality.incidence)

    def median(values: np.ndarray) -> float | None:
        return float(np.median(values[seen])) if seen.any() else None

    registered = [s for s in steps if s.registration_overlap is not None]
    overlaps = np.array([s.registration_overlap for s in registered], dtype=float)
    fitness = np.array([s.registration_fitness for s in registered], dtype=float)

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
                "quality_pct": _share(good, meter.samples.rooms == room.id),
            }
        )

    step_rows = [
        {
            "scan": int(s.scan),
            "room": room,
            "position": [float(v) for v in s.true_position[:3]],
            "estimated_position": [float(v) for v in s.estimated_position[:3]],
            "estimated_rotation": quaternion_wxyz(s.estimated_pose).tolist(),
            "predicted_gain": int(s.predicted_gain),
            "structure_sensed_pct": float(s.structure_sensed_pct),
            "path_length_m": float(s.path_length),
            "processing_time_s": processing(k),
            "points": int(s.points),
            "structure_points": int(s.structure_points),
            "door": bool(s.door),
            "times": {str(k): float(v) for k, v in s.times.items()},
            "registration_refused": str(s.registration_refused),
            "registration_overlap": s.registration_overlap,
            "registration_fitness": s.registration_fitness,
            **quality_rows[k],
        }
        for k, (s, room) in enumerate(zip(steps, true_rooms, strict=True))
    ]

    metrics = {
        "schema": SCHEMA,
        "scene": str(scene_name),
        "scene_offset_m": getattr(storey.scene, "metadata", {}).get("offset"),
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
        "quality": {
            "min_density_per_m2": float(quality_config.min_density),
            "max_incidence_deg": float(quality_config.max_incidence),
            "density_radius_m": float(quality_config.density_radius),
            "dense_pct": _share(quality.density >= quality_config.min_density),
            "incidence_pct": _share(quality.incidence <= quality_config.max_incidence),
            "quality_pct": _share(good),
            "median_density_per_m2": median(quality.density),
            "median_incidence_deg": median(quality.incidence),
            "median_range_m": median(quality.range),
        },
        "registrability": {
            "scans": len(registered),
            "mean_overlap": float(overlaps.mean()) if len(overlaps) else None,
            "min_overlap": float(overlaps.min()) if len(overlaps) else None,
            "mean_fitness": float(fitness.mean()) if len(fitness) else None,
            "min_fitness": float(fitness.min()) if len(fitness) else None,
            "refused": sum(1 for s in steps if s.registration_refused),
        },
        "rooms": rooms,
        "steps": step_rows,
        "door_events": storey.door_events,
        "room_ends": storey.room_ends,
        "wall_searches": storey.wall_searches,
        "scanner": scanner_preset(storey.config.robot.scanner.preset),
        "config": storey.config.to_dict(),
    }
    return json_safe(metrics)
