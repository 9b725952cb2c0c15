"""The building model: a labelled triangle mesh plus optional ground truth about rooms and doors.

Everything here is *ground truth*. Only the simulator (ray casting, noise) and evaluation (metrics,
rewards, the oracle) may read a :class:`Scene`'s labels, rooms or doors; perception and policies see
only what the simulated robot measures.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from scenes.errors import InvalidMeshError, MissingStructureError
from scenes.geometry import auto_start
from scenes.labels import STRUCTURAL_CLASSES, SurfaceClass
from scenes.limits import check_sample_count, check_storey_size

__all__ = [
    "STRUCTURAL_CLASSES",
    "Door",
    "Room",
    "Scene",
    "StructureSamples",
    "SurfaceClass",
]


@dataclass(frozen=True)
class Room:
    """A room's ground truth.

    Attributes
    ----------
    id : int
        Index of the room in ``Scene.rooms``; the value used in ``Scene.face_rooms``.
    name : str
        Human-readable name.
    polygon : (n, 2) float
        The room's clear floor outline (inside the walls), counter-clockwise, not closed.
    floor_z, ceiling_z : float
        Heights of the floor and the ceiling in metres.
    """

    id: int
    name: str
    polygon: np.ndarray
    floor_z: float = 0.0
    ceiling_z: float = 2.7

    @property
    def area(self) -> float:
        """Floor area of the polygon in m² (shoelace formula)."""
        x, y = self.polygon[:, 0], self.polygon[:, 1]
        return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


@dataclass(frozen=True)
class Door:
    """A door opening between two rooms (a room id of -1 means the outside).

    Attributes
    ----------
    rooms : (int, int)
        The two room ids it joins.
    position : (3,) float
        Centre of the opening at floor level.
    width, height : float
        Clear opening in metres.
    normal : (2,) float
        Horizontal unit vector across the wall, pointing from ``rooms[0]`` to ``rooms[1]``.
    """

    rooms: tuple[int, int]
    position: np.ndarray
    width: float
    height: float
    normal: np.ndarray = field(default_factory=lambda: np.zeros(2))


@dataclass(frozen=True)
class StructureSamples:
    """Points spread uniformly over the structural faces, for the coverage metric.

    Attributes
    ----------
    points : (n, 3) float
        Sample positions on the mesh.
    labels : (n,) uint8
        SurfaceClass of the face each sample lies on (FLOOR, CEILING or WALL).
    rooms : (n,) int
        Room id of that face, or -1.
    faces : (n,) int
        Index of that face in ``Scene.mesh.faces``.
    """

    points: np.ndarray
    labels: np.ndarray
    rooms: np.ndarray
    faces: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


# The R2 sequence (Roberts 2018) spreads points evenly in the unit square without an RNG, so the
# samples are deterministic and have no clumps that a seeded uniform draw would have.
_R2_G = 1.32471795724474602596
_R2_A = np.array([1.0 / _R2_G, 1.0 / _R2_G**2])


class Scene:
    """A storey as a labelled triangle mesh, metres, z up.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The building's surfaces. Vertices must be finite; at least one face.
    face_labels : (F,) int
        One :class:`SurfaceClass` per face; stored as uint8.
    face_rooms : (F,) int, optional
        A room id or -1 per face; all -1 when omitted.
    rooms : sequence of Room, optional
        Ground-truth rooms; ``face_rooms`` values index into it.
    doors : sequence of Door, optional
        Ground-truth doors.
    start : (2,) or (3,) float, optional
        Start position of the robot on the floor. When omitted, :meth:`auto_start` chooses one
        lazily (see :attr:`start`).
    name : str
        Where the scene came from, used in messages.
    metadata : dict, optional
        Free-form JSON-safe information (source file, plan version, ...).

    Raises
    ------
    InvalidMeshError
        Empty mesh, NaN or infinite vertices, or label arrays whose shape does not match the faces.
    StoreySizeError
        Larger than :mod:`scenes.limits` allows: too wide, too high or too many faces.
    MissingStructureError
        No floor or no wall faces.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        face_labels: np.ndarray,
        face_rooms: np.ndarray | None = None,
        *,
        rooms: tuple[Room, ...] | list[Room] = (),
        doors: tuple[Door, ...] | list[Door] = (),
        start: np.ndarray | tuple[float, ...] | None = None,
        name: str = "scene",
        metadata: dict | None = None,
    ) -> None:
        self.name = name
        if not isinstance(mesh, trimesh.Trimesh):
            raise InvalidMeshError(name, f"expected a trimesh.Trimesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
            raise InvalidMeshError(name, "the mesh is empty (no faces)")
        if not np.all(np.isfinite(mesh.vertices)):
            bad = int(np.count_nonzero(~np.isfinite(mesh.vertices).all(axis=1)))
            raise InvalidMeshError(name, f"{bad} vertices are NaN or infinite")
        n_faces = len(mesh.faces)
        # Before anything is sized from the bounds: a file in millimetres would ask for hundreds of GiB.
        check_storey_size(name, mesh.vertices, n_faces)
        labels = np.asarray(face_labels)
        if labels.shape != (n_faces,):
            raise InvalidMeshError(name, f"face_labels has shape {labels.shape}, expected ({n_faces},)")
        valid = np.isin(labels, [c.value for c in SurfaceClass])
        if not valid.all():
            raise InvalidMeshError(
                name, f"face_labels holds values that are no SurfaceClass: {np.unique(labels[~valid])}"
            )
        if face_rooms is None:
            face_rooms = np.full(n_faces, -1, dtype=np.int32)
        room_ids = np.asarray(face_rooms)
        if room_ids.shape != (n_faces,):
            raise InvalidMeshError(name, f"face_rooms has shape {room_ids.shape}, expected ({n_faces},)")
        self.mesh = mesh
        self.face_labels = labels.astype(np.uint8)
        self.face_rooms = room_ids.astype(np.int32)
        self.rooms = tuple(rooms)
        if room_ids.size and room_ids.max() >= max(len(self.rooms), 0) and len(self.rooms):
            raise InvalidMeshError(name, f"face_rooms refers to room {int(room_ids.max())} of {len(self.rooms)}")
        for required in (SurfaceClass.FLOOR, SurfaceClass.WALL):
            if not np.any(self.face_labels == required):
                raise MissingStructureError(name, f"the scene has no {required.name.lower()} faces; nothing to scan")
        self.doors = tuple(doors)
        self.metadata = dict(metadata or {})
        self._start = None if start is None else self._as_floor_point(start)

    # ------------------------------------------------------------------ ground truth
    @property
    def start(self) -> np.ndarray:
        """(3,) float: the start position on the floor, chosen by :meth:`auto_start` if not given."""
        if self._start is None:
            self._start = self._as_floor_point(auto_start(self))
        return self._start

    @start.setter
    def start(self, value: np.ndarray | tuple[float, ...]) -> None:
        self._start = self._as_floor_point(value)

    @property
    def has_explicit_start(self) -> bool:
        return self._start is not None

    def _as_floor_point(self, value: np.ndarray | tuple[float, ...]) -> np.ndarray:
        try:
            p = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError, OverflowError):  # a string, a ragged list, 10**400
            p = np.full(1, np.nan)
        if p.shape not in ((2,), (3,)) or not np.all(np.isfinite(p)):
            raise InvalidMeshError(self.name, f"start must be a finite (x, y[, z]) point, got {str(value)[:80]}")
        if p.shape == (2,):
            p = np.array([p[0], p[1], self.floor_height_at(p)])
        return p

    def floor_height_at(self, xy: np.ndarray) -> float:
        """Height of the room floor under ``xy`` (lowest floor level if no room contains it)."""
        from shapely import Point, Polygon

        for room in self.rooms:
            if Polygon(room.polygon).contains(Point(float(xy[0]), float(xy[1]))):
                return float(room.floor_z)
        floor = self.face_labels == SurfaceClass.FLOOR
        return float(self.mesh.vertices[self.mesh.faces[floor]][..., 2].min())

    # ------------------------------------------------------------------ areas and samples
    @property
    def face_areas(self) -> np.ndarray:
        """(F,) float: area of every face in m²."""
        return self.mesh.area_faces

    def class_areas(self) -> dict[SurfaceClass, float]:
        """Area in m² of every SurfaceClass (zero for absent classes)."""
        sums = np.bincount(self.face_labels, weights=self.face_areas, minlength=len(SurfaceClass))
        return {c: float(sums[c.value]) for c in SurfaceClass}

    def structural_mask(self) -> np.ndarray:
        """(F,) bool: faces that are FLOOR, CEILING or WALL (which of them face the interior:
        :func:`scenes.interior.interior_samples`)."""
        return np.isin(self.face_labels, [c.value for c in STRUCTURAL_CLASSES])

    def structural_area(self) -> float:
        """Area in m² of the structural elements: floor + ceiling + wall faces."""
        return float(self.face_areas[self.structural_mask()].sum())

    def structure_samples(self, spacing: float = 0.05) -> StructureSamples:
        """Deterministic points spread uniformly over the SE faces (those facing the interior:
        :func:`scenes.interior.interior_samples`).

        Parameters
        ----------
        spacing : float
            Nominal distance between samples in metres; one sample per ``spacing**2`` of area
            (0.05 m gives one per 25 cm²).

        Returns
        -------
        StructureSamples
            ``round(structural_area / spacing**2)`` samples; faces get counts in proportion to their
            area (running rounding, so small faces are not all dropped). Computed once per spacing
            and kept.
        """
        if not (np.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be a positive number of metres, got {spacing}")
        cache = self.__dict__.setdefault("_samples", {})
        key = ("all", float(spacing))
        if key not in cache:
            cache[key] = self._samples_of(spacing)
        return cache[key]

    def _samples_of(self, spacing: float) -> StructureSamples:
        faces = np.flatnonzero(self.structural_mask())
        areas = self.face_areas[faces]
        check_sample_count(self.name, float(areas.sum()), spacing)  # before any array of them is made
        # Running rounding keeps the total exact and gives tiny faces their share over many faces.
        cum = np.floor(np.cumsum(areas) / spacing**2 + 0.5).astype(np.int64)
        counts = np.diff(np.concatenate([[0], cum]))
        face_of = np.repeat(faces, counts)
        # Index of each sample within its face drives the R2 sequence.
        starts = np.repeat(cum - counts, counts)
        k = np.arange(len(face_of)) - starts + 0.5
        uv = np.mod(k[:, None] * _R2_A[None, :] + 0.5, 1.0)
        fold = uv.sum(axis=1) > 1.0
        uv[fold] = 1.0 - uv[fold]
        tri = self.mesh.vertices[self.mesh.faces[face_of]]
        points = tri[:, 0] + uv[:, :1] * (tri[:, 1] - tri[:, 0]) + uv[:, 1:] * (tri[:, 2] - tri[:, 0])
        return StructureSamples(
            points=points,
            labels=self.face_labels[face_of].copy(),
            rooms=self.face_rooms[face_of].copy(),
            faces=face_of,
        )

    # ------------------------------------------------------------------ convenience
    def room_by_name(self, name: str) -> Room:
        for room in self.rooms:
            if room.name == name:
                return room
        raise KeyError(f"{self.name}: no room named {name!r}; rooms: {[r.name for r in self.rooms]}")

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float: axis-aligned bounds of the mesh."""
        return np.asarray(self.mesh.bounds)

    def __repr__(self) -> str:
        areas = self.class_areas()
        return (
            f"Scene({self.name!r}, faces={len(self.mesh.faces)}, rooms={len(self.rooms)}, "
            f"doors={len(self.doors)}, wall={areas[SurfaceClass.WALL]:.1f} m², "
            f"floor={areas[SurfaceClass.FLOOR]:.1f} m²)"
        )
