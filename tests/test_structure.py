"""SE classification (paper §3.2, METHOD §4): face images, (α, δ, ε), the SVM and its file, point labels."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from nbs_env.errors import ModelFileError, NBSError
from nbs_env.perception.faces import WallFace
from nbs_env.perception.structure import (
    SEClassifier,
    face_features,
    face_image,
    label_points,
)

# ----------------------------------------------------------------------------- helpers


def _face(p0, p1, z0=0.0, z1=2.6) -> WallFace:
    return WallFace(np.asarray(p0, dtype=float), np.asarray(p1, dtype=float), z0, z1)


def _image(shape, pixels) -> np.ndarray:
    image = np.zeros(shape, dtype=bool)
    for r, c in pixels:
        image[r, c] = True
    return image


def _box_points(rng, lo, hi, n) -> np.ndarray:
    """n points uniformly inside the axis-aligned box [lo, hi] (a solid blob of measured points)."""
    return rng.uniform(lo, hi, size=(n, 3))


def _covered_face_points(face: WallFace, spacing=0.02, offset=0.0) -> np.ndarray:
    """A dense grid of points on the face plane (offset metres in front of it) covering the whole face."""
    u = np.arange(spacing / 2, face.length, spacing)
    v = np.arange(spacing / 2, face.height, spacing)
    uu, vv = (a.ravel() for a in np.meshgrid(u, v))
    xy = np.asarray(face.p0) + uu[:, None] * face.direction + offset * face.normal
    return np.column_stack([xy, face.z0 + vv])


def _synthetic_training_set(seed=0, per_class=80, shape=(52, 80)):
    """Features of synthetic face images, labelled SE or not.

    SE-like: a wall mostly covered, with rectangular occlusion shadows (furniture in front of it)
    and a sprinkle of missing pixels. Non-SE: a few compact blobs (furniture cut by the face), most
    of them standing on the floor, or only the floor and ceiling lines (a face across open space),
    or both.
    """
    rng = np.random.default_rng(seed)
    d2, d1 = shape
    features, labels = [], []
    for _ in range(per_class):
        image = np.ones(shape, dtype=bool)
        for _ in range(rng.integers(0, 4)):
            h, w = rng.integers(5, d2 // 2), rng.integers(5, d1 // 3)
            r, c = rng.integers(0, d2 - h), rng.integers(0, d1 - w)
            image[r : r + h, c : c + w] = False
        image &= rng.random(shape) > rng.uniform(0.0, 0.15)
        features.append(face_features(image))
        labels.append(True)
    for i in range(per_class):
        image = np.zeros(shape, dtype=bool)
        kind = i % 3
        if kind in (0, 2):
            for _ in range(rng.integers(1, 5)):
                h, w = rng.integers(3, d2 // 2), rng.integers(3, d1 // 4)
                # Furniture mostly stands on the floor, where it joins the floor line into one cluster.
                r = 0 if rng.random() < 0.6 else rng.integers(0, d2 - h)
                c = rng.integers(0, d1 - w)
                image[r : r + h, c : c + w] = True
        if kind in (1, 2):
            # Floor and ceiling seen through the face's band: continuous lines with a few occlusion gaps.
            for row in (0, d2 - 1):
                image[row, :] = True
                for _ in range(rng.integers(0, 3)):
                    c, w = rng.integers(0, d1), rng.integers(2, d1 // 4)
                    image[row, c : c + w] = False
        if not image.any():
            image[0, 0] = True
        features.append(face_features(image))
        labels.append(False)
    return np.array(features), np.array(labels)


@pytest.fixture(scope="module")
def classifier() -> SEClassifier:
    features, labels = _synthetic_training_set()
    return SEClassifier.fit(features, labels, seed=0)


# ----------------------------------------------------------------------------- α, δ, ε


def test_features_all_white_image_is_one_one_one():
    np.testing.assert_array_equal(face_features(np.ones((5, 7), dtype=bool)), [1.0, 1.0, 1.0])


def test_features_empty_image_is_zero():
    np.testing.assert_array_equal(face_features(np.zeros((4, 4), dtype=bool)), [0.0, 0.0, 0.0])


def test_features_two_separate_filled_squares():
    image = np.zeros((10, 10), dtype=bool)
    image[0:2, 0:2] = True  # 4 px, box 4
    image[5:8, 4:7] = True  # 9 px, box 9
    np.testing.assert_allclose(face_features(image), [13 / 100, 1.0, 13 / 100], rtol=0, atol=1e-15)


def test_features_l_shaped_cluster_is_not_compact():
    image = _image((6, 8), [(1, 1), (2, 1), (3, 1), (3, 2), (3, 3)])  # 5 px in a 3x3 box
    alpha, delta, epsilon = face_features(image)
    assert alpha == pytest.approx(5 / 48, abs=1e-15)
    assert delta == pytest.approx(5 / 9, abs=1e-15)
    assert delta < 1
    assert epsilon == pytest.approx(9 / 48, abs=1e-15)


def test_features_mean_compactness_over_clusters():
    # The L (5/9) and a separate 2x2 square (1): δ is their mean, ε the sum of their boxes.
    image = _image((6, 8), [(1, 1), (2, 1), (3, 1), (3, 2), (3, 3)])
    image[0:2, 6:8] = True
    np.testing.assert_allclose(face_features(image), [9 / 48, (5 / 9 + 1) / 2, 13 / 48], rtol=0, atol=1e-15)


def test_features_diagonal_line_is_one_eight_connected_cluster():
    image = np.zeros((5, 8), dtype=bool)
    image[np.arange(5), np.arange(5)] = True
    # 8-connected: one cluster of 5 px in a 5x5 box. (4-connectivity would give 5 clusters: δ=1, ε=5/40.)
    np.testing.assert_allclose(face_features(image), [5 / 40, 5 / 25, 25 / 40], rtol=0, atol=1e-15)


def test_features_anti_diagonal_is_one_cluster_too():
    image = np.fliplr(np.eye(4, dtype=bool))
    np.testing.assert_allclose(face_features(image), [4 / 16, 4 / 16, 1.0], rtol=0, atol=1e-15)


def test_features_sparse_pattern_of_isolated_pixels():
    image = np.zeros((6, 6), dtype=bool)
    image[::2, ::2] = True  # 9 pixels two apart: not even diagonal neighbours, so 9 clusters of 1 px
    np.testing.assert_allclose(face_features(image), [9 / 36, 1.0, 9 / 36], rtol=0, atol=1e-15)


def test_features_checkerboard_is_one_sparse_cluster():
    rows, cols = np.indices((4, 4))
    image = (rows + cols) % 2 == 0  # 8 px, all diagonal neighbours: one cluster filling the image's box
    np.testing.assert_allclose(face_features(image), [0.5, 0.5, 1.0], rtol=0, atol=1e-15)


def test_features_refuse_non_2d_images():
    with pytest.raises(ValueError, match="2-D"):
        face_features(np.ones(5, dtype=bool))
    with pytest.raises(ValueError, match="2-D"):
        face_features(np.ones((0, 3), dtype=bool))


# ----------------------------------------------------------------------------- face image


def test_face_image_shape():
    assert face_image(_face([0, 0], [2.0, 0], 0.0, 1.0), np.zeros((0, 3)), pixel=0.1).shape == (10, 20)
    # Partial pixels round up.
    assert face_image(_face([0, 0], [2.03, 0], 0.0, 1.01), np.zeros((0, 3)), pixel=0.1).shape == (11, 21)
    # Whole numbers of pixels up to float rounding get no empty sliver column (0.3/0.1 = 2.9999999999999996).
    assert face_image(_face([0, 0], [0.3, 0], 0.0, 0.7), np.zeros((0, 3)), pixel=0.1).shape == (7, 3)
    assert face_image(_face([0, 0], [0.6, 0], 0.0, 0.3), np.zeros((0, 3)), pixel=0.2).shape == (2, 3)
    # Degenerate faces still give one pixel.
    assert face_image(_face([0, 0], [0.01, 0], 0.0, 0.0), np.zeros((0, 3)), pixel=0.1).shape == (1, 1)


def test_face_image_puts_a_point_in_its_pixel():
    face = _face([0, 0], [2.0, 0], 0.0, 1.0)  # u = x, v = z, w = y (normal +y)
    image = face_image(face, np.array([[0.55, 0.05, 0.32]]), pixel=0.1, band=0.1)
    assert image.sum() == 1
    assert image[3, 5]


def test_face_image_on_an_oblique_face_with_offset_base():
    face = _face([1.0, 1.0], [3.0, 3.0], 0.5, 2.5)
    # 0.77 m along the edge, 1.22 m above z0, 3 cm behind the plane (clear of pixel edges).
    point = np.r_[np.array([1.0, 1.0]) + 0.77 * face.direction - 0.03 * face.normal, 0.5 + 1.22]
    image = face_image(face, point[None, :], pixel=0.05, band=0.1)
    assert image.shape == (40, 57)
    assert np.argwhere(image).tolist() == [[24, 15]]


def test_face_image_ignores_points_outside_band_or_extent():
    face = _face([0, 0], [2.0, 0], 0.0, 1.0)
    points = np.array(
        [
            [1.0, 0.15, 0.5],  # 15 cm in front of the plane
            [1.0, -0.11, 0.5],  # 11 cm behind it
            [-0.01, 0.0, 0.5],  # before p0
            [2.01, 0.0, 0.5],  # past p1
            [1.0, 0.0, -0.01],  # below the floor
            [1.0, 0.0, 1.02],  # above the ceiling
        ]
    )
    assert not face_image(face, points, pixel=0.1, band=0.1).any()
    # Inside the band on both sides, and on the extent's edges (the far edges go to the last pixel).
    inside = np.array([[1.0, 0.1, 0.5], [1.0, -0.1, 0.5], [0.0, 0.0, 0.0], [2.0, 0.0, 1.0]])
    image = face_image(face, inside, pixel=0.1, band=0.1)
    assert np.argwhere(image).tolist() == [[0, 0], [5, 10], [9, 19]]


def test_face_image_refuses_bad_arguments():
    face = _face([0, 0], [2.0, 0])
    with pytest.raises(ValueError, match="pixel"):
        face_image(face, np.zeros((1, 3)), pixel=0.0)
    with pytest.raises(ValueError, match="band"):
        face_image(face, np.zeros((1, 3)), band=-0.1)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        face_image(face, np.zeros((4, 2)))


# ----------------------------------------------------------------------------- faces from points


WALL = _face([0.0, 0.0], [4.0, 0.0], 0.0, 2.6)


def _blob_face_points(seed=1) -> np.ndarray:
    """Two solid furniture blobs straddling the face line, plus floor and ceiling under and over it."""
    rng = np.random.default_rng(seed)
    blobs = [
        _box_points(rng, [0.5, -0.3, 0.0], [1.3, 0.3, 0.8], 20_000),  # a low cabinet
        _box_points(rng, [2.5, -0.2, 0.0], [3.0, 0.2, 1.2], 15_000),  # a box
    ]
    floor = np.column_stack([rng.uniform(0, 4, 4000), rng.uniform(-0.5, 0.5, 4000), np.zeros(4000)])
    ceiling = np.column_stack([rng.uniform(0, 4, 4000), rng.uniform(-0.5, 0.5, 4000), np.full(4000, 2.6)])
    return np.vstack([*blobs, floor, ceiling])


def test_fully_covered_face_has_features_one_one_one():
    points = _covered_face_points(WALL, spacing=0.02, offset=0.03)
    np.testing.assert_allclose(face_features(face_image(WALL, points)), [1.0, 1.0, 1.0])


def test_face_through_furniture_has_small_occupancy():
    alpha, _, _ = face_features(face_image(WALL, _blob_face_points()))
    # Cabinet 0.8 x 0.8 m and box 0.5 x 1.2 m, plus two pixel rows, on a 4 x 2.6 m face.
    assert 0.05 < alpha < 0.2


def test_classifier_separates_covered_wall_from_furniture_face(classifier):
    assert classifier.training["train_accuracy"] > 0.95
    points = np.vstack([_covered_face_points(WALL, offset=-0.02), _blob_face_points() + np.array([0.0, 5.0, 0.0])])
    furniture_face = _face([0.0, 5.0], [4.0, 5.0], 0.0, 2.6)
    np.testing.assert_array_equal(classifier.classify_faces([WALL, furniture_face], points), [True, False])
    assert classifier.classify_faces([], points).shape == (0,)


def test_classifier_keeps_occluded_wall_as_se(classifier):
    # A wall with a wardrobe-shaped shadow (1 x 2 m) missing is still a wall.
    points = _covered_face_points(WALL)
    u = WALL.local(points)[:, 0]
    shadowed = points[~((u > 1.0) & (u < 2.0) & (points[:, 2] < 2.0))]
    assert classifier.classify_faces([WALL], shadowed).tolist() == [True]


def test_fit_refuses_a_single_class_and_bad_shapes():
    features = np.random.default_rng(0).random((10, 3))
    with pytest.raises(ValueError, match="both"):
        SEClassifier.fit(features, np.ones(10, dtype=bool))
    with pytest.raises(ValueError, match=r"\(m, 3\)"):
        SEClassifier.fit(features[:, :2], np.arange(10) % 2 == 0)
    with pytest.raises(ValueError, match="labels"):
        SEClassifier.fit(features, np.arange(9) % 2 == 0)


# ----------------------------------------------------------------------------- numpy inference = sklearn


def test_decision_function_matches_sklearn():
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    features, labels = _synthetic_training_set(seed=3)
    model = SEClassifier.fit(features, labels, C=10.0, gamma="scale", seed=0)
    reference = Pipeline(
        [("s", StandardScaler()), ("v", SVC(kernel="rbf", C=10.0, gamma="scale", class_weight="balanced"))]
    ).fit(features, labels)
    rng = np.random.default_rng(7)
    queries = np.vstack([rng.uniform(-0.2, 1.2, size=(2000, 3)), features])
    ours, theirs = model.decision_function(queries), reference.decision_function(queries)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(model.predict(queries), reference.predict(queries))
    assert model.predict(queries).dtype == bool
    # Both signs occur, so the test checks the sign convention and not just one class.
    assert (ours > 0).any() and (ours < 0).any()


def test_decision_function_with_a_numeric_gamma_matches_sklearn():
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    rng = np.random.default_rng(11)
    features = rng.random((150, 3))
    labels = features[:, 0] + 0.2 * rng.standard_normal(150) > 0.5
    model = SEClassifier.fit(features, labels, C=3.0, gamma=0.7)
    reference = Pipeline(
        [("s", StandardScaler()), ("v", SVC(kernel="rbf", C=3.0, gamma=0.7, class_weight="balanced"))]
    ).fit(features, labels)
    queries = rng.uniform(-1, 2, size=(500, 3))
    np.testing.assert_allclose(model.decision_function(queries), reference.decision_function(queries), atol=1e-9)
    assert model.gamma == 0.7


def test_inference_does_not_need_sklearn(classifier, tmp_path, monkeypatch):
    path = classifier.save(tmp_path / "model.json")
    import sys

    monkeypatch.setitem(sys.modules, "sklearn", None)  # any import of sklearn now fails
    loaded = SEClassifier.load(path)
    assert loaded.predict(np.array([[1.0, 1.0, 1.0]])).tolist() == [True]


# ----------------------------------------------------------------------------- the model file


def test_save_load_round_trips_exactly(classifier, tmp_path):
    path = classifier.save(tmp_path / "se_svm.json")
    loaded = SEClassifier.load(path)
    for name in ("mean", "scale", "support_vectors", "dual_coef"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(classifier, name))
    assert (loaded.intercept, loaded.gamma, loaded.pixel, loaded.band) == (
        classifier.intercept,
        classifier.gamma,
        classifier.pixel,
        classifier.band,
    )
    assert loaded.training == classifier.training
    queries = np.random.default_rng(2).uniform(0, 1, size=(300, 3))
    np.testing.assert_array_equal(loaded.decision_function(queries), classifier.decision_function(queries))


def test_model_file_layout_and_checksum(classifier, tmp_path):
    path = classifier.save(tmp_path / "m.json")
    document = json.loads(path.read_text())
    assert document["format"] == "nbs-se-classifier"
    assert document["version"] == 1
    assert document["features"] == ["alpha", "delta", "epsilon"]
    assert set(document) == {"format", "version", "features", "image", "scaler", "svm", "training", "sha256"}
    assert document["training"]["seed"] == 0
    # The checksum is over the canonical JSON (sorted keys, no spaces) of everything but itself.
    rest = {k: v for k, v in document.items() if k != "sha256"}
    canonical = json.dumps(rest, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode()
    assert document["sha256"] == hashlib.sha256(canonical).hexdigest()
    # Not a pickle: plain UTF-8 JSON text.
    assert path.read_bytes().startswith(b"{")


def test_training_dict_accepts_numpy_values(classifier, tmp_path):
    classifier_copy = SEClassifier.load(classifier.save(tmp_path / "a.json"))
    classifier_copy.training["held_out_accuracy"] = np.float64(0.93)
    classifier_copy.training["confusion"] = np.array([[10, 1], [2, 20]])
    loaded = SEClassifier.load(classifier_copy.save(tmp_path / "b.json"))
    assert loaded.training["held_out_accuracy"] == 0.93
    assert loaded.training["confusion"] == [[10, 1], [2, 20]]


def _rewrite(path: Path, document: dict, *, recompute_checksum: bool) -> None:
    if recompute_checksum:
        rest = {k: v for k, v in document.items() if k != "sha256"}
        canonical = json.dumps(rest, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode()
        document["sha256"] = hashlib.sha256(canonical).hexdigest()
    path.write_text(json.dumps(document))


def test_missing_model_file(tmp_path):
    path = tmp_path / "nowhere" / "se_svm.json"
    with pytest.raises(ModelFileError, match="not found") as info:
        SEClassifier.load(path)
    assert str(path) in str(info.value)
    assert isinstance(info.value, NBSError) and isinstance(info.value, ValueError)


def test_truncated_model_file(classifier, tmp_path):
    path = classifier.save(tmp_path / "se_svm.json")
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(ModelFileError, match="truncated or not JSON") as info:
        SEClassifier.load(path)
    assert str(path) in str(info.value)


def test_binary_garbage_model_file(tmp_path):
    path = tmp_path / "se_svm.json"
    path.write_bytes(b"\x80\x04\x95 not json")  # e.g. a pickle
    with pytest.raises(ModelFileError, match="truncated or not JSON") as info:
        SEClassifier.load(path)
    assert str(path) in str(info.value)


def test_tampered_model_file(classifier, tmp_path):
    path = classifier.save(tmp_path / "se_svm.json")
    document = json.loads(path.read_text())
    document["svm"]["intercept"] += 0.5
    _rewrite(path, document, recompute_checksum=False)
    with pytest.raises(ModelFileError, match="checksum mismatch: the file was modified") as info:
        SEClassifier.load(path)
    assert str(path) in str(info.value)


def test_tampered_support_vector(classifier, tmp_path):
    path = classifier.save(tmp_path / "se_svm.json")
    document = json.loads(path.read_text())
    document["svm"]["support_vectors"][0][1] = 0.125
    _rewrite(path, document, recompute_checksum=False)
    with pytest.raises(ModelFileError, match="checksum mismatch"):
        SEClassifier.load(path)


def test_wrong_format(classifier, tmp_path):
    path = classifier.save(tmp_path / "se_svm.json")
    document = json.loads(path.read_text())
    document["format"] = "nbs-floorplan"
    _rewrite(path, document, recompute_checksum=False)
    with pytest.raises(ModelFileError, match="'format'") as info:
        SEClassifier.load(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d.update(version=2), "'version'"),
        (lambda d: d.pop("scaler"), "'scaler'"),
        (lambda d: d.update(extra=1), "'extra'"),
        (lambda d: d.update(features=["alpha", "epsilon", "delta"]), "'features'"),
        (lambda d: d["svm"].update(dual_coef=d["svm"]["dual_coef"][:-1]), "'svm.dual_coef'"),
        (lambda d: d["svm"].update(support_vectors=[r[:2] for r in d["svm"]["support_vectors"]]), "'svm.support"),
        (lambda d: d["scaler"].update(mean=[0.0, 0.0]), "'scaler.mean'"),
        (lambda d: d["scaler"].update(scale=[1.0, 0.0, 1.0]), "'scaler.scale'"),
        (lambda d: d["svm"].update(gamma="scale"), "'svm.gamma'"),
        (lambda d: d["svm"].update(gamma=-1.0), "'svm.gamma'"),
        (lambda d: d["svm"].update(kernel="linear"), "'svm.kernel'"),
        (lambda d: d["svm"].pop("intercept"), "'svm.intercept'"),
        (lambda d: d["image"].update(pixel=[0.05]), "'image.pixel'"),
        (lambda d: d.update(training=[]), "'training'"),
    ],
)
def test_malformed_fields_are_named(classifier, tmp_path, edit, field):
    # The checksum is recomputed, so only the field check can catch these.
    path = classifier.save(tmp_path / "se_svm.json")
    document = json.loads(path.read_text())
    edit(document)
    _rewrite(path, document, recompute_checksum=True)
    with pytest.raises(ModelFileError, match="field") as info:
        SEClassifier.load(path)
    assert field in str(info.value)
    assert str(path) in str(info.value)


def test_load_default_is_the_packaged_model_or_a_clear_error():
    from importlib import resources

    resource = resources.files("nbs_env.perception").joinpath("data/se_svm.json")
    if resource.is_file():
        model = SEClassifier.load_default()
        points = _covered_face_points(WALL)
        assert model.classify_faces([WALL], points).tolist() == [True]
    else:
        with pytest.raises(ModelFileError, match=r"se_svm\.json"):
            SEClassifier.load_default()


def test_load_default_reads_the_file_once_and_hands_out_independent_copies(monkeypatch):
    """Every reset asks for the shipped model: it is read and checked once, and each caller gets
    its own copy (changing one changes neither the next nor the cached one)."""
    from nbs_env.perception import structure

    first = SEClassifier.load_default()
    monkeypatch.setattr(SEClassifier, "_read_default", classmethod(lambda cls: pytest.fail("read again")))
    first.support_vectors[:] = 0.0
    first.training["tampered"] = True
    second = SEClassifier.load_default()
    assert second is not first and "tampered" not in second.training
    assert np.any(second.support_vectors != 0.0)
    assert structure._shipped_classifier.cache_info().currsize == 1


# ----------------------------------------------------------------------------- point labels

ROOM = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 4.0], [0.0, 4.0]])  # counter-clockwise
ROOM_FACES = [_face(ROOM[i], ROOM[(i + 1) % 4], 0.0, 2.6) for i in range(4)]
SE_FACES = ROOM_FACES[:3]  # the wall x = 0 (last face) is not SE


def test_label_points_structure_and_clutter():
    points = np.array(
        [
            [2.0, 0.03, 1.3],  # on the SE wall y = 0, in front
            [2.0, -0.08, 1.3],  # just behind it
            [4.95, 2.0, 1.0],  # on the SE wall x = 5
            [2.0, 2.0, 0.02],  # floor
            [2.0, 2.0, -0.05],  # floor, just below
            [2.0, 2.0, 2.58],  # ceiling
            [2.5, 2.0, 1.3],  # middle of the room
            [0.05, 2.0, 1.3],  # 5 cm from the non-SE wall x = 0
            [-0.05, 2.0, 1.3],  # 5 cm behind it
            [-0.05, 2.0, 0.0],  # floor height, just outside the polygon but within the grown one
            [-0.5, 2.0, 0.0],  # floor height, 50 cm outside the polygon
            [2.0, 2.0, 0.2],  # 20 cm above the floor
        ]
    )
    expected = [True, True, True, True, True, True, False, False, False, True, False, False]
    labels = label_points(points, SE_FACES, 0.0, 2.6, ROOM)
    assert labels.dtype == bool
    assert labels.tolist() == expected


def test_label_points_respects_the_face_extent_with_margin():
    # Only the face y = 0 (x from 0 to 5, z from 0 to 2.6); floor and ceiling far away.
    face = ROOM_FACES[0]
    points = np.array(
        [
            [5.08, 0.05, 1.3],  # past p1 but within the 10 cm margin
            [5.15, 0.05, 1.3],  # 5 cm from the plane but 15 cm past the wall's end
            [-0.15, 0.05, 1.3],  # 15 cm before p0
            [2.0, 0.05, 2.68],  # 8 cm above the face top
            [2.0, 0.05, 2.75],  # 15 cm above it
            [2.0, 0.05, -0.2],  # 20 cm below the face bottom
        ]
    )
    labels = label_points(points, [face], -10.0, 10.0, ROOM)
    assert labels.tolist() == [True, False, False, True, False, False]


def test_label_points_without_se_walls_keeps_floor_and_ceiling():
    points = np.array([[2.0, 0.03, 1.3], [2.0, 2.0, 0.0], [2.0, 2.0, 2.6]])
    assert label_points(points, [], 0.0, 2.6, ROOM).tolist() == [False, True, True]
    assert label_points(np.zeros((0, 3)), SE_FACES, 0.0, 2.6, ROOM).shape == (0,)


def test_label_points_concave_room():
    # An L-shaped room: the floor of the notch outside the L is not Structure.
    polygon = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]], dtype=float)
    points = np.array([[1.0, 1.0, 0.0], [3.0, 3.0, 0.0], [3.0, 2.05, 0.0]])
    assert label_points(points, [], 0.0, 2.6, polygon).tolist() == [True, False, True]


def test_label_points_many_points_is_fast():
    import time

    rng = np.random.default_rng(0)
    points = rng.uniform([-0.5, -0.5, -0.2], [5.5, 4.5, 2.8], size=(200_000, 3))
    faces = [_face(ROOM[i % 4] + 0.01 * i, ROOM[(i + 1) % 4] + 0.01 * i) for i in range(20)]
    start = time.perf_counter()
    labels = label_points(points, faces, 0.0, 2.6, ROOM)
    assert time.perf_counter() - start < 2.0
    assert 0 < labels.sum() < len(points)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_labelling_through_the_compiled_face_pass_is_the_numpy_labelling(seed):
    """label_points over a PointIndex marks the SE faces' points in one compiled pass; the numpy
    pass over a plain array (kept as the oracle) must give the same labels: oblique, axis-parallel
    and reversed faces, points on the bounds (distance exactly), in and beyond the margins."""
    from nbs_env.perception.faces import PointIndex
    from nbs_env.perception.structure import label_points

    rng = np.random.default_rng(seed)
    faces = [
        WallFace(np.array([0.0, 0.0]), np.array([6.0, 0.0]), 0.0, 2.8),
        WallFace(np.array([6.0, 0.0]), np.array([6.0, 4.0]), 0.0, 2.8),
        WallFace(np.array([6.0, 4.0]), np.array([1.3, 5.7]), 0.0, 2.8),
        WallFace(np.array([1.3, 5.7]), np.array([0.0, 0.0]), 0.0, 2.8),
    ]
    points = rng.uniform([-1.0, -1.0, -0.5], [7.0, 7.0, 3.3], size=(20_000, 3))
    # Points exactly 0.1 m off the first face and exactly at its ends.
    points[:50] = np.column_stack([rng.uniform(0, 6, 50), np.full(50, 0.1), rng.uniform(0, 2.8, 50)])
    points[50:60] = [[-0.1, 0.05, 1.0]] * 10
    polygon = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [1.3, 5.7]])
    for cell in (0.5, 0.37):
        for chosen in (faces, faces[1:3], []):
            want = label_points(points, chosen, 0.0, 2.8, polygon)
            got = label_points(PointIndex(points, cell=cell), chosen, 0.0, 2.8, polygon)
            np.testing.assert_array_equal(got, want)
            assert want.sum() > (1000 if chosen else 0)


@pytest.mark.parametrize("seed", [0, 1])
def test_face_images_in_one_compiled_pass_are_the_numpy_images(seed):
    """face_images over a PointIndex fills every face's image in one compiled pass; each must be
    face_image's numpy image (the oracle): oblique faces, points on the far edges and band."""
    from nbs_env.perception.faces import PointIndex
    from nbs_env.perception.structure import face_image, face_images

    rng = np.random.default_rng(seed)
    faces = [
        WallFace(np.array([0.0, 0.0]), np.array([6.0, 0.0]), 0.1, 2.8),
        WallFace(np.array([6.0, 0.0]), np.array([6.0, 4.02]), 0.1, 2.8),
        WallFace(np.array([6.0, 4.02]), np.array([1.3, 5.7]), 0.1, 2.8),
    ]
    points = rng.uniform([-1.0, -1.0, -0.5], [7.0, 7.0, 3.3], size=(30_000, 3))
    points[:20] = [[6.0, 0.1, 2.8]] * 10 + [[3.0, 0.1, 0.1]] * 10  # on the far edge, on the band
    for pixel, band in ((0.05, 0.10), (0.1, 0.2)):
        got = face_images(faces, PointIndex(points, cell=0.5), pixel=pixel, band=band)
        for face, image in zip(faces, got, strict=True):
            want = face_image(face, points, pixel=pixel, band=band)
            assert image.shape == want.shape and want.any()
            np.testing.assert_array_equal(image, want)
    assert face_images([], PointIndex(points)) == []
