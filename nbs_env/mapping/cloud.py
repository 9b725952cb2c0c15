"""Working copies of accumulated scans: points (and normals) averaged in world-anchored voxels,
updated scan by scan (the room's copy for perception, S(t)'s for registration)."""

from __future__ import annotations

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
        keys = keys[order]
        starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
        keys = keys[starts]
        sums = np.add.reduceat(values[order], starts, axis=0)
        counts = np.diff(np.append(starts, len(order)))
        at = np.searchsorted(self._keys, keys)
        held = at < len(self._keys)
        held[held] = self._keys[at[held]] == keys[held]
        self._sums[at[held]] += sums[held]
        self._counts[at[held]] += counts[held]
        new = ~held
        if new.any():
            self._keys = np.insert(self._keys, at[new], keys[new])
            self._sums = np.insert(self._sums, at[new], sums[new], axis=0)
            self._counts = np.insert(self._counts, at[new], counts[new])
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
