"""The accumulated cloud S(t), and its working copies: points (and normals) averaged in
world-anchored voxels, updated scan by scan (the room's copy for perception, S(t)'s for registration).

S(t) keeps every registered scan at full resolution (for output and the coverage metric) and a
voxel-downsampled working copy with normals (ICP's target), for the storey and per room: each scan
is downsampled once (10 cm voxel means), its normals estimated in the scan itself, and merged into
world-anchored voxels. Registration (:mod:`nbs_env.sensing.registration`) reads it through
:class:`~nbs_env.sensing.registration.TargetCloud` and makes the scans' downsampled copies.
"""

from __future__ import annotations

from concurrent.futures import Future

import numba
import numpy as np

from nbs_env import threads
from nbs_env.sensing.pose import check_pose
from nbs_env.sensing.registration import _cloud, _ScanCopy

__all__ = ["AccumulatedCloud", "VoxelMeans"]

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
    tags : bool
        Keep, per voxel, the ``tag`` of the ``add`` that first put a point in it (then every ``add``
        gives one): the room's copy tags each voxel with the scan that first measured it, the scan
        index the report's ``cloud.laz`` writes as its point source (:attr:`tags`). Unlike the means,
        the tags depend on the order the scans came in.
    """

    def __init__(self, voxel_size: float, normals: bool = False, covariances: bool = False, tags: bool = False) -> None:
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be a positive number of metres, got {voxel_size}")
        self.voxel_size = float(voxel_size)
        self.has_normals = bool(normals)
        self.has_covariances = bool(covariances)
        self.has_tags = bool(tags)
        self._keys = np.zeros(0, dtype=np.int64)
        self._tags = np.zeros(0, dtype=np.int32)
        # Columns 0-2 the points' sums, then 3 of their normals' (with ``normals``), then 6 of their
        # covariances' upper triangles (xx, xy, xz, yy, yz, zz) and how many gave one (with
        # ``covariances``).
        self._sums = np.zeros((0, 3 + 3 * self.has_normals + 7 * self.has_covariances))
        self._counts = np.zeros(0, dtype=np.int64)
        self._points: np.ndarray | None = np.zeros((0, 3))

    def __len__(self) -> int:
        """Voxels held (points in the working copy)."""
        return len(self._keys)

    def add(
        self,
        points: np.ndarray,
        normals: np.ndarray | None = None,
        covariances: np.ndarray | None = None,
        tag: int | None = None,
    ) -> None:
        """Add (n, 3) float world points, with their (n, 3) float unit ``normals`` when the copy
        keeps normals, their (n, 3, 3) float ``covariances`` when it keeps covariances (a zero
        matrix: no estimate for that point) and an int ``tag`` (0..2^31-1) when it keeps tags.

        Raises
        ------
        ValueError
            The points are not a finite (n, 3) array, lie farther than 2^20 voxels from the origin,
            or normals, covariances or the tag are missing, or given to a copy without.
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
        if (tag is None) == self.has_tags:
            raise ValueError("tag must be given exactly when the copy keeps tags (VoxelMeans(tags=True))")
        if tag is not None and not 0 <= int(tag) <= np.iinfo(np.int32).max:
            raise ValueError(f"tag must be in 0..{np.iinfo(np.int32).max}, got {tag}")
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
        held = self._keys
        self._keys, self._sums, self._counts = _merge(held, self._sums, self._counts, keys, order, values)
        if tag is not None:
            # The voxels held keep their tags (their keys are among the merged ones, in order); the
            # new ones take this add's. A search over the sorted keys, not a change to the merge.
            tags = np.full(len(self._keys), int(tag), dtype=np.int32)
            tags[np.searchsorted(self._keys, held)] = self._tags
            self._tags = tags
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

    @property
    def tags(self) -> np.ndarray:
        """(m,) int32: per voxel (in the order of :attr:`points`), the ``tag`` of the ``add`` that
        first put a point in it (the copy keeps tags)."""
        if not self.has_tags:
            raise ValueError("this copy keeps no tags (VoxelMeans(tags=True))")
        return self._tags

    def copy(self) -> VoxelMeans:
        """An independent copy."""
        out = VoxelMeans(self.voxel_size, self.has_normals, self.has_covariances, self.has_tags)
        out._keys, out._sums, out._counts = self._keys.copy(), self._sums.copy(), self._counts.copy()
        out._tags = self._tags.copy()
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


