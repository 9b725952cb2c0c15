"""Geometry shared by the loaders: polygon faces as triangles, obstacle footprints and the automatic
start position."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon
from shapely.ops import polylabel

from scenes.errors import StoreyValidationError
from scenes.labels import SurfaceClass

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "STOREY_CLEARANCE",
    "CrossingPolygonError",
    "auto_start",
    "free_region",
    "inner_point",
    "obstacle_footprint",
    "point_is_free",
    "split_long_faces",
    "triangulate_polygons",
]

#: The clear floor (m, from any obstacle) that a storey promises: automatic starts keep it, and
#: generated storeys are validated for it (every room reachable by a disc of this radius). It is a
#: property of the building, not of a robot: the robot's footprint is nbs_env's NavigationConfig,
#: whose defaults (0.25 m radius + 0.20 m safety distance, METHOD §6) need exactly this much, and the
#: robot's side passes its own clearance wherever it asks (a test keeps the two in step).
STOREY_CLEARANCE = 0.45

# The robot collides with anything between just above the floor and the scanner head.
_BODY_Z = (0.05, 1.8)


class RoomLike(Protocol):
    """What :func:`auto_start` reads of a room; :class:`scenes.model.Room` is one."""

    @property
    def name(self) -> str: ...

    @property
    def polygon(self) -> np.ndarray: ...

    @property
    def floor_z(self) -> float: ...

    @property
    def area(self) -> float: ...


class SceneLike(Protocol):
    """What the functions here read of a building; :class:`scenes.model.Scene` is one.

    A shape rather than the class itself: scenes.model imports this module for ``Scene.start``, so
    naming Scene here would make the two modules import each other.
    """

    @property
    def name(self) -> str: ...

    @property
    def mesh(self) -> trimesh.Trimesh: ...

    @property
    def face_labels(self) -> np.ndarray: ...

    @property
    def rooms(self) -> Sequence[RoomLike]: ...


def obstacle_footprint(
    scene: SceneLike, floor_z: float, region: Polygon | None = None, margin: float = 0.0
) -> Polygon | MultiPolygon:
    """Plan-view footprint of everything the robot would bump into on the floor at ``floor_z``.

    Parameters
    ----------
    scene : SceneLike
        The building (ground truth: only loaders and validation call this).
    floor_z : float
        Height of the floor the robot stands on.
    region : shapely Polygon, optional
        Only faces whose plan projection meets this region's bounds, grown by ``margin``, are
        considered (speed).
    margin : float
        Metres.

    Returns
    -------
    shapely geometry
        Union of the projected outlines of every non-floor, non-ceiling face whose z-range meets
        the robot's body height, each clipped to that height first.
    """
    keep = ~np.isin(scene.face_labels, [SurfaceClass.FLOOR, SurfaceClass.CEILING])
    tri = scene.mesh.vertices[scene.mesh.faces[keep]]
    lo_z, hi_z = floor_z + _BODY_Z[0], floor_z + _BODY_Z[1]
    z = tri[..., 2]
    tri = tri[(z.max(axis=1) > lo_z) & (z.min(axis=1) < hi_z)]
    if region is not None and len(tri):
        x0, y0, x1, y1 = region.buffer(margin).bounds if margin > 0 else region.bounds
        lo, hi = tri[..., :2].min(axis=1), tri[..., :2].max(axis=1)
        tri = tri[(hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)]
    if len(tri) == 0:
        return Polygon()
    # A face that only dips into the body's height band (a rafter's side, a stair's string) is an
    # obstacle only where it does: what is projected is the face clipped to the band, which is the
    # convex hull of its corners inside the band and its edges' crossings of the band's two planes.
    z = tri[..., 2]
    partial = (z.min(axis=1) < lo_z) | (z.max(axis=1) > hi_z)
    flat = tri[~partial][..., :2]
    parts = []
    if len(flat):
        # Vertical faces project to slivers of zero area; their closed outlines (as lines) keep them.
        rings = shapely.linestrings(np.concatenate([flat, flat[:, :1]], axis=1))
        solid = shapely.polygons(flat)
        parts += [shapely.buffer(rings, 1e-3), solid[shapely.area(solid) > 1e-8]]
    if partial.any():
        parts.append(shapely.buffer(_clipped_hulls(tri[partial], lo_z, hi_z), 1e-3))
    return shapely.union_all(np.concatenate(parts)) if parts else Polygon()


def _clipped_hulls(tri: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Plan projections (shapely geometries) of the (n, 3, 3) triangles clipped to lo <= z <= hi."""
    candidates, owners = [], []
    index = np.arange(len(tri))
    inside = (tri[..., 2] >= lo) & (tri[..., 2] <= hi)
    for k in range(3):
        candidates.append(tri[inside[:, k], k, :2])
        owners.append(index[inside[:, k]])
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        dz = b[:, 2] - a[:, 2]
        for level in (lo, hi):
            safe = np.where(dz != 0, dz, 1.0)
            t = np.where(dz != 0, (level - a[:, 2]) / safe, -1.0)
            crossing = (t > 0) & (t < 1)
            candidates.append((a + t[:, None] * (b - a))[crossing, :2])
            owners.append(index[crossing])
    points = np.concatenate(candidates)
    owner = np.concatenate(owners)
    order = np.argsort(owner, kind="stable")
    groups = shapely.multipoints(points[order], indices=owner[order])
    return shapely.convex_hull(groups)


