"""Registration of a new scan into the accumulated cloud S(t): ICP from the odometry pose.

S(t) itself is :class:`nbs_env.mapping.cloud.AccumulatedCloud`. Registration reads it through
:class:`TargetCloud`, the few members it needs, so that sensing imports nothing of mapping; what
the cloud shares with registration (a scan's downsampled copy with its normals, :class:`_ScanCopy`;
open3d's copy of a point set, :func:`_cloud`) lives here, and the cloud imports it.

The default ICP is GICP (:mod:`nbs_env.sensing.gicp`, compiled, one thread, small_gicp's k-d trees),
coarse to fine: the coarse stages align coarser copies of the scan (30 and 20 cm), the finest the
10 cm copy, against the target's 10 cm copy with the covariances S(t) keeps: each scan's own, where
the scan was dense enough to estimate one, averaged per voxel; only the voxels no scan saw densely
get theirs from the target's own neighbours at the registration. It is restarted from the walls'
heading when that disagrees with ICP's. A pose is judged by how much of the scan's overlap with
S(t) lies on S(t)'s planes and by how much of S(t) it would have had to see through; a refused scan
stays out of later targets.
``benchmarks/registration.py`` measures it against open3d's ICP on the same scans (figures in
``benchmarks/README.md``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numba
import numpy as np

from nbs_env import threads
from nbs_env.config import RegistrationConfig
from nbs_env.sensing import gicp
from nbs_env.sensing.pose import check_pose, pose_error, yaw_of
from scenes._open3d import open3d

__all__ = ["RegistrationResult", "TargetCloud", "level_from_floor", "register"]


def _cloud(points: np.ndarray, normals: np.ndarray | None = None):
    o3d = open3d()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    return pc


@contextlib.contextmanager
def _open3d_threads(n: int | None) -> Iterator[None]:
    """Run open3d with ``n`` threads (None: leave as is), restoring the previous count afterwards."""
    if n is None:
        yield
        return
    utility = open3d().utility
    previous = utility.get_max_threads()
    utility.set_max_threads(n)
    try:
        yield
    finally:
        utility.set_max_threads(previous)


#: Nearest points a normal reads at most, and the fewest within ``normal_radius`` for a trusted one.
_NORMAL_NEIGHBOURS = 20
_MIN_NORMAL_NEIGHBOURS = 6


def _plane_normals(
    points: np.ndarray, idx: np.ndarray, sq: np.ndarray, radius2: float, reach2: float, least: int
) -> np.ndarray:
    """Per point, the normal of the plane through its nearest points (``idx``, ``sq``: their indices
    and squared distances, ascending, -1 past the last): those within ``radius2``, or within
    ``reach2`` when fewer than ``least`` lie within ``radius2``. Zero with fewer than three."""
    out = np.zeros((idx.shape[0], 3))

    def rows(part: slice) -> None:
        # Each point's normal is its own: the runs write disjoint rows.
        _plane_normal_rows(points, idx[part], sq[part], radius2, reach2, least, out[part])

    threads.split(rows, len(idx), cost=20 * idx.shape[1] * len(idx), interleave=False)
    return out


@numba.njit(cache=True, nogil=True)
def _plane_normal_rows(
    points: np.ndarray, idx: np.ndarray, sq: np.ndarray, radius2: float, reach2: float, least: int, out: np.ndarray
) -> None:
    n, k = idx.shape
    A = np.empty((3, 3))
    V = np.empty((3, 3))
    for i in range(n):
        near = 0
        while near < k and idx[i, near] >= 0 and sq[i, near] <= radius2:
            near += 1
        limit = radius2 if near >= least else reach2
        count = 0
        sx = sy = sz = 0.0
        while count < k and idx[i, count] >= 0 and sq[i, count] <= limit:
            p = points[idx[i, count]]
            sx += p[0]
            sy += p[1]
            sz += p[2]
            count += 1
        if count < 3:
            continue
        mx, my, mz = sx / count, sy / count, sz / count
        xx = xy = xz = yy = yz = zz = 0.0
        for j in range(count):
            p = points[idx[i, j]]
            dx, dy, dz = p[0] - mx, p[1] - my, p[2] - mz
            xx += dx * dx
            xy += dx * dy
            xz += dx * dz
            yy += dy * dy
            yz += dy * dz
            zz += dz * dz
        A[0, 0], A[0, 1], A[0, 2] = xx, xy, xz
        A[1, 0], A[1, 1], A[1, 2] = xy, yy, yz
        A[2, 0], A[2, 1], A[2, 2] = xz, yz, zz
        a, b, c = gicp.smallest_eigenvector(A, V)
        norm = np.sqrt(a * a + b * b + c * c)
        out[i, 0], out[i, 1], out[i, 2] = a / norm, b / norm, c / norm


class _ScanCopy:
    """One scan downsampled in the frame it is given in (small_gicp's voxel means), with unit
    normals turned towards ``origin`` and, for GICP, covariances from each point's ``neighbours``
    nearest; and the pose that places it once known.

    A normal is the plane through the point's nearest points (at most 20) within ``normal_radius``,
    estimated in the scan itself, so that a surface's normal never mixes in another scan's copy of
    it. Far returns are sparser than the radius (9 cm apart at 10 m, 26 cm at 30 m with the 0.5°
    pattern): a point with fewer than six points within it reads those within ``normal_reach``
    instead. (Normals from the k nearest points alone reach across a corner into the next surface
    where a scan is sparse: 15 m down a corridor from the scanner they turned the facing test and
    the plane agreement against a correct pose; ``tests/test_registration.py``.)
    """

    def __init__(
        self,
        points: np.ndarray,
        voxel: float,
        neighbours: int,
        origin: np.ndarray | None = None,
        normal_radius: float | None = 0.15,
        normal_reach: float | None = 0.6,
        covariances: bool = True,
    ) -> None:
        small_gicp = _small_gicp()
        points = np.asarray(points, dtype=np.float64)
        self.size = len(points)
        # One thread: small_gicp's threaded voxel grid does not merge voxels across its chunks.
        self.sg = small_gicp.voxelgrid_sampling(points, voxel, num_threads=1) if len(points) else None
        self.points = np.asarray(self.sg.points())[:, :3].copy() if self.sg is not None else np.zeros((0, 3))
        self.normals = np.zeros_like(self.points)
        #: (n, 3, 3) float GICP covariances (:func:`~nbs_env.sensing.gicp.covariances_from_neighbours`),
        #: or None when not asked for.
        self.covariances: np.ndarray | None = None
        self.pose: np.ndarray | None = None
        #: (n,) bool: points whose covariance S(t) keeps (dense enough for a local estimate).
        self.dense = np.zeros(len(self.points), dtype=bool)
        if covariances:
            self.covariances = np.tile(np.eye(3), (len(self.points), 1, 1))
        if len(self.points) < 5 or (normal_radius is None and not covariances):
            return
        workers = threads.cores()
        tree = small_gicp.KdTree(self.sg, num_threads=workers)
        # One search serves the covariances and the normals.
        idx, sq = tree.batch_knn_search(self.points, max(neighbours, _NORMAL_NEIGHBOURS), num_threads=workers)
        idx, sq = np.asarray(idx).astype(np.int64), np.asarray(sq)
        if covariances:
            self.covariances = gicp.covariances_from_neighbours(self.points, idx, neighbours)
            # Where the scan is sparse (fewer than six points within the normals' radius: far
            # returns, grazing surfaces) its 20 nearest reach across corners and along scan rings,
            # and its estimate is the scan's, not the surface's; S(t) keeps none for such points.
            radius = normal_radius if normal_radius is not None else 0.15
            self.dense = np.count_nonzero(sq[:, :_NORMAL_NEIGHBOURS] <= radius**2, axis=1) >= _MIN_NORMAL_NEIGHBOURS
        if normal_radius is not None:
            reach = max(normal_radius, normal_reach or normal_radius)
            normals = _plane_normals(
                self.points,
                np.ascontiguousarray(idx[:, :_NORMAL_NEIGHBOURS]),
                np.ascontiguousarray(sq[:, :_NORMAL_NEIGHBOURS]),
                normal_radius**2,
                reach**2,
                _MIN_NORMAL_NEIGHBOURS,
            )
            towards = (np.zeros(3) if origin is None else np.asarray(origin, dtype=float)) - self.points
            self.normals = np.where((np.einsum("ij,ij->i", normals, towards) < 0)[:, None], -normals, normals)

    def world(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(points, normals, covariances or None), (n, 3), (n, 3) and (n, 3, 3) float, placed with
        :attr:`pose` (identity when None); the covariances S(t) keeps, zero where the scan was
        sparse (:attr:`dense`)."""
        covariances = None
        if self.covariances is not None:
            covariances = np.where(self.dense[:, None, None], self.covariances, 0.0)
        if self.pose is None:
            return self.points, self.normals, covariances
        R, t = self.pose[:3, :3], self.pose[:3, 3]
        if covariances is not None:
            covariances = np.matmul(np.matmul(R, covariances), R.T)
        return self.points @ R.T + t, self.normals @ R.T, covariances


class _WorkingCopy(Protocol):
    """A working copy of S(t) as :func:`_select_target` reads it: points averaged per voxel, with the
    sums of their normals and their mean covariances (:class:`nbs_env.mapping.cloud.VoxelMeans` is one).

    Attributes
    ----------
    has_normals, has_covariances : bool
        Whether the copy keeps normals, and covariances.
    points : (m, 3) float
        One point per voxel.
    normal_sums : (m, 3) float
        Per voxel, the sum of its points' unit normals (with ``has_normals``).
    counts : (m,) int
        Points per voxel.
    """

    has_normals: bool
    has_covariances: bool

    def __len__(self) -> int: ...

    @property
    def points(self) -> np.ndarray: ...

    @property
    def normal_sums(self) -> np.ndarray: ...

    @property
    def counts(self) -> np.ndarray: ...

    def covariances(self, subset: np.ndarray | None = None) -> np.ndarray:
        """(m, 3, 3) float: per voxel of ``subset`` (indices), its mean covariance (with ``has_covariances``)."""
        ...


class TargetCloud(Protocol):
    """S(t) as :func:`register` reads and writes it: the members registration uses and no more, so
    that sensing needs nothing of mapping (:class:`nbs_env.mapping.cloud.AccumulatedCloud` is the one
    implementation).

    Attributes
    ----------
    voxel_size : float
        Voxel size of the cloud's working copies, metres: when it is the registration's, the scan's
        downsampled copy is made by :meth:`_scan_copy` and left in :attr:`_prepared`.
    _prepared : _ScanCopy or None
        Written: the downsampled copy of the scan the last registration aligned (sensor frame), for
        the cloud's next ``add`` with ``pose=`` to merge instead of downsampling the scan again;
        None when the registration's voxels are not the cloud's.
    _verdict : bool or None
        Written: whether the last registration was accepted, for the cloud's next ``add`` (a
        refused scan stays out of ICP's target).
    """

    voxel_size: float
    _prepared: _ScanCopy | None
    _verdict: bool | None

    def _scan_copy(self, points: np.ndarray, *, neighbours: int = 20) -> _ScanCopy:
        """The scan's downsampled copy with the cloud's normals and GICP's covariances from each
        point's ``neighbours`` nearest."""
        ...

    def _copy(self, key: str | None) -> _WorkingCopy | None:
        """ICP's target (``"target"``: the accepted scans' working copy) or the storey's (None),
        with every scan added so far merged in; None while the cloud is empty."""
        ...


@dataclass(frozen=True)
class RegistrationResult:
    """The outcome of registering one scan.

    Attributes
    ----------
    pose : (4, 4) float
        The pose to use: ICP's when accepted, the odometry pose when rejected.
    initial : (4, 4) float
        The odometry pose ICP started from.
    fitness : float
        Share of source points with a correspondence at the finest stage.
    rmse : float
        Inlier RMSE at the finest stage, metres.
    accepted : bool
        Whether ICP's pose was accepted.
    reason : str
        Why it was rejected (empty when accepted).
    correction_m, correction_deg : float
        How far ICP moved the pose away from the odometry pose.
    seconds : float
        Time spent.
    overlap : float
        Share of source points within the coarsest correspondence distance of S(t) (the part of
        the scan S(t) can explain; the rest is new surface).
    inliers : int
        Source points with a correspondence at the finest stage.
    weak_directions : int
        Directions of the pose (eigenvectors of the point-to-plane information) that the matches
        constrained too little, kept at the odometry pose.
    agreement : float
        Share of the overlap (source points within ``overlap_distance`` of S(t)) that lies within
        ``plane_tolerance`` of S(t)'s local plane at the final pose.
    see_through : float
        Share of the points of S(t) in the scan's view that lie in front of everything the scan
        measured in their direction, at the final pose (:class:`_RangeImage`).
    """

    pose: np.ndarray
    initial: np.ndarray
    fitness: float
    rmse: float
    accepted: bool
    reason: str
    correction_m: float
    correction_deg: float
    seconds: float
    overlap: float = 1.0
    inliers: int = 0
    weak_directions: int = 0
    agreement: float = 1.0
    see_through: float = 0.0


def _select_target(cloud: TargetCloud, centre: np.ndarray, cfg: RegistrationConfig, extent=None):
    """The part of S(t) a scan from ``centre`` can overlap: ICP's target (the accepted scans, or
    every scan when ``cfg.exclude_rejected`` is off) within ``target_radius`` and, given the scan's
    ``extent`` ((2, 3) world box at the prior), within ``crop_margin`` of it; surfaces facing the
    scanner. (points, normals or None, covariances or None), or None when S(t) is empty."""
    copy = cloud._copy("target" if cfg.exclude_rejected else None)
    if copy is None or len(copy) == 0:
        return None
    points = copy.points
    # Only the part of S(t) the scan can overlap; a storey-wide target slows every ICP step.
    lo, hi = centre - cfg.target_radius, centre + cfg.target_radius
    if extent is not None and cfg.crop_margin is not None:
        # The scan's own reach: a small room's scan needs little of S(t), and a corridor's reaches
        # the end walls that fix its axis (a fixed 30 m box cut them off in the middle of a 70 m
        # corridor, and the pose drifted along it by 25 cm).
        lo, hi = np.maximum(lo, extent[0] - cfg.crop_margin), np.minimum(hi, extent[1] + cfg.crop_margin)
    if not copy.has_normals:
        return points[np.all((points >= lo) & (points <= hi), axis=1)], None, None
    # Only surfaces that face the scanner can be in its scan. Without this, the far face of a wall
    # (scanned from the next room, 10-25 cm behind) offers ICP a parallel twin to lock onto:
    # measured on five_rooms, accepted poses 15 cm off, one wall thickness.
    index, normals = _facing_voxels(points, copy.normal_sums, copy.counts, lo, hi, np.asarray(centre, dtype=float))
    return points[index], normals, (copy.covariances(index) if copy.has_covariances else None)


@numba.njit(cache=True)
def _facing_voxels(points, sums, counts, lo, hi, centre):
    """The voxels of a working copy (``points``, its ``normal_sums`` and ``counts``, as kept by
    :class:`_WorkingCopy`) inside the box ``lo``-``hi`` whose normals agree (mean length at least 0.5, as
    in :meth:`nbs_env.mapping.cloud.AccumulatedCloud._arrays`)
    and face ``centre``: (indices, unit normals), in one pass instead of numpy's six over the storey."""
    n = len(points)
    index = np.empty(n, dtype=np.int64)
    normals = np.empty((n, 3))
    m = 0
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1] and lo[2] <= pz <= hi[2]):
            continue
        c = counts[i]
        mx, my, mz = sums[i, 0] / c, sums[i, 1] / c, sums[i, 2] / c
        length = np.sqrt(mx * mx + my * my + mz * mz)
        if not length >= 0.5:
            continue
        nx, ny, nz = mx / length, my / length, mz / length
        if nx * (centre[0] - px) + ny * (centre[1] - py) + nz * (centre[2] - pz) > 0:
            index[m] = i
            normals[m, 0], normals[m, 1], normals[m, 2] = nx, ny, nz
            m += 1
    return index[:m], normals[:m]


