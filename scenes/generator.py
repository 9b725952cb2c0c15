"""Seeded, deterministic storeys: an endless supply of cluttered, multi-room buildings.

How a storey is drawn
---------------------
1. A grid of ``nx × ny`` cells with random widths covers the storey; a few outer cells may be dropped
   so the outline itself is irregular.
2. Rooms grow from random seed cells over the grid (randomised region growing), which yields
   rectangles, L, T, U and irregular orthogonal rooms. A room whose cells do not form a simple
   polygon (a hole, or cells touching at a corner only) rejects the draw.
3. With probability ``nonorthogonal``, one or two grid lines are tilted. Grid lines stay straight,
   so shared walls stay shared, and the rooms next to a tilted line get non-right angles.
4. Doors join the rooms along shared walls: a random spanning tree of the room adjacency graph, plus
   extra doors with probability ``extra_doors``, so every room is reachable.
5. Windows go on outside walls; clutter is placed room by room (about ``clutter_density`` objects
   per 6 m²), part of it standing against walls where it hides them. An object is kept only if the
   room's free space stays in one piece around its doors.
6. The storey is extruded and validated (:mod:`scenes.validation`); a failed draw is redrawn from the
   same generator, so a seed always gives the same storey.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, replace

import numpy as np
import shapely
from shapely.geometry import Point, Polygon, box
from shapely.geometry.polygon import orient

from scenes.errors import GeneratorConfigError, SceneError, StoreyValidationError
from scenes.floorplan import (
    DOOR_CLEARANCE,
    ClutterPlan,
    DoorPlan,
    FloorPlan,
    RoomPlan,
    WindowPlan,
    _rectangle,
)
from scenes.geometry import STOREY_CLEARANCE
from scenes.limits import is_finite
from scenes.model import Scene
from scenes.validation import validate_plan_scene

__all__ = ["MAX_CLUTTER_DENSITY", "GeneratorConfig", "generate_plan", "generate_scene"]

#: The densest clutter the generator draws (objects per 6 m²): placement is tried per object, so
#: the work grows with it; at 10 a room is already as full as free space allows.
MAX_CLUTTER_DENSITY = 10.0


@dataclass(frozen=True)
class GeneratorConfig:
    """Options of the storey generator (all JSON-safe).

    Attributes
    ----------
    rooms : int or (int, int)
        Number of rooms, or an inclusive range to draw from (1 to 8).
    clutter_density : float
        Scales the clutter: about this many objects per 6 m² of floor (0 for none, at most
        :data:`MAX_CLUTTER_DENSITY`).
    wall_standing : float
        Share of the clutter placed against walls, where it hides them.
    nonorthogonal : float
        Probability that the storey has tilted walls (non-right angles).
    irregular_outline : float
        Probability of dropping outer cells so the outline is not a rectangle.
    extra_doors : float
        Probability of a second door between two rooms already joined through others.
    windows : float
        Probability that a room with an outside wall gets a window.
    cell_size : (float, float)
        Range of grid-cell widths in metres.
    ceiling_height, wall_thickness, door_width, door_height : (float, float)
        Ranges in metres.
    max_attempts : int
        Redraws before giving up.
    """

    rooms: int | tuple[int, int] = (1, 8)
    clutter_density: float = 1.0
    wall_standing: float = 0.6
    nonorthogonal: float = 0.35
    irregular_outline: float = 0.5
    extra_doors: float = 0.25
    windows: float = 0.5
    cell_size: tuple[float, float] = (2.0, 3.6)
    ceiling_height: tuple[float, float] = (2.5, 3.2)
    wall_thickness: tuple[float, float] = (0.10, 0.25)
    door_width: tuple[float, float] = (0.8, 1.0)
    door_height: tuple[float, float] = (2.0, 2.1)
    max_attempts: int = 200

    def __post_init__(self) -> None:
        try:
            self._check()
        except RecursionError:  # a repr of a value nested thousands of levels deep, in a message
            raise GeneratorConfigError("GeneratorConfig", "a value nested too deep to check") from None
        except ValueError as exc:
            raise GeneratorConfigError("GeneratorConfig", str(exc)) from None

    def _check(self) -> None:
        import numbers
        from collections.abc import Callable

        def plain(value: object) -> object:  # a numpy number as the int or float JSON writes
            if type(value) in (int, float):
                return value
            return int(value) if integer(value) else float(value)  # type: ignore[arg-type]

        def integer(value: object) -> bool:
            return isinstance(value, numbers.Integral) and not isinstance(value, bool)

        def number(value: object) -> bool:
            return isinstance(value, numbers.Real) and not isinstance(value, bool) and is_finite(value)

        def pair(name: str, check: Callable[[object], bool], low: float, high: float, kind: str) -> tuple:
            value = getattr(self, name)
            if not (
                isinstance(value, (tuple, list))
                and len(value) == 2
                and all(check(v) for v in value)
                and low <= value[0] <= value[1] <= high
            ):
                raise ValueError(
                    f"{name} must be a pair [low, high] of {kind} with {low:g} <= low <= high <= {high:g}, "
                    f"got {value!r}"
                )
            return (plain(value[0]), plain(value[1]))

        if integer(self.rooms):
            if not 1 <= self.rooms <= 8:
                raise ValueError(f"rooms must be within 1..8, got {self.rooms}")
            object.__setattr__(self, "rooms", plain(self.rooms))
        elif isinstance(self.rooms, (tuple, list)) and len(self.rooms) == 2 and all(integer(v) for v in self.rooms):
            if not 1 <= self.rooms[0] <= self.rooms[1] <= 8:
                raise ValueError(f"rooms must be within 1..8 (a pair [low, high] with low <= high), got {self.rooms}")
            object.__setattr__(self, "rooms", (plain(self.rooms[0]), plain(self.rooms[1])))
        else:
            raise ValueError(
                f"rooms must be within 1..8: an integer or a pair [low, high] of integers, got {self.rooms!r}"
            )
        if not (number(self.clutter_density) and 0 <= self.clutter_density <= MAX_CLUTTER_DENSITY):
            raise ValueError(
                f"clutter_density must be a number within 0..{MAX_CLUTTER_DENSITY:g}, got {self.clutter_density}"
            )
        for name in ("wall_standing", "nonorthogonal", "irregular_outline", "extra_doors", "windows"):
            if not (number(getattr(self, name)) and 0.0 <= getattr(self, name) <= 1.0):
                raise ValueError(f"{name} is a probability in [0, 1], got {getattr(self, name)!r}")
        # Below 1.8 m a room is too narrow for the robot; above 10 m a storey of 8 rooms passes the
        # storeys' size limits' spirit (train.ppo's --cell-size has the same bounds).
        object.__setattr__(self, "cell_size", pair("cell_size", number, 1.8, 10.0, "metres"))
        # The floor plans' own limits (scenes.floorplan): ceilings up to 30 m, walls up to 3 m.
        object.__setattr__(self, "ceiling_height", pair("ceiling_height", number, 2.0, 30.0, "metres"))
        object.__setattr__(self, "wall_thickness", pair("wall_thickness", number, 0.01, 3.0, "metres"))
        object.__setattr__(self, "door_width", pair("door_width", number, 0.5, 10.0, "metres"))
        object.__setattr__(self, "door_height", pair("door_height", number, 1.0, 30.0, "metres"))
        # A door reaches at most 0.3 m below the ceiling (a lintel): a taller one was cut to that
        # height without a word.
        if self.door_height[1] > self.ceiling_height[0] - 0.3:
            raise ValueError(
                f"door_height {list(self.door_height)} must stay 0.3 m below the lowest ceiling "
                f"(ceiling_height {list(self.ceiling_height)}): at most {self.ceiling_height[0] - 0.3:g} m"
            )
        if not (integer(self.max_attempts) and 1 <= self.max_attempts <= 100_000):
            raise ValueError(f"max_attempts must be an integer within [1, 100,000], got {self.max_attempts!r}")
        object.__setattr__(self, "max_attempts", plain(self.max_attempts))
        for name in (
            "clutter_density",
            "wall_standing",
            "nonorthogonal",
            "irregular_outline",
            "extra_doors",
            "windows",
        ):
            object.__setattr__(self, name, plain(getattr(self, name)))

    @property
    def room_range(self) -> tuple[int, int]:
        if isinstance(self.rooms, int):
            return (self.rooms, self.rooms)
        return (int(self.rooms[0]), int(self.rooms[1]))

    def to_dict(self) -> dict:
        return asdict(self)


def generate_plan(seed: int, config: GeneratorConfig | None = None, **options: object) -> FloorPlan:
    """Draw a valid storey plan.

    Parameters
    ----------
    seed : int
        Same seed and options, same plan (and so the same mesh, byte for byte).
    config : GeneratorConfig, optional
        Generator options; keyword ``options`` override its fields (e.g. ``rooms=5``).

    Raises
    ------
    StoreyValidationError
        When no valid storey was drawn in ``max_attempts`` tries.
    """
    return generate_storey(seed, config, **options)[0]


def generate_storey(seed: int, config: GeneratorConfig | None = None, **options: object) -> tuple[FloorPlan, Scene]:
    """:func:`generate_plan` and the validated scene it was checked on (extruded once, not twice).

    The scene carries the plan's metadata and the source name ``generated:SEED``.

    Raises
    ------
    StoreyValidationError
        When no valid storey was drawn in ``max_attempts`` tries.
    TypeError, ValueError
        ``seed`` is not an integer >= 0 (numpy's own messages named neither the seed nor the function).
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"the generator's seed must be an integer >= 0, got {type(seed).__name__} {seed!r:.40}")
    if seed < 0:
        raise ValueError(f"the generator's seed must be an integer >= 0, got {seed}")
    config = replace(config or GeneratorConfig(), **options) if options else (config or GeneratorConfig())
    rng = np.random.default_rng(seed)
    last: Exception | None = None
    for attempt in range(config.max_attempts):
        try:
            plan = _draw(rng, config, f"generated:{seed}")
            if plan is None:
                continue
            scene = plan.to_scene(source=plan.name, validate=False)
            plan = replace(plan, start=(round(float(scene.start[0]), 4), round(float(scene.start[1]), 4)))
            scene.start = plan.start
            validate_plan_scene(plan, scene)
            plan = replace(plan, metadata={"seed": seed, "attempts": attempt + 1, "generator": config.to_dict()})
            scene.metadata.update(plan.metadata)
            return plan, scene
        except SceneError as exc:  # a draw that failed a check: draw again
            last = exc
    raise StoreyValidationError(f"generated:{seed}", f"no valid storey in {config.max_attempts} draws (last: {last})")


