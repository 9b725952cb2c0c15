"""The robot's side of nbs-env: scanner, registration, perception, voxel labels, planning, the storey
session and the env.

One step reads top-down: :mod:`nbs_env.env` → :mod:`nbs_env.storey` → :mod:`nbs_env.robot` →
sensing and :mod:`nbs_env.belief` (perception, mapping) → :mod:`nbs_env.planning.planner`.

It reads buildings from :mod:`scenes` (the floor below) and never imports :mod:`policies` or
:mod:`train` (the floors above). Only the simulator and evaluation parts of this package may read a
scene's ground truth.

Importing it registers the Gymnasium ids in :data:`ENV_IDS` (``gymnasium.make("nbs_env/NBS-v0")``).
"""

from __future__ import annotations

__version__ = "0.2.0"

#: The registered environments: id → (preset, overrides, max_episode_steps).
ENV_IDS: dict[str, tuple[str, dict, int]] = {
    "nbs_env/NBS-v0": ("default", {}, 80),
    "nbs_env/NBS-Fast-v0": ("fast", {}, 40),
    "nbs_env/NBS-FiveRooms-v0": ("default", {"scene": "five_rooms"}, 60),
}


def _register() -> None:
    from gymnasium.envs.registration import register, registry

    for env_id, (preset, overrides, steps) in ENV_IDS.items():
        if env_id not in registry:
            register(
                id=env_id,
                entry_point="nbs_env.env:NBSEnv",
                kwargs={"config": preset, **overrides},
                max_episode_steps=steps,
            )


_register()
