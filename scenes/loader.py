"""Loading a building from a bundled name, a floor plan, a file or ``generated:SEED``.

This is everything :func:`scenes.load_scene` reads except ``"corpus:NAME"``: a corpus entry is itself
one of these sources, and :func:`scenes.corpus.load_corpus_scene` loads it through here, so this
module must not know the corpus.
"""

from __future__ import annotations

import json
import os
import re
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from scenes.errors import (
    GeneratorConfigError,
    MissingStructureError,
    SceneError,
    SceneFileError,
    SceneOptionError,
    StoreySizeError,
    StoreyValidationError,
    UnknownSceneError,
    UnsupportedFormatError,
)
from scenes.floorplan import FloorPlan, extrude, load_plan
from scenes.generator import GeneratorConfig, generate_storey
from scenes.labels import SurfaceClass
from scenes.limits import MAX_SEED_DIGITS, check_origin_distance, check_storey_shape
from scenes.model import Scene

__all__ = [
    "MESH_EXTENSIONS",
    "SUPPORTED_EXTENSIONS",
    "as_spec",
    "bundled_plan",
    "bundled_plan_path",
    "check_source",
    "list_scenes",
    "load_source",
]

MESH_EXTENSIONS = (".obj", ".glb", ".gltf", ".ply")
SUPPORTED_EXTENSIONS = (".json", *MESH_EXTENSIONS, ".ifc")
_GENERATED = "generated:"


def list_scenes() -> list[str]:
    """Names of the bundled scenes, sorted."""
    data = resources.files("scenes") / "data"
    return sorted(p.name[: -len(".json")] for p in data.iterdir() if p.name.endswith(".json"))


def bundled_plan(name: str) -> FloorPlan:
    """The floor plan of a bundled scene.

    Raises
    ------
    UnknownSceneError
        ``name`` is not bundled; the message lists the bundled names.
    """
    if name not in list_scenes():
        raise UnknownSceneError(name, f"no bundled scene of that name; bundled: {', '.join(list_scenes())}")
    text = _bundled_file(name).read_text()
    return FloorPlan.from_dict(json.loads(text), source=f"{name} (bundled)")


def bundled_plan_path(name: str) -> Path | None:
    """The plan file of a bundled scene, or None when ``name`` is not bundled (or its package is
    not on disk): what a path to that file names too."""
    if name not in list_scenes():
        return None
    path = Path(str(_bundled_file(name)))
    return path if path.exists() else None


def _bundled_file(name: str) -> Any:  # an importlib Traversable
    return resources.files("scenes") / "data" / f"{name}.json"


