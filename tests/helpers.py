"""Shared builders for tests: a small valid plan, a closed box room and its analytic ranges."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from scenes import FloorPlan, RoomPlan, Scene


def two_room_plan() -> dict:
    """A small valid two-room plan as a JSON dict, to be broken by the bad-input tests."""
    return {
        "format": "nbs-floorplan",
        "version": 1,
        "name": "two_rooms",
        "ceiling_height": 2.6,
        "wall_thickness": 0.2,
        "rooms": [
            {"name": "a", "polygon": [[0, 0], [5, 0], [5, 4], [0, 4]]},
            {"name": "b", "polygon": [[5, 0], [9, 0], [9, 4], [5, 4]]},
        ],
        "doors": [{"rooms": ["a", "b"], "position": [5, 2], "width": 0.9, "height": 2.0}],
        "clutter": [{"kind": "cabinet", "position": [1.0, 3.6], "size": [1.2, 0.5, 1.9], "yaw": 0}],
        "start": [2.0, 1.5],
    }


def box_room(a: float, b: float, h: float, wall: float = 0.2) -> Scene:
    """An empty room whose clear inside is [0, a] x [0, b] x [0, h]."""
    t = wall
    plan = FloorPlan(
        rooms=(RoomPlan("box", ((-t / 2, -t / 2), (a + t / 2, -t / 2), (a + t / 2, b + t / 2), (-t / 2, b + t / 2))),),
        ceiling_height=h,
        wall_thickness=t,
        start=(a / 2, b / 2),
    )
    return plan.to_scene()


def box_ranges(origin: np.ndarray, directions: np.ndarray, size: tuple[float, float, float]) -> np.ndarray:
    """(n,) float: distance from ``origin`` inside [0, size] to the box's faces along each direction."""
    hi = np.asarray(size, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(directions > 0, (hi - origin) / directions, np.where(directions < 0, -origin / directions, np.inf))
    return t.min(axis=1)


def _wall_boxes(p0, p1, thickness: float, height: float, openings=()) -> list:
    """Boxes of a straight wall from ``p0`` to ``p1`` (centre line), with (start, end, top) openings
    measured along it from ``p0``: full-height pieces between them and a lintel over each."""
    import trimesh

    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    length = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / length
    yaw = float(np.arctan2(u[1], u[0]))

    def box(a: float, b: float, z0: float, z1: float):
        centre = p0 + u * (a + b) / 2
        transform = trimesh.transformations.rotation_matrix(yaw, [0, 0, 1])
        transform[:3, 3] = [centre[0], centre[1], (z0 + z1) / 2]
        return trimesh.creation.box(extents=(b - a, thickness, z1 - z0), transform=transform)

    pieces, at = [], -thickness / 2
    for start, end, top in sorted(openings):
        if start > at:
            pieces.append(box(at, start, 0.0, height))
        pieces.append(box(start, end, top, height))
        at = end
    if length + thickness / 2 > at:
        pieces.append(box(at, length + thickness / 2, 0.0, height))
    return pieces


def boxed_storey(walls, floors, ceilings, clutter=(), start=(1.5, 2.0), name="boxed") -> Scene:
    """A storey built directly with trimesh boxes, not by our floor-plan extruder.

    walls : [(p0, p1, openings)] centre lines 0.2 m thick, 2.6 m high; floors and ceilings:
    [(x0, y0, x1, y1)] slabs 0.2 m thick under z=0 and over z=2.6; clutter: [(x0, y0, x1, y1, h)].
    """
    import trimesh

    from scenes import SurfaceClass

    parts: list[tuple[object, SurfaceClass]] = []
    for p0, p1, openings in walls:
        parts += [(b, SurfaceClass.WALL) for b in _wall_boxes(p0, p1, 0.2, 2.6, openings)]
    for (x0, y0, x1, y1), z, cls in [(f, -0.1, SurfaceClass.FLOOR) for f in floors] + [
        (c, 2.7, SurfaceClass.CEILING) for c in ceilings
    ]:
        slab = trimesh.creation.box(extents=(x1 - x0, y1 - y0, 0.2))
        slab.apply_translation([(x0 + x1) / 2, (y0 + y1) / 2, z])
        parts.append((slab, cls))
    for x0, y0, x1, y1, h in clutter:
        item = trimesh.creation.box(extents=(x1 - x0, y1 - y0, h))
        item.apply_translation([(x0 + x1) / 2, (y0 + y1) / 2, h / 2])
        parts.append((item, SurfaceClass.CLUTTER))
    mesh = trimesh.util.concatenate([m for m, _ in parts])
    labels = np.concatenate([np.full(len(m.faces), c.value) for m, c in parts])
    return Scene(mesh, labels, start=start, name=name)


@contextmanager
def time_limit(seconds: int) -> Iterator[None]:
    """A ``TimeoutError`` if the block runs longer than ``seconds`` (SIGALRM: the main thread, POSIX):
    the property tests count a loader or a command that does not answer in time as a hang."""

    def expire(*_):
        raise TimeoutError(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
