"""Volumetric information gain: Potthast & Sukhatme 2014 and the formulations of Isler et al. 2016.

**Sources.** Potthast & Sukhatme, "A probabilistic framework for next best view estimation in a
cluttered environment" (2014): occupancy probabilities per voxel; a view's gain is the sum over its
rays of the entropy of unknown voxels weighted by the probability that the ray reaches them,
P(visible) = Π (1 − p_occ) over the voxels before; take the argmax, stop when the gain is small.
Isler, Sabzevari, Delmerico & Scaramuzza, "An information gain formulation for active volumetric 3D
reconstruction" (2016) compare such gains along rays:

- ``occlusion_aware``: Σ P(visible) · H(p) over all voxels on the rays;
- ``unobserved_voxel``: Σ P(visible) over unknown voxels;
- ``rear_side_voxel``: Σ P(visible) over unknown voxels right behind an occupied one on the ray
  (the unseen back of a surface);
- ``rear_side_entropy``: as the rear side voxel, weighted by H(p);
- ``proximity_count``: Σ P(visible) over unknown voxels within 0.3 m of an occupied one.

**Adapted here** (our door detection and dynamic voxel space):
- Occupancy probabilities are kept per room by the policy as clamped log-odds (OctoMap's update:
  hit +0.85, miss −0.41, clamped to [−2, 3.5]). After every scan, the voxels the planner's view of
  the room (``belief.labels``) marks Empty take a miss and the occupied ones a hit (our space has
  already cast that scan's rays); unknown voxels keep p = 0.5. A voxel whose log-odds stay within
  ±0.2 counts as unknown. The planner's view takes the blind zone under each stop as free, as the
  greedy's navigation does: without it every stop left an unseen cone that the next stop's gain
  counted.
- Visibility follows OctoMap's three states, as its ray casting does: a voxel known free (log-odds
  below −0.2) lets the ray through, an unknown one with p = 0.5, an occupied one with 1 − p. Taking
  free voxels at their clamped p (0.12) made every ray die within a metre of 5 cm voxels: the gain
  at a room's first decision was about 0 (``five_rooms``: 0.0006 nats in its first room) and grew as
  misses accumulated, so no rule relative to it could ever fire.
- Rays: a 5° azimuth-elevation grid over the scanner's field (360° × 100°, 1,440 rays), sampled
  every voxel out to 12 m or the room grid's diagonal, from the candidate at scanner height;
  samples outside the grid count as unknown (p = 0.5). Only voxels of the room's dynamic
  workspace (the RoI prism and 0.5 m past its frontier faces, :func:`~policies.baselines._maps.workspace`) count
  towards a gain; rays cross the whole grid.
- As for the greedy, what a chosen view was to see (unknown workspace voxels it reached with
  P(visible) >= 0.5, within the range where a scan's points are denser than a voxel) and left
  unknown is no longer counted.
- The stopping rule is the papers' "stop when the best gain is small": the best gain below ε, in
  the formulation's own unit (nats, or P(visible)-weighted voxels; both are sums over the fixed
  ray pattern, so ε does not depend on the voxel size). No paper gives ε for our rooms;
  :data:`STOP_BELOW` was calibrated on generated training storeys (``python -m
  train.calibrate_stops``, figures in ``docs/experiments/stopping.md``). Potthast & Sukhatme's is per √m²
  of the RoI's floor, the form the calibration chose (to end all 59 training rooms it loses 2.6
  points, where a fixed ε loses 3.8 and one per m² 7.1). A fixed ε let the largest
  furnished rooms run to the cap (``five_rooms``' 57 m² lounge in every seed).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from scipy import ndimage

from nbs_env.observation import BeliefView
from policies.baselines._maps import MappingPolicy, collapse, march, sphere_directions, workspace

__all__ = ["FORMULATIONS", "STOP_BELOW", "InformationGainPolicy", "PotthastSukhatmePolicy"]

FORMULATIONS = ("occlusion_aware", "unobserved_voxel", "rear_side_voxel", "rear_side_entropy", "proximity_count")
_HIT, _MISS, _LO, _HI = 0.85, -0.41, -2.0, 3.5
#: ε of each formulation's stopping rule, and Potthast & Sukhatme's (``train.calibrate_stops``).
#: Only Potthast & Sukhatme's is calibrated; the Isler et al. formulations' 1.0 is a placeholder in
#: their units, not yet measured (``python -m train.calibrate_stops --methods information_gain:F``).
STOP_BELOW: dict[str, float] = {
    # Nats per √m² of the RoI's floor. generated:0-9, fast preset, after navigation read the rays'
    # crossed voxels near the floor: the rule ends all 59 training rooms, at a cost of 2.56 points of
    # coverage against running every room to the cap (4.918 and 2.75 points before).
    "potthast_sukhatme": 4.8,
    "occlusion_aware": 1.0,
    "unobserved_voxel": 1.0,
    "rear_side_voxel": 1.0,
    "rear_side_entropy": 1.0,
    "proximity_count": 1.0,
}


def _entropy(p: np.ndarray) -> np.ndarray:
    q = np.clip(p, 1e-6, 1 - 1e-6)
    return -(q * np.log(q) + (1 - q) * np.log(1 - q))


class InformationGainPolicy(MappingPolicy):
    """Ray-based volumetric information gain with one of :data:`FORMULATIONS` (see the module
    docstring).

    Parameters
    ----------
    formulation : str
        One of :data:`FORMULATIONS`: what a ray sample is worth when the ray reaches it.
    ray_step_deg : float
        Spacing of the azimuth-elevation grid of rays over the scanner's field, degrees.
    max_range : float
        How far the rays are sampled, metres (no further than the room grid's diagonal).
    stop_below : float, optional
        ε of the stopping rule, in the formulation's unit; 0 never stops by the rule. None (the
        default): the formulation's :data:`STOP_BELOW` (Potthast & Sukhatme's for
        :class:`PotthastSukhatmePolicy`).
    controlled : bool
        As for :class:`MappingPolicy`.

    Raises
    ------
    ValueError
        An unknown ``formulation``, or ``stop_below`` not a finite number >= 0.
    """

    name = "information_gain"
    formulations: ClassVar[tuple[str, ...]] = FORMULATIONS

    def __init__(
        self,
        formulation: str = "occlusion_aware",
        ray_step_deg: float = 5.0,
        max_range: float = 12.0,
        stop_below: float | None = None,
        controlled: bool = False,
    ):
        if formulation not in FORMULATIONS:
            raise ValueError(f"unknown formulation {formulation!r}; formulations: {', '.join(FORMULATIONS)}")
        self.formulation = formulation
        self.ray_step_deg = ray_step_deg
        self.max_range = max_range
        if stop_below is None:
            stop_below = STOP_BELOW[self.name if self.name in STOP_BELOW else formulation]
        super().__init__(stop_below, controlled)

    def new_room(self, belief: BeliefView) -> None:
        """Forget the occupancy map: the new room's log-odds start at 0 (p = 0.5) at its first
        :meth:`observe`.

        Parameters
        ----------
        belief : BeliefView
            Not read; as for :meth:`MappingPolicy.new_room`.
        """
        self.log_odds: np.ndarray | None = None
        self.origin: np.ndarray | None = None

    def observe(self, belief: BeliefView) -> None:
        """Update the occupancy log-odds with this step's scans: for each scan, a miss for every free
        voxel of the planner's view of the room and a hit for every occupied one (as
        :func:`~policies.baselines._maps.collapse` reads them), clamped to [−2, 3.5]. When the grid
        has grown, each voxel keeps its log-odds at its world place.

        Parameters
        ----------
        belief : BeliefView
            As :meth:`MappingPolicy.observe`; its ``grid``, ``labels`` (the planner's view) and
            ``scans`` (the scans registered this step) are read.
        """
        grid = belief.grid
        shape, origin = grid.shape, grid.origin
        if self.log_odds is None:
            self.log_odds = np.zeros(shape, dtype=np.float32)
        elif self.log_odds.shape != shape or not np.allclose(self.origin, origin):
            # The grid grew: keep each voxel's log-odds at its world place.
            grown = np.zeros(shape, dtype=np.float32)
            off = np.rint((self.origin - origin) / grid.voxel_size).astype(int)
            sx, sy, sz = self.log_odds.shape
            grown[off[0] : off[0] + sx, off[1] : off[1] + sy, off[2] : off[2] + sz] = self.log_odds
            self.log_odds = grown
        self.origin = origin.copy()
        free, occupied, _ = collapse(self.labels_of(belief))
        for _ in belief.scans:
            self.log_odds[free] += _MISS
            self.log_odds[occupied] += _HIT
        np.clip(self.log_odds, _LO, _HI, out=self.log_odds)

    def utilities(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        """The formulation's gain of each valid candidate: over the rays from the candidate at scanner
        height, the worth of each workspace sample weighted by the probability that the ray reaches
        it. Keeps the maps it read for :meth:`expect`.

        Parameters
        ----------
        belief, valid
            As :meth:`MappingPolicy.utilities`.

        Returns
        -------
        (m,) float
            The gains, in the formulation's unit (nats, or P(visible)-weighted voxels).
        """
        grid = belief.grid
        p = (1.0 / (1.0 + np.exp(-self.log_odds))).astype(np.float32)
        unknown = np.abs(self.log_odds) < 0.2
        occupied = self.log_odds > 0.2
        # OctoMap's ray casting: a voxel known free lets the ray through (module docstring).
        p[self.log_odds < -0.2] = 0.0
        extra = None
        if self.formulation == "proximity_count":
            near = ndimage.binary_dilation(occupied, iterations=max(1, round(0.3 / grid.voxel_size)))
            extra = (unknown & near).astype(np.float32)
        scanner = belief.scanner
        directions = sphere_directions(self.ray_step_deg, scanner.elevation_min, scanner.elevation_max)
        reach = min(self.max_range, float(np.linalg.norm(np.asarray(grid.shape) * grid.voxel_size)))
        z = belief.roi.floor_z + scanner.height
        region = workspace(belief)[1] & ~self.dropped_mask(grid)
        self._state = (p, unknown, extra, region, directions, reach)
        out = np.empty(len(valid))
        for n, i in enumerate(valid):
            sensor = np.array([*belief.candidates_xy[i], z])
            out[n] = self._gain(p, unknown, extra, grid, sensor, directions, reach, scanner.min_range, region)
        return out

    def _gain(self, p, unknown, extra, grid, sensor, directions, reach, min_range, region=None) -> float:
        flat, first, inside, distance = march(grid.shape, grid.origin, grid.voxel_size, sensor, directions, reach)
        # Outside the room's grid: unknown free space, p = 0.5; a voxel counts once per ray.
        probs = np.where(inside, p.reshape(-1)[flat], 0.5)
        unk = np.where(inside, unknown.reshape(-1)[flat], True)
        visible = _visibility(np.where(first, probs, 0.0))
        counted = first & inside & (distance[None, :] >= min_range)
        if region is not None:
            counted &= region.reshape(-1)[flat]
        return float((visible * self._weight(probs, unk, counted, inside, flat, extra)).sum())

    def expect(self, belief: BeliefView, index: int):
        """The unknown workspace voxels the chosen view reaches with P(visible) >= 0.5 within the
        dense range (:meth:`~policies.baselines._maps.MappingPolicy.dense_range`), on the maps of
        the last :meth:`utilities`.

        Parameters
        ----------
        belief, index
            As :meth:`MappingPolicy.expect` (the maps are those the last :meth:`utilities` read).

        Returns
        -------
        tuple of ((n, 3) float, None)
            The voxels' world centres, and no memo: :meth:`still_unseen` reads the log-odds.
        """
        grid, scanner = belief.grid, belief.scanner
        p, unknown, _, region, directions, reach = self._state
        sensor = np.array([*belief.candidates_xy[index], belief.roi.floor_z + scanner.height])
        reach = min(reach, self.dense_range(belief))
        flat, first, inside, distance = march(grid.shape, grid.origin, grid.voxel_size, sensor, directions, reach)
        probs = np.where(inside, p.reshape(-1)[flat], 0.5)
        visible = _visibility(np.where(first, probs, 0.0))
        hit = first & inside & (distance[None, :] >= scanner.min_range) & (visible >= 0.5)
        hit &= np.where(inside, (unknown & region).reshape(-1)[flat], False)
        voxels = np.unique(flat[hit])
        return grid.centres(np.column_stack(np.unravel_index(voxels, grid.shape))), None

    def still_unseen(self, belief: BeliefView, points: np.ndarray, memo) -> np.ndarray:
        """Which of :meth:`expect`'s voxels the scans since have left unknown.

        Parameters
        ----------
        belief
            Read for its grid only: the log-odds are the policy's own.
        points, memo
            As :meth:`MappingPolicy.still_unseen` (the voxels' world centres, and None, not read).

        Returns
        -------
        (n,) bool
            True for a voxel whose log-odds stay within ±0.2 (still unknown); False outside the grid.
        """
        idx = belief.grid.index_of(points)
        ok = belief.grid.inside(idx)
        out = np.zeros(len(points), dtype=bool)
        out[ok] = np.abs(self.log_odds[tuple(idx[ok].T)]) < 0.2
        return out

    def _weight(self, probs, unk, counted, inside, flat, extra) -> np.ndarray:
        """(r, s) what each ray sample is worth when the ray reaches it, by the formulation."""
        f = self.formulation
        if f == "occlusion_aware":
            return _entropy(probs) * counted
        if f == "unobserved_voxel":
            return (unk & counted).astype(np.float32)
        if f in ("rear_side_voxel", "rear_side_entropy"):
            behind = np.zeros_like(unk)
            behind[:, 1:] = probs[:, :-1] > 0.5
            weight = (unk & counted & behind).astype(np.float32)
            return weight * _entropy(probs) if f == "rear_side_entropy" else weight
        return np.where(inside, extra.reshape(-1)[flat], 0.0) * counted  # proximity_count


def _visibility(blocking: np.ndarray) -> np.ndarray:
    """(r, s): P(the ray reaches sample s) = Π (1 − p) over the samples before it."""
    through = np.cumprod(1.0 - blocking, axis=1)
    return np.concatenate([np.ones((len(through), 1), dtype=through.dtype), through[:, :-1]], axis=1)


class PotthastSukhatmePolicy(InformationGainPolicy):
    """Potthast & Sukhatme 2014: visibility-weighted entropy of unknown voxels (module docstring).

    Parameters
    ----------
    ray_step_deg, max_range
        As for :class:`InformationGainPolicy`, whose ``occlusion_aware`` rays this method casts.
    stop_below : float, optional
        ε of the stopping rule, in nats per √m² of the RoI's floor. None (the default):
        ``STOP_BELOW["potthast_sukhatme"]``.
    controlled : bool
        As for :class:`MappingPolicy`, which also says what ε = 0 means.

    Raises
    ------
    ValueError
        ``stop_below`` negative or not finite.
    """

    name = "potthast_sukhatme"
    stop_area_power = 0.5

    def __init__(
        self,
        ray_step_deg: float = 5.0,
        max_range: float = 12.0,
        stop_below: float | None = None,
        controlled: bool = False,
    ) -> None:
        super().__init__("occlusion_aware", ray_step_deg, max_range, stop_below, controlled)

    def _weight(self, probs, unk, counted, inside, flat, extra) -> np.ndarray:
        # The entropy of the unknown voxels only.
        return _entropy(probs) * (counted & unk)
