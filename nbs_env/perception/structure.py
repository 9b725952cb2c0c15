"""Structural-element (SE) classification of the RoI's wall faces and Structure/Clutter point labels.

Paper §3.2 and METHOD §4. Floor and ceiling are SE by assumption; each vertical wall face of the
RoI is classified from the binary image of the measured points near its plane:

1. :func:`face_image` rasterises the points within ±``band`` of the face plane onto the face
   (``pixel`` metres per pixel).
2. :func:`face_features` computes the paper's features F = (α, δ, ε): occupancy, mean cluster
   compactness and dispersion, equations (1)-(3).
3. :class:`SEClassifier` is a binary RBF SVM on the standardised features. It is trained with
   scikit-learn but predicts from its stored arrays with numpy alone, so the shipped model is a
   plain JSON file (never a pickle) and inference does not depend on the scikit-learn version.
4. :func:`label_points` labels each point Structure when it lies within ``distance`` of an SE face
   (wall, floor or ceiling), else Clutter.

Honest simulation: this module sees only measured points and the robot's own faces; it never
imports the ``scenes`` ground truth.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import math
import os
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Polygon

from nbs_env.atomic import write_text
from nbs_env.errors import ModelFileError
from nbs_env.perception.faces import PointIndex, WallFace
from scenes.jsonio import MAX_JSON_BYTES, json_text, read_json

__all__ = [
    "DEFAULT_MODEL_RESOURCE",
    "FEATURE_NAMES",
    "MODEL_FORMAT",
    "MODEL_VERSION",
    "SEClassifier",
    "face_features",
    "face_image",
    "face_images",
    "label_points",
]

#: Value of the ``format`` key of a stored classifier.
MODEL_FORMAT = "nbs-se-classifier"
#: Version of the stored classifier layout understood by :meth:`SEClassifier.load`.
MODEL_VERSION = 1
#: Feature order of every (m, 3) feature array and of the stored model.
FEATURE_NAMES = ("alpha", "delta", "epsilon")
#: Packaged model, relative to the ``nbs_env.perception`` package (written by the training script).
DEFAULT_MODEL_RESOURCE = "data/se_svm.json"
#: Metres a face image's pixel may take in a stored model (the shipped one's is 0.05): as the voxels'
#: sizes are bounded, and for the same reason (1e-9 m asked numpy for an image it cannot index).
PIXEL_RANGE = (0.005, 1.0)
#: Metres of the band about a face plane whose points make its image (the shipped one's is 0.10).
BAND_RANGE = (0.0, 1.0)
#: The largest magnitude of a stored model's scaler, support vectors, coefficients and intercept
#: (the shipped one's largest is 16), and the smallest scale: far beyond, the decision overflows.
MAX_MODEL_VALUE = 1e6
MIN_SCALE = 1e-6
#: The largest RBF gamma a stored model may hold (the shipped one's is 0.33, on standardised features).
MAX_GAMMA = 1e6

_TOP_KEYS = frozenset({"format", "version", "features", "image", "scaler", "svm", "training", "sha256"})

# An edge whose length is a whole number of pixels up to rounding (0.3 m / 0.1 m = 2.9999999999999996
# or 4.000000000000001) must not get a sliver column that no point can fill: it would always be
# black and lower α for no reason. Lengths within this many pixels of a whole number are rounded.
_PIXEL_ROUNDING = 1e-9

# Rows of the (rows, support vectors, 3) difference array built per block in the decision function;
# bounds its memory to ~100 MB for a few thousand support vectors.
_DECISION_BLOCK = 4096

# The 3×3 all-ones structuring element: diagonal neighbours connect (8-connectivity), so a thin
# diagonal run of points is one cluster, as it is one object on the wall.
_EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


# ----------------------------------------------------------------------------- face image & features


def _pixel_count(extent: float, pixel: float) -> int:
    """Pixels covering ``extent`` metres: max(1, ceil(extent / pixel)), forgiving rounding noise."""
    ratio = extent / pixel
    nearest = round(ratio)
    if abs(ratio - nearest) <= _PIXEL_ROUNDING * max(1.0, abs(ratio)):
        ratio = float(nearest)
    return max(1, math.ceil(ratio))


def _near(face: WallFace, points: np.ndarray | PointIndex, margin: float) -> np.ndarray:
    """Indices of the (n, 3) points whose xy lies in the face's bounding box grown by ``margin``: a
    cheap first cut, so that only those go through the face-frame transform."""
    p0, p1 = np.asarray(face.p0, dtype=float), np.asarray(face.p1, dtype=float)
    lo, hi = np.minimum(p0, p1) - margin, np.maximum(p0, p1) + margin
    if isinstance(points, PointIndex):
        return points.within(lo, hi)
    x, y = points[:, 0], points[:, 1]
    return np.flatnonzero((x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1]))


def face_image(
    face: WallFace, points: np.ndarray | PointIndex, *, pixel: float = 0.05, band: float = 0.10
) -> np.ndarray:
    """Binary image of the measured points near a wall face.

    Parameters
    ----------
    face : WallFace
        The vertical face.
    points : (n, 3) float or PointIndex
        Measured world points (any n, also 0), or an index of them (the same image, faster when
        many faces look at the same points).
    pixel : float, keyword-only
        Pixel size in metres (> 0).
    band : float, keyword-only
        Half-thickness of the slab around the face plane whose points are kept, metres (>= 0).

    Returns
    -------
    (d2, d1) bool
        ``image[row, col]`` is True when some point with ``|w| <= band``, ``0 <= u <= length`` and
        ``0 <= v <= height`` falls in it, with ``col = floor(u / pixel)`` and ``row = floor(v / pixel)``
        (row 0 at the floor). ``d1 = max(1, ceil(length / pixel))``, ``d2 = max(1, ceil(height / pixel))``.
        Points exactly on the far edge (u = length or v = height) go into the last column or row.
    """
    if not (math.isfinite(pixel) and pixel > 0):
        raise ValueError(f"pixel must be a finite number > 0 metres, got {pixel!r}")
    if not (math.isfinite(band) and band >= 0):
        raise ValueError(f"band must be a finite number >= 0 metres, got {band!r}")
    index = points if isinstance(points, PointIndex) else None
    points = index.points if index is not None else np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {points.shape}")
    length, height = face.length, face.height
    d1, d2 = _pixel_count(length, pixel), _pixel_count(height, pixel)
    image = np.zeros((d2, d1), dtype=bool)
    if len(points) == 0:
        return image
    u, v, w = face.local(points[_near(face, index if index is not None else points, band)]).T
    keep = (np.abs(w) <= band) & (u >= 0) & (u <= length) & (v >= 0) & (v <= height)
    cols = np.minimum((u[keep] / pixel).astype(np.intp), d1 - 1)  # u, v >= 0 here, so truncation is floor
    rows = np.minimum((v[keep] / pixel).astype(np.intp), d2 - 1)
    image[rows, cols] = True
    return image


def face_images(
    faces: Sequence[WallFace], points: np.ndarray | PointIndex, *, pixel: float = 0.05, band: float = 0.10
) -> list[np.ndarray]:
    """:func:`face_image` of each of ``faces``; over a :class:`PointIndex`, in one compiled pass
    (the same images)."""
    if not isinstance(points, PointIndex) or not (math.isfinite(pixel) and pixel > 0 and math.isfinite(band)):
        return [face_image(f, points, pixel=pixel, band=band) for f in faces]
    if band < 0:
        raise ValueError(f"band must be a finite number >= 0 metres, got {band!r}")
    dims = np.array([[_pixel_count(f.height, pixel), _pixel_count(f.length, pixel)] for f in faces], dtype=np.int64)
    return points.face_images(faces, band, pixel, dims)


def face_features(image: np.ndarray) -> np.ndarray:
    """The paper's feature vector F = (α, δ, ε) of a binary face image, equations (1)-(3).

    Parameters
    ----------
    image : (d2, d1) bool
        Binary face image (True = white = some point), as from :func:`face_image`.

    Returns
    -------
    (3,) float
        α = n / (d1·d2), the occupancy, with n the white pixels;
        δ = (1/k) Σ_i n_i / (d1i·d2i), the mean compactness of the k clusters (8-connected
        components), n_i the white pixels of cluster i and d1i×d2i its bounding box in pixels;
        ε = Σ_i d1i·d2i / (d1·d2), the dispersion. All three are 0 for an image with no white pixel.
        Bounding boxes of different clusters may overlap, so ε can exceed 1 in principle; the paper
        sums them as they are and so does this function.
    """
    image = np.asarray(image, dtype=bool)
    if image.ndim != 2 or image.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {image.shape}")
    area = float(image.size)
    labels, k = ndimage.label(image, structure=_EIGHT_CONNECTED)
    if k == 0:
        return np.zeros(3)
    # Per-cluster pixel counts and bounding boxes, vectorised over the white pixels (no loop).
    rows, cols = np.nonzero(labels)
    ids = labels[rows, cols] - 1
    n_i = np.bincount(ids, minlength=k).astype(float)
    row_min = np.full(k, image.shape[0], dtype=np.intp)
    col_min = np.full(k, image.shape[1], dtype=np.intp)
    row_max = np.zeros(k, dtype=np.intp)
    col_max = np.zeros(k, dtype=np.intp)
    np.minimum.at(row_min, ids, rows)
    np.minimum.at(col_min, ids, cols)
    np.maximum.at(row_max, ids, rows)
    np.maximum.at(col_max, ids, cols)
    box = ((row_max - row_min + 1) * (col_max - col_min + 1)).astype(float)
    alpha = rows.size / area
    delta = float(np.mean(n_i / box))
    epsilon = float(box.sum()) / area
    return np.array([alpha, delta, epsilon])


# ----------------------------------------------------------------------------- classifier


def _canonical(document: dict[str, Any]) -> bytes:
    """The bytes the checksum is taken over: sorted keys, no spaces, ASCII, no NaN."""
    return json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False).encode()


def _checksum(document: dict[str, Any]) -> str:
    return hashlib.sha256(_canonical({k: v for k, v in document.items() if k != "sha256"})).hexdigest()


def _json_default(value: Any) -> Any:
    """Let numpy scalars and arrays in the free-form ``training`` dict be written as JSON."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _as_features(features: np.ndarray) -> np.ndarray:
    features = np.asarray(features, dtype=float)
    if features.ndim == 1 and features.shape == (3,):
        features = features[None, :]
    if features.ndim != 2 or features.shape[1] != 3:
        raise ValueError(f"features must have shape (m, 3) (alpha, delta, epsilon), got {features.shape}")
    if not np.all(np.isfinite(features)):
        raise ValueError("features must be finite")
    return features


