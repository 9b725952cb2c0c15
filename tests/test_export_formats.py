"""The report's scan files as scanning software reads them, with readers other than the writers.

``scans.e57`` (written through libE57Format) is read by the Rust ``e57`` crate and by pye57;
``cloud.laz`` (written by laspy with lazrs) by LASzip and lazrs. One short episode (``five_rooms``,
the fast preset with the Leica RTC360 preset, a few greedy scans) writes two reports: the 5 cm
working copies (the default) and every measured point (``full_cloud``).
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import e57
import laspy
import numpy as np
import pye57
import pytest

import nbs_env
from nbs_env.config import make_config
from nbs_env.config.scanners import SCANNERS, scanner_config
from nbs_env.env import NBSEnv
from nbs_env.export import LAS_CLASSES, LOCAL_CRS_WKT, simulated_intensity, write_report
from policies import GreedyPolicy
from scenes import load_scene

#: Scans of the episode: enough to enter a second room (its door-frame scan), a few seconds of simulation.
SCANS = 6
E57_NS = {"e57": "http://www.astm.org/COMMIT/E57/2010-e57-v1.0"}
XYZ = ("cartesianX", "cartesianY", "cartesianZ")


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> SimpleNamespace:
    scanner = scanner_config("rtc360", simulated_step=1.0)  # nbs scan --preset fast --scanner rtc360
    config = make_config(
        "fast", scene="five_rooms", keep_scans=True, max_scans=SCANS, **{"robot.scanner": scanner.to_dict()}
    )
    env = NBSEnv(config)
    obs, info = env.reset(seed=0)
    policy = GreedyPolicy()
    policy.reset()
    started = time.time()
    while env.storey.open:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    out = tmp_path_factory.mktemp("formats")
    metrics = write_report(env, out / "work", "five_rooms", "greedy", 0, run_started=started)
    write_report(env, out / "full", "five_rooms", "greedy", 0, run_started=started, full_cloud=True)
    e57_path = out / "full" / "scans.e57"
    reader = pye57.E57(str(e57_path))
    try:
        records = [
            reader.read_scan(k, intensity=True, row_column=True, transform=False) for k in range(reader.scan_count)
        ]
        headers = [reader.get_header(k) for k in range(reader.scan_count)]
        poses = [(h.rotation.copy(), h.translation.copy()) for h in headers]
        counts = [h.point_count for h in headers]
    finally:
        reader.close()
    xml = ET.fromstring(e57.raw_xml(str(e57_path)))
    return SimpleNamespace(
        out=out,
        metrics=metrics,
        scanner=env.storey.config.robot.scanner,
        e57=e57_path,
        records=records,
        poses=poses,
        counts=counts,
        xml=xml,
        xml_records=xml.findall("e57:data3D/e57:vectorChild", E57_NS),
        work=laspy.read(out / "work" / "cloud.laz", laz_backend=laspy.LazBackend.Laszip),
        full=laspy.read(out / "full" / "cloud.laz", laz_backend=laspy.LazBackend.Laszip),
    )


def _text(node: ET.Element, path: str) -> str:
    found = node.find(path, E57_NS)
    assert found is not None, path
    return found.text or "0"  # libE57 writes a zero number as an empty element


def _placed(record: dict, pose: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """A record's scanner-frame points placed with its E57 pose."""
    from scipy.spatial.transform import Rotation

    w, x, y, z = pose[0]
    local = np.column_stack([record[c] for c in XYZ])
    return local @ Rotation.from_quat([x, y, z, w]).as_matrix().T + pose[1]


# ---------------------------------------------------------------------- scans.e57
def test_e57_readers_agree_on_every_record(run):
    """pye57 (libE57Format) and the Rust e57 crate see one record per scan, with the scans' point
    counts, the same placed points and the same intensities."""
    steps = run.metrics["steps"]
    assert len(run.counts) == len(run.xml_records) == len(steps) == SCANS
    rust_counts = [int(r.find("e57:points", E57_NS).get("recordCount")) for r in run.xml_records]
    assert rust_counts == run.counts == [s["points"] for s in steps]
    assert [len(r["cartesianX"]) for r in run.records] == run.counts
    rust = e57.read_points(str(run.e57))
    assert rust.points.shape == (sum(run.counts), 3)
    placed = np.concatenate([_placed(r, p) for r, p in zip(run.records, run.poses, strict=True)])
    np.testing.assert_allclose(rust.points, placed, atol=1e-6)
    intensity = np.concatenate([r["intensity"] for r in run.records])
    np.testing.assert_array_equal(np.asarray(rust.intensity).reshape(-1), intensity)


