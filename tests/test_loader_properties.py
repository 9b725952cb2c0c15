"""Property-based tests of the three loaders: any input loads into a valid Scene or raises a SceneError.

Nothing else may escape (no KeyError, TypeError, IndexError, numpy or trimesh error from inside), and
nothing may hang: every example has a time bound. The examples are drawn deterministically
(``derandomize``), few enough for the default suite.
"""

from __future__ import annotations

import copy
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from helpers import time_limit, two_room_plan  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from scenes import Scene, SceneError, load_scene  # noqa: E402
from scenes.corpus import corpus_entry  # noqa: E402

DATA = Path(__file__).parent / "data"
FZK = corpus_entry("fzk_haus_eg").path()

#: The valid two-room plan, with a window too.
PLAN = {
    **two_room_plan(),
    "windows": [{"room": "a", "position": [0, 2], "width": 1.2, "height": 1.2, "sill": 0.9}],
}

#: Bounded work: a loader that takes longer than this on a small input counts as a hang.
SECONDS = 30
SETTINGS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def loads_or_refuses(path: Path, **options) -> Scene | None:
    """The property: a valid Scene, or a SceneError; nothing else, and within the time bound."""
    try:
        with time_limit(SECONDS):
            scene = load_scene(str(path), **options)
            start = scene.start  # chosen lazily when the file gives none; it may find no free floor
    except SceneError as exc:
        hypothesis.event(f"refused: {type(exc).__name__}")
        return None
    hypothesis.event("loaded")
    assert isinstance(scene, Scene)
    assert len(scene.face_labels) == len(scene.mesh.faces) == len(scene.face_rooms) > 0
    assert np.all(np.isfinite(scene.mesh.vertices))
    assert np.all(np.isfinite(start))
    return scene


