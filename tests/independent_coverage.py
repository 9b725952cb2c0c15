"""An independent count of structural coverage: code that imports nothing of nbs-env.

The project's coverage (:class:`nbs_env.evaluation.CoverageMeter`) is the share of the storey's
interior structural samples that some measured point lies within 5 cm of, the interior decided by
probes beside each face (:func:`scenes.interior.interior_samples`). This module counts the same
quantity another way, from a labelled triangle mesh and a point cloud alone, so that a figure the
project prints can be checked against it:

1. **Samples.** Structural faces (floor, ceiling, wall) are sampled uniformly by area, one random
   point per ``spacing``² on average (not the project's per-face lattice).
2. **Inside.** A sample counts only when a point ``PROBE`` off its face, on one side, lies in free
   space (floor, ceiling and wall faces at least ``MIN_SPAN`` apart along x, y and z: not inside
   a wall or a slab), is
   enclosed (something above; of eight horizontal rays at most two escape; a model with no
   ceiling faces is open at the top, and every side counts), and has a floor of the storey as the
   first floor, ceiling or wall face straight below (within ``LEVEL_SPAN`` of the lowest floor a
   free position stands on): not a porch's floor or a facade, not the storey above seen through a
   stair opening, not the void over a suspended ceiling.
3. **Visible.** A sample counts when a straight line from some free position reaches it unblocked:
   positions are a lattice over every floor face a ray dropped through the model lands on, at three
   heights, kept where a vertical ray meets a ceiling above and the floor below, no face lies
   nearer than ``CLEARANCE`` horizontally (a scanner stands on a body), the position is enclosed as above (not
   on a porch), and its floor is within ``LEVEL_SPAN`` of the lowest one. The top of a suspended
   ceiling, a wall's cavity or the slab above a covering are seen from no such position.
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
#: Metres: the least horizontal distance from a free position to any face.
CLEARANCE = 0.25
#: Metres off a face where its two sides are judged inside or out.
PROBE = 0.1
#: Metres: floors this far above the storey's lowest one (a split level) are still its own.
LEVEL_SPAN = 1.95


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
    """Whether faces close a point in: something above it, and of eight horizontal directions at
    most two escape (two open doors in line). A porch, a balcony or a carport under a roof is open.
    A model with no ceiling faces (``roofed`` false) is cut open at the top: every point is in."""
    if not roofed:
        return np.ones(len(points), dtype=bool)
    if not len(points):
        return np.zeros(0, dtype=bool)
    covered = np.isfinite(_cast(scene, points, (0.0, 0.0, 1.0))[0])
    escapes = np.zeros(len(points), dtype=np.int64)
    for angle in np.arange(8) * np.pi / 4:
        escapes += ~np.isfinite(_cast(scene, points, (np.cos(angle), np.sin(angle), 0.0))[0])
    return covered & (escapes <= 2)


def _free_positions(scene, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, lattice: float) -> np.ndarray:
    """Lattice points over the upward floor faces, 0.5, 1.2 and 1.8 m up, inside the storey."""
    o3d = _open3d()
    tri = vertices[faces[labels == FLOOR]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    up = tri[normal[:, 2] > 1e-12]
    if not len(up):
        return np.zeros((0, 3))
    lo = np.floor(up[..., :2].reshape(-1, 2).min(axis=0) / lattice) * lattice
    hi = up[..., :2].reshape(-1, 2).max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], lattice) + lattice / 2, np.arange(lo[1], hi[1], lattice) + lattice / 2)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    top = float(vertices[:, 2].max()) + 1.0
    # Drop a ray from above the model at each lattice point and walk down through roofs and slabs,
    # keeping every FLOOR face it lands on: each is a floor a place may stand over.
    start = np.column_stack([xy, np.full(len(xy), top), np.zeros((len(xy), 2)), -np.ones(len(xy))])
    landings = []
    going = np.ones(len(xy), dtype=bool)
    for _ in range(24):
        if not going.any():
            break
        hits = scene.cast_rays(o3d.core.Tensor(start.astype(np.float32)))
        t, ids = hits["t_hit"].numpy(), hits["primitive_ids"].numpy()
        going &= np.isfinite(t)
        land = start[:, 2] - np.where(going, t, 0.0)
        floor = going & (labels[np.where(going, ids, 0)] == FLOOR)
        landings.append(np.column_stack([xy[floor], land[floor]]))
        start[:, 2] = np.where(going, land - 1e-3, start[:, 2])
    found = np.concatenate(landings) if landings else np.zeros((0, 3))
    xy, z = found[:, :2], found[:, 2]
    out = []
    for height in (0.5, 1.2, 1.8):
        p = np.column_stack([xy, z + height])
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
        # A scanner stands on a body: no face nearer than CLEARANCE in sixteen horizontal directions
        # (not inside a wall, not in the slot behind a wardrobe).
        open_ = np.ones(len(p), dtype=bool)
        for angle in np.arange(16) * np.pi / 8:
            open_ &= _cast(scene, p, (np.cos(angle), np.sin(angle), 0.0))[0] >= CLEARANCE
        keep = above & below & open_
        keep[keep] = _enclosed(scene, p[keep], roofed=bool(np.any(labels == CEILING)))
        out.append(p[keep])
    positions = np.concatenate(out) if out else np.zeros((0, 3))
    if len(positions):
        # The storey is its lowest floor and the levels up to LEVEL_SPAN above it; higher floors
        # (the storey above, seen up a stair) are not its free space.
        ground = positions[:, 2] - _cast(scene, positions, (0.0, 0.0, -1.0))[0]
        positions = positions[ground <= ground.min() + LEVEL_SPAN]
    return positions


def _spans(scene, points: np.ndarray) -> np.ndarray:
    """The least free span through each point along x, y and z: the distance between the faces met
    either way (inside a wall or a slab it is the solid's thickness)."""
    least = np.full(len(points), np.inf)
    for axis in np.eye(3):
        t = _cast(scene, points, axis)[0] + _cast(scene, points, -axis)[0]
        least = np.minimum(least, t)
    return least


def _floor_below(scene, labels: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Height of the first floor, ceiling or wall face straight down from each point when it is a
    FLOOR face (furniture is looked through); NaN otherwise."""
    o3d = _open3d()
    z = np.full(len(points), np.nan)
    rays = np.column_stack([points, np.zeros((len(points), 2)), -np.ones(len(points))]).astype(np.float32)
    going = np.ones(len(points), dtype=bool)
    for _ in range(12):
        if not going.any():
            break
        hits = scene.cast_rays(o3d.core.Tensor(rays))
        t, ids = hits["t_hit"].numpy(), hits["primitive_ids"].numpy()
        going &= np.isfinite(t)
        label = labels[np.where(going, ids, 0)]
        land = rays[:, 2] - np.where(going, t, 0.0)
        structure = going & np.isin(label, (FLOOR, CEILING, WALL))
        z[structure & (label == FLOOR)] = land[structure & (label == FLOOR)]
        going &= ~structure
        rays[:, 2] = np.where(going, land - 1e-3, rays[:, 2])
    return z


def visible_structure(
    vertices: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    *,
    spacing: float = 0.05,
    lattice: float = 0.5,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The storey's inside structural samples, which of them some free position sees, and the
    positions (module docstring, steps 1-3).

    Parameters
    ----------
    vertices : (V, 3) float
        The true storey's vertices, metres, z up.
    faces : (F, 3) int
    labels : (F,) int
        Class of each face: 0 floor, 1 ceiling, 2 wall; others are occluders only.
    spacing : float
        Sample spacing, metres.
    lattice : float
        Spacing of the free positions, metres.
    seed : int
        Seeds the random samples.

    Returns
    -------
    samples : (n, 3) float
    visible : (n,) bool
    positions : (m, 3) float
    """
    o3d = _open3d()

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    labels = np.asarray(labels).astype(np.int64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))
    # Walls and slabs alone: a probe is inside a solid when these close it in (a wardrobe's top
    # 0.3 m under the ceiling does not).
    solids = o3d.t.geometry.RaycastingScene()
    structural = faces[np.isin(labels, (FLOOR, CEILING, WALL))]
    solids.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(structural.astype(np.uint32)))
    rng = np.random.default_rng(seed)
    samples, normals = _sample_faces(vertices[faces[np.isin(labels, (FLOOR, CEILING, WALL))]], spacing, rng)
    positions = _free_positions(scene, vertices, faces, labels, lattice)
    # The storey's own structure: a sample counts when, on one side of its face, the point PROBE off
    # it lies in free space (not inside a wall or slab), closed in (not a porch seen through the
    # front door), and over a floor of the storey (not the storey above, seen up a stair; not the
    # void over a suspended ceiling, whose first face below is the ceiling).
    roofed = bool(np.any(labels == CEILING))
    if len(positions):
        ground = positions[:, 2] - _cast(scene, positions, (0.0, 0.0, -1.0))[0]
        low, high = ground.min() - LEVEL_SPAN, ground.min() + LEVEL_SPAN
        sides = np.zeros(len(samples), dtype=bool)
        for sign in (1.0, -1.0):
            rest = np.flatnonzero(~sides)
            probe = samples[rest] + sign * PROBE * normals[rest]
            floor = _floor_below(scene, labels, probe)
            ok = (floor >= low) & (floor <= high)
            ok[ok] = _spans(solids, probe[ok]) >= MIN_SPAN
            ok[ok] = _enclosed(scene, probe[ok], roofed)
            sides[rest[ok]] = True
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
    return samples, visible, positions


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
    vertices, faces, labels, spacing, lattice, seed
        As :func:`visible_structure`.
    cloud : (N, 3) float
        The registered measured points, the storey's frame.
    radius : float
        Sensing radius, metres.
    """
    from scipy.spatial import cKDTree

    samples, visible, positions = visible_structure(
        vertices, faces, labels, spacing=spacing, lattice=lattice, seed=seed
    )
    sensed = np.zeros(len(samples), dtype=bool)
    if len(cloud) and visible.any():
        distance, _ = cKDTree(np.asarray(cloud, dtype=float)).query(samples[visible], distance_upper_bound=radius)
        sensed[np.flatnonzero(visible)[np.isfinite(distance)]] = True
    return IndependentCount(len(samples), int(visible.sum()), int(sensed.sum()), len(positions))
