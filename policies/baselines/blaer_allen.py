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
  ones, inside the room's dynamic workspace: the RoI and 0.5 m past its frontier faces, as for
  the greedy's targets, :func:`~policies.baselines._maps.workspace`; phase 1's boundary is taken
  there too) that a line of sight through the occupied voxels reaches (Embree, as the greedy's gain
  does) within the scanner's range, taken as the range where a scan's points are denser than a
  voxel (a voxel further off may fall between them: counted, it kept drawing views to the far side
  of ``five_rooms``' lounge, 7 m off, whose voxels each scan left unknown, and the room ran to the
  12-scan cap).
- Both phases read the planner's view of the room (``belief.labels``): the blind zone under each
  stop is free, as for the greedy. Without it the surface of each stop's unseen cone was "boundary
  unseen" and drew the next view back beside it (every ``five_rooms`` room ran to the 12-scan cap).
- As for the greedy, what a chosen phase-2 view was to see (within that range) and left unknown is
  no longer counted.
- The stopping rule is the paper's, phase 2's best count below a threshold, read in m² (the count
  times a voxel's face, so that it does not depend on the voxel size) per m² of the RoI's floor
  (the form the calibration chose). The paper gives no value for our rooms; :data:`STOP_BELOW`
  was calibrated on generated training storeys (``python -m train.calibrate_stops``, figures in
  ``docs/experiments/stopping.md``): the rule ends all 58 training rooms that reach the cap at ε = 0 at
  5.6 points of coverage (per √m² 6.5 points, a fixed ε 7.7).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage

from nbs_env.labels import VoxelLabel
from nbs_env.observation import BeliefView
from nbs_env.planning.planner import sensor_positions
from nbs_env.planning.visibility import GainConfig, VisibilityModel
from policies.baselines._maps import MappingPolicy, band_columns, collapse, visible_cells_2d, workspace

__all__ = ["STOP_BELOW", "BlaerAllenPolicy"]

#: ε of phase 2's stopping rule: m² of visible boundary-unseen voxels per m² of the RoI's floor
#: (``train.calibrate_stops`` on generated:0-9, fast preset, with phase 2 counting within the dense
#: range and navigation reading the rays' crossed voxels near the floor: the rule ends all 58
#: training rooms that reach the cap at ε = 0, at a cost of 5.6 points of coverage against running
#: every room to the cap; 0.175 per √m² and 6.4 points before).
STOP_BELOW = 0.03911


class BlaerAllenPolicy(MappingPolicy):
    """Two-phase view planning: 2-D set cover, then visible boundary-unseen voxels (see the module
    docstring).

    Parameters
    ----------
    max_grazing_deg : float
        Phase 1: the largest angle, degrees, between a line of sight and a boundary cell's normal at
        which the candidate covers the cell.
    stop_below : float, optional
        ε of phase 2's stopping rule, in m² of visible boundary-unseen voxels per m² of the RoI's
        floor. None (the default): :data:`STOP_BELOW`.
    controlled : bool
        As for :class:`MappingPolicy`, which also says what ε = 0 means.

    Raises
    ------
    ValueError
        A ``stop_below`` that is negative or not finite.
    """

    name = "blaer_allen"
    default_stop_below = STOP_BELOW
    stop_area_power = 1.0

    def __init__(
        self, max_grazing_deg: float = 70.0, stop_below: float | None = None, controlled: bool = False
    ) -> None:
        self.max_grazing = np.radians(max_grazing_deg)
        super().__init__(stop_below, controlled)

    def new_room(self, belief: BeliefView) -> None:
        """Start the room in phase 1, its set cover to be planned at its first decision.

        Parameters
        ----------
        belief : BeliefView
            Not read (:meth:`MappingPolicy.new_room`).
        """
        self.plan: list[np.ndarray] | None = None
        self.phase = 1

    # ------------------------------------------------------------------ phase 1
    def _set_cover(self, belief: BeliefView) -> list[np.ndarray]:
        grid, roi = belief.grid, belief.roi
        _, occupied, _ = collapse(self.labels_of(belief)[:, :, band_columns(grid, roi.floor_z)])
        boundary = occupied.any(axis=2) & workspace(belief)[0]
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
        free, occupied, unknown = collapse(self.labels_of(belief))
        near_free = ndimage.binary_dilation(free, structure=ndimage.generate_binary_structure(3, 1))
        frontier = unknown & near_free & workspace(belief)[1] & ~self.dropped_mask(grid)
        # The visibility model counts OCCLUDED_STRUCTURE targets; give it the frontier as targets and
        # the occupied voxels as blockers, with no structure knowledge.
        proxy = np.where(occupied, VoxelLabel.CLUTTER, VoxelLabel.UNKNOWN).astype(np.uint8)
        proxy[frontier] = VoxelLabel.OCCLUDED_STRUCTURE
        # The paper's visibility model whatever gain the greedy is configured with: this is B&A's
        # own utility, counted with the same lines of sight. Kept for :meth:`expect`.
        self._model = VisibilityModel(proxy, grid.origin, grid.voxel_size, GainConfig(model="visibility"))
        sensors = sensor_positions(belief.candidates_xy[valid], belief.roi.floor_z, belief.scanner)
        return np.asarray(self._model.gains(sensors, self._sensing(belief)), dtype=float)

    def _sensing(self, belief: BeliefView):
        """The scanner as phase 2 counts with it: its range limited to where a scan resolves a voxel."""
        reach = min(belief.scanner.max_range, max(self.dense_range(belief), belief.scanner.min_range))
        return dataclasses.replace(belief.scanner, max_range=reach)

    def expect(self, belief: BeliefView, index: int):
        """The boundary-unseen voxels the chosen view sees within the dense range
        (:meth:`~policies.baselines._maps.MappingPolicy.dense_range`), by phase 2's last count.

        Parameters
        ----------
        belief, index
            As :meth:`MappingPolicy.expect`; the voxels are those of phase 2's last count.

        Returns
        -------
        tuple of ((n, 3) float, None), or None
            The voxels' world centres and no memo; None in phase 1, which predicts nothing
            checkable.
        """
        if self.phase == 1:
            return None
        sensor = sensor_positions(belief.candidates_xy[index : index + 1], belief.roi.floor_z, belief.scanner)[0]
        return self._model.targets[self._model.visible(sensor, self._sensing(belief))], None

    def still_unseen(self, belief: BeliefView, points: np.ndarray, memo) -> np.ndarray:
        """Which of :meth:`expect`'s voxels are still unknown (the scans since measured neither a
        surface nor free space there).

        Parameters
        ----------
        belief, points
            As :meth:`MappingPolicy.still_unseen`: here the voxels' world centres.
        memo : None
            Not read.

        Returns
        -------
        (n,) bool
            True for a voxel still unknown in the room's labels (:func:`~policies.baselines._maps.collapse`);
            False outside the grid.
        """
        grid = belief.grid
        _, _, unknown = collapse(self.labels_of(belief))
        idx = grid.index_of(points)
        ok = grid.inside(idx)
        out = np.zeros(len(points), dtype=bool)
        out[ok] = unknown[tuple(idx[ok].T)]
        return out

    def act(self, obs, info) -> int:
        """Phase 1's next planned view, then phase 2's best candidate, or "room done" by phase 2's
        stopping rule.

        Phase 1 plans the room's set cover at its first decision and visits the views nearest first,
        each through the candidate nearest to it; once they are visited, phase 2 chooses the candidate
        that sees the most boundary-unseen voxels.

        Parameters
        ----------
        obs, info
            As :meth:`MappingPolicy.act` (``obs`` not read: the method keeps its own map).

        Returns
        -------
        int
            A candidate slot, or "room done" (K), as :meth:`MappingPolicy.act` says: while phase 1's
            plan lasts, the candidate nearest its next view; after it, phase 2's best candidate, or
            "room done" by phase 2's stopping rule.

        Raises
        ------
        KeyError
            As :meth:`MappingPolicy.act`.
        """
        belief = self._belief(info)
        stop = len(belief.mask)
        self._track_room(belief)
        self._settle(belief)
        valid = np.flatnonzero(belief.mask)
        if not len(valid):
            return 0 if self.controlled else stop
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
        return self._choose(belief, valid, counts, float(counts.max()) * belief.grid.voxel_size**2)
