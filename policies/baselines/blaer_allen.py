"""Blaer & Allen 2007, "Data acquisition and view planning for 3-D modeling tasks".

**Source.** Two phases. Phase 1: from a 2-D map of the site, choose a small set of views that sees
the whole boundary under range and grazing-angle limits (a greedy set cover), and visit them.
Phase 2: on a voxel grid, each next view maximises the number of visible "boundary unseen" voxels
(unknown voxels next to free ones); stop below a threshold. Structure-agnostic.

**Adapted here** (our door detection and dynamic voxel space, per room):
- Phase 1 runs at a room's first decision, on the 2-D map of its first scan: boundary cells are
  columns with occupied voxels between 0.3 and 2.0 m above the floor; a candidate covers a boundary
  cell it sees in 2-D (line of sight stops at boundary cells) from 1.5 to 20 m, at a grazing angle
  under 70° (the angle between the line of sight and the boundary's normal, from the map's
  gradient). Greedy set cover picks views until one adds less than 2% of the boundary. The robot
  then visits them nearest first; as the candidate list changes with the map, each planned view is
  reached through the candidate nearest to it.
- Phase 2 counts, per candidate, the "boundary unseen" voxels (unknown voxels 6-adjacent to Empty
  ones, inside the room's grid) that a line of sight through the occupied voxels reaches (Embree,
  as the greedy's gain does), and stops below 5% of its count at the first phase-2 decision.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from nbs_env.labels import VoxelLabel
from nbs_env.observation import BeliefView
from nbs_env.planning.planner import predict_gains
from nbs_env.planning.visibility import GainConfig
from policies.baselines._maps import MappingPolicy, band_columns, collapse, visible_cells_2d

__all__ = ["BlaerAllenPolicy"]


class BlaerAllenPolicy(MappingPolicy):
    """Two-phase view planning: 2-D set cover, then visible boundary-unseen voxels."""

    name = "blaer_allen"

    def __init__(self, max_grazing_deg: float = 70.0, stop_fraction: float = 0.05) -> None:
        self.max_grazing = np.radians(max_grazing_deg)
        super().__init__(stop_fraction)

    def new_room(self, belief: BeliefView) -> None:
        self.plan: list[np.ndarray] | None = None
        self.phase = 1

    # ------------------------------------------------------------------ phase 1
    def _set_cover(self, belief: BeliefView) -> list[np.ndarray]:
        grid, roi = belief.grid, belief.roi
        _, occupied, _ = collapse(grid.labels[:, :, band_columns(grid, roi.floor_z)])
        boundary = occupied.any(axis=2)
        if not boundary.any():
            return []
        # The boundary's normal from the gradient of its blurred map (pointing away from it).
        smooth = ndimage.gaussian_filter(boundary.astype(float), 1.5)
        gx, gy = np.gradient(smooth)
        cell, origin = grid.voxel_size, grid.origin[:2]
        b_idx = np.flatnonzero(boundary.reshape(-1))
        bi, bj = np.unravel_index(b_idx, boundary.shape)
        centres = origin + (np.column_stack([bi, bj]) + 0.5) * cell
        normals = -np.column_stack([gx[bi, bj], gy[bi, bj]])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-9)
        reach = min(20.0, float(np.hypot(*boundary.shape)) * cell)
        position = {int(f): n for n, f in enumerate(b_idx)}
        covers = []
        valid = np.flatnonzero(belief.mask)
        for i in valid:
            xy = belief.candidates_xy[i]
            seen = visible_cells_2d(boundary, origin, cell, xy, belief.scanner.min_range, reach)
            rows = np.array([position[int(f)] for f in seen if int(f) in position], dtype=np.int64)
            if not len(rows):
                covers.append(set())
                continue
            view = xy - centres[rows]
            view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-9)
            cos = np.einsum("ij,ij->i", view, normals[rows])
            covers.append(set(rows[cos >= np.cos(self.max_grazing)].tolist()))
        chosen, covered = [], set()
        total = len(b_idx)
        while True:
            gains = [len(c - covered) for c in covers]
            best = int(np.argmax(gains)) if gains else 0
            if not gains or gains[best] < 0.02 * total:
                break
            chosen.append(belief.candidates_xy[valid[best]].copy())
            covered |= covers[best]
        return chosen

    # ------------------------------------------------------------------ phase 2
    def _boundary_unseen(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        grid = belief.grid
        labels = grid.labels
        free, occupied, unknown = collapse(labels)
        near_free = ndimage.binary_dilation(free, structure=ndimage.generate_binary_structure(3, 1))
        frontier = unknown & near_free
        # The visibility model counts OCCLUDED_STRUCTURE targets; give it the frontier as targets and
        # the occupied voxels as blockers, with no structure knowledge.
        proxy = np.where(occupied, VoxelLabel.CLUTTER, VoxelLabel.UNKNOWN).astype(np.uint8)
        proxy[frontier] = VoxelLabel.OCCLUDED_STRUCTURE
        # The paper's visibility model whatever gain the greedy is configured with: this is B&A's
        # own utility, counted with the same lines of sight.
        counts = predict_gains(
            proxy, grid.origin, grid.voxel_size, belief.candidates_xy[valid], belief.roi.floor_z, belief.scanner,
            GainConfig(model="visibility"),
        )  # fmt: skip
        return counts.astype(float)

    def act(self, obs, info) -> int:
        belief = self._belief(info)
        stop = len(belief.mask)
        self._track_room(belief)
        valid = np.flatnonzero(belief.mask)
        if not len(valid):
            return stop
        if self.phase == 1:
            if self.plan is None:
                self.plan = self._set_cover(belief)
            here = belief.pose[:2, 3]
            if self.plan:
                # The nearest planned view, reached through the candidate nearest to it.
                k = int(np.argmin([np.linalg.norm(p - here) for p in self.plan]))
                target = self.plan.pop(k)
                d = np.linalg.norm(belief.candidates_xy[valid] - target, axis=1)
                return int(valid[int(np.argmin(d))])
            self.phase = 2
        counts = self._boundary_unseen(belief, valid)
        top = float(counts.max())
        if self._first_best is None:
            self._first_best = max(top, 1e-9)
        elif top < self.stop_fraction * self._first_best:
            return stop
        if top <= 0:
            return stop
        return int(valid[int(np.argmax(counts))])
