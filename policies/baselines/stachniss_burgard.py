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
  ``gain_voxels`` more observations, for every cell the candidate sees: 2-D line of sight through
  cells whose expected coverage is not above 0.5 (unseen cells are expected to be seen through),
  from 1.5 m (the scanner's minimum range) to 20 m.
- Utility = Σ ΔH − α · path length (α = 2 nats per metre); the room ends when the best utility falls
  below 5% of its value at the room's first decision.
"""

from __future__ import annotations

import numpy as np

from nbs_env.observation import BeliefView
from policies.baselines._maps import MappingPolicy, band_columns, collapse, visible_cells_2d

__all__ = ["StachnissBurgardPolicy"]

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
    """Coverage maps with expected entropy reduction minus path cost (see the module docstring)."""

    name = "stachniss_burgard"

    def __init__(self, alpha: float = 2.0, gain_voxels: float = 4.0, stop_fraction: float = 0.05) -> None:
        self.alpha = alpha
        self.gain_voxels = gain_voxels
        super().__init__(stop_fraction)

    def observe(self, belief: BeliefView) -> None:
        grid, roi = belief.grid, belief.roi
        band = band_columns(grid, roi.floor_z)
        free, occupied, _ = collapse(grid.labels[:, :, band])
        self.occupied = occupied.sum(axis=2).astype(float)
        self.free = free.sum(axis=2).astype(float)
        self.entropy = _entropy(self.occupied, self.free)
        seen = self.occupied + self.free
        self.mean = np.where(seen > 0, (self.occupied + 1) / (seen + 2), 0.5)
        self.origin, self.cell = grid.origin[:2], grid.voxel_size

    def utilities(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        # After k more observations at the current mean coverage.
        k = self.gain_voxels
        after = _entropy(self.occupied + k * self.mean, self.free + k * (1 - self.mean))
        reduction = (self.entropy - after).reshape(-1)
        blocked = self.mean > 0.5  # unknown cells (0.5) are expected to be seen through
        scanner = belief.scanner
        reach = min(20.0, float(np.hypot(*self.mean.shape)) * self.cell)
        out = np.empty(len(valid))
        for n, i in enumerate(valid):
            seen = visible_cells_2d(blocked, self.origin, self.cell, belief.candidates_xy[i], scanner.min_range, reach)
            out[n] = reduction[seen].sum() - self.alpha * belief.path_length[i]
        return out