class AccumulatedCloud:
    """S(t): the registered scans of the storey and of each room.

    Parameters
    ----------
    voxel_size : float
        Voxel size of the working copies in metres.
    normal_radius : float
        Neighbourhood radius for the normals, metres (:class:`~nbs_env.sensing.registration._ScanCopy`).
    normals : bool
        Estimate normals (ICP's target needs them).
    rooms : bool
        Keep a working copy per room as well as the storey's.
    normal_reach : float or None
        Points with fewer than six neighbours within ``normal_radius`` (far returns) take their
        normal from within this radius instead. None: ``normal_radius`` for all.

    The working copies are world-anchored voxel means (:class:`VoxelMeans`)
    of every scan's downsampled copy: adding a scan touches only its own voxels, not the storey's.
    With normals, the storey's copy and ICP's target also keep GICP's covariances, each scan's own
    (from its 20 nearest points in the scan, where at least six lie within ``normal_radius``)
    placed with its pose and averaged per voxel.
    A voxel's normal is the mean of its points' normals made unit length; voxels whose normals
    disagree (mean length below 0.5: a corner, both faces of a thin board) are left out.

    Besides the working copies of every scan, the cloud keeps ICP's target: the working copy of the
    scans whose registration was accepted. A scan whose ICP was refused lies in S(t) at its odometry
    pose, centimetres to decimetres off; as a target it doubles every surface it shares with the
    registered scans, and the next scans can lock onto the wrong copy.
    The two copies are one object until the first refused scan.
    """

    def __init__(
        self,
        voxel_size: float = 0.1,
        normal_radius: float = 0.15,
        *,
        normals: bool = True,
        rooms: bool = True,
        normal_reach: float | None = 0.6,
    ) -> None:
        self.voxel_size = voxel_size
        self.normal_radius = normal_radius
        self.normal_reach = normal_reach
        self.normals = normals
        self.rooms = rooms
        self._full: list[np.ndarray] = []
        self._rooms_of_scans: list[int] = []
        self._origins: list[np.ndarray] = []
        self._registered: list[bool] = []
        self._storey: VoxelMeans | None = None
        self._target: VoxelMeans | None = None
        self._room_copies: dict[int, VoxelMeans] = {}
        self._pending: list[int] = []
        self._views: dict = {}
        # The verdict of the last ``register`` on this cloud, for the scan added next.
        self._verdict: bool | None = None
        # The downsampled copy of the scan the last ``register`` aligned (sensor frame), and the
        # scans' copies waiting to be merged: each scan is downsampled, and its normals estimated, once.
        self._prepared: _ScanCopy | None = None
        self._copies: dict[int, _ScanCopy] = {}
        # The merge of the scans added last, running beside the robot's next work (see ``add``).
        self._merging: Future | None = None

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

    def add(
        self,
        points_world: np.ndarray,
        origin: np.ndarray,
        room: int = 0,
        registered: bool | None = None,
        pose: np.ndarray | None = None,
    ) -> None:
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
            target). Default: the verdict of the last
            :func:`~nbs_env.sensing.registration.register` into this cloud, or True when there was
            none since the last ``add`` (a scan placed without ICP).
        pose : (4, 4) float, optional
            The pose that placed the scan (its position is ``origin``). Given, the working copy is
            the downsampled copy the last :func:`~nbs_env.sensing.registration.register` into this
            cloud made of the same scan, placed with it, instead of a new downsampling of
            ``points_world``: the scan is then downsampled, and its normals estimated, once. The
            registration's voxels must be the cloud's.
        """
        points_world = np.asarray(points_world, dtype=np.float64)
        if points_world.ndim != 2 or points_world.shape[1] != 3 or not np.all(np.isfinite(points_world)):
            raise ValueError(f"points_world must be a finite (n, 3) array, got shape {points_world.shape}")
        self._settle()
        if registered is None:
            registered = True if self._verdict is None else self._verdict
        self._verdict = None
        prepared, self._prepared = self._prepared, None
        if pose is not None and prepared is not None:
            pose = check_pose(pose, "pose")
            if prepared.size != len(points_world):
                raise ValueError(
                    f"the last registered scan had {prepared.size} points and this one {len(points_world)}: "
                    "pose= adds only the scan register() aligned"
                )
            prepared.pose = pose
            self._copies[len(self._full)] = prepared
        self._full.append(points_world)
        self._rooms_of_scans.append(int(room))
        self._origins.append(np.asarray(origin, dtype=float))
        self._registered.append(bool(registered))
        # The working copies are merged when first asked for: a robot without ICP never asks. With
        # ICP, and a second core, the merge starts now beside the robot's perception of the scan
        # (numpy and the compiled merge release the GIL), off the next registration's path.
        self._pending.append(len(self._full) - 1)
        if self.normals and threads.cores() > 1:
            self._merging = threads.beside(self._update)

    def _settle(self) -> None:
        """Wait for a merge running beside (and raise what it raised)."""
        merging, self._merging = self._merging, None
        if merging is not None:
            merging.result()

    def __getstate__(self) -> dict:
        self._settle()
        return self.__dict__.copy()

    def _update(self) -> None:
        if not self._pending:
            return
        for k in self._pending:
            copy = self._copies.pop(k, None)
            if copy is None or (self.normals and copy.covariances is None):
                copy = self._scan_copy(self._full[k], self._origins[k], covariances=self.normals)
                copy.pose = None
            points, normals, covariances = copy.world()
            if not len(points):
                continue
            normals = normals if self.normals else None
            # The covariances ride with the normals: both are ICP's, and S(t) without ICP keeps neither.
            covariances = covariances if self.normals else None
            if self._storey is None:
                self._storey = self._target = VoxelMeans(self.voxel_size, self.normals, self.normals)
            if not self._registered[k] and self._target is self._storey:
                # The first refused scan: from here on the target holds the registered scans only.
                self._target = self._storey.copy()
            self._storey.add(points, normals, covariances)
            if self._registered[k] and self._target is not self._storey:
                self._target.add(points, normals, covariances)
            if self.rooms:
                room = self._rooms_of_scans[k]
                self._room_copies.setdefault(room, VoxelMeans(self.voxel_size, self.normals)).add(points, normals)
        self._pending = []
        self._views = {}

    def _scan_copy(self, points: np.ndarray, origin=None, neighbours: int = 20, covariances: bool = True) -> _ScanCopy:
        """A scan's downsampled copy with this cloud's normals (and GICP's covariances)."""
        radius = self.normal_radius if self.normals else None
        return _ScanCopy(points, self.voxel_size, neighbours, origin, radius, self.normal_reach, covariances)

    def _copy(self, key) -> VoxelMeans | None:
        """The storey's copy (``None``), a room's (its index) or the target's (``"target"``), updated."""
        self._settle()
        self._update()
        return self._target if key == "target" else self._storey if key is None else self._room_copies.get(key)

    def _arrays(self, copy: VoxelMeans | None, subset: np.ndarray | None = None):
        """(points, unit normals or None) of a working copy (of its voxels ``subset``), voxels with
        disagreeing normals left out."""
        if copy is None:
            return np.zeros((0, 3)), (np.zeros((0, 3)) if self.normals else None)
        points = copy.points if subset is None else copy.points[subset]
        if not copy.has_normals:
            return points, None
        sums, counts = copy.normal_sums, copy.counts
        if subset is not None:
            sums, counts = sums[subset], counts[subset]
        mean = sums / counts[:, None]
        length = np.sqrt(np.einsum("ij,ij->i", mean, mean))
        keep = length >= 0.5
        return points[keep], mean[keep] / length[keep, None]

    def _view(self, key):
        """The arrays of the storey's copy (``None``), a room's (its index) or the target's (``"target"``)."""
        copy = self._copy(key)
        if key not in self._views:
            self._views[key] = self._arrays(copy)
        return self._views[key]

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
        return self._view(room)[0]

    def working_normals(self, room: int | None = None) -> np.ndarray | None:
        """(n, 3) float unit normals of :meth:`working_points` (None without normals)."""
        return self._view(room)[1]

    def working_cloud(self, room: int | None = None):
        """The downsampled working copy (an open3d PointCloud with normals), or None when empty."""
        points, normals = self._view(room)
        return _cloud(points, normals) if len(points) else None

    def target_arrays(self) -> tuple[np.ndarray, np.ndarray | None]:
        """ICP's target, the working copy of the scans whose registration was accepted: (points,
        unit normals or None), (n, 3) float each."""
        return self._view("target")

    def target_cloud(self):
        """ICP's target as an open3d PointCloud with normals, or None when empty."""
        points, normals = self.target_arrays()
        return _cloud(points, normals) if len(points) else None
