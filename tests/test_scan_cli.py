"""``nbs scan`` and its report files (nbs_env.export): the metrics schema, the clouds, the model."""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from nbs_env.belief import RoomModel
from nbs_env.evaluation import QualityConfig, QualityReport
from nbs_env.export import FACE_KINDS, structural_model, write_model_obj, write_points_ply
from nbs_env.perception.faces import WallFace
from nbs_env.report import SCHEMA, metrics_dict
from scenes import Room, load_scene
from train.cli import EXIT_SCENE_ERROR, EXIT_USAGE, main

# A coarse, fast episode of the small bundled scene.
FAST = ["scan", "--scene", "l_room", "--resolution", "1", "--voxel", "0.1", "--max-scans", "3"]


def nbs(*args: str) -> int:
    """Run the CLI in-process; argparse's usage errors arrive as SystemExit."""
    try:
        return main(list(args))
    except SystemExit as exc:
        return int(exc.code)


def read_ply(path: Path) -> np.ndarray:
    """A binary little-endian PLY vertex element as a structured array (our writer's subset)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[:2] == ["ply", "format binary_little_endian 1.0"]
    n = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    types = {"float": "<f4", "uchar": "u1"}
    dtype = [(line.split()[2], types[line.split()[1]]) for line in header if line.startswith("property")]
    array = np.frombuffer(data[end:], dtype=np.dtype(dtype))
    assert len(array) == n
    return array


def strip_times(value):
    """``value`` without the wall-clock fields (they differ between runs)."""
    if isinstance(value, dict):
        return {k: strip_times(v) for k, v in value.items() if k not in ("processing_time_s", "policy_time_s", "times")}
    if isinstance(value, list):
        return [strip_times(v) for v in value]
    return value


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> SimpleNamespace:
    out = tmp_path_factory.mktemp("scan") / "report"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = nbs(*FAST, "--seed", "3", "--out", str(out), "--quiet")
    assert code == 0
    metrics = json.loads((out / "metrics.json").read_text())
    return SimpleNamespace(out=out, metrics=metrics, stdout=stdout.getvalue())


# ---------------------------------------------------------------------- the report
TOP_LEVEL = {
    "schema": str,
    "scene": str,
    "scene_offset_m": type(None),  # a list [x, y] for an IFC storey at survey coordinates
    "policy": str,
    "seed": int,
    "complete": bool,
    "scans": int,
    "structure_sensed_pct": float,
    "path_length_m": float,
    "processed_points": int,
    "measured_points": int,
    "processing_time_s": float,
    "policy_time_s": float,
    "acquisition_time_s": float,
    "travel_time_s": float,
    "registration_error": dict,
    "quality": dict,
    "registrability": dict,
    "rooms": list,
    "steps": list,
    "door_events": list,
    "room_ends": list,
    "wall_searches": list,
    "scanner": (dict, type(None)),
    "config": dict,
}
ROOM_KEYS = {
    "id": int,
    "name": str,
    "scans": int,
    "structure_sensed_pct": float,
    "path_length_m": float,
    "processed_points": int,
    "processing_time_s": float,
    "quality_pct": float,
}
STEP_KEYS = {
    "scan": int,
    "room": (int, type(None)),
    "position": list,
    "estimated_position": list,
    "estimated_rotation": list,
    "predicted_gain": int,
    "structure_sensed_pct": float,
    "path_length_m": float,
    "processing_time_s": float,
    "points": int,
    "structure_points": int,
    "door": bool,
    "times": dict,
    "registration_refused": str,
    "registration_overlap": (float, type(None)),
    "registration_fitness": (float, type(None)),
    "dense_pct": float,
    "incidence_pct": float,
    "quality_pct": float,
}


def check_types(record: dict, spec: dict) -> None:
    assert set(record) == set(spec), set(record) ^ set(spec)
    for key, kind in spec.items():
        assert isinstance(record[key], kind), (key, record[key])
        if kind is int:
            assert not isinstance(record[key], bool), key


def test_metrics_json_has_the_schema(report):
    m = report.metrics
    check_types(m, TOP_LEVEL)
    assert m["schema"] == SCHEMA == "nbs-metrics/1"
    assert (m["scene"], m["policy"], m["seed"]) == ("l_room", "greedy", 3)
    assert m["scans"] == 3 and not m["complete"]  # the budget of 3 scans ends it
    assert 0 < m["structure_sensed_pct"] <= 100
    assert m["processed_points"] > 0 and m["acquisition_time_s"] > 0
    assert m["travel_time_s"] == pytest.approx(m["path_length_m"] / m["config"]["travel_speed"])
    assert set(m["registration_error"]) == {"mean_m", "max_m", "mean_deg", "max_deg"}
    assert all(isinstance(v, float) and v >= 0 for v in m["registration_error"].values())
    assert m["registration_error"]["mean_m"] <= m["registration_error"]["max_m"]
    # The config is the env's, JSON-safe (tuples became lists).
    assert m["config"]["max_scans"] == 3 and m["config"]["scene"] == "l_room"
    assert m["config"]["robot"]["scanner"]["angular_step"] == 1.0 and m["config"]["robot"]["voxel_size"] == 0.1
    assert isinstance(m["config"]["observation"]["shape"], list)
    assert m["scanner"] is None  # the method's generic scanner, no datasheet preset


def test_rooms_are_the_true_rooms(report):
    m = report.metrics
    scene = load_scene("l_room")
    assert [r["id"] for r in m["rooms"]] == [r.id for r in scene.rooms]
    for room in m["rooms"]:
        check_types(room, ROOM_KEYS)
    (room,) = m["rooms"]
    assert room["name"] == "l_room" and room["scans"] == 3
    assert room["structure_sensed_pct"] == pytest.approx(m["structure_sensed_pct"])
    assert room["path_length_m"] == pytest.approx(m["path_length_m"])
    assert room["processed_points"] == m["processed_points"]


def test_steps_one_per_scan_with_cumulative_fields(report):
    steps = report.metrics["steps"]
    assert len(steps) == report.metrics["scans"]
    for k, step in enumerate(steps):
        check_types(step, STEP_KEYS)
        assert step["scan"] == k and step["room"] == 0
        assert len(step["position"]) == 3 and len(step["estimated_position"]) == 3
        assert set(step["times"]) >= {"scan", "registration", "roi", "classification", "voxels", "planning"}
    for key in ("structure_sensed_pct", "path_length_m"):
        values = [s[key] for s in steps]
        assert all(b >= a for a, b in itertools.pairwise(values)), (key, values)
    assert steps[-1]["structure_sensed_pct"] == pytest.approx(report.metrics["structure_sensed_pct"])
    assert steps[-1]["path_length_m"] == pytest.approx(report.metrics["path_length_m"])
    assert steps[0]["position"][:2] == [3.0, 4.5]  # l_room's start
    assert steps[1]["position"] != steps[0]["position"]  # the robot moved


def test_point_clouds_load_and_structure_is_part_of_the_cloud(report):
    from scenes._open3d import open3d

    o3d = open3d()
    structure = np.asarray(o3d.io.read_point_cloud(str(report.out / "structure.ply")).points)
    cloud = np.asarray(o3d.io.read_point_cloud(str(report.out / "cloud.ply")).points)
    assert 0 < len(structure) < len(cloud)
    labels = read_ply(report.out / "cloud.ply")["label"]
    assert set(np.unique(labels)) == {0, 1}
    assert int((labels == 1).sum()) == len(structure)
    np.testing.assert_array_equal(cloud[labels == 1], structure)
    # The points lie in the building (with a margin for noise and drift).
    lo, hi = load_scene("l_room").mesh.bounds
    assert np.all(cloud >= lo - 0.3) and np.all(cloud <= hi + 0.3)


def test_model_obj_loads_inside_the_scene(report):
    text = (report.out / "model.obj").read_text()
    assert "o room0_wall" in text and "o room0_floor" in text and "o room0_ceiling" in text
    mesh = trimesh.load(report.out / "model.obj", force="mesh")
    assert len(mesh.faces) >= 2 + 2 + 2  # some walls, a floor and a ceiling
    lo, hi = load_scene("l_room").mesh.bounds
    assert np.all(mesh.bounds[0] >= lo - 0.3) and np.all(mesh.bounds[1] <= hi + 0.3)
    # The recovered floor (faces facing up) lies within the L's 45.6 m² of clear floor, and covers most of it.
    floor = mesh.area_faces[mesh.face_normals[:, 2] > 0.99].sum()
    assert 30.0 < floor < 45.6 * 1.1


def test_scans_e57_holds_every_station_with_the_poses_of_metrics_json(report):
    import pye57

    steps = report.metrics["steps"]
    e57 = pye57.E57(str(report.out / "scans.e57"))
    try:
        assert e57.scan_count == len(steps) == 3
        registered = []
        for k, step in enumerate(steps):
            header = e57.get_header(k)
            assert header["name"].value() == f"scan_{k:03d}"
            assert header.point_count == step["points"] > 0
            np.testing.assert_allclose(header.translation, step["estimated_position"], atol=1e-9)
            np.testing.assert_allclose(header.rotation, step["estimated_rotation"], atol=1e-9)
            assert abs(np.linalg.norm(header.rotation) - 1.0) < 1e-9
            local = e57.read_scan_raw(k)
            assert set(local) >= {"cartesianX", "rowIndex", "columnIndex"}
            # The points are stored in the scanner frame: within the scanner's range of its origin.
            ranges = np.linalg.norm(
                np.column_stack([local[c] for c in ("cartesianX", "cartesianY", "cartesianZ")]), axis=1
            )
            scanner = report.metrics["config"]["robot"]["scanner"]
            assert ranges.min() >= scanner["min_range"] - 0.05 and ranges.max() <= scanner["max_range"]
            placed = e57.read_scan(k, transform=True, ignore_missing_fields=True)
            registered.append(np.column_stack([placed[c] for c in ("cartesianX", "cartesianY", "cartesianZ")]))
            # The station's time: its acquisition after the start of the one before.
            start = header.acquisitionStart["dateTimeValue"].value()
            end = header.acquisitionEnd["dateTimeValue"].value()
            assert end > start > 1e9  # GPS seconds of this century
    finally:
        e57.close()
    # Placed with their poses, the stations are the registered cloud that cloud.laz downsamples.
    import laspy
    from scipy.spatial import cKDTree

    cloud = laspy.read(report.out / "cloud.laz").xyz
    distance, _ = cKDTree(np.concatenate(registered)).query(cloud)
    assert np.median(distance) < 0.03 and np.quantile(distance, 0.99) < 0.1


def test_cloud_laz_is_the_classified_cloud(report):
    import laspy

    from nbs_env.export import LAS_CLASSES

    las = laspy.read(report.out / "cloud.laz")
    labels = read_ply(report.out / "cloud.ply")
    assert las.header.version.minor == 4 and las.header.point_format.id == 6
    assert len(las.points) == len(labels)
    np.testing.assert_allclose(las.x, labels["x"], atol=2e-3)
    classes = np.asarray(las.classification)
    assert set(np.unique(classes)) <= set(LAS_CLASSES)
    # Structure (cloud.ply's label 1) is wall, floor or ceiling; the rest is clutter.
    np.testing.assert_array_equal(classes != 67, labels["label"] == 1)
    floor, ceiling = np.asarray(las.z)[classes == 65], np.asarray(las.z)[classes == 66]
    assert len(floor) and len(ceiling) and floor.max() < ceiling.min()
    assert set(np.unique(las.room)) == {0}
    (lookup,) = [v for v in las.header.vlrs if v.user_id == "LASF_Spec" and v.record_id == 0]
    assert lookup.lookups == LAS_CLASSES


def test_quality_figures_are_bounded_by_the_coverage(report):
    m = report.metrics
    q = m["quality"]
    assert q["min_density_per_m2"] == 400.0 and q["max_incidence_deg"] == 70.0
    assert 0 < q["quality_pct"] <= min(q["dense_pct"], q["incidence_pct"]) <= m["structure_sensed_pct"]
    assert 0 <= q["median_incidence_deg"] <= 90 and q["median_range_m"] > 1.0 and q["median_density_per_m2"] > 0
    steps = m["steps"]
    for key in ("dense_pct", "incidence_pct", "quality_pct"):
        values = [s[key] for s in steps]
        assert all(b >= a for a, b in itertools.pairwise(values)), (key, values)
        assert values[-1] == pytest.approx(q[key])
    assert all(s["quality_pct"] <= s["structure_sensed_pct"] + 1e-9 for s in steps)
    # Registrability: every scan after the first was registered to the cloud before it.
    reg = m["registrability"]
    assert reg["scans"] == 2 and steps[0]["registration_overlap"] is None
    assert 0 < reg["min_overlap"] <= reg["mean_overlap"] <= 1 and 0 < reg["min_fitness"] <= 1
    samples = np.load(report.out / "samples.npz")
    n = len(samples["points"])
    assert all(len(samples[k]) == n for k in ("labels", "rooms", "sensed", "density", "incidence", "range"))
    sensed = samples["sensed"]
    assert 100.0 * sensed.mean() == pytest.approx(m["structure_sensed_pct"])
    seen = np.isfinite(samples["incidence"])
    assert not np.any(seen & ~sensed) and np.all(samples["density"][~sensed] == 0)
    assert np.all((samples["incidence"][seen] >= 0) & (samples["incidence"][seen] <= 90))


def test_pictures_and_table(report):
    from PIL import Image

    image = np.asarray(Image.open(report.out / "topdown.png"))
    assert image.ndim == 3 and image.shape[0] > 100 and image.std() > 0
    steps = sorted((report.out / "steps").glob("step_*.png"))
    assert [p.name for p in steps][:2] == ["step_000.png", "step_001.png"] and len(steps) >= 2
    out = report.stdout
    assert "l_room" in out and "SE sensed %" in out and "processed points" in out
    total = next(line for line in out.splitlines() if line.startswith("total"))
    assert f"{report.metrics['processed_points']:,}" in total
    assert "storey complete: no" in out and "metrics.json" in out


def test_same_seed_same_report(report, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert nbs(*FAST, "--seed", "3", "--no-steps", "--quiet") == 0
    out = tmp_path / "scan-l_room"  # the default --out
    assert not (out / "steps").exists()
    again = json.loads((out / "metrics.json").read_text())
    first = report.metrics
    assert [s["position"] for s in again["steps"]] == [s["position"] for s in first["steps"]]
    assert [s["structure_sensed_pct"] for s in again["steps"]] == [s["structure_sensed_pct"] for s in first["steps"]]
    assert strip_times(again) == strip_times(first)
    assert "total" in capsys.readouterr().out


# ---------------------------------------------------------------------- errors
def test_unknown_policy_is_a_usage_error(tmp_path, capsys):
    assert nbs(*FAST, "--policy", "clairvoyant", "--out", str(tmp_path / "r"), "--quiet") == EXIT_USAGE
    err = capsys.readouterr().err
    assert "nbs scan: error:" in err and "'clairvoyant'" in err and "greedy" in err
    assert not (tmp_path / "r").exists()


def test_unknown_scene_is_a_scene_error(tmp_path, capsys):
    assert nbs("scan", "--scene", "atlantis", "--out", str(tmp_path / "r"), "--quiet") == EXIT_SCENE_ERROR
    err = capsys.readouterr().err
    assert "nbs scan: error: atlantis: no bundled scene" in err


@pytest.mark.parametrize(
    ("start", "message"),
    [("100,100", "is not free floor"), ("0.0,4.0", "is not free floor"), ("5.0,2.5", "is not free floor")],
    ids=["outside", "in-a-wall", "in-the-column"],
)
def test_bad_start_is_refused(tmp_path, capsys, start, message):
    assert nbs(*FAST, "--start", start, "--out", str(tmp_path / "r"), "--quiet") == EXIT_SCENE_ERROR
    err = capsys.readouterr().err
    assert err.startswith("nbs scan: error: l_room: start") and message in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--start", "abc"], "expected X,Y"),
        (["--start", "1,2,3"], "expected X,Y"),
        (["--resolution", "0"], "angular_step must be > 0"),
        (["--resolution", "-1"], "angular_step must be > 0"),
        (["--voxel", "0"], "voxel_size must be within"),
        (["--storey", "Erdgeschoss"], "--storey applies to .ifc files only"),
        (["--max-scans", "0"], "expected an integer >= 1"),
        (["--scanner", "vz-400"], "unknown scanner 'vz-400'"),
        (["--scanner", "rtc360:1mm"], "valid settings: 3mm, 6mm, 12mm"),
        (["--min-density", "-1"], "min_density must be within [0, 1e8]"),
        (["--max-incidence", "120"], "max_incidence must be in"),
        (["--record", "run.txt"], "a rerun recording ends in .rrd"),
    ],
)
def test_bad_options_are_usage_errors(tmp_path, capsys, args, message):
    assert nbs(*FAST, *args, "--out", str(tmp_path / "r"), "--quiet") == EXIT_USAGE
    err = capsys.readouterr().err
    assert "nbs scan: error:" in err and message in err


def test_python_m_train_scan_reports_without_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "train", *FAST, "--start", "100,100", "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert proc.returncode == EXIT_SCENE_ERROR
    assert "nbs scan: error: l_room: start [100.0, 100.0] is not free floor" in proc.stderr
    assert "Traceback" not in proc.stderr


# ---------------------------------------------------------------------- nbs_env.export units
def test_write_points_ply_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.uniform(-5, 5, size=(1000, 3))
    labels = rng.integers(0, 2, size=1000).astype(np.uint8)
    labels[:3] = [7, 255, 0]
    path = write_points_ply(tmp_path / "p.ply", points, labels)
    array = read_ply(path)
    assert array.dtype.names == ("x", "y", "z", "label")
    np.testing.assert_array_equal(array["label"], labels)
    np.testing.assert_allclose(np.column_stack([array["x"], array["y"], array["z"]]), points, atol=1e-5)
    loaded = trimesh.load(path)
    np.testing.assert_allclose(loaded.vertices, points, atol=1e-5)
    # Without labels: just x, y, z; an empty cloud is a valid file.
    assert read_ply(write_points_ply(tmp_path / "q.ply", points)).dtype.names == ("x", "y", "z")
    assert len(read_ply(write_points_ply(tmp_path / "e.ply", np.zeros((0, 3)), np.zeros(0, np.uint8)))) == 0


@pytest.mark.parametrize(
    ("points", "labels"),
    [
        (np.zeros((4, 2)), None),
        (np.full((2, 3), np.nan), None),
        (np.zeros((3, 3)), [0, 1]),
        (np.zeros((2, 3)), [0, 256]),
    ],
    ids=["not-n-by-3", "nan", "label-count", "label-range"],
)
def test_write_points_ply_refuses_bad_input(tmp_path, points, labels):
    with pytest.raises(ValueError):
        write_points_ply(tmp_path / "bad.ply", points, labels)


def room_model(polygon, index=0, floor_z=0.0, ceiling_z=2.5) -> RoomModel:
    polygon = np.asarray(polygon, dtype=float)
    faces = [WallFace(polygon[k], polygon[(k + 1) % len(polygon)], floor_z, ceiling_z) for k in range(len(polygon))]
    return RoomModel(index, polygon, floor_z, ceiling_z, faces, np.zeros((0, 3)), np.zeros(0, dtype=bool))


def test_structural_model_of_a_rectangle():
    room = room_model([[0, 0], [4, 0], [4, 3], [0, 3]])
    mesh = structural_model([room])
    kinds = np.asarray(mesh.face_attributes["kind"])
    assert np.count_nonzero(kinds == FACE_KINDS.index("wall")) == 8
    assert np.count_nonzero(kinds == FACE_KINDS.index("floor")) >= 2
    assert np.count_nonzero(kinds == FACE_KINDS.index("ceiling")) >= 2
    np.testing.assert_array_equal(mesh.face_attributes["room"], 0)
    area = mesh.area_faces
    assert area[kinds == 0].sum() == pytest.approx(2 * (4 + 3) * 2.5)
    assert area[kinds == 1].sum() == pytest.approx(12.0)
    assert area[kinds == 2].sum() == pytest.approx(12.0)
    # Normals point into the room: walls inwards, floor up, ceiling down.
    normals, centres = mesh.face_normals, mesh.triangles_center
    assert np.all(normals[kinds == 1][:, 2] > 0.99) and np.all(normals[kinds == 2][:, 2] < -0.99)
    inward = np.array([2.0, 1.5]) - centres[kinds == 0][:, :2]
    assert np.all(np.einsum("ij,ij->i", normals[kinds == 0][:, :2], inward) > 0)
    assert np.all(mesh.vertices[:, 2] >= 0) and np.all(mesh.vertices[:, 2] <= 2.5)


def test_structural_model_of_two_rooms_one_concave(tmp_path):
    l_shape = room_model([[0, 0], [8, 0], [8, 4], [4, 4], [4, 8], [0, 8]], index=0)
    box = room_model([[10, 0], [12, 0], [12, 2], [10, 2]], index=1, floor_z=0.1, ceiling_z=2.6)
    box = RoomModel(1, box.polygon, 0.1, 2.6, box.se_faces[:2], box.points, box.structure)  # two SE walls only
    mesh = structural_model([l_shape, box])
    kinds, rooms = np.asarray(mesh.face_attributes["kind"]), np.asarray(mesh.face_attributes["room"])
    area = mesh.area_faces
    assert area[(rooms == 0) & (kinds == 1)].sum() == pytest.approx(48.0)  # 64 - 16: earcut kept the notch
    assert area[(rooms == 1) & (kinds == 2)].sum() == pytest.approx(4.0)
    assert np.count_nonzero((rooms == 1) & (kinds == 0)) == 4
    path = write_model_obj(tmp_path / "m.obj", [l_shape, box])
    text = path.read_text()
    for name in ("room0_wall", "room0_floor", "room0_ceiling", "room1_wall", "room1_floor", "room1_ceiling"):
        assert f"o {name}\n" in text
    loaded = trimesh.load(path, force="mesh")
    assert loaded.area == pytest.approx(mesh.area)
    assert len(structural_model([]).faces) == 0
    assert "no faces" in write_model_obj(tmp_path / "e.obj", []).read_text()


def test_door_frame_scans_belong_to_the_room_entered():
    """A door-frame scan goes to the room entered, though it stands on the wall face of the room
    left; the path legs and points are counted per room."""
    rooms = [
        Room(0, "a", np.array([[0, 0], [5, 0], [5, 4], [0, 4]], dtype=float)),
        Room(1, "b", np.array([[5.2, 0], [9, 0], [9, 4], [5.2, 4]], dtype=float)),
        Room(2, "c", np.array([[0, 5], [4, 5], [4, 9], [0, 9]], dtype=float)),
    ]

    def step(k, robot_room, xy, path, door=False):
        return SimpleNamespace(
            scan=k, room=robot_room, door=door, true_position=np.array([*xy, 1.5]),
            estimated_position=np.array([*xy, 1.5]), predicted_gain=np.int64(3), path_length=path,
            structure_sensed_pct=10.0 * (k + 1), processing_time=0.5, acquisition_time=0.2,
            points=1000 + k, structure_points=500 + k, registration_error=(0.01 * k, 0.1 * k), times={"scan": 0.1},
            registration_refused="", estimated_pose=np.eye(4), registration_overlap=None if k == 0 else 0.8,
            registration_fitness=None if k == 0 else 0.7,
        )  # fmt: skip

    steps = [
        step(0, 0, (2, 2), 0.0),
        step(1, 0, (4, 1), 2.0),
        step(2, 1, (4.95, 2), 3.5, door=True),  # in the door of a and b, on a's wall face
        step(3, 1, (7, 2), 5.5),
        step(4, 1, (5.1, 2), 7.5),  # in the wall (drift), not a door scan: b, by the robot's room
        step(5, 2, (2, 4.9), 12.0, door=True),  # entering c, the budget ran out: the room no scan was in
    ]
    config = SimpleNamespace(
        travel_speed=0.5,
        quality=QualityConfig(),
        robot=SimpleNamespace(scanner=SimpleNamespace(preset=None)),
        to_dict=lambda: {"max_scans": 10, "shape": (1, 2)},
    )
    # One sample per room; the first dense and seen squarely after the second scan.
    curve = np.array([0.0, 100 / 3, 100 / 3, 100 / 3, 100 / 3, 100 / 3])
    quality = QualityReport(
        np.array([500.0, 0.0, 0.0]),
        np.array([10.0, np.nan, np.nan]),
        np.array([2.0, np.nan, np.nan]),
        curve,
        curve,
        curve,
    )
    meter = SimpleNamespace(
        percent=lambda room=None: {None: 40.0, 0: 60.0, 1: 30.0, 2: 0.0}[room],
        quality=lambda config: quality,
        samples=SimpleNamespace(rooms=np.array([0, 1, 2])),
    )
    storey = SimpleNamespace(
        scans=steps,
        scene=SimpleNamespace(rooms=rooms),
        meter=meter,
        config=config,
        complete=True,
        door_events=[],
        room_ends=[],
        wall_searches=[],
    )
    m = metrics_dict(storey, "fake", "stachniss_burgard", 0, structure_aware=False)
    json.dumps(m)  # plain JSON types only
    assert [r["quality_pct"] for r in m["rooms"]] == [100.0, 0.0, 0.0]
    assert m["quality"]["quality_pct"] == pytest.approx(100 / 3) and m["steps"][1]["quality_pct"] == pytest.approx(
        100 / 3
    )
    assert m["registrability"] == {
        "scans": 5, "mean_overlap": 0.8, "min_overlap": 0.8, "mean_fitness": 0.7, "min_fitness": 0.7, "refused": 0
    }  # fmt: skip
    assert [s["room"] for s in m["steps"]] == [0, 0, 1, 1, 1, 2]
    a, b, c = m["rooms"]
    assert (a["scans"], b["scans"], c["scans"]) == (2, 3, 1)
    assert a["path_length_m"] == pytest.approx(2.0) and b["path_length_m"] == pytest.approx(5.5)
    assert c["path_length_m"] == pytest.approx(4.5)
    # A structure-agnostic method processes every point; ours keeps the SE points (the paper's measure).
    assert b["processed_points"] == 1002 + 1003 + 1004 and c["processed_points"] == 1005
    ours = metrics_dict(storey, "fake", "greedy", 0, policy_times={1: 0.25})
    assert (
        ours["processed_points"] == sum(500 + k for k in range(6)) and ours["measured_points"] == m["measured_points"]
    )
    assert ours["processing_time_s"] == pytest.approx(6 * 0.5 + 0.25) and ours["policy_time_s"] == 0.25
    assert (a["structure_sensed_pct"], c["structure_sensed_pct"]) == (60.0, 0.0)
    assert m["travel_time_s"] == pytest.approx(24.0) and m["config"]["shape"] == [1, 2]
    assert m["registration_error"]["max_m"] == pytest.approx(0.05)
    assert type(m["steps"][0]["predicted_gain"]) is int


@pytest.mark.parametrize("spec", ["vz400", "rtc360", "focus:1/8", "blk360:fast+"])
def test_nbs_scan_with_each_scanner_preset_times_its_stations(tmp_path, spec):
    """Each preset drives a run (a steep -60° field with a 0.5 m minimum range once left the robot no
        way off its first stop), and the acquisition time is the preset's station time per scan: its set-up
    and its scan."""
    from nbs_env.config.scanners import SCANNERS, scanner_config

    out = tmp_path / "report"
    with contextlib.redirect_stdout(io.StringIO()) as stdout:
        assert nbs(*FAST, "--scanner", spec, "--out", str(out), "--no-steps", "--quiet") == 0
    m = json.loads((out / "metrics.json").read_text())
    expected = scanner_config(spec, simulated_step=1.0)
    assert m["config"]["robot"]["scanner"] == json.loads(json.dumps(expected.to_dict()))
    name, setting = expected.preset.split(":")
    assert m["scanner"] == {"name": name, "setting": setting, "model": SCANNERS[name].title}
    assert m["scans"] == 3 and m["path_length_m"] > 0  # the robot moved
    assert expected.setup_time > 0
    assert m["acquisition_time_s"] == pytest.approx(3 * (expected.setup_time + expected.station_time))
    assert f"3 stations: {expected.station_time:g} s scan + {expected.setup_time:g} s set-up" in stdout.getvalue()


@pytest.mark.parametrize(
    ("points", "classes", "rooms", "message"),
    [
        (np.zeros(6), np.zeros(2, dtype=np.uint8), None, r"\(n, 3\)"),
        (np.full((2, 3), np.nan), np.zeros(2, dtype=np.uint8), None, "finite"),
        (np.zeros((2, 3)), np.zeros(3, dtype=np.uint8), None, "classes must have shape"),
        (np.zeros((2, 3)), np.zeros(2, dtype=np.uint8), np.zeros(3), "rooms must have shape"),
    ],
)
def test_write_las_refuses_bad_input_and_writes_nothing(tmp_path, points, classes, rooms, message):
    from nbs_env.export import write_las

    with pytest.raises(ValueError, match=message):
        write_las(tmp_path / "c.laz", points, classes, rooms)
    assert not (tmp_path / "c.laz").exists()
