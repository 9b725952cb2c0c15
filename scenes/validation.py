"""Checks that a storey built from a plan can be scanned by the robot.

- **Reachable**: every room can be reached from the start through doors by a disc of radius
  :data:`~scenes.geometry.STOREY_CLEARANCE` (a robot's radius plus its safety distance) that touches
  no wall or clutter inside rooms. A door is crossed straight along its axis, so it needs only to be
  :data:`MIN_DOOR_WIDTH` wide (a 0.5 m wide robot plus 10 cm): doors of 0.8-1.0 m could never be
  crossed with 0.2 m of safety on each side, and the method drives to the door frame deliberately
  (METHOD §8); and at least :data:`MIN_DOOR_HEIGHT` high, the robot's height.
- **Free start**: the start keeps the same clearance.
- **Closed**: no ray cast from inside any room escapes the building.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from scenes._open3d import open3d
from scenes.errors import StoreyValidationError
from scenes.geometry import STOREY_CLEARANCE, inner_point
from scenes.model import Scene

__all__ = [
    "MIN_DOOR_HEIGHT",
    "MIN_DOOR_WIDTH",
    "count_escaping_rays",
    "fibonacci_sphere",
    "room_free_space",
    "start_within_check",
    "validate_plan_scene",
]

#: The narrowest door a valid storey may have, metres.
MIN_DOOR_WIDTH = 0.60
#: The lowest door a valid storey may have, metres: the robot's height (the column above the floor
#: its navigation keeps clear, ``NavigationConfig.robot_height``) and the lowest lintel its door
#: detection takes (``DoorConfig.min_height``).
MIN_DOOR_HEIGHT = 1.80


class ClutterLike(Protocol):
    """What validation reads of a piece of clutter; :class:`scenes.floorplan.ClutterPlan` is one."""

    def footprint(self) -> Polygon: ...


class PlanLike(Protocol):
    """What validation reads of a plan; :class:`scenes.floorplan.FloorPlan` is one.

    A shape rather than the class itself: scenes.floorplan imports this module to validate what it
    extrudes, so naming FloorPlan here would make the two modules import each other.
    """

    @property
    def wall_thickness(self) -> float: ...

    @property
    def clutter(self) -> Sequence[ClutterLike]: ...

    @property
    def start(self) -> tuple[float, float] | None: ...


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) float: unit vectors spread evenly over the sphere."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z**2)
    phi = np.pi * (1.0 + 5**0.5) * k
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def count_escaping_rays(scene: Scene, origins: np.ndarray, n_directions: int = 4096) -> np.ndarray:
    """For each origin, how many of ``n_directions`` rays hit nothing.

    Parameters
    ----------
    origins : (m, 3) float
        Ray origins.

    Returns
    -------
    (m,) int
    """
    o3d = open3d()
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(
        o3d.core.Tensor(scene.mesh.vertices.astype(np.float32)),
        o3d.core.Tensor(scene.mesh.faces.astype(np.uint32)),
    )
    dirs = fibonacci_sphere(n_directions)
    origins = np.asarray(origins, dtype=float).reshape(-1, 3)
    rays = np.concatenate([np.repeat(origins, len(dirs), axis=0), np.tile(dirs, (len(origins), 1))], axis=1).astype(
        np.float32
    )
    t_hit = rc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return (~np.isfinite(t_hit)).reshape(len(origins), len(dirs)).sum(axis=1)


def room_free_space(plan: PlanLike, scene: Scene, room: int, clearance: float = STOREY_CLEARANCE) -> Polygon:
    """Where the robot's centre may stand in ``room`` (shapely Polygon or MultiPolygon)."""
    clear = Polygon(scene.rooms[room].polygon)
    free = clear.buffer(-clearance, join_style="mitre")
    feet = [c.footprint() for c in plan.clutter if clear.buffer(1e-6).contains(c.footprint())]
    if feet:
        free = free.difference(shapely.union_all(feet).buffer(clearance))
    return free


