"""An independent count of structural coverage: code that imports nothing of nbs-env.

The project's coverage (:class:`nbs_env.evaluation.CoverageMeter`) is the share of the storey's
interior structural samples that some measured point lies within 5 cm of, the interior decided by
probes beside each face (:func:`scenes.interior.interior_samples`). This module counts the same
quantity another way, from a labelled triangle mesh and a point cloud alone, so that a figure the
project prints can be checked against it:

1. **Samples.** Structural faces (floor, ceiling, wall) are sampled uniformly by area, one random
   point per ``spacing``² on average (not the project's per-face lattice).
2. **Inside.** A sample counts only when a point ``PROBE`` off its face, on one side, is enclosed
   (something above; of eight horizontal rays at most one escapes) and it lies no higher than the
   ceilings over the free positions (their 95th percentile): not a porch's floor or a facade, not the
   storey above seen through a stair opening.
3. **Visible.** A sample counts when a straight line from some free position reaches it unblocked:
   positions are a lattice over the upward floor faces at three heights, kept where a vertical ray
   meets a ceiling above and the floor below, faces lie at least ``MIN_SPAN`` apart along x and
   along y (not in a wall), and the position is enclosed as above (not on a porch). The top of a
   suspended ceiling, a wall's cavity or the slab above a covering are seen from no such position.
4. **Sensed.** A visible sample is sensed when a point of the cloud lies within ``radius`` of it.

Only numpy, scipy, open3d (and libusb-package, which open3d's library needs) are imported. The
class codes are written out (floor 0, ceiling 1, wall 2, as the scene files store them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FLOOR, CEILING, WALL = 0, 1, 2
#: Metres: a position between faces nearer than this along x or y is inside a wall, not free.
MIN_SPAN = 0.6
#: Metres off a face where its two sides are judged inside or out.
PROBE = 0.1


def _open3d():
    """open3d, with the libusb its shared library links against loaded first."""
    import ctypes

    try:
        import libusb_package

        path = libusb_package.get_library_path()
        if path is not None:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
    except (ImportError, OSError):
        pass
    import open3d

    return open3d


@dataclass(frozen=True)
class IndependentCount:
    """What :func:`count` found.

    Attributes
    ----------
    samples : int
        Structural samples drawn.
    visible : int
        Of them, seen from some free position.
    sensed : int
        Of the visible ones, within the radius of a cloud point.
    positions : int
        Free positions used for the visibility test.
    """

    samples: int
    visible: int
    sensed: int
    positions: int

    @property
    def percent(self) -> float:
        """Sensed visible samples, % of the visible ones."""
        return 100.0 * self.sensed / max(1, self.visible)


def _sample_faces(triangles: np.ndarray, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted random points on (n, 3, 3) triangles, about one per ``spacing``², and the unit
    normal of each point's triangle."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    cross = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    n = round(float(area.sum()) / spacing**2)
    if n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    face = rng.choice(len(triangles), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    points = a[face] + u[:, None] * (b - a)[face] + v[:, None] * (c - a)[face]
    return points, cross[face] / np.maximum(2.0 * area[face], 1e-12)[:, None]


def _cast(scene, origins: np.ndarray, direction) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the first face (inf: none) and its index, per ray from each origin."""
    o3d = _open3d()
    direction = np.broadcast_to(np.asarray(direction, dtype=float), origins.shape)
    hits = scene.cast_rays(o3d.core.Tensor(np.column_stack([origins, direction]).astype(np.float32)))
    return hits["t_hit"].numpy(), hits["primitive_ids"].numpy()


def _enclosed(scene, points: np.ndarray, roofed: bool = True) -> np.ndarray:
    """Whether faces close a point in: something above it (when the model has ceilings at all), and
    of eight horizontal directions at most one escapes (an open door). A porch, a balcony or a carport
    under a roof is open."""
    if not len(points):
        return np.zeros(0, dtype=bool)
    covered = np.isfinite(_cast(scene, points, (0.0, 0.0, 1.0))[0]) if roofed else np.ones(len(points), dtype=bool)
    escapes = np.zeros(len(points), dtype=np.int64)
    for angle in np.arange(8) * np.pi / 4:
        escapes += ~np.isfinite(_cast(scene, points, (np.cos(angle), np.sin(angle), 0.0))[0])
    return covered & (escapes <= 1)