#: Histogram of wall-normal headings: bins per degree, and the smoothing (σ in bins).
_HEADING_BINS_PER_DEG = 2
_HEADING_SMOOTH = 2.0


def _heading_histogram(normals: np.ndarray) -> np.ndarray:
    """Unit-norm histogram of the headings (mod 180°) of the near-horizontal ``normals`` (walls)."""
    n = normals[np.abs(normals[:, 2]) < 0.3]
    bins = 180 * _HEADING_BINS_PER_DEG
    heading = np.degrees(np.arctan2(n[:, 1], n[:, 0])) % 180.0
    h, _ = np.histogram(heading, bins=bins, range=(0.0, 180.0))
    half = int(4 * _HEADING_SMOOTH)
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / _HEADING_SMOOTH) ** 2)
    h = np.convolve(np.concatenate([h[-half:], h, h[:half]]).astype(float), kernel, mode="valid")
    norm = float(np.linalg.norm(h))
    return h / norm if norm > 0 else h


def _heading_offset(normals: np.ndarray, initial: np.ndarray, target_normals, limit_deg: float):
    """The heading error of ``initial`` (radians, to add to its yaw) by matching the histogram of the
    scan's wall-normal headings against S(t)'s, within ±``limit_deg`` (below 45°, so that the 90°
    aliases of a rectangular building stay out); None without walls to match. ``normals``: (n, 3)
    the normals of the scan's working copy, sensor frame.

    Independent of the translation, so it holds where ICP's coarsest stage cannot: after a long
    leg down a corridor the odometry's heading can be more than 10° off (a 30 m corridor, 15 m
    from the first scan, 14° and 0.68 m off: GICP from the prior stops in a wrong pose, from the
    histogram's heading it finds the true one within 1 cm; tests/test_registration.py).
    """
    if len(normals) < 10 or len(target_normals) == 0:
        return None
    hs = _heading_histogram(np.asarray(normals) @ initial[:3, :3].T)
    ht = _heading_histogram(np.asarray(target_normals))
    if not hs.any() or not ht.any():
        return None
    reach = int(min(limit_deg, 44.0) * _HEADING_BINS_PER_DEG)
    shifts = np.arange(-reach, reach + 1)
    score = np.array([np.dot(np.roll(hs, int(k)), ht) for k in shifts])
    return float(np.radians(shifts[int(np.argmax(score))] / _HEADING_BINS_PER_DEG))


