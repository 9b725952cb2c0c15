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
from nbs_env.config import checks, robot, rooms, scanners
from nbs_env.config.checks import *  # noqa: F403 - each module's __all__ is the one list of its names
from nbs_env.config.checks import _finite, _finite_fields, _integer, _require
from nbs_env.config.robot import *  # noqa: F403
from nbs_env.config.rooms import *  # noqa: F403
from nbs_env.config.scanners import *  # noqa: F403

#: Imported on first use: EnvConfig's defaults load the buildings' generator (about 0.5 s), which
#: the command line's ``--help`` and the scanners' table do not need.
_LAZY = {
    **dict.fromkeys(("EnvConfig", "ObservationConfig", "QualityConfig", "RewardConfig"), "nbs_env.config.env"),
    **dict.fromkeys(("PRESETS", "config_paths", "make_config"), "nbs_env.config.presets"),
}

__all__ = [
    *checks.__all__,
    *robot.__all__,
    *rooms.__all__,
    *scanners.__all__,
    *_LAZY,
    "_finite",
    "_finite_fields",
    "_integer",
    "_require",
]

__getattr__ = lazy_getattr(__name__, _LAZY)