def _free_positions(scene, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, lattice: float) -> np.ndarray:
    """Lattice points over the upward floor faces, 0.5, 1.2 and 1.8 m up, inside the storey."""
    o3d = _open3d()
    tri = vertices[faces[labels == FLOOR]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    up = tri[normal[:, 2] > 1e-12]
    if not len(up):
        return np.zeros((0, 3))
    lo, hi = up[..., :2].reshape(-1, 2).min(axis=0), up[..., :2].reshape(-1, 2).max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], lattice) + lattice / 2, np.arange(lo[1], hi[1], lattice) + lattice / 2)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    top = float(vertices[:, 2].max()) + 1.0
    # Drop a ray from above the model at each lattice point and walk down through roofs and slabs
    # to the first FLOOR face it lands on.
    start = np.column_stack([xy, np.full(len(xy), top), np.zeros((len(xy), 2)), -np.ones(len(xy))])
    z = np.full(len(xy), np.nan)
    going = np.ones(len(xy), dtype=bool)
    for _ in range(12):
        if not going.any():
            break
        hits = scene.cast_rays(o3d.core.Tensor(start.astype(np.float32)))
        t, ids = hits["t_hit"].numpy(), hits["primitive_ids"].numpy()
        going &= np.isfinite(t)
        land = start[:, 2] - np.where(going, t, 0.0)
        floor = going & (labels[np.where(going, ids, 0)] == FLOOR)
        z[floor] = land[floor]
        going &= ~floor
        start[:, 2] = np.where(going, land - 1e-3, start[:, 2])
    ok = np.isfinite(z)
    out = []
    for height in (0.5, 1.2, 1.8):
        p = np.column_stack([xy[ok], z[ok] + height])
        # Inside: straight up meets a ceiling face, straight down the floor it stands on.
        up_hits = scene.cast_rays(
            o3d.core.Tensor(np.column_stack([p, np.zeros((len(p), 2)), np.ones(len(p))]).astype(np.float32))
        )
        t_up, id_up = up_hits["t_hit"].numpy(), up_hits["primitive_ids"].numpy()
        above = np.isfinite(t_up) & (labels[np.where(np.isfinite(t_up), id_up, 0)] == CEILING)
        if not np.any(labels == CEILING):  # a model cut open at the top: the sky is allowed
            above = np.ones(len(p), dtype=bool)
        down = scene.cast_rays(
            o3d.core.Tensor(np.column_stack([p, np.zeros((len(p), 2)), -np.ones(len(p))]).astype(np.float32))
        )
        below = np.abs(down["t_hit"].numpy() - height) < 0.02
        # Not inside a wall: along x and along y the faces met either way lie MIN_SPAN apart or more.
        spans = []
        for axis in ((1.0, 0.0), (0.0, 1.0)):
            ways = [
                np.column_stack([p, np.tile([sign * axis[0], sign * axis[1], 0.0], (len(p), 1))]) for sign in (1, -1)
            ]
            t = [scene.cast_rays(o3d.core.Tensor(w.astype(np.float32)))["t_hit"].numpy() for w in ways]
            spans.append(t[0] + t[1])
        open_ = np.minimum(*spans) >= MIN_SPAN
        keep = above & below & open_
        keep[keep] = _enclosed(scene, p[keep], roofed=bool(np.any(labels == CEILING)))
        out.append(p[keep])
    return np.concatenate(out) if out else np.zeros((0, 3))


def count(
    vertices: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    cloud: np.ndarray,
    *,
    spacing: float = 0.05,
    radius: float = 0.05,
    lattice: float = 0.5,
    seed: int = 0,
) -> IndependentCount:
    """Count the visible structure and the share of it a cloud senses (module docstring).

    Parameters
    ----------
    vertices : (V, 3) float
        The true storey's vertices, metres, z up.
    faces : (F, 3) int
    labels : (F,) int
        Class of each face: 0 floor, 1 ceiling, 2 wall; others are occluders only.
    cloud : (N, 3) float
        The registered measured points, the storey's frame.
    spacing, radius : float
        Sample spacing and sensing radius, metres.
    lattice : float
        Spacing of the free positions, metres.
    seed : int
        Seeds the random samples.
    """
    from scipy.spatial import cKDTree

    o3d = _open3d()

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    labels = np.asarray(labels).astype(np.int64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))
    rng = np.random.default_rng(seed)
    samples, normals = _sample_faces(vertices[faces[np.isin(labels, (FLOOR, CEILING, WALL))]], spacing, rng)
    positions = _free_positions(scene, vertices, faces, labels, lattice)
    # The storey's own structure: below the ceilings over its free places (the 95th percentile, so
    # that what a stair opening shows of the storey above does not count), and on a side of its
    # face that lies inside (enclosed, not a porch seen through the front door).
    roofed = bool(np.any(labels == CEILING))
    if len(positions):
        t_up = _cast(scene, positions, (0.0, 0.0, 1.0))[0]
        top = float(np.percentile(positions[:, 2] + np.where(np.isfinite(t_up), t_up, 0.0), 95)) + 0.05
        top = top if roofed else np.inf
        inside = samples[:, 2] <= top
        sides = np.zeros(len(samples), dtype=bool)
        for sign in (1.0, -1.0):
            rest = np.flatnonzero(inside & ~sides)
            sides[rest] = _enclosed(scene, samples[rest] + sign * PROBE * normals[rest], roofed)
        samples = samples[sides]
    visible = np.zeros(len(samples), dtype=bool)
    for p in positions[rng.permutation(len(positions))]:
        todo = np.flatnonzero(~visible)
        if not len(todo):
            break
        offset = samples[todo] - p
        dist = np.linalg.norm(offset, axis=1)
        rays = np.column_stack([np.repeat(p[None], len(todo), axis=0), offset / np.maximum(dist, 1e-9)[:, None]])
        t = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        # The first surface the line meets is the sample's own (to float precision and 1 cm).
        visible[todo[t >= dist - 0.01]] = True
    sensed = np.zeros(len(samples), dtype=bool)
    if len(cloud) and visible.any():
        distance, _ = cKDTree(np.asarray(cloud, dtype=float)).query(samples[visible], distance_upper_bound=radius)
        sensed[np.flatnonzero(visible)[np.isfinite(distance)]] = True
    return IndependentCount(len(samples), int(visible.sum()), int(sensed.sum()), len(positions))
