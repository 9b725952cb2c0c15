"""Plan-view geometry shared by the loaders: obstacle footprints and the automatic start position."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon
from shapely.ops import polylabel

from scenes.errors import StoreyValidationError
from scenes.labels import SurfaceClass

if TYPE_CHECKING:
    from scenes.model import Scene

__all__ = ["STOREY_CLEARANCE", "auto_start", "free_region", "obstacle_footprint", "point_is_free"]

#: The clear floor (m, from any obstacle) that a storey promises: automatic starts keep it, and
#: generated storeys are validated for it (every room reachable by a disc of this radius). It is a
#: property of the building, not of a robot: the robot's footprint is nbs_env's NavigationConfig,
#: whose defaults (0.25 m radius + 0.20 m safety distance, METHOD §6) need exactly this much, and the
#: robot's side passes its own clearance wherever it asks (a test keeps the two in step).
STOREY_CLEARANCE = 0.45

# The robot collides with anything between just above the floor and the scanner head.
_BODY_Z = (0.05, 1.8)


def obstacle_footprint(
    scene: Scene, floor_z: float, region: Polygon | None = None, margin: float = 0.0
) -> Polygon | MultiPolygon:
    """Plan-view footprint of everything the robot would bump into on the floor at ``floor_z``.

    Parameters
    ----------
    scene : Scene
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
        the robot's body height.
    """
    keep = ~np.isin(scene.face_labels, [SurfaceClass.FLOOR, SurfaceClass.CEILING])
    tri = scene.mesh.vertices[scene.mesh.faces[keep]]
    z = tri[..., 2]
    keep_z = (z.max(axis=1) > floor_z + _BODY_Z[0]) & (z.min(axis=1) < floor_z + _BODY_Z[1])
    tri = tri[keep_z][..., :2]
    if region is not None and len(tri):
        x0, y0, x1, y1 = region.buffer(margin).bounds if margin > 0 else region.bounds
        lo, hi = tri.min(axis=1), tri.max(axis=1)
        tri = tri[(hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)]
    if len(tri) == 0:
        return Polygon()
    # Vertical faces project to slivers of zero area; their closed outlines (as lines) keep them.
    rings = shapely.linestrings(np.concatenate([tri, tri[:, :1]], axis=1))
    solid = shapely.polygons(tri)
    return shapely.union_all(np.concatenate([shapely.buffer(rings, 1e-3), solid[shapely.area(solid) > 1e-8]]))


def free_region(scene: Scene, region: Polygon, floor_z: float, clearance: float) -> Polygon | MultiPolygon:
    """Where a disc of radius ``clearance`` (m) may stand inside ``region`` without touching an obstacle."""
    obstacles = obstacle_footprint(scene, floor_z, region, margin=clearance)
    free = region.buffer(-clearance)
    if not obstacles.is_empty:
        free = free.difference(obstacles.buffer(clearance))
    return free


def _largest(geom: Polygon | MultiPolygon) -> Polygon:
    parts = [g for g in getattr(geom, "geoms", [geom]) if isinstance(g, Polygon) and not g.is_empty]
    return max(parts, key=lambda g: g.area) if parts else Polygon()


def auto_start(scene: Scene, clearance: float = STOREY_CLEARANCE) -> np.ndarray:
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
    p = polylabel(free, tolerance=0.01)
    if not free.contains(p):
        p = free.representative_point()
    return np.array([p.x, p.y, floor_z])


def point_is_free(scene: Scene, xy: np.ndarray, floor_z: float, clearance: float) -> bool:
    """Whether a disc of radius ``clearance`` (m) centred at ``xy`` touches no obstacle."""
    probe = Point(float(xy[0]), float(xy[1])).buffer(clearance)
    return not obstacle_footprint(scene, floor_z, probe).intersects(probe)
