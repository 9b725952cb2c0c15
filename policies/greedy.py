"""The paper's next-best-scan: the candidate with the most predicted Occluded-structure→Structure
conversions, ties to the shorter path (paper §4, METHOD §7)."""

from __future__ import annotations

from typing import Any

import numpy as np

from nbs_env.env import candidate_table_of
from nbs_env.planning.navigation import Candidates
from nbs_env.planning.visibility import greedy_order
from nbs_env.robot import Robot
from policies.base import mask_of

__all__ = ["GreedyPolicy", "greedy_index", "scan_room"]


def greedy_index(cands: Candidates, gains: np.ndarray) -> int:
    """Index of the next best scan among the valid candidates."""
    return int(greedy_order(gains[: cands.count], cands.path_length[: cands.count])[0])


class GreedyPolicy:
    """The paper's NBS as a policy: argmax of ``info["candidate_gains"]`` (predicted conversions the
    env computes from the robot's own voxel grid) over the mask, ties to the shorter path."""

    name = "greedy"
    #: Keeps only the SE points (the paper's processed-point measure).
    structure_aware = True

    def reset(self) -> None:
        """The greedy keeps no state."""

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        if "candidate_gains" not in info:
            raise KeyError("GreedyPolicy needs info['candidate_gains'], which NBSEnv's reset and step provide")
        mask = mask_of(obs, info)
        path = candidate_table_of(obs)[:, 2]
        return int(greedy_order(info["candidate_gains"], path, mask)[0])


def scan_room(robot: Robot, max_scans: int | None = None) -> int:
    """Scan the robot's current room greedily until it is complete; returns the scans taken.

    ``max_scans`` caps the robot's total number of stops (on top of the room's own scan cap).
    """
    taken = 0
    while not robot.room_complete() and (max_scans is None or len(robot.stops) < max_scans):
        robot.move_to(greedy_index(*robot.candidates()))
        taken += 1
    return taken
