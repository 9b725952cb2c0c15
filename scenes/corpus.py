"""The evaluation corpus: storeys our generator did not make, named ``corpus:NAME``, and the suites that
group them (``suite:unseen``).

The corpus is for measuring, never for tuning: a default chosen by looking at it must say so where it
is defined. Its entries are listed in ``scenes/data/corpus/corpus.json``; each is one of

- a file shipped in that folder (labelled meshes authored directly with trimesh by
  ``scenes/data/corpus/make_corpus.py``, in several construction styles, and the FZK-Haus IFC model),
  loaded with the entry's ``options`` (an IFC ``storey``, ``y_up``, a ``start``);
- a file that may not be shipped (``"local": true``): looked up under the folder named by the
  ``NBS_SHARED_DATA`` environment variable, else ``../shared/data`` of the working directory; absent,
  the entry is left out of its suites (:func:`suite` says which were skipped);
- a generated storey at the edges of the generator (``"generated": SEED`` with generator options).

:func:`load_corpus_scene` loads one; :func:`scenes.load_scene` takes ``"corpus:NAME"`` too.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from scenes.errors import SceneError, SceneFileError, UnknownSceneError
from scenes.loader import load_source, source_options

__all__ = [
    "PREFIX",
    "SHARED_DATA_VARIABLE",
    "SUITES",
    "CorpusEntry",
    "corpus",
    "corpus_entry",
    "load_corpus_scene",
    "suite",
]

#: The scene-spec prefix of a corpus entry.
PREFIX = "corpus:"
#: Environment variable naming the folder of local-only data (files we may not ship).
SHARED_DATA_VARIABLE = "NBS_SHARED_DATA"
#: Suites by name: the corpus entries each runs, in order. ``unseen`` is every entry.
SUITES: dict[str, tuple[str, ...] | None] = {"unseen": None}


@dataclass(frozen=True)
class CorpusEntry:
    """One storey of the corpus (fields as in ``corpus.json``)."""

    name: str
    file: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    styles: tuple[str, ...] = ()
    description: str = ""
    local: bool = False
    generated: int | None = None

    @property
    def spec(self) -> str:
        return PREFIX + self.name

    def path(self) -> Path | None:
        """The entry's file, None when it is generated or a local-only file that is absent."""
        if self.file is None:
            return None
        if self.local:
            root = Path(os.environ.get(SHARED_DATA_VARIABLE) or Path.cwd().parent / "shared" / "data")
            path = root / self.file
            return path if path.is_file() else None
        return Path(str(resources.files("scenes") / "data" / "corpus" / self.file))

    @property
    def available(self) -> bool:
        return self.generated is not None or self.path() is not None


@cache
def corpus() -> dict[str, CorpusEntry]:
    """Every corpus entry by name, in the manifest's order."""
    text = (resources.files("scenes") / "data" / "corpus" / "corpus.json").read_text(encoding="utf-8")
    data = json.loads(text)
    entries = {}
    for raw in data["entries"] if isinstance(data, dict) else data:
        known = {k: raw[k] for k in CorpusEntry.__dataclass_fields__ if k in raw}
        known["styles"] = tuple(known.get("styles", ()))
        if "start" in raw:  # the manifest's start is a load option like any other
            known["options"] = {**known.get("options", {}), "start": tuple(raw["start"])}
        entry = CorpusEntry(**known)
        entries[entry.name] = entry
    return entries


def corpus_entry(name: str) -> CorpusEntry:
    """The entry ``name`` (without the ``corpus:`` prefix).

    Raises
    ------
    UnknownSceneError
        No entry of that name; the message lists them.
    """
    entries = corpus()
    if name not in entries:
        raise UnknownSceneError(PREFIX + name, f"no corpus entry of that name; entries: {', '.join(entries)}")
    return entries[name]


def suite(name: str) -> tuple[list[str], list[str]]:
    """The scene specs of suite ``name`` that can run here, and the names of those skipped (local-only
    files that are absent).

    Raises
    ------
    UnknownSceneError
        No suite of that name.
    """
    if name not in SUITES:
        raise UnknownSceneError(f"suite:{name}", f"no suite of that name; suites: {', '.join(SUITES)}")
    names = SUITES[name] or tuple(corpus())
    entries = [corpus_entry(n) for n in names]
    return [e.spec for e in entries if e.available], [e.name for e in entries if not e.available]


def corpus_source_options(name: str) -> tuple[str, tuple[str, ...]]:
    """:func:`scenes.loader.source_options` of corpus entry ``name``: those of its source, which
    take the options given over the entry's own (:func:`load_corpus_scene`)."""
    try:
        entry = corpus_entry(name)
    except SceneError:
        return "corpus entry", ()
    inner = f"generated:{entry.generated}" if entry.generated is not None else str(entry.file)
    kind, allowed = source_options(inner)
    return f"corpus entry, a {kind}", allowed


def load_corpus_scene(name: str, **options: Any):
    """Load corpus entry ``name`` with its options, ``options`` given here overriding them.

    Raises
    ------
    UnknownSceneError
        No entry of that name.
    SceneFileError
        A local-only entry whose file is absent (the message says where it was looked for).
    """
    entry = corpus_entry(name)
    merged = {**entry.options, **options}
    start = merged.pop("start", None)
    if entry.generated is not None:
        scene = load_source(f"generated:{entry.generated}", merged)
    else:
        path = entry.path()
        if path is None:
            where = os.environ.get(SHARED_DATA_VARIABLE) or str(Path.cwd().parent / "shared" / "data")
            raise SceneFileError(
                entry.spec, f"local-only file {entry.file!r} not found under {where} (set {SHARED_DATA_VARIABLE})"
            )
        scene = load_source(path, merged)
    scene.name = entry.spec
    if start is not None:
        scene.start = start
    return scene
