"""The paper's next-best-scan: the candidate with the most predicted Occluded-structure→Structure
conversions, ties to the shorter path (paper §4, METHOD §7).

The gain and the order are the planner's (:mod:`nbs_env.planning.planner`); this module only
chooses by them, in an env loop (:class:`GreedyPolicy`) or on a storey session directly
(:func:`scan_storey`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nbs_env.observation import CandidateColumn, candidate_table_of
from nbs_env.planning.planner import greedy_order
from nbs_env.storey import Storey
from policies.base import mask_of

__all__ = ["GreedyPolicy", "scan_storey"]


class GreedyPolicy:
    """The paper's NBS as a policy: argmax of ``info["candidate_gains"]`` (predicted conversions the
    env computes from the robot's own voxel grid) over the mask, ties to the shorter path.

    In an env with ``rooms.completion="policy"`` (a "room done" action after the K candidates) it
    declares the room done where the gain rule would end it (``info["gain_rule_done"]``), so that it
    scans as with ``rooms.completion="gain"``.

    Parameters
    ----------
    near : float
        In (0, 1]. Below 1, a gain-travel trade-off (``greedy:NEAR`` by name): the candidate with
        the shortest path among those predicting at least ``near`` × the best gain, ties to the
        larger gain. 1 (the default) is the paper's rule. Not the paper's method: it measures how
        much of the greedy's path a choice of positions can save (docs/experiments/learning.md).
    stop : float, optional
        In [0, 1). The completion fraction the greedy's rooms end at (``greedy:stop=0.08`` by name):
        the gain rule (:attr:`nbs_env.config.RoomRules.completion_fraction`, 0.03 by default) with
        this fraction instead, through :attr:`config_overrides`. Larger fractions end
        rooms sooner: the greedy's own trade of coverage for scans, against which a policy that
        ends rooms itself is measured (docs/experiments/learning.md). None (the default): the robot's.
    """

    #: Keeps only the SE points (the paper's processed-point measure).
    structure_aware = True

    def __init__(self, near: float = 1.0, stop: float | None = None) -> None:
        near = float(near)
        if not 0.0 < near <= 1.0:
            raise ValueError(f"near must be in (0, 1], got {near}")
        options = [] if near == 1.0 else [f"{near:g}"]
        #: What it runs with (:func:`policies.config_for` applies it): its own stopping fraction.
        self.config_overrides: dict[str, Any] = {}
        #: The greedy runs on any robot.
        self.requires: dict[str, Any] = {}
        if stop is not None:
            stop = float(stop)
            if not 0.0 <= stop < 1.0:
                raise ValueError(f"stop must be in [0, 1), got {stop}")
            self.config_overrides = {"rooms.completion_fraction": stop}
            options.append(f"stop={stop:g}")
        self.near = near
        self.stop = stop
        self.name = "greedy" if not options else "greedy:" + "+".join(options)

    def reset(self) -> None:
        """The greedy keeps no state."""

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        """The allowed candidate with the most predicted conversions, ties to the shorter path (with
        ``near`` < 1: the shortest path among those near the best gain); "room done" where the gain
        rule ends the room.

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            The env's observation; the greedy reads the path lengths of its ``"candidates"`` table
            ((K·5,) float32), and its valid column when ``info`` has no ``"action_mask"``.
        info : dict of str to Any
            The env's ``info``: ``"candidate_gains"`` (K,) int64, ``"action_mask"`` (n_actions,) bool
            (optional), and ``"gain_rule_done"`` bool where there is a "room done" action.

        Returns
        -------
        int
            A candidate index in [0, K); K ("room done") when the mask has that action and
            ``info["gain_rule_done"]`` is True or no candidate is allowed.

        Raises
        ------
        KeyError
            ``info`` lacks ``"candidate_gains"``, or lacks ``"gain_rule_done"`` where there is a
            "room done" action.
        """
        if "candidate_gains" not in info:
            raise KeyError("GreedyPolicy needs info['candidate_gains'], which NBSEnv's reset and step provide")
        mask = mask_of(obs, info)
        gains = np.asarray(info["candidate_gains"])
        k = len(gains)
        if len(mask) > k:  # completion="policy": action k is "room done"
            if "gain_rule_done" not in info:
                raise KeyError("GreedyPolicy needs info['gain_rule_done'] to end rooms, which NBSEnv provides")
            if info["gain_rule_done"] or not mask[:k].any():
                return k
        path = candidate_table_of(obs)[:, CandidateColumn.PATH_LENGTH]
        if self.near == 1.0 or not mask[:k].any():
            return int(greedy_order(gains, path, mask[:k])[0])
        gains = gains.astype(float)
        near = np.flatnonzero(mask[:k] & (gains >= self.near * gains[mask[:k]].max()))
        return int(near[np.lexsort((-gains[near], path[near]))[0]])


def scan_storey(storey: Storey, max_rooms: int | None = None) -> int:
    """Scan a storey session greedily until it ends (complete or out of budget), with no env.

    Parameters
    ----------
    storey : Storey
        A session with gain completion (``rooms.completion="gain"``).
    max_rooms : int, optional
        Stop once this many rooms are done.

    Returns
    -------
    int
        The scans taken here.
    """
    before = len(storey.scans)
    while storey.open and (max_rooms is None or storey.rooms_done < max_rooms):
        storey.scan_at(storey.plan.best())
    return len(storey.scans) - before
