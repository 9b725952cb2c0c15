"""Fixed-shape views of the robot's belief for a policy: the voxel window and the candidate table.

The labelled grid V(t) grows as the room is discovered, and every room has its own. A policy needs
a fixed shape, so the observation is a window of the current room's grid, centred on the robot's
estimated position, axis-aligned with the world, with its labels pooled into coarser cells. Pooling
keeps, per cell, the label that matters most to the method, by a fixed priority:

    STRUCTURE > OCCLUDED_STRUCTURE > CLUTTER > OCCLUDED_CLUTTER > EMPTY > UNKNOWN

so that one Structure voxel among many Empty ones still shows, and an unsensed piece of wall is never
hidden by the free space in front of it. Cells outside the grid are UNKNOWN. No gymnasium import.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from nbs_env.config import _finite, _require
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.voxels import VoxelGrid

__all__ = ["CANDIDATE_FEATURES", "ObservationConfig", "candidate_table", "pool_labels", "voxel_window"]

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

#: Columns of the candidate table, in order.
CANDIDATE_FEATURES = ("dx", "dy", "path_length", "predicted_gain", "valid")


@dataclass(frozen=True)
class ObservationConfig:
    """The voxel window of the observation.

    Attributes
    ----------
    shape : (int, int, int)
        Cells along x, y and z.
    cell : float
        Edge of an observation cell in metres (a whole number of voxels is best: 0.2 m pools 4³
        voxels of 5 cm or 2³ of 10 cm).
    below_floor : float
        How far below the robot's floor the window starts, metres (the floor slab must be inside).
    """

    shape: tuple[int, int, int] = (64, 64, 16)
    cell: float = 0.2
    below_floor: float = 0.2

    def __post_init__(self) -> None:
        _require(
            len(self.shape) == 3 and all(isinstance(n, int) and n >= 1 for n in self.shape),
            f"shape must be three positive integers, got {self.shape}",
        )
        _finite(cell=self.cell, below_floor=self.below_floor)
        _require(self.cell > 0, f"cell must be > 0 metres, got {self.cell}")

    @property
    def extent(self) -> np.ndarray:
        """(3,) float: the window's size in metres."""
        return np.asarray(self.shape, dtype=float) * self.cell

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


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
    out = np.zeros(tuple(shape), dtype=np.uint8)
    ranks = _RANK[labels]
    slices, targets = [], []
    for axis in range(3):
        c = np.asarray(cell_of[axis])
        inside = np.flatnonzero((c >= 0) & (c < shape[axis]))
        if not len(inside):
            return out
        lo, hi = int(inside[0]), int(inside[-1]) + 1
        sub = c[lo:hi]
        starts = np.flatnonzero(np.r_[True, sub[1:] != sub[:-1]])
        slices.append((lo, hi, starts))
        targets.append(sub[starts])
    block = ranks[slices[0][0] : slices[0][1], slices[1][0] : slices[1][1], slices[2][0] : slices[2][1]]
    for axis in range(3):
        block = np.maximum.reduceat(block, slices[axis][2], axis=axis)
    out[np.ix_(targets[0], targets[1], targets[2])] = _LABEL_OF_RANK[block]
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


def candidate_table(
    xy: np.ndarray,
    path_length: np.ndarray,
    gains: np.ndarray,
    mask: np.ndarray,
    robot_xy: np.ndarray,
    structural_voxels: int,
) -> np.ndarray:
    """(K, 5) float32 rows ``CANDIDATE_FEATURES`` for the K candidate slots.

    ``predicted_gain`` is the predicted Occluded-structure→Structure conversions as a share of the
    room's structural voxels (Structure + Occluded-structure), so that it reads alike at any voxel
    size. Padding rows are all zero.
    """
    k = len(mask)
    table = np.zeros((k, len(CANDIDATE_FEATURES)), dtype=np.float32)
    m = np.asarray(mask, dtype=bool)
    table[m, 0:2] = np.asarray(xy, dtype=float)[m] - np.asarray(robot_xy, dtype=float)
    table[m, 2] = np.asarray(path_length, dtype=float)[m]
    table[m, 3] = np.asarray(gains, dtype=float)[m] / max(1, int(structural_voxels))
    table[m, 4] = 1.0
    return table
