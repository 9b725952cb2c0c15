"""Working copies of accumulated scans: points (and normals) averaged in world-anchored voxels,
updated scan by scan (the room's copy for perception, S(t)'s for registration)."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["VoxelMeans"]

# Cells are packed 21 bits an axis into one int64 key: +-2^20 cells, 52 km at 5 cm.
_BITS = 21
_HALF = 1 << (_BITS - 1)
#: The upper triangle of a 3 x 3 matrix (rows, columns): xx, xy, xz, yy, yz, zz.
_UPPER = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))


class VoxelMeans:
    """Points averaged per voxel of a grid anchored at the world origin.

    Each voxel ``floor(p / voxel_size)`` keeps the sum and the count of the points that fell in it;
    the working copy is one point per voxel, their mean. Adding a scan costs a sort of its points
    and a merge with the voxels held, not a new downsampling of every point of the room, and the
    copy does not depend on the order the scans came in.

    Parameters
    ----------
    voxel_size : float
        Edge of the voxels, metres.
    normals : bool
        Keep the sum of the points' normals per voxel too (then every ``add`` gives normals).
    covariances : bool
        Keep the sum of the points' covariances per voxel too (then every ``add`` gives them, a
        zero matrix for a point without one): a voxel's covariance is then the mean of its points'
        that have one, as in VGICP's voxels (Koide et al., ICRA 2021), which ICP's target reads
        instead of estimating its own at every registration.
    """

    def __init__(self, voxel_size: float, normals: bool = False, covariances: bool = False) -> None:
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be a positive number of metres, got {voxel_size}")
        self.voxel_size = float(voxel_size)
        self.has_normals = bool(normals)
        self.has_covariances = bool(covariances)
        self._keys = np.zeros(0, dtype=np.int64)
        # Columns 0-2 the points' sums, then 3 of their normals' (with ``normals``), then 6 of their
        # covariances' upper triangles (xx, xy, xz, yy, yz, zz) and how many gave one (with
        # ``covariances``).
        self._sums = np.zeros((0, 3 + 3 * self.has_normals + 7 * self.has_covariances))
        self._counts = np.zeros(0, dtype=np.int64)
        self._points: np.ndarray | None = np.zeros((0, 3))

    def __len__(self) -> int:
        """Voxels held (points in the working copy)."""
        return len(self._keys)

    def add(self, points: np.ndarray, normals: np.ndarray | None = None, covariances: np.ndarray | None = None) -> None:
        """Add (n, 3) float world points, with their (n, 3) float unit ``normals`` when the copy
        keeps normals and their (n, 3, 3) float ``covariances`` when it keeps covariances (a zero
        matrix: no estimate for that point).

        Raises
        ------
        ValueError
            The points are not a finite (n, 3) array, lie farther than 2^20 voxels from the origin,
            or normals or covariances are missing, or given to a copy without.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise ValueError(f"points must be a finite (n, 3) array, got shape {points.shape}")
        if (normals is None) == self.has_normals:
            raise ValueError("normals must be given exactly when the copy keeps normals (VoxelMeans(normals=True))")
        if (covariances is None) == self.has_covariances:
            raise ValueError(
                "covariances must be given exactly when the copy keeps them (VoxelMeans(covariances=True))"
            )
        columns = [points]
        if normals is not None:
            normals = np.asarray(normals, dtype=np.float64)
            if normals.shape != points.shape or not np.all(np.isfinite(normals)):
                raise ValueError(f"normals must be a finite array shaped like the points, got {normals.shape}")
            columns.append(normals)
        if covariances is not None:
            covariances = np.asarray(covariances, dtype=np.float64)
            if covariances.shape != (len(points), 3, 3) or not np.all(np.isfinite(covariances)):
                raise ValueError(f"covariances must be a finite (n, 3, 3) array, got {covariances.shape}")
            given = np.any(covariances.reshape(len(points), 9) != 0.0, axis=1)
            columns += [covariances[:, _UPPER[0], _UPPER[1]], given[:, None].astype(np.float64)]
        values = np.hstack(columns) if len(columns) > 1 else points
        if not len(points):
            return
        cells = np.floor(points / self.voxel_size).astype(np.int64)
        if cells.min() < -_HALF or cells.max() >= _HALF:
            raise ValueError(f"points lie farther than {_HALF} voxels of {self.voxel_size} m from the origin")
        cells += _HALF
        keys = (cells[:, 0] << (2 * _BITS)) | (cells[:, 1] << _BITS) | cells[:, 2]
        order = np.argsort(keys, kind="stable")
        self._keys, self._sums, self._counts = _merge(self._keys, self._sums, self._counts, keys, order, values)
        self._points = None

    @property
    def points(self) -> np.ndarray:
        """(m, 3) float: one point per voxel, the mean of its points, in the order of the voxels' keys."""
        if self._points is None:
            self._points = self._sums[:, :3] / self._counts[:, None]
            self._points.flags.writeable = False
        return self._points

    @property
    def normal_sums(self) -> np.ndarray:
        """(m, 3) float: per voxel, the sum of its points' normals (the copy keeps normals)."""
        if not self.has_normals:
            raise ValueError("this copy keeps no normals (VoxelMeans(normals=True))")
        return self._sums[:, 3:6]

    def covariances(self, subset: np.ndarray | None = None) -> np.ndarray:
        """(m, 3, 3) float: per voxel (of ``subset``, indices, when given), the mean of its points'
        covariances; zero where none of its points came with one (the copy keeps covariances)."""
        if not self.has_covariances:
            raise ValueError("this copy keeps no covariances (VoxelMeans(covariances=True))")
        sums = self._sums[:, -7:]
        if subset is not None:
            sums = sums[subset]
        upper = sums[:, :6] / np.maximum(sums[:, 6:], 1.0)
        out = np.empty((len(upper), 3, 3))
        out[:, _UPPER[0], _UPPER[1]] = upper
        out[:, _UPPER[1], _UPPER[0]] = upper
        return out

    @property
    def counts(self) -> np.ndarray:
        """(m,) int: points per voxel."""
        return self._counts

    def copy(self) -> VoxelMeans:
        """An independent copy."""
        out = VoxelMeans(self.voxel_size, self.has_normals, self.has_covariances)
        out._keys, out._sums, out._counts = self._keys.copy(), self._sums.copy(), self._counts.copy()
        out._points = None
        return out