def generate_scene(seed: int, config: GeneratorConfig | None = None, **options: object) -> Scene:
    """:func:`generate_plan` extruded to a validated :class:`~scenes.model.Scene`."""
    return generate_storey(seed, config, **options)[1]


# -------------------------------------------------------------------------------------- internals
def _draw(rng: np.random.Generator, cfg: GeneratorConfig, name: str) -> FloorPlan | None:
    lo, hi = cfg.room_range
    n_rooms = int(rng.integers(lo, hi + 1))
    n_cells = max(1, round(n_rooms * rng.uniform(2.0, 4.5)))
    aspect = rng.uniform(0.6, 1.6)
    nx = max(1, round(math.sqrt(n_cells * aspect)))
    ny = max(1, math.ceil(n_cells / nx))
    if nx * ny < n_rooms:
        ny = math.ceil(n_rooms / nx)
    cells = np.ones((nx, ny), dtype=bool)
    if rng.random() < cfg.irregular_outline and nx * ny > n_rooms + 1:
        corners = [(0, 0), (nx - 1, 0), (0, ny - 1), (nx - 1, ny - 1)]
        for k in rng.permutation(4)[: int(rng.integers(1, 3))]:
            cells[corners[k]] = False
        if cells.sum() < n_rooms:
            return None
    owner = _grow_rooms(rng, cells, n_rooms)
    if owner is None:
        return None
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.cell_size, nx))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.cell_size, ny))])
    sx, sy = np.zeros(nx + 1), np.zeros(ny + 1)
    if rng.random() < cfg.nonorthogonal:
        tilted = 0
        for _ in range(8):
            # A tilt is a sideways shift of 0.5-1.3 m over the storey's extent (6-30 degrees or so).
            shift = float(rng.choice([-1, 1]) * rng.uniform(0.5, 1.3))
            vertical = bool(rng.random() < 0.5)
            pos, slopes, extent = (xs, sx, ys[-1]) if vertical else (ys, sy, xs[-1])
            k = int(rng.integers(0, len(pos)))
            old = slopes[k]
            slopes[k] = shift / extent
            if _lines_apart(pos, slopes, extent * 1.2, cfg.cell_size[0] * 0.8):
                tilted += 1
                if tilted == 2 or rng.random() < 0.5:
                    break
            else:
                slopes[k] = old

    def world(i: float, j: float) -> tuple[float, float]:
        # Vertex where vertical line i (x = X_i + s_i y) meets horizontal line j (y = Y_j + r_j x).
        X, s, Y, r = xs[int(i)], sx[int(i)], ys[int(j)], sy[int(j)]
        x = (X + s * Y) / (1.0 - s * r)
        return (float(x), float(Y + r * x))

    t = round(float(rng.uniform(*cfg.wall_thickness)), 3)
    height = round(float(rng.uniform(*cfg.ceiling_height)), 3)
    rooms: list[RoomPlan] = []
    clear: list[Polygon] = []
    for k in range(n_rooms):
        union = shapely.union_all([box(i, j, i + 1, j + 1) for i, j in zip(*np.nonzero(owner == k), strict=True)])
        if union.geom_type != "Polygon" or len(union.interiors):
            return None
        grid_poly = orient(shapely.simplify(union, 0.0), 1.0)
        pts = [world(i, j) for i, j in np.asarray(grid_poly.exterior.coords)[:-1].round().astype(int)]
        poly = Polygon(pts)
        if not poly.is_valid:
            return None
        rooms.append(RoomPlan(f"room{k}", tuple((round(x, 4), round(y, 4)) for x, y in pts)))
        inner = Polygon(rooms[-1].polygon).buffer(-t / 2, join_style="mitre", mitre_limit=100.0)
        if inner.geom_type != "Polygon":
            return None
        clear.append(orient(inner, 1.0))

    # Shared walls as runs of unit grid edges, per pair of rooms and per outside room.
    runs = _wall_runs(owner)
    doors: list[DoorPlan] = []
    margin = t + 0.15
    parent = list(range(n_rooms))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    pairs = sorted(k for k in runs if k[0] >= 0 and k[1] >= 0)
    for idx in rng.permutation(len(pairs)):
        a, b = pairs[idx]
        joined = find(a) == find(b)
        if joined and rng.random() >= cfg.extra_doors:
            continue
        width = round(float(rng.uniform(*cfg.door_width)), 3)
        spot = _spot_on_runs(rng, runs[(a, b)], world, width / 2 + margin)
        if spot is None:
            continue
        door_h = round(min(float(rng.uniform(*cfg.door_height)), height - 0.3), 3)
        doors.append(DoorPlan((f"room{a}", f"room{b}"), spot, width, door_h))
        parent[find(a)] = find(b)
    if len({find(k) for k in range(n_rooms)}) != 1:
        return None

    windows: list[WindowPlan] = []
    for k in range(n_rooms):
        outside = runs.get((k, -1))
        if outside and rng.random() < cfg.windows:
            width = round(float(rng.uniform(0.8, 1.6)), 3)
            spot = _spot_on_runs(rng, outside, world, width / 2 + margin)
            if spot is not None:
                sill = round(float(rng.uniform(0.8, 1.0)), 3)
                win_h = round(min(float(rng.uniform(1.0, 1.4)), height - sill - 0.2), 3)
                windows.append(WindowPlan(f"room{k}", spot, width, win_h, sill))

    door_zones = [
        _rectangle(
            d.position,
            d.width,
            t + 2 * DOOR_CLEARANCE,
            _run_angle(d.position, clear, names=[r.name for r in rooms], door=d),
        )
        for d in doors
    ]
    clutter: list[ClutterPlan] = []
    for k in range(n_rooms):
        approach = [_approach_point(d, t, clear[k]) for d in doors if f"room{k}" in d.rooms]
        clutter.extend(_place_clutter(rng, cfg, clear[k], height, door_zones, [p for p in approach if p is not None]))
    return FloorPlan(
        rooms=tuple(rooms),
        ceiling_height=height,
        wall_thickness=t,
        doors=tuple(doors),
        windows=tuple(windows),
        clutter=tuple(clutter),
        name=name,
        description="generated by nbs-env's storey generator",
    )