def _turned(pose: np.ndarray, yaw: float) -> np.ndarray:
    """``pose`` turned by ``yaw`` radians about the vertical through its origin."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = pose.copy()
    out[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ pose[:3, :3]
    return out


def _agreement(
    world: np.ndarray, target: _Target, cfg: RegistrationConfig, nearest: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[int, int]:
    """(overlap, agreeing): source points (``world``, placed) within ``cfg.overlap_distance`` of
    S(t), and those of them within ``cfg.plane_tolerance`` of the nearest target point's plane.
    ``nearest``: ``target.nearest(world)`` when the caller has it already.

    A distance to the plane, not to the point: where S(t) is sparse (surfaces seen at a grazing
    angle or from afar, 9 cm between returns at 10 m with the 0.5° pattern) a correctly placed
    point is often more than ICP's finest 8 cm from the nearest target point though on its plane;
    fitness and RMSE then condemn a correct pose.
    """
    dist, idx = target.nearest(world) if nearest is None else nearest
    near = dist < cfg.overlap_distance
    if not near.any():
        return 0, 0
    q = idx[near]
    off = np.abs(np.einsum("ij,ij->i", world[near] - target.points[q], target.normals[q]))
    return int(near.sum()), int(np.count_nonzero(off < cfg.plane_tolerance))


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """The axis-angle vector of rotation ``R``."""
    angle = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-12:
        return 0.5 * axis
    return axis * (angle / (2.0 * np.sin(angle)))


def _rotation_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation of axis-angle vector ``w``."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _information(source_points: np.ndarray, target_normals: np.ndarray, pairs: np.ndarray, pose: np.ndarray):
    """The point-to-plane information JᵀJ (6 x 6) of the matched pairs at ``pose``.

    The parameters are a rotation about the scanner (axis-angle, radians; its rows are scaled by
    the lever arm in metres) and a translation of the scanner (metres), in the world frame.
    """
    if len(pairs) == 0:
        return np.zeros((6, 6))
    p = source_points[pairs[:, 0]] @ pose[:3, :3].T  # the lever arm from the scanner
    n = target_normals[pairs[:, 1]]
    J = np.hstack([np.cross(p, n), n])
    return J.T @ J


def _keep_constrained(pose: np.ndarray, initial: np.ndarray, H: np.ndarray, least: float) -> tuple[np.ndarray, int]:
    """``pose`` with its move away from ``initial`` kept only along well-constrained directions.

    Solution remapping (Zhang, Kaess and Singh, "On degeneracy of optimization-based state
    estimation problems", ICRA 2016): the eigenvectors of the information ``H`` with eigenvalue
    below ``least`` (point-equivalents) are directions the matches hardly fix, e.g. along a
    corridor with no end in view; along them ICP moves by noise and numerical round-off, so the
    odometry's value is kept there. Returns the pose and the number of such directions.
    """
    w, V = np.linalg.eigh(H)
    weak = w < least
    if not weak.any():
        return pose, 0
    move = np.concatenate([_rotation_vector(pose[:3, :3] @ initial[:3, :3].T), pose[:3, 3] - initial[:3, 3]])
    good = V[:, ~weak]
    kept = good @ (good.T @ move)
    out = np.eye(4)
    out[:3, :3] = _rotation_matrix(kept[:3]) @ initial[:3, :3]
    out[:3, 3] = initial[:3, 3] + kept[3:]
    return out, int(weak.sum())


def level_from_floor(points_sensor: np.ndarray, initial: np.ndarray, height: float) -> np.ndarray:
    """The first pose levelled by the floor the scan measured: its roll and pitch from the floor
    plane, the rest of ``initial`` kept.

    The first scan is S(t)'s frame, and every later scan registers to it: a stop that stands
    0.65° out of level (``five_rooms`` seed 3, the simulator's tilt σ 0.2°) left the whole map
    tilted by as much, its far rooms' surfaces 5-14 cm from the truth and 67% of the storey's
    structure sensed. A surveying scanner's dual-axis compensator levels its scans; this does it
    from the data: a least-squares plane through the returns near the expected floor, 1-5 m from
    the scanner, refitted in bands narrowing from 8 to 1 cm about it (clutter on the floor).

    Parameters
    ----------
    points_sensor : (n, 3) float
        The first scan in the sensor frame.
    initial : (4, 4) float
        The pose taken as level.
    height : float
        The scanner's height above the floor, metres.

    Returns
    -------
    (4, 4) float: ``initial`` with the rotation that makes the fitted floor horizontal; ``initial``
    itself where fewer than 500 returns lie near the floor or the fit tilts more than 5°.
    """
    p = np.asarray(points_sensor, dtype=np.float64)
    r = np.hypot(p[:, 0], p[:, 1])
    near = p[(r > 1.0) & (r < 5.0) & (np.abs(p[:, 2] + height) < 0.25)]
    if len(near) < 500:
        return initial
    # Start level at the floor's median height, then tighten: a first fit through wall bases and
    # furniture legs would tilt the plane by tenths of a degree.
    a = b = 0.0
    c = float(np.median(near[:, 2]))
    for band in (0.08, 0.04, 0.02, 0.01):
        keep = np.abs(near[:, 0] * a + near[:, 1] * b + c - near[:, 2]) < band
        if keep.sum() < 500:
            return initial
        A = np.column_stack([near[keep, 0], near[keep, 1], np.ones(keep.sum())])
        (a, b, c), *_ = np.linalg.lstsq(A, near[keep, 2], rcond=None)
    n = np.array([-a, -b, 1.0]) / np.sqrt(a * a + b * b + 1.0)  # the floor's up, in the sensor frame
    angle = float(np.arccos(np.clip(n[2], -1.0, 1.0)))
    if angle > np.radians(5.0):
        return initial
    # The smallest rotation taking the floor's up to the world's (Rodrigues), after the heading.
    axis = np.cross(n, [0.0, 0.0, 1.0])
    if np.linalg.norm(axis) < 1e-12:
        return initial
    axis /= np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    level = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    out = np.array(initial, dtype=np.float64, copy=True)
    out[:3, :3] = initial[:3, :3] @ level
    return out


def register(
    points_sensor: np.ndarray,
    initial: np.ndarray,
    cloud: TargetCloud,
    config: RegistrationConfig | None = None,
    travelled: float = 0.0,
) -> RegistrationResult:
    """Align a scan to S(t) by coarse-to-fine ICP (GICP by default), starting from the odometry pose.

    Parameters
    ----------
    points_sensor : (n, 3) float
        The scan in the sensor frame.
    initial : (4, 4) float
        The odometry pose estimate.
    cloud : TargetCloud
        S(t) (:class:`nbs_env.mapping.cloud.AccumulatedCloud`). When it is empty (the first scan)
        the initial pose is accepted as it is. The verdict is left on it for the scan's
        :meth:`~nbs_env.mapping.cloud.AccumulatedCloud.add`: a rejected scan does not become ICP's
        target.
    config : RegistrationConfig
    travelled : float
        Metres driven since the last accepted registration (the robot counts a refused scan's leg
        with the next one's, as its odometry pose kept the drift): the correction gates grow with it.

    Returns
    -------
    RegistrationResult
        Rejected (keeping ``initial``) when the scan or the part of S(t) near it has too few
        points, too little of the scan's overlap with S(t) lies on S(t)'s planes (or, with
        ``min_agreement=None``, fitness too low or RMSE too high), or the correction is larger than
        odometry drift can explain. Directions the matches hardly constrain keep the odometry's
        value (``weak_directions``).
    """
    cfg = config or RegistrationConfig()
    result = _register(points_sensor, initial, cloud, cfg, travelled, time.perf_counter())
    cloud._verdict = result.accepted
    return result


class _Target:
    """ICP's target for one registration: its points, unit normals for the plane tests, a nearest-
    neighbour search, and what the ICP method needs.

    The plane tests (``min_agreement``, ``min_constraint``) use the working copy's normals, each
    estimated in its own scan (from a wider neighbourhood for sparse far returns) and kept unit
    length through merges. Normals re-estimated from the target's k nearest points are worse where
    the target is sparse: their neighbourhoods reach across a corner into the next surface (on a
    30 m corridor, 15-19 m from the scans of S(t), 60% of the overlap of a correctly placed scan
    lay on their planes against 87% on the working copy's, and a correct pose was refused).
    ``method="gicp"``: small_gicp's k-d tree and the covariances S(t) keeps (plane-to-plane wants
    the local spread, not only the normal), those S(t) lacks from the ``neighbours`` nearest target
    points; ``"plane"``: small_gicp's own normals; ``"open3d"``: open3d on the working copy.
    """

    def __init__(
        self,
        points: np.ndarray,
        normals: np.ndarray | None,
        covariances: np.ndarray | None,
        cfg: RegistrationConfig,
        need_planes: bool,
    ):
        self.points = points
        self.method = cfg.method
        self.normals = np.zeros_like(points) if normals is None else normals
        self.covariances = covariances
        if cfg.method != "open3d":
            small_gicp = _small_gicp()
            self.sg = small_gicp.PointCloud(self.points)
            self.tree = small_gicp.KdTree(self.sg, num_threads=threads.cores())
            if cfg.method == "plane":
                small_gicp.estimate_normals(
                    self.sg, self.tree, num_neighbors=cfg.neighbours, num_threads=threads.cores()
                )
            else:
                # Where S(t) keeps no covariance (sparse in every scan, or a cloud without normals),
                # the target's own nearest points give it, as small_gicp estimates a target's.
                missing = (
                    np.arange(len(points))
                    if covariances is None
                    else np.flatnonzero(~np.any(covariances.reshape(len(points), 9) != 0.0, axis=1))
                )
                if covariances is None:
                    self.covariances = np.zeros((len(points), 3, 3))
                if len(missing):
                    self.covariances[missing] = _neighbour_covariances(
                        self.tree, self.points, self.points[missing], cfg.neighbours
                    )
        else:
            self.cloud = _cloud(points, normals)
            self._kd = None
            if need_planes:
                from scipy.spatial import cKDTree

                self._kd = cKDTree(self.points)

    def nearest_squared(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(index, squared distance) of the nearest target point to each of (m, 3) ``world``
        (index -1 where none), from small_gicp's k-d tree."""
        idx, sq = self.tree.batch_nearest_neighbor_search(world, num_threads=threads.cores())
        return np.asarray(idx, dtype=np.int64), np.asarray(sq, dtype=float)

    def nearest(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of the nearest target point to each of ``world``."""
        if self.method != "open3d":
            idx, sq = self.nearest_squared(world)
            dist = np.where(idx >= 0, np.sqrt(np.maximum(sq, 0.0)), np.inf)
            return dist, np.maximum(idx, 0)
        if self._kd is None:
            from scipy.spatial import cKDTree

            self._kd = cKDTree(self.points)
        dist, idx = self._kd.query(world)
        return dist, idx


def _neighbour_covariances(tree, points: np.ndarray, queries: np.ndarray, k: int) -> np.ndarray:
    """(m, 3, 3) float: GICP's covariance of each of the (m, 3) ``queries`` from its ``k`` nearest
    among the (n, 3) ``points`` (small_gicp's k-d ``tree`` of them)."""
    idx, _ = tree.batch_knn_search(queries, k, num_threads=threads.cores())
    return gicp.covariances_from_neighbours(points, np.asarray(idx).astype(np.int64), k)


def _small_gicp():
    try:
        import small_gicp
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise ImportError(
            "RegistrationConfig(method='gicp') needs small_gicp (pip install small_gicp); "
            "method='open3d' runs on open3d alone"
        ) from exc
    return small_gicp


def _register(points_sensor, initial, cloud: TargetCloud, cfg: RegistrationConfig, travelled: float, t0: float):
    initial = check_pose(initial, "initial pose")
    centre = initial[:3, 3]
    if cloud.voxel_size == cfg.voxel_size:
        # The scan's working copy is the same downsampling (AccumulatedCloud.add with pose=).
        copy = cloud._scan_copy(points_sensor, neighbours=cfg.neighbours)
        cloud._prepared = copy
    else:
        copy = _ScanCopy(points_sensor, cfg.voxel_size, cfg.neighbours)
        cloud._prepared = None
    extent = None
    if len(copy.points):
        world = copy.points @ initial[:3, :3].T + centre
        extent = np.stack([world.min(axis=0), world.max(axis=0)])
    selected = _select_target(cloud, centre, cfg, extent)
    if selected is None:
        return RegistrationResult(initial, initial, 1.0, 0.0, True, "", 0.0, 0.0, time.perf_counter() - t0)

    def refuse(reason: str) -> RegistrationResult:
        seconds = time.perf_counter() - t0
        return RegistrationResult(initial, initial, 0.0, float("inf"), False, reason, 0.0, 0.0, seconds)

    if len(copy.points) < cfg.min_points:
        return refuse(f"the scan has {len(copy.points)} points after downsampling, fewer than {cfg.min_points}")
    if len(selected[0]) < cfg.min_points:
        return refuse(f"S(t) has {len(selected[0])} points facing the scanner, fewer than {cfg.min_points}")
    gate_m = max(cfg.max_correction_m, cfg.correction_per_metre_m * travelled)
    gate_deg = max(cfg.max_correction_deg, cfg.correction_per_metre_deg * travelled)
    # Parallel reductions in open3d's ICP differ in the last bits from run to run, and ICP can
    # amplify that into a different local minimum; one thread makes a seed give the same poses
    # (small_gicp runs on one thread too).
    with _open3d_threads(1 if cfg.deterministic else None):
        target = _Target(*selected, cfg, cfg.min_agreement is not None or cfg.min_constraint > 0)
        src = _Source(copy.points, cfg, np.asarray(points_sensor, dtype=float), copy.sg, copy.covariances)
        if cfg.stage_voxels is not None and cfg.method != "open3d":
            # The coarse stages only need to bring the pose within the next stage's reach, and
            # their time grows with the scan's points: they align coarser copies of it.
            copies = {v: src if v == cfg.voxel_size else _Source.coarser(copy.points, v, cfg) for v in cfg.stage_voxels}
            src.stages = [copies[v] for v in cfg.stage_voxels]
        best = _attempt(src, target, initial, initial, cfg, gate_m, gate_deg)
        if cfg.heading_check_deg > 0:
            offset = _heading_offset(copy.normals, initial, target.normals, gate_deg)
            turned = yaw_of(best.pose_icp) - yaw_of(initial)
            gap = (offset - turned + np.pi) % (2 * np.pi) - np.pi if offset is not None else 0.0
            check = np.radians(cfg.heading_check_deg)
            if offset is not None and (abs(gap) > check or (not best.accepted and abs(offset) > check)):
                # ICP's heading disagrees with the walls': ICP may have started too far off to
                # turn there. Or ICP was refused after the walls' turn: turning that far from the
                # prior, its coarse matches can drag the position off (a 22° turn slid 3 m along a
                # corridor of example_level1). Try again from the walls' heading and keep the
                # better of the two.
                other = _attempt(src, target, _turned(initial, offset), initial, cfg, gate_m, gate_deg)
                if (other.accepted, other.agreeing) > (best.accepted, best.agreeing):
                    best = other
    return RegistrationResult(
        pose=best.pose_icp if best.accepted else initial,
        initial=initial,
        fitness=best.fitness,
        rmse=best.rmse,
        accepted=best.accepted,
        reason=best.reason,
        correction_m=best.moved_m,
        correction_deg=best.moved_deg,
        seconds=time.perf_counter() - t0,
        overlap=best.overlap,
        inliers=best.inliers,
        weak_directions=best.weak,
        agreement=best.agreement,
        see_through=best.see_through,
    )


@numba.njit(cache=True)
def _ranges(points: np.ndarray) -> np.ndarray:
    """(n,) float: the length of each of (n, 3) ``points``, summed as ``np.linalg.norm(axis=1)`` does."""
    out = np.empty(len(points))
    for i in range(len(points)):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        out[i] = np.sqrt(x * x + y * y + z * z)
    return out


@numba.njit(cache=True)
def _cell_minima(cells: np.ndarray, values: np.ndarray, size: int) -> np.ndarray:
    """(size,) float: per cell the least of ``values`` that fall in it, inf where none
    (``np.minimum.at``, which costs ten times more on a scan)."""
    out = np.full(size, np.inf)
    for i in range(len(cells)):
        if values[i] < out[cells[i]]:
            out[cells[i]] = values[i]
    return out


class _RangeImage:
    """The scan as a coarse range image in its own frame: per 1° cell, the nearest return within
    the cell and its eight neighbours.

    A pose is wrong when, placed with it, S(t) shows surfaces clearly in front of everything the
    scan measured in their direction: the scan would have seen through them. The plane agreement
    cannot tell: a scan shifted 2 m along a room's length (ICP kept in the prior's basin) still
    has its floor, ceiling and the walls along the shift on S(t)'s planes (five_rooms: 0.77 of its
    overlap, where 0.65 passes), while 9.5% of S(t) in its view lies in front of its returns,
    against under 0.1% at the true pose. The neighbours' minimum keeps a wall seen at a grazing
    angle, whose range changes fast across a cell, from counting against a correct pose.
    """

    CELL_DEG = 1.0
    #: Surfaces seen closer to edge-on than this (degrees of incidence) are left out.
    GRAZING_DEG = 80.0
    #: How far in front of the scan's nearest return a point of S(t) must lie to count, metres.
    TOLERANCE = 0.2

    def __init__(self, points: np.ndarray) -> None:
        from scipy.ndimage import minimum_filter

        self.shape = (round(180 / self.CELL_DEG), round(360 / self.CELL_DEG))
        points = np.ascontiguousarray(points, dtype=float)
        r = _ranges(points)
        ok = r > 0
        if not ok.all():  # a copy only where needed: boolean indexing costs as much as the rest
            points, r = points[ok], r[ok]
        cells = self._cells(points, r)
        nearest = _cell_minima(cells, r, self.shape[0] * self.shape[1]).reshape(self.shape)
        seen = np.isfinite(nearest)
        # Along the azimuth the image wraps around; over the poles it does not need to.
        grown = minimum_filter(np.where(seen, nearest, np.inf), size=3, mode=("nearest", "wrap"))
        self.nearest = np.where(seen, grown, np.inf).reshape(-1)
        # Nothing nearer than the scan's own closest return was measurable (the minimum range).
        self.closest = float(r.min()) if len(r) else np.inf

    def _cells(self, points: np.ndarray, r: np.ndarray) -> np.ndarray:
        el = np.degrees(np.arcsin(np.clip(points[:, 2] / r, -1.0, 1.0)))
        az = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
        row = np.clip(np.floor((el + 90.0) / self.CELL_DEG).astype(np.int64), 0, self.shape[0] - 1)
        col = np.floor((az + 180.0) / self.CELL_DEG).astype(np.int64) % self.shape[1]
        return row * self.shape[1] + col

    def see_through(self, world: np.ndarray, normals: np.ndarray, pose: np.ndarray) -> float:
        """Share of ``world`` points (S(t), with unit ``normals``) in the scan's view, placed with
        ``pose``, that lie more than :attr:`TOLERANCE` in front of the nearest return in their
        direction. Points on surfaces seen within :attr:`GRAZING_DEG` of edge-on do not count: a
        wall in line with the scanner (standing in a door frame) hides behind its own edge."""
        world = np.asarray(world, dtype=float)
        rel = world - pose[:3, 3]
        r = _ranges(rel)
        facing = np.abs(np.einsum("ij,ij->i", rel, normals)) > np.cos(np.radians(self.GRAZING_DEG)) * r
        keep = (r > self.closest + self.TOLERANCE) & facing
        if not keep.any():
            return 0.0
        local = rel[keep] @ pose[:3, :3]
        nearest = self.nearest[self._cells(local, r[keep])]
        seen = np.isfinite(nearest)
        if not seen.any():
            return 0.0
        return float(np.count_nonzero(r[keep][seen] < nearest[seen] - self.TOLERANCE) / np.count_nonzero(seen))


class _Source:
    """The downsampled scan (sensor frame), small_gicp's copy of it and, for ``method="gicp"``, its
    covariances, the raw scan's range image for the see-through gate, and the coarser copies the
    coarse stages align (``stages``, None: this one for every stage)."""

    def __init__(
        self,
        points: np.ndarray,
        cfg: RegistrationConfig,
        raw: np.ndarray | None = None,
        sg=None,
        covariances: np.ndarray | None = None,
    ) -> None:
        self.points = points
        self.stages: list[_Source] | None = None
        self.image = None if raw is None or cfg.max_see_through is None else _RangeImage(raw)
        self.covariances = covariances
        if cfg.method == "open3d":
            self.cloud = _cloud(points)
            return
        small_gicp = _small_gicp()
        self.sg = small_gicp.PointCloud(points) if sg is None else sg
        if cfg.method == "gicp" and covariances is None:  # plane-to-plane needs the scan's covariances
            tree = small_gicp.KdTree(self.sg, num_threads=threads.cores())
            self.covariances = _neighbour_covariances(tree, points, points, cfg.neighbours)

    @classmethod
    def coarser(cls, points: np.ndarray, voxel: float, cfg: RegistrationConfig) -> _Source:
        """A coarser copy of ``points`` (voxel means of edge ``voxel``), for a coarse stage."""
        sg = _small_gicp().voxelgrid_sampling(points, voxel, num_threads=1)
        return cls(np.asarray(sg.points())[:, :3].copy(), cfg)


@dataclass(frozen=True)
class _Attempt:
    pose_icp: np.ndarray
    fitness: float
    rmse: float
    overlap: float
    inliers: int
    agreeing: int
    agreement: float
    weak: int
    moved_m: float
    moved_deg: float
    reason: str
    see_through: float = 0.0

    @property
    def accepted(self) -> bool:
        return not self.reason


def _align(src: _Source, target: _Target, start: np.ndarray, cfg: RegistrationConfig):
    """Coarse-to-fine ICP from ``start``: (pose, fitness, inlier RMSE, finest-stage pairs or None)."""
    pose = start.copy()
    stages = src.stages or [src] * len(cfg.max_correspondence)
    if cfg.method == "gicp":
        for distance, stage in zip(cfg.max_correspondence, stages, strict=True):
            pose = gicp.align(
                target.nearest_squared,
                target.points,
                target.covariances,
                stage.points,
                stage.covariances,
                pose,
                distance,
                cfg.max_iterations,
                cfg.convergence,
            )
        return pose, None, None, None
    if cfg.method == "plane":
        small_gicp = _small_gicp()
        for distance, stage in zip(cfg.max_correspondence, stages, strict=True):
            result = small_gicp.align(
                target.sg,
                stage.sg,
                target.tree,
                init_T_target_source=pose,
                registration_type="PLANE_ICP",
                max_correspondence_distance=distance,
                num_threads=1,
                max_iterations=cfg.max_iterations,
                rotation_epsilon=cfg.convergence,
                translation_epsilon=cfg.convergence,
            )
            pose = np.asarray(result.T_target_source).copy()
        return pose, None, None, None
    reg = open3d().pipelines.registration
    result = None
    for distance in cfg.max_correspondence:
        result = reg.registration_icp(
            src.cloud,
            target.cloud,
            distance,
            pose,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=cfg.max_iterations),
        )
        pose = np.asarray(result.transformation).copy()
    pairs = np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2)
    return pose, float(result.fitness), float(result.inlier_rmse), pairs


def _attempt(src: _Source, target: _Target, start, initial, cfg: RegistrationConfig, gate_m, gate_deg):
    """ICP from ``start``, the degeneracy check and the gates (against ``initial``)."""
    pose, fitness, rmse, pairs = _align(src, target, start, cfg)
    finest = cfg.max_correspondence[-1]
    world = src.points @ pose[:3, :3].T + pose[:3, 3]
    nearest = None
    if pairs is None:  # GICP: fitness, RMSE and pairs as open3d defines them, at the finest distance
        nearest = dist, idx = target.nearest(world)
        inl = dist < finest
        fitness = float(inl.mean()) if len(dist) else 0.0
        rmse = float(np.sqrt(np.mean(dist[inl] ** 2))) if inl.any() else 0.0
        pairs = np.stack([np.flatnonzero(inl), idx[inl]], axis=1)
    inliers = len(pairs)
    weak = 0
    if cfg.min_constraint > 0 and inliers:
        H = _information(src.points, target.normals, pairs, pose)
        pose, weak = _keep_constrained(pose, initial, H, cfg.min_constraint)
        if weak:  # the pose moved: the scan's place and its nearest target points with it
            world, nearest = src.points @ pose[:3, :3].T + pose[:3, 3], None
    moved_m, moved_deg = pose_error(pose, initial)
    reason = ""
    if cfg.min_agreement is None:
        # The gates before the plane agreement: matches within the finest distance.
        overlap, agreeing, agreement = 1.0, inliers, 1.0
        if inliers < cfg.min_inliers:
            reason = f"{inliers} matches, fewer than {cfg.min_inliers}"
        elif fitness < cfg.min_fitness:
            reason = f"fitness {fitness:.3f} below {cfg.min_fitness}"
        elif rmse > cfg.max_rmse:
            reason = f"RMSE {rmse:.4f} m above {cfg.max_rmse} m"
    else:
        # Judged on the part of the scan S(t) can explain: a scan that sees mostly new surface (a
        # new room through a door) agrees with S(t) where they overlap; a wrong pose does not.
        near, agreeing = _agreement(world, target, cfg, nearest)
        overlap, agreement = near / len(src.points), (agreeing / near if near else 0.0)
        if agreeing < cfg.min_inliers:
            reason = f"{agreeing} points on S(t)'s planes, fewer than {cfg.min_inliers}"
        elif agreement < cfg.min_agreement:
            reason = (
                f"{agreement:.3f} of the overlap ({overlap:.3f} of the scan) on S(t)'s planes, "
                f"below {cfg.min_agreement}"
            )
    see_through = src.image.see_through(target.points, target.normals, pose) if src.image is not None else 0.0
    if not reason and cfg.max_see_through is not None and see_through > cfg.max_see_through:
        reason = (
            f"{see_through:.3f} of S(t) in the scan's view lies in front of what the scan measured, "
            f"above {cfg.max_see_through}"
        )
    if not reason and (moved_m > gate_m or moved_deg > gate_deg):
        reason = f"correction of {moved_m:.2f} m / {moved_deg:.1f}° exceeds {gate_m:.2f} m / {gate_deg:.1f}°"
    return _Attempt(
        pose, fitness, rmse, overlap, inliers, agreeing, agreement, weak, moved_m, moved_deg, reason, see_through
    )