@numba.njit(cache=True, nogil=True)
def _pairwise(values: np.ndarray, order: np.ndarray, first: int, n: int, column: int) -> float:
    """numpy's pairwise sum (``pairwise_sum`` in its loops, the one ``np.add.reduceat`` runs) of
    ``values[order[first:first + n], column]``: the same result, bit for bit."""
    if n < 8:
        res = -0.0  # numpy's start: -0.0 + x is x for every x, -0.0 included
        for i in range(n):
            res += values[order[first + i], column]
        return res
    if n <= 128:
        r = np.empty(8)
        for j in range(8):
            r[j] = values[order[first + j], column]
        i = 8
        while i < n - (n % 8):
            for j in range(8):
                r[j] += values[order[first + i + j], column]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += values[order[first + i], column]
            i += 1
        return res
    half = n // 2
    half -= half % 8
    return _pairwise(values, order, first, half, column) + _pairwise(values, order, first + half, n - half, column)


@numba.njit(cache=True, nogil=True)
def _merge(held_keys, held_sums, held_counts, keys, order, values):
    """The voxels held merged with a scan's points (``keys`` per point, ``order`` sorting them):
    new (keys, sums, counts), sorted by key. A voxel's sum of the scan's points is its first point
    plus numpy's pairwise sum of the rest, as ``np.add.reduceat`` gives it, added to the sum held."""
    n, m, width = len(order), len(held_keys), values.shape[1]
    # The scan's voxels: the first point of each run of equal keys.
    runs = np.empty(n + 1, dtype=np.int64)
    count = 0
    for i in range(n):
        if i == 0 or keys[order[i]] != keys[order[i - 1]]:
            runs[count] = i
            count += 1
    runs[count] = n
    # How many of them are new.
    fresh = 0
    at = 0
    for r in range(count):
        key = keys[order[runs[r]]]
        while at < m and held_keys[at] < key:
            at += 1
        if at == m or held_keys[at] != key:
            fresh += 1
    out_keys = np.empty(m + fresh, dtype=np.int64)
    out_sums = np.empty((m + fresh, width))
    out_counts = np.empty(m + fresh, dtype=np.int64)
    at = 0
    k = 0
    for r in range(count):
        first, size = runs[r], runs[r + 1] - runs[r]
        key = keys[order[first]]
        while at < m and held_keys[at] < key:
            out_keys[k] = held_keys[at]
            out_sums[k] = held_sums[at]
            out_counts[k] = held_counts[at]
            at += 1
            k += 1
        held = at < m and held_keys[at] == key
        for c in range(width):
            total = values[order[first], c]
            if size > 1:
                total += _pairwise(values, order, first + 1, size - 1, c)
            out_sums[k, c] = held_sums[at, c] + total if held else total
        out_keys[k] = key
        out_counts[k] = (held_counts[at] if held else 0) + size
        if held:
            at += 1
        k += 1
    while at < m:
        out_keys[k] = held_keys[at]
        out_sums[k] = held_sums[at]
        out_counts[k] = held_counts[at]
        at += 1
        k += 1
    return out_keys, out_sums, out_counts