def _grow_rooms(rng: np.random.Generator, cells: np.ndarray, n_rooms: int) -> np.ndarray | None:
    owner = np.full(cells.shape, -1, dtype=int)
    free = list(zip(*np.nonzero(cells), strict=True))
    for k, idx in enumerate(rng.choice(len(free), size=n_rooms, replace=False)):
        owner[free[idx]] = k
    nx, ny = cells.shape
    while True:
        frontier = []
        for i, j in zip(*np.nonzero(cells & (owner < 0)), strict=True):
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny and owner[a, b] >= 0:
                    frontier.append((int(i), int(j), int(owner[a, b])))
        if not frontier:
            break
        sizes = np.bincount(owner[owner >= 0], minlength=n_rooms)
        # Smaller rooms grow first more often, so room sizes stay comparable.
        weights = np.array([1.0 / (1 + sizes[k]) ** 2 for _, _, k in frontier])
        i, j, k = frontier[int(rng.choice(len(frontier), p=weights / weights.sum()))]
        owner[i, j] = k
    if np.any(cells & (owner < 0)):
        return None
    return owner


def _lines_apart(pos: np.ndarray, slope: np.ndarray, extent: float, gap: float) -> bool:
    for y in (0.0, extent):
        p = pos + slope * y
        if np.any(np.diff(p) < gap):
            return False
    return True