def test_e57_records_are_structured_scans_of_the_preset(run):
    """Each record names the RTC360 preset's vendor and model with a simulated serial number and
    nbs-env, has no placeholder environment values, and its points carry their row and column of
    the scan pattern, within the record's index bounds and matching the points' directions."""
    scanner, model = run.scanner, SCANNERS["rtc360"]
    assert _text(run.xml, "e57:coordinateMetadata") == LOCAL_CRS_WKT
    assert float(_text(run.xml, "e57:creationDateTime/e57:dateTimeValue")) > 1e9
    steps = run.metrics["steps"]
    previous_end = -np.inf
    for k, (node, record) in enumerate(zip(run.xml_records, run.records, strict=True)):
        assert _text(node, "e57:sensorVendor") == model.vendor == "Leica Geosystems"
        assert _text(node, "e57:sensorModel") == model.title == "Leica RTC360"
        assert _text(node, "e57:sensorSerialNumber") == "SIM-rtc360-0001"
        description = _text(node, "e57:description")
        assert f"nbs-env {nbs_env.__version__}" in description and "simulated" in description
        for placeholder in ("temperature", "relativeHumidity", "atmosphericPressure"):
            assert node.find(f"e57:{placeholder}", E57_NS) is None, placeholder
        bounds = {key: int(_text(node, f"e57:indexBounds/e57:{key}")) for key in ("rowMinimum", "rowMaximum")}
        bounds |= {key: int(_text(node, f"e57:indexBounds/e57:{key}")) for key in ("columnMinimum", "columnMaximum")}
        assert bounds == {"rowMinimum": 0, "rowMaximum": scanner.n_rows - 1, "columnMinimum": 0, "columnMaximum": 359}
        prototype = {child.tag.split("}")[1] for child in node.find("e57:points/e57:prototype", E57_NS)}
        assert {"rowIndex", "columnIndex", "intensity"} <= prototype
        rows, cols = record["rowIndex"].astype(int), record["columnIndex"].astype(int)
        assert rows.min() >= bounds["rowMinimum"] and rows.max() <= bounds["rowMaximum"]
        assert cols.min() >= bounds["columnMinimum"] and cols.max() <= bounds["columnMaximum"]
        assert len(np.unique(rows * scanner.n_cols + cols)) == len(rows)  # one point per direction: a grid
        # The grid is the pattern: each point lies in the direction of its row and column.
        x, y, z = (record[c] for c in XYZ)
        elevation = np.degrees(np.arctan2(z, np.hypot(x, y)))
        azimuth = np.degrees(np.arctan2(y, x))
        assert np.abs(elevation - (scanner.elevation_min + rows * scanner.angular_step)).max() < 0.01
        turn = (azimuth - (-180.0 + cols * 360.0 / scanner.n_cols) + 180.0) % 360.0 - 180.0
        assert np.abs(turn).max() < 0.01
        assert record["intensity"].min() >= 1 and record["intensity"].std() > 0
        # Poses as metrics.json has them; acquisitions in order.
        rotation, translation = run.poses[k]
        np.testing.assert_allclose(translation, steps[k]["estimated_position"], atol=1e-9)
        np.testing.assert_allclose(rotation, steps[k]["estimated_rotation"], atol=1e-9)
        start = float(_text(node, "e57:acquisitionStart/e57:dateTimeValue"))
        end = float(_text(node, "e57:acquisitionEnd/e57:dateTimeValue"))
        # The scan lasts its station time and begins after the station's set-up.
        assert scanner.setup_time > 0
        assert end - start == pytest.approx(scanner.station_time) and start >= previous_end + scanner.setup_time
        previous_end = end


def test_pye57_reads_the_records_without_options(run):
    """Every record has ``cartesianInvalidState``, which pye57's ``read_scan`` asks for by default."""
    reader = pye57.E57(str(run.e57))
    try:
        points = reader.read_scan(0)
    finally:
        reader.close()
    assert len(points["cartesianX"]) == run.counts[0]


# ---------------------------------------------------------------------- cloud.laz
@pytest.mark.parametrize("kind", ["work", "full"])
def test_laszip_and_lazrs_read_the_same_cloud(run, kind):
    path = run.out / kind / "cloud.laz"
    a = getattr(run, kind)
    b = laspy.read(path, laz_backend=laspy.LazBackend.Lazrs)
    assert len(a.points) == len(b.points) > 0
    names = list(a.point_format.dimension_names)
    assert names == list(b.point_format.dimension_names)
    assert {"room", "structure", "NormalX", "NormalY", "NormalZ"} <= set(a.point_format.extra_dimension_names)
    for name in names:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)


