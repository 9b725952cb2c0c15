"""The policy protocol: what ``nbs scan``, ``nbs compare`` and users' loops call."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from nbs_env.observation import CandidateColumn, candidate_table_of

__all__ = ["Policy", "mask_of"]


@runtime_checkable
class Policy(Protocol):
    """Chooses the next scan.

    ``act`` gets the observation and info of :class:`nbs_env.env.NBSEnv` and returns an index into
    the candidate list that the mask allows; ``reset`` forgets any state at the start of an episode.
    """

    name: str

    def reset(self) -> None: ...

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int: ...


def mask_of(obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
    """(K,) bool: the action mask, from ``info["action_mask"]`` or else the candidates' valid column."""
    if "action_mask" in info:
        return np.asarray(info["action_mask"], dtype=bool)
    return candidate_table_of(obs)[:, CandidateColumn.VALID] > 0.5
