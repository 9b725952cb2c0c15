"""Evaluation against ground truth (METHOD §9): the coverage meter and its scan-quality figures.

With the scanner and the episode's report (:mod:`nbs_env.report`, ``metrics.json``, which reads
this meter and the true rooms of the scans), the only parts of ``nbs_env`` that read a scene's
labels, rooms and true poses: they score the robot, they never inform it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from scipy.spatial import cKDTree

from nbs_env import threads
from nbs_env.config import QualityConfig
from scenes import Scene, SurfaceClass
from scenes.interior import interior_samples
from scenes.limits import check_sample_count

__all__ = ["CoverageMeter", "QualityConfig", "QualityReport"]


@numba.njit(cache=True, nogil=True)
def _sense(
    points: np.ndarray,
    samples: np.ndarray,
    order: np.ndarray,
    starts: np.ndarray,
    lo: np.ndarray,
    cell: float,
    shape: np.ndarray,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples within ``radius`` of the (n, 3) points, and each point's nearest sample and its
    distance: :meth:`_SampleColumns.query` on the columns' sorted ``samples``."""
    count = len(order)
    near = np.zeros(count, dtype=np.bool_)
    nearest = np.full(len(points), count, dtype=np.int64)
    distance = np.full(len(points), np.inf)
    r2 = radius * radius
    for p in range(len(points)):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        x0 = max(int(np.floor((x - radius - lo[0]) / cell)), 0)
        x1 = min(int(np.floor((x + radius - lo[0]) / cell)), shape[0] - 1)
        y0 = max(int(np.floor((y - radius - lo[1]) / cell)), 0)
        y1 = min(int(np.floor((y + radius - lo[1]) / cell)), shape[1] - 1)
        best, which = np.inf, count
        for ix in range(x0, x1 + 1):
            for iy in range(y0, y1 + 1):
                a, b = starts[ix * shape[1] + iy], starts[ix * shape[1] + iy + 1]
                j = a + np.searchsorted(samples[a:b, 2], z - radius)
                while j < b and samples[j, 2] <= z + radius:
                    dx, dy, dz = samples[j, 0] - x, samples[j, 1] - y, samples[j, 2] - z
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 < r2:
                        s = order[j]
                        near[s] = True
                        if d2 < best or (d2 == best and s < which):
                            best, which = d2, s
                    j += 1
        if which < count:
            nearest[p] = which
            distance[p] = np.sqrt(best)
    return near, nearest, distance


