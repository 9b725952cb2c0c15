"""The base of every configuration class: checks on construction and a JSON round trip.

A configuration is a frozen dataclass whose fields are numbers, strings, booleans, None, tuples,
string-keyed dicts or other configurations. ``to_dict()`` gives the JSON-safe tree that
``metrics.json`` and a checkpoint record; ``from_dict()`` builds the configuration back from it
(lists become the tuples the fields declare), checking every value as the constructor does.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
import re
import types
import typing
from dataclasses import asdict
from typing import Any, TypeVar

import numpy as np

from nbs_env.errors import ConfigError
from scenes.errors import SceneError
from scenes.jsonio import MAX_JSON_DEPTH, json_text
from scenes.limits import is_finite

__all__ = ["Config", "json_form", "parse_float", "parse_int"]

C = TypeVar("C", bound="Config")


# Numbers as a user types them: ASCII digits (Python's int and float also read "1_0" as 10 and
# Arabic-Indic or full-width digits as digits, which nothing else a user runs does).
_INT = re.compile(r"[+-]?[0-9]+", re.ASCII)
_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)", re.I)


def parse_int(text: str) -> int:
    """``int(text)`` for ASCII digits with an optional sign (blanks around allowed).

    Raises
    ------
    ValueError
        Anything else: ``"1_0"``, ``"\u0661"``, ``"1.0"``.
    """
    stripped = text.strip(" \t")
    if not _INT.fullmatch(stripped):
        raise ValueError(f"not an integer: {text!r}")
    return int(stripped)


def parse_float(text: str) -> float:
    """``float(text)`` for a decimal number in ASCII (or ``nan``, ``inf``: ranges are the caller's).

    Raises
    ------
    ValueError
        Anything else: ``"1_0"``, ``"\u0663.5"``, ``"0x10"``.
    """
    stripped = text.strip(" \t")
    if not _FLOAT.fullmatch(stripped):
        raise ValueError(f"not a number: {text!r}")
    return float(stripped)


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def _finite(**values: float) -> None:
    for name, value in values.items():
        _require(
            isinstance(value, (int, float)) and not isinstance(value, bool) and is_finite(value),
            f"{name} must be a finite number, got {json_text(value, 60)}",
        )


def _finite_fields(config: Any, *names: str) -> None:
    """Each named field of ``config`` is a finite number."""
    _finite(**{name: getattr(config, name) for name in names})


def _integer(config: Any, name: str, least: int, most: int | None = None) -> None:
    """Field ``name`` of ``config`` is an integer (not a bool) of at least ``least`` (and at most
    ``most``); any :class:`numbers.Integral` (a numpy integer) is stored as an ``int``."""
    value = getattr(config, name)
    if isinstance(value, numbers.Integral) and not isinstance(value, (bool, int)):
        value = int(value)
        object.__setattr__(config, name, value)
    within = f">= {least}" if most is None else f"within [{least:,}, {most:,}]"
    _require(
        isinstance(value, int) and not isinstance(value, bool) and value >= least and (most is None or value <= most),
        f"{name} must be an integer {within}, got {json_text(value)}",
    )


def _text(value: float) -> str:
    """A bound as a message states it: ``10,000``, ``0.05``, ``1e-09``."""
    if isinstance(value, int) and not is_finite(value):  # format(10**400, "g") raises too
        return f"an integer of {len(str(abs(value))):,} digits"
    if isinstance(value, (int, float)) and math.isfinite(value) and float(value).is_integer() and abs(value) < 1e15:
        return f"{int(value):,}"
    return f"{value:g}" if isinstance(value, (int, float)) else repr(value)


def _at_most(config: Any, name: str, most: float, unit: str = "") -> None:
    """Field ``name`` of ``config`` (a number checked already) is at most ``most``."""
    value = getattr(config, name)
    _require(value <= most, f"{name} must be at most {_text(most)}{' ' + unit if unit else ''}, got {_text(value)}")


def _within(config: Any, name: str, low: float, high: float, unit: str = "", *, open_low: bool = False) -> None:
    """Field ``name`` of ``config`` is a finite number within [low, high] (``open_low``: (low, high])."""
    value = getattr(config, name)
    _finite(**{name: value})
    inside = (low < value if open_low else low <= value) and value <= high
    bounds = f"{'(' if open_low else '['}{_text(low)}, {_text(high)}]"
    _require(inside, f"{name} must be within {bounds}{' ' + unit if unit else ''}, got {value}")


@functools.cache
def _numeric_hints(cls: type) -> dict[str, tuple[bool, bool]]:
    """Per field of ``cls``, whether its type admits an int and whether it admits a float (also
    inside a tuple)."""
    out = {}
    for name, hint in typing.get_type_hints(cls).items():
        found: set[Any] = set()
        stack = [hint]
        while stack:
            h = stack.pop()
            if isinstance(h, types.UnionType) or typing.get_origin(h) in (typing.Union, tuple):
                stack.extend(a for a in typing.get_args(h) if a is not Ellipsis)
            else:
                found.add(h)
        if int in found or float in found:
            out[name] = (int in found, float in found)
    return out


def _plain_number(value: Any, takes_int: bool, takes_float: bool) -> Any:
    """A numpy integer as an ``int``, a numpy float as a ``float`` (a bool, a string or a plain
    number stays as it is): what JSON writes."""
    if isinstance(value, bool) or type(value) in (int, float):
        return value
    if isinstance(value, numbers.Integral) and (takes_int or takes_float):
        return int(value)
    if isinstance(value, numbers.Real) and takes_float:
        return float(value)
    return value


def _plain_numbers(config: Any) -> None:
    """Numpy numbers in the numeric fields of ``config`` (and in its tuples of numbers) become
    plain ``int`` and ``float``, so that the configuration stays JSON-safe; bools are left to the
    checks, which refuse them where a number is wanted."""
    for name, (takes_int, takes_float) in _numeric_hints(type(config)).items():
        value = getattr(config, name)
        if isinstance(value, np.ndarray) and value.ndim == 1:  # a pair given as an array: a tuple of numbers
            value = tuple(value.tolist())
            object.__setattr__(config, name, value)
        if isinstance(value, (tuple, list)):
            items = [_plain_number(v, takes_int, takes_float) for v in value]
            if any(p is not v for p, v in zip(items, value, strict=True)):
                object.__setattr__(config, name, type(value)(items))
        else:
            plain = _plain_number(value, takes_int, takes_float)
            if plain is not value:
                object.__setattr__(config, name, plain)


def _plain_values(value: Any, depth: int = 0) -> Any:
    """``value`` with every numpy scalar inside its dicts, lists and tuples a plain ``bool``,
    ``int``, ``float`` or ``str`` and every numpy array a list: a free-form field
    (``TrainConfig.overrides``) JSON can write.

    Raises
    ------
    ConfigError
        ``value`` nested deeper than a JSON file may be (:data:`scenes.jsonio.MAX_JSON_DEPTH`).
    """
    if depth > MAX_JSON_DEPTH:  # a RecursionError otherwise, as JSON read without a bound
        raise ConfigError(f"a value nested more than {MAX_JSON_DEPTH} levels deep")
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, dict):
        return {k: _plain_values(v, depth + 1) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_plain_values(v, depth + 1) for v in value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.str_):
        return str(value)
    return _plain_number(value, True, True)


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


def same_json(a: Any, b: Any) -> bool:
    """Whether ``a`` and ``b`` are one value as JSON writes them: Python's ``==`` takes ``true`` and
    ``1.0`` for ``1``, which a record holding them does not mean."""
    return json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


class Config:
    """Base of the frozen configuration dataclasses: their JSON-safe tree and back.

    Every subclass's ``__post_init__`` checks are wrapped so that a field of a kind they did not
    expect (``shape=5``, ``robot=0``, an int no float holds) is a :class:`ConfigError`, never a
    ``TypeError``, ``OverflowError`` or ``RecursionError`` from inside a check.
    """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        checks = cls.__dict__.get("__post_init__")
        if checks is None:
            return

        @functools.wraps(checks)
        def checked(self: Any) -> None:
            try:
                _check_field_kinds(self)
                checks(self)
            except ConfigError:
                raise
            except RecursionError:  # a repr or a walk of a value nested thousands of levels deep
                raise ConfigError(
                    f"{type(self).__name__}: a value nested too deep to check (a JSON file or --set may nest "
                    f"{MAX_JSON_DEPTH} levels)"
                ) from None
            except (TypeError, ValueError, AttributeError, OverflowError, IndexError) as exc:
                raise ConfigError(
                    f"{type(self).__name__}: a field of a kind or size it cannot hold ({type(exc).__name__}: "
                    f"{str(exc)[:120]})"
                ) from None

        cls.__post_init__ = checked  # type: ignore[attr-defined]

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
        try:
            return _build(cls, data, where)
        except RecursionError:  # a repr of a value nested thousands of levels deep, in a message
            raise ConfigError(f"{cls.__name__}: a value nested too deep to check") from None


def _check_field_kinds(config: Any) -> None:
    """The fields declared as a configuration or a bool hold one: ``EnvConfig(observation=0)`` was
    taken and failed later in the env, ``keep_scans="no"`` kept every scan (a non-empty string is true)."""
    hints = _field_hints(type(config))
    for name, hint in hints.items():
        value = getattr(config, name)
        kinds = hint.__args__ if isinstance(hint, types.UnionType) else (hint,)
        if value is None and type(None) in kinds:
            continue
        configs = [k for k in kinds if isinstance(k, type) and (issubclass(k, Config) or dataclasses.is_dataclass(k))]
        if configs and not isinstance(value, tuple(configs)):
            raise ConfigError(f"{name} must be a {configs[0].__name__}, got {json_text(value, 60)}")
        if bool in kinds and len(kinds) == 1:
            if isinstance(value, np.bool_):  # numpy's bool: stored as Python's, JSON-safe
                object.__setattr__(config, name, bool(value))
            elif not isinstance(value, bool):
                raise ConfigError(f"{name} must be a bool (true or false), got {json_text(value, 60)}")


@functools.cache
def _field_hints(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.name in hints}


def _build(cls: type, data: Any, where: str) -> Any:
    """A dataclass ``cls`` from a JSON object, each value read as its field's type declares."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where or cls.__name__} must be a JSON object of fields, got {json_text(data)}")
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
    except (TypeError, ValueError, OverflowError) as exc:  # a value of a kind the class's checks did not expect
        if isinstance(exc, ConfigError) and not where:
            raise
        # A scenes error's message leads with its source ("GeneratorConfig: ..."): the field path says where.
        message = exc.problem if isinstance(exc, SceneError) else str(exc)
        raise ConfigError(_qualified(message, where or cls.__name__, fields)) from None


def _qualified(message: str, where: str, fields: Any) -> str:
    """``message`` naming its field by its dotted path: ``lattice must be ...`` from the section
    ``robot.navigation`` reads ``robot.navigation.lattice must be ...``; a message that does not
    start with one of the section's ``fields`` is prefixed with the section's name."""
    first = re.match(r"\w+", message)
    if first is not None and first.group() in fields:
        return f"{where}.{message}"
    return f"{where}: {message}"


def _from_json(value: Any, hint: Any, where: str) -> Any:
    """``value`` read as the type ``hint`` declares: a configuration from a dict, a tuple from a list."""
    if type(value).__module__ == "numpy" and getattr(value, "ndim", 0) >= 1:
        value = value.tolist()  # an array where a list is wanted
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
        raise ConfigError(f"{where} must be a JSON object of fields, got {json_text(value)}")
    lists = [o for o in options if typing.get_origin(o) is tuple]
    if lists and value is not None and len(lists) == len([o for o in options if o is not type(None)]):
        raise ConfigError(f"{where} must be a list, got {json_text(value, 60)}")
    return _plain_number(value, int in options, float in options)
