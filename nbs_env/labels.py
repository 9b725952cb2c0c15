"""The labels of the voxel space V(t) (paper §4, METHOD §5), stored as uint8."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["OCCUPIED", "VoxelLabel"]


class VoxelLabel(IntEnum):
    """Label of a voxel. Occupied: CLUTTER, STRUCTURE. Not occupied: the rest."""

    UNKNOWN = 0  # outside the RoI, or not yet reasoned about
    EMPTY = 1  # a ray passed through it before hitting something, and it holds no point
    CLUTTER = 2  # holds points labelled Clutter
    STRUCTURE = 3  # holds points labelled Structure
    OCCLUDED_CLUTTER = 4  # not sensed; inside the RoI; not on an SE face
    OCCLUDED_STRUCTURE = 5  # not sensed; on an SE face (the slab of voxels the face passes through)


#: Labels of voxels that hold points.
OCCUPIED = (VoxelLabel.CLUTTER, VoxelLabel.STRUCTURE)
