"""The vertical faces of the RoI prism, and points expressed in a face's own frame."""

from __future__ import annotations

from collections.abc import Sequence
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
        p0, d = np.asarray(self.p0, dtype=float), self.direction
        # Element-wise products and sums, not a matrix product (whose BLAS kernel may fuse them):
        # the compiled kernels below compute the same numbers.
        rx, ry = points[:, 0] - p0[0], points[:, 1] - p0[1]
        return np.column_stack([rx * d[0] + ry * d[1], points[:, 2] - self.z0, rx * -d[1] + ry * d[0]])

    def params(self) -> np.ndarray:
        """(7,) float: p0 (x, y), the unit direction (x, y), z0, length and height: what the
        compiled kernels read of a face."""
        p0, d = np.asarray(self.p0, dtype=float), self.direction
        return np.array([p0[0], p0[1], d[0], d[1], self.z0, self.length, self.height])


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


@numba.njit(cache=True, nogil=True)
def _face_points(
    points: np.ndarray,
    order: np.ndarray,
    keys: np.ndarray,
    corner: np.ndarray,
    shape: np.ndarray,
    cell: float,
    faces: np.ndarray,
    ends: np.ndarray,
    f: int,
    margin: float,
    found: np.ndarray,
    frame: np.ndarray,
) -> int:
    """The points of face ``f``'s xy bounding box grown by ``margin``, read from the cells of a
    :class:`PointIndex` (``order``, ``keys``, ``corner``, ``shape``, ``cell``): their indices into
    ``found`` and their face-frame (u, w, v) into ``frame``, in the index's order. Returns how many.
    ``faces`` (m, 7) are :meth:`WallFace.params`, ``ends`` (m, 4) the faces' xy bounding boxes
    (lo x, lo y, hi x, hi y)."""
    px, py, dx, dy, z0 = faces[f, 0], faces[f, 1], faces[f, 2], faces[f, 3], faces[f, 4]
    lo_x, lo_y = ends[f, 0] - margin, ends[f, 1] - margin
    hi_x, hi_y = ends[f, 2] + margin, ends[f, 3] + margin
    c0x = max(np.int64(np.floor((lo_x - corner[0]) / cell)), 0)
    c0y = max(np.int64(np.floor((lo_y - corner[1]) / cell)), 0)
    c1x = min(np.int64(np.floor((hi_x - corner[0]) / cell)), shape[0] - 1)
    c1y = min(np.int64(np.floor((hi_y - corner[1]) / cell)), shape[1] - 1)
    count = 0
    if c1x < c0x or c1y < c0y:
        return 0
    for cx in range(c0x, c1x + 1):
        start = np.searchsorted(keys, cx * shape[1] + c0y)
        stop = np.searchsorted(keys, cx * shape[1] + c1y, side="right")
        for k in range(start, stop):
            i = order[k]
            x, y = points[i, 0], points[i, 1]
            if not (x >= lo_x and x <= hi_x and y >= lo_y and y <= hi_y):
                continue
            rx, ry = x - px, y - py
            found[count] = i
            frame[count, 0] = rx * dx + ry * dy
            frame[count, 1] = rx * -dy + ry * dx
            frame[count, 2] = points[i, 2] - z0
            count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _mark_near_faces(
    points: np.ndarray,
    order: np.ndarray,
    keys: np.ndarray,
    corner: np.ndarray,
    shape: np.ndarray,
    cell: float,
    faces: np.ndarray,
    ends: np.ndarray,
    distance: float,
    out: np.ndarray,
) -> None:
    """Set ``out[i]`` for the points within ``distance`` of one of the ``faces``' rectangles.

    A point counts when its xy lies in the face's bounding box grown by 1.5 ``distance`` (the cells
    of a :class:`PointIndex` of ``points``: ``order``, ``keys``, ``corner``, ``shape``, ``cell``)
    and, in the face frame, ``|w| <= distance``, ``-distance <= u <= length + distance`` and
    ``-distance <= v <= height + distance``. ``faces`` (m, 7) are :meth:`WallFace.params`,
    ``ends`` (m, 4) the faces' xy bounding boxes (lo x, lo y, hi x, hi y).
    """
    found = np.empty(len(points), dtype=np.int64)
    frame = np.empty((len(points), 3))
    for f in range(len(faces)):
        length, height = faces[f, 5], faces[f, 6]
        n = _face_points(points, order, keys, corner, shape, cell, faces, ends, f, 1.5 * distance, found, frame)
        for q in range(n):
            u, w, v = frame[q, 0], frame[q, 1], frame[q, 2]
            if (
                abs(w) <= distance
                and u >= -distance
                and u <= length + distance
                and v >= -distance
                and v <= height + distance
            ):
                out[found[q]] = True


