"""Shared builders for tests: a small valid plan, a closed box room and its analytic ranges."""

from __future__ import annotations

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
