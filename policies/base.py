"""The policy protocol: what ``nbs scan``, ``nbs compare`` and users' loops call, and what a policy
declares about the configuration it runs with."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

from nbs_env.config import EnvConfig, json_form, make_config
from nbs_env.errors import ConfigError
from nbs_env.observation import CandidateColumn, candidate_table_of

__all__ = ["Policy", "agreed_requirements", "config_for", "mask_of"]


@runtime_checkable
class Policy(Protocol):
    """Chooses the next scan.

    ``act`` gets the observation and info of :class:`nbs_env.env.NBSEnv` and returns an index into
    the candidate list that the mask allows; ``reset`` forgets any state at the start of an episode.

    Attributes
    ----------
    name : str
        The policy's name, as :func:`policies.make_policy` takes it.
    config_overrides : Mapping[str, Any]
        What the policy runs with, as dotted :func:`nbs_env.config.make_config` names: its own
        interface (``"rooms.completion": "policy"`` for a "room done" action, ``"expose_belief":
        True`` for its own maps) and its parameters (the greedy's ``stop``). Applied to each of its
        runs (:func:`config_for`); empty for most.
    requires : Mapping[str, Any]
        The configuration the policy was made for: the storey's room rules (a learned policy: those
        it was trained with, e.g. ``{"rooms.wall_search.scans": 3}``) and, for a learned policy, how
        its observations were made (``{"robot.voxel_size": 0.1, "observation.cell": 0.2, ...}``). A run
        whose configuration differs is refused, and policies that require different values are not
        compared in one grid (:func:`agreed_requirements`); empty for most.
    """

    name: str
    config_overrides: Mapping[str, Any]
    requires: Mapping[str, Any]

    def reset(self) -> None:
        """Forget any state of the previous episode; called after each ``env.reset``, before the
        episode's first :meth:`act`."""

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        """The next action.

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            The observation of :class:`nbs_env.env.NBSEnv`: ``"voxels"`` (64, 64, 16) uint8 voxel
            labels, ``"candidates"`` (K·5,) float32 candidate table
            (:func:`nbs_env.observation.candidate_table_of`), ``"pose"`` (4,) float32 and ``"room"``
            (5,) float32.
        info : dict of str to Any
            The env's ``info``: ``"action_mask"`` (n_actions,) bool, ``"candidate_gains"`` (K,)
            int64, ``"gain_rule_done"`` bool, and with ``expose_belief=True`` ``"belief"``
            (:class:`~nbs_env.observation.BeliefView`).

        Returns
        -------
        int
            An action the mask allows: a candidate index in [0, K), or K ("room done") with
            ``rooms.completion="policy"``.
        """


def agreed_requirements(policies: Iterable[Policy]) -> dict[str, tuple[Any, str]]:
    """What every one of ``policies`` requires, with the policy that asks for it.

    Parameters
    ----------
    policies : iterable of Policy

    Returns
    -------
    dict
        Dotted configuration name -> (value, the name of a policy that requires it).

    Raises
    ------
    ConfigError
        Two policies require different values of one field: they ran on different robots and are
        not compared side by side. The message names both.
    """
    agreed: dict[str, tuple[Any, str]] = {}
    for policy in policies:
        for path, value in policy.requires.items():
            if path in agreed and json_form(agreed[path][0]) != json_form(value):
                other_value, other = agreed[path]
                raise ConfigError(
                    f"{other} requires {path}={other_value!r} and {policy.name} requires {path}={value!r}: "
                    "they were made for different robots; compare them in separate grids"
                )
            agreed.setdefault(path, (value, policy.name))
    return agreed


def config_for(config: EnvConfig, policy: Policy) -> EnvConfig:
    """``config`` with what ``policy`` runs with, checked against what it requires.

    Parameters
    ----------
    config : EnvConfig
        The run's configuration.
    policy : Policy

    Returns
    -------
    EnvConfig
        ``config`` with :attr:`Policy.config_overrides` applied (:func:`nbs_env.config.make_config`).

    Raises
    ------
    ConfigError
        The configuration differs from :attr:`Policy.requires`; the message names the field. Or the
        policy's own ``check_config(config)``, where it has one, refuses the configuration (a learned
        policy whose network reads another observation window or candidate count,
        :meth:`policies.LearnedPolicy.check_config`).
    """
    out = make_config(config, **dict(policy.config_overrides)) if policy.config_overrides else config
    tree = json_form(out.to_dict())
    for path, value in policy.requires.items():
        node: Any = tree
        for part in path.split("."):
            node = node[part]
        if node != json_form(value):
            raise ConfigError(f"{policy.name} requires {path}={value!r} (it was trained so); this run has {node!r}")
    # Optional, not part of the Protocol: most policies read any observation; a network reads one shape.
    check = getattr(policy, "check_config", None)
    if callable(check):
        check(out)
    return out


def mask_of(obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
    """(K,) bool: the action mask, from ``info["action_mask"]`` or else the candidates' valid column."""
    if "action_mask" in info:
        return np.asarray(info["action_mask"], dtype=bool)
    return candidate_table_of(obs)[:, CandidateColumn.VALID] > 0.5