@numba.njit(cache=True, nogil=True)
def _fill_face_images(
    points: np.ndarray,
    order: np.ndarray,
    keys: np.ndarray,
    corner: np.ndarray,
    shape: np.ndarray,
    cell: float,
    faces: np.ndarray,
    ends: np.ndarray,
    band: float,
    pixel: float,
    dims: np.ndarray,
    offsets: np.ndarray,
    out: np.ndarray,
) -> None:
    """The faces' binary images (:func:`nbs_env.perception.structure.face_image`), each written
    row-major into ``out`` from ``offsets[f]`` with ``dims[f]`` = (rows, cols): a pixel is set when
    a point of the face's bounding box grown by ``band`` (the cells of a :class:`PointIndex`) lies
    within ``band`` of the plane and on the face, ``0 <= u <= length``, ``0 <= v <= height``.
    ``faces`` (m, 7) are :meth:`WallFace.params`, ``ends`` (m, 4) the faces' xy bounding boxes."""
    found = np.empty(len(points), dtype=np.int64)
    frame = np.empty((len(points), 3))
    for f in range(len(faces)):
        length, height = faces[f, 5], faces[f, 6]
        rows, cols = dims[f, 0], dims[f, 1]
        n = _face_points(points, order, keys, corner, shape, cell, faces, ends, f, band, found, frame)
        for q in range(n):
            u, w, v = frame[q, 0], frame[q, 1], frame[q, 2]
            if abs(w) <= band and u >= 0 and u <= length and v >= 0 and v <= height:
                col = min(np.int64(u / pixel), cols - 1)
                row = min(np.int64(v / pixel), rows - 1)
                out[offsets[f] + row * cols + col] = True


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

    def mark_near(self, faces: Sequence[WallFace], distance: float, out: np.ndarray) -> None:
        """Set ``out`` (n,) bool where a point lies within ``distance`` of one of ``faces``'
        rectangles (see :func:`_mark_near_faces`); one compiled pass over the faces' cells."""
        if not len(self.points) or not len(faces):
            return
        params = np.array([f.params() for f in faces])
        ends = np.array([[*np.minimum(f.p0, f.p1), *np.maximum(f.p0, f.p1)] for f in faces], dtype=float)
        _mark_near_faces(
            self.points, self._order, self._keys, self._min, self._shape, self.cell, params, ends, float(distance), out
        )

    def face_images(self, faces: Sequence[WallFace], band: float, pixel: float, dims: np.ndarray) -> list[np.ndarray]:
        """The (rows, cols) bool images of ``faces`` (``dims`` (m, 2) int) from the indexed points,
        in one compiled pass (see :func:`_fill_face_images`)."""
        dims = np.asarray(dims, dtype=np.int64).reshape(-1, 2)
        sizes = dims[:, 0] * dims[:, 1]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        out = np.zeros(int(offsets[-1]), dtype=bool)
        if len(self.points) and len(faces):
            params = np.array([f.params() for f in faces])
            ends = np.array([[*np.minimum(f.p0, f.p1), *np.maximum(f.p0, f.p1)] for f in faces], dtype=float)
            _fill_face_images(
                self.points,
                self._order,
                self._keys,
                self._min,
                self._shape,
                self.cell,
                params,
                ends,
                float(band),
                float(pixel),
                dims,
                offsets[:-1],
                out,
            )
        return [out[a:b].reshape(int(r), int(c)) for a, b, (r, c) in zip(offsets[:-1], offsets[1:], dims, strict=True)]

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
