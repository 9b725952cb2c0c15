"""Who decides where to scan next: the greedy NBS of the paper, the compared methods, learned agents.

Policies see only what the robot measured (its voxel labels, candidates and pose estimate), never a
scene's ground truth; the one exception is the documented ``oracle`` yardstick.

Every policy follows :class:`policies.base.Policy`: ``reset()``, ``act(obs, info) -> int``, and
what it runs with (``config_overrides``) and requires of the robot (``requires``).
:func:`make_policy` builds one by name.
"""

from __future__ import annotations

import numpy as np

from nbs_env import lazy_getattr
from nbs_env.config.checks import parse_float
from nbs_env.errors import ConfigError
from policies.base import Policy, agreed_requirements, config_for
from policies.greedy import GreedyPolicy
from policies.random import RandomPolicy

__all__ = [
    "POLICIES",
    "BlaerAllenPolicy",
    "GreedyPolicy",
    "InformationGainPolicy",
    "LearnedPolicy",
    "NearestFrontierPolicy",
    "Policy",
    "PotthastSukhatmePolicy",
    "RandomPolicy",
    "StachnissBurgardPolicy",
    "UnknownPolicyError",
    "agreed_requirements",
    "config_for",
    "make_policy",
]

#: Policy classes whose modules are imported on first use (the compared methods' maps and torch for
#: the learned policy cost about a second; most users of this package need neither).
_LAZY = {
    "BlaerAllenPolicy": "policies.baselines",
    "InformationGainPolicy": "policies.baselines",
    "NearestFrontierPolicy": "policies.baselines",
    "PotthastSukhatmePolicy": "policies.baselines",
    "StachnissBurgardPolicy": "policies.baselines",
    "LearnedPolicy": "policies.learned",
}


__getattr__ = lazy_getattr(__name__, _LAZY)


class UnknownPolicyError(ValueError):
    """A policy name that is not registered, or an option the policy does not take."""


def _no_option(name: str, option: str | None) -> None:
    if option:
        raise UnknownPolicyError(f"policy {name!r} takes no option, got {name}:{option}")


def _greedy(seed: int | None, option: str | None = None):
    if not option:
        return GreedyPolicy()
    usage = (
        "greedy takes NEAR, the share of the best gain a nearer candidate must reach, a number in (0, 1] "
        "(greedy:0.8), and stop=FRACTION, the completion fraction its rooms end at, in [0, 1) "
        f"(greedy:stop=0.08), joined by + (greedy:0.8+stop=0.08); got greedy:{option}"
    )
    kwargs: dict[str, float] = {}
    for part in option.split("+"):
        key, equals, value = part.rpartition("=")
        key = key if equals else "near"
        if key not in ("near", "stop") or key in kwargs:
            raise UnknownPolicyError(usage)
        try:
            kwargs[key] = parse_float(value)
        except ValueError:
            raise UnknownPolicyError(usage) from None
    try:
        return GreedyPolicy(**kwargs)
    except ValueError:
        raise UnknownPolicyError(usage) from None


def _random(seed: int | None, option: str | None = None):
    _no_option("random", option)
    return RandomPolicy(seed)


def _controlled(name: str, option: str | None) -> bool:
    """Whether ``option`` asks for the controlled mode (the greedy's room completion)."""
    if option in (None, ""):
        return False
    if option != "controlled":
        raise UnknownPolicyError(
            f"policy {name!r} takes one option, controlled ({name}:controlled), got {name}:{option}"
        )
    return True


def _baseline(name: str):
    def factory(seed: int | None, option: str | None = None):
        controlled = _controlled(name, option)
        from policies import baselines

        cls = {
            "stachniss_burgard": baselines.StachnissBurgardPolicy,
            "blaer_allen": baselines.BlaerAllenPolicy,
            "potthast_sukhatme": baselines.PotthastSukhatmePolicy,
            "nearest_frontier": baselines.NearestFrontierPolicy,
        }[name]
        return cls(controlled=controlled)

    return factory


