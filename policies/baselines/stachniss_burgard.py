"""Stachniss & Burgard 2003, "Exploring unknown environments with mobile robots using coverage maps".

**Source.** A 2-D grid whose cells hold a belief over how much of the cell is covered (occupied); a
cell's uncertainty is the entropy of that belief. The next view maximises the expected entropy
reduction over the sensor's footprint minus α times the path cost; exploration stops when no
reachable view has gain above ε. Structure-agnostic.

**Adapted here** (as the paper did: our door detection and our dynamic voxel space):
- The coverage map is built per room from the robot's voxel space: a cell's observations are the
  free and occupied voxels in its column between 0.3 and 2.0 m above the floor (the band a 2-D
  sensor would sweep). Its belief over the coverage c ∈ {0, 0.1, ..., 1} is the normalised binomial
  likelihood c^o (1-c)^f of o occupied and f free voxels: uniform (log 11 nats) when nothing is seen.
- The expected entropy after a scan from a candidate is that of the belief with the same mean and
  ``gain_voxels`` more observations (no more than the column's unseen voxels: a column seen whole
  has nothing left to observe, and promising it more kept 0.5 nat·m² of gain in every covered room
  of ``generated:0``), for every cell the candidate sees: 2-D line of sight through
  cells whose expected coverage is not above 0.5 (unseen cells are expected to be seen through),
  from 1.5 m (the scanner's minimum range) to 20 m.
- Utility = Σ ΔH − α · path length (α = 2 nats per metre).
- Only cells of the room's dynamic workspace (the RoI and 0.5 m past its frontier faces:
  :func:`~policies.baselines._maps.workspace`) count towards a gain; lines of sight cross the whole
  map.
- The map is built from the planner's view of the room (``belief.labels``): the blind zone under
  each stop is free, as for the greedy. Without it, each stop left a disk of about 1.5 m radius
  whose band no scan measured (log 11 nats a cell), and the next stop beside it always had a large
  gain: every room of ``five_rooms`` ran to the 12-scan cap.
- As for the greedy, what a chosen scan was to observe and did not is no longer counted: cells
  with unseen voxels in their band that the view saw in 2-D within the range where a scan's
  points are denser than a voxel and whose unseen voxels the scan did not reduce (under a table, in
  a cabinet's shadow: the 2-D line of sight cannot tell).
- The stopping rule is the paper's, "no reachable view has gain above ε", with the gain Σ ΔH (no
  path cost) read in nat·m² (Σ ΔH times the cell's area, so that ε does not depend on the voxel
  size) per m² of the RoI's floor (the form the calibration chose: it lost less coverage than a
  fixed ε or one per √m² for the same rooms ended). The paper gives no ε for our maps; :data:`STOP_BELOW` was
  calibrated on generated training storeys (``python -m train.calibrate_stops``, figures in
  ``docs/experiments/stopping.md``). The 2-D gain does not fall while clutter shadows in the band stay
  unseen, so the rule ends rooms only at an ε that gives up coverage: 8.6 points on the training
  storeys (to end all of them), where ending rooms within 1 point of their coverage at the cap left
  more than half of them to it.
"""

from __future__ import annotations

import numpy as np

from nbs_env.observation import BeliefView
from policies.baselines._maps import MappingPolicy, band_columns, collapse, visible_cells_2d, workspace

__all__ = ["STOP_BELOW", "StachnissBurgardPolicy"]

#: ε of the stopping rule: nat·m² of expected entropy reduction per m² of the RoI's floor
#: (``train.calibrate_stops`` on generated:0-9, fast preset, after navigation read the rays' crossed
#: voxels near the floor: the rule ends all 59 training rooms that reach the cap at ε = 0, at a cost
#: of 8.6 points of coverage against running every room to the cap; 0.002011 and 6.3 points before).
STOP_BELOW = 0.00296

_BINS = np.linspace(0.0, 1.0, 11)