def load_source(spec: str | os.PathLike[str] | FloorPlan, options: dict[str, Any]) -> Scene:
    """Load a building from any source but a corpus entry: what :func:`scenes.load_scene` does for
    every other spec, with the ``start`` option already taken out.

    Every source, whatever its format, is then checked in one place against the limits of
    :mod:`scenes.limits` that the format loaders leave to it: a storey farther than
    :data:`~scenes.limits.MAX_ORIGIN_DISTANCE` from the origin, lower than
    :data:`~scenes.limits.MIN_STOREY_HEIGHT`, with walls of no area, or with floors on two storeys'
    levels is refused.

    Parameters
    ----------
    spec : str, os.PathLike or FloorPlan
        A bundled name, a file path, ``"generated:SEED"`` or a :class:`FloorPlan`.
    options : dict
        The options of :func:`scenes.load_scene` that the kind of source takes; the dict may be changed.

    Returns
    -------
    Scene
        The building with its labelled mesh, rooms, doors and start.

    Raises
    ------
    SceneError, TypeError
        As :func:`scenes.load_scene`: a source that cannot be loaded, an option it does not take.
    """
    spec = as_spec(spec)
    units, y_up = options.get("units", "m"), options.get("y_up", False)
    try:
        scene = _load_source(spec, options)
    except (StoreySizeError, StoreyValidationError, MissingStructureError) as exc:
        # A storey too small or with no floor is as often the options as the file: name the options.
        given = [f"--units {units}"] * (units != "m") + ["--y-up"] * bool(y_up)
        if given and not isinstance(spec, FloorPlan) and "read with" not in exc.problem:
            raise type(exc)(
                exc.source, f"{exc.problem} (it was read with {' and '.join(given)}: are they right for this file?)"
            ) from None
        raise
    if isinstance(spec, FloorPlan):
        source, hint = scene.name, _PLAN_LOW_HINT
    else:
        text = str(spec)
        suffix = Path(text).suffix.lower()
        # A file is named as the user spelled it (a name= option must not hide which file it was).
        source = scene.name if suffix not in (*MESH_EXTENSIONS, ".ifc") else text
        if suffix == ".ifc" and scene.metadata.get("storey") is not None:
            source = f"{text}#{scene.metadata['storey']}"
        hint = _MESH_LOW_HINT if suffix in MESH_EXTENSIONS else _IFC_LOW_HINT if suffix == ".ifc" else _PLAN_LOW_HINT
        if suffix in MESH_EXTENSIONS and y_up:
            hint = "is the model flattened, or is its up axis z (it was read with y up: --y-up, y_up=True)?"
        if suffix in MESH_EXTENSIONS and units != "m":
            # The option given is the likelier cause than one not given.
            hint = f"are its coordinates in {units} (it was read with --units {units}), or {hint}"
    vertices = scene.mesh.vertices
    check_origin_distance(source, vertices)
    check_storey_shape(source, vertices, scene.mesh.faces, scene.face_labels, low_hint=hint)
    if not isinstance(spec, FloorPlan) and suffix in MESH_EXTENSIONS and not scene.rooms:
        # No room outlines, and floor faces of no plan area: the start (and the robot's floor) would
        # be refused later with "no floor area", far from the cause, most often the up axis.
        floor = vertices[scene.mesh.faces[scene.face_labels == SurfaceClass.FLOOR]]
        cross = np.cross(floor[:, 1] - floor[:, 0], floor[:, 2] - floor[:, 0])[:, 2]
        if float(np.abs(cross).sum()) / 2 < 1e-6:
            axis = "it was read with y up (--y-up): is its up axis z?" if y_up else _MESH_LOW_HINT
            raise StoreyValidationError(source, f"its floor faces cover no floor area: {axis}")
    return scene


_MESH_LOW_HINT = "is the model flattened, or is its up axis y (pass --y-up, load_scene's y_up=True)?"
_IFC_LOW_HINT = "does the storey hold its walls and slabs, and is the file's unit right?"
_PLAN_LOW_HINT = "raise the plan's ceiling_height"


def as_spec(spec: Any) -> str | Path | FloorPlan:
    """``spec`` as :func:`load_source` reads it: any ``os.PathLike`` becomes a :class:`~pathlib.Path`.

    Raises
    ------
    TypeError
        ``spec`` is no str, path-like object or FloorPlan.
    """
    if isinstance(spec, (str, Path, FloorPlan)):
        return spec
    if isinstance(spec, os.PathLike):
        return Path(os.fsdecode(os.fspath(spec)))
    raise TypeError(f"scene spec must be a str, os.PathLike or FloorPlan, got {type(spec).__name__}")


def source_options(text: str) -> tuple[str, tuple[str, ...]]:
    """What kind of source ``text`` names and the :func:`scenes.load_scene` options it takes, from
    its name alone (nothing is read): so that a configuration can refuse an option its scene would
    refuse at the first load.

    Returns
    -------
    kind : str
        ``"generated storey"``, ``"bundled scene"``, ``"floor-plan file"``, ``"mesh file"`` or
        ``"IFC file"``.
    options : tuple of str
    """
    if text.startswith(_GENERATED):
        return "generated storey", (*GeneratorConfig.__dataclass_fields__, "validate")
    suffix = Path(text).suffix.lower()
    if not suffix and "/" not in text and "\\" not in text:
        return "bundled scene", ("validate",)
    if suffix == ".json":
        return "floor-plan file", ("validate",)
    if suffix in MESH_EXTENSIONS:
        return "mesh file", ("y_up", "units", "name")
    return "IFC file", ("storey", "class_map", "name", "doors")