class SEClassifier:
    """Binary RBF SVM deciding whether a wall face is a structural element, from F = (α, δ, ε).

    Trained with scikit-learn (:meth:`fit`); predicts from its stored arrays with numpy alone:
    ``decision(x) = Σ_i dual_i · exp(-γ ‖sv_i − z‖²) + b`` with ``z = (x − mean) / scale``; the face
    is SE when ``decision > 0``.

    Parameters
    ----------
    mean, scale : (3,) float
        Standardisation of the features (``scale > 0``).
    support_vectors : (s, 3) float
        Support vectors in standardised feature space.
    dual_coef : (s,) float
        Signed dual coefficients (positive for SE support vectors).
    intercept : float
        Bias b.
    gamma : float
        RBF kernel coefficient (> 0), in standardised units.
    pixel, band : float, keyword-only
        Image parameters the training features were computed with; :meth:`classify_faces` uses them.
    training : dict, keyword-only
        Free-form, JSON-serialisable record of how the model was trained (counts, metrics, seed).
    """

    def __init__(
        self,
        mean: np.ndarray,
        scale: np.ndarray,
        support_vectors: np.ndarray,
        dual_coef: np.ndarray,
        intercept: float,
        gamma: float,
        *,
        pixel: float = 0.05,
        band: float = 0.10,
        training: dict[str, Any] | None = None,
    ) -> None:
        self.mean = np.array(mean, dtype=float).reshape(-1)
        self.scale = np.array(scale, dtype=float).reshape(-1)
        self.support_vectors = np.array(support_vectors, dtype=float)
        self.dual_coef = np.array(dual_coef, dtype=float).reshape(-1)
        self.intercept = float(intercept)
        self.gamma = float(gamma)
        self.pixel = float(pixel)
        self.band = float(band)
        self.training: dict[str, Any] = dict(training or {})
        problem = self._problem()
        if problem is not None:
            raise ValueError(f"{problem[0]}: {problem[1]}")

    def _problem(self) -> tuple[str, str] | None:
        """(field, what is wrong) for the first invalid array, or None. Field names are the JSON ones."""
        checks: list[tuple[str, np.ndarray, bool, str]] = [
            # The features are ratios in [0, 1]; a scaler or model far outside what fitting them gives
            # (1e-300, 1e308) overflows at the first face and calls every face clutter, silently.
            (
                "scaler.mean",
                self.mean,
                self.mean.shape == (3,) and _within(self.mean, MAX_MODEL_VALUE),
                f"shape (3,), each within ±{MAX_MODEL_VALUE:g}",
            ),
            (
                "scaler.scale",
                self.scale,
                self.scale.shape == (3,) and bool(np.all((self.scale >= MIN_SCALE) & (self.scale <= MAX_MODEL_VALUE))),
                f"shape (3,), within [{MIN_SCALE:g}, {MAX_MODEL_VALUE:g}]",
            ),
            (
                "svm.support_vectors",
                self.support_vectors,
                self.support_vectors.ndim == 2
                and self.support_vectors.shape[1] == 3
                and len(self.support_vectors) > 0
                and _within(self.support_vectors, MAX_MODEL_VALUE),
                f"shape (s, 3) with s >= 1, each within ±{MAX_MODEL_VALUE:g}",
            ),
            (
                "svm.dual_coef",
                self.dual_coef,
                self.dual_coef.shape == (len(self.support_vectors),) and _within(self.dual_coef, MAX_MODEL_VALUE),
                f"shape ({len(self.support_vectors)},), one per support vector, each within ±{MAX_MODEL_VALUE:g}",
            ),
            (
                "svm.intercept",
                np.array(self.intercept),
                _within(np.array(self.intercept), MAX_MODEL_VALUE),
                f"within ±{MAX_MODEL_VALUE:g}",
            ),
            # The features are standardised, so gamma is about 1 / features; far beyond, exp overflows.
            ("svm.gamma", np.array(self.gamma), 0 < self.gamma <= MAX_GAMMA, f"within (0, {MAX_GAMMA:g}]"),
            # Bounded as the voxels are: an image of 1e-9 m pixels asked numpy for more than it can index.
            ("image.pixel", np.array(self.pixel), PIXEL_RANGE[0] <= self.pixel <= PIXEL_RANGE[1], _metres(PIXEL_RANGE)),
            ("image.band", np.array(self.band), BAND_RANGE[0] <= self.band <= BAND_RANGE[1], _metres(BAND_RANGE)),
        ]
        for name, array, ok, expected in checks:
            if not ok:
                got = f"{float(array):g}" if array.shape == () else f"shape {array.shape}"
                if array.shape != () and array.size and array.dtype.kind == "f":
                    got += f", values {np.nanmin(array):g} to {np.nanmax(array):g}"
                return name, f"expected {expected}, got {got}"
            if not np.all(np.isfinite(array)):
                return name, "values must be finite"
        return None

    # --------------------------------------------------------------------- training

    @classmethod
    def fit(
        cls,
        features: np.ndarray,
        labels: np.ndarray,
        *,
        C: float = 10.0,
        gamma: str | float = "scale",
        seed: int = 0,
        pixel: float = 0.05,
        band: float = 0.10,
    ) -> SEClassifier:
        """Train on labelled feature vectors with scikit-learn and keep only the arrays inference needs.

        Parameters
        ----------
        features : (m, 3) float
            (α, δ, ε) per face.
        labels : (m,) bool
            True for SE faces. Both classes must occur.
        C : float, keyword-only
            SVM regularisation (> 0).
        gamma : "scale", "auto" or float, keyword-only
            RBF coefficient as scikit-learn's ``SVC`` takes it; the resolved value is stored.
        seed : int, keyword-only
            ``random_state`` of the SVC (recorded; libsvm's C-SVC itself is deterministic).
        pixel, band : float, keyword-only
            Image parameters the features were computed with, stored for :meth:`classify_faces`.

        Returns
        -------
        SEClassifier
            With ``training`` holding the sample counts, hyper-parameters, seed and training accuracy.
        """
        # Imported here: scikit-learn is needed to train, never to load or predict.
        from sklearn.pipeline import Pipeline
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import SVC

        X = _as_features(features)
        y = np.asarray(labels).reshape(-1)
        if y.shape != (len(X),):
            raise ValueError(f"labels must have shape ({len(X)},), got {np.asarray(labels).shape}")
        y = y.astype(bool)
        if y.all() or not y.any():
            raise ValueError("labels must contain both SE (True) and non-SE (False) faces")
        if not (math.isfinite(C) and C > 0):
            raise ValueError(f"C must be a finite number > 0, got {C!r}")
        pipeline = Pipeline(
            [
                ("scaler", StandardScaler()),
                ("svm", SVC(kernel="rbf", C=C, gamma=gamma, class_weight="balanced", random_state=seed)),
            ]
        )
        pipeline.fit(X, y)
        scaler: StandardScaler = pipeline.named_steps["scaler"]
        svc: SVC = pipeline.named_steps["svm"]
        # scikit-learn's binary decision_function is dual_coef_ @ K + intercept_ and its positive side
        # is classes_[1]; with bool labels classes_ is [False, True], so positive means SE.
        if list(svc.classes_) != [False, True]:
            raise RuntimeError(f"unexpected SVC classes {svc.classes_!r}")
        train_accuracy = float(np.mean(pipeline.predict(X) == y))
        model = cls(
            mean=scaler.mean_,
            scale=scaler.scale_,
            support_vectors=svc.support_vectors_,
            dual_coef=svc.dual_coef_[0],
            intercept=float(svc.intercept_[0]),
            gamma=float(svc._gamma),  # the resolved value of "scale"/"auto"; no public attribute holds it
            pixel=pixel,
            band=band,
            training={
                "n_samples": len(y),
                "n_se": int(y.sum()),
                "n_non_se": int((~y).sum()),
                "n_support_vectors": len(svc.support_vectors_),
                "C": float(C),
                "gamma": gamma if isinstance(gamma, str) else float(gamma),
                "class_weight": "balanced",
                "seed": int(seed),
                "train_accuracy": train_accuracy,
            },
        )
        return model

    # --------------------------------------------------------------------- inference

    def decision_function(self, features: np.ndarray) -> np.ndarray:
        """Signed SVM decision per feature vector; > 0 means SE.

        Parameters
        ----------
        features : (m, 3) float
            (α, δ, ε) per face (a single (3,) vector is taken as m = 1).

        Returns
        -------
        (m,) float
        """
        z = (_as_features(features) - self.mean) / self.scale
        out = np.empty(len(z))
        for start in range(0, len(z), _DECISION_BLOCK):
            block = z[start : start + _DECISION_BLOCK]
            # Squared distances from explicit differences rather than ‖a‖²+‖b‖²−2a·b: no cancellation,
            # so the result matches libsvm's own kernel evaluation to rounding.
            sq = np.sum((block[:, None, :] - self.support_vectors[None, :, :]) ** 2, axis=2)
            out[start : start + len(block)] = np.exp(-self.gamma * sq) @ self.dual_coef + self.intercept
        return out

    def predict(self, features: np.ndarray) -> np.ndarray:
        """(m,) bool: True where the face with these (α, δ, ε) is classified SE."""
        return self.decision_function(features) > 0

    def classify_faces(self, faces: Sequence[WallFace], points: np.ndarray | PointIndex) -> np.ndarray:
        """Classify wall faces from the measured points, with the model's own pixel and band.

        Parameters
        ----------
        faces : sequence of m WallFace
        points : (n, 3) float or PointIndex
            Measured world points, or an index of them.

        Returns
        -------
        (m,) bool
            True for faces classified SE.
        """
        if len(faces) == 0:
            return np.zeros(0, dtype=bool)
        if not isinstance(points, PointIndex):
            points = np.asarray(points, dtype=float)
        return self.classify_images([face_image(f, points, pixel=self.pixel, band=self.band) for f in faces])

    def classify_images(self, images: Sequence[np.ndarray]) -> np.ndarray:
        """(m,) bool: :meth:`classify_faces` from the faces' images, made at the model's own pixel and
        band (:func:`face_image`)."""
        if len(images) == 0:
            return np.zeros(0, dtype=bool)
        return self.predict(np.array([face_features(image) for image in images]))

    # --------------------------------------------------------------------- storage

    def to_dict(self) -> dict[str, Any]:
        """The JSON document :meth:`save` writes, checksum included."""
        document: dict[str, Any] = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "features": list(FEATURE_NAMES),
            "image": {"pixel": self.pixel, "band": self.band},
            "scaler": {"mean": self.mean.tolist(), "scale": self.scale.tolist()},
            "svm": {
                "kernel": "rbf",
                "gamma": self.gamma,
                "intercept": self.intercept,
                "support_vectors": self.support_vectors.tolist(),
                "dual_coef": self.dual_coef.tolist(),
            },
            "training": self.training,
        }
        # Round-trip through JSON first so the checksum is over exactly what a reader will parse
        # (numpy scalars in ``training`` become plain numbers, tuples become lists).
        document = json.loads(json.dumps(document, default=_json_default, allow_nan=False))
        document["sha256"] = _checksum(document)
        return document

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the model as JSON (atomically: a reader never sees half a file).

        Parameters
        ----------
        path : str or PathLike
            Destination; its directory must exist.

        Returns
        -------
        Path
            The path written.
        """
        path = Path(path)
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
        return write_text(path, text)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SEClassifier:
        """Read a model written by :meth:`save`.

        Raises
        ------
        ModelFileError
            Missing or unreadable file, truncated or not JSON, wrong format/version/keys, invalid
            array shapes or values, or a checksum mismatch. The message names the path.
        """
        path = Path(path)
        try:
            size = path.stat().st_size
            if size > MAX_JSON_BYTES:  # read whole and decoded: sized first
                raise ModelFileError(f"{path}: a file of {size:,} bytes; a model file holds at most {MAX_JSON_BYTES:,}")
            text = path.read_text(encoding="utf-8-sig")  # a byte-order mark, as RFC 8259 allows
        except FileNotFoundError:
            raise ModelFileError(f"{path}: model file not found") from None
        except UnicodeDecodeError:
            raise ModelFileError(f"{path}: truncated or not JSON (not UTF-8 text)") from None
        except OSError as exc:
            raise ModelFileError(f"{path}: cannot read the model file ({exc.strerror or exc})") from None
        return cls.from_text(text, source=str(path))

    @classmethod
    def load_default(cls) -> SEClassifier:
        """The classifier shipped with the package (``nbs_env/perception/data/se_svm.json``): a copy
        of the one read and checked on the first call (each env reset asks for it; reading and
        checking the file cost 2.9 ms a reset, a copy 0.04 ms)."""
        return copy.deepcopy(_shipped_classifier(cls))

    @classmethod
    def _read_default(cls) -> SEClassifier:
        resource = resources.files("nbs_env.perception").joinpath(DEFAULT_MODEL_RESOURCE)
        source = str(resource)
        try:
            text = resource.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ModelFileError(
                f"{source}: model file not found (train it with the SE training script in train/)"
            ) from None
        except UnicodeDecodeError:
            raise ModelFileError(f"{source}: truncated or not JSON (not UTF-8 text)") from None
        except OSError as exc:
            raise ModelFileError(f"{source}: cannot read the model file ({exc})") from None
        return cls.from_text(text, source=source)

    @classmethod
    def from_text(cls, text: str, *, source: str = "<string>") -> SEClassifier:
        """Parse and check a stored model; ``source`` names it in error messages."""
        try:
            document = read_json(text)
        except json.JSONDecodeError as exc:  # the reader's own words: a key twice, nesting, a huge number
            raise ModelFileError(f"{source}: truncated or not JSON ({exc})") from None
        except RecursionError:
            raise ModelFileError(f"{source}: truncated or not JSON") from None

        def fail(field: str, message: str) -> ModelFileError:
            return ModelFileError(f"{source}: field {field!r}: {message}")

        if not isinstance(document, dict):
            raise fail("<top level>", f"expected a JSON object, got {type(document).__name__}")
        # Format and version first: a wrong kind of file should be reported as such, not as a bad checksum.
        if document.get("format") != MODEL_FORMAT:
            raise fail("format", f"expected {json_text(MODEL_FORMAT)}, got {json_text(document.get('format'))}")
        if document.get("version") != MODEL_VERSION or isinstance(document.get("version"), bool):
            raise fail("version", f"expected {MODEL_VERSION}, got {json_text(document.get('version'))}")
        missing = sorted(_TOP_KEYS - document.keys())
        if missing:
            raise fail(missing[0], f"missing (required keys: {sorted(_TOP_KEYS)})")
        unknown = sorted(document.keys() - _TOP_KEYS)
        if unknown:
            raise fail(unknown[0], "unknown key")
        if not isinstance(document["sha256"], str):
            raise fail("sha256", "expected a hex string")
        try:
            checksum = _checksum(document)
        except ValueError:  # NaN or Infinity literals, which save() never writes
            raise fail("<document>", "non-finite number") from None
        if checksum != document["sha256"]:
            raise ModelFileError(f"{source}: checksum mismatch: the file was modified")
        if document["features"] != list(FEATURE_NAMES):
            raise fail("features", f"expected {list(FEATURE_NAMES)}, got {document['features']!r}")
        for section in ("image", "scaler", "svm", "training"):
            if not isinstance(document[section], dict):
                raise fail(section, f"expected a JSON object, got {type(document[section]).__name__}")
        svm = document["svm"]
        if svm.get("kernel") != "rbf":
            raise fail("svm.kernel", f"expected 'rbf', got {svm.get('kernel')!r}")

        def get(section: str, key: str) -> Any:
            if key not in document[section]:
                raise fail(f"{section}.{key}", "missing")
            value = document[section][key]
            try:
                # Only numbers (and nested lists of them) are accepted; bools and strings are not.
                array = np.array(value, dtype=float)
                if _has_non_number(value):
                    raise TypeError
            except (TypeError, ValueError, OverflowError):  # an int of 400 digits overflows
                raise fail(f"{section}.{key}", "expected numbers") from None
            return array

        arrays = {
            "mean": get("scaler", "mean"),
            "scale": get("scaler", "scale"),
            "support_vectors": get("svm", "support_vectors"),
            "dual_coef": get("svm", "dual_coef"),
            "intercept": get("svm", "intercept"),
            "gamma": get("svm", "gamma"),
            "pixel": get("image", "pixel"),
            "band": get("image", "band"),
        }
        for name in ("intercept", "gamma", "pixel", "band"):
            if arrays[name].shape != ():
                section = "image" if name in ("pixel", "band") else "svm"
                raise fail(f"{section}.{name}", f"expected a single number, got shape {arrays[name].shape}")
        # Shapes are checked on the raw arrays (no reshape), so a (1, s) dual_coef is refused too.
        if arrays["dual_coef"].ndim != 1:
            raise fail("svm.dual_coef", f"expected shape (s,), got {arrays['dual_coef'].shape}")
        model = cls.__new__(cls)
        model.mean, model.scale = arrays["mean"], arrays["scale"]
        model.support_vectors, model.dual_coef = arrays["support_vectors"], arrays["dual_coef"]
        model.intercept, model.gamma = float(arrays["intercept"]), float(arrays["gamma"])
        model.pixel, model.band = float(arrays["pixel"]), float(arrays["band"])
        model.training = document["training"]
        problem = model._problem()
        if problem is not None:
            raise fail(*problem)
        return model


def _within(values: np.ndarray, bound: float) -> bool:
    with np.errstate(invalid="ignore"):
        return bool(np.all(np.abs(values) <= bound))  # NaN is not


def _metres(bounds: tuple[float, float]) -> str:
    return f"within [{bounds[0]:g}, {bounds[1]:g}] metres"


@functools.cache
def _shipped_classifier(cls: type[SEClassifier]) -> SEClassifier:
    return cls._read_default()


def _has_non_number(value: Any) -> bool:
    """True when a nested JSON list holds anything but int/float (bools would silently become 0/1)."""
    if isinstance(value, list):
        return any(_has_non_number(v) for v in value)
    return isinstance(value, bool) or not isinstance(value, (int, float))


# ----------------------------------------------------------------------------- point labels


def label_points(
    points: np.ndarray | PointIndex,
    se_faces: Sequence[WallFace],
    floor_z: float,
    ceiling_z: float,
    polygon: np.ndarray,
    *,
    distance: float = 0.10,
    ceiling: bool = True,
) -> np.ndarray:
    """Label points Structure (True) or Clutter (False) by their distance to the SE faces.

    Parameters
    ----------
    points : (n, 3) float or PointIndex
        Measured world points, or an index of them (the same labels, faster over many points).
    se_faces : sequence of WallFace
        The wall faces classified SE.
    floor_z, ceiling_z : float
        Heights of the RoI floor and ceiling (both SE by assumption).
    polygon : (k, 2) float
        The RoI polygon, counter-clockwise (orientation does not matter here).
    distance : float, keyword-only
        How close to an SE face a point must be, metres (>= 0).
    ceiling : bool, keyword-only
        Whether the ceiling is an SE face (False under the sky: :attr:`RoI.has_ceiling`).

    Returns
    -------
    (n,) bool
        True for a point with ``|w| <= distance`` from an SE wall face and ``-distance <= u <=
        length + distance``, ``-distance <= v <= height + distance``; or with ``|z - floor_z| <= distance``
        or ``|z - ceiling_z| <= distance`` and its xy inside the polygon grown by ``distance``.
    """
    index = points if isinstance(points, PointIndex) else None
    points = index.points if index is not None else np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {points.shape}")
    if not (math.isfinite(distance) and distance >= 0):
        raise ValueError(f"distance must be a finite number >= 0 metres, got {distance!r}")
    polygon = np.asarray(polygon, dtype=float)
    if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3:
        raise ValueError(f"polygon must have shape (k, 2) with k >= 3, got {polygon.shape}")
    structure = np.zeros(len(points), dtype=bool)
    if len(points) == 0:
        return structure
    # One vectorised pass over the points per face: O(n) memory, and 10-20 faces cost 10-20 passes,
    # where an (n, faces) broadcast would allocate several (n, faces) arrays for nothing.
    # The rectangle kept reaches `distance` past the face's ends and sides: its corners lie
    # within distance·√2 of the face's bounding box.
    if index is not None:
        index.mark_near(se_faces, distance, structure)
    for face in se_faces if index is None else ():
        idx = _near(face, points, 1.5 * distance)
        u, v, w = face.local(points[idx]).T
        structure[idx] |= (
            (np.abs(w) <= distance)
            & (u >= -distance)
            & (u <= face.length + distance)
            & (v >= -distance)
            & (v <= face.height + distance)
        )
    z = points[:, 2]
    horizontal = ~structure & ((np.abs(z - floor_z) <= distance) | (ceiling & (np.abs(z - ceiling_z) <= distance)))
    if horizontal.any():
        # Only the candidates at floor or ceiling height go through the polygon test, the costly part.
        grown = Polygon(polygon).buffer(distance)
        idx = np.flatnonzero(horizontal)
        structure[idx] = shapely.contains_xy(grown, points[idx, 0], points[idx, 1])
    return structure
