"""The named presets and the one override path, :func:`make_config`.

A preset is data: the dotted overrides it makes to ``EnvConfig()``. Every command and training
build their configuration with :func:`make_config`, so that a name means the same everywhere::

    make_config("fast", max_scans=20, **{"rooms.wall_search.scans": 3})
    make_config("default", completion_fraction=0.05)   # a leaf's name, where it is unique
"""

from __future__ import annotations

import dataclasses
from typing import Any

from nbs_env.config.checks import Config, _plain_values
from nbs_env.config.env import EnvConfig
from nbs_env.errors import ConfigError

__all__ = ["PRESETS", "config_paths", "make_config"]

#: Named configurations, as dotted overrides of ``EnvConfig()``: ``"default"`` is the best robot
#: the project knows (the paper's method with the searches for doors no scan faced, three scans a
#: room, and NVPs in passages narrower than the lattice); ``"paper"`` the paper's literal robot (a
#: room ends by its gain alone: no wall or door search; NVPs on the lattice only; thin rays), which the
#: paper's §5 comparison uses; ``"fast"`` the RL preset (the default robot with a
#: 1° scanner, 10 cm voxels, perfect localisation, 1-3 room storeys, 40 scans); ``"train"`` the
#: training fidelity (``"fast"`` without the coverage meter, rewarded by the robot's own map). A preset changes the
#: robot, never the evaluation: coverage is counted at the same sample spacing and radius whatever
#: the preset, so that one cloud gives one figure.
_FAST: dict[str, Any] = {
    "robot.scanner.angular_step": 1.0,
    "robot.odometry": {"sigma_xy_per_m": 0.0, "sigma_yaw_deg_per_m": 0.0, "sigma_tilt_deg": 0.0},
    "robot.voxel_size": 0.1,
    "robot.perfect_localisation": True,
    "generator.rooms": (1, 3),
    "max_scans": 40,
}
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    # The paper's scanner casts thin rays (no beam footprint, so no mixed pixels).
    "paper": {"rooms.wall_search.scans": 0, "robot.navigation.snap": False, "robot.scanner.beam_divergence": 0.0},
    "fast": _FAST,
    # The training fidelity: the fast robot (its observations and decisions) without the ground-truth
    # meter, which no decision reads; the reward is then the robot's own map.
    "train": {**_FAST, "coverage_meter": False, "reward.kind": "mapped"},
}


