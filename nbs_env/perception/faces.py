"""The vertical faces of the RoI prism, and points expressed in a face's own frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WallFace"]


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
