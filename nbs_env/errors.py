"""Errors of the robot side. Each message says what is wrong and with which value."""

from __future__ import annotations


class NBSError(Exception):
    """Base class of nbs_env errors."""


class ConfigError(NBSError, ValueError):
    """A configuration value out of its valid range (a step <= 0, min range above max range, ...)."""


class InvalidPoseError(NBSError, ValueError):
    """A pose that is not a finite rigid transform (NaN, infinite, not a rotation)."""


class ModelFileError(NBSError, ValueError):
    """A stored model file that is missing, not JSON, malformed, or modified after it was written."""


class InvalidActionError(NBSError, ValueError):
    """An action outside the action space (not an integer, or out of range)."""


class UnreachableDoorError(NBSError, RuntimeError):
    """A detected door the robot cannot drive to from where it is."""
