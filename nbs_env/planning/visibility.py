"""The greedy NBS gain (paper §4, METHOD §7): predicted Occluded-structure→Structure conversions.

For each next valid position, the scanner is placed there and the OCCLUDED_STRUCTURE voxels it
would see are counted: a voxel counts when it lies inside the field of view and the range limits,
and the line of sight to its centre meets no occupied voxel on the way. Lines of sight are traversed
voxel by voxel through V(t) (Amanatides & Woo), skipping 4³ cells that hold no blocking voxel, in a
compiled kernel; only V(t) is used, never the scene.
"""

from __future__ import annotations

import numba
import numpy as np

from nbs_env import threads
from nbs_env.config import GainConfig, ScannerConfig
from nbs_env.labels import VoxelLabel

__all__ = ["COARSE", "GainConfig", "VisibilityModel", "coarse_blocking"]


#: Edge of the coarse cells of the traversal, in voxels: a line of sight crosses a coarse cell that
#: holds no blocking voxel in one step (see :func:`_clear`).
COARSE = 4
# The labels as plain integers, for the compiled pass (numba reads module globals as constants).
_CLUTTER, _STRUCTURE = int(VoxelLabel.CLUTTER), int(VoxelLabel.STRUCTURE)
_OCCLUDED_CLUTTER, _OCCLUDED_STRUCTURE = int(VoxelLabel.OCCLUDED_CLUTTER), int(VoxelLabel.OCCLUDED_STRUCTURE)


def coarse_blocking(blocking: np.ndarray, block: int = COARSE) -> np.ndarray:
    """Which ``block``³ cells of the grid hold a blocking voxel.

    Parameters
    ----------
    blocking : (nx, ny, nz) bool

    Returns
    -------
    (ceil(nx / block), ceil(ny / block), ceil(nz / block)) bool
    """
    return _coarse(np.ascontiguousarray(blocking, dtype=np.bool_), int(block))


