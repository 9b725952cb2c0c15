"""The robot's belief about the current room, updated scan by scan (paper Fig. 2, stages 2-4).

A :class:`RoomBelief` holds what the robot has measured in the room it is scanning and what it has
derived from that: the scans (S(t) of the room), the RoI, the SE classification of its faces, the
point labels and the labelled voxel space V(t). It never sees the scene: scans come in with the
robot's own pose estimates.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel, is_occupied
from nbs_env.mapping.cloud import VoxelMeans
from nbs_env.mapping.voxels import IntegrationStats, VoxelGrid
from nbs_env.perception.faces import PointIndex, WallFace
from nbs_env.perception.roi import RoI, RoIConfig, RoIScan, compute_roi
from nbs_env.perception.structure import SEClassifier, face_image, face_images, label_points
from nbs_env.sensing.scanner import Scan

__all__ = ["BeliefUpdate", "MissedVoxels", "RoomBelief", "RoomModel"]


@dataclass(frozen=True)
class BeliefUpdate:
    """What one scan changed, and how long each stage took (seconds)."""

    integration: IntegrationStats
    structure_points: int
    clutter_points: int
    times: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class RoomModel:
    """The structural model the robot recovered for one room, from its own measurements.

    Attributes
    ----------
    index : int
        The robot's number for the room (the order it entered them in).
    polygon : (n, 2) float
        The RoI outline, counter-clockwise.
    floor_z, ceiling_z : float
    se_faces : list of WallFace
        The RoI wall faces classified SE.
    points : (m, 3) float
        The room's registered points, downsampled to 5 cm (the perception working copy, whatever
        the voxel size of V(t)).
    structure : (m,) bool
        Which of ``points`` are labelled Structure.
    has_ceiling : bool
        False for a room open to the sky (:attr:`RoI.has_ceiling`): ``ceiling_z`` is its walls' top.
    scans : (m,) int32 or None
        For each of ``points``, the index of the scan that first measured its 5 cm voxel (the
        episode's scan index, :attr:`nbs_env.storey.ScanRecord.scan`, for a robot's rooms); None
        where unknown (a model made by hand).
    """

    index: int
    polygon: np.ndarray
    floor_z: float
    ceiling_z: float
    se_faces: list[WallFace]
    points: np.ndarray = field(repr=False)
    structure: np.ndarray = field(repr=False)
    has_ceiling: bool = True
    scans: np.ndarray | None = field(repr=False, default=None)


#: A RoI face is a frontier when less than this share of its image between 0.3 m above the floor and
#: 0.3 m below the ceiling holds measured points: no wall was seen along it. (Measured on RoI faces at
#: room ends, fast preset: walls 0.2-0.95, clutter-hidden or door faces 0.2-0.4, the sides of the
#: view from a door frame and edges past a corner 0.0-0.07.) A face that is a wall after all (hidden
#: behind furniture, beyond a window) costs at most one scan: the voxels guessed past it that a scan
#: should have seen and did not leave later gains (``planner.unobservable_after``).
FRONTIER_OCCUPANCY = 0.1


def frontier_faces(
    faces: list[WallFace],
    points: np.ndarray | PointIndex,
    min_length: float = 0.3,
    images: list[np.ndarray] | None = None,
) -> list[WallFace]:
    """The RoI faces along which no wall was measured (:data:`FRONTIER_OCCUPANCY`), at least
    ``min_length`` metres long: where the room may go on beyond what the scans saw. ``images``:
    the faces' images at 5 cm and ±10 cm when the caller has them (:func:`face_image`'s defaults)."""
    out = []
    margin = round(0.3 / 0.05)
    for k, face in enumerate(faces):
        if face.length < min_length:
            continue
        band = (images[k] if images is not None else face_image(face, points))[margin:-margin]
        if band.size == 0 or band.mean() < FRONTIER_OCCUPANCY:
            out.append(face)
    return out


@dataclass(frozen=True)
class MissedVoxels:
    """Occluded-structure voxels scans had in view beyond the dense range and missed
    (:meth:`RoomBelief.missed_from_afar`).

    Attributes
    ----------
    voxels : (k, 3) float
        Their centres, one entry a voxel.
    voxel : (r,) int
        For each miss, its voxel's row of ``voxels``.
    sensors : (r, 3) float
        The scanner position of each miss.
    ranges : (r,) float
        Its distance to the voxel, metres.
    """

    voxels: np.ndarray
    voxel: np.ndarray
    sensors: np.ndarray
    ranges: np.ndarray


class RoomBelief:
    """The robot's knowledge of the room it is scanning.

    Parameters
    ----------
    scanner : ScannerConfig
        The scanner's pattern (for carving).
    classifier : SEClassifier, optional
        The SE classifier; the packaged model by default.
    voxel_size : float
        Edge of the voxels of V(t), metres.
    perception_voxel : float
        Voxel size of the downsampled working copy of the room's points that SE classification and
        point labelling read. It stays at the 5 cm the SVM was trained at whatever ``voxel_size`` is:
        at 10 cm the face images thin out and the SVM called most walls non-SE (measured on
        ``five_rooms``: 2 of 6 faces SE in the first room, 21.9% of the storey sensed).
    margin : float
        How far V(t) extends beyond the RoI prism, metres.
    roi_config : RoIConfig, optional
        Its ``azimuth_bins`` is capped at the scanner's columns.
    exclude : list of (k, 2) float, optional
        Outlines of the rooms scanned before (the robot's own RoIs), kept out of this room's RoI.

    Attributes
    ----------
    unobservable : (n, 3) float
        Centres of Occluded-structure voxels that a scan was predicted to see, close enough to be hit,
        and left unconverted (:func:`nbs_env.planning.planner.unobservable_after`); later gains
        leave them out.
    missed : (k, 3) float
        Centres of Occluded-structure voxels a scan had in view beyond that range and left
        unconverted; ``missed_range`` (k,) float: its distance to each, ``missed_from`` (k, 3) float:
        its scanner position. Later gains from about the same place leave them out
        (:func:`nbs_env.planning.planner.missed_again`).
    """

    def __init__(
        self,
        scanner: ScannerConfig,
        classifier: SEClassifier | None = None,
        voxel_size: float = 0.05,
        perception_voxel: float = 0.05,
        margin: float = 0.3,
        roi_config: RoIConfig | None = None,
        exclude: list[np.ndarray] | None = None,
    ) -> None:
        self.scanner = scanner
        self.classifier = classifier or SEClassifier.load_default()
        self.voxel_size = voxel_size
        self.margin = margin
        # More azimuth bins than the scanner has columns leave most bins empty, and the RoI would
        # refuse a scan that sees a quarter of them or less (measured: every door-frame scan at 1°).
        roi_config = roi_config or RoIConfig()
        self.roi_config = replace(roi_config, azimuth_bins=min(roi_config.azimuth_bins, scanner.n_cols))
        self.exclude = list(exclude or [])
        self.scans: list[RoIScan] = []
        # Occluded-structure voxels a scan was predicted to see and did not: kept out of later gains.
        self.unobservable = np.zeros((0, 3))
        # Those it had in view beyond the dense range, with the distance: kept out of gains from as far.
        self.missed = np.zeros((0, 3))
        self.missed_range = np.zeros(0)
        self.missed_from = np.zeros((0, 3))
        # Each voxel keeps the scan that first measured it: the report's point source (cloud.laz).
        self.cloud = VoxelMeans(perception_voxel, tags=True)
        self.grid: VoxelGrid | None = None
        self.roi: RoI | None = None
        self.se: np.ndarray = np.zeros(0, dtype=bool)
        self.frontier: list[WallFace] = []

    @property
    def se_faces(self) -> list[WallFace]:
        """The RoI wall faces classified SE."""
        if self.roi is None:
            return []
        return [f for f, s in zip(self.roi.wall_faces, self.se, strict=True) if s]

    def earlier_share(self) -> float:
        """The share of this room's RoI, as its scans outline it, that lies in rooms scanned before
        (``exclude``): 1.0 when what the robot took for a new room was all seen as an earlier one's
        (a door detected inside a room whose first RoI reached through a wide opening)."""
        if not self.exclude or not self.scans or self.roi is None:
            return 0.0
        from shapely.geometry import Polygon

        whole = Polygon(compute_roi(self.scans, self.roi_config).polygon).area
        return 0.0 if whole <= 0 else max(0.0, 1.0 - Polygon(self.roi.polygon).area / whole)

    def add_scan(
        self,
        scan: Scan,
        pose: np.ndarray,
        keep_direction: np.ndarray | None = None,
        world: np.ndarray | None = None,
        scan_index: int | None = None,
    ) -> BeliefUpdate:
        """Take in a registered scan: RoI, SE classification, point labels, V(t).

        Parameters
        ----------
        scan : Scan
            The new scan (its measured part only is read).
        pose : (4, 4) float
            The robot's estimate of the scan's pose (after registration).
        keep_direction : (2,) float, optional
            For the first scan of a room taken in its door frame: the direction into the room.
        world : (n, 3) float, optional
            The scan placed with ``pose`` (``scan.to_world(pose)``), when the caller has it.
        scan_index : int, optional
            The number the working copy's new voxels are tagged with (:attr:`RoomModel.scans`): the
            robot passes the episode's scan index. Default: the scan's order in this room (0, 1, ...).

        Returns
        -------
        BeliefUpdate
        """
        times: dict[str, float] = {}
        t = time.perf_counter()
        new = RoIScan.from_scan(scan, pose, keep_direction, world)
        self.scans.append(new)
        self.cloud.add(new.points, tag=len(self.scans) - 1 if scan_index is None else scan_index)
        roi = compute_roi(self.scans, self.roi_config, self.exclude)
        times["roi"] = time.perf_counter() - t

        t = time.perf_counter()
        # Classification, relabelling and the frontier each look at the points near one face at a time.
        working = PointIndex(self.cloud.points)
        clf = self.classifier
        images = face_images(roi.wall_faces, working, pixel=clf.pixel, band=clf.band)
        self.se = clf.classify_images(images)
        self.roi = roi
        se_faces = self.se_faces
        labels = label_points(
            PointIndex(new.points), se_faces, roi.floor_z, roi.ceiling_z, roi.polygon, ceiling=roi.has_ceiling
        )
        times["classification"] = time.perf_counter() - t

        t = time.perf_counter()
        lo = np.array([*roi.polygon.min(axis=0), roi.floor_z]) - self.margin
        hi = np.array([*roi.polygon.max(axis=0), roi.ceiling_z]) + self.margin
        if self.grid is None:
            self.grid = VoxelGrid.covering(lo, hi, self.voxel_size)
        else:
            self.grid.ensure_covers(lo, hi)
        stats = self.grid.integrate(new.points, labels, pose, scan.depth_image(), self.scanner, roi.floor_z)
        self._relabel_occupied(working, se_faces, roi)
        # Under the sky the floor goes on outdoors: no edge of the view says the room does.
        # The frontier reads the classifier's images when they are at its own pixel and band.
        same = (clf.pixel, clf.band) == (0.05, 0.10)
        self.frontier = (
            frontier_faces(roi.wall_faces, working, images=images if same else None) if roi.has_ceiling else []
        )
        self.grid.update_occlusion(
            roi.polygon, roi.floor_z, roi.ceiling_z, se_faces, ceiling=roi.has_ceiling, frontier=self.frontier
        )
        times["voxels"] = time.perf_counter() - t
        return BeliefUpdate(stats, int(labels.sum()), int((~labels).sum()), times)

    def _relabel_occupied(self, working: PointIndex, se_faces: list[WallFace], roi: RoI) -> None:
        """Bring earlier occupied voxels in line with the current SE faces (the RoI and its
        classification change as the room is discovered)."""
        grid = self.grid
        assert grid is not None
        idx = grid.index_of(working.points)
        ok = grid.inside(idx)
        idx = idx[ok]
        # A point's label depends on it alone: labelling all and keeping those in the grid is
        # labelling those in the grid.
        structure = label_points(working, se_faces, roi.floor_z, roi.ceiling_z, roi.polygon, ceiling=roi.has_ceiling)
        structure = structure[ok]
        flat = np.ravel_multi_index(idx.T, grid.shape)
        labels = grid.labels.reshape(-1)
        occupied = is_occupied(labels[flat])
        # A voxel is Structure when any of its points is.
        has_structure = np.zeros(labels.size, dtype=bool)
        has_structure[flat[structure]] = True
        target = flat[occupied]
        labels[target] = np.where(has_structure[target], VoxelLabel.STRUCTURE, VoxelLabel.CLUTTER)

    def cover(self, xy: np.ndarray, reach: float) -> None:
        """Grow V(t) (with Unknown) to hold the floor within ``reach`` metres of ``xy``.

        A poor registration can put the pose estimate outside the room's grid; the robot still
        stands somewhere, and the planner needs its cell.
        """
        grid = self.grid
        if grid is None:
            return
        xy = np.asarray(xy, dtype=float)[:2]
        if np.any(xy < grid.origin[:2]) or np.any(xy >= grid.upper[:2]):
            grid.ensure_covers(np.array([*(xy - reach), grid.origin[2]]), np.array([*(xy + reach), grid.upper[2]]))

    def model(self, index: int) -> RoomModel | None:
        """The room's recovered model (None before its first scan), under the robot's number ``index``."""
        roi = self.roi
        if roi is None:
            return None
        points = self.cloud.points
        se_faces = self.se_faces
        structure = label_points(points, se_faces, roi.floor_z, roi.ceiling_z, roi.polygon, ceiling=roi.has_ceiling)
        return RoomModel(
            index,
            roi.polygon.copy(),
            roi.floor_z,
            roi.ceiling_z,
            se_faces,
            points,
            structure,
            roi.has_ceiling,
            self.cloud.tags.copy(),
        )

    def keep_unobservable(
        self,
        expected: np.ndarray,
        far: np.ndarray | None = None,
        far_range: np.ndarray | None = None,
        sensor: np.ndarray | None = None,
    ) -> None:
        """Mark the Occluded-structure voxels a scan was predicted to see and did not.

        Parameters
        ----------
        expected : (n, 3) float
            Voxel centres the last scan was predicted to convert
            (:func:`nbs_env.planning.planner.unobservable_after`); those still Occluded-structure
            join :attr:`unobservable`, which later gains leave out.
        far : (m, 3) float, optional
            Voxel centres it had in view beyond the dense range; those still Occluded-structure are
            kept with their distance ``far_range`` (m,) float and the scan's ``sensor`` (3,) float
            as :attr:`missed`, out of later gains from about as far and the same place
            (:func:`nbs_env.planning.planner.missed_again`).
        """
        if len(expected):
            missed = expected[self.labels_at(expected) == VoxelLabel.OCCLUDED_STRUCTURE]
            self.unobservable = np.concatenate([self.unobservable, missed])
        if far is not None and len(far) and sensor is not None:
            still = self.labels_at(far) == VoxelLabel.OCCLUDED_STRUCTURE
            self.missed = np.concatenate([self.missed, far[still]])
            self.missed_range = np.concatenate([self.missed_range, np.asarray(far_range, dtype=float)[still]])
            where = np.broadcast_to(np.asarray(sensor, dtype=float), (int(still.sum()), 3))
            self.missed_from = np.concatenate([self.missed_from, where])

    def missed_from_afar(self, labels: np.ndarray | None = None) -> MissedVoxels:
        """The :attr:`missed` voxels still Occluded-structure in ``labels`` (V(t)'s by default)."""
        grid = self.grid
        if grid is None or not len(self.missed):
            return MissedVoxels(np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
        idx = grid.index_of(self.missed)
        keep = grid.inside(idx)
        labels = grid.labels if labels is None else labels
        keep[keep] = labels[tuple(idx[keep].T)] == VoxelLabel.OCCLUDED_STRUCTURE
        idx = idx[keep]
        cells, voxel = np.unique(idx, axis=0, return_inverse=True)
        return MissedVoxels(grid.centres(cells), voxel.reshape(-1), self.missed_from[keep], self.missed_range[keep])

    def occluded_structure_centres(self) -> np.ndarray:
        """(n, 3) float: world centres of the OCCLUDED_STRUCTURE voxels."""
        if self.grid is None:
            return np.zeros((0, 3))
        return self.grid.centres(np.argwhere(self.grid.labels == VoxelLabel.OCCLUDED_STRUCTURE))

    def labels_at(self, points: np.ndarray) -> np.ndarray:
        """(n,) uint8: the current labels at world points (UNKNOWN outside the grid)."""
        out = np.zeros(len(points), dtype=np.uint8)
        if self.grid is None:
            return out
        idx = self.grid.index_of(points)
        ok = self.grid.inside(idx)
        out[ok] = self.grid.labels[tuple(idx[ok].T)]
        return out
