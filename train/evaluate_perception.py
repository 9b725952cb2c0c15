"""Measure perception against ground truth: RoI IoU, leaks through doors, SE classification, point labels.

Usage::

    python -m train.evaluate_perception --rooms 30 [--fzk scenes/data/corpus/AC20-FZK-Haus.ifc] [--json out.json]

Rooms come from generated storeys that neither the classifier's training nor its held-out report
used (seeds from 200000 on), picked so that at least a third are L, T, U or irregular and at least
a fifth have non-right angles. Each room is scanned from three well-spread stops (true poses: this
measures perception, not registration). For every room:

- **IoU** of the RoI polygon with the true clear floor polygon;
- **leak**: the RoI's area inside other rooms (rooms that have a door only); "stays out" is < 0.5 m²;
- **SE classification** of the RoI's wall faces against ground truth (F1 over all faces);
- **point labels**: Structure/Clutter of every point inside the RoI (grown by 0.2 m to keep the
  walls' points) against whether its ray hit a true floor, ceiling or wall.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from shapely.geometry import Polygon
from tqdm import tqdm

from nbs_env.perception.roi import leaked_area, roi_iou
from nbs_env.perception.structure import SEClassifier, label_points
from scenes import Scene, load_scene
from train.perception_data import RoomCase, WallDistance, face_is_structural, room_cases
from train.se_classifier import metrics

EVAL_BASE = 200_000


def room_shape(polygon: np.ndarray) -> tuple[str, bool]:
    """('rect' | 'L' | 'T/U/irregular', has a non-right angle) of a room polygon."""
    p = np.asarray(polygon)
    a, b = np.roll(p, 1, axis=0) - p, np.roll(p, -1, axis=0) - p
    cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return {4: "rect", 6: "L"}.get(len(p), "T/U/irregular"), bool(np.any(np.abs(cos) > 0.05))


def evaluate_case(case: RoomCase, model: SEClassifier, distance: WallDistance) -> dict:
    roi, scene, room = case.roi, case.scene, case.room
    points = np.concatenate([s.points for s in case.scans])
    faces = roi.wall_faces
    predicted = model.classify_faces(faces, points)
    truth = np.array([face_is_structural(f, distance) for f in faces])
    se_faces = [f for f, se in zip(faces, predicted, strict=True) if se]
    near = Polygon(roi.polygon).buffer(0.2)
    import shapely

    inside = shapely.contains_xy(near, points[:, 0], points[:, 1])
    labels = label_points(points[inside], se_faces, roi.floor_z, roi.ceiling_z, roi.polygon)
    has_door = any(room.id in d.rooms for d in scene.doors)
    others = [r.polygon for r in scene.rooms if r.id != room.id]
    shape, oblique = room_shape(room.polygon)
    return {
        "scene": scene.name,
        "room": room.name,
        "shape": shape,
        "non_right_angle": oblique,
        "iou": roi_iou(roi.polygon, room.polygon),
        "has_door": has_door,
        "leak_m2": leaked_area(roi.polygon, others) if has_door else None,
        "roi_vertices": len(roi.polygon),
        "true_vertices": len(room.polygon),
        "faces_truth": truth.tolist(),
        "faces_predicted": predicted.tolist(),
        "points": int(inside.sum()),
        "points_agree": int(np.count_nonzero(labels == case.truth_labels[inside])),
    }


def summarise(rows: list[dict]) -> dict:
    iou = np.array([r["iou"] for r in rows])
    leaks = np.array([r["leak_m2"] for r in rows if r["leak_m2"] is not None])
    ft = np.concatenate([r["faces_truth"] for r in rows]).astype(bool)
    fp = np.concatenate([r["faces_predicted"] for r in rows]).astype(bool)
    agree = sum(r["points_agree"] for r in rows) / max(1, sum(r["points"] for r in rows))
    shapes: dict[str, int] = {}
    for r in rows:
        shapes[r["shape"]] = shapes.get(r["shape"], 0) + 1
    return {
        "rooms": len(rows),
        "shapes": shapes,
        "non_right_angle_rooms": sum(r["non_right_angle"] for r in rows),
        "iou_median": float(np.median(iou)),
        "iou_min": float(iou.min()),
        "share_iou_at_least_0.9": float(np.mean(iou >= 0.9)),
        "rooms_with_door": len(leaks),
        "share_no_leak_below_0.5m2": float(np.mean(leaks < 0.5)) if len(leaks) else None,
        "leak_max_m2": float(leaks.max()) if len(leaks) else None,
        "se_faces": metrics(ft, fp),
        "point_label_agreement": float(agree),
    }


def generated_rows(n_rooms: int, model: SEClassifier, rng: np.random.Generator) -> list[dict]:
    rows: list[dict] = []
    rects = 0
    seed = EVAL_BASE
    with tqdm(total=n_rooms, desc="generated rooms", unit="room") as bar:
        while len(rows) < n_rooms:
            scene = load_scene(f"generated:{seed}", rooms=(2, 5), nonorthogonal=0.6)
            seed += 1
            distance = WallDistance(scene)
            for case in room_cases(scene, rng, stops=3):
                shape, _ = room_shape(case.room.polygon)
                # Keep rectangles to at most a third, so L/T/U and oblique rooms are well represented.
                if shape == "rect" and rects >= n_rooms // 3:
                    continue
                rects += shape == "rect"
                rows.append(evaluate_case(case, model, distance))
                bar.update(1)
                if len(rows) == n_rooms:
                    break
    return rows


def scene_rows(scene: Scene, model: SEClassifier, rng: np.random.Generator) -> list[dict]:
    distance = WallDistance(scene)
    return [evaluate_case(case, model, distance) for case in room_cases(scene, rng, stops=3)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Measure perception against ground truth.")
    parser.add_argument("--rooms", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--fzk", type=Path, default=Path("scenes/data/corpus/AC20-FZK-Haus.ifc"))
    parser.add_argument("--json", type=Path, default=None, help="write the per-room rows and summaries here")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    model = SEClassifier.load_default()
    rng = np.random.default_rng(args.seed)
    rows = generated_rows(args.rooms, model, rng)
    out = {"generated": summarise(rows)}
    fzk_rows = []
    if args.fzk.is_file():
        fzk_rows = scene_rows(load_scene(str(args.fzk)), model, rng)
        out["fzk_ground_floor"] = summarise(fzk_rows)
        out["fzk_rooms"] = [
            {k: r[k] for k in ("room", "iou", "leak_m2", "roi_vertices", "true_vertices")} for r in fzk_rows
        ]
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, indent=1))
    if args.json is not None:
        args.json.write_text(json.dumps(out | {"rows": rows, "fzk_rows": fzk_rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
