"""The vertical faces of the RoI prism, and points expressed in a face's own frame."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["PointIndex", "WallFace"]


@dataclass(frozen=True)
class WallFace:
    """A vertical parallelogram of the RoI prism: one polygon edge from floor to ceiling.

    Attributes
    ----------
    p0, p1 : (2,) float
        Ends of the polygon edge in the world xy plane. RoI polygons are counter-clockwise, so
        the room lies to the left of p0 → p1.
    z0, z1 : float
        Floor and ceiling heights of the RoI.
    """

    p0: np.ndarray
    p1: np.ndarray
    z0: float
    z1: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.asarray(self.p1) - np.asarray(self.p0)))

    @property
    def height(self) -> float:
        return float(self.z1 - self.z0)

    @property
    def direction(self) -> np.ndarray:
        """(2,) float: unit vector from p0 to p1."""
        d = np.asarray(self.p1, dtype=float) - np.asarray(self.p0, dtype=float)
        return d / np.linalg.norm(d)

    @property
    def normal(self) -> np.ndarray:
        """(2,) float: horizontal unit normal pointing into the room (left of p0 → p1)."""
        d = self.direction
        return np.array([-d[1], d[0]])

    def corners(self) -> np.ndarray:
        """(4, 3) float: the parallelogram's corners, counter-clockwise seen from outside the room
        (their right-hand normal points out of it)."""
        p0, p1 = np.asarray(self.p0, dtype=float), np.asarray(self.p1, dtype=float)
        return np.array([[*p0, self.z0], [*p1, self.z0], [*p1, self.z1], [*p0, self.z1]])

    def local(self, points: np.ndarray) -> np.ndarray:
        """Points in the face frame.

        Parameters
        ----------
        points : (n, 3) float
            World points.

        Returns
        -------
        (n, 3) float
            Columns u (metres along the edge from p0), v (metres above z0) and w (signed distance
            from the face plane, positive into the room).
        """
        points = np.asarray(points, dtype=float)
        rel = points[:, :2] - np.asarray(self.p0, dtype=float)
        return np.column_stack([rel @ self.direction, points[:, 2] - self.z0, rel @ self.normal])


@numba.njit(cache=True, nogil=True)
def _counting_sort(keys: np.ndarray, count: int) -> np.ndarray:
    """The stable argsort of (n,) integer ``keys`` in [0, count): a counting sort, O(n + count)."""
    starts = np.zeros(count + 1, dtype=np.int64)
    for key in keys:
        starts[key + 1] += 1
    for k in range(count):
        starts[k + 1] += starts[k]
    order = np.empty(len(keys), dtype=np.int64)
    for i in range(len(keys)):
        order[starts[keys[i]]] = i
        starts[keys[i]] += 1
    return order


class PointIndex:
    """Points sorted into square plan cells, to find those in a plan box without a pass over all.

    The door search and the face images look at the points near one face at a time; over a
    room's hundreds of thousands of points a mask per face costs more than the rest of the work.

    Parameters
    ----------
    points : (n, 3) float
        World points (any n, also 0).
    cell : float
        Edge of the plan cells, metres (> 0).
    """

    def __init__(self, points: np.ndarray, cell: float = 0.5) -> None:
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {points.shape}")
        if not (np.isfinite(cell) and cell > 0):
            raise ValueError(f"cell must be a finite number > 0 metres, got {cell!r}")
        self.points = points
        self.cell = float(cell)
        if len(points):
            # Column by column: numpy reduces a strided (n, 2) view along axis 0 several times slower.
            x, y = points[:, 0], points[:, 1]
            self._min = np.array([x.min(), y.min()])
            cx = np.floor((x - self._min[0]) / self.cell).astype(np.int64)
            cy = np.floor((y - self._min[1]) / self.cell).astype(np.int64)
            self._shape = np.array([cx.max() + 1, cy.max() + 1])
            keys = cx * self._shape[1] + cy
            self._order = _counting_sort(keys, int(self._shape[0] * self._shape[1]))
            self._keys = keys[self._order]

    def __len__(self) -> int:
        return len(self.points)

    def _cells(self, xy: np.ndarray) -> np.ndarray:
        # Subtraction and division by a positive number round monotonically, so a point at or
        # beyond a bound is never put in a cell before the bound's.
        return np.floor((xy - self._min) / self.cell).astype(np.int64)

    def within(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Ascending indices of the points whose xy lies in the box [lo, hi] (bounds included):
        ``np.flatnonzero`` of the mask over all points.

        Parameters
        ----------
        lo, hi : (2,) float
        """
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        if not len(self.points):
            return np.zeros(0, dtype=np.intp)
        c0 = np.maximum(self._cells(lo[None])[0], 0)
        c1 = np.minimum(self._cells(hi[None])[0], self._shape - 1)
        if np.any(c1 < c0):
            return np.zeros(0, dtype=np.intp)
        rows = np.arange(c0[0], c1[0] + 1) * self._shape[1]
        starts = np.searchsorted(self._keys, rows + c0[1], side="left")
        ends = np.searchsorted(self._keys, rows + c1[1], side="right")
        idx = np.concatenate([self._order[a:b] for a, b in zip(starts, ends, strict=True)])
        if len(idx) > len(self.points) // 64:  # many: a pass over a mask beats sorting them
            mask = np.zeros(len(self.points), dtype=bool)
            mask[idx] = True
            idx = np.flatnonzero(mask)
        else:
            idx = np.sort(idx)
        x, y = self.points[idx, 0], self.points[idx, 1]
        return idx[(x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])]
