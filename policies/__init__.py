"""Who decides where to scan next: the greedy NBS of the paper, the compared methods, learned agents.

Policies see only what the robot measured (its voxel labels, candidates and pose estimate), never a
scene's ground truth; the one exception is the documented ``oracle`` yardstick.

Every policy follows :class:`policies.base.Policy`: ``reset()``, ``act(obs, info) -> int``.
:func:`make_policy` builds one by name.
"""

from __future__ import annotations

from policies.base import Policy
from policies.greedy import GreedyPolicy
from policies.random import RandomPolicy

__all__ = ["POLICIES", "GreedyPolicy", "Policy", "RandomPolicy", "UnknownPolicyError", "make_policy"]

#: Policy names → factories taking a seed.
POLICIES = {
    "greedy": lambda seed: GreedyPolicy(),
    "random": lambda seed: RandomPolicy(seed),
}


class UnknownPolicyError(ValueError):
    """A policy name that is not registered."""


def make_policy(name: str, seed: int | None = None) -> Policy:
    """A policy by name (see :data:`POLICIES`)."""
    if name not in POLICIES:
        raise UnknownPolicyError(f"unknown policy {name!r}; policies: {', '.join(POLICIES)}")
    return POLICIES[name](seed)
