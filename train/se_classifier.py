"""Train the SE classifier (paper §3.2) on faces of generated storeys, and report on held-out ones.

Usage::

    python -m train.se_classifier --storeys 40 --held-out 12 --seed 0 \\
        --out nbs_env/perception/data/se_svm.json

1. Each training storey (``generated:SEED`` for SEED in ``seed .. seed+storeys-1``, 1-5 rooms) is
   scanned room by room from 1, 2 and 3 well-spread stops; after each set of stops the robot's RoI
   is computed and every wall face of it becomes a sample (partial RoIs give the open, non-SE
   faces). Vertical faces cut through each piece of furniture are added as further samples.
2. Features are the paper's (α, δ, ε) of the face image; labels come from ground truth (a face is SE
   when most of its area lies within 10 cm of a true wall). Ground truth is read here only.
3. An RBF SVM on standardised features is fitted and written as JSON (never a pickle).
4. The report gives accuracy, precision, recall, F1 and the confusion matrix on held-out storeys
   (seeds from 100000 on) that no training sample came from.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from nbs_env.perception.faces import WallFace
from nbs_env.perception.structure import SEClassifier, face_features, face_image
from scenes import generate_plan
from train.perception_data import WallDistance, face_is_structural, room_cases

HELD_OUT_BASE = 100_000
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "nbs_env" / "perception" / "data" / "se_svm.json"


def furniture_faces(plan, roi_floor: float, roi_ceiling: float) -> list[WallFace]:
    """Vertical faces through each piece of furniture along its length (training negatives)."""
    faces = []
    for c in plan.clutter:
        yaw = math.radians(c.yaw)
        d = np.array([math.cos(yaw), math.sin(yaw)])
        half = c.size[0] / 2 + 0.3
        centre = np.asarray(c.position, dtype=float)
        faces.append(WallFace(centre - half * d, centre + half * d, roi_floor, roi_ceiling))
    return faces


def storey_samples(seed: int, rng: np.random.Generator, stops: tuple[int, ...] = (1, 2, 3)) -> tuple[list, list]:
    """(features, labels) of every RoI face and furniture face of one generated storey."""
    plan = generate_plan(seed, rooms=(1, 5))
    scene = plan.to_scene(validate=False)
    distance = WallDistance(scene)
    features, labels = [], []
    for k in stops:
        for case in room_cases(scene, rng, stops=k):
            points = np.concatenate([s.points for s in case.scans])
            faces = list(case.roi.wall_faces)
            if k == max(stops):
                inside = [
                    f
                    for f in furniture_faces(plan, case.roi.floor_z, case.roi.ceiling_z)
                    if case.roi.contains(np.asarray([(np.asarray(f.p0) + np.asarray(f.p1)) / 2]))[0]
                ]
                faces += inside
            for face in faces:
                if face.length < 0.2:
                    continue
                features.append(face_features(face_image(face, points)))
                labels.append(face_is_structural(face, distance))
    return features, labels


def metrics(truth: np.ndarray, predicted: np.ndarray) -> dict:
    """Accuracy, precision, recall, F1 (SE is positive) and the confusion matrix [[TN, FP], [FN, TP]]."""
    from sklearn.metrics import accuracy_score, confusion_matrix, f1_score, precision_score, recall_score

    return {
        "faces": len(truth),
        "accuracy": float(accuracy_score(truth, predicted)),
        "precision": float(precision_score(truth, predicted, zero_division=0)),
        "recall": float(recall_score(truth, predicted, zero_division=0)),
        "f1": float(f1_score(truth, predicted, zero_division=0)),
        "confusion_matrix": confusion_matrix(truth, predicted, labels=[False, True]).tolist(),
    }


def collect(seeds: range, rng: np.random.Generator, label: str) -> tuple[np.ndarray, np.ndarray]:
    features, labels = [], []
    for seed in tqdm(seeds, desc=label, unit="storey"):
        f, y = storey_samples(seed, rng)
        features += f
        labels += y
    return np.asarray(features, dtype=float).reshape(-1, 3), np.asarray(labels, dtype=bool)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Train the SE classifier on generated storeys.")
    parser.add_argument("--storeys", type=int, default=40, help="training storeys (default 40)")
    parser.add_argument("--held-out", type=int, default=12, help="held-out storeys for the report (default 12)")
    parser.add_argument("--seed", type=int, default=0, help="first training storey seed and RNG seed")
    parser.add_argument("--C", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="model JSON to write")
    parser.add_argument("--report", type=Path, default=None, help="also write the report as JSON here")
    args = parser.parse_args(argv)
    if args.storeys < 1 or args.held_out < 1:
        parser.error("--storeys and --held-out must be at least 1")

    t0 = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    X, y = collect(range(args.seed, args.seed + args.storeys), rng, "training storeys")
    Xh, yh = collect(range(HELD_OUT_BASE, HELD_OUT_BASE + args.held_out), rng, "held-out storeys")
    model = SEClassifier.fit(X, y, C=args.C, seed=args.seed)
    report = {
        "command": "python -m train.se_classifier "
        + f"--storeys {args.storeys} --held-out {args.held_out} --seed {args.seed} --C {args.C}",
        "training": {"storeys": args.storeys, "faces": len(y), "se_share": float(y.mean())},
        "training_fit": metrics(y, model.predict(X)),
        "held_out": {"storeys": args.held_out, "first_seed": HELD_OUT_BASE} | metrics(yh, model.predict(Xh)),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    model.training.update({"report": report})
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out)
    text = json.dumps(report, indent=1)
    print(text)
    if args.report is not None:
        args.report.write_text(text + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
