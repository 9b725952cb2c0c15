"""The floor of every comparison: a uniformly random valid candidate."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from policies.base import mask_of

__all__ = ["RandomPolicy"]


class RandomPolicy:
    """Picks uniformly among the candidates the mask allows.

    Parameters
    ----------
    rng : numpy.random.Generator or int, optional
        Its only source of randomness (a seed is turned into a Generator).
    """

    name = "random"
    #: It needs no setting and runs on any robot.
    config_overrides: ClassVar[dict[str, Any]] = {}
    requires: ClassVar[dict[str, Any]] = {}
    #: Runs our pipeline (RoI, SE classification); only the choice is random.
    structure_aware = True

    def __init__(self, rng: np.random.Generator | int | None = None) -> None:
        self._seed = rng
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)

    def reset(self) -> None:
        """Random keeps no episode state (its generator runs on across episodes)."""

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        """A uniformly random action among those the mask allows.

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            The env's observation; its ``"candidates"`` table's valid column ((K·5,) float32) is the
            mask when ``info`` has no ``"action_mask"``.
        info : dict of str to Any
            The env's ``info``; ``"action_mask"`` (n_actions,) bool, when given, is the mask (with
            ``rooms.completion="policy"`` it allows "room done" too).

        Returns
        -------
        int
            An index the mask allows.

        Raises
        ------
        ValueError
            The mask allows no action.
        """
        valid = np.flatnonzero(mask_of(obs, info))
        if not len(valid):
            raise ValueError("no valid action: the mask is all False")
        return int(self.rng.choice(valid))