@pytest.mark.parametrize("kind", ["work", "full"])
def test_cloud_laz_points_are_single_returns_of_the_storey(run, kind):
    """Return 1 of 1, classes of LAS_CLASSES, inside the storey, the coordinate system and the GPS
    time type declared, normals that face the scanner (floors up, ceilings down)."""
    las = getattr(run, kind)
    header = las.header
    assert header.version.minor == 4 and header.point_format.id == 6
    assert np.all(las.return_number == 1) and np.all(las.number_of_returns == 1)
    assert set(np.unique(las.classification).tolist()) <= set(LAS_CLASSES)
    assert header.global_encoding.wkt and header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
    (wkt,) = [v for v in header.vlrs if v.user_id == "LASF_Projection" and v.record_id == 2112]
    assert wkt.string == LOCAL_CRS_WKT
    descriptions = {d.name: d.description for d in header.point_format.extra_dimensions}
    assert all(descriptions[name] for name in ("room", "structure", "NormalX"))
    lo, hi = load_scene("five_rooms").mesh.bounds
    assert np.all(las.xyz >= lo - 0.3) and np.all(las.xyz <= hi + 0.3)
    assert np.all(np.asarray(las.point_source_id) < SCANS) and np.all(las.intensity >= 1)
    normals = np.column_stack([las.NormalX, las.NormalY, las.NormalZ])
    length = np.linalg.norm(normals, axis=1)
    # Components are multiples of 1/4096 (write_las): unit length within 1e-3.
    assert np.mean(length > 0.99) > 0.99 and np.all((length == 0) | (np.abs(length - 1) < 1e-3))
    np.testing.assert_array_equal(np.rint(normals * 4096) / 4096, normals)
    classes = np.asarray(las.classification)
    assert np.median(normals[classes == 65, 2]) > 0.95 and np.median(normals[classes == 66, 2]) < -0.95
    np.testing.assert_array_equal(np.asarray(las.structure) == 1, classes != 67)


def test_full_cloud_separates_the_scans_as_the_e57_records(run):
    """With ``full_cloud``, the points of each ``point_source_id`` are that E57 record's points,
    placed with its pose, with its intensities, timed within its acquisition in the scanner's
    order (column by column, each column bottom-up)."""
    las, scanner = run.full, run.scanner
    ids = np.asarray(las.point_source_id)
    np.testing.assert_array_equal(np.bincount(ids, minlength=SCANS), run.counts)
    gps = np.asarray(las.gps_time)
    for k, (node, record) in enumerate(zip(run.xml_records, run.records, strict=True)):
        mine = ids == k
        np.testing.assert_allclose(las.xyz[mine], _placed(record, run.poses[k]), atol=6e-4)  # 1 mm scale
        np.testing.assert_array_equal(las.intensity[mine], record["intensity"].astype(np.uint16))
        assert len(np.unique(np.asarray(las.room)[mine])) == 1
        start = float(_text(node, "e57:acquisitionStart/e57:dateTimeValue")) - 1e9  # Adjusted Standard GPS
        end = float(_text(node, "e57:acquisitionEnd/e57:dateTimeValue")) - 1e9
        assert start <= gps[mine].min() and gps[mine].max() < end
        order = record["columnIndex"].astype(int) * scanner.n_rows + record["rowIndex"].astype(int)
        assert np.all(np.diff(gps[mine][np.argsort(order)]) > 0)
        # At the scanner's rate: one direction every 1 / points_per_second.
        np.testing.assert_allclose(gps[mine] - start, order / scanner.points_per_second, atol=1e-5)


def test_intensity_is_the_documented_model(run):
    """Each record's intensity is ``simulated_intensity`` of its points' ranges and incidence on
    the LAZ normals: head-on and near, bright; grazing or far, dim."""
    las = run.full
    ids = np.asarray(las.point_source_id)
    normals = np.column_stack([las.NormalX, las.NormalY, las.NormalZ])
    for k, record in enumerate(run.records):
        local = np.column_stack([record[c] for c in XYZ])
        rays = _placed(record, run.poses[k]) - run.poses[k][1]
        n = normals[ids == k]
        ranges = np.linalg.norm(local, axis=1)
        length = np.linalg.norm(n, axis=1)
        cos = np.where(length > 0, np.abs(np.einsum("ij,ij->i", n, rays)) / (ranges * np.maximum(length, 1e-12)), 1.0)
        expected = simulated_intensity(ranges, cos).astype(int)
        # The LAZ normals are rounded to 1/4096 (cos within 3e-4): intensities within that share of full scale.
        tolerance = 1 + 65535 * 3e-4 / np.maximum(ranges, 1.0) ** 2
        assert np.all(np.abs(expected - record["intensity"].astype(int)) <= tolerance)
        assert np.median(record["intensity"][ranges < 2.0]) > np.median(record["intensity"][ranges > 5.0])