# ---------------------------------------------------------------------- floor-plan JSON
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.lists(st.floats(-20, 20), max_size=4),
    st.lists(st.lists(st.floats(-20, 20, allow_nan=False), min_size=2, max_size=2), max_size=5),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _paths(node, prefix=()):
    """Every place in a JSON document a value could be replaced."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _paths(value, (*prefix, i))


PLACES = [p for p in _paths(PLAN) if p]


@st.composite
def broken_plans(draw):
    """The valid plan with one to three of its values replaced or removed: by anything JSON holds
    (type errors, NaN, huge values), or by a number near the one it replaces (geometric edge cases:
    overlapping rooms, doors off their wall, clutter in a doorway)."""
    near = st.tuples(st.floats(-1.0, 3.0), st.floats(-1.0, 1.0)).map(lambda ab: lambda old: old * ab[0] + ab[1])
    return damaged(draw, copy.deepcopy(PLAN), PLACES, near)


def damaged(draw, document, places, number) -> Any:
    """``document`` with one to three of its ``places`` replaced or removed: a number by ``number``'s
    function of it (or by anything JSON holds), any value by anything JSON holds, or dropped."""
    for _ in range(draw(st.integers(1, 3))):
        place = draw(st.sampled_from(places))
        parent = document
        try:
            for key in place[:-1]:
                parent = parent[key]
            old = parent[place[-1]]
            if isinstance(old, (int, float)) and not isinstance(old, bool) and draw(st.booleans()):
                parent[place[-1]] = draw(number)(old)
            elif draw(st.integers(0, 3)) == 0 and isinstance(parent, dict):
                parent.pop(place[-1], None)
            else:
                parent[place[-1]] = draw(VALUES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed the place
    return document


@SETTINGS
@given(plan=broken_plans())
def test_any_floor_plan_loads_or_raises_a_scene_error(plan):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "plan.json"
        path.write_text(json.dumps(plan))  # NaN and Infinity as Python's json writes them
        loads_or_refuses(path)


# ---------------------------------------------------------------------- labelled meshes
NAMES = st.sampled_from(["wall_a", "floor", "ceiling_1", "clutter_desk", "door_x", "window", "thing", "w", "room"])


def _box_room(size: tuple[float, float, float]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """A room as separate labelled parts, faces towards the inside."""
    x, y, z = size
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    corners = {
        "floor_0": [[0, 0, 0], [x, 0, 0], [x, y, 0], [0, y, 0]],
        "ceiling_0": [[0, 0, z], [0, y, z], [x, y, z], [x, 0, z]],
        "wall_south": [[0, 0, 0], [0, 0, z], [x, 0, z], [x, 0, 0]],
        "wall_east": [[x, 0, 0], [x, 0, z], [x, y, z], [x, y, 0]],
        "wall_north": [[x, y, 0], [x, y, z], [0, y, z], [0, y, 0]],
        "wall_west": [[0, y, 0], [0, y, z], [0, 0, z], [0, 0, 0]],
    }
    return {name: (np.asarray(c, dtype=float), quad) for name, c in corners.items()}


@st.composite
def meshes(draw):
    """A box room whose parts may be dropped, jittered or renamed, with random extra parts."""
    import trimesh

    size = (draw(st.floats(0.5, 12)), draw(st.floats(0.5, 12)), draw(st.floats(0.3, 5)))
    parts = _box_room(size)
    scene = trimesh.Scene()
    for name, (vertices, faces) in parts.items():
        if draw(st.integers(0, 5)) == 0:
            continue  # a part left out (no floor, a wall missing: a room open to the outside)
        vertices = vertices + np.asarray(draw(st.lists(st.floats(-0.3, 0.3), min_size=12, max_size=12))).reshape(4, 3)
        if draw(st.integers(0, 5)) == 0:
            name = f"{draw(NAMES)}_{name}"
        scene.add_geometry(trimesh.Trimesh(vertices, faces, process=False), geom_name=name, node_name=name)
    for k in range(draw(st.integers(0, 3))):
        n = draw(st.integers(3, 8))
        vertices = np.array(draw(st.lists(st.tuples(*[st.floats(-1, 13)] * 3), min_size=n, max_size=n)))
        faces = np.array(draw(st.lists(st.tuples(*[st.integers(0, n - 1)] * 3), min_size=1, max_size=6)))
        name = f"{draw(NAMES)}_extra{k}"
        scene.add_geometry(trimesh.Trimesh(vertices, faces, process=False), geom_name=name, node_name=name)
    return scene, draw(st.sampled_from([".obj", ".ply", ".glb"]))


@pytest.mark.filterwarnings("ignore::UserWarning")  # parts without a class prefix are announced
@SETTINGS
@given(case=meshes())
def test_any_labelled_mesh_loads_or_raises_a_scene_error(case):
    scene, suffix = case
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"mesh{suffix}"
        data = scene.export(file_type=suffix[1:]) if scene.geometry else b""  # trimesh exports no empty scene
        path.write_bytes(data if isinstance(data, bytes) else data.encode())
        loads_or_refuses(path)


@pytest.mark.filterwarnings("ignore::UserWarning")
@SETTINGS
@given(data=st.binary(max_size=400), suffix=st.sampled_from([".obj", ".ply", ".glb", ".gltf", ".json"]))
def test_any_bytes_with_a_scene_suffix_load_or_raise_a_scene_error(data, suffix):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"scene{suffix}"
        path.write_bytes(data)
        loads_or_refuses(path)


#: A labelled box room as text, in the two text formats whose bodies are read line by line.
_BOX_PLY = (
    "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 6\nproperty list uchar int vertex_indices\nproperty uchar label\nproperty int room\n"
    "end_header\n0 0 0\n4 0 0\n4 3 0\n0 3 0\n0 0 2.5\n4 0 2.5\n4 3 2.5\n0 3 2.5\n"
    "4 0 1 2 3 0 0\n4 4 7 6 5 1 0\n4 0 4 5 1 2 0\n4 1 5 6 2 2 0\n4 2 6 7 3 2 0\n4 3 7 4 0 2 0\n"
)
_BOX_OBJ = (
    "v 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n"
    "o floor_room0\nf 1 2 3 4\no ceiling_room0\nf 5 8 7 6\no wall_room0\nf 1 5 6 2\nf 2 6 7 3\n"
    "f 3 7 8 4\nf 4 8 5 1\n"
)
TOKENS = st.sampled_from(
    ["0", "-1", "3", "2.5", "1e308", "-1e308", "nan", "inf", "x", "", "99999999999999999999", "0x1F", "#"]
)


@st.composite
def edited_texts(draw):
    """A labelled box room's OBJ or ASCII PLY text with one to four edits of its lines or words: a
    word replaced, inserted or dropped, a line dropped, doubled or swapped with another."""
    suffix, text = draw(st.sampled_from([(".ply", _BOX_PLY), (".obj", _BOX_OBJ)]))
    lines = text.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        words = lines[i].split()
        edit = draw(st.sampled_from(["replace", "insert", "drop_word", "drop_line", "double", "swap"]))
        if edit in ("replace", "insert", "drop_word") and words:
            k = draw(st.integers(0, len(words) - 1))
            if edit == "replace":
                words[k] = draw(TOKENS)
            elif edit == "insert":
                words.insert(k, draw(TOKENS))
            else:
                del words[k]
            lines[i] = " ".join(words)
        elif edit == "drop_line":
            del lines[i]
        elif edit == "double":
            lines.insert(i, lines[i])
        else:
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        if not lines:
            lines = [""]
    return suffix, "\n".join(lines) + "\n"


@pytest.mark.filterwarnings("ignore::UserWarning")
@settings(SETTINGS, max_examples=60)
@given(case=edited_texts())
def test_any_edit_of_a_text_mesh_loads_or_raises_a_scene_error(case):
    """The bodies of text meshes, which random bytes rarely reach: short, long and wordy rows."""
    suffix, text = case
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"room{suffix}"
        path.write_text(text)
        loads_or_refuses(path)


# ---------------------------------------------------------------------- IFC
@settings(SETTINGS, max_examples=6)
@given(cut=st.floats(0.0, 0.999), flip=st.integers(0, 10**9))
def test_any_damaged_ifc_loads_or_raises_a_scene_error(cut, flip):
    pytest.importorskip("ifcopenshell")
    data = bytearray(FZK.read_bytes())
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "damaged.ifc"
        # A truncated copy, then one with a byte changed inside (the end marker kept).
        path.write_bytes(bytes(data[: int(cut * len(data))]))
        assert loads_or_refuses(path, storey="Erdgeschoss") is None
        k = 200 + flip % (len(data) - 400)
        data[k] = (data[k] + 1 + flip % 200) % 256
        path.write_bytes(bytes(data))
        loads_or_refuses(path)


# ---------------------------------------------------------------------- checkpoints
REFERENCE = Path(__file__).parents[1] / "policies" / "data" / "ppo_reference"


def _reference_document() -> dict:
    return json.loads((REFERENCE / "policy.json").read_text())


CHECKPOINT_PLACES = [p for p in _paths(_reference_document()) if p]


#: How a checkpoint's tensors may differ from a float network's weights and still pass
#: ``torch.load(weights_only=True)``: :func:`_variant_weights` applies one to one tensor.
TENSOR_VARIANTS = ["float64", "float16", "int64", "bool", "complex64", "meta", "sparse", "strided", "extra", "number"]


def _variant_weights(variant: str, which: int, path: Path) -> str:
    """Write the reference weights with tensor number ``which`` changed by ``variant`` to ``path``;
    returns the file's SHA-256."""
    import hashlib

    import torch

    state = torch.load(REFERENCE / "policy.pt", weights_only=True)
    name = sorted(state)[which % len(state)]
    tensor = state[name]
    if variant in ("float64", "float16", "int64", "bool", "complex64"):
        state[name] = tensor.to(getattr(torch, variant))
    elif variant == "meta":
        state[name] = tensor.to("meta")
    elif variant == "sparse":
        state[name] = tensor.to_sparse()
    elif variant == "strided":  # not contiguous, the same numbers
        state[name] = tensor.t().contiguous().t() if tensor.dim() == 2 else tensor
    elif variant == "extra":
        state[f"{name}.extra"] = tensor.clone()
    else:
        state[which] = tensor.clone()
    torch.save(state, path)
    return hashlib.sha256(path.read_bytes()).hexdigest()