class _SampleColumns:
    """The meter's samples sorted into plan columns of twice the sensing radius, by height within
    each: a point's samples within reach lie in the (at most 2 x 2) columns its reach overlaps, in
    one run of heights each. Built once per scene; a k-d tree queried with each scan's points did
    the same three times slower (benchmarks/README.md)."""

    def __init__(self, samples: np.ndarray, radius: float) -> None:
        self.radius = float(radius)
        self.cell = 2.0 * self.radius
        self.lo = samples[:, :2].min(axis=0) - self.cell
        cells = np.floor((samples[:, :2] - self.lo) / self.cell).astype(np.int64)
        self.shape = cells.max(axis=0) + 2
        column = cells[:, 0] * self.shape[1] + cells[:, 1]
        self.order = np.lexsort((samples[:, 2], column))
        self.samples = np.ascontiguousarray(samples[self.order], dtype=float)
        counts = np.bincount(column, minlength=int(np.prod(self.shape)))
        self.starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(samples within ``radius`` of a point, each point's nearest sample (the sample count
        where none is within reach), its distance (inf where none))."""
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)

        def rows(part: slice):
            some = np.ascontiguousarray(points[part])
            return _sense(some, self.samples, self.order, self.starts, self.lo, self.cell, self.shape, self.radius)

        # Each point reads the samples of up to four columns within its reach: tens of steps.
        parts = threads.split(rows, len(points), cost=30 * len(points))
        if len(parts) == 1:
            return parts[0]
        near = np.logical_or.reduce([p[0] for p in parts])
        nearest = np.empty(len(points), dtype=np.int64)
        distance = np.empty(len(points))
        for k, (_, which, dist) in enumerate(parts):
            nearest[k :: len(parts)] = which
            distance[k :: len(parts)] = dist
        return near, nearest, distance


@dataclass(frozen=True)
class QualityReport:
    """What :meth:`CoverageMeter.quality` measured.

    Attributes
    ----------
    density : (n,) float
        Points per m² around each sample, over all scans (``QualityConfig.density_radius``), at the
        instrument's density (the meter's ``density_weight``).
    incidence : (n,) float
        The smallest incidence angle (degrees from the normal) each sample was seen at; NaN when no
        point was attributed to it.
    range : (n,) float
        The shortest range (metres) each sample was seen from; NaN when never.
    dense_pct, incidence_pct, quality_pct : (k,) float
        After each of the ``k`` scans: % of the structural samples with density >= ``min_density``,
        seen at <= ``max_incidence``, and both.
    """

    density: np.ndarray
    incidence: np.ndarray
    range: np.ndarray
    dense_pct: np.ndarray
    incidence_pct: np.ndarray
    quality_pct: np.ndarray


class CoverageMeter:
    """Share of the true structural surface sensed, overall and per room, and how well.

    A ground-truth sample (one per ``spacing``² of floor, ceiling and wall) counts as sensed when a
    registered point lies within ``radius`` of it. The denominator is always the full surface.

    Given the scan's origin, :meth:`add` also attributes every point to its nearest sample within
    ``radius`` and notes, per sample, how many points it got and the incidence angle and range it
    was seen at: the scan-quality figures of :meth:`quality`.

    Parameters
    ----------
    scene : Scene
        The true building.
    spacing : float
        Sample spacing in metres (0.05: one sample per 25 cm²).
    radius : float
        Sensing radius in metres.
    interior_only : bool
        Count only the SE surface that faces the building's interior, decided by geometry
        (:func:`scenes.interior.interior_samples`): never the far sides of walls or the undersides
        of slabs, and the same whether or not the file names its rooms.
    density_weight : float
        Instrument points each added point stands for in the density (:meth:`quality`): a scanner
        preset's ``(simulated step / instrument step)²``
        (:attr:`~nbs_env.config.ScannerConfig.density_weight`), so that the density is the real
        instrument's. Coverage, incidence and range do not depend on it.
    density_radius : float, optional
        The ``quality.density_radius`` :meth:`quality` will be asked for: its neighbourhoods' memory
        is checked now, before any scan (:func:`scenes.limits.check_sample_count`), rather
        than found missing at the run's end.

    Raises
    ------
    scenes.StoreySizeError
        With ``density_radius``: the neighbourhoods would not fit in the memory left.
    """

    def __init__(
        self,
        scene: Scene,
        spacing: float = 0.05,
        radius: float = 0.05,
        interior_only: bool = True,
        density_weight: float = 1.0,
        density_radius: float | None = None,
    ) -> None:
        if not (np.isfinite(density_weight) and density_weight > 0):
            raise ValueError(f"density_weight must be a finite number > 0, got {density_weight}")
        self.density_weight = float(density_weight)
        if density_radius is not None:  # the quality's neighbourhoods, asked for at the run's end, too
            area = float(np.asarray(scene.face_areas)[scene.structural_mask()].sum())
            check_sample_count(scene.name, area, spacing, density_radius)
        self.samples = interior_samples(scene, spacing) if interior_only else scene.structure_samples(spacing)
        self.spacing = float(spacing)
        self.radius = radius
        self.sensed = np.zeros(len(self.samples), dtype=bool)
        self.room_ids = sorted({int(r) for r in self.samples.rooms})
        self.normals = np.asarray(scene.mesh.face_normals, dtype=float)[self.samples.faces].reshape(-1, 3)
        # Per scan: (sample indices, points attributed (times density_weight), incidence degrees, range m,
        # samples newly sensed).
        self.observations: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._tree: cKDTree | None = None
        self._columns: _SampleColumns | None = None
        self._neighbours: tuple[float, tuple[Any, np.ndarray]] | None = None
        self._quality: tuple[tuple[QualityConfig, int], QualityReport] | None = None

    def add(self, points: np.ndarray, origin: np.ndarray | None = None) -> int:
        """Mark the samples the (n, 3) registered points sense; returns how many were newly sensed.

        ``origin`` (3,): where the scan was taken from; when given, the scan's quality figures are
        noted too (:meth:`quality`)."""
        points = np.asarray(points, dtype=float)
        near, nearest, distance = self._query(points)
        hit = np.flatnonzero(near & ~self.sensed)
        self.sensed[hit] = True
        if origin is not None:
            self._observe(np.asarray(origin, dtype=float).reshape(3), nearest[np.isfinite(distance)], hit)
        return len(hit)

    def _sample_tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.samples.points)
        return self._tree

    def _query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n_samples,) bool: the samples within ``radius`` of some point; and per point its nearest
        sample and the distance to it (``inf`` where none is within ``radius``)."""
        n = len(self.samples)
        if not len(points) or not n:
            return np.zeros(n, dtype=bool), np.full(len(points), n, dtype=np.int64), np.full(len(points), np.inf)
        if self._columns is None:
            self._columns = _SampleColumns(self.samples.points, self.radius)
        return self._columns.query(points)

    def _observe(self, origin: np.ndarray, nearest: np.ndarray, newly: np.ndarray) -> None:
        """Note one scan's quality figures; ``nearest`` holds each attributed point's sample."""
        count = np.bincount(nearest, minlength=len(self.samples))
        index = np.flatnonzero(count)
        count = count[index] * self.density_weight
        ray = origin - self.samples.points[index]
        rng = np.linalg.norm(ray, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", ray, self.normals[index])) / np.maximum(rng, 1e-9)
        incidence = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
        self.observations.append(
            (
                index.astype(np.int32),
                count.astype(np.float32),
                incidence.astype(np.float32),
                rng.astype(np.float32),
                newly.astype(np.int32),
            )
        )

    def _neighbourhoods(self, radius: float) -> tuple[Any, np.ndarray]:
        """The (n, n) sparse 0/1 matrix of samples within ``radius`` of each other (self included),
        and each sample's count of them; built once per meter."""
        from scipy.sparse import csr_matrix, identity

        if self._neighbours is None or self._neighbours[0] != radius:
            n = len(self.samples)
            pairs = self._sample_tree().query_pairs(radius, output_type="ndarray")
            rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
            cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
            near = csr_matrix((np.ones(len(rows), dtype=np.float32), (rows, cols)), shape=(n, n))
            near = (near + identity(n, dtype=np.float32, format="csr")).tocsr()
            self._neighbours = (radius, (near, np.asarray(near.sum(axis=1)).ravel()))
        return self._neighbours[1]

    def quality(self, config: QualityConfig | None = None) -> QualityReport:
        """The scan-quality figures of the scans added with their origin (:class:`QualityReport`).

        Every point is attributed to its nearest sample within ``radius``. A sample's density is the
        points attributed around it (``config.density_radius``), over all scans. Its incidence and
        range are the smallest of the samples around it that a scan's points were attributed to, so
        that a sample between the points of a sparse pattern, sensed but attributed none, takes its
        neighbours' angle. Only sensed samples (:meth:`percent`) count, so the shares never exceed
        the coverage; like it, they are shares of all samples.
        """
        config = config or QualityConfig()
        # metrics.json and the report's samples.npz both ask at the run's end: computed once.
        key = (config, len(self.observations))
        if self._quality is not None and self._quality[0] == key:
            return self._quality[1]
        n = len(self.samples)
        near, size = self._neighbourhoods(config.density_radius)
        counts = np.zeros(n)
        seen = np.full(n, np.inf, dtype=np.float32)
        closest = np.full(n, np.inf, dtype=np.float32)
        sensed = np.zeros(n, dtype=bool)
        area = size * self.spacing**2
        curves = np.zeros((len(self.observations), 3))
        density, incidence, rng = np.zeros(n), np.full(n, np.inf), np.full(n, np.inf)
        for k, (index, count, angle, distance, newly) in enumerate(self.observations):
            counts[index] += count
            np.minimum.at(seen, index, angle)
            np.minimum.at(closest, index, distance)
            sensed[newly] = True
            if not n:
                continue
            density = np.where(sensed, near @ counts / area, 0.0)
            incidence = np.where(sensed, _neighbourhood_min(near, seen), np.inf)
            dense = density >= max(config.min_density, 1e-12)
            square = incidence <= config.max_incidence
            curves[k] = [dense.mean(), square.mean(), (dense & square).mean()]
        if n:
            rng = np.where(sensed, _neighbourhood_min(near, closest), np.inf)
        incidence = np.where(np.isfinite(incidence), incidence, np.nan)
        rng = np.where(np.isfinite(rng), rng, np.nan)
        report = QualityReport(density, incidence, rng, *(100.0 * curves.T))
        self._quality = (key, report)
        return report

    def percent(self, room: int | None = None, label: SurfaceClass | None = None) -> float:
        """Sensed share in % of all samples, of one room's, and/or of one class's."""
        mask = self._mask(room, label)
        total = int(mask.sum())
        return 100.0 * float(self.sensed[mask].sum()) / total if total else 0.0

    def _mask(self, room: int | None = None, label: SurfaceClass | None = None) -> np.ndarray:
        mask = np.ones(len(self.samples), dtype=bool)
        if room is not None:
            mask &= self.samples.rooms == room
        if label is not None:
            mask &= self.samples.labels == label
        return mask


def _neighbourhood_min(near: Any, values: np.ndarray) -> np.ndarray:
    """(n,) float: the smallest of ``values`` over each row's neighbours of the sparse matrix ``near``
    (every row holds at least its own sample)."""
    return np.minimum.reduceat(values[near.indices], near.indptr[:-1]).astype(float)
