"""One episode of a policy in NBSEnv, as ``nbs scan`` and ``nbs compare`` run it."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from nbs_env.env import NBSEnv
from nbs_env.settings import EnvConfig
from policies import Policy, env_settings

__all__ = ["config_for", "run_episode", "wall_search_note"]


def config_for(config: EnvConfig, policy: Policy) -> EnvConfig:
    """``config`` with the settings the policy needs (its own room completion, the belief view)."""
    env_overrides, robot_overrides = env_settings(policy)
    robot = replace(config.robot, **robot_overrides) if robot_overrides else config.robot
    return replace(config, robot=robot, **env_overrides)


def wall_search_note(policy: Policy, wall_search: int) -> str | None:
    """A note when ``policy`` was trained with another robot wall search than ``wall_search``
    (a learned policy that ends rooms leans on the search it was trained with); None otherwise."""
    trained = getattr(policy, "trained_wall_search", None)
    if trained is None or trained == wall_search:
        return None
    return (
        f"{policy.name} was trained with --wall-search {trained}; this run uses --wall-search {wall_search} "
        f"(pass --wall-search {trained} to run it, and the policies beside it, as it was trained)"
    )


def run_episode(
    env: NBSEnv,
    policy: Policy,
    seed: int | None,
    options: dict[str, Any] | None = None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
    max_invalid: int = 10,
) -> dict[int, float]:
    """Reset ``env``, play ``policy`` to the end of the episode.

    Returns
    -------
    dict of int to float
        The policy's decision time by the index of the scan the decision led to (for
        :func:`nbs_env.report.metrics_dict`).

    Raises
    ------
    RuntimeError
        The policy chose a masked action ``max_invalid`` times in a row.
    """
    obs, info = env.reset(seed=seed, options=options or {})
    policy.reset()
    if on_step is not None:
        on_step(info)
    times: dict[int, float] = {}
    invalid = 0
    done = not env.storey.open
    while not done:
        before = info["scans"]
        t = time.perf_counter()
        action = policy.act(obs, info)
        elapsed = time.perf_counter() - t
        obs, _, terminated, truncated, info = env.step(action)
        times[before] = times.get(before, 0.0) + elapsed
        done = terminated or truncated
        invalid = invalid + 1 if info["invalid_action"] else 0
        if invalid >= max_invalid:
            raise RuntimeError(f"policy {policy.name!r} chose a masked action {max_invalid} times in a row")
        if on_step is not None:
            on_step(info)
    return times
