"""The labels of the voxel space V(t) (paper §4, METHOD §5), stored as uint8."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

__all__ = ["LABEL_COLOURS", "OCCUPIED", "VoxelLabel", "is_occupied"]


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


def is_occupied(labels: np.ndarray) -> np.ndarray:
    """Bool array of ``labels``' shape: which voxels are :data:`OCCUPIED` (hold points)."""
    labels = np.asarray(labels)
    return (labels == OCCUPIED[0]) | (labels == OCCUPIED[1])


#: (6, 3) uint8 RGB of each VoxelLabel, by value: the one palette of pictures and PLY exports.
#: Structure blue and Occluded-structure green as in the paper's Fig. 4; Unknown white and Empty a
#: light grey, so that a top-down picture shows what was seen.
LABEL_COLOURS = np.array(
    [
        [255, 255, 255],  # UNKNOWN
        [237, 237, 230],  # EMPTY
        [242, 153, 51],  # CLUTTER
        [31, 119, 180],  # STRUCTURE
        [252, 217, 140],  # OCCLUDED_CLUTTER
        [44, 160, 44],  # OCCLUDED_STRUCTURE
    ],
    dtype=np.uint8,
)
LABEL_COLOURS.setflags(write=False)