def _wall_runs(owner: np.ndarray) -> dict[tuple[int, int], list[tuple[tuple[int, int], tuple[int, int]]]]:
    """Unit grid edges between two owners (-1 for outside), merged into straight runs."""
    nx, ny = owner.shape
    padded = np.full((nx + 2, ny + 2), -1, dtype=int)
    padded[1:-1, 1:-1] = owner
    unit: dict[tuple[int, int], list[tuple[str, int, int]]] = {}
    for i in range(nx + 1):
        for j in range(ny):
            a, b = padded[i, j + 1], padded[i + 1, j + 1]
            if a != b and max(a, b) >= 0:
                key = (a, b) if a >= 0 and (b < 0 or a < b) else (b, a)
                unit.setdefault(key, []).append(("v", i, j))
    for j in range(ny + 1):
        for i in range(nx):
            a, b = padded[i + 1, j], padded[i + 1, j + 1]
            if a != b and max(a, b) >= 0:
                key = (a, b) if a >= 0 and (b < 0 or a < b) else (b, a)
                unit.setdefault(key, []).append(("h", j, i))
    runs: dict[tuple[int, int], list[tuple[tuple[int, int], tuple[int, int]]]] = {}
    for key, edges in unit.items():
        out = []
        for kind, line, pos in sorted(edges):
            if out and out[-1][0] == kind and out[-1][1] == line and out[-1][3] == pos:
                out[-1][3] = pos + 1
            else:
                out.append([kind, line, pos, pos + 1])
        runs[key] = [
            ((line, p0), (line, p1)) if kind == "v" else ((p0, line), (p1, line)) for kind, line, p0, p1 in out
        ]
    return runs