def _entropy(occupied: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Entropy (nats) of the discretised coverage belief after o occupied and f free observations."""
    c = np.clip(_BINS, 1e-3, 1 - 1e-3)
    log_like = occupied[..., None] * np.log(c) + free[..., None] * np.log1p(-c)
    log_like -= log_like.max(axis=-1, keepdims=True)
    p = np.exp(log_like)
    p /= p.sum(axis=-1, keepdims=True)
    return -(p * np.log(np.maximum(p, 1e-12))).sum(axis=-1)


class StachnissBurgardPolicy(MappingPolicy):
    """Coverage maps with expected entropy reduction minus path cost (see the module docstring).

    Parameters
    ----------
    alpha : float
        The path cost, nats per metre: a candidate's utility is its Σ ΔH minus ``alpha`` × its path
        length.
    gain_voxels : float
        The observations a scan is expected to add to each cell it sees (no more than the cell's
        unseen voxels in the band).
    stop_below : float, optional
        ε of the stopping rule, in nat·m² of expected entropy reduction per m² of the RoI's floor.
        None (the default): :data:`STOP_BELOW`.
    controlled : bool
        As for :class:`MappingPolicy`, which also says what ε = 0 means; the path cost still ranks
        the candidates.

    Raises
    ------
    ValueError
        ``stop_below`` is not a finite number >= 0.
    """

    name = "stachniss_burgard"
    default_stop_below = STOP_BELOW
    stop_area_power = 1.0

    def __init__(
        self, alpha: float = 2.0, gain_voxels: float = 4.0, stop_below: float | None = None, controlled: bool = False
    ) -> None:
        self.alpha = alpha
        self.gain_voxels = gain_voxels
        super().__init__(stop_below, controlled)

    def observe(self, belief: BeliefView) -> None:
        """Rebuild the room's coverage map from the planner's view of the room: per column, the
        occupied, free and unseen voxels of the band 0.3 to 2.0 m above the floor, the entropy of
        the coverage belief and its mean.

        Parameters
        ----------
        belief : BeliefView
            Read for its ``grid``, ``roi`` and ``labels`` (:meth:`MappingPolicy.observe`).
        """
        grid, roi = belief.grid, belief.roi
        band = band_columns(grid, roi.floor_z)
        free, occupied, unknown = collapse(self.labels_of(belief)[:, :, band])
        self.occupied = occupied.sum(axis=2).astype(float)
        self.free = free.sum(axis=2).astype(float)
        self.unseen = unknown.sum(axis=2).astype(float)
        self.entropy = _entropy(self.occupied, self.free)
        seen = self.occupied + self.free
        self.mean = np.where(seen > 0, (self.occupied + 1) / (seen + 2), 0.5)
        self.origin, self.cell = grid.origin[:2], grid.voxel_size
        self.floor_z = roi.floor_z

    def utilities(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        """Each valid candidate's expected entropy reduction over the workspace cells it sees in 2-D,
        minus ``alpha`` × its path length. Keeps the gains and the workspace for
        :meth:`stop_statistic` and :meth:`expect`.

        Parameters
        ----------
        belief, valid
            As :meth:`MappingPolicy.utilities`; ``belief.path_length`` gives the path costs.

        Returns
        -------
        (m,) float
            Σ ΔH (nats) − ``alpha`` × path length (m).
        """
        # After k more observations at the current mean coverage; a cell's observations are the
        # voxels of its column, so a column with nothing left unseen learns nothing more.
        k = np.minimum(self.gain_voxels, self.unseen)
        self.region = workspace(belief)[0] & ~self.dropped_mask(belief.grid, plan=True)
        after = _entropy(self.occupied + k * self.mean, self.free + k * (1 - self.mean))
        # An expected entropy reduction is never negative; the same-mean approximation can be, at
        # cells seen once or twice (generated:3: a negative best gain ended a room at ε = 0).
        reduction = (np.maximum(self.entropy - after, 0.0) * self.region).reshape(-1)
        blocked = self.mean > 0.5  # unknown cells (0.5) are expected to be seen through
        scanner = belief.scanner
        reach = min(20.0, float(np.hypot(*self.mean.shape)) * self.cell)
        gain = np.empty(len(valid))
        for n, i in enumerate(valid):
            seen = visible_cells_2d(blocked, self.origin, self.cell, belief.candidates_xy[i], scanner.min_range, reach)
            gain[n] = reduction[seen].sum()
        self._gain = gain
        return gain - self.alpha * belief.path_length[valid]

    def _cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cell indices (n, 2) of world points and which lie in the map."""
        ij = np.floor((np.asarray(points)[:, :2] - self.origin) / self.cell).astype(np.int64)
        ok = np.all((ij >= 0) & (ij < np.asarray(self.unseen.shape)), axis=1)
        return ij, ok

    def expect(self, belief: BeliefView, index: int):
        """The workspace cells with unseen voxels in their band that the chosen view sees in 2-D
        within the dense range (:meth:`~policies.baselines._maps.MappingPolicy.dense_range`).

        Parameters
        ----------
        belief, index
            As :meth:`MappingPolicy.expect`; the coverage map is the last :meth:`observe`'s.

        Returns
        -------
        tuple of ((n, 3) float, (n,) float)
            The cells' centres at floor height (world), and as memo their unseen voxel counts now.
        """
        xy = belief.candidates_xy[index]
        blocked = self.mean > 0.5
        seen = visible_cells_2d(blocked, self.origin, self.cell, xy, belief.scanner.min_range, self.dense_range(belief))
        seen = seen[(self.unseen.reshape(-1)[seen] > 0) & self.region.reshape(-1)[seen]]
        ij = np.column_stack(np.unravel_index(seen, self.unseen.shape))
        centres = self.origin + (ij + 0.5) * self.cell
        points = np.column_stack([centres, np.full(len(centres), self.floor_z)])
        return points, self.unseen.reshape(-1)[seen].copy()

    def still_unseen(self, belief: BeliefView, points: np.ndarray, memo) -> np.ndarray:
        """Which of :meth:`expect`'s cells the scans since have not reduced.

        Parameters
        ----------
        belief
            Not read: the map is the one :meth:`observe` rebuilt.
        points
            As :meth:`MappingPolicy.still_unseen`: here the cells' points at floor height.
        memo : (n,) float
            The cells' unseen voxel counts when :meth:`expect` was called.

        Returns
        -------
        (n,) bool
            True for a cell whose band has no fewer unseen voxels than ``memo``; False outside the
            map.
        """
        ij, ok = self._cells(points)
        out = np.zeros(len(points), dtype=bool)
        out[ok] = self.unseen[tuple(ij[ok].T)] >= memo[ok]
        return out

    def stop_statistic(self, belief: BeliefView, valid: np.ndarray, utility: np.ndarray) -> float:
        """The best expected entropy reduction of the last :meth:`utilities`, which the stopping rule
        reads (the path cost ranks candidates; it does not stop rooms).

        Parameters
        ----------
        belief, valid, utility
            As :meth:`MappingPolicy.stop_statistic`, none of them read (the utilities include the
            path cost).

        Returns
        -------
        float
            The largest Σ ΔH times a cell's area, nat·m².
        """
        return float(np.max(self._gain)) * self.cell**2
