"""The evaluation corpus (scenes.corpus): every entry loads as a storey the robot can start in, the
suites list what can run here, and local-only files are skipped, never required."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from scenes import SceneError, UnknownSceneError, load_scene
from scenes.corpus import SHARED_DATA_VARIABLE, corpus, corpus_entry, suite
from scenes.geometry import STOREY_CLEARANCE, point_is_free

SHIPPED = [e.name for e in corpus().values() if not e.local]
IFC = {name for name in SHIPPED if (corpus_entry(name).file or "").endswith(".ifc")}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.expensive) if n in IFC else n for n in SHIPPED])
def test_every_shipped_entry_loads_as_a_storey_to_start_in(name):
    scene = load_scene(f"corpus:{name}")
    assert scene.name == f"corpus:{name}" and scene.rooms
    start = scene.start
    assert any(shapely.contains_xy(Polygon(r.polygon), *start[:2]) for r in scene.rooms)
    assert point_is_free(scene, start[:2], float(start[2]), STOREY_CLEARANCE)


def test_the_unseen_suite_is_every_entry_and_skips_absent_local_files(monkeypatch, tmp_path):
    monkeypatch.setenv(SHARED_DATA_VARIABLE, str(tmp_path))  # an empty folder: no local file here
    present, skipped = suite("unseen")
    local = [e.name for e in corpus().values() if e.local]
    assert local and sorted(skipped) == sorted(local)
    assert [p.removeprefix("corpus:") for p in present] == SHIPPED
    with pytest.raises(SceneError, match=SHARED_DATA_VARIABLE):
        load_scene(f"corpus:{local[0]}")


def test_unknown_names_are_refused_with_the_list():
    with pytest.raises(UnknownSceneError, match="corridor_flat"):
        load_scene("corpus:no_such_storey")
    with pytest.raises(UnknownSceneError, match="unseen"):
        suite("no_such_suite")


def test_the_room_named_and_room_less_copies_hold_the_same_faces():
    named, bare = load_scene("corpus:u_office_rooms"), load_scene("corpus:u_office")
    assert np.array_equal(named.mesh.faces, bare.mesh.faces) and np.array_equal(named.face_labels, bare.face_labels)
    assert named.metadata["rooms"] == "file" and bare.metadata["rooms"] == "derived"