def _spot_on_runs(rng: np.random.Generator, runs: list, world, half: float) -> tuple[float, float] | None:
    """A random point on one of ``runs`` at least ``half`` from both ends, in world coordinates."""
    options = []
    for (i0, j0), (i1, j1) in runs:
        p0, p1 = np.array(world(i0, j0)), np.array(world(i1, j1))
        length = float(np.linalg.norm(p1 - p0))
        if length >= 2 * half + 0.05:
            options.append((p0, p1, length))
    if not options:
        return None
    p0, p1, length = options[int(rng.integers(len(options)))]
    s = rng.uniform(half, length - half)
    p = p0 + (p1 - p0) * (s / length)
    return (round(float(p[0]), 4), round(float(p[1]), 4))


def _run_angle(position, clear: list[Polygon], names: list[str], door: DoorPlan) -> float:
    """Direction (degrees) of the wall a door sits in: that of the nearest edge of its first room."""
    k = names.index(door.rooms[0])
    pts = np.asarray(clear[k].exterior.coords)
    p = np.asarray(position)
    best, angle = math.inf, 0.0
    for a, b in itertools.pairwise(pts):
        seg = shapely.LineString([a, b])
        dist = seg.distance(Point(p))
        if dist < best:
            best, angle = dist, math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
    return angle


