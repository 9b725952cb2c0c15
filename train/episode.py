"""One episode of a policy in NBSEnv, as ``nbs scan`` and ``nbs compare`` run it."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from nbs_env.env import NBSEnv
from policies import Policy

__all__ = ["run_episode"]


def run_episode(
    env: NBSEnv,
    policy: Policy,
    seed: int | None,
    options: dict[str, Any] | None = None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
    max_invalid: int = 10,
    stop: Callable[[], bool] | None = None,
) -> dict[int, float]:
    """Reset ``env``, play ``policy`` to the end of the episode.

    ``stop``, when given, is asked before each step after the first scan: once it says True the
    episode ends there, unfinished (:class:`train.stopping.StopRequest`: Ctrl-C or SIGTERM).

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
    while not done and not (stop is not None and stop()):
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
