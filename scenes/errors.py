"""The ``SceneError`` family: every way a building can fail to load.

Each error names *where* (a file, a bundled name, a JSON field path) and *what*. The CLI prints
``str(error)`` and exits non-zero without a traceback, so the message must stand on its own.
"""

from __future__ import annotations


def short_name(name: object, keep: int = 200) -> str:
    """A name for a message: one of thousands of characters (too long for any file system, often the
    very cause of the error) is cut, so that the reason after it is still read."""
    text = str(name)
    return text if len(text) <= keep else f"{text[: keep - 40]}… ({len(text):,} characters)"


class SceneError(Exception):
    """Base class of every error raised while loading, building or validating a scene.

    Parameters
    ----------
    source : str
        Where the problem is: a file path, a bundled scene name or a spec string.
    problem : str
        What is wrong, as a sentence fragment.
    path : str, optional
        For structured input (floor-plan JSON), the offending field, e.g. ``rooms[2].polygon``.
    """

    def __init__(self, source: str, problem: str, *, path: str | None = None) -> None:
        self.source = str(source)
        self.problem = problem
        self.path = path
        # A source of thousands of characters (a name too long for any file system, the very cause)
        # is cut in the message so that the problem after it is read; .source keeps it whole.
        shown = short_name(self.source) if self.source.strip() else repr(self.source)  # '' rather than nothing
        where = f"{shown}: {path}" if path else shown
        super().__init__(f"{where}: {problem}")


class UnknownSceneError(SceneError, LookupError):
    """A spec that is neither a bundled name, nor a file, nor ``generated:SEED``."""


class SceneFileError(SceneError, OSError):
    """A scene file that is missing or cannot be read."""


class UnsupportedFormatError(SceneError, ValueError):
    """A file whose extension no loader handles."""


class InvalidMeshError(SceneError, ValueError):
    """An empty mesh, non-finite vertices, or label arrays that do not match the faces."""


class GeneratorConfigError(SceneError, ValueError):
    """A generator option (:class:`scenes.generator.GeneratorConfig`) of the wrong kind or out of its range."""


class SceneOptionError(SceneError, TypeError):
    """An option ``load_scene`` was given that the source's kind does not take (a TypeError, as
    Python's own for an unexpected keyword)."""


class StoreySizeError(SceneError, ValueError):
    """A storey beyond the limits of :mod:`scenes.limits`: too wide, too high, too many faces, too
    small, too low, too far from the origin, or two storeys in one. Most often a file drawn in
    millimetres or centimetres read as metres; the message names the likely unit or cause."""


class MissingStructureError(SceneError, ValueError):
    """A scene with no floor or no wall faces: there is nothing structural to scan."""


class FloorPlanError(SceneError, ValueError):
    """Invalid floor-plan JSON: a syntax error or a schema violation (``path`` names the field)."""


class PlanGeometryError(FloorPlanError):
    """A plan that parses but cannot be built: a self-intersecting room, a misplaced door, clutter
    blocking a door, clutter outside every room."""


class StoreyValidationError(SceneError, ValueError):
    """A built storey that fails validation: an unreachable room, a blocked start, a leak."""


class IfcError(SceneError, ValueError):
    """An IFC file with no storey, an unknown storey, or no walls on the chosen storey."""


class MissingDependencyError(SceneError, ImportError):
    """An optional dependency (an extra) is not installed; the message gives the install hint."""