def _approach_point(door: DoorPlan, t: float, clear: Polygon) -> Point | None:
    """The point in front of a door, inside room ``clear``, where the robot lines up to cross it."""
    p = np.asarray(door.position)
    near = clear.exterior.interpolate(clear.exterior.project(Point(p)))
    v = np.array([near.x, near.y]) - p
    n = np.linalg.norm(v)
    if n < 1e-9:
        return None
    q = p + v / n * (t / 2 + STOREY_CLEARANCE + 0.05)
    return Point(q)


_SIZES = {
    "cabinet": ((0.6, 1.6), (0.4, 0.6), (1.6, 2.2)),
    "shelf": ((0.8, 2.0), (0.3, 0.45), (1.5, 2.2)),
    "sofa": ((1.6, 2.4), (0.8, 1.0), (0.75, 0.95)),
    "box": ((0.4, 1.2), (0.4, 0.8), (0.4, 1.2)),
    "table": ((1.0, 2.0), (0.7, 1.0), (0.72, 0.78)),
    "chair": ((0.42, 0.5), (0.42, 0.5), (0.8, 1.0)),
    "column": ((0.3, 0.5), (0.3, 0.5), (2.0, 2.0)),
}
_WALL_KINDS = ("cabinet", "shelf", "sofa", "box")
_FREE_KINDS = ("table", "chair", "column", "box")


def _place_clutter(
    rng: np.random.Generator,
    cfg: GeneratorConfig,
    room: Polygon,
    height: float,
    door_zones: list[Polygon],
    approach: list[Point],
) -> list[ClutterPlan]:
    count = round(cfg.clutter_density * room.area / 6.0)
    if cfg.clutter_density > 0:
        count = max(1, count)
    placed: list[ClutterPlan] = []
    feet: list[Polygon] = []
    base_free = room.buffer(-STOREY_CLEARANCE, join_style="mitre")
    coords = np.asarray(room.exterior.coords)
    edges = [(coords[k], coords[k + 1]) for k in range(len(coords) - 1)]
    for _ in range(count):
        against = rng.random() < cfg.wall_standing
        kind = str(rng.choice(_WALL_KINDS if against else _FREE_KINDS))
        (l0, l1), (d0, d1), (h0, h1) = _SIZES[kind]
        for _try in range(25):
            length, depth = float(rng.uniform(l0, l1)), float(rng.uniform(d0, d1))
            # A plan refuses clutter taller than its ceiling; a low ceiling_height option bounds it.
            h = height if kind == "column" else min(float(rng.uniform(h0, h1)), height)
            if against:
                a, b = edges[int(rng.integers(len(edges)))]
                seg = b - a
                seg_len = float(np.linalg.norm(seg))
                if seg_len < length + 0.3:
                    continue
                d = seg / seg_len
                inward = np.array([-d[1], d[0]])
                s = rng.uniform(0.15 + length / 2, seg_len - 0.15 - length / 2)
                centre = a + d * s + inward * (depth / 2 + 0.02)
                yaw = math.degrees(math.atan2(d[1], d[0])) + 180.0
            else:
                x0, y0, x1, y1 = room.bounds
                centre = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
                yaw = (
                    float(rng.uniform(0.0, 360.0))
                    if kind == "chair"
                    else float(rng.choice([0.0, 90.0, rng.uniform(0, 180)]))
                )
            item = ClutterPlan(
                kind,
                (round(float(centre[0]), 4), round(float(centre[1]), 4)),
                (round(length, 3), round(depth, 3), round(h, 3)),
                round(float(yaw) % 360.0, 3),
            )
            foot = item.footprint()
            if not room.buffer(-0.01).contains(foot):
                continue
            if any(foot.distance(f) < 0.05 for f in feet) or any(z.intersects(foot) for z in door_zones):
                continue
            free = base_free.difference(shapely.union_all([*feet, foot]).buffer(STOREY_CLEARANCE))
            parts = [g for g in getattr(free, "geoms", [free]) if not g.is_empty]
            if not parts:
                continue
            main = max(parts, key=lambda g: g.area)
            # Every door must stay approachable from the room's main free area.
            if any(not main.covers(p) for p in approach) or main.area < 0.5 * base_free.area:
                continue
            placed.append(item)
            feet.append(foot)
            break
    return placed
