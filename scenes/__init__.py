"""Buildings as labelled meshes: the bottom floor of nbs-env, with nothing about robots.

``load_scene(spec, **options)`` is the one entry point. ``spec`` is one of:

- a bundled name (:func:`list_scenes`): ``"five_rooms"``, ``"l_room"``, ``"office"``;
- a floor-plan JSON path (see :mod:`scenes.floorplan` for the format);
- a labelled mesh path: ``.obj``, ``.glb``/``.gltf``, ``.ply`` (see :mod:`scenes.importers`);
- an ``.ifc`` path (needs the ``ifc`` extra; see :mod:`scenes.ifc`);
- ``"generated:SEED"``: a storey from the seeded generator (see :mod:`scenes.generator`);
- ``"corpus:NAME"``: a storey of the evaluation corpus (see :mod:`scenes.corpus`).

Everything a :class:`Scene` holds is ground truth: only the simulator and evaluation may read it.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

from scenes.errors import (
    FloorPlanError,
    IfcError,
    InvalidMeshError,
    MissingDependencyError,
    MissingStructureError,
    PlanGeometryError,
    SceneError,
    SceneFileError,
    StoreyValidationError,
    UnknownSceneError,
    UnsupportedFormatError,
)
from scenes.floorplan import ClutterPlan, DoorPlan, FloorPlan, RoomPlan, WindowPlan, extrude, load_plan
from scenes.generator import GeneratorConfig, generate_plan, generate_storey
from scenes.model import STRUCTURAL_CLASSES, Door, Room, Scene, StructureSamples, SurfaceClass

__all__ = [
    "STRUCTURAL_CLASSES",
    "ClutterPlan",
    "Door",
    "DoorPlan",
    "FloorPlan",
    "FloorPlanError",
    "GeneratorConfig",
    "IfcError",
    "InvalidMeshError",
    "MissingDependencyError",
    "MissingStructureError",
    "PlanGeometryError",
    "Room",
    "RoomPlan",
    "Scene",
    "SceneError",
    "SceneFileError",
    "StoreyValidationError",
    "StructureSamples",
    "SurfaceClass",
    "UnknownSceneError",
    "UnsupportedFormatError",
    "WindowPlan",
    "bundled_plan",
    "extrude",
    "generate_plan",
    "generate_storey",
    "list_scenes",
    "load_plan",
    "load_scene",
]

MESH_EXTENSIONS = (".obj", ".glb", ".gltf", ".ply")
SUPPORTED_EXTENSIONS = (".json", *MESH_EXTENSIONS, ".ifc")
_GENERATED = "generated:"
_CORPUS = "corpus:"


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
    text = (resources.files("scenes") / "data" / f"{name}.json").read_text()
    return FloorPlan.from_dict(json.loads(text), source=f"{name} (bundled)")


def load_scene(spec: str | Path | FloorPlan, **options: Any) -> Scene:
    """Load a building from any supported source.

    Parameters
    ----------
    spec : str, Path or FloorPlan
        A bundled name, a file path (``.json``, ``.obj``, ``.glb``, ``.gltf``, ``.ply``, ``.ifc``),
        ``"generated:SEED"``, or a :class:`FloorPlan`.
    **options
        - ``start=(x, y)``: override the start position (every source);
        - ``validate=True``: validate plan-based storeys (reachability, free start, closed);
        - for ``generated:SEED``: any :class:`GeneratorConfig` field, e.g. ``rooms=5``;
        - for meshes: ``y_up=True`` converts y-up coordinates (glTF convention) to z-up;
        - for IFC: ``storey`` (name or index), ``class_map`` (IFC class → SurfaceClass overrides),
          ``doors`` (``"open"``, the default: frames only; ``"closed"``: doors as drawn).

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        A subclass naming the source and the problem: :class:`UnknownSceneError`,
        :class:`SceneFileError`, :class:`UnsupportedFormatError`, :class:`InvalidMeshError`,
        :class:`MissingStructureError`, :class:`FloorPlanError`, :class:`PlanGeometryError`,
        :class:`StoreyValidationError`, :class:`IfcError` or :class:`MissingDependencyError`.
    TypeError
        An option that the chosen kind of source does not take.
    """
    start = options.pop("start", None)
    scene = _load(spec, options)
    if start is not None:
        scene.start = start
    return scene


def _take(options: dict[str, Any], allowed: tuple[str, ...], kind: str) -> dict[str, Any]:
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise TypeError(f"load_scene got options {unknown} that a {kind} does not take; it takes {list(allowed)}")
    return options


def _load(spec: str | Path | FloorPlan, options: dict[str, Any]) -> Scene:
    if isinstance(spec, FloorPlan):
        return extrude(spec, **_take(options, ("validate",), "floor plan"))
    if not isinstance(spec, (str, Path)):
        raise TypeError(f"scene spec must be a str, Path or FloorPlan, got {type(spec).__name__}")
    text = str(spec)
    if text.startswith(_CORPUS):
        from scenes.corpus import load_corpus_scene

        return load_corpus_scene(text[len(_CORPUS) :], **options)
    if text.startswith(_GENERATED):
        seed_text = text[len(_GENERATED) :]
        try:
            seed = int(seed_text)
        except ValueError:
            raise UnknownSceneError(text, f"the seed {seed_text!r} is not an integer (use generated:SEED)") from None
        fields = tuple(GeneratorConfig.__dataclass_fields__)
        opts = _take(options, (*fields, "validate"), "generated storey")
        opts.pop("validate", None)  # generated storeys are always validated
        try:
            _, scene = generate_storey(seed, GeneratorConfig(**opts))
        except ValueError as exc:
            if isinstance(exc, SceneError):
                raise
            raise UnknownSceneError(text, f"bad generator option: {exc}") from None
        scene.name = text  # as the user spelled it ("generated:05")
        return scene
    path = Path(text)
    suffix = path.suffix.lower()
    if not suffix and "/" not in text and "\\" not in text:
        if text in list_scenes():
            return extrude(bundled_plan(text), source=text, **_take(options, ("validate",), "bundled scene"))
        raise UnknownSceneError(
            text, f"no bundled scene of that name and no such file; bundled: {', '.join(list_scenes())}"
        )
    if suffix not in SUPPORTED_EXTENSIONS:
        raise UnsupportedFormatError(
            text, f"unsupported file type {suffix or '(none)'!r}; supported: {', '.join(SUPPORTED_EXTENSIONS)}"
        )
    if not path.is_file():
        raise SceneFileError(text, "no such file" if not path.exists() else "not a regular file")
    if suffix == ".json":
        return extrude(load_plan(path), source=text, **_take(options, ("validate",), "floor-plan file"))
    if suffix in MESH_EXTENSIONS:
        from scenes.importers import load_mesh_scene

        return load_mesh_scene(path, **_take(options, ("y_up", "name"), "mesh file"))
    from scenes.ifc import load_ifc_scene

    return load_ifc_scene(path, **_take(options, ("storey", "class_map", "name", "doors"), "IFC file"))