def free_region(scene: SceneLike, region: Polygon, floor_z: float, clearance: float) -> Polygon | MultiPolygon:
    """Where a disc of radius ``clearance`` (m) may stand inside ``region`` without touching an obstacle."""
    obstacles = obstacle_footprint(scene, floor_z, region, margin=clearance)
    free = region.buffer(-clearance)
    if not obstacles.is_empty:
        free = free.difference(obstacles.buffer(clearance))
    return free


def _largest(geom: Polygon | MultiPolygon) -> Polygon:
    parts = [g for g in getattr(geom, "geoms", [geom]) if isinstance(g, Polygon) and not g.is_empty]
    return max(parts, key=lambda g: g.area) if parts else Polygon()


def auto_start(scene: SceneLike, clearance: float = STOREY_CLEARANCE) -> np.ndarray:
    """A free point well inside the largest room: the pole of inaccessibility of its free space.

    Uses the ground-truth rooms when the scene has them, else the largest connected floor area.
    The point keeps ``clearance`` metres from every obstacle.

    Returns
    -------
    (3,) float
        (x, y, floor z).

    Raises
    ------
    StoreyValidationError
        When the largest room has no point with the robot's clearance.
    """
    if scene.rooms:
        room = max(scene.rooms, key=lambda r: r.area)
        region, floor_z, label = Polygon(room.polygon), room.floor_z, f"room {room.name!r}"
    else:
        floor = scene.face_labels == SurfaceClass.FLOOR
        tri = scene.mesh.vertices[scene.mesh.faces[floor]]
        floor_z = float(tri[..., 2].min())
        low = tri[..., 2].max(axis=1) < floor_z + 0.3
        polys = shapely.polygons(tri[low][..., :2])
        region = _largest(shapely.union_all(polys[shapely.area(polys) > 1e-10]).buffer(0))
        label = "the largest floor area"
    if region.is_empty:
        raise StoreyValidationError(scene.name, "cannot choose a start: no floor area")
    free = _largest(free_region(scene, region, floor_z, clearance))
    if free.is_empty:
        raise StoreyValidationError(
            scene.name, f"cannot choose a start: {label} has no point {clearance} m clear of obstacles"
        )
    p = inner_point(free)
    return np.array([p.x, p.y, floor_z])


def inner_point(region: Polygon) -> Point:
    """The point of ``region`` farthest from its edges (its pole of inaccessibility, to 1 cm), or a
    point inside it where that lies outside (a pole of a thin region may)."""
    p = polylabel(region, tolerance=0.01)
    return p if region.contains(p) else region.representative_point()


