"""Ground-truth side of perception experiments: scan positions, scans, and true labels of faces.

This module reads scene ground truth on purpose: it builds training data for the SE classifier and
measures perception against the truth. Nothing under ``nbs_env`` imports it.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from nbs_env.config import ScannerConfig
from nbs_env.perception.faces import WallFace
from nbs_env.perception.roi import RoI, RoIScan, compute_roi
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import Room, Scene, SurfaceClass
from scenes._open3d import open3d
from scenes.geometry import STOREY_CLEARANCE, free_region

__all__ = ["RoomCase", "face_is_structural", "room_cases", "spread_positions"]


def spread_positions(scene: Scene, room: Room, rng: np.random.Generator, k: int = 3) -> list[np.ndarray]:
    """``k`` well-spread free stops in ``room``: farthest-point picks among 200 random free points."""
    free = free_region(scene, Polygon(room.polygon), room.floor_z, STOREY_CLEARANCE)
    if free.is_empty:
        return []
    x0, y0, x1, y1 = free.bounds
    candidates: list[np.ndarray] = []
    for _ in range(20):
        xy = np.column_stack([rng.uniform(x0, x1, 500), rng.uniform(y0, y1, 500)])
        inside = shapely.contains_xy(free, xy[:, 0], xy[:, 1])
        candidates.extend(xy[inside][: 200 - len(candidates)])
        if len(candidates) >= 200:
            break
    if not candidates:
        return []
    cands = np.asarray(candidates)
    chosen = [cands[int(rng.integers(len(cands)))]]
    for _ in range(k - 1):
        d = np.min([np.linalg.norm(cands - c, axis=1) for c in chosen], axis=0)
        chosen.append(cands[int(np.argmax(d))])
    return chosen


@dataclass
class RoomCase:
    """One room scanned from a few stops, with the RoI the robot computed from those scans."""

    scene: Scene
    room: Room
    scans: list[RoIScan]
    roi: RoI
    truth_labels: np.ndarray  # (n,) bool per point of all scans: hit a structural face


def room_cases(
    scene: Scene,
    rng: np.random.Generator,
    stops: int = 3,
    scanner_config: ScannerConfig | None = None,
) -> Iterator[RoomCase]:
    """Scan every room of ``scene`` from ``stops`` well-spread positions and compute its RoI.

    Poses are the true ones: these cases measure perception, not registration.
    """
    scanner = Scanner(scene, scanner_config or ScannerConfig())
    for room in scene.rooms:
        positions = spread_positions(scene, room, rng, stops)
        if len(positions) < stops:
            continue
        scans, labels = [], []
        for p in positions:
            pose = pose_from_xyz_rpy(
                p[0], p[1], room.floor_z + scanner.config.height, 0.0, 0.0, rng.uniform(-np.pi, np.pi)
            )
            scan = scanner.scan(pose, rng)
            scans.append(RoIScan.from_scan(scan, pose))
            labels.append(np.isin(scan.truth.labels, [SurfaceClass.FLOOR, SurfaceClass.CEILING, SurfaceClass.WALL]))
        try:
            roi = compute_roi(scans)
        except ValueError:
            continue
        yield RoomCase(scene, room, scans, roi, np.concatenate(labels))


class WallDistance:
    """Distance from points to the nearest true WALL triangle of a scene (open3d)."""

    def __init__(self, scene: Scene) -> None:
        o3d = open3d()
        walls = scene.face_labels == SurfaceClass.WALL
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(scene.mesh.vertices.astype(np.float32)),
            o3d.core.Tensor(scene.mesh.faces[walls].astype(np.uint32)),
        )
        self._o3d = o3d

    def __call__(self, points: np.ndarray) -> np.ndarray:
        q = self._o3d.core.Tensor(np.asarray(points, dtype=np.float32))
        return self._scene.compute_distance(q).numpy()


def face_is_structural(face: WallFace, distance: WallDistance, spacing: float = 0.1, within: float = 0.10) -> bool:
    """A face is SE when most of its area lies within ``within`` m of a true wall (METHOD §4)."""
    nu = max(2, int(np.ceil(face.length / spacing)))
    nv = max(2, int(np.ceil(face.height / spacing)))
    u = (np.arange(nu) + 0.5) / nu * face.length
    v = (np.arange(nv) + 0.5) / nv * face.height
    uu, vv = np.meshgrid(u, v)
    xy = np.asarray(face.p0, dtype=float) + uu.reshape(-1, 1) * face.direction
    points = np.column_stack([xy, face.z0 + vv.reshape(-1)])
    return bool(np.mean(distance(points) <= within) > 0.5)