@st.composite
def broken_checkpoints(draw):
    """The reference checkpoint's description with one to three values replaced or removed (its weights
    untouched, so that a change reaches past the checksum), or its weights replaced by other bytes (the
    checksum made to match, so that they reach torch's tensors-only reader), or one of its tensors
    changed in kind (:data:`TENSOR_VARIANTS`, written when the test runs)."""
    document = _reference_document()
    weights = None
    choice = draw(st.integers(0, 5))
    if choice == 5:  # tensors that torch's tensors-only reader passes, of another kind than weights
        return document, (draw(st.sampled_from(TENSOR_VARIANTS)), draw(st.integers(0, 15)))
    if choice == 0:
        data = (REFERENCE / "policy.pt").read_bytes()
        weights = draw(
            st.one_of(
                st.binary(max_size=300),
                st.integers(0, len(data) - 1).map(lambda n: data[:n]),
            )
        )
        import hashlib

        document["sha256"] = hashlib.sha256(weights).hexdigest()
        return document, weights
    extremes = st.sampled_from([0, -1, 10**9, 10**30, 2.5, float("nan")]).map(lambda v: lambda old: v)
    return damaged(draw, document, CHECKPOINT_PLACES, extremes), weights


@settings(SETTINGS, max_examples=80)
@given(case=broken_checkpoints())
def test_any_damaged_checkpoint_drives_a_run_or_is_refused_in_one_line(case, capsys, monkeypatch):
    """Through ``nbs scan --policy ppo:DIR``'s door, the episode itself replaced: a checkpoint either
    gives a run configuration its checks accept, or exit 2 (a configuration it cannot drive) or 1 (a
    file it cannot read) with one line; never a traceback or an allocation its description claims."""
    pytest.importorskip("torch")
    import shutil

    import train.cli
    from train.cli import EXIT_SCENE_ERROR, EXIT_USAGE, main

    document, weights = case
    reached = []
    monkeypatch.setattr(train.cli, "_scan", lambda args, policy, out, config, stop: reached.append(config) or 0)
    with tempfile.TemporaryDirectory() as folder:
        checkpoint = Path(folder) / "ckpt"
        shutil.copytree(REFERENCE, checkpoint)
        (checkpoint / "policy.json").write_text(json.dumps(document))
        if isinstance(weights, tuple):
            document["sha256"] = _variant_weights(*weights, checkpoint / "policy.pt")
            (checkpoint / "policy.json").write_text(json.dumps(document))
        elif weights is not None:
            (checkpoint / "policy.pt").write_bytes(weights)
        argv = ["scan", "--scene", "l_room", "--policy", f"ppo:{checkpoint}", "--out", f"{folder}/r", "--quiet"]
        try:
            with time_limit(SECONDS):
                code = main(argv)
        except SystemExit as exc:
            code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    if code == 0:
        hypothesis.event("accepted")
        assert len(reached) == 1
        return
    hypothesis.event(f"refused with {code}")
    assert code in (EXIT_USAGE, EXIT_SCENE_ERROR), (code, err)
    assert len(err.strip().splitlines()) == 1 and err.startswith("nbs scan: error: "), err
