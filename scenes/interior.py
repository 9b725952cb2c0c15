"""Inside from outside, by geometry: which structural surface faces the building's interior, and rooms
from the floor's free space for files that name none (METHOD §8-9).

Users' meshes and IFC files rarely carry room annotations, and their solids have faces nobody can see
from inside (the far sides of exterior walls, the undersides of slabs, the tops of walls under a
slab). The evaluation must count the same surface whether or not a file names its rooms, so nothing
here reads ``Scene.rooms`` or ``Scene.face_rooms``: only the mesh and its surface classes.

*Interior side.* A point ``p`` on a structural face with unit normal ``n`` faces the interior when,
on one of its two sides, the probe ``q = p ± INTERIOR_PROBE · n``

- stands above a floor of the storey: straight down from ``q`` the first structural surface is a
  FLOOR face, within :data:`LEVEL_SPAN` (and the floor band) of the storey's floor level (a split
  level counts; the storey above, seen up a stair, does not);
- stands under cover: straight up from ``q`` the first structural surface is not a FLOOR face (the
  storey's own slab seen from below or from inside), and there is one, unless the storey has no
  ceiling faces at all (a model cut open at the top), where the sky is allowed;
- is not enclosed in a wall: along none of four horizontal directions do the first structural faces
  met either way lie on two parallel planes less than :data:`MIN_SPAN` apart (inside a wall solid,
  a ray either way meets the wall's own two faces; in a room's corner they are two walls at an
  angle);
- is closed in: of :data:`ENCLOSURE_RAYS` horizontal rays at most :data:`MAX_ESCAPES` leave the
  model, faces of every class closing it (a porch, a balcony or a carport under a roof is open on
  more sides; a model with no ceiling faces is not tested).

Both sides are tried because files do not agree on normals: a single-quad wall has one normal for
two visible sides, and a solid's faces point out of the solid. A side counts only when the straight
way from ``p`` to its probe crosses no structural face: the top of a suspended ceiling (an
``IfcCovering`` a few centimetres thick) does not count by the room under it.

*Visible.* Of the interior side, what counts is what some place of the storey's free space sees: a
straight line from one of the :func:`free_positions` (a :data:`VIEW_LATTICE` lattice over the
free floor of every level of the storey at :data:`VIEW_HEIGHTS`, under a ceiling and over the floor
with nothing between, closed in as above)
reaches the point before any face, furniture included. A point is tried from the positions within
:data:`VIEW_RING` lattice cells of its own, then from every position of a lattice three times coarser
(the full lattice costs minutes on a large storey; on ``five_rooms`` the two leave out 7.3% of
the interior structure where the full lattice leaves out 6.9%: surface seen only along a grazing
line from a few far places). The floor under a low cabinet, the wall
behind a wardrobe standing against it, and a wall's face inside a closed cupboard are seen from no
such place and do not count: no robot, and no plan of scans, could sense them.

*Derived rooms.* The indoor floor (FLOOR faces within :data:`FLOOR_BAND` of the storey's floor level,
the height holding most upward-facing floor area, under a CEILING face when the storey has any) minus the plan
footprint of walls, doors and windows (furniture does not split a room) is the free space. Eroded
by :data:`ROOM_NECK`, it falls apart at door openings narrower than twice that; each piece of at
least :data:`MIN_ROOM_AREA` seeds a room, which takes back the free space within ``ROOM_NECK`` of
it; what is left (door passages, niches) joins the room it borders most. Rooms are numbered by
decreasing area and named ``space 1``, ``space 2``, ...
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

from scenes.labels import STRUCTURAL_CLASSES, SurfaceClass

#: Metres between the free positions :func:`visible_mask` looks from, in plan.
VIEW_LATTICE = 0.5
#: A point is tried first from the free positions of its lattice cell and of the cells this many
#: rings around it.
VIEW_RING = 2
_KEY = 1 << 32
#: Their heights above the floor, metres: low enough to see under a table, high enough to see over
#: a sideboard.
VIEW_HEIGHTS = (0.5, 1.2, 1.8)
#: Least horizontal distance (m) from a free position to any face: a scanner stands on a body (the
#: robot's radius), not in a wall and not in the slot behind a wardrobe.
VIEW_CLEARANCE = 0.25

if TYPE_CHECKING:
    from scenes.model import Room, Scene, StructureSamples

__all__ = [
    "ENCLOSURE_RAYS",
    "INTERIOR_PROBE",
    "LEVEL_SPAN",
    "MAX_ESCAPES",
    "MIN_ROOM_AREA",
    "MIN_SPAN",
    "ROOM_NECK",
    "VIEW_CLEARANCE",
    "VIEW_HEIGHTS",
    "VIEW_LATTICE",
    "VIEW_RING",
    "derive_rooms",
    "escapes",
    "floor_levels",
    "free_positions",
    "horizontal_hits",
    "indoor_floor",
    "interior_area",
    "interior_mask",
    "interior_samples",
    "rooms_by_probe",
    "separating_footprint",
    "visible_mask",
    "with_derived_rooms",
]

#: How far (m) in front of a surface point the interior tests are made.
INTERIOR_PROBE = 0.1
#: Free span (m) a probe needs across every horizontal direction; inside a wall it is the wall's
#: thickness (walls up to half a metre thick are told from space this way).
MIN_SPAN = 0.55
#: Erosion radius (m) that separates rooms at their doors: openings narrower than twice this close.
ROOM_NECK = 0.5
#: Least eroded area (m²) that makes a room of its own rather than a niche of its neighbour.
MIN_ROOM_AREA = 1.0
#: Floor faces within this height (m) of the storey's floor level belong to its floor.
FLOOR_BAND = 0.35
#: How far (m) a probe looks down for its floor.
MAX_DROP = 8.0
#: Horizontal directions along which a place is tested for being closed in, and how many of them
#: may leave the model for the place to be inside (two open doors in line, a door and a window
#: without a pane): a porch, a balcony, a loggia or a carport is open on more sides than that. A
#: model with no ceiling faces at all (cut open at the top) gets no such test: nothing tells its
#: roofed porch from its rooms.
ENCLOSURE_RAYS = 8
MAX_ESCAPES = 2
#: Floor levels other than the storey's own (a split level, a raised dais) belong to its free space
#: when they lie within this height (m) of it; floors higher up are the storey above.
LEVEL_SPAN = 1.6
#: Rays leave a surface this far (m) off it, so as not to hit the face they start on.
_SURFACE_EPS = 1e-3

_HORIZONTAL = np.array([[np.cos(a), np.sin(a), 0.0] for a in np.deg2rad([0.0, 45.0, 90.0, 135.0])])


class _Caster:
    """First structural hits of rays (open3d Embree), with the surface class of the face hit."""

    def __init__(self, scene: Scene) -> None:
        from scenes._open3d import open3d

        o3d = open3d()
        self._o3d = o3d
        vertices = o3d.core.Tensor.from_numpy(np.ascontiguousarray(scene.mesh.vertices, dtype=np.float32))

        def raycaster(faces: np.ndarray):
            caster = o3d.t.geometry.RaycastingScene()
            tri = np.ascontiguousarray(scene.mesh.faces[faces], dtype=np.uint32)
            caster.add_triangles(vertices, o3d.core.Tensor.from_numpy(tri))
            return caster

        faces = np.flatnonzero(np.isin(scene.face_labels, [c.value for c in STRUCTURAL_CLASSES]))
        self.labels = scene.face_labels[faces]
        self._scene = raycaster(faces)
        # Floors alone: a wall standing on a slab ties with the slab's top, and either may win.
        self._floors = raycaster(np.flatnonzero(scene.face_labels == SurfaceClass.FLOOR))
        self.has_ceiling = bool(np.any(self.labels == SurfaceClass.CEILING))
        floors = scene.mesh.vertices[scene.mesh.faces[scene.face_labels == SurfaceClass.FLOOR]]
        self.floor_z = floor_level(floors) if len(floors) else 0.0
        self._all = None
        self._every = scene

    def escapes(self, origins: np.ndarray) -> np.ndarray:
        """Of :data:`ENCLOSURE_RAYS` horizontal rays from each origin, how many meet no face at all
        (every face: a door leaf, a window pane and furniture close a room as well as a wall)."""
        if self._all is None:
            self._all = _all_faces(self._every)
        return escapes(self._all, origins)

    def cast(
        self, origins: np.ndarray, direction: np.ndarray, floors_only: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per ray from each origin: distance to the first hit (inf: none), its class (255: none) and
        the unit normal of the face hit."""
        n = len(origins)
        rays = np.empty((n, 6), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = direction
        out = (self._floors if floors_only else self._scene).cast_rays(self._o3d.core.Tensor.from_numpy(rays))
        t = out["t_hit"].numpy().astype(float)
        ids = out["primitive_ids"].numpy()
        hit = np.isfinite(t)
        labels = np.full(n, 255, dtype=np.uint8)
        labels[hit] = SurfaceClass.FLOOR if floors_only else self.labels[ids[hit]]
        return t, labels, out["primitive_normals"].numpy().astype(float)


def _probe_is_inside(caster: _Caster, q: np.ndarray) -> np.ndarray:
    t_down, below, _ = caster.cast(q, np.array([0.0, 0.0, -1.0]))
    # Over a floor of the storey: its own level or one within LEVEL_SPAN of it, not the storey
    # above seen up a stair.
    level = np.abs(q[:, 2] - np.where(np.isfinite(t_down), t_down, 0.0) - caster.floor_z) <= LEVEL_SPAN + FLOOR_BAND
    ok = (below == SurfaceClass.FLOOR) & (t_down <= MAX_DROP) & level
    todo = np.flatnonzero(ok)  # the rays up only for probes above a floor
    if len(todo):
        up = np.array([0.0, 0.0, 1.0])
        t_up, _, _ = caster.cast(q[todo], up)
        t_floor, _, _ = caster.cast(q[todo], up, floors_only=True)
        under_floor = np.isfinite(t_floor) & (t_floor <= t_up + 1e-3)  # inside or under the storey's own slab
        ok[todo] = ~under_floor & (np.isfinite(t_up) if caster.has_ceiling else True)
        todo = np.flatnonzero(ok)
    for d in _HORIZONTAL:
        if not len(todo):
            break
        t_f, _, n_f = caster.cast(q[todo], d)
        across = n_f[:, :2] @ d[:2]
        # Inside a wall, both rays meet the wall's own two faces: parallel planes, close together.
        # In a room's corner the two faces met are different walls at an angle, which is no wall.
        # The gap is (t_f + t_b)·|across| >= t_f·|across|: a probe whose forward hit alone is that
        # far off is not enclosed, and casts no backward ray (most probes: floors and ceilings).
        hit = np.isfinite(t_f)
        reach = np.abs(np.where(hit, t_f, 0.0) * across)
        near = np.flatnonzero(hit & (np.abs(n_f[:, 2]) < 0.3) & (reach < MIN_SPAN))
        enclosed = np.zeros(len(todo), dtype=bool)
        if len(near):
            t_b, _, n_b = caster.cast(q[todo[near]], -d)
            parallel = np.abs(np.einsum("ij,ij->i", n_f[near], n_b)) > 0.95
            gap = np.abs((t_f[near] + t_b) * across[near])
            enclosed[near] = np.isfinite(t_b) & (np.abs(n_b[:, 2]) < 0.3) & parallel & (gap < MIN_SPAN)
        ok[todo[enclosed]] = False
        todo = todo[~enclosed]
    if len(todo) and caster.has_ceiling:  # a porch, a balcony or a carport under a roof is open to the sides
        ok[todo[caster.escapes(q[todo]) > MAX_ESCAPES]] = False
    return ok


def horizontal_hits(caster, origins: np.ndarray) -> np.ndarray:
    """Distance to the first face (inf: none) along each of :data:`ENCLOSURE_RAYS` horizontal
    directions from each (n, 3) origin (an open3d ray caster of every face): (n, ENCLOSURE_RAYS)."""
    from scenes._open3d import open3d

    o3d = open3d()
    origins = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
    out = np.empty((len(origins), ENCLOSURE_RAYS))
    rays = np.empty((len(origins), 6), dtype=np.float32)
    rays[:, :3] = origins
    for k, angle in enumerate(np.arange(ENCLOSURE_RAYS) * (2.0 * np.pi / ENCLOSURE_RAYS)):
        rays[:, 3:] = (np.cos(angle), np.sin(angle), 0.0)
        out[:, k] = caster.cast_rays(o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy()
    return out


def escapes(caster, origins: np.ndarray) -> np.ndarray:
    """Of :data:`ENCLOSURE_RAYS` horizontal rays from each (n, 3) origin, how many leave the model
    (an open3d ray caster of every face): (n,) int."""
    return np.count_nonzero(~np.isfinite(horizontal_hits(caster, origins)), axis=1)


def interior_mask(scene: Scene, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Which surface points face the building's interior (module docstring).

    Parameters
    ----------
    scene : Scene
        The true building (its mesh and surface classes only).
    points : (n, 3) float
        Points on structural faces.
    normals : (n, 3) float
        The unit normals of their faces (either orientation).

    Returns
    -------
    (n,) bool
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    if len(points) != len(normals):
        raise ValueError(f"{len(points)} points but {len(normals)} normals")
    if not len(points):
        return np.zeros(0, dtype=bool)
    caster = _Caster(scene)
    inside = np.zeros(len(points), dtype=bool)
    for side in (1.0, -1.0):
        rest = np.flatnonzero(~inside)
        if not len(rest):
            break
        # A probe stands in the space the point faces only if nothing lies between them: a covering
        # or a wall leaf thinner than the probe would put the far side's probe through it (the top
        # of a suspended ceiling would then count by the room under it).
        away = side * normals[rest]
        t, _, _ = caster.cast(points[rest] + _SURFACE_EPS * away, away)
        open_side = rest[t >= INTERIOR_PROBE - _SURFACE_EPS]
        if len(open_side):
            probes = points[open_side] + side * INTERIOR_PROBE * normals[open_side]
            inside[open_side] = _probe_is_inside(caster, probes)
    return inside


#: Which samples count, by the mesh and labels they were computed for: the same building loaded again
#: (each ``load_scene`` hands out a copy; a test builds the same storey many times) is not looked at
#: again. The masks depend on geometry alone; a few storeys are kept.
_KEPT: dict[tuple[bytes, float], np.ndarray] = {}
_KEPT_SIZE = 8


def _fingerprint(scene: Scene) -> bytes:
    import hashlib

    digest = hashlib.blake2b(digest_size=16)
    for array in (scene.mesh.vertices, scene.mesh.faces, scene.face_labels):
        a = np.ascontiguousarray(array)
        digest.update(str((a.dtype, a.shape)).encode())
        digest.update(a.tobytes())
    return digest.digest()


def interior_samples(scene: Scene, spacing: float = 0.05) -> StructureSamples:
    """The samples of :meth:`Scene.structure_samples` that face the building's interior
    (:func:`interior_mask`) and that a place of its free space sees (:func:`visible_mask`): what the
    evaluation counts, the same whether or not the file names its
    rooms. Computed once per scene and spacing.

    With rooms derived from geometry (``metadata["rooms"] == "derived"``) each sample takes the room
    of its own probe (:func:`rooms_by_probe`), as one large triangle of a file may lie under several.
    """
    from scenes.model import StructureSamples

    cache = scene.__dict__.setdefault("_samples", {})
    key = ("interior", float(spacing))
    if key not in cache:
        every = scene.structure_samples(spacing)
        normals = scene.mesh.face_normals[every.faces]
        geometry = (_fingerprint(scene), float(spacing))
        keep = _KEPT.pop(geometry, None)
        if keep is None:
            keep = interior_mask(scene, every.points, normals)
            keep[keep] = visible_mask(scene, every.points[keep])
        _KEPT[geometry] = keep  # the most recent last
        while len(_KEPT) > _KEPT_SIZE:
            _KEPT.pop(next(iter(_KEPT)))
        rooms = every.rooms[keep]
        if scene.metadata.get("rooms") == "derived":
            rooms = rooms_by_probe(list(scene.rooms), every.points[keep], normals[keep])
        cache[key] = StructureSamples(every.points[keep], every.labels[keep], rooms, every.faces[keep])
    return cache[key]


def floor_levels(scene: Scene) -> list[tuple[Polygon | MultiPolygon, float]]:
    """The free floor of every level of the storey, and its height.

    The storey's own level (:func:`indoor_floor`) first; then each other band of upward FLOOR faces
    within :data:`LEVEL_SPAN` of it (a split level up a few steps, a sunken living room), under a
    CEILING face when the storey has any, minus the walls, doors and windows at its height. A band of
    less than :data:`MIN_ROOM_AREA` (a stair's tread) is no level.

    Returns
    -------
    list of (shapely geometry, float)
        Empty when the storey has no floor.
    """
    main, floor_z = indoor_floor(scene)
    if main.is_empty:
        return []
    levels = [(main, floor_z)]
    tri = scene.mesh.vertices[scene.mesh.faces[scene.face_labels == SurfaceClass.FLOOR]]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    z = tri[..., 2]
    own = (z.min(axis=1) > floor_z - FLOOR_BAND) & (z.max(axis=1) < floor_z + FLOOR_BAND)
    height = z.mean(axis=1)
    rest = (cross[:, 2] > 0.5 * np.linalg.norm(cross, axis=1)) & ~own & (np.abs(height - floor_z) <= LEVEL_SPAN)
    if not rest.any():
        return levels
    ceiling_tri = scene.mesh.vertices[scene.mesh.faces[scene.face_labels == SurfaceClass.CEILING]]
    ceiling = _union_xy(ceiling_tri) if len(ceiling_tri) else None
    while rest.any():
        level = floor_level(tri[rest])
        band = rest & (np.abs(height - level) < FLOOR_BAND)
        rest &= ~band
        region = _union_xy(tri[band])
        if ceiling is not None:
            region = region.intersection(ceiling)
        walls = separating_footprint(scene, level)
        region = region.difference(walls) if not walls.is_empty else region
        if region.area >= MIN_ROOM_AREA:
            levels.append((region, level))
    return levels


def free_positions(scene: Scene, caster=None) -> np.ndarray:
    """Places of the storey's free space to look from (module docstring, *Visible*).

    Parameters
    ----------
    scene : Scene
    caster : open3d RaycastingScene, optional
        Of every face of ``scene``, when the caller has built it.

    Returns
    -------
    (m, 3) float
        Lattice points of each of the :func:`floor_levels` at each of :data:`VIEW_HEIGHTS` above it,
        kept where the first face straight up is a CEILING face (not furniture, not the sky), the first
        face straight down is the floor they stand over, no face lies nearer than
        :data:`VIEW_CLEARANCE` along any of the :data:`ENCLOSURE_RAYS` horizontal directions, and
        faces close them in (at most
        :data:`MAX_ESCAPES` of :data:`ENCLOSURE_RAYS` horizontal rays leave the model: not a porch).
    """
    from scenes._open3d import open3d

    o3d = open3d()
    caster = caster if caster is not None else _all_faces(scene)
    out = []
    for floor, floor_z in floor_levels(scene):
        # The lattice is anchored on the world's origin: the same places whatever the floor's extent.
        x0, y0, x1, y1 = (np.floor(np.asarray(floor.bounds) / VIEW_LATTICE) * VIEW_LATTICE).tolist()
        gx, gy = np.meshgrid(
            np.arange(x0 + VIEW_LATTICE / 2, x1 + VIEW_LATTICE, VIEW_LATTICE),
            np.arange(y0 + VIEW_LATTICE / 2, y1 + VIEW_LATTICE, VIEW_LATTICE),
        )
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        xy = xy[shapely.contains_xy(floor, xy[:, 0], xy[:, 1])]
        if not len(xy):
            xy = np.array([[p.x, p.y] for p in (floor.representative_point(),)])
        for height in VIEW_HEIGHTS:
            p = np.column_stack([xy, np.full(len(xy), floor_z + height)]).astype(np.float32)
            up = caster.cast_rays(
                o3d.core.Tensor.from_numpy(np.column_stack([p, np.tile([0, 0, 1], (len(p), 1))]).astype(np.float32))
            )
            t_up, id_up = up["t_hit"].numpy(), up["primitive_ids"].numpy()
            covered = np.isfinite(t_up)
            covered[covered] = scene.face_labels[id_up[covered]] == SurfaceClass.CEILING
            down = caster.cast_rays(
                o3d.core.Tensor.from_numpy(np.column_stack([p, np.tile([0, 0, -1], (len(p), 1))]).astype(np.float32))
            )
            keep = covered & (np.abs(down["t_hit"].numpy() - height) < 0.05)
            around = horizontal_hits(caster, p[keep])
            keep[keep] = (around.min(axis=1) >= VIEW_CLEARANCE) & (
                np.count_nonzero(~np.isfinite(around), axis=1) <= MAX_ESCAPES
            )
            out.append(p[keep])
    return np.concatenate(out).astype(float) if out else np.zeros((0, 3))


def visible_mask(scene: Scene, points: np.ndarray, positions: np.ndarray | None = None) -> np.ndarray:
    """Which surface points some free position sees (module docstring, *Visible*).

    Parameters
    ----------
    scene : Scene
        The true building (its mesh and surface classes only).
    points : (n, 3) float
        Points on the mesh's faces.
    positions : (m, 3) float, optional
        Where to look from; :func:`free_positions` by default. With none, every point is kept (a
        storey with no indoor floor has no place to judge from).

    Returns
    -------
    (n,) bool
    """
    from scenes._open3d import open3d

    points = np.asarray(points, dtype=float).reshape(-1, 3)
    caster = _all_faces(scene)
    positions = (
        free_positions(scene, caster) if positions is None else np.asarray(positions, dtype=float).reshape(-1, 3)
    )
    if not len(positions) or not len(points):
        return np.ones(len(points), dtype=bool)
    o3d = open3d()
    seen = np.zeros(len(points), dtype=bool)

    def look(origins: np.ndarray, which: np.ndarray) -> None:
        offset = points[which] - origins
        distance = np.linalg.norm(offset, axis=1)
        rays = np.empty((len(which), 6), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = offset / np.maximum(distance, 1e-9)[:, None]
        t = caster.cast_rays(o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy()
        # The first face met is the point's own, to float precision and a centimetre.
        seen[which[t >= distance - 0.01]] = True

    # Most points are seen from a position near them: each point tries the positions of its own
    # lattice cell and of the cells around it first (rings out to VIEW_RING cells, nearest ring
    # first), one ray a point per round.
    cells = np.floor(positions[:, :2] / VIEW_LATTICE).astype(np.int64)
    keys = cells[:, 0] * _KEY + cells[:, 1]
    unique, inverse = np.unique(keys, return_inverse=True)
    slots = np.zeros(len(unique), dtype=np.int64)
    table = np.full((len(unique), np.bincount(inverse).max()), -1, dtype=np.int64)
    for index, u in enumerate(inverse):
        table[u, slots[u]] = index
        slots[u] += 1
    own = np.floor(points[:, :2] / VIEW_LATTICE).astype(np.int64)
    ring = [(dx, dy) for dx in range(-VIEW_RING, VIEW_RING + 1) for dy in range(-VIEW_RING, VIEW_RING + 1)]
    for dx, dy in sorted(ring, key=lambda d: (max(abs(d[0]), abs(d[1])), abs(d[0]) + abs(d[1]))):
        for slot in range(table.shape[1]):
            todo = np.flatnonzero(~seen)
            if not len(todo):
                return seen
            key = (own[todo, 0] + dx) * _KEY + own[todo, 1] + dy
            at = np.minimum(np.searchsorted(unique, key), len(unique) - 1)
            index = np.where(unique[at] == key, table[at, slot], -1)
            has = index >= 0
            if has.any():
                look(positions[index[has]], todo[has])
    # What those do not see (under and behind furniture, mostly) is tried from every position of a
    # lattice three times coarser, all over the storey.
    cell = np.round(positions[:, :2] / VIEW_LATTICE).astype(np.int64)
    coarse = positions[(cell[:, 0] % 3 == 0) & (cell[:, 1] % 3 == 0)]
    for origin in coarse if len(coarse) else positions:
        todo = np.flatnonzero(~seen)
        if not len(todo):
            break
        look(origin[None, :], todo)
    return seen


def _all_faces(scene: Scene):
    """An open3d ray caster of every face of the scene: furniture hides too."""
    from scenes._open3d import open3d

    o3d = open3d()
    caster = o3d.t.geometry.RaycastingScene()
    caster.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(scene.mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(scene.mesh.faces, dtype=np.uint32)),
    )
    return caster


def interior_area(scene: Scene) -> float:
    """Area (m²) of the structural surface facing the interior, from the 5 cm samples."""
    return len(interior_samples(scene, 0.05)) * 0.05**2


def _union_xy(triangles: np.ndarray) -> Polygon | MultiPolygon:
    polys = shapely.polygons(np.asarray(triangles)[..., :2])
    polys = polys[shapely.area(polys) > 1e-10]
    if not len(polys):
        return Polygon()
    # A hair of growth closes the cracks between triangles that share an edge only up to rounding.
    return shapely.union_all(shapely.buffer(polys, 1e-4)).buffer(-1e-4)


def _parts(geom) -> list[Polygon]:
    return [g for g in getattr(geom, "geoms", [geom]) if isinstance(g, Polygon) and not g.is_empty]


def separating_footprint(scene: Scene, floor_z: float):
    """Plan footprint of the walls, doors and windows the robot's body meets on this floor."""
    keep = np.isin(scene.face_labels, [SurfaceClass.WALL, SurfaceClass.DOOR, SurfaceClass.WINDOW])
    tri = scene.mesh.vertices[scene.mesh.faces[keep]]
    z = tri[..., 2]
    tri = tri[(z.max(axis=1) > floor_z + 0.05) & (z.min(axis=1) < floor_z + 1.8)][..., :2]
    if not len(tri):
        return Polygon()
    rings = shapely.linestrings(np.concatenate([tri, tri[:, :1]], axis=1))
    solid = shapely.polygons(tri)
    return shapely.union_all(np.concatenate([shapely.buffer(rings, 0.01), solid[shapely.area(solid) > 1e-8]]))


def floor_level(floor_triangles: np.ndarray) -> float:
    """The storey's floor height: the 5 cm band of z holding the most upward-facing floor area (m).

    A slab's underside has the area of its top; only where no floor face faces up (a file with
    flipped normals) does every face count."""
    tri = np.asarray(floor_triangles, dtype=float)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    up = cross[:, 2] > 0.5 * np.linalg.norm(cross, axis=1)
    weight = np.where(up, area, 0.0) if np.any(up & (area > 0)) else area
    z = tri[..., 2].mean(axis=1)
    bins = np.round(z / 0.05).astype(np.int64)
    _, inverse = np.unique(bins, return_inverse=True)
    best = int(np.argmax(np.bincount(inverse, weights=weight)))
    members = np.flatnonzero(inverse == best)
    order = members[np.argsort(z[members])]
    cumulative = np.cumsum(weight[order])
    return float(z[order[np.searchsorted(cumulative, 0.5 * cumulative[-1])]])  # the band's median


def indoor_floor(scene: Scene) -> tuple[Polygon | MultiPolygon, float]:
    """The storey's indoor free floor and its height (module docstring): FLOOR faces of the floor
    level, under a CEILING face when the storey has any, minus the footprint of walls, doors and
    windows (furniture stays in).

    Returns
    -------
    free : shapely geometry
        Empty when the storey has no floor.
    floor_z : float
    """
    vertices, faces, labels = scene.mesh.vertices, scene.mesh.faces, scene.face_labels
    floor_tri = vertices[faces[labels == SurfaceClass.FLOOR]]
    if not len(floor_tri):
        return Polygon(), 0.0
    floor_z = floor_level(floor_tri)
    z = floor_tri[..., 2]
    level = (z.min(axis=1) > floor_z - FLOOR_BAND) & (z.max(axis=1) < floor_z + FLOOR_BAND)
    floor = _union_xy(floor_tri[level])
    ceiling_tri = vertices[faces[labels == SurfaceClass.CEILING]]
    if len(ceiling_tri):
        floor = floor.intersection(_union_xy(ceiling_tri))
    walls = separating_footprint(scene, floor_z)
    return (floor.difference(walls) if not walls.is_empty else floor), floor_z


def derive_rooms(scene: Scene) -> list[Room]:
    """Rooms from the free space of the storey's floor (module docstring); [] when there is none.

    Returns
    -------
    list of Room
        Ids 0..k-1 by decreasing area; polygons counter-clockwise, not closed; ``ceiling_z`` the
        highest CEILING vertex over the room (``floor_z + 2.7`` without one).
    """
    from scenes.model import Room

    free, floor_z = indoor_floor(scene)
    if free.is_empty:
        return []
    ceiling_tri = scene.mesh.vertices[scene.mesh.faces[scene.face_labels == SurfaceClass.CEILING]]
    seeds = [p for p in _parts(free.buffer(-ROOM_NECK)) if p.area >= MIN_ROOM_AREA]
    if not seeds:
        seeds = [p for p in _parts(free) if p.area >= MIN_ROOM_AREA]
        grown = seeds
    else:
        grown = []
        taken = Polygon()
        for seed in sorted(seeds, key=lambda p: -p.area):
            region = seed.buffer(ROOM_NECK + 0.02).intersection(free).difference(taken)
            region = max(_parts(region), key=lambda p: p.area, default=Polygon())
            if region.is_empty:
                continue
            grown.append(region)
            taken = taken.union(region)
        # Door passages and niches the seeds did not reach join the room they border most.
        for piece in _parts(free.difference(taken)):
            if piece.area < 1e-4:
                continue
            touching = [piece.buffer(0.02).intersection(g).area for g in grown]
            if touching and max(touching) > 0:
                k = int(np.argmax(touching))
                grown[k] = max(_parts(grown[k].union(piece.buffer(0.01)).intersection(free)), key=lambda p: p.area)
    rooms = []
    for k, region in enumerate(sorted(grown, key=lambda p: -p.area)):
        outline = orient(Polygon(region.exterior), sign=1.0)
        coords = np.asarray(outline.exterior.coords)[:-1]
        ceiling_z = floor_z + 2.7
        if len(ceiling_tri):
            centre = ceiling_tri.mean(axis=1)
            over = shapely.contains_xy(outline, centre[:, 0], centre[:, 1])
            if over.any():
                ceiling_z = float(ceiling_tri[over][..., 2].max())
        rooms.append(Room(k, f"space {k + 1}", coords, floor_z, ceiling_z))
    return rooms


def rooms_by_probe(rooms: list[Room], points: np.ndarray, normals: np.ndarray, tolerance: float = 0.05) -> np.ndarray:
    """(n,) int32: the room of each surface point, whose prism holds the point :data:`INTERIOR_PROBE`
    in front of it (behind it, when the front lies in none), else -1.

    Parameters
    ----------
    rooms : list of Room
    points, normals : (n, 3) float
        Points on faces and their faces' unit normals.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    result = np.full(len(points), -1, dtype=np.int32)
    polygons = [Polygon(room.polygon) for room in rooms]
    for side in (1.0, -1.0):
        probe = points + side * INTERIOR_PROBE * normals
        for room, polygon in zip(rooms, polygons, strict=True):
            todo = np.flatnonzero(result < 0)
            if not len(todo):
                return result
            p = probe[todo]
            inside = (p[:, 2] >= room.floor_z - tolerance) & (p[:, 2] <= room.ceiling_z + tolerance)
            inside[inside] = shapely.contains_xy(polygon, p[inside, 0], p[inside, 1])
            result[todo[inside]] = room.id
    return result


def with_derived_rooms(scene: Scene) -> Scene:
    """``scene`` itself when it has rooms, else a copy with rooms derived from its floor's free space
    (:func:`derive_rooms`), faces given rooms by :func:`rooms_by_probe` at their centroids, and
    ``metadata["rooms"] = "derived"`` (so that :meth:`Scene.structure_samples` gives each sample
    the room of its own probe, one large triangle being shared by several rooms). The mesh is
    kept as it is."""
    from scenes.model import Scene as SceneType

    if scene.rooms:
        return scene
    rooms = derive_rooms(scene)
    if not rooms:
        return scene
    mesh = scene.mesh
    return SceneType(
        mesh,
        scene.face_labels,
        rooms_by_probe(rooms, mesh.triangles_center, mesh.face_normals),
        rooms=rooms,
        doors=scene.doors,
        start=scene.start if scene.has_explicit_start else None,
        name=scene.name,
        metadata={**scene.metadata, "rooms": "derived"},
    )