def _information_gain(seed: int | None, option: str | None = None):
    from policies.baselines.information_gain import FORMULATIONS, InformationGainPolicy

    formulation, plus, mode = (option or "").partition("+")
    if plus and not (formulation and mode):  # "information_gain:+controlled", "information_gain:x+"
        raise UnknownPolicyError(
            f"information_gain:{option}: an empty part around '+'; write information_gain:FORMULATION+controlled "
            f"(formulations: {', '.join(FORMULATIONS)})"
        )
    controlled = _controlled("information_gain", mode) if plus else False
    if formulation and formulation not in FORMULATIONS:
        known = ", ".join(FORMULATIONS)
        raise UnknownPolicyError(
            f"information_gain:{option}: unknown formulation {formulation!r}; formulations: {known}"
        )
    return InformationGainPolicy(formulation or "occlusion_aware", controlled=controlled)


def _learned(seed: int | None, option: str | None = None):
    if not option:
        raise UnknownPolicyError(
            "ppo needs a checkpoint: ppo:PATH (a folder with policy.json and policy.pt) or ppo:reference (bundled)"
        )
    from policies.learned import LearnedPolicy

    return LearnedPolicy(option)


#: Policy names → factories taking a seed (and, after a colon, an option: ``information_gain:rear_side_voxel``,
#: ``blaer_allen:controlled``, ``information_gain:rear_side_voxel+controlled``, ``greedy:0.8``).
POLICIES = {
    "greedy": _greedy,
    "stachniss_burgard": _baseline("stachniss_burgard"),
    "blaer_allen": _baseline("blaer_allen"),
    "potthast_sukhatme": _baseline("potthast_sukhatme"),
    "information_gain": _information_gain,
    "nearest_frontier": _baseline("nearest_frontier"),
    "random": _random,
    "ppo": _learned,
}


def make_policy(name: str, seed: int | np.random.Generator | None = None) -> Policy:
    """A policy by name (see :data:`POLICIES`); ``name:option`` passes an option: a formulation
    (``information_gain:rear_side_voxel``), the controlled mode of a compared method, which ends
    rooms by the greedy's rule (``stachniss_burgard:controlled``,
    ``information_gain:rear_side_voxel+controlled``), or a checkpoint (``ppo:PATH``).

    Parameters
    ----------
    name : str
        A name of :data:`POLICIES`, optionally followed by ``:OPTION`` (``greedy:0.8+stop=0.08``,
        ``ppo:reference``).
    seed : int or numpy.random.Generator, optional
        Seeds the policies that draw at random (``random``); the others do not read it. A
        non-negative integer (numpy's seeds) or a Generator to draw from.

    Returns
    -------
    Policy
        A new policy.

    Raises
    ------
    UnknownPolicyError
        An unknown name, an option the policy does not take, or an empty option after the colon.
    ConfigError
        A seed that is not a non-negative integer, a Generator or None.
    ModelFileError
        ``ppo:PATH`` with a missing, corrupt or mismatched checkpoint.
    """
    integer = isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_))
    if not (seed is None or isinstance(seed, np.random.Generator) or (integer and seed >= 0)):
        raise ConfigError(f"seed must be a non-negative integer, a numpy Generator or None, got {seed!r}")
    base, colon, option = str(name).partition(":")
    if base not in POLICIES:
        raise UnknownPolicyError(f"unknown policy {name!r}; policies: {', '.join(POLICIES)}")
    # "information_gain:" was read as no option at all: a colon promises one, and a blank one is a slip
    # (a shell variable that expanded to nothing), not a choice of the default.
    if colon and not option.strip():
        raise UnknownPolicyError(
            f"policy {name!r}: the option after the colon is empty; name one ({base}:OPTION) or leave out the colon"
        )
    # A constructor's own errors (a bug, a bad checkpoint) pass through as they are.
    return POLICIES[base](seed, option or None)
