"""The base of every configuration class: checks on construction and a JSON round trip.

A configuration is a frozen dataclass whose fields are numbers, strings, booleans, None, tuples,
string-keyed dicts or other configurations. ``to_dict()`` gives the JSON-safe tree that
``metrics.json`` and a checkpoint record; ``from_dict()`` builds the configuration back from it
(lists become the tuples the fields declare), checking every value as the constructor does.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from dataclasses import asdict
from typing import Any, TypeVar

from nbs_env.errors import ConfigError

__all__ = ["Config", "json_form"]

C = TypeVar("C", bound="Config")


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def _finite(**values: float) -> None:
    for name, value in values.items():
        _require(
            isinstance(value, (int, float)) and math.isfinite(value), f"{name} must be a finite number, got {value!r}"
        )


def _finite_fields(config: Any, *names: str) -> None:
    """Each named field of ``config`` is a finite number."""
    _finite(**{name: getattr(config, name) for name in names})


def _integer(config: Any, name: str, least: int) -> None:
    """Field ``name`` of ``config`` is an integer (not a bool) of at least ``least``."""
    value = getattr(config, name)
    _require(
        isinstance(value, int) and not isinstance(value, bool) and value >= least,
        f"{name} must be an integer >= {least}, got {value!r}",
    )


def json_form(value: Any) -> Any:
    """``value`` as JSON reads it back (tuples become lists): how a recorded configuration value and
    a live one are compared.

    Parameters
    ----------
    value : Any
        A JSON-safe value (numbers, strings, booleans, None, lists, tuples, string-keyed dicts).

    Returns
    -------
    Any
        The same value with every tuple a list.
    """
    return json.loads(json.dumps(value))


class Config:
    """Base of the frozen configuration dataclasses: their JSON-safe tree and back."""

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-safe tree of dicts (nested configurations become dicts).

        Returns
        -------
        dict
            ``{field: value}``; :meth:`from_dict` of it gives an equal configuration.
        """
        return asdict(self)  # type: ignore[call-overload]

    @classmethod
    def from_dict(cls: type[C], data: dict[str, Any], where: str = "") -> C:
        """The configuration ``data`` describes, checked as the constructor checks it.

        Parameters
        ----------
        data : dict
            Field names to values, as :meth:`to_dict` writes them; fields left out keep their
            defaults. Lists become tuples where a field is a tuple; dicts become configurations
            where a field is one.
        where : str
            The dotted name of this configuration in its tree, for messages.

        Returns
        -------
        Config
            An instance of ``cls``.

        Raises
        ------
        ConfigError
            ``data`` is not a dict, names a field ``cls`` has not (the message lists its fields), or
            a value the constructor refuses.
        """
        return _build(cls, data, where)


def _build(cls: type, data: Any, where: str) -> Any:
    """A dataclass ``cls`` from a JSON object, each value read as its field's type declares."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where or cls.__name__} must be a JSON object of fields, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{where or cls.__name__} has no field(s) {unknown}; its fields: {', '.join(fields)}")
    hints = typing.get_type_hints(cls)
    values = {
        name: _from_json(value, hints[name], f"{where}.{name}" if where else name) for name, value in data.items()
    }
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:  # a value of a kind the class's own checks did not expect
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{where or cls.__name__}: {exc}") from None


def _from_json(value: Any, hint: Any, where: str) -> Any:
    """``value`` read as the type ``hint`` declares: a configuration from a dict, a tuple from a list."""
    options = (
        typing.get_args(hint)
        if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union
        else (hint,)
    )
    for option in options:
        if isinstance(option, type) and dataclasses.is_dataclass(option):
            if isinstance(value, option):
                return value
            if isinstance(value, dict):
                return _build(option, value, where)
        if typing.get_origin(option) is tuple and isinstance(value, (list, tuple)):
            args = typing.get_args(option)
            inner = args[0] if args else Any
            return tuple(_from_json(v, inner, where) if inner is not Any else v for v in value)
    if all(isinstance(o, type) and dataclasses.is_dataclass(o) for o in options):
        raise ConfigError(f"{where} must be a JSON object of fields, got {value!r}")
    return value