def config_paths(cls: type = EnvConfig, prefix: str = "") -> list[str]:
    """Every dotted name of a configuration class's tree, sections and leaves.

    Parameters
    ----------
    cls : type
        A configuration dataclass (default :class:`EnvConfig`).
    prefix : str
        Prepended to each name with a dot.

    Returns
    -------
    list of str
        E.g. ``["preset", "scene", ..., "robot", "robot.scanner", "robot.scanner.angular_step", ...]``.
    """
    import typing

    out = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        name = f"{prefix}{f.name}"
        out.append(name)
        hint = hints[f.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            out += config_paths(hint, name + ".")
    return out


def resolve_path(key: str, paths: list[str] | None = None) -> str:
    """The dotted path a key names: itself, or the one path whose last part it is
    (``"scan_cost"`` is ``"reward.scan_cost"``).

    Parameters
    ----------
    key : str
        A dotted path or a field's own name.
    paths : list of str, optional
        :func:`config_paths` (computed when not given).

    Raises
    ------
    ConfigError
        No field has that name, or more than one does.
    """
    paths = config_paths() if paths is None else paths
    if key in paths:
        return key
    if "." in key:
        raise ConfigError(f"the configuration has no {key!r}; see nbs_env.config.config_paths() for its names")
    matches = [p for p in paths if p.rpartition(".")[2] == key]
    if not matches:
        raise ConfigError(f"the configuration has no field {key!r}; see nbs_env.config.config_paths() for its names")
    if len(matches) > 1:
        raise ConfigError(f"{key!r} is ambiguous: name one of {', '.join(matches)}")
    return matches[0]


def make_config(preset: str | EnvConfig | None = None, /, **overrides: Any) -> EnvConfig:
    """A preset's configuration with fields replaced: the one override path.

    Parameters
    ----------
    preset : str or EnvConfig, optional
        A name of :data:`PRESETS`, or a configuration to start from (its ``preset`` is kept);
        ``"default"`` when omitted. It may be given by keyword too (``make_config(preset="fast",
        scene="office")``, as ``NBSEnv(scene="office", preset="fast")`` passes it).
    **overrides
        Field names to values. A name is a top-level field (``scene="five_rooms"``), a dotted path
        (``**{"robot.scanner.angular_step": 1.0}``) or a field's own name where only one field of
        the tree has it (``completion_fraction=0.05``). A value is what the field takes, or its
        JSON form (a dict for a section merges into it; a list for a tuple); a configuration
        instance replaces the section whole. Sections are applied before the fields inside them.

    Returns
    -------
    EnvConfig
        Checked, with ``preset`` recording the preset's name.

    Raises
    ------
    ConfigError
        An unknown preset or field name, an ambiguous name (the message lists the candidates), or a
        value a configuration refuses.
    """
    try:
        return _make_config(preset, overrides)
    except RecursionError:  # a repr of a value nested thousands of levels deep, in a message
        raise ConfigError("make_config: a value nested too deep to check") from None


def _make_config(preset: str | EnvConfig | None, overrides: dict[str, Any]) -> EnvConfig:
    named = overrides.pop("preset", None)
    if named is not None:
        if preset is not None and (preset.preset if isinstance(preset, EnvConfig) else preset) != named:
            shown = f"a configuration of preset {preset.preset!r}" if isinstance(preset, EnvConfig) else repr(preset)
            raise ConfigError(f"preset {named!r} given as a field, but the configuration starts from {shown}: pass one")
        preset = named if preset is None else preset
    preset = "default" if preset is None else preset
    if isinstance(preset, EnvConfig):
        base, name, preset_overrides = preset.to_dict(), preset.preset, {}
    elif isinstance(preset, str) and preset in PRESETS:
        base, name, preset_overrides = EnvConfig().to_dict(), preset, PRESETS[preset]
    else:
        raise ConfigError(f"unknown preset {preset!r}; presets: {', '.join(PRESETS)}")
    paths = config_paths()
    resolved: dict[str, Any] = {}
    for key, value in overrides.items():
        path = resolve_path(key, paths)
        if path in resolved:
            raise ConfigError(f"{key!r} and another name both set {path}")
        # Numpy arrays and scalars as their JSON form: every configuration takes that.
        resolved[path] = value if isinstance(value, Config) else _plain_values(value)
    tree = base
    for path, value in [*preset_overrides.items(), *sorted(resolved.items(), key=lambda kv: kv[0].count("."))]:
        _set(tree, path, value)
    tree["preset"] = name
    return EnvConfig.from_dict(tree)


def _set(tree: dict[str, Any], path: str, value: Any) -> None:
    *parents, leaf = path.split(".")
    node = tree
    for k, part in enumerate(parents):
        if not isinstance(node.get(part), dict):  # robot=5 with robot.scanner.height=2: a TypeError from here
            section = ".".join(parents[: k + 1])
            raise ConfigError(f"{section} is set to {repr(node.get(part))[:40]}, not a section, and {path} inside it")
        node = node[part]
    if isinstance(value, Config) or (dataclasses.is_dataclass(value) and not isinstance(value, type)):
        node[leaf] = dataclasses.asdict(value)  # a GeneratorConfig is a dataclass of its own
    elif isinstance(value, dict) and isinstance(node.get(leaf), dict) and leaf != "scene_options":
        node[leaf] = _merged(node[leaf], value)
    else:
        node[leaf] = value


def _merged(section: dict[str, Any], value: dict[str, Any]) -> dict[str, Any]:
    """``value`` merged into ``section`` at every depth: ``robot={"scanner": {"height": 1.2}}`` keeps
    the preset's scanner step (a merge of the top level alone put the default scanner back)."""
    out = dict(section)
    for key, item in value.items():
        if isinstance(item, dict) and isinstance(out.get(key), dict) and key != "scene_options":
            out[key] = _merged(out[key], item)
        else:
            out[key] = item
    return out