@numba.njit(cache=True, nogil=True)
def _coarse(blocking: np.ndarray, block: int) -> np.ndarray:
    nx, ny, nz = blocking.shape
    out = np.zeros((-(-nx // block), -(-ny // block), -(-nz // block)), dtype=np.bool_)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if blocking[i, j, k]:
                    out[i // block, j // block, k // block] = True
    return out


@numba.njit(cache=True, nogil=True)
def _read_labels(labels: np.ndarray, clutter_blocks: bool, block: int):
    """One pass over V(t)'s labels: which voxels block a line of sight (occupied, and Occluded-
    clutter when ``clutter_blocks``), the ``block``³ cells holding one (:func:`coarse_blocking`),
    and the (n, 3) indices of the Occluded-structure voxels in C order (``np.argwhere``'s)."""
    nx, ny, nz = labels.shape
    blocking = np.zeros((nx, ny, nz), dtype=np.bool_)
    coarse = np.zeros((-(-nx // block), -(-ny // block), -(-nz // block)), dtype=np.bool_)
    count = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                label = labels[i, j, k]
                occupied = (label == _CLUTTER) | (label == _STRUCTURE)
                if occupied or (clutter_blocks and label == _OCCLUDED_CLUTTER):
                    blocking[i, j, k] = True
                    coarse[i // block, j // block, k // block] = True
                elif label == _OCCLUDED_STRUCTURE:
                    count += 1
    targets = np.empty((count, 3), dtype=np.int64)
    n = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if labels[i, j, k] == _OCCLUDED_STRUCTURE:
                    targets[n, 0], targets[n, 1], targets[n, 2] = i, j, k
                    n += 1
    return blocking, coarse, targets


@numba.njit(cache=True, nogil=True, inline="always")
def _start(p: float, d: float, t: float, lo: int, hi: int) -> tuple[int, int, float, float]:
    """One axis of a traversal starting at ``t``: the cell (clamped to [lo, hi)), its step, the ``t``
    of the next cell boundary and the ``t`` between boundaries (Amanatides & Woo)."""
    x = p + t * d
    c = min(max(int(np.floor(x)), lo), hi - 1)
    if d > 0.0:
        return c, 1, t + (c + 1 - x) / d, 1.0 / d
    if d < 0.0:
        return c, -1, t + (c - x) / d, -1.0 / d
    return c, 0, np.inf, np.inf


@numba.njit(cache=True, nogil=True)
def _clear(
    blocking: np.ndarray,
    coarse: np.ndarray,
    p0: float,
    p1: float,
    p2: float,
    d0: float,
    d1: float,
    d2: float,
    limit: float,
    block: int,
) -> bool:
    """Whether the ray from (p0, p1, p2) along the unit (d0, d1, d2), all in voxel units, enters no
    blocking voxel before ``limit``.

    A traversal of the coarse cells; inside a cell that holds a blocking voxel, a traversal of its
    voxels. Outside the grid nothing blocks. Where the ray passes exactly through an edge or a
    corner, the traversal enters one of the voxels that meet there, so a line never slips between
    two diagonal neighbours.
    """
    nx, ny, nz = blocking.shape
    t_in, t_out = 0.0, np.inf
    for p, d, n in ((p0, d0, nx), (p1, d1, ny), (p2, d2, nz)):
        if d != 0.0:
            ta, tb = (0.0 - p) / d, (n - p) / d
            t_in = max(t_in, min(ta, tb))
            t_out = min(t_out, max(ta, tb))
        elif p < 0.0 or p >= n:
            return True
    end = min(t_out, limit)
    if t_in >= end:
        return True
    cx, cy, cz = coarse.shape
    i, si, ti, di = _start(p0 / block, d0, t_in / block, 0, cx)
    j, sj, tj, dj = _start(p1 / block, d1, t_in / block, 0, cy)
    k, sk, tk, dk = _start(p2 / block, d2, t_in / block, 0, cz)
    t = t_in
    while True:
        if coarse[i, j, k]:
            x0, y0, z0 = i * block, j * block, k * block
            x1, y1, z1 = min(x0 + block, nx), min(y0 + block, ny), min(z0 + block, nz)
            x, sx, tx, dx = _start(p0, d0, t, x0, x1)
            y, sy, ty, dy = _start(p1, d1, t, y0, y1)
            z, sz, tz, dz = _start(p2, d2, t, z0, z1)
            tf = t
            while True:
                if blocking[x, y, z]:
                    return tf >= limit
                if tx <= ty and tx <= tz:
                    tf, x, tx = tx, x + sx, tx + dx
                    if x < x0 or x >= x1:
                        break
                elif ty <= tz:
                    tf, y, ty = ty, y + sy, ty + dy
                    if y < y0 or y >= y1:
                        break
                else:
                    tf, z, tz = tz, z + sz, tz + dz
                    if z < z0 or z >= z1:
                        break
                if tf >= end:
                    return True
        if ti <= tj and ti <= tk:
            t, i, ti = ti * block, i + si, ti + di
            if i < 0 or i >= cx:
                return True
        elif tj <= tk:
            t, j, tj = tj * block, j + sj, tj + dj
            if j < 0 or j >= cy:
                return True
        else:
            t, k, tk = tk * block, k + sk, tk + dk
            if k < 0 or k >= cz:
                return True
        if t >= end:
            return True


@numba.njit(cache=True, nogil=True)
def _lines_of_sight(
    blocking: np.ndarray,
    coarse: np.ndarray,
    origin: np.ndarray,
    size: float,
    sensors: np.ndarray,
    targets: np.ndarray,
    min_range: float,
    max_range: float,
    sin_lo: float,
    sin_hi: float,
    tolerance: float,
    block: int,
) -> np.ndarray:
    """(c, n) bool: whether each of the (c, 3) sensors sees each of the (n, 3) targets (world
    metres): within the range limits and the elevation band, and the line to the target enters no
    blocking voxel before ``tolerance`` metres short of it."""
    out = np.zeros((len(sensors), len(targets)), dtype=np.bool_)
    for c in range(len(sensors)):
        q0 = (sensors[c, 0] - origin[0]) / size
        q1 = (sensors[c, 1] - origin[1]) / size
        q2 = (sensors[c, 2] - origin[2]) / size
        for n in range(len(targets)):
            r0 = targets[n, 0] - sensors[c, 0]
            r1 = targets[n, 1] - sensors[c, 1]
            r2 = targets[n, 2] - sensors[c, 2]
            d = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if d < min_range or d > max_range or d <= 0.0:
                continue
            sine = r2 / d
            if sine < sin_lo or sine > sin_hi:
                continue
            out[c, n] = _clear(blocking, coarse, q0, q1, q2, r0 / d, r1 / d, r2 / d, (d - tolerance) / size, block)
    return out


class VisibilityModel:
    """Lines of sight through one state of the voxel grid.

    Parameters
    ----------
    labels : (nx, ny, nz) uint8
        VoxelLabel values of V(t).
    origin : (3,) float
        World position of the corner of voxel (0, 0, 0).
    voxel_size : float
    config : GainConfig
    """

    def __init__(self, labels: np.ndarray, origin: np.ndarray, voxel_size: float, config: GainConfig | None = None):
        self.config = config or GainConfig()
        self.origin = np.asarray(origin, dtype=float)
        self.voxel_size = float(voxel_size)
        # One compiled pass for what numpy took five (is_occupied, ==, argwhere, the coarse cells):
        # the same arrays (tests/test_gain.py).
        blocking, coarse, targets = _read_labels(
            np.ascontiguousarray(labels, dtype=np.uint8), bool(self.config.occluded_clutter_blocks), COARSE
        )
        self.targets = self.origin + (targets + 0.5) * self.voxel_size  # (n, 3) world centres
        # Groups of voxels share one line of sight (see GainConfig.group).
        g = max(1, int(self.config.group))
        if len(targets):
            # One integer per group, in the lexicographic order of its (i, j, k) // g: the groups of
            # np.unique(targets // g, axis=0) without its sort of rows.
            cells = targets // g
            span = np.asarray(labels.shape) // g + 1
            key = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
            _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
            # bincount adds each group's members in their order, as np.add.at does, 3x faster.
            sums = np.stack([np.bincount(inverse, self.targets[:, a], len(counts)) for a in range(3)], axis=1)
            self.group_centres = sums / counts[:, None]
            self.group_counts = counts.astype(np.int64)
        else:
            self.group_centres = np.zeros((0, 3))
            self.group_counts = np.zeros(0, dtype=np.int64)
        self.blocking = blocking
        self.coarse = coarse

    def sees(self, sensors: np.ndarray, targets: np.ndarray, scanner: ScannerConfig) -> np.ndarray:
        """(c, n) bool: which of the (n, 3) targets (world metres) each of the (c, 3) sensors sees:
        within the scanner's range and elevation band, with no blocking voxel of V(t) on the line."""
        sensors = np.ascontiguousarray(sensors, dtype=float).reshape(-1, 3)
        targets = np.ascontiguousarray(targets, dtype=float).reshape(-1, 3)
        limits = (
            float(scanner.min_range),
            float(scanner.max_range),
            float(np.sin(np.radians(scanner.elevation_min))),
            float(np.sin(np.radians(scanner.elevation_max))),
            float(self.config.tolerance_voxels * self.voxel_size),
            COARSE,
        )

        def rows(part: slice) -> np.ndarray:
            some = np.ascontiguousarray(sensors[part])
            return _lines_of_sight(self.blocking, self.coarse, self.origin, self.voxel_size, some, targets, *limits)

        # A line of sight costs about as many steps as voxels it crosses: tens per sensor-target pair.
        parts = threads.split(rows, len(sensors), cost=20 * len(sensors) * len(targets))
        if len(parts) == 1:
            return parts[0]
        out = np.empty((len(sensors), len(targets)), dtype=np.bool_)
        for k, part in enumerate(parts):
            out[k :: len(parts)] = part
        return out

    def visible(self, sensor: np.ndarray, scanner: ScannerConfig) -> np.ndarray:
        """(n,) bool: which OCCLUDED_STRUCTURE voxels (:attr:`targets`) a scanner at ``sensor`` (3,)
        would see, one line of sight each (no grouping): for inspecting the model."""
        return self.sees(np.asarray(sensor, dtype=float).reshape(1, 3), self.targets, scanner)[0]

    def gains(self, sensors: np.ndarray, scanner: ScannerConfig) -> np.ndarray:
        """(m,) int: predicted conversions for each of the (m, 3) scanner positions."""
        sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
        if not len(self.targets) or not len(sensors):
            return np.zeros(len(sensors), dtype=np.int64)
        return self.sees(sensors, self.group_centres, scanner).astype(np.int64) @ self.group_counts
