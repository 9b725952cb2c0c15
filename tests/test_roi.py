"""The dynamic RoI: polygons from binary images, floor/ceiling, IoU on rooms, no leak through doors."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Polygon
from skimage.draw import polygon as fill_polygon

from nbs_env.config import ScannerConfig
from nbs_env.perception.faces import WallFace
from nbs_env.perception.roi import (
    RoIError,
    RoIScan,
    compute_roi,
    floor_and_ceiling,
    leaked_area,
    polygon_from_image,
    roi_iou,
)
from nbs_env.sensing.pose import pose_from_xyz_rpy
from nbs_env.sensing.scanner import Scanner
from scenes import load_scene


def rasterise(vertices: np.ndarray, pixel: float, origin: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    image = np.zeros(shape, dtype=bool)
    rr, cc = fill_polygon((vertices[:, 1] - origin[1]) / pixel - 0.5, (vertices[:, 0] - origin[0]) / pixel - 0.5, shape)
    image[rr, cc] = True
    return image


def match_vertices(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.array([np.min(np.linalg.norm(found - t, axis=1)) for t in truth])


def test_l_shaped_projection_gives_six_vertices_within_10cm():
    truth = np.array([[0.3, 0.4], [6.3, 0.4], [6.3, 3.4], [3.1, 3.4], [3.1, 7.0], [0.3, 7.0]])
    origin, pixel = np.array([-0.5, -0.5]), 0.05
    image = rasterise(truth, pixel, origin, (170, 150))
    found = polygon_from_image(image, origin, pixel)
    assert len(found) == 6
    assert match_vertices(found, truth).max() < 0.10
    assert Polygon(found).exterior.is_ccw


def test_non_right_angles_and_concave_polygons():
    truth = np.array([[0.0, 0.0], [7.0, 0.0], [7.0, 2.5], [5.0, 4.5], [2.5, 4.5], [2.5, 3.0], [0.0, 3.0]])
    origin, pixel = np.array([-0.5, -0.5]), 0.05
    image = rasterise(truth, pixel, origin, (120, 170))
    found = polygon_from_image(image, origin, pixel)
    assert len(found) == len(truth)
    assert match_vertices(found, truth).max() < 0.10


def test_floor_and_ceiling_peaks():
    rng = np.random.default_rng(0)
    z = np.concatenate([rng.normal(0.0, 0.005, 5000), rng.normal(2.8, 0.005, 4000), rng.uniform(0, 2.8, 3000)])
    floor, ceiling = floor_and_ceiling(z, 1.5)
    assert floor == pytest.approx(0.0, abs=0.01) and ceiling == pytest.approx(2.8, abs=0.01)
    with pytest.raises(RoIError, match="floor and ceiling"):
        floor_and_ceiling(np.full(100, 2.0), 1.5)


def roi_after(scene, positions, seed=0, yaw=0.3):
    scanner = Scanner(scene, ScannerConfig())
    rng = np.random.default_rng(seed)
    scans = []
    for x, y in positions:
        pose = pose_from_xyz_rpy(x, y, 1.5, 0.0, 0.0, yaw)
        scans.append(RoIScan.from_scan(scanner.scan(pose, rng), pose))
    return compute_roi(scans)


def test_roi_of_the_l_room_after_three_scans():
    scene = load_scene("l_room")
    roi = roi_after(scene, [(3.0, 4.5), (6.5, 1.2), (1.5, 6.8)])
    assert roi_iou(roi.polygon, scene.rooms[0].polygon) >= 0.9
    assert roi.floor_z == pytest.approx(0.0, abs=0.02) and roi.ceiling_z == pytest.approx(2.6, abs=0.02)
    assert len(roi.wall_faces) == len(roi.polygon)
    face = roi.wall_faces[0]
    assert face.z0 == roi.floor_z and face.z1 == roi.ceiling_z


def test_one_scan_sees_only_part_of_the_l():
    scene = load_scene("l_room")
    roi = roi_after(scene, [(6.5, 1.2)])
    truth = Polygon(scene.rooms[0].polygon)
    assert Polygon(roi.polygon).area < 0.9 * truth.area  # the far arm is hidden
    assert Polygon(roi.polygon).difference(truth.buffer(0.1)).area < 0.2


def test_roi_stays_out_of_the_next_room():
    scene = load_scene("five_rooms")
    hall = scene.room_by_name("hall")
    # One stop 0.6 m from the door to the living room, others in the hall.
    roi = roi_after(scene, [(7.7, 1.75), (9.0, 2.5), (6.5, 5.5)])
    others = [r.polygon for r in scene.rooms if r.id != hall.id]
    assert leaked_area(roi.polygon, others) < 0.5
    assert roi_iou(roi.polygon, hall.polygon) > 0.8


def test_a_scan_taken_again_from_a_door_frame_keeps_the_room_it_belongs_to():
    # Three stops in the hall, then one standing in the frame of its door to the study (a visited
    # door cell is a valid NVP): the RoI is still the hall's, the room most of its scans stand in,
    # not whatever component the frame's own stop falls in (the study, before the vote).
    scene = load_scene("five_rooms")
    hall = scene.room_by_name("hall")
    roi = roi_after(scene, [(8.0, 2.0), (6.0, 6.0), (8.5, 6.5), (9.5, 6.5)])
    assert roi_iou(roi.polygon, hall.polygon) > 0.9


def test_no_scans_is_an_error():
    with pytest.raises(RoIError, match="no scans"):
        compute_roi([])


def test_shipped_classifier_on_real_scans_and_the_figure(tmp_path):
    from nbs_env.perception.structure import SEClassifier, label_points
    from nbs_env.render import save_roi_png

    model = SEClassifier.load_default()
    assert model.training["report"]["held_out"]["f1"] >= 0.9
    scene = load_scene("l_room")
    scanner = Scanner(scene, ScannerConfig())
    rng = np.random.default_rng(1)
    scans = []
    for x, y in [(3.0, 4.5), (6.5, 1.2), (1.5, 6.8)]:
        pose = pose_from_xyz_rpy(x, y, 1.5, 0.0, 0.0, 0.0)
        scans.append((scanner.scan(pose, rng), pose))
    roi = compute_roi([RoIScan.from_scan(s, p) for s, p in scans])
    points = np.concatenate([s.to_world(p) for s, p in scans])
    se = model.classify_faces(roi.wall_faces, points)
    assert se.all()  # the L room's six faces are all walls
    labels = label_points(points, roi.wall_faces, roi.floor_z, roi.ceiling_z, roi.polygon)
    truth = np.concatenate([np.isin(s.truth.labels, [0, 1, 2]) for s, _ in scans])
    assert np.mean(labels == truth) > 0.95
    # A face across the room, through the table and the column, is not a wall.
    cut = WallFace(np.array([0.5, 2.3]), np.array([7.5, 2.3]), roi.floor_z, roi.ceiling_z)
    assert not model.classify_faces([cut], points)[0]
    out = save_roi_png(roi, se, tmp_path / "roi.png", points=points, origins=[p[:3, 3] for _, p in scans])
    from PIL import Image

    assert Image.open(out).size[0] > 400


def _box_returns(origin, size, wall_top=None):
    """The pattern's rays in a box [0, size] (no roof when ``wall_top`` is given: rays leaving above
    the walls' top return nothing), with the scanner's minimum range: (directions, returned, heights)."""
    from nbs_env.sensing.scanner import ray_pattern
    from tests.helpers import box_ranges

    config = ScannerConfig(angular_step=1.0)
    directions = ray_pattern(config)[0].astype(float)
    origin = np.asarray(origin, dtype=float)
    box = list(size) if wall_top is None else [size[0], size[1], 1e6]
    r = box_ranges(origin, directions, box)
    hit_z = origin[2] + r * directions[:, 2]
    returned = (r >= config.min_range) & (r <= config.max_range)
    if wall_top is not None:
        returned &= hit_z <= wall_top
    heights = (r * directions[:, 2])[returned]
    return directions, returned, heights


@pytest.mark.parametrize(
    ("origin", "size", "wall_top", "sky"),
    [
        ((3.0, 2.0, 1.5), (6.0, 4.0, 2.7), None, False),  # a room
        ((0.45, 0.45, 1.5), (6.0, 4.0, 2.7), None, False),  # in a corner at the robot's clearance
        ((5.0, 0.45, 1.5), (10.0, 0.9, 2.6), None, False),  # the middle of a 0.9 m corridor
        ((3.0, 2.0, 1.5), (6.0, 4.0, 2.2), None, False),  # a ceiling within the minimum range overhead
        ((3.0, 2.0, 1.5), (6.0, 4.0, 12.0), None, False),  # a hall
        ((3.0, 2.0, 1.5), (6.0, 4.0, None), 3.0, True),  # walls and no roof
        ((0.45, 0.45, 1.5), (6.0, 4.0, None), 3.0, True),  # the same, in a corner
        ((10.0, 10.0, 1.5), (20.0, 20.0, None), 3.0, True),  # a large yard
    ],
)
def test_a_scan_sees_the_sky_only_where_there_is_no_roof(origin, size, wall_top, sky):
    from nbs_env.perception.roi import sees_sky

    directions, returned, heights = _box_returns(origin, size, wall_top)
    assert sees_sky(directions, returned, heights, ScannerConfig().min_range) is sky


def test_a_room_under_the_sky_has_no_ceiling_and_its_walls_top_the_prism():
    from tests.helpers import boxed_storey

    outline = [((0, 0), (6, 0)), ((6, 0), (6, 4)), ((6, 4), (0, 4)), ((0, 4), (0, 0))]
    slab = (-0.1, -0.1, 6.1, 4.1)
    cfg = ScannerConfig(angular_step=1.0)
    for ceilings in ([slab], []):
        scene = boxed_storey([(a, b, []) for a, b in outline], [slab], ceilings, start=(3.0, 2.0))
        pose = pose_from_xyz_rpy(3.0, 2.0, 1.5)
        scan = RoIScan.from_scan(Scanner(scene, cfg).scan(pose, np.random.default_rng(0)), pose)
        roi = compute_roi([scan])
        assert scan.sky is (not ceilings) and roi.has_ceiling is bool(ceilings)
        # The whole room either way: the upward rays into the sky are not walls next to the robot.
        inside = Polygon([(0.1, 0.1), (5.9, 0.1), (5.9, 3.9), (0.1, 3.9)])
        assert Polygon(roi.polygon).intersection(inside).area >= 0.9 * inside.area, roi.polygon
        # The prism ends under the ceiling, or at the top of the walls (2.6 m) under the sky.
        assert roi.ceiling_z == pytest.approx(2.6, abs=0.25)


@pytest.mark.parametrize("seed", range(4))
def test_the_fallback_outline_is_skimages_douglas_peucker(seed):
    """The fallback's own Douglas-Peucker keeps the vertices skimage's approximate_polygon keeps
    (bit for bit), on the traced outline of a noisy room image and on a random walk."""
    from skimage.measure import approximate_polygon, find_contours

    from nbs_env.perception.roi import _douglas_peucker

    rng = np.random.default_rng(seed)
    image = np.zeros((120, 160), dtype=bool)
    rows, cols = fill_polygon([10, 10, 60, 60, 110, 110], [10, 150, 150, 80, 80, 10], image.shape)
    image[rows, cols] = True
    image ^= rng.random(image.shape) < 0.02
    contour = max(find_contours(image.astype(float), 0.5), key=len)
    walk = np.cumsum(rng.normal(size=(500, 2)), axis=0)
    for chain in (contour, walk):
        for tolerance in (0.0, 0.5, 2.0, 7.5):
            want = approximate_polygon(chain, tolerance)
            got = _douglas_peucker(chain, tolerance)
            assert np.array_equal(got, want)
        assert 3 < len(_douglas_peucker(chain, 2.0)) < len(chain) // 2
