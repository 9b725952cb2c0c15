"""Nearest frontier (Yamauchi 1997), a floor for the comparison.

**Source.** Drive to the nearest frontier, the boundary between known free space and unknown space.

**Adapted here:** frontier voxels are unknown voxels 6-adjacent to Empty ones, inside the room's
RoI prism (the dynamic workspace the compared methods were given), projected to the floor. The next
scan is the candidate that minimises its path length plus its distance to the nearest frontier
column, among candidates within 3 m of one; the room ends when fewer than 1% of the RoI's columns
are frontier. Structure-agnostic. Like the compared methods it reads the planner's view of the room
(``belief.labels``: the blind zone under each stop free) with the rays' semantics of
:func:`~policies.baselines._maps.collapse`; in the controlled mode (``nearest_frontier:controlled``)
the greedy's rule ends rooms and, with no frontier left, the nearest candidate is taken.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy import ndimage
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from nbs_env.observation import BeliefView
from policies.baselines._maps import MappingPolicy, collapse

__all__ = ["NearestFrontierPolicy"]


class NearestFrontierPolicy(MappingPolicy):
    """Go to the nearest frontier (see the module docstring).

    Parameters
    ----------
    reach : float
        Metres: only candidates within this distance of a frontier column are chosen (in the
        controlled mode, any candidate when none is).
    stop_share : float
        The room ends when fewer than this share of the RoI's columns are frontier columns (and
        always when none is).
    controlled : bool
        As for :class:`MappingPolicy` (the frontier rule then never ends a room: see :meth:`act`).
    """

    name = "nearest_frontier"

    def __init__(self, reach: float = 3.0, stop_share: float = 0.01, controlled: bool = False) -> None:
        self.reach = reach
        self.stop_share = stop_share
        super().__init__(controlled=controlled)

    def act(self, obs, info) -> int:
        """The valid candidate within ``reach`` of a frontier column with the least path length plus
        distance to the nearest frontier column, or "room done".

        Parameters
        ----------
        obs, info
            As :meth:`MappingPolicy.act` (the method reads the robot's voxel labels, not ``obs``).

        Returns
        -------
        int
            A candidate slot, or K = ``len(belief.mask)`` ("room done") when too few frontier
            columns are left (``stop_share``), no candidate is within ``reach`` or none is valid. In
            the controlled mode it never declares the room done: with too few frontier columns it
            takes the candidate with the shortest path, with none within ``reach`` it ranks all,
            and with no valid candidate it returns 0.

        Raises
        ------
        KeyError
            ``info`` has no ``"belief"``.
        """
        belief = self._belief(info)
        stop = len(belief.mask)
        valid = np.flatnonzero(belief.mask)
        if not len(valid):
            return 0 if self.controlled else stop
        frontier, columns = self._frontier(belief)
        if len(frontier) < max(1, self.stop_share * columns):
            return int(valid[int(np.argmin(belief.path_length[valid]))]) if self.controlled else stop
        d, _ = cKDTree(frontier).query(belief.candidates_xy[valid])
        ok = d <= self.reach
        if not ok.any():
            ok = np.ones(len(valid), dtype=bool) if self.controlled else ok
            if not ok.any():
                return stop
        cost = np.where(ok, belief.path_length[valid] + d, np.inf)
        return int(valid[int(np.argmin(cost))])

    def _frontier(self, belief: BeliefView) -> tuple[np.ndarray, int]:
        """(f, 2) world xy of the frontier columns inside the RoI, and the RoI's column count."""
        grid, roi = belief.grid, belief.roi
        free, _, unknown = collapse(self.labels_of(belief))
        k0 = max(0, int(np.floor((roi.floor_z + 0.1 - grid.origin[2]) / grid.voxel_size)))
        k1 = min(grid.shape[2], int(np.ceil((roi.ceiling_z - 0.1 - grid.origin[2]) / grid.voxel_size)))
        near_free = ndimage.binary_dilation(free, structure=ndimage.generate_binary_structure(3, 1))
        column = (unknown & near_free)[:, :, k0:k1].any(axis=2)
        i, j = np.indices(column.shape)
        xy = grid.origin[:2] + (np.stack([i, j], -1).reshape(-1, 2) + 0.5) * grid.voxel_size
        inside = shapely.contains_xy(Polygon(roi.polygon).buffer(-0.1), xy[:, 0], xy[:, 1])
        return xy[inside & column.reshape(-1)], int(inside.sum())
