"""Registration of a new scan into the accumulated cloud S(t): point-to-plane ICP from the odometry pose.

S(t) keeps every registered scan at full resolution (for output and the coverage metric) and a
voxel-downsampled working copy with normals (for ICP and perception), for the storey and per room.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from nbs_env.config import RegistrationConfig
from nbs_env.sensing.pose import check_pose, pose_error
from scenes._open3d import open3d

__all__ = ["AccumulatedCloud", "RegistrationResult", "register"]


def _cloud(points: np.ndarray, normals: np.ndarray | None = None):
    o3d = open3d()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    return pc


def _downsample_with_normals(points: np.ndarray, origin: np.ndarray, voxel: float, radius: float | None):
    o3d = open3d()
    pc = _cloud(points).voxel_down_sample(voxel)
    # An empty scan (the scanner inside a wall, or every return below the minimum range) has no
    # normals to orient; open3d raises on it.
    if radius is None or len(pc.points) == 0:
        return pc
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    # Normals face the scanner, so that averaging over scans does not cancel them.
    pc.orient_normals_towards_camera_location(np.asarray(origin, dtype=np.float64))
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


class AccumulatedCloud:
    """S(t): the registered scans of the storey and of each room.

    Parameters
    ----------
    voxel_size : float
        Voxel size of the working copies in metres.
    normal_radius : float
        Neighbourhood radius for the normals of the working copies.
    normals : bool
        Estimate normals (ICP's target needs them); without, adding a scan costs about a third.
    rooms : bool
        Keep a working copy per room as well as the storey's.

    Besides the working copies of every scan, the cloud keeps ICP's target: the working copy of the
    scans whose registration was accepted. A scan whose ICP was refused lies in S(t) at its odometry
    pose, centimetres to decimetres off; as a target it doubles every surface it shares with the
    registered scans, and the next scans lock onto the wrong copy (measured on a five_rooms tour: one
    refused scan 12 cm off, the next ten registered 22-37 cm off; see docs/registration_study.md).
    The two copies are one object until the first refused scan.
    """

    def __init__(
        self, voxel_size: float = 0.05, normal_radius: float = 0.15, *, normals: bool = True, rooms: bool = True
    ) -> None:
        self.voxel_size = voxel_size
        self.normal_radius = normal_radius
        self.normals = normals
        self.rooms = rooms
        self._full: list[np.ndarray] = []
        self._rooms_of_scans: list[int] = []
        self._origins: list[np.ndarray] = []
        self._registered: list[bool] = []
        self._storey = None
        self._target = None
        self._room_copies: dict[int, object] = {}
        self._pending: list[int] = []
        # The verdict of the last ``register`` on this cloud, for the scan added next.
        self._verdict: bool | None = None

    def __len__(self) -> int:
        return len(self._full)

    @property
    def n_points(self) -> int:
        """Points at full resolution over all scans."""
        return int(sum(len(p) for p in self._full))

    @property
    def registered(self) -> list[bool]:
        """Per scan, whether it is in ICP's target (its registration was accepted)."""
        return list(self._registered)

    def add(self, points_world: np.ndarray, origin: np.ndarray, room: int = 0, registered: bool | None = None) -> None:
        """Add a registered scan.

        Parameters
        ----------
        points_world : (n, 3) float
            The scan placed with the robot's pose estimate.
        origin : (3,) float
            The estimated scanner position (normals are oriented towards it).
        room : int
            The room the robot believes it is scanning.
        registered : bool, optional
            Whether the pose came from an accepted registration (only such scans become ICP's
            target). Default: the verdict of the last :func:`register` into this cloud, or True
            when there was none since the last ``add`` (a scan placed without ICP).
        """
        points_world = np.asarray(points_world, dtype=np.float64)
        if points_world.ndim != 2 or points_world.shape[1] != 3 or not np.all(np.isfinite(points_world)):
            raise ValueError(f"points_world must be a finite (n, 3) array, got shape {points_world.shape}")
        if registered is None:
            registered = True if self._verdict is None else self._verdict
        self._verdict = None
        self._full.append(points_world)
        self._rooms_of_scans.append(int(room))
        self._origins.append(np.asarray(origin, dtype=float))
        self._registered.append(bool(registered))
        # The working copies are merged when first asked for: a robot without ICP never asks.
        self._pending.append(len(self._full) - 1)

    def _update(self) -> None:
        for k in self._pending:
            points, origin, room = self._full[k], self._origins[k], self._rooms_of_scans[k]
            new = _downsample_with_normals(
                points, origin, self.voxel_size, self.normal_radius if self.normals else None
            )
            if len(new.points) == 0:
                continue
            shared = self._target is self._storey
            self._storey = self._merge(self._storey, new)
            if self._registered[k]:
                self._target = self._storey if shared else self._merge(self._target, new)
            if self.rooms:
                self._room_copies[room] = self._merge(self._room_copies.get(room), new)
        self._pending = []

    def _merge(self, old, new):
        if old is None:
            return new
        merged = old + new
        return merged.voxel_down_sample(self.voxel_size)

    # ------------------------------------------------------------------ views
    def storey_points(self) -> np.ndarray:
        """(n, 3) float: all registered points at full resolution."""
        return np.concatenate(self._full) if self._full else np.zeros((0, 3))

    def room_points(self, room: int) -> np.ndarray:
        """(n, 3) float: the full-resolution points of the scans taken in ``room``."""
        parts = [p for p, r in zip(self._full, self._rooms_of_scans, strict=True) if r == room]
        return np.concatenate(parts) if parts else np.zeros((0, 3))

    def working_points(self, room: int | None = None) -> np.ndarray:
        """(n, 3) float: the downsampled working copy of the storey, or of one room."""
        self._update()
        pc = self._storey if room is None else self._room_copies.get(room)
        return np.zeros((0, 3)) if pc is None else np.asarray(pc.points)

    def working_cloud(self, room: int | None = None):
        """The downsampled working copy (an open3d PointCloud with normals), or None when empty."""
        self._update()
        return self._storey if room is None else self._room_copies.get(room)

    def target_cloud(self):
        """ICP's target: the working copy of the scans whose registration was accepted, or None."""
        self._update()
        return self._target


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


_KERNELS = {"tukey": "TukeyLoss", "huber": "HuberLoss", "cauchy": "CauchyLoss"}


def _estimation(cfg: RegistrationConfig, distance: float):
    reg = open3d().pipelines.registration
    if cfg.robust_kernel == "none":
        return reg.TransformationEstimationPointToPlane()
    kernel = getattr(reg, _KERNELS[cfg.robust_kernel])(k=cfg.kernel_width * distance)
    return reg.TransformationEstimationPointToPlane(kernel)


def _select_target(cloud: AccumulatedCloud, centre: np.ndarray, cfg: RegistrationConfig):
    """The part of S(t) a scan from ``centre`` can overlap: ICP's target (the accepted scans, or
    every scan when ``cfg.exclude_rejected`` is off) within ``target_radius``, surfaces facing the
    scanner. None when S(t) is empty."""
    o3d = open3d()
    target = cloud.target_cloud() if cfg.exclude_rejected else cloud.working_cloud()
    if target is None or len(target.points) == 0:
        return None
    # Only the part of S(t) the scan can overlap; a storey-wide target slows every ICP step.
    box = o3d.geometry.AxisAlignedBoundingBox(centre - cfg.target_radius, centre + cfg.target_radius)
    target = target.crop(box)
    # Only surfaces that face the scanner can be in its scan. Without this, the far face of a wall
    # (scanned from the next room, 10-25 cm behind) offers ICP a parallel twin to lock onto:
    # measured on five_rooms, accepted poses 15 cm off, one wall thickness.
    if target.has_normals() and len(target.points):
        pts, nrm = np.asarray(target.points), np.asarray(target.normals)
        facing = np.einsum("ij,ij->i", nrm, centre - pts) > 0
        target = target.select_by_index(np.flatnonzero(facing).tolist())
    return target


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


def register(
    points_sensor: np.ndarray,
    initial: np.ndarray,
    cloud: AccumulatedCloud,
    config: RegistrationConfig | None = None,
    travelled: float = 0.0,
) -> RegistrationResult:
    """Align a scan to S(t) by coarse-to-fine point-to-plane ICP, starting from the odometry pose.

    Parameters
    ----------
    points_sensor : (n, 3) float
        The scan in the sensor frame.
    initial : (4, 4) float
        The odometry pose estimate.
    cloud : AccumulatedCloud
        S(t). When it is empty (the first scan) the initial pose is accepted as it is. The verdict
        is left on it for the scan's :meth:`AccumulatedCloud.add`: a rejected scan does not become
        ICP's target.
    config : RegistrationConfig
    travelled : float
        Metres driven since the last scan: the correction gates grow with it.

    Returns
    -------
    RegistrationResult
        Rejected (keeping ``initial``) when the scan or the part of S(t) near it has too few
        points, too few matches, too low a share of matches where S(t) overlaps the scan, too high
        an RMSE, or a correction larger than odometry drift can explain. Directions the matches
        hardly constrain keep the odometry's value (``weak_directions``).
    """
    cfg = config or RegistrationConfig()
    result = _register(points_sensor, initial, cloud, cfg, travelled, time.perf_counter())
    cloud._verdict = result.accepted
    return result


def _register(points_sensor, initial, cloud, cfg: RegistrationConfig, travelled: float, t0: float):
    initial = check_pose(initial, "initial pose")
    centre = initial[:3, 3]
    target = _select_target(cloud, centre, cfg)
    if target is None:
        return RegistrationResult(initial, initial, 1.0, 0.0, True, "", 0.0, 0.0, time.perf_counter() - t0)

    def refuse(reason: str, fitness=0.0, rmse=float("inf"), overlap=0.0, inliers=0) -> RegistrationResult:
        return RegistrationResult(
            initial, initial, fitness, rmse, False, reason, 0.0, 0.0, time.perf_counter() - t0, overlap, inliers
        )

    source = _cloud(points_sensor).voxel_down_sample(cfg.voxel_size)
    if len(source.points) < cfg.min_points:
        return refuse(f"the scan has {len(source.points)} points after downsampling, fewer than {cfg.min_points}")
    if len(target.points) < cfg.min_points:
        return refuse(f"S(t) has {len(target.points)} points facing the scanner, fewer than {cfg.min_points}")
    reg = open3d().pipelines.registration
    pose = initial.copy()
    fitness, rmse, overlap = 0.0, float("inf"), 0.0
    pairs = np.zeros((0, 2), dtype=np.int64)
    # Parallel reductions in open3d's ICP differ in the last bits from run to run, and ICP can
    # amplify that into a different local minimum; one thread makes a seed give the same poses.
    with _open3d_threads(1 if cfg.deterministic else None):
        for stage, distance in enumerate(cfg.max_correspondence):
            result = reg.registration_icp(
                source,
                target,
                distance,
                pose,
                _estimation(cfg, distance),
                reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=cfg.max_iterations),
            )
            pose = np.asarray(result.transformation).copy()
            fitness, rmse = float(result.fitness), float(result.inlier_rmse)
            if stage == 0:
                overlap = fitness
        pairs = np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2)
    inliers = len(pairs)
    weak = 0
    if cfg.min_constraint > 0 and inliers:
        H = _information(np.asarray(source.points), np.asarray(target.normals), pairs, pose)
        pose, weak = _keep_constrained(pose, initial, H, cfg.min_constraint)
    moved_m, moved_deg = pose_error(pose, initial)
    # Fitness where S(t) overlaps the scan: a scan that sees mostly new surface (a new room
    # through a door, after a long leg) has a low share of matches overall, yet most of the part
    # S(t) can explain matches; a wrong alignment leaves much of that part unmatched.
    share = fitness / overlap if overlap > 0 else 0.0
    reason = ""
    if inliers < cfg.min_inliers:
        reason = f"{inliers} matches, fewer than {cfg.min_inliers}"
    elif fitness < cfg.min_fitness and (cfg.min_overlap_fitness is None or share < cfg.min_overlap_fitness):
        reason = f"fitness {fitness:.3f} below {cfg.min_fitness}"
        if cfg.min_overlap_fitness is not None:
            reason += f", and {share:.3f} of the overlap ({overlap:.3f} of the scan) below {cfg.min_overlap_fitness}"
    elif rmse > cfg.max_rmse:
        reason = f"RMSE {rmse:.4f} m above {cfg.max_rmse} m"
    else:
        gate_m = max(cfg.max_correction_m, cfg.correction_per_metre_m * travelled)
        gate_deg = max(cfg.max_correction_deg, cfg.correction_per_metre_deg * travelled)
        if moved_m > gate_m or moved_deg > gate_deg:
            reason = f"correction of {moved_m:.2f} m / {moved_deg:.1f}° exceeds {gate_m:.2f} m / {gate_deg:.1f}°"
    accepted = not reason
    return RegistrationResult(
        pose=pose if accepted else initial,
        initial=initial,
        fitness=fitness,
        rmse=rmse,
        accepted=accepted,
        reason=reason,
        correction_m=moved_m,
        correction_deg=moved_deg,
        seconds=time.perf_counter() - t0,
        overlap=overlap,
        inliers=inliers,
        weak_directions=weak,
    )