def start_within_check(plan: PlanLike, scene: Scene) -> None:
    """Move a plan scene's chosen start into the free space :func:`validate_plan_scene` checks.

    :func:`scenes.geometry.auto_start` keeps a disc clear of the mesh; the check keeps the room's
    outline offset with mitred corners, which reaches farther into a concave corner. In a narrow
    room the first's point can lie outside the second (a plan with 1 m corridors refused its own
    start): the start then moves to the inside of the largest room's checked free space.
    """
    if not scene.rooms:
        return
    room = max(range(len(scene.rooms)), key=lambda i: scene.rooms[i].area)
    free = room_free_space(plan, scene, room)
    parts = [g for g in getattr(free, "geoms", [free]) if isinstance(g, Polygon) and not g.is_empty]
    if parts and not free.covers(Point(float(scene.start[0]), float(scene.start[1]))):
        p = inner_point(max(parts, key=lambda g: g.area))
        scene.start = (p.x, p.y)


def validate_plan_scene(plan: PlanLike, scene: Scene) -> None:
    """Raise :class:`StoreyValidationError` unless the storey is reachable, starts free and is closed."""
    name = scene.name
    parts: list[list[Polygon]] = []
    for i in range(len(scene.rooms)):
        free = room_free_space(plan, scene, i)
        parts.append([g for g in getattr(free, "geoms", [free]) if not g.is_empty])
        if not parts[-1]:
            raise StoreyValidationError(
                name, f"room {scene.rooms[i].name!r} has no space where the robot keeps {STOREY_CLEARANCE} m clearance"
            )

    def node_of(room: int, p: np.ndarray) -> tuple[int, int] | None:
        pt = Point(float(p[0]), float(p[1]))
        for k, g in enumerate(parts[room]):
            if g.covers(pt):
                return (room, k)
        return None

    adjacency: dict[tuple[int, int], set[tuple[int, int]]] = {}
    reach = plan.wall_thickness / 2 + STOREY_CLEARANCE + 0.05
    for j, door in enumerate(scene.doors):
        a, b = door.rooms
        if door.width < MIN_DOOR_WIDTH:
            raise StoreyValidationError(
                name, f"door doors[{j}] is {door.width} m wide; the robot needs {MIN_DOOR_WIDTH} m"
            )
        if door.height < MIN_DOOR_HEIGHT:  # 1.5 m doors were accepted, and the robot never left its first room
            raise StoreyValidationError(
                name, f"door doors[{j}] is {door.height} m high; the robot needs {MIN_DOOR_HEIGHT} m"
            )
        c = door.position[:2]
        na = node_of(a, c - door.normal * reach)
        nb = node_of(b, c + door.normal * reach)
        for room, node in ((a, na), (b, nb)):
            if node is None:
                raise StoreyValidationError(
                    name, f"door doors[{j}] cannot be approached from room {scene.rooms[room].name!r} (blocked)"
                )
        adjacency.setdefault(na, set()).add(nb)
        adjacency.setdefault(nb, set()).add(na)

    start = scene.start
    first = None
    inside = False
    for i, room in enumerate(scene.rooms):
        if Polygon(room.polygon).covers(Point(start[0], start[1])):
            inside = True
            first = node_of(i, start)
            break
    if first is None:
        shown = ", ".join(f"{float(v):g}" for v in np.round(start[:2], 3))
        raise StoreyValidationError(
            name,
            f"the start ({shown}) is not {STOREY_CLEARANCE} m clear of walls and clutter"
            if inside
            else f"the start ({shown}) lies in no room",
        )
    seen = {first}
    todo = [first]
    while todo:
        for nxt in adjacency.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    for i, room_parts in enumerate(parts):
        main = max(range(len(room_parts)), key=lambda k: room_parts[k].area)
        if (i, main) not in seen:
            split = ""
            if len(room_parts) > 1:
                # Its free space is in parts (clutter or a narrow waist cuts it): its largest is not reached.
                split = (
                    f" (clutter or a narrow waist cuts its free space into {len(room_parts)} parts, and its largest, "
                    f"{room_parts[main].area:.1f} m², is not the start's or a door's)"
                )
            where = ", ".join(f"{float(v):g}" for v in np.round(start[:2], 2))
            chosen = "; chosen, as the plan gives none" if plan.start is None else ""
            raise StoreyValidationError(
                name,
                f"room {scene.rooms[i].name!r} cannot be reached from the start ({where}{chosen}) through doors{split}",
            )

    origins = []
    for room_parts in parts:
        g = max(room_parts, key=lambda p: p.area).representative_point()
        origins.append([g.x, g.y, 1.5])
    escaped = count_escaping_rays(scene, np.array(origins))
    if escaped.any():
        i = int(np.argmax(escaped))
        raise StoreyValidationError(
            name, f"{int(escaped[i])} rays cast from inside room {scene.rooms[i].name!r} escape the building"
        )
