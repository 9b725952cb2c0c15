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

import os
from typing import Any

from scenes.corpus import PREFIX as CORPUS_PREFIX
from scenes.corpus import load_corpus_scene
from scenes.errors import (
    FloorPlanError,
    GeneratorConfigError,
    IfcError,
    InvalidMeshError,
    MissingDependencyError,
    MissingStructureError,
    PlanGeometryError,
    SceneError,
    SceneFileError,
    SceneOptionError,
    StoreySizeError,
    StoreyValidationError,
    UnknownSceneError,
    UnsupportedFormatError,
)
from scenes.floorplan import ClutterPlan, DoorPlan, FloorPlan, RoomPlan, WindowPlan, extrude, load_plan
from scenes.generator import GeneratorConfig, generate_plan, generate_storey
from scenes.loader import MESH_EXTENSIONS as MESH_EXTENSIONS
from scenes.loader import SUPPORTED_EXTENSIONS as SUPPORTED_EXTENSIONS
from scenes.loader import as_spec as _as_spec
from scenes.loader import bundled_plan, list_scenes, load_source
from scenes.model import STRUCTURAL_CLASSES, Door, Room, Scene, StructureSamples, SurfaceClass

__all__ = [
    "STRUCTURAL_CLASSES",
    "ClutterPlan",
    "Door",
    "DoorPlan",
    "FloorPlan",
    "FloorPlanError",
    "GeneratorConfig",
    "GeneratorConfigError",
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
    "SceneOptionError",
    "StoreySizeError",
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


def load_scene(spec: str | os.PathLike[str] | FloorPlan, **options: Any) -> Scene:
    """Load a building from any supported source.

    Parameters
    ----------
    spec : str, os.PathLike (a Path) or FloorPlan
        A bundled name, a file path (``.json``, ``.obj``, ``.glb``, ``.gltf``, ``.ply``, ``.ifc``),
        ``"generated:SEED"``, or a :class:`FloorPlan`.
    **options
        - ``start=(x, y)``: override the start position (every source);
        - ``validate=True``: validate plan-based storeys (reachability, free start, closed);
        - for ``generated:SEED``: any :class:`GeneratorConfig` field, e.g. ``rooms=5``;
        - for meshes: ``y_up=True`` converts y-up coordinates (glTF convention) to z-up;
          ``units="mm"`` (or ``"cm"``, ``"ft"``, ``"in"``; default ``"m"``) scales the file to metres;
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
        :class:`StoreySizeError` (beyond the limits of :mod:`scenes.limits`: a file in millimetres,
        a georeferenced file far from the origin, a flattened model, two storeys in one file?),
        :class:`MissingStructureError`, :class:`FloorPlanError`, :class:`PlanGeometryError`,
        :class:`StoreyValidationError`, :class:`IfcError` or :class:`MissingDependencyError`.
    TypeError
        An option that the chosen kind of source does not take.
    ValueError
        A ``units`` that is none of :data:`scenes.limits.UNITS`.
    """
    start = options.pop("start", None)
    scene = _load(spec, options)
    if start is not None:
        scene.start = start
    return scene


def _load(spec: str | os.PathLike[str] | FloorPlan, options: dict[str, Any]) -> Scene:
    spec = _as_spec(spec)
    # Corpus entries are loaded through scenes.loader, so the corpus spec is told apart here, above both.
    if not isinstance(spec, FloorPlan) and str(spec).startswith(CORPUS_PREFIX):
        return load_corpus_scene(str(spec)[len(CORPUS_PREFIX) :], **options)
    return load_source(spec, options)
