"""The paper's next-best-scan: the candidate with the most predicted Occluded-structure→Structure
conversions, ties to the shorter path (paper §4, METHOD §7)."""

from __future__ import annotations

import numpy as np

from nbs_env.planning.navigation import Candidates
from nbs_env.planning.visibility import greedy_order
from nbs_env.robot import Robot

__all__ = ["greedy_index", "scan_room"]


def greedy_index(cands: Candidates, gains: np.ndarray) -> int:
    """Index of the next best scan among the valid candidates."""
    return int(greedy_order(gains[: cands.count], cands.path_length[: cands.count])[0])


def scan_room(robot: Robot, max_scans: int | None = None) -> int:
    """Scan the robot's current room greedily until it is complete; returns the scans taken.

    ``max_scans`` caps the robot's total number of stops (on top of the room's own scan cap).
    """
    taken = 0
    while not robot.room_complete() and (max_scans is None or len(robot.stops) < max_scans):
        robot.move_to(greedy_index(*robot.candidates()))
        taken += 1
    return taken