def point_is_free(scene: SceneLike, xy: np.ndarray, floor_z: float, clearance: float) -> bool:
    """Whether a disc of radius ``clearance`` (m) centred at ``xy`` touches no obstacle."""
    probe = Point(float(xy[0]), float(xy[1])).buffer(clearance)
    return not obstacle_footprint(scene, floor_z, probe).intersects(probe)


def split_long_faces(
    vertices: np.ndarray, faces: np.ndarray, max_edge: float, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bisect the longest edge of every face (of those in ``mask``) longer than ``max_edge``.

    Returns the new vertices (V', 3), faces (F', 3) and, per new face, the index of the face it came
    from (F',); the first F faces keep their indices. Bisecting only the longest edge splits a long
    thin face into about ``length / max_edge`` pieces, where splitting into four would make slivers
    by the thousand.
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.array(faces, dtype=np.int64)
    origin = np.arange(len(faces))
    eligible = np.ones(len(faces), bool) if mask is None else np.asarray(mask, bool).copy()
    for _ in range(64):
        tri = vertices[faces]
        lengths = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)  # edge k runs from corner k to k+1
        longest = lengths.argmax(axis=1)
        split = eligible & (lengths[np.arange(len(faces)), longest] > max_edge)
        if not split.any():
            break
        idx = np.flatnonzero(split)
        k = longest[idx]
        a = faces[idx, k]
        b = faces[idx, (k + 1) % 3]
        c = faces[idx, (k + 2) % 3]
        mid = np.arange(len(vertices), len(vertices) + len(idx))
        vertices = np.concatenate([vertices, 0.5 * (vertices[a] + vertices[b])])
        # (a, m, c) and (m, b, c) keep the winding of (a, b, c).
        faces[idx] = np.column_stack([a, mid, c])
        faces = np.concatenate([faces, np.column_stack([mid, b, c])])
        origin = np.concatenate([origin, origin[idx]])
        eligible = np.concatenate([eligible, np.ones(len(idx), bool)])
    return vertices, faces, origin


class CrossingPolygonError(ValueError):
    """A polygon face whose outline crosses itself: no triangulation of it is the surface meant.
    ``index`` is the polygon's position in the list given."""

    def __init__(self, index: int) -> None:
        super().__init__(f"polygon {index} crosses itself")
        self.index = index


def triangulate_polygons(vertices: np.ndarray, polygons: Sequence[Sequence[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of faces given as polygons of vertex indices (OBJ's and PLY's faces).

    A convex polygon is fanned from its first corner, as every reader does. A concave one (an
    L-shaped slab written as one face) is triangulated by ear clipping in its plane
    (``mapbox_earcut``), as Blender and Assimp do: the fan covered what lies outside it, and an L
    floor read so was a third larger, silently. A corner repeated next to itself (a collapsed edge)
    is one corner; a polygon left with fewer than 3 has no surface and no triangle.

    Parameters
    ----------
    vertices : (V, 3) float
    polygons : sequence of sequences of int
        Each of 3 or more indices into ``vertices``. A polygon with an index outside them is fanned
        (the caller's index check names it).

    Returns
    -------
    triangles : (T, 3) int64
        Each polygon's triangles together, in the polygons' order.
    source : (T,) int64
        The polygon each triangle comes from.

    Raises
    ------
    CrossingPolygonError
        A polygon whose outline crosses or overlaps itself (a bow-tie, a star, a ring written twice).
    """
    vertices = np.asarray(vertices, dtype=float)
    lengths = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    parts_tris, parts_src = [], []
    for n in np.unique(lengths):
        rows = np.flatnonzero(lengths == n)
        same = len(rows) == len(polygons)  # one size (triangles, or quads), the common file: no gather
        corners = np.array(polygons if same else [polygons[i] for i in rows], dtype=np.int64).reshape(len(rows), n)
        if n > 3:
            special = _not_simply_convex(vertices, corners)
            for r in np.flatnonzero(special):
                tris = corners[r][_one_polygon(vertices, corners[r], int(rows[r]))]
                parts_tris.append(tris)
                parts_src.append(np.full(len(tris), rows[r]))
            corners, rows = corners[~special], rows[~special]
        fan = np.arange(1, n - 1)
        tris = np.stack([np.repeat(corners[:, :1], n - 2, axis=1), corners[:, fan], corners[:, fan + 1]], axis=2)
        parts_tris.append(tris.reshape(-1, 3))
        parts_src.append(np.repeat(rows, n - 2))
    if not parts_tris:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    if len(parts_tris) == 1:
        return parts_tris[0], parts_src[0]
    tris, src = np.concatenate(parts_tris), np.concatenate(parts_src)
    order = np.argsort(src, kind="stable")
    return tris[order], src[order]


def _not_simply_convex(vertices: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(m,) bool: which polygons of ``corners`` (m, n) a fan would not cover exactly: a corner
    repeated next to itself, a turn against the polygon's own normal (concave), or turns that add up
    to more than one round (a star, a ring written twice), or none (a bow-tie's lobes cancel)."""
    inside = (corners >= 0).all(axis=1) & (corners < len(vertices)).all(axis=1)
    repeated = (corners == np.roll(corners, -1, axis=1)).any(axis=1)
    p = vertices[np.where(inside[:, None], corners, 0)]
    # Coordinates no storey has (1e300, inf) overflow here: such a polygon is fanned, and the
    # storey's size check names the coordinates.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        edges = np.roll(p, -1, axis=1) - p
        normal = np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1)  # Newell's: twice the vector area
        length = np.linalg.norm(normal, axis=1)
        bends = np.cross(np.roll(edges, 1, axis=1), edges)
        turns = np.einsum("mij,mj->mi", bends, normal)
        longest = np.einsum("mij,mij->mi", edges, edges).max(axis=1)
        scale = longest * length
        concave = (turns < -1e-9 * scale[:, None]).any(axis=1)
        angles = np.arctan2(turns / length[:, None], np.einsum("mij,mij->mi", np.roll(edges, 1, axis=1), edges))
        rounds = np.abs(angles.sum(axis=1)) / (2 * np.pi)
        bent = np.linalg.norm(bends, axis=2).max(axis=1) > 1e-12 * longest
        # A flat polygon with corners that bend (its lobes cancel) or one that goes round twice.
        overturned = (length <= 1e-12 * scale + 1e-300) & bent | (rounds > 1.5)
    return inside & (repeated | concave | overturned)


def _one_polygon(vertices: np.ndarray, corners: np.ndarray, index: int) -> np.ndarray:
    """(k, 3) local corner indices of one polygon that is no plain convex one (:func:`_not_simply_convex`)."""
    keep = corners != np.roll(corners, -1)
    local = np.flatnonzero(keep) if not keep.all() else np.arange(len(corners))
    if len(local) < 3:  # collapsed to an edge or a point: no surface
        return np.zeros((0, 3), np.int64)
    if len(local) == 3:
        return local[None, :]
    points = vertices[corners[local]]
    if not _not_simply_convex(vertices, corners[local][None, :])[0]:
        fan = np.arange(1, len(local) - 1)
        return np.column_stack([np.full(len(fan), local[0]), local[fan], local[fan + 1]])
    return local[_ear_clipped(points, index)]


def _ear_clipped(points: np.ndarray, index: int) -> np.ndarray:
    """(n-2, 3) local corner indices of one concave polygon's triangles, by ear clipping in its plane."""
    import mapbox_earcut

    normal = np.cross(points, np.roll(points, -1, axis=0)).sum(axis=0)
    if not np.linalg.norm(normal) > 0:  # its lobes cancel: a bow-tie
        raise CrossingPolygonError(index)
    normal /= np.linalg.norm(normal)
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    flat = np.column_stack([points @ u, points @ v])
    if not Polygon(flat).is_valid:
        raise CrossingPolygonError(index)
    found = np.asarray(
        mapbox_earcut.triangulate_float64(flat, np.array([len(points)], dtype=np.uint32)), dtype=np.int64
    ).reshape(-1, 3)
    if len(found) != len(points) - 2:
        raise CrossingPolygonError(index)
    # earcut winds its triangles its own way: turned to the polygon's, so the faces keep their normal
    a, b, c = (flat[found[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    found[cross < 0] = found[cross < 0][:, ::-1]
    return found