def _load_source(spec: str | Path | FloorPlan, options: dict[str, Any]) -> Scene:
    if isinstance(spec, FloorPlan):
        return extrude(spec, **_take(options, ("validate",), "floor plan"))
    text = str(spec)
    check_source(text)
    kind, allowed = source_options(text)
    if text.startswith(_GENERATED):
        seed = int(text[len(_GENERATED) :])
        opts = _take(options, allowed, kind)
        opts.pop("validate", None)  # generated storeys are always validated
        try:
            _, scene = generate_storey(seed, GeneratorConfig(**opts))
        except ValueError as exc:
            if isinstance(exc, SceneError) and not isinstance(exc, GeneratorConfigError):
                raise
            raise GeneratorConfigError(text, f"bad generator option: {getattr(exc, 'problem', exc)}") from None
        scene.name = text  # as the user spelled it ("generated:05")
        return scene
    path = Path(text)
    suffix = path.suffix.lower()
    if not suffix and "/" not in text and "\\" not in text:
        return extrude(bundled_plan(text), source=text, **_take(options, allowed, kind))
    if suffix == ".json":
        return extrude(load_plan(path), source=text, **_take(options, allowed, kind))
    if suffix in MESH_EXTENSIONS:
        from scenes.importers import load_mesh_scene

        return load_mesh_scene(path, **_take(options, allowed, kind))
    from scenes.ifc import load_ifc_scene

    return load_ifc_scene(path, **_take(options, allowed, kind))


def check_source(text: str) -> None:
    """Whether ``text`` names a source :func:`load_source` can try, without reading it: a
    ``generated:SEED`` with an integer seed, a bundled name, or an existing regular file of a
    supported type. What a command checks for every scene before any run starts.

    Raises
    ------
    UnknownSceneError, UnsupportedFormatError, SceneFileError
        As :func:`load_source` would, naming the source.
    """
    if not text.strip():  # Path("") is the working folder: it was called "a folder, not a scene file"
        raise UnknownSceneError(text, "the scene's name is empty: name a bundled scene, a scene file or generated:SEED")
    if text.startswith(_GENERATED):
        seed_text = text[len(_GENERATED) :]
        # ASCII digits: Python's int also reads " 1", "+1", "1_0" and Arabic-Indic digits, so one
        # storey had several names (a comparison ran it twice).
        if not re.fullmatch(r"[0-9]+", seed_text):
            raise UnknownSceneError(
                text, f"the seed {seed_text[:40]!r} is not an integer >= 0 in digits (use generated:SEED)"
            )
        if len(seed_text) > MAX_SEED_DIGITS:  # Python's int refuses 4,300 digits with a ValueError
            raise UnknownSceneError(
                text, f"the seed has {len(seed_text):,} digits; a generated storey's seed has at most {MAX_SEED_DIGITS}"
            )
        return
    path = Path(text)
    if text.endswith(("/", "\\")):
        # Path drops a trailing separator, so "p.json/" read the file p.json, which the system
        # refuses under that name ("Not a directory") and the report then recorded.
        raise SceneFileError(
            text, "a folder, not a scene file" if path.is_dir() else "a name ending in a separator names a folder"
        )
    suffix = path.suffix.lower()
    if not suffix and "/" not in text and "\\" not in text:
        if text not in list_scenes():
            if path.is_dir():
                problem = "a folder, not a scene file"
            elif path.exists():
                problem = f"a file without a type suffix ({', '.join(SUPPORTED_EXTENSIONS)})"
            else:
                problem = "no bundled scene of that name and no such file"
            raise UnknownSceneError(text, f"{problem}; bundled: {', '.join(list_scenes())}")
        return
    if suffix not in SUPPORTED_EXTENSIONS:
        raise UnsupportedFormatError(
            text, f"unsupported file type {suffix or '(none)'!r}; supported: {', '.join(SUPPORTED_EXTENSIONS)}"
        )
    try:
        regular = path.is_file()
        present = path.exists()
    except OSError as exc:  # a name too long, a loop of links
        raise SceneFileError(text, exc.strerror or str(exc)) from None
    if not regular:
        raise SceneFileError(text, "no such file" if not present else "not a regular file")


def _take(options: dict[str, Any], allowed: tuple[str, ...], kind: str) -> dict[str, Any]:
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise SceneOptionError(
            "load_scene", f"options {unknown} do not apply to this source ({kind}); it takes {list(allowed)}"
        )
    return options
