"""The classes of a building's mesh faces (ground truth), stored as uint8."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["STRUCTURAL_CLASSES", "SurfaceClass"]


class SurfaceClass(IntEnum):
    """The class of a mesh face. FLOOR, CEILING and WALL are the structural elements (SE)."""

    FLOOR = 0
    CEILING = 1
    WALL = 2
    DOOR = 3
    WINDOW = 4
    CLUTTER = 5

    @property
    def is_structural(self) -> bool:
        return self in STRUCTURAL_CLASSES


STRUCTURAL_CLASSES: frozenset[SurfaceClass] = frozenset({SurfaceClass.FLOOR, SurfaceClass.CEILING, SurfaceClass.WALL})
