"""What a policy sees: the robot's belief as a :class:`BeliefView`, and its fixed-shape observation
(the voxel window and the candidate table).

The labelled grid V(t) grows as the room is discovered, and every room has its own. A policy needs
a fixed shape, so the observation is a window of the current room's grid, centred on the robot's
estimated position, axis-aligned with the world, with its labels pooled into coarser cells. Pooling
keeps, per cell, the label that matters most to the method, by a fixed priority:

    STRUCTURE > OCCLUDED_STRUCTURE > CLUTTER > OCCLUDED_CLUTTER > EMPTY > UNKNOWN

so that one Structure voxel among many Empty ones still shows, and an unsensed piece of wall is never
hidden by the free space in front of it. Cells outside the grid are UNKNOWN.

The candidate table has one row per NVP slot and the columns :class:`CandidateColumn`; policies
index it by name (``table[:, CandidateColumn.PATH_LENGTH]``), never by number. No gymnasium import.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numba
import numpy as np

from nbs_env.config import ObservationConfig, ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.voxels import VoxelGrid
from nbs_env.perception.faces import WallFace
from nbs_env.perception.roi import RoI

__all__ = [
    "CANDIDATE_FEATURES",
    "ROOM_FEATURES",
    "STOREY_FEATURES",
    "BeliefView",
    "CandidateColumn",
    "ObservationConfig",
    "RoomColumn",
    "StoreyColumn",
    "candidate_table",
    "candidate_table_of",
    "observe",
    "pool_labels",
    "room_features",
    "storey_features",
    "voxel_window",
]

#: Pooling priority, lowest first (see the module docstring).
_PRIORITY = (
    VoxelLabel.UNKNOWN,
    VoxelLabel.EMPTY,
    VoxelLabel.OCCLUDED_CLUTTER,
    VoxelLabel.CLUTTER,
    VoxelLabel.OCCLUDED_STRUCTURE,
    VoxelLabel.STRUCTURE,
)
_RANK = np.zeros(256, dtype=np.uint8)
for _rank, _label in enumerate(_PRIORITY):
    _RANK[int(_label)] = _rank
_LABEL_OF_RANK = np.array([int(label) for label in _PRIORITY], dtype=np.uint8)


class CandidateColumn(IntEnum):
    """The columns of the candidate table."""

    DX = 0  # metres along world x from the robot's estimated position
    DY = 1  # metres along world y
    PATH_LENGTH = 2  # geodesic path length, metres
    PREDICTED_GAIN = 3  # predicted conversions as a share of the room's structural voxels
    VALID = 4  # 1 for a real NVP, 0 for padding


#: Names of the candidate table's columns, in order.
CANDIDATE_FEATURES = tuple(c.name.lower() for c in CandidateColumn)


class RoomColumn(IntEnum):
    """The entries of the observation's ``room`` vector: the state of the room being scanned, for a
    policy that decides when the room is done (``completion="policy"``)."""

    SCANS_IN_ROOM = 0  # scans taken in the room, its door-frame scan included
    STRUCTURE_SENSED_SHARE = 1  # Structure / (Structure + Occluded-structure) voxels of the room's V(t)
    STRUCTURE_AREA = 2  # (Structure + Occluded-structure) voxels × voxel face, m²: the room's size as mapped
    FRONTIER_LENGTH = 3  # metres of RoI faces along which no wall was measured yet
    ROOMS_DONE = 4  # rooms completed before this one


#: Names of the ``room`` vector's entries, in order.
ROOM_FEATURES = tuple(c.name.lower() for c in RoomColumn)


class StoreyColumn(IntEnum):
    """The entries of the observation's ``storey`` vector: what the robot knows of the storey beyond
    the room, for a critic that predicts the scans and metres still to come (the doors it found and
    has not crossed are rooms still to scan)."""

    SCANS_TAKEN = 0  # scans taken in the episode, door-frame scans included
    DOORS_WAITING = 1  # doors detected, not crossed and not given up
    NEAREST_DOOR = 2  # metres in a straight line to the nearest of them (0 when none)
    DOOR_DISTANCE = 3  # metres in a straight line to all of them, summed


#: Names of the ``storey`` vector's entries, in order.
STOREY_FEATURES = tuple(c.name.lower() for c in StoreyColumn)


@dataclass(frozen=True)
class BeliefView:
    """What the robot believes, for policies that keep their own state (``info["belief"]``), and
    what the observation is built from.

    Everything here is the robot's: measured points placed with its pose estimates, its own grid,
    RoI and plan. Nothing is ground truth. Arrays are references into the live belief: read, never
    write.

    Attributes
    ----------
    pose : (4, 4) float
        The pose estimate.
    room : int
        The robot's number of the room it is in.
    new_room : bool
        This step (or reset) started the room: maps of the previous room no longer apply.
    scans : list of ((n, 3) float, (3,) float)
        The scans registered during this step (a door crossing adds one): world points and the
        scanner position.
    grid : VoxelGrid or None
        The room's labelled voxel space V(t).
    labels : (nx, ny, nz) uint8 or None
        ``grid``'s labels as the planner reads them: what no scan from the room's stops could
        measure (the blind zone under each stop) taken as Empty
        (:func:`~nbs_env.planning.planner.unseeable_free`). The greedy navigates on it; the compared
        methods build their maps from it, so that all share one treatment of the blind zone.
    roi : RoI or None
        The room's region of interest.
    se : (f,) bool
        Which of ``roi.wall_faces`` are classified SE.
    frontier : list of WallFace
        The RoI faces along which no wall was measured, where the room may go on past what the
        scans saw (:func:`~nbs_env.belief.frontier_faces`).
    candidates_xy : (K, 2) float
        World positions of the NVPs (zeros for padding, and all padding once the episode is over).
    path_length : (K,) float
        Geodesic path lengths to them.
    mask : (K,) bool
        Which entries are real.
    gains : (K,) int64
        The greedy's predicted Occluded-structure→Structure conversions, voxels (zeros when the
        robot does not predict gains).
    gain_share : (K,) float
        ``gains`` as shares of the room's structural voxels.
    scanner : ScannerConfig
        The scanner's pattern and limits.
    scans_in_room : int
        Scans the robot took in the current room (its door-frame scan included).
    rooms_done : int
        Rooms the robot has completed.
    scans_taken : int
        Scans taken in the episode.
    doors_waiting : (d, 2) float
        Centres of the doors the robot detected and has not crossed or given up, map frame.
    """

    pose: np.ndarray
    room: int
    new_room: bool
    scans: list[tuple[np.ndarray, np.ndarray]]
    grid: VoxelGrid | None
    labels: np.ndarray | None
    roi: RoI | None
    se: np.ndarray
    frontier: list[WallFace]
    candidates_xy: np.ndarray
    path_length: np.ndarray
    mask: np.ndarray
    gains: np.ndarray
    gain_share: np.ndarray
    scanner: ScannerConfig
    scans_in_room: int = 0
    rooms_done: int = 0
    scans_taken: int = 0
    doors_waiting: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def count(self) -> int:
        """How many NVPs are real."""
        return int(np.count_nonzero(self.mask))


def pool_labels(labels: np.ndarray, cell_of: tuple[np.ndarray, np.ndarray, np.ndarray], shape) -> np.ndarray:
    """Pool voxel labels into cells by the fixed priority.

    Parameters
    ----------
    labels : (nx, ny, nz) uint8
        VoxelLabel values.
    cell_of : three (nx,), (ny,), (nz,) int arrays
        The output cell of each voxel index along each axis, non-decreasing; -1 or ``shape[a]`` and
        beyond for voxels outside the output.
    shape : (int, int, int)
        The output shape.

    Returns
    -------
    (shape) uint8
        VoxelLabel values; UNKNOWN where no voxel falls.
    """
    c = [np.ascontiguousarray(cell_of[a], dtype=np.int64) for a in range(3)]
    for a in range(3):
        if len(c[a]) != labels.shape[a]:
            raise ValueError(f"cell_of[{a}] has {len(c[a])} entries for {labels.shape[a]} voxels")
    ranks = _pool_ranks(labels, c[0], c[1], c[2], tuple(int(n) for n in shape), _RANK)
    return _LABEL_OF_RANK[ranks]


@numba.njit(cache=True, nogil=True)
def _pool_ranks(labels, cx, cy, cz, shape, rank):
    """Per output cell, the highest priority rank of the voxels that fall in it (0: none)."""
    out = np.zeros(shape, dtype=np.uint8)
    nx, ny, nz = labels.shape
    for i in range(nx):
        a = cx[i]
        if a < 0 or a >= shape[0]:
            continue
        for j in range(ny):
            b = cy[j]
            if b < 0 or b >= shape[1]:
                continue
            for k in range(nz):
                d = cz[k]
                if d < 0 or d >= shape[2]:
                    continue
                r = rank[labels[i, j, k]]
                if r > out[a, b, d]:
                    out[a, b, d] = r
    return out


def voxel_window(
    grid: VoxelGrid | None, centre_xy: np.ndarray, floor_z: float, config: ObservationConfig
) -> np.ndarray:
    """The observation window of ``grid`` around ``centre_xy`` (see the module docstring).

    Parameters
    ----------
    grid : VoxelGrid or None
        The current room's V(t); None gives an all-UNKNOWN window.
    centre_xy : (2,) float
        The robot's estimated position.
    floor_z : float
        The floor height the window is anchored to.
    config : ObservationConfig

    Returns
    -------
    (nx, ny, nz) uint8
    """
    shape = config.shape
    if grid is None:
        return np.zeros(shape, dtype=np.uint8)
    lo = np.array([*(np.asarray(centre_xy, dtype=float) - config.extent[:2] / 2), floor_z - config.below_floor])
    cell_of = []
    for axis in range(3):
        centres = grid.origin[axis] + (np.arange(grid.shape[axis]) + 0.5) * grid.voxel_size
        cell_of.append(np.floor((centres - lo[axis]) / config.cell).astype(np.int64))
    return pool_labels(grid.labels, tuple(cell_of), shape)


def candidate_table(view: BeliefView) -> np.ndarray:
    """(K, 5) float32: the rows of the K candidate slots, columns :class:`CandidateColumn`.

    ``PREDICTED_GAIN`` is the predicted Occluded-structure→Structure conversions as a share of the
    room's structural voxels (Structure + Occluded-structure), so that it reads alike at any voxel
    size. Padding rows are all zero.
    """
    m = np.asarray(view.mask, dtype=bool)
    table = np.zeros((len(m), len(CandidateColumn)), dtype=np.float32)
    # The lattice points at float32, as the candidate list stores them (Candidates.xy).
    xy = np.asarray(view.candidates_xy, dtype=np.float32).astype(float)
    table[m, CandidateColumn.DX : CandidateColumn.DY + 1] = xy[m] - np.asarray(view.pose, dtype=float)[:2, 3]
    table[m, CandidateColumn.PATH_LENGTH] = np.asarray(view.path_length, dtype=float)[m]
    table[m, CandidateColumn.PREDICTED_GAIN] = np.asarray(view.gain_share, dtype=float)[m]
    table[m, CandidateColumn.VALID] = 1.0
    return table


def candidate_table_of(obs: dict[str, np.ndarray]) -> np.ndarray:
    """(..., K, 5) float32: ``obs["candidates"]`` as a table with columns :class:`CandidateColumn`
    (works on a single observation and on a batch from a vector env)."""
    flat = np.asarray(obs["candidates"])
    return flat.reshape(*flat.shape[:-1], -1, len(CandidateColumn))


def room_features(view: BeliefView) -> np.ndarray:
    """(5,) float32: the room's state, entries :class:`RoomColumn`, from the robot's own grid, RoI
    and scan count (zeros but the counts when the room has no grid yet)."""
    out = np.zeros(len(RoomColumn), dtype=np.float32)
    out[RoomColumn.SCANS_IN_ROOM] = view.scans_in_room
    out[RoomColumn.ROOMS_DONE] = view.rooms_done
    grid = view.grid
    if grid is not None:
        counts = np.bincount(grid.labels.ravel(), minlength=256)
        sensed = int(counts[int(VoxelLabel.STRUCTURE)])
        structural = sensed + int(counts[int(VoxelLabel.OCCLUDED_STRUCTURE)])
        out[RoomColumn.STRUCTURE_SENSED_SHARE] = sensed / max(1, structural)
        out[RoomColumn.STRUCTURE_AREA] = structural * grid.voxel_size**2
    out[RoomColumn.FRONTIER_LENGTH] = sum(face.length for face in view.frontier)
    return out


def storey_features(view: BeliefView) -> np.ndarray:
    """(4,) float32: what the robot knows of the storey beyond the room, entries :class:`StoreyColumn`,
    from its own scan count and door memory."""
    out = np.zeros(len(StoreyColumn), dtype=np.float32)
    out[StoreyColumn.SCANS_TAKEN] = view.scans_taken
    doors = np.asarray(view.doors_waiting, dtype=float).reshape(-1, 2)
    out[StoreyColumn.DOORS_WAITING] = len(doors)
    if len(doors):
        distance = np.linalg.norm(doors - np.asarray(view.pose, dtype=float)[:2, 3], axis=1)
        out[StoreyColumn.NEAREST_DOOR] = distance.min()
        out[StoreyColumn.DOOR_DISTANCE] = distance.sum()
    return out


def observe(view: BeliefView, config: ObservationConfig) -> dict[str, np.ndarray]:
    """The env's observation of a belief: ``voxels``, ``candidates`` (flat), ``pose`` and ``room``.

    Returns
    -------
    dict
        ``voxels`` ``config.shape`` uint8; ``candidates`` (K·5,) float32; ``pose`` (4,) float32 x, y,
        z (m) and yaw (rad); ``room`` (5,) float32 (:func:`room_features`); ``storey`` (4,) float32
        (:func:`storey_features`); all clipped to the observation space's ±1e4.
    """
    pose = view.pose
    xy = pose[:2, 3]
    floor_z = view.roi.floor_z if view.roi is not None else float(pose[2, 3] - view.scanner.height)
    voxels = voxel_window(view.grid, xy, floor_z, config)
    table = candidate_table(view)
    yaw = float(np.arctan2(pose[1, 0], pose[0, 0]))
    pose_vec = np.array([pose[0, 3], pose[1, 3], pose[2, 3], yaw], dtype=np.float32)
    return {
        "voxels": voxels,
        "candidates": np.clip(table, -1e4, 1e4).reshape(-1),
        "pose": np.clip(pose_vec, -1e4, 1e4),
        "room": np.clip(room_features(view), -1e4, 1e4),
        "storey": np.clip(storey_features(view), -1e4, 1e4),
    }
