"""Evaluation against ground truth (METHOD §9). The only module of ``nbs_env`` besides the scanner that
reads a scene's labels: it scores the robot, it never informs it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from scenes import Scene, SurfaceClass

__all__ = ["CoverageMeter"]


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
        Count only SE faces that face into a room (see :meth:`scenes.Scene.structural_mask`).
    """

    def __init__(self, scene: Scene, spacing: float = 0.05, radius: float = 0.05, interior_only: bool = True) -> None:
        self.samples = scene.structure_samples(spacing, interior_only=interior_only)
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