def _ply_points(path: Path) -> np.ndarray:
    """The float32 x, y, z of the report's binary PLY (its own writer's layout: x, y, z, then a label)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    labelled = b"property uchar label" in data[:end]
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")] + [("label", "u1")] * labelled)
    array = np.frombuffer(data[end:], dtype=dtype)
    return np.column_stack([array["x"], array["y"], array["z"]]).astype(np.float64)


def test_working_copy_points_name_the_scan_that_first_measured_them(run):
    """A working-copy point's ``point_source_id`` is the first scan of its room with a measured
    point in its 5 cm voxel (the E57 records' points, placed; the working copy's float32 points of
    ``cloud.ply``, in the order of ``cloud.laz``)."""
    work = run.work
    ids, rooms = np.asarray(work.point_source_id), np.asarray(work.room)
    points = _ply_points(run.out / "work" / "cloud.ply")
    np.testing.assert_allclose(points, work.xyz, atol=6e-4)
    assert set(np.unique(ids).tolist()) <= set(range(SCANS)) and len(np.unique(ids)) > 1
    scan_room = [int(np.asarray(run.full.room)[np.asarray(run.full.point_source_id) == k][0]) for k in range(SCANS)]
    assert len(set(scan_room)) > 1  # the scan indices run on across rooms
    agree = []
    for room in np.unique(rooms):
        first: dict[tuple[int, int, int], int] = {}
        for k in (k for k in range(SCANS) if scan_room[k] == room):
            for cell in map(tuple, np.floor(_placed(run.records[k], run.poses[k]) / 0.05).astype(np.int64)):
                first.setdefault(cell, k)
        here = rooms == room
        cells = np.floor(points[here] / 0.05).astype(np.int64)
        agree.append(np.array([first.get(tuple(c), -1) for c in cells]) == ids[here])
    # Walls on whole 5 cm coordinates put means on voxel faces: float32 rounding moves a few (0.1%)
    # across. A scan index off by one, or every voxel given its room's first scan, agrees below 50%.
    assert np.mean(np.concatenate(agree)) > 0.99


def test_metrics_json_records_the_scanner_preset(run):
    assert run.metrics["scanner"] == {"name": "rtc360", "setting": "6mm", "model": "Leica RTC360"}
    assert run.metrics["config"]["robot"]["scanner"]["preset"] == "rtc360:6mm"


def test_full_cloud_needs_the_kept_scans(tmp_path):
    env = NBSEnv(make_config("fast", scene="five_rooms", max_scans=1))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="keep_scans"):
        write_report(env, tmp_path / "r", "five_rooms", "greedy", 0, full_cloud=True)
    assert not (tmp_path / "r").exists()


def test_a_report_that_fails_part_way_leaves_the_earlier_one_whole(tmp_path, monkeypatch):
    """The report's files are renamed into the folder together, after all are written: a full disk
    at the fourth file leaves the earlier report's files as they were (not some of each run) and no
    temporary folder; a report without scans then removes the earlier one's scans.e57."""
    import errno

    import nbs_env.export as export

    env = NBSEnv(make_config("fast", scene="l_room", keep_scans=True, max_scans=2))
    obs, info = env.reset(seed=0)
    env.step(GreedyPolicy().act(obs, info))
    out = tmp_path / "r"
    write_report(env, out, "l_room", "greedy", 0)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "scans.e57" in before and json_scans(out) == 2

    env.step(GreedyPolicy().act(*env.reset(seed=1)))

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "model.obj"))

    with monkeypatch.context() as patch:
        patch.setattr(export, "write_model_obj", full)
        with pytest.raises(OSError):
            write_report(env, out, "l_room", "greedy", 1)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before

    bare = NBSEnv(make_config("fast", scene="l_room", max_scans=1))  # keeps no scans: no scans.e57
    obs, info = bare.reset(seed=0)
    write_report(bare, out, "l_room", "greedy", 0)
    assert not (out / "scans.e57").exists() and json_scans(out) == 1
    assert sorted(p.name for p in out.iterdir()) == sorted(set(export.REPORT_FILES) - {"scans.e57"})


def json_scans(folder: Path) -> int:
    import json

    return json.loads((folder / "metrics.json").read_text())["scans"]
