"""The configuration, in one place: frozen, checked, JSON-safe dataclasses, the named presets and
the one override path.

- :mod:`nbs_env.config.robot`: what the robot is made of, its hardware (:class:`ScannerConfig`,
  :class:`OdometryConfig`, the base and its footprint in :class:`NavigationConfig`) and the stages
  of a scan cycle (:class:`RegistrationConfig`, :class:`RoIConfig`, :class:`DoorConfig`,
  :class:`GainConfig`), together :class:`RobotConfig`.
- :mod:`nbs_env.config.rooms`: the storey's rules for rooms (:class:`RoomRules`: who ends a room
  and when, its scan cap, the door searches of :class:`WallSearchConfig`).
- :mod:`nbs_env.config.env`: :class:`EnvConfig`, the robot and the rules with the reward, the
  observation and the evaluation.
- :mod:`nbs_env.config.presets`: :data:`PRESETS` and :func:`make_config`, which every command and
  training use.
- :mod:`nbs_env.config.scanners`: real scanners' datasheets, :func:`scanner_config`.

``EnvConfig.to_dict()`` is what ``metrics.json`` and a checkpoint record, and
``EnvConfig.from_dict()`` reads it back.
"""

from nbs_env import lazy_getattr
from nbs_env.config.checks import Config, _finite, _finite_fields, _integer, _require

#: Each name is imported from its module on first use: the command line reads the scanners' table
#: without loading the buildings' generator that EnvConfig's defaults need.
_EXPORTS = {
    **dict.fromkeys(("EnvConfig", "ObservationConfig", "QualityConfig", "RewardConfig"), "nbs_env.config.env"),
    **dict.fromkeys(("PRESETS", "config_paths", "make_config"), "nbs_env.config.presets"),
    **dict.fromkeys(
        (
            "MAX_RAYS",
            "DoorConfig",
            "GainConfig",
            "NavigationConfig",
            "OdometryConfig",
            "PlanningConfig",
            "RegistrationConfig",
            "RobotConfig",
            "RoIConfig",
            "ScannerConfig",
        ),
        "nbs_env.config.robot",
    ),
    **dict.fromkeys(("COMPLETIONS", "RoomRules", "WallSearchConfig"), "nbs_env.config.rooms"),
    **dict.fromkeys(("SCANNERS", "scanner_config"), "nbs_env.config.scanners"),
}

__all__ = [
    "COMPLETIONS",
    "MAX_RAYS",
    "PRESETS",
    "SCANNERS",
    "Config",
    "DoorConfig",
    "EnvConfig",
    "GainConfig",
    "NavigationConfig",
    "ObservationConfig",
    "OdometryConfig",
    "PlanningConfig",
    "QualityConfig",
    "RegistrationConfig",
    "RewardConfig",
    "RoIConfig",
    "RobotConfig",
    "RoomRules",
    "ScannerConfig",
    "WallSearchConfig",
    "_finite",
    "_finite_fields",
    "_integer",
    "_require",
    "config_paths",
    "make_config",
    "scanner_config",
]

__getattr__ = lazy_getattr(__name__, _EXPORTS)
