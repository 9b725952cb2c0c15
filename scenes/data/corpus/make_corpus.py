"""Author the evaluation corpus of labelled storey meshes, directly with numpy + shapely + trimesh.

Run ``python scenes/data/corpus/make_corpus.py`` to (re)write the mesh files and ``corpus.json``
next to this script; ``--check`` afterwards loads every file with :func:`scenes.load_scene` and
checks labels, rooms, the start and the reachability of every room (it prints, it writes nothing).

The buildings are drawn here by hand, wall by wall, the way a CAD user or an exporter would leave
them, and deliberately NOT through the project's floor-plan extruder: each scene has its own
construction style (closed wall solids with outer faces and overlapping corners, zero-thickness
single quads, double-sided quads in a rotated building, a y-up glTF with room empties, walls
triangulated on a 0.5 m grid with a real floor slab and stair well, one big storey with a slab split
along room outlines). Everything is deterministic: no random numbers, fixed output order.

Units are metres; the storey floor is z = 0 and z is up (``enfilade.glb`` is written y up).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
import trimesh
from shapely.geometry import Point, Polygon
from shapely.geometry import box as rect

OUT = Path(__file__).resolve().parent

# SurfaceClass values (scenes/labels.py); --check asserts that they still match.
FLOOR, CEILING, WALL, DOOR, WINDOW, CLUTTER = 0, 1, 2, 3, 4, 5
CLASS_NAMES = {FLOOR: "floor", CEILING: "ceiling", WALL: "wall", DOOR: "door", WINDOW: "window", CLUTTER: "clutter"}

Z = np.array([0.0, 0.0, 1.0])


# ============================================================================ triangle primitives
def _v3(p, z=0.0):
    p = np.asarray(p, float)
    return p if p.shape == (3,) else np.array([p[0], p[1], z])


def quad(p0, p1, p2, p3, normal=None) -> np.ndarray:
    """(2, 3, 3) triangles of the planar quad p0 p1 p2 p3, facing ``normal`` when given."""
    t = np.array([[p0, p1, p2], [p0, p2, p3]], float)
    if normal is not None:
        n = np.cross(t[0, 1] - t[0, 0], t[0, 2] - t[0, 0])
        if np.dot(n, normal) < 0:
            t = t[:, [0, 2, 1]]
    return t


def grid_quad(p0, eu, ev, step, normal) -> np.ndarray:
    """The parallelogram p0 + [0,1] eu + [0,1] ev split into a grid of cells <= ``step`` (2 triangles each)."""
    p0, eu, ev = (np.asarray(x, float) for x in (p0, eu, ev))
    nu = max(1, math.ceil(np.linalg.norm(eu) / step - 1e-9))
    nv = max(1, math.ceil(np.linalg.norm(ev) / step - 1e-9))
    out = []
    for i in range(nu):
        for j in range(nv):
            a = p0 + eu * (i / nu) + ev * (j / nv)
            out.append(quad(a, a + eu / nu, a + eu / nu + ev / nv, a + ev / nv, normal))
    return np.concatenate(out)


def cuboid(o, a, b, c, step=None) -> np.ndarray:
    """Closed box o + [0,1] a + [0,1] b + [0,1] c, 12 outward triangles (or a ``step`` grid per face)."""
    o, a, b, c = (np.asarray(x, float) for x in (o, a, b, c))
    centre = o + (a + b + c) / 2
    faces = []
    for e1, e2, e3 in ((a, b, c), (b, c, a), (c, a, b)):
        for base in (o, o + e3):
            normal = (base + (e1 + e2) / 2) - centre
            if step is None:
                faces.append(quad(base, base + e1, base + e1 + e2, base + e2, normal))
            else:
                faces.append(grid_quad(base, e1, e2, step, normal))
    return np.concatenate(faces)


def abox(x0, y0, x1, y1, z0, z1, step=None) -> np.ndarray:
    """Axis-aligned closed box."""
    return cuboid((x0, y0, z0), (x1 - x0, 0, 0), (0, y1 - y0, 0), (0, 0, z1 - z0), step)


def obox(cx, cy, length, depth, z0, z1, yaw_deg=0.0) -> np.ndarray:
    """Closed box centred on (cx, cy), ``length`` along the direction ``yaw_deg`` from +x."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    a = np.array([c, s, 0.0]) * length
    b = np.array([-s, c, 0.0]) * depth
    o = np.array([cx, cy, z0]) - a / 2 - b / 2
    return cuboid(o, a, b, (0, 0, z1 - z0))


def polygon_faces(poly, z, up: bool, step=None) -> np.ndarray:
    """Horizontal triangles covering ``poly`` (holes allowed) at height z, facing up or down.

    With ``step`` the polygon is cut into grid cells of that size first (a slab triangulated on a grid).
    """
    pieces = [poly]
    if step is not None:
        x0, y0, x1, y1 = poly.bounds
        pieces = []
        for i in range(math.floor(x0 / step), math.ceil(x1 / step)):
            for j in range(math.floor(y0 / step), math.ceil(y1 / step)):
                cell = poly.intersection(rect(i * step, j * step, (i + 1) * step, (j + 1) * step))
                pieces += [g for g in getattr(cell, "geoms", [cell]) if isinstance(g, Polygon) and g.area > 1e-9]
    tris = []
    for piece in pieces:
        for t in shapely.constrained_delaunay_triangles(piece).geoms:
            xy = np.asarray(t.exterior.coords)[:3]
            if abs(Polygon(xy).area) < 1e-10:
                continue
            tri = np.column_stack([xy, np.full(3, z)])
            n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            if (n[2] > 0) != up:
                tri = tri[[0, 2, 1]]
            tris.append(tri)
    return np.array(tris).reshape(-1, 3, 3)


def rot_z(tris: np.ndarray, deg: float, about=(0.0, 0.0)) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    o = np.array([about[0], about[1], 0.0])
    return (tris - o) @ r.T + o


def rot_xy(p, deg: float):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return [c * p[0] - s * p[1], s * p[0] + c * p[1]]


# ============================================================================ furniture (CLUTTER)
def table(x0, y0, x1, y1, h=0.75, leg=0.05) -> np.ndarray:
    """Table top (4 cm) on four legs."""
    parts = [abox(x0, y0, x1, y1, h - 0.04, h)]
    i = 0.03
    for lx, ly in ((x0 + i, y0 + i), (x1 - i - leg, y0 + i), (x0 + i, y1 - i - leg), (x1 - i - leg, y1 - i - leg)):
        parts.append(abox(lx, ly, lx + leg, ly + leg, 0.0, h - 0.04))
    return np.concatenate(parts)


def chair(cx, cy, facing_deg) -> np.ndarray:
    """Chair: seat, four legs and a back on the side opposite to ``facing``."""
    seat, leg = 0.44, 0.03
    parts = [obox(cx, cy, seat, seat, 0.42, 0.46, facing_deg)]
    c, s = math.cos(math.radians(facing_deg)), math.sin(math.radians(facing_deg))
    fwd, left = np.array([c, s]), np.array([-s, c])
    for a in (-1, 1):
        for b in (-1, 1):
            p = np.array([cx, cy]) + fwd * a * (seat / 2 - 0.04) + left * b * (seat / 2 - 0.04)
            parts.append(obox(p[0], p[1], leg, leg, 0.0, 0.42, facing_deg))
    back = np.array([cx, cy]) - fwd * (seat / 2 - 0.02)
    parts.append(obox(back[0], back[1], 0.04, seat, 0.46, 0.9, facing_deg))
    return np.concatenate(parts)


def sofa(x0, y0, x1, y1, back: str) -> np.ndarray:
    """Sofa: seat block, a back rest on side ``back`` (+x, -x, +y, -y) and two arms."""
    parts = [abox(x0, y0, x1, y1, 0.0, 0.42)]
    d = 0.2
    if back in ("+y", "-y"):
        by0, by1 = (y1 - d, y1) if back == "+y" else (y0, y0 + d)
        parts += [
            abox(x0, by0, x1, by1, 0.42, 0.85),
            abox(x0, y0, x0 + d, y1, 0.42, 0.62),
            abox(x1 - d, y0, x1, y1, 0.42, 0.62),
        ]
    else:
        bx0, bx1 = (x1 - d, x1) if back == "+x" else (x0, x0 + d)
        parts += [
            abox(bx0, y0, bx1, y1, 0.42, 0.85),
            abox(x0, y0, x1, y0 + d, 0.42, 0.62),
            abox(x0, y1 - d, x1, y1, 0.42, 0.62),
        ]
    return np.concatenate(parts)


def bed(x0, y0, x1, y1, head: str) -> np.ndarray:
    """Bed: frame with mattress (0.5 m) and a 1.0 m headboard on side ``head``."""
    parts = [abox(x0, y0, x1, y1, 0.0, 0.5)]
    k = 0.06
    box = {
        "-x": (x0, y0, x0 + k, y1),
        "+x": (x1 - k, y0, x1, y1),
        "-y": (x0, y0, x1, y0 + k),
        "+y": (x0, y1 - k, x1, y1),
    }[head]
    parts.append(abox(*box, 0.5, 1.0))
    return np.concatenate(parts)


def shelf(x0, y0, x1, y1, h=2.0, boards=5, back: str | None = None) -> np.ndarray:
    """Open shelf unit: two side panels, ``boards`` boards and a back panel (``back`` side, or none)."""
    k = 0.02
    along_x = (x1 - x0) >= (y1 - y0)
    parts = []
    if along_x:
        parts += [abox(x0, y0, x0 + k, y1, 0, h), abox(x1 - k, y0, x1, y1, 0, h)]
    else:
        parts += [abox(x0, y0, x1, y0 + k, 0, h), abox(x0, y1 - k, x1, y1, 0, h)]
    for i in range(boards):
        z = 0.08 + i * (h - 0.1) / (boards - 1)
        parts.append(abox(x0, y0, x1, y1, z - k, z))
    if back is not None:
        box = {
            "-x": (x0, y0, x0 + k, y1),
            "+x": (x1 - k, y0, x1, y1),
            "-y": (x0, y0, x1, y0 + k),
            "+y": (x0, y1 - k, x1, y1),
        }[back]
        parts.append(abox(*box, 0, h))
    return np.concatenate(parts)


def counter(x0, y0, x1, y1) -> np.ndarray:
    """Kitchen base cabinets (0.86 m) with a worktop overhanging 2 cm at the front."""
    return np.concatenate([abox(x0, y0, x1, y1, 0.0, 0.86), abox(x0, y0, x1, y1, 0.86, 0.9)])


def toilet(x0, y0, x1, y1) -> np.ndarray:
    return np.concatenate([abox(x0, y0, x1, y1, 0.0, 0.42), abox(x0, y0, x1, y1, 0.42, 0.45)])


# ============================================================================ model container
@dataclass
class Part:
    name: str  # the part name in the file (OBJ o/g, glTF node)
    cls: int  # SurfaceClass value the name stands for
    room: int  # room number the name carries (-1: none)
    tris: list = field(default_factory=list)
    parent: str | None = None  # glTF parent node
    group_of: str | None = None  # OBJ: an `o` name above this part's `g`
    alt: str | None = None  # an alternative name (u_office without room tags)


class Model:
    def __init__(self) -> None:
        self.parts: dict[str, Part] = {}

    def add(self, name, cls, room, tris, **kw) -> None:
        tris = np.asarray(tris, float).reshape(-1, 3, 3)
        if name not in self.parts:
            self.parts[name] = Part(name, cls, room, [], **kw)
        p = self.parts[name]
        assert (p.cls, p.room) == (cls, room), name
        p.tris.append(tris)

    def items(self):
        for p in self.parts.values():
            yield p, np.concatenate(p.tris)

    def transform(self, fn) -> None:
        for p in self.parts.values():
            p.tris = [fn(np.concatenate(p.tris))]


def indexed(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (deduplicated at 0.1 mm, sorted) and faces of a triangle soup; degenerate faces dropped."""
    flat = np.round(tris.reshape(-1, 3), 4) + 0.0
    v, inv = np.unique(flat, axis=0, return_inverse=True)
    f = inv.reshape(-1, 3)
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    f = f[ok]
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    return v, f[area > 1e-10]


# ============================================================================ walls
class Wall:
    """A straight wall on the centre line a -> b, ``t`` thick, ``h`` high, with openings.

    ``e0``/``e1`` extend the wall past its end points (so that outer corners close: walls overlap,
    as two solids do when drawn in CAD). Openings are given by their centre on the centre line.
    """

    def __init__(self, a, b, t, h, room, e0=0.0, e1=0.0):
        self.a, self.b = np.asarray(a, float), np.asarray(b, float)
        d = self.b - self.a
        self.L = float(np.hypot(*d))
        self.u = d / self.L
        self.n = np.array([-self.u[1], self.u[0]])
        self.t, self.h, self.room, self.e0, self.e1 = t, h, room, e0, e1
        self.ops: list[dict] = []

    def s_of(self, p) -> float:
        return float(np.dot(np.asarray(p, float) - self.a, self.u))

    def _op(self, kind, p, width, z0, z1, **kw) -> dict:
        s = self.s_of(p)
        off = np.linalg.norm(self.a + self.u * s - np.asarray(p, float))
        assert off < 1e-6, f"opening {p} is not on the wall {self.a} -> {self.b}"
        op = dict(kind=kind, s0=s - width / 2, s1=s + width / 2, z0=z0, z1=z1, width=width, wall=self, **kw)
        assert op["s0"] > 0.05 and op["s1"] < self.L - 0.05, f"opening {p} too close to the wall's end"
        for o in self.ops:
            assert op["s1"] <= o["s0"] or op["s0"] >= o["s1"], f"openings overlap at {p}"
        self.ops.append(op)
        return op

    def door(self, p, width, height=2.05, exterior=False, leaf=None, passable=True) -> dict:
        """``leaf``: (hinge 's0'|'s1', swing side +1 (left of a->b) | -1, opening angle in degrees)."""
        return self._op("door", p, width, 0.0, height, exterior=exterior, leaf=leaf, passable=passable)

    def opening(self, p, width, height) -> dict:
        return self._op("opening", p, width, 0.0, height, exterior=False, leaf=None, passable=True)

    def window(self, p, width=1.2, sill=0.9, height=1.2) -> dict:
        return self._op("window", p, width, sill, sill + height)

    def pt(self, s, d, z) -> np.ndarray:
        xy = self.a + self.u * s + self.n * d
        return np.array([xy[0], xy[1], z])

    def vec(self, s, d) -> np.ndarray:
        """A vector s along, d across."""
        xy = self.u * s + self.n * d
        return np.array([xy[0], xy[1], 0.0])

    def pieces(self) -> list[tuple[float, float, float, float]]:
        """(s0, s1, z0, z1) of the solid parts: full-height runs, sills under windows, lintels above."""
        out, cur = [], -self.e0
        for o in sorted(self.ops, key=lambda o: o["s0"]):
            if o["s0"] > cur + 1e-9:
                out.append((cur, o["s0"], 0.0, self.h))
            if o["z0"] > 1e-9:
                out.append((o["s0"], o["s1"], 0.0, o["z0"]))
            if o["z1"] < self.h - 1e-9:
                out.append((o["s0"], o["s1"], o["z1"], self.h))
            cur = o["s1"]
        end = self.L + self.e1
        if end > cur + 1e-9:
            out.append((cur, end, 0.0, self.h))
        return out

    # ---- geometry in the different styles
    def solid(self, step=None) -> np.ndarray:
        """Each piece a closed box (inner, outer, top, bottom, end faces)."""
        t = self.t
        return np.concatenate(
            [
                cuboid(self.pt(s0, -t / 2, z0), self.vec(s1 - s0, 0), self.vec(0, t), (0, 0, z1 - z0), step)
                for s0, s1, z0, z1 in self.pieces()
            ]
        )

    def sheet(self, d=0.0, side=+1) -> list[np.ndarray]:
        """Each piece ONE quad on the line at offset d, facing side (+1: left of a->b)."""
        nrm = np.array([*(self.n * side), 0.0])
        return [
            quad(self.pt(s0, d, z0), self.pt(s1, d, z0), self.pt(s1, d, z1), self.pt(s0, d, z1), nrm)
            for s0, s1, z0, z1 in self.pieces()
        ]

    def footprint(self) -> Polygon:
        t, e0, e1 = self.t, self.e0, self.e1
        pts = [
            self.pt(-e0, -t / 2, 0),
            self.pt(self.L + e1, -t / 2, 0),
            self.pt(self.L + e1, t / 2, 0),
            self.pt(-e0, t / 2, 0),
        ]
        return Polygon([p[:2] for p in pts])

    def threshold(self, op) -> Polygon:
        t = self.t
        pts = [
            self.pt(op["s0"], -t / 2, 0),
            self.pt(op["s1"], -t / 2, 0),
            self.pt(op["s1"], t / 2, 0),
            self.pt(op["s0"], t / 2, 0),
        ]
        return Polygon([p[:2] for p in pts])

    def pane(self, op, thickness=0.02) -> np.ndarray:
        """The window glass: a thin box in the middle of the wall (a quad when thickness is 0)."""
        s0, s1, z0, z1 = op["s0"], op["s1"], op["z0"], op["z1"]
        if thickness == 0:
            return quad(self.pt(s0, 0, z0), self.pt(s1, 0, z0), self.pt(s1, 0, z1), self.pt(s0, 0, z1))
        return cuboid(self.pt(s0, -thickness / 2, z0), self.vec(s1 - s0, 0), self.vec(0, thickness), (0, 0, z1 - z0))

    def leaf(self, op, thickness=0.04) -> np.ndarray:
        """The door leaf, hinged at a jamb on the face of the swing side, opened by ``angle`` degrees."""
        hinge, side, angle = op["leaf"]
        s_h = op["s0"] if hinge == "s0" else op["s1"]
        closed = self.u * (1 if hinge == "s0" else -1)
        ns = self.n * side
        th = math.radians(angle)
        w = closed * math.cos(th) + ns * math.sin(th)
        k = (ns - closed) - np.dot(ns - closed, w) * w
        k = k / np.linalg.norm(k)
        w3, k3 = np.array([*w, 0.0]), np.array([*k, 0.0])
        origin = self.pt(s_h, side * self.t / 2, 0.01) + 0.01 * w3 + 0.005 * k3
        length = op["width"] - 0.03
        return cuboid(origin, w3 * length, k3 * thickness, (0, 0, op["z1"] - 0.02))

    def centre(self, op) -> list[float]:
        p = self.a + self.u * (op["s0"] + op["s1"]) / 2
        return [float(p[0]), float(p[1])]


def clear_polygons(room_lines: dict[int, list], walls: list[Wall]) -> dict[int, Polygon]:
    """Each room's clear floor: its centre-line polygon less every wall's footprint (largest piece)."""
    solid = shapely.union_all([w.footprint() for w in walls])
    out = {}
    for r, pts in room_lines.items():
        g = Polygon(pts).difference(solid)
        pieces = [p for p in getattr(g, "geoms", [g]) if isinstance(p, Polygon)]
        out[r] = shapely.geometry.polygon.orient(max(pieces, key=lambda p: p.area).simplify(1e-6), 1.0)
    return out


def door_entries(walls: list[Wall], rotate: float = 0.0, to_frame=None) -> list[dict]:
    out = []
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            if op["kind"] not in ("door", "opening"):
                continue
            c = w.centre(op)
            if rotate:
                c = rot_xy(c, rotate)
            e = {"centre": [round(c[0], 3), round(c[1], 3)], "width": op["width"], "exterior": bool(op["exterior"])}
            e["height"] = op["z1"]
            if op["kind"] == "opening":
                e["kind"] = "opening"
            if op.get("leaf") is not None:
                e["leaf_open_deg"] = op["leaf"][2]
            if not op["passable"]:
                e["passable"] = False
            out.append(e)
    return out


def add_openings(m: Model, walls: list[Wall], name_of, pane_thickness=0.02, thresholds=True) -> None:
    """Window panes, door leaves and (for thick walls) the floor strips under door openings."""
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            if op["kind"] == "window":
                m.add(name_of("window", w.room, k), WINDOW, w.room, w.pane(op, pane_thickness))
            else:
                if op.get("leaf") is not None:
                    m.add(name_of("door", w.room, k), DOOR, w.room, w.leaf(op))
                if thresholds and w.t > 0:
                    m.add(f"floor_threshold_{k}", FLOOR, -1, polygon_faces(w.threshold(op), 0.0, True))


# ============================================================================ writers
def write_obj(path: Path, m: Model, header: str, keyword: str = "o", use_alt: bool = False) -> None:
    """OBJ with `o` (or `g`) per part; parts with ``group_of`` get `o group_of` + `g name`."""
    lines = [f"# {line}" for line in header.splitlines()]
    vlines, flines, base, current_o = [], [], 0, None
    for p, tris in m.items():
        v, f = indexed(tris)
        vlines += [f"v {x:.4f} {y:.4f} {z:.4f}" for x, y, z in v.tolist()]
        name = p.alt if use_alt else p.name
        if p.group_of is not None:
            if p.group_of != current_o:
                flines.append(f"o {p.group_of}")
                current_o = p.group_of
            flines.append(f"g {name}")
        else:
            flines.append(f"{keyword} {name}")
            current_o = name if keyword == "o" else current_o
        flines += [f"f {a + base + 1} {b + base + 1} {c + base + 1}" for a, b, c in f.tolist()]
        base += len(v)
    path.write_text("\n".join(lines + vlines + flines) + "\n", encoding="ascii")


def write_ply(path: Path, m: Model, comment: str) -> None:
    """One merged mesh, binary little endian, per-face uchar ``label`` and int ``room``."""
    tris, labels, rooms = [], [], []
    for p, t in m.items():
        tris.append(t)
        labels.append(np.full(len(t), p.cls))
        rooms.append(np.full(len(t), p.room))
    t = np.concatenate(tris)
    flat = np.round(t.reshape(-1, 3), 4) + 0.0
    v, inv = np.unique(flat, axis=0, return_inverse=True)
    f = inv.reshape(-1, 3)
    lab, rm = np.concatenate(labels), np.concatenate(rooms)
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    f, lab, rm = f[ok], lab[ok], rm[ok]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        + "".join(f"comment {c}\n" for c in comment.splitlines())
        + f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nproperty uchar label\nproperty int room\n"
        "end_header\n"
    )
    rec = np.zeros(len(f), dtype=[("n", "u1"), ("vi", "<i4", (3,)), ("label", "u1"), ("room", "<i4")])
    rec["n"], rec["vi"], rec["label"], rec["room"] = 3, f, lab, rm
    with path.open("wb") as out:
        out.write(header.encode("ascii"))
        out.write(np.ascontiguousarray(v, dtype="<f4").tobytes())
        out.write(rec.tobytes())


def write_glb(path: Path, m: Model, parents: list[str] = (), y_up: bool = False) -> None:
    """One glTF node (and mesh of the same name) per part; optional empty parent nodes."""
    sc = trimesh.Scene()
    for name in parents:
        sc.graph.update(frame_from=sc.graph.base_frame, frame_to=name, matrix=np.eye(4))
    for p, tris in m.items():
        if y_up:  # z-up (x, y, z) -> glTF y-up (x, z, -y)
            tris = tris[..., [0, 2, 1]] * np.array([1.0, 1.0, -1.0])
        v, f = indexed(tris)
        mesh = trimesh.Trimesh(v, f, process=False, validate=False)
        sc.add_geometry(mesh, node_name=p.name, geom_name=p.name, parent_node_name=p.parent)
    path.write_bytes(sc.export(file_type="glb"))


# ============================================================================ scene 1: corridor_flat
def corridor_flat():
    """Thick wall solids (outer faces too, corners overlapping), one glTF node per wall."""
    H, TE, TI = 2.6, 0.3, 0.2
    m = Model()
    rooms = {  # centre-line outlines; room1 is the corridor
        1: [(0, 3.9), (10.5, 3.9), (10.5, 5.5), (0, 5.5)],
        2: [(0, 0), (5, 0), (5, 3.9), (0, 3.9)],
        3: [(5, 0), (10.5, 0), (10.5, 3.9), (5, 3.9)],
        4: [(0, 5.5), (5.5, 5.5), (5.5, 9), (0, 9)],
        5: [(5.5, 5.5), (10.5, 5.5), (10.5, 9), (5.5, 9)],
        6: [(10.5, 0), (14.5, 0), (14.5, 9), (10.5, 9)],
    }
    e = TE / 2
    W = Wall
    walls = [
        # corridor (room1): both long walls, the end wall with the door to the living room, the west end
        W((0, 3.9), (10.5, 3.9), TI, H, 1),
        W((0, 5.5), (10.5, 5.5), TI, H, 1),
        W((10.5, 3.9), (10.5, 5.5), TI, H, 1),
        W((0, 3.9), (0, 5.5), TE, H, 1),
        # bedroom (room2)
        W((0, 0), (5, 0), TE, H, 2, e0=e),
        W((0, 0), (0, 3.9), TE, H, 2, e0=e),
        W((5, 0), (5, 3.9), TI, H, 2),
        # kitchen (room3)
        W((5, 0), (10.5, 0), TE, H, 3),
        W((10.5, 0), (10.5, 3.9), TI, H, 3),
        # bedroom 2 (room4)
        W((0, 5.5), (0, 9), TE, H, 4, e1=e),
        W((0, 9), (5.5, 9), TE, H, 4, e0=e),
        W((5.5, 5.5), (5.5, 9), TI, H, 4),
        # study (room5)
        W((5.5, 9), (10.5, 9), TE, H, 5),
        W((10.5, 5.5), (10.5, 9), TI, H, 5),
        # living room at the corridor's end (room6)
        W((10.5, 0), (14.5, 0), TE, H, 6, e1=e),
        W((14.5, 0), (14.5, 9), TE, H, 6, e0=e, e1=e),
        W((10.5, 9), (14.5, 9), TE, H, 6, e1=e),
    ]
    (cs, cn, cend, cw, s2, w2, _p23, s3, _p36, _w4, n4, _p45, n5, _p56, s6, e6, _n6) = walls
    # doors along the corridor: hinge jamb, swing side (+1 = left of the wall's a->b), angle
    cs.door((3.8, 3.9), 1.0, leaf=("s1", -1, 90))  # bedroom, leaf at 90 deg beside the opening
    cs.door((6.2, 3.9), 0.95, leaf=("s1", -1, 180))  # kitchen, leaf flat against the wall
    cn.door((4.5, 5.5), 1.0, leaf=("s0", +1, 90))  # bedroom 2
    cn.door((9.0, 5.5), 0.95, leaf=("s1", +1, 90))  # study
    cend.door((10.5, 4.7), 1.0, leaf=("s1", -1, 180))  # living room: leaf against the living room's west wall
    cw.window((0, 4.7), width=0.8)
    s2.window((2.5, 0))
    w2.window((0, 2.0))
    s3.window((8.0, 0))
    n4.window((2.7, 9))
    n5.window((8.0, 9))
    e6.window((14.5, 2.0))
    e6.window((14.5, 7.0))
    s6.window((12.5, 0))

    for k, w in enumerate(walls):
        m.add(f"wall_room{w.room}_{k}", WALL, w.room, w.solid())
    add_openings(m, walls, lambda c, r, k: f"{c}_room{r}_{k}")
    clear = clear_polygons(rooms, walls)
    for r, poly in clear.items():
        m.add(f"floor_room{r}", FLOOR, r, polygon_faces(poly, 0.0, True))
        m.add(f"ceiling_room{r}", CEILING, r, polygon_faces(poly, H, False))

    def cl(room, what, tris):
        m.add(f"clutter_room{room}_{what}", CLUTTER, room, tris)

    # bedroom (clear x 0.15..4.9, y 0.15..3.8)
    cl(2, "bed", bed(0.15, 1.0, 2.15, 2.6, "-x"))
    cl(2, "nightstand_a", abox(0.15, 0.5, 0.55, 0.9, 0, 0.5))
    cl(2, "nightstand_b", abox(0.15, 2.7, 0.55, 3.1, 0, 0.5))
    cl(2, "wardrobe", abox(2.8, 0.15, 4.8, 0.75, 0, 2.1))
    # kitchen (clear x 5.1..10.4, y 0.15..3.8): counters along the outside wall, wall cabinets, table
    cl(3, "counter", counter(5.1, 0.15, 10.4, 0.75))
    cl(3, "wall_cabinets_a", abox(5.1, 0.15, 7.2, 0.5, 1.45, 2.15))
    cl(3, "wall_cabinets_b", abox(8.8, 0.15, 10.4, 0.5, 1.45, 2.15))
    cl(3, "fridge", abox(9.75, 2.8, 10.4, 3.5, 0, 1.9))
    cl(3, "table", table(7.3, 2.0, 8.7, 2.8))
    cl(3, "chair_a", chair(7.7, 3.2, -90))
    cl(3, "chair_b", chair(8.3, 3.2, -90))
    # bedroom 2 (clear x 0.15..5.4, y 5.6..8.85)
    cl(4, "bed", bed(1.0, 6.85, 2.6, 8.85, "+y"))
    cl(4, "wardrobe", abox(0.15, 5.7, 0.75, 7.5, 0, 2.0))
    cl(4, "desk", table(4.8, 7.3, 5.4, 8.7))
    cl(4, "chair", chair(4.45, 8.0, 0))
    # study (clear x 5.6..10.4, y 5.6..8.85)
    for i, x in enumerate((5.8, 6.8, 7.8, 8.8)):
        cl(5, f"bookshelf_{i}", shelf(x, 8.5, x + 1.0, 8.85, 2.0, 5, "+y"))
    cl(5, "desk", table(5.6, 6.0, 7.2, 6.8))
    cl(5, "chair", chair(6.4, 7.2, -90))
    cl(5, "sofa", sofa(9.55, 6.6, 10.4, 8.3, "+x"))
    # living room (clear x 10.6..14.35, y 0.15..8.85)
    cl(6, "sofa", sofa(13.45, 2.5, 14.35, 4.7, "+x"))
    cl(6, "coffee_table", table(12.2, 3.0, 13.0, 4.2, h=0.45))
    cl(6, "tv_cabinet", abox(10.6, 2.6, 11.05, 4.0, 0, 0.6))
    cl(6, "dining_table", table(11.6, 6.6, 13.4, 7.5))
    cl(6, "dining_chair_a", chair(12.1, 8.0, -90))
    cl(6, "dining_chair_b", chair(12.9, 8.0, -90))
    cl(6, "shelf", shelf(13.0, 8.5, 14.3, 8.85, 2.0, 5, "+y"))

    write_glb(OUT / "corridor_flat.glb", m)
    return {
        "name": "corridor_flat",
        "file": "corridor_flat.glb",
        "options": {},
        "styles": [
            "glb",
            "z-up",
            "thick-wall-solids",
            "outer-faces",
            "overlapping-corners",
            "node-per-wall",
            "room-tags-in-node-names",
        ],
        "description": (
            "A flat of five rooms off a 10.25 m x 1.4 m corridor (two bedrooms, kitchen, study on its sides, the "
            "living room at its end), five doors along it. Walls are closed box solids (inner, outer, top, bottom and "
            "end faces; exterior 0.3 m, interior 0.2 m) split around openings, overlapping at corners; one glTF node "
            "per wall, named wall_room<N>_<k>; corridor walls belong to the corridor (room1), each partition to one "
            "of its two rooms. Floor strips under door openings are floor_threshold_<k> (no room). Door leaves: three "
            "at 90 deg beside the opening, two flat against the wall. Ceiling 2.6 m, doors 2.05 m high."
        ),
        "_clear": clear,
        "_walls": walls,
        "start": [12.2, 5.6],
    }


# ============================================================================ scene 2: u_office
def u_office():
    """Zero-thickness walls: ONE quad (2 triangles) per wall piece; two files with and without room tags."""
    HU, HO = 3.0, 2.7
    m = Model()
    rooms = {
        0: [(0, 0), (10, 0), (10, 8), (7, 8), (7, 3), (3, 3), (3, 8), (0, 8)],  # the U
        1: [(2.5, -4), (7.5, -4), (7.5, 0), (2.5, 0)],  # the office
    }
    W = Wall
    walls = [
        W((0, 0), (2.5, 0), 0, HU, 0),
        W((2.5, 0), (7.5, 0), 0, HU, 0),  # between U and office
        W((7.5, 0), (10, 0), 0, HU, 0),
        W((10, 0), (10, 8), 0, HU, 0),
        W((10, 8), (7, 8), 0, HU, 0),
        W((7, 8), (7, 3), 0, HU, 0),
        W((7, 3), (3, 3), 0, HU, 0),
        W((3, 3), (3, 8), 0, HU, 0),
        W((3, 8), (0, 8), 0, HU, 0),
        W((0, 8), (0, 0), 0, HU, 0),
        W((2.5, -4), (7.5, -4), 0, HO, 1),
        W((7.5, -4), (7.5, 0), 0, HO, 1),
        W((2.5, 0), (2.5, -4), 0, HO, 1),
    ]
    walls[1].door((5.0, 0), 1.0, leaf=("s0", -1, 90))  # office door: leaf at 90 deg into the office
    walls[3].window((10, 1.5))
    walls[3].window((10, 5.5))
    walls[4].window((8.5, 8))
    walls[5].window((7, 5.5))
    walls[7].window((3, 5.5))
    walls[8].window((1.5, 8))
    walls[9].window((0, 5.5))
    walls[9].window((0, 1.5))
    walls[10].window((4.0, -4))
    walls[10].window((6.3, -4))
    walls[11].window((7.5, -2.0))

    def names(cls, room, tag):
        return f"{cls}_room{room}_{tag}", f"{cls}_{tag}"

    for k, w in enumerate(walls):
        n_room, n_plain = names("wall", w.room, k)
        for q in w.sheet():
            m.add(n_room, WALL, w.room, q, alt=n_plain)
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            if op["kind"] == "window":
                a, b = names("window", w.room, k)
                m.add(a, WINDOW, w.room, w.pane(op, 0), alt=b)
            elif op.get("leaf") is not None:
                a, b = names("door", w.room, k)
                m.add(a, DOOR, w.room, w.leaf(op), alt=b)
    letters = {0: "a", 1: "b"}
    for r, pts in rooms.items():
        poly = Polygon(pts)
        h = HU if r == 0 else HO
        m.add(f"floor_room{r}", FLOOR, r, polygon_faces(poly, 0.0, True), alt=f"floor_{letters[r]}")
        m.add(f"ceiling_room{r}", CEILING, r, polygon_faces(poly, h, False), alt=f"ceiling_{letters[r]}")

    def cl(room, what, tris):
        m.add(f"clutter_room{room}_{what}", CLUTTER, room, tris, alt=f"clutter_{what}")

    # U: workstations along the outer walls of both arms, cabinets on the notch walls, base-bar furniture
    for i, y in enumerate((3.6, 5.8)):
        cl(0, f"desk_w{i}", table(0.0, y, 0.8, y + 1.6))
        cl(0, f"chair_w{i}", chair(1.1, y + 0.8, 180))
        cl(0, f"desk_e{i}", table(9.2, y, 10.0, y + 1.6))
        cl(0, f"chair_e{i}", chair(8.9, y + 0.8, 0))
    cl(0, "cabinet_w", abox(2.55, 4.2, 3.0, 6.2, 0, 1.2))
    cl(0, "cabinet_e", abox(7.0, 4.2, 7.45, 6.2, 0, 1.2))
    cl(0, "shelf_w", shelf(0.0, 7.55, 1.8, 8.0, 2.0, 5, "+y"))
    cl(0, "shelf_e", shelf(8.2, 7.55, 10.0, 8.0, 2.0, 5, "+y"))
    cl(0, "sofa", sofa(3.6, 2.15, 6.4, 3.0, "+y"))
    cl(0, "cabinet_sw", abox(0.0, 0.0, 1.2, 0.45, 0, 0.9))
    cl(0, "cabinet_se", abox(8.8, 0.0, 10.0, 0.45, 0, 0.9))
    # office (x 2.5..7.5, y -4..0)
    cl(1, "desk", table(4.0, -4.0, 5.6, -3.2))
    cl(1, "chair", chair(4.8, -2.8, -90))
    cl(1, "shelf", shelf(2.5, -3.6, 2.9, -1.2, 2.0, 5, "-x"))
    cl(1, "meeting_table", table(6.1, -2.5, 6.9, -1.7))
    cl(1, "meeting_chair", chair(6.5, -1.3, -90))

    hdr = "u_office: a U-shaped room and an office; walls are single zero-thickness quads; z up, metres"
    write_obj(OUT / "u_office.obj", m, hdr + "\nno room tags in any name", "o", use_alt=True)
    write_obj(OUT / "u_office_rooms.obj", m, hdr + "\nthe same geometry and labels, with room tags", "o")
    clear = {r: shapely.geometry.polygon.orient(Polygon(p), 1.0) for r, p in rooms.items()}
    base = {
        "options": {},
        "styles": ["obj", "z-up", "zero-thickness-walls", "single-quad-per-wall-piece", "o-names", "non-convex-room"],
        "doors": door_entries(walls),
        "start": [1.5, 1.5],
        "_clear": clear,
        "_walls": walls,
    }
    desc = (
        "A U-shaped open office (outer 10 x 8 m, arms 3 m wide, 5 m deep; ceiling 3.0 m) and a 5 x 4 m office "
        "beside it (ceiling 2.7 m), one 1.0 m door between them in the middle of the U's base, so that the far ends "
        "of both arms cannot be seen from that door. Walls are zero-thickness single quads (2 triangles per wall "
        "piece, split around the door and windows; window panes coplanar). "
    )
    return [
        dict(
            base,
            name="u_office",
            file="u_office.obj",
            description=desc
            + "No room tags in any name (rooms: 0 counts the file's tagged rooms; a loader that derives rooms "
            "from the free floor finds the same two spaces).",
        ),
        dict(
            base,
            name="u_office_rooms",
            file="u_office_rooms.obj",
            description=desc
            + "The same geometry and per-face classes as u_office.obj, with room tags room0 (U), room1 (office).",
        ),
    ]


# ============================================================================ scene 3: open_plan
def open_plan():
    """Double-sided walls (two quads 1 mm apart, facing away from each other), one merged PLY, rotated 30 deg."""
    H, ROT = 2.7, 30.0
    m = Model()
    # room numbers as a CAD export might leave them (renumbered 0..3 on loading)
    LIV, KIT, BED, BATH = 10, 20, 30, 40
    rooms = {
        LIV: [(0, 0), (6, 0), (6, 5), (0, 5)],
        KIT: [(6, 0), (10, 0), (10, 5), (6, 5)],
        BED: [(0, 5), (4.5, 5), (4.5, 9), (0, 9)],
        BATH: [(4.5, 5), (7, 5), (7, 8), (4.5, 8)],
    }
    W = Wall
    walls = [
        W((0, 0), (6, 0), 0, H, LIV),
        W((6, 0), (10, 0), 0, H, KIT),
        W((10, 0), (10, 5), 0, H, KIT),
        W((10, 5), (7, 5), 0, H, KIT),
        W((7, 5), (7, 8), 0, H, BATH),
        W((7, 8), (4.5, 8), 0, H, BATH),
        W((4.5, 8), (4.5, 9), 0, H, BED),
        W((4.5, 9), (0, 9), 0, H, BED),
        W((0, 9), (0, 5), 0, H, BED),
        W((0, 5), (0, 0), 0, H, LIV),
        W((6, 0), (6, 5), 0, H, LIV),  # living | kitchen, the 3 m opening
        W((0, 5), (4.5, 5), 0, H, BED),  # living | bedroom
        W((4.5, 5), (7, 5), 0, H, BATH),  # living, kitchen | bathroom
        W((4.5, 5), (4.5, 8), 0, H, BED),  # bedroom | bathroom
    ]
    walls[10].opening((6, 2.5), 3.0, 2.1)
    walls[11].door((3.0, 5), 1.0, leaf=("s0", +1, 180))  # bedroom: leaf flat against the bedroom wall
    walls[12].door((5.5, 5), 0.95, leaf=("s0", -1, 90))  # bathroom: opens out into the living room
    walls[0].window((1.5, 0))
    walls[0].window((4.5, 0))
    walls[9].window((0, 2.5))
    walls[1].window((8.0, 0))
    walls[2].window((10, 2.5))
    walls[8].window((0, 7.0))
    walls[7].window((2.25, 9))
    walls[5].window((5.75, 8), width=0.8)
    EPS = 0.0005  # half the 1 mm gap between the two faces of a wall
    for k, w in enumerate(walls):
        for q in w.sheet(+EPS, +1) + w.sheet(-EPS, -1):
            m.add(f"wall{k}", WALL, w.room, q)
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            if op["kind"] == "window":
                s0, s1, z0, z1 = op["s0"], op["s1"], op["z0"], op["z1"]
                for d, side in ((EPS, 1), (-EPS, -1)):
                    nrm = np.array([*(w.n * side), 0.0])
                    m.add(
                        f"window{k}",
                        WINDOW,
                        w.room,
                        quad(w.pt(s0, d, z0), w.pt(s1, d, z0), w.pt(s1, d, z1), w.pt(s0, d, z1), nrm),
                    )
            elif op.get("leaf") is not None:
                m.add(f"door{k}", DOOR, w.room, w.leaf(op))
    for r, pts in rooms.items():
        m.add(f"floor{r}", FLOOR, r, polygon_faces(Polygon(pts), 0.0, True))
        m.add(f"ceiling{r}", CEILING, r, polygon_faces(Polygon(pts), H, False))

    def cl(room, what, tris):
        m.add(f"clutter_{what}", CLUTTER, room, tris)

    # living room (0..6 x 0..5)
    cl(LIV, "sofa", sofa(0.0, 1.2, 0.9, 3.4, "-x"))
    cl(LIV, "coffee_table", table(1.4, 1.8, 2.2, 2.8, h=0.45))
    cl(LIV, "tv_cabinet", abox(1.0, 0.0, 2.6, 0.45, 0, 0.55))
    cl(LIV, "dining_table", table(3.6, 1.4, 5.0, 2.3))
    cl(LIV, "dining_chair_a", chair(4.0, 1.0, 90))
    cl(LIV, "dining_chair_b", chair(4.6, 1.0, 90))
    cl(LIV, "dining_chair_c", chair(4.0, 2.7, -90))
    cl(LIV, "dining_chair_d", chair(4.6, 2.7, -90))
    cl(LIV, "bookshelf", shelf(0.0, 3.8, 0.4, 4.9, 2.0, 5, "-x"))
    # kitchen (6..10 x 0..5): counters along the outside walls (L), wall cabinets, fridge
    cl(KIT, "counter_south", counter(6.6, 0.0, 10.0, 0.6))
    cl(KIT, "counter_east", counter(9.4, 0.6, 10.0, 3.8))
    cl(KIT, "wall_cabinets_south", abox(6.6, 0.0, 7.4, 0.35, 1.45, 2.15))
    cl(KIT, "wall_cabinets_east", abox(9.65, 3.2, 10.0, 3.8, 1.45, 2.15))
    cl(KIT, "fridge", abox(9.35, 4.2, 10.0, 4.9, 0, 1.95))
    cl(KIT, "island", counter(7.3, 2.0, 8.3, 3.0))
    # bedroom (0..4.5 x 5..9)
    cl(BED, "bed", bed(1.2, 7.0, 2.8, 9.0, "+y"))
    cl(BED, "wardrobe", abox(0.0, 5.2, 0.6, 6.8, 0, 2.1))
    cl(BED, "nightstand", abox(2.9, 8.55, 3.35, 9.0, 0, 0.5))
    cl(BED, "desk", table(3.7, 6.4, 4.5, 7.6))
    # bathroom (4.5..7 x 5..8)
    cl(BATH, "bathtub", abox(4.5, 7.25, 6.2, 8.0, 0, 0.55))
    cl(BATH, "toilet", toilet(6.3, 5.9, 7.0, 6.3))
    cl(BATH, "sink", abox(4.5, 6.0, 5.0, 6.6, 0, 0.85))

    m.transform(lambda t: rot_z(t, ROT))
    write_ply(
        OUT / "open_plan.ply",
        m,
        "open_plan: labelled storey, label = SurfaceClass (0 floor 1 ceiling 2 wall 3 door 4 window 5 clutter)\n"
        "room = room number or -1; z up, metres; the building is rotated 30 deg about z",
    )
    clear = {r: shapely.affinity.rotate(Polygon(p), ROT, origin=(0, 0)) for r, p in rooms.items()}
    return {
        "name": "open_plan",
        "file": "open_plan.ply",
        "options": {},
        "styles": [
            "ply",
            "z-up",
            "per-face-label-room",
            "double-sided-walls",
            "rotated-30deg",
            "merged-mesh",
            "wide-opening",
        ],
        "description": (
            "An open-plan living room (6 x 5 m) and kitchen (4 x 5 m, L of counters along the outside walls, an "
            "island) joined by a 3 m wide opening under a lintel at 2.1 m, a bedroom and a bathroom through doors "
            "(1.0 m, 0.95 m). Walls are double-sided: two quads 1 mm apart facing away from each other. One merged "
            "mesh with per-face label and room (room numbers 10, 20, 30, 40, renumbered on loading); the whole "
            "building is rotated 30 deg about z (about the origin). Ceiling 2.7 m."
        ),
        "doors": door_entries(walls, rotate=ROT),
        "start": [round(v, 3) for v in rot_xy((2.8, 3.6), ROT)],
        "_clear": clear,
        "_walls": walls,
        "_rot": ROT,
    }


# ============================================================================ scene 4: enfilade
def enfilade():
    """Thick wall solids under glTF empties room<N>, written y up; an exterior door onto a terrace."""
    H, TE, TI = 3.0, 0.4, 0.2
    m = Model()
    rooms = {
        1: [(0, 0), (6, 0), (6, 5), (0, 5)],  # hall
        2: [(6, 0), (10, 0), (10, 5), (6, 5)],  # room A
        3: [(10, 0), (14, 0), (14, 5), (10, 5)],  # room B, only through A
        4: [(0, 5), (3, 5), (3, 8), (8, 8), (8, 11), (0, 11)],  # room C, L-shaped
    }
    e = TE / 2
    W = Wall
    walls = [
        W((0, 0), (6, 0), TE, H, 1, e0=e),
        W((0, 0), (0, 5), TE, H, 1, e0=e),
        W((3, 5), (6, 5), TE, H, 1),
        W((6, 0), (6, 5), TI, H, 1),  # hall | A
        W((0, 5), (3, 5), TI, H, 1),  # hall | C
        W((6, 0), (10, 0), TE, H, 2),
        W((6, 5), (10, 5), TE, H, 2),
        W((10, 0), (10, 5), TI, H, 2),  # A | B
        W((10, 0), (14, 0), TE, H, 3, e1=e),
        W((14, 0), (14, 5), TE, H, 3, e0=e, e1=e),
        W((10, 5), (14, 5), TE, H, 3, e1=e),
        W((0, 5), (0, 11), TE, H, 4, e1=e),
        W((0, 11), (8, 11), TE, H, 4, e0=e, e1=e),
        W((8, 8), (8, 11), TE, H, 4, e0=e, e1=e),
        W((3, 8), (8, 8), TE, H, 4, e0=e, e1=e),
        W((3, 5), (3, 8), TE, H, 4, e1=e),
    ]
    hs, hw, hn, hA, hC, As, An, AB, Bs, Be, Bn, Cw, Cn, Ce, Cs, _Cx = walls
    hs.door((3.0, 0), 1.0, height=2.1, exterior=True, leaf=("s0", +1, 45))  # front door, half open inwards
    hA.door((6, 2.5), 1.0, height=2.1, leaf=("s0", -1, 180))
    AB.door((10, 2.5), 1.0, height=2.1, leaf=("s1", -1, 90))
    hC.door((1.5, 5), 1.0, height=2.1, leaf=("s0", +1, 90))
    hs.window((1.2, 0), width=1.0)
    hs.window((4.8, 0), width=1.0)
    hw.window((0, 2.5))
    hn.window((4.5, 5))
    As.window((8, 0))
    An.window((8, 5))
    Bs.window((12, 0))
    Be.window((14, 2.5))
    Bn.window((12.9, 5), width=1.0)
    Cw.window((0, 8))
    Cn.window((1.5, 11))
    Cn.window((5.5, 11))
    Ce.window((8, 9.5))
    Cs.window((5.5, 8))

    tags = {1: "h", 2: "a", 3: "b", 4: "c"}
    for k, w in enumerate(walls):
        m.add(f"wall_{tags[w.room]}{k}", WALL, w.room, w.solid(), parent=f"room{w.room}")
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            par = f"room{w.room}"
            if op["kind"] == "window":
                m.add(f"window_{tags[w.room]}{k}", WINDOW, w.room, w.pane(op), parent=par)
            else:
                if op.get("leaf") is not None:
                    m.add(f"door_{tags[w.room]}{k}", DOOR, w.room, w.leaf(op), parent=par)
                m.add(f"floor_threshold_{k}", FLOOR, -1, polygon_faces(w.threshold(op), 0.0, True))
    clear = clear_polygons(rooms, walls)
    for r, poly in clear.items():
        m.add(f"floor_{tags[r]}", FLOOR, r, polygon_faces(poly, 0.0, True), parent=f"room{r}")
        m.add(f"ceiling_{tags[r]}", CEILING, r, polygon_faces(poly, H, False), parent=f"room{r}")
    # the terrace outside the front door: a 3 x 4 m slab, no walls, no ceiling, in no room
    m.add("floor_terrace", FLOOR, -1, abox(1.5, -4.2, 4.5, -0.2, -0.18, 0.0))

    def cl(room, what, tris):
        m.add(f"clutter_{tags[room]}_{what}", CLUTTER, room, tris, parent=f"room{room}")

    # hall (clear x 0.2..5.9, y 0.2..4.9)
    cl(1, "console", abox(0.2, 1.6, 0.6, 3.4, 0, 0.85))
    cl(1, "bench", abox(3.3, 4.35, 5.3, 4.8, 0, 0.45))
    cl(1, "table", table(3.3, 2.8, 4.5, 3.6))
    cl(1, "coat_cabinet", abox(5.4, 0.2, 5.9, 1.3, 0, 2.0))
    # room A (clear x 6.1..9.9, y 0.2..4.8): the enfilade axis y = 2.5 kept free
    cl(2, "dining_table", table(7.1, 3.5, 8.9, 4.4))
    for i, x in enumerate((7.6, 8.4)):
        cl(2, f"chair_{i}", chair(x, 3.15, 90))
    cl(2, "sideboard", abox(6.8, 0.2, 9.2, 0.65, 0, 0.85))
    # room B (clear x 10.1..13.8, y 0.2..4.8)
    cl(3, "bed", bed(11.4, 2.8, 13.0, 4.8, "+y"))
    cl(3, "wardrobe", abox(12.6, 0.2, 13.8, 0.8, 0, 2.2))
    cl(3, "desk", table(10.1, 0.2, 11.3, 0.9))
    # room C (clear x 0.2..2.8 by y 5.1..10.8, the arm x 2.8..7.8 by y 8.2..10.8)
    cl(4, "piano", abox(0.2, 6.4, 0.8, 7.9, 0, 1.3))
    cl(4, "sofa", sofa(4.0, 9.9, 6.0, 10.8, "+y"))
    cl(4, "shelves", shelf(4.0, 8.2, 7.5, 8.55, 1.2, 3, "-y"))
    cl(4, "armchair", sofa(7.0, 9.2, 7.8, 10.0, "+x"))

    write_glb(OUT / "enfilade.glb", m, parents=[f"room{r}" for r in rooms], y_up=True)
    return {
        "name": "enfilade",
        "file": "enfilade.glb",
        "options": {"y_up": True},
        "styles": [
            "glb",
            "y-up",
            "thick-wall-solids",
            "room-empties-as-parents",
            "exterior-door",
            "terrace",
            "l-shaped-room",
            "enfilade",
        ],
        "description": (
            "An old-town flat: a hall with the front door (an exterior opening, its leaf half open inwards at 45 deg) "
            "onto a 3 x 4 m terrace slab outside (floor_terrace: floor-labelled, in no room, no walls, no ceiling), "
            "windows to the outside, room A off the hall and room B reachable only through room A (the doors on one "
            "axis, an enfilade), and an L-shaped room C off the hall whose arm cannot be seen from its door. Walls "
            "are box solids (0.4 m outside, 0.2 m inside), ceiling 3.0 m, doors 2.1 m. Written Y-UP ((x, y, z) -> "
            "(x, z, -y)): load with y_up=True. Room tags come from empty parent nodes room1..room4 (children named "
            "wall_h0, floor_h, ... without room tokens)."
        ),
        "doors": door_entries(walls),
        "start": [1.8, 2.0],
        "_clear": clear,
        "_walls": walls,
    }


# ============================================================================ scene 5: stairwell
def stairwell():
    """Box walls with every face on a 0.5 m grid; a real floor slab with a stair well, a ceiling slab above."""
    H, SLAB, TOP, TE, TI, G = 2.6, 0.3, 0.3, 0.25, 0.2, 0.5
    STOREY = H + TOP
    m = Model()
    rooms = {
        1: [(0, 0), (8, 0), (8, 5), (0, 5)],  # hall with the stair well
        2: [(0, 5), (4, 5), (4, 9), (0, 9)],
        3: [(4, 5), (8, 5), (8, 9), (4, 9)],
    }
    e = TE / 2
    W = Wall
    walls = [
        W((0, 0), (8, 0), TE, H, 1, e0=e, e1=e),
        W((8, 0), (8, 5), TE, H, 1),
        W((0, 0), (0, 5), TE, H, 1),
        W((0, 5), (8, 5), TI, H, 1),  # hall | rooms
        W((0, 5), (0, 9), TE, H, 2, e1=e),
        W((0, 9), (4, 9), TE, H, 2, e0=e),
        W((4, 5), (4, 9), TI, H, 2),
        W((4, 9), (8, 9), TE, H, 3, e1=e),
        W((8, 5), (8, 9), TE, H, 3, e1=e),
    ]
    hs, he, hw, hn, w2, n2, _p23, n3, e3 = walls
    hn.door((2.0, 5), 1.0, leaf=("s0", +1, 90))
    hn.door((6.0, 5), 1.0, leaf=("s1", +1, 180))
    hs.window((1.0, 0))
    hs.window((6.6, 0))
    hw.window((0, 3.8))
    he.window((8, 3.5))
    n2.window((2.0, 9))
    w2.window((0, 7.0))
    n3.window((6.0, 9))
    e3.window((8, 7.0))
    for k, w in enumerate(walls):
        m.add(f"wall_room{w.room}_{k}", WALL, w.room, w.solid(step=G))
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            if op["kind"] == "window":
                m.add(f"window_room{w.room}_{k}", WINDOW, w.room, w.pane(op))
            else:
                m.add(f"door_room{w.room}_{k}", DOOR, w.room, w.leaf(op))
                m.add("floor_thresholds", FLOOR, -1, polygon_faces(w.threshold(op), 0.0, True, step=G))

    clear = clear_polygons(rooms, walls)
    HX0, HX1, HY0, HY1 = 2.0, 4.5, 1.6, 2.8  # the well: 2.5 x 1.2 m, in the floor and in the ceiling
    hole = rect(HX0, HY0, HX1, HY1)
    outline = shapely.union_all([w.footprint() for w in walls] + [Polygon(p) for p in rooms.values()])
    outline = Polygon(outline.exterior)
    for r, poly in clear.items():
        floor = poly.difference(hole) if r == 1 else poly
        m.add(f"floor_room{r}", FLOOR, r, polygon_faces(floor, 0.0, True, step=G))
        m.add(f"ceiling_room{r}", CEILING, r, polygon_faces(floor, H, False, step=G))

    def vertical_ring(poly, z0, z1, inward: bool):
        """Grid-triangulated vertical faces along a polygon's exterior, facing out (or into a hole)."""
        pts = np.asarray(shapely.geometry.polygon.orient(poly, 1.0).exterior.coords)
        out = []
        for p, q in itertools.pairwise(pts):
            d = q - p
            nrm = np.array([d[1], -d[0], 0.0]) * (-1 if inward else 1)
            out.append(grid_quad((*p, z0), (*d, 0), (0, 0, z1 - z0), G, nrm))
        return np.concatenate(out)

    # floor slab: the top is the rooms' floors (above), the underside and edges are slab (clutter)
    m.add("clutter_slab_underside", CLUTTER, -1, polygon_faces(outline.difference(hole), -SLAB, False, step=G))
    m.add("clutter_slab_edge", CLUTTER, -1, vertical_ring(outline, -SLAB, 0.0, False))
    m.add("clutter_stairwell_floor_hole_sides", CLUTTER, -1, vertical_ring(hole, -SLAB, 0.0, True))
    # ceiling slab above: its top is the next storey's floor (clutter here), the same hole
    m.add("clutter_ceiling_slab_top", CLUTTER, -1, polygon_faces(outline.difference(hole), STOREY, True, step=G))
    m.add("clutter_ceiling_slab_edge", CLUTTER, -1, vertical_ring(outline, H, STOREY, False))
    m.add("clutter_stairwell_ceiling_hole_sides", CLUTTER, -1, vertical_ring(hole, H, STOREY, True))

    # stairs: 16 risers per storey, 0.25 m treads, 1.1 m wide; the down flight starts at the well's west
    # edge and runs east under the slab; the up flight rises westwards from x = 5.75 (its foot on this
    # floor, over the east end of the well) and reaches the next storey at the west edge of the ceiling hole.
    rise, run, y0, y1 = STOREY / 16, 0.25, HY0 + 0.05, HY1 - 0.05
    down, up = [], []
    for k in range(1, 17):
        z = -k * rise
        x0 = HX0 + (k - 1) * run
        down.append(abox(x0, y0, x0 + run, y1, z - 0.2, z))
    foot = HX0 + 15 * run
    for k in range(1, 16):
        z = k * rise
        xa, xb = foot - k * run, foot - (k - 1) * run
        up.append(abox(xa, y0, xb, y1, 0.0 if xa >= HX1 - 1e-9 else z - 0.2, z))
    m.add("clutter_room1_stair_down", CLUTTER, 1, np.concatenate(down))
    m.add("clutter_room1_stair_up", CLUTTER, 1, np.concatenate(up))
    # railing 1.0 m around the well and the foot of the up flight: posts, a top rail and a knee rail
    rx0, rx1, ry0, ry1, p = HX0 - 0.08, foot + 0.05, HY0 - 0.08, HY1 + 0.08, 0.04
    rail = []
    for y in (ry0, ry1):
        for x in np.linspace(rx0, rx1, 5):
            rail.append(abox(x - p / 2, y - p / 2, x + p / 2, y + p / 2, 0, 1.0))
        for z in (0.95, 0.5):
            rail.append(abox(rx0 - p / 2, y - p / 2, rx1 + p / 2, y + p / 2, z, z + 0.05))
    for yy in np.linspace(ry0, ry1, 3)[1:-1]:
        rail.append(abox(rx0 - p / 2, yy - p / 2, rx0 + p / 2, yy + p / 2, 0, 1.0))
    for z in (0.95, 0.5):  # the west side (a closed gate at the head of the down flight)
        rail.append(abox(rx0 - p / 2, ry0, rx0 + p / 2, ry1, z, z + 0.05))
    m.add("clutter_room1_railing", CLUTTER, 1, np.concatenate(rail))

    def cl(room, what, tris):
        m.add(f"clutter_room{room}_{what}", CLUTTER, room, tris)

    cl(1, "cabinet", abox(7.42, 0.4, 7.875, 1.8, 0, 1.1))
    cl(1, "bench", abox(0.125, 0.5, 0.55, 1.9, 0, 0.45))
    # room 2 (clear x 0.125..3.9, y 5.1..8.875)
    cl(2, "table", table(1.2, 6.8, 2.8, 7.7))
    cl(2, "chair_a", chair(1.6, 6.4, 90))
    cl(2, "chair_b", chair(2.4, 6.4, 90))
    cl(2, "shelf", shelf(0.125, 5.6, 0.5, 7.8, 2.0, 5, "-x"))
    cl(2, "cabinet", abox(3.4, 7.5, 3.9, 8.875, 0, 1.0))
    # room 3 (clear x 4.1..7.875, y 5.1..8.875)
    cl(3, "sofa", sofa(5.0, 7.95, 7.2, 8.875, "+y"))
    cl(3, "coffee_table", table(5.6, 6.9, 6.6, 7.4, h=0.45))
    cl(3, "cabinet", abox(7.4, 5.6, 7.875, 7.2, 0, 0.9))

    header = (
        "stairwell: a hall with a stair well and two rooms; walls, floors and ceilings triangulated on a 0.5 m grid\n"
        "z up, metres; groups (g) name the parts"
    )
    write_obj(OUT / "stairwell.obj", m, header, "g")
    return {
        "name": "stairwell",
        "file": "stairwell.obj",
        "options": {},
        "styles": [
            "obj",
            "z-up",
            "wall-solids",
            "0.5m-grid-triangulation",
            "g-names",
            "floor-slab",
            "stair-well",
            "holes-in-floor-and-ceiling",
        ],
        "description": (
            "A hall (8 x 5 m) with a 2.5 x 1.2 m stair well and two rooms off it. Walls are box solids (0.25 m "
            "outside, 0.2 m inside) whose faces, like the floors and ceilings, are triangulated on a 0.5 m grid. "
            "The floor is a real 0.3 m slab: its top is the rooms' floors, its underside (clutter_slab_underside), "
            "its outer edge and the well's four vertical sides are labelled CLUTTER (slab edges, not walls or "
            "floor). The ceiling has the same hole; above it a 0.3 m slab whose top (the next storey's floor) and "
            "sides are CLUTTER too. A straight stair (16 risers of 0.181 m, 0.25 m treads) goes down through the "
            "floor hole and another flight rises from the hall floor (its foot at x 4.5..5.75) through the ceiling "
            "hole; both are CLUTTER steps. A 1.0 m railing (posts, top and knee rails) closes the well and the "
            "foot of the up flight on all sides (a closed gate at the head of the down flight). Rays escape through "
            "the holes (the storey is cut out of a taller building). Ceiling 2.6 m. "
            "floor_area_m2 is the rooms' outlines, the hall's with its 3 m2 well (as the loader's room polygon)."
        ),
        "doors": door_entries(walls),
        "start": [6.6, 3.8],
        "_clear": clear,
        "_walls": walls,
    }


# ============================================================================ scene 6: large_storey
def large_storey():
    """A 24 x 18 m office storey: box walls, one floor slab object split into per-room groups, same for the ceiling."""
    H, TE, TI = 2.8, 0.3, 0.15
    m = Model()
    c45 = 0.3 / 2 * math.tan(math.radians(22.5))  # extension that closes a 135 deg corner of 0.3 m walls
    rooms = {
        1: [(8, 0), (16, 0), (16, 6), (8, 6)],  # entrance hall
        2: [(0, 10), (11, 10), (11, 6), (13, 6), (13, 10), (24, 10), (24, 12), (0, 12)],  # T corridor
        3: [(16, 12), (24, 12), (24, 18), (16, 18)],  # meeting room 8 x 6
        4: [(0, 12), (5, 12), (5, 18), (2.5, 18), (0, 15.5)],  # office with a 45 deg corner cut
        5: [(5, 12), (10.5, 12), (10.5, 18), (5, 18)],  # office
        6: [(10.5, 12), (16, 12), (16, 18), (10.5, 18)],  # storage
        7: [(0, 0), (8, 0), (8, 6), (0, 6)],  # office SW
        8: [(0, 6), (11, 6), (11, 10), (0, 10)],  # office W
        9: [(13, 6), (16, 6), (16, 0), (24, 0), (24, 10), (13, 10)],  # open-plan office, L-shaped
    }
    e = TE / 2
    W = Wall
    walls = [
        # exterior
        W((0, 0), (8, 0), TE, H, 7, e0=e),
        W((8, 0), (16, 0), TE, H, 1),
        W((16, 0), (24, 0), TE, H, 9, e1=e),
        W((24, 0), (24, 10), TE, H, 9, e0=e),
        W((24, 10), (24, 12), TE, H, 2),
        W((24, 12), (24, 18), TE, H, 3, e1=e),
        W((24, 18), (16, 18), TE, H, 3, e0=e),
        W((16, 18), (10.5, 18), TE, H, 6),
        W((10.5, 18), (5, 18), TE, H, 5),
        W((5, 18), (2.5, 18), TE, H, 4, e1=c45),
        W((2.5, 18), (0, 15.5), TE, H, 4, e0=c45, e1=c45),
        W((0, 15.5), (0, 12), TE, H, 4, e0=c45),
        W((0, 12), (0, 10), TE, H, 2),
        W((0, 10), (0, 6), TE, H, 8),
        W((0, 6), (0, 0), TE, H, 7, e1=e),
        # interior
        W((0, 6), (8, 6), TI, H, 7),
        W((8, 6), (11, 6), TI, H, 8),
        W((11, 6), (13, 6), TI, H, 2),
        W((13, 6), (16, 6), TI, H, 9),
        W((8, 0), (8, 6), TI, H, 1),
        W((16, 0), (16, 6), TI, H, 1),
        W((11, 6), (11, 10), TI, H, 2),
        W((13, 6), (13, 10), TI, H, 2),
        W((0, 10), (11, 10), TI, H, 2),
        W((13, 10), (24, 10), TI, H, 2),
        W((0, 12), (5, 12), TI, H, 2),
        W((5, 12), (10.5, 12), TI, H, 2),
        W((10.5, 12), (16, 12), TI, H, 2),
        W((16, 12), (24, 12), TI, H, 2),
        W((5, 12), (5, 18), TI, H, 4),
        W((10.5, 12), (10.5, 18), TI, H, 5),
        W((16, 12), (16, 18), TI, H, 6),
    ]
    (
        xs7,
        xs1,
        xs9,
        xe9,
        xe2,
        xe3,
        xn3,
        _xn6,
        xn5,
        xn4,
        xd4,
        xw4,
        _xw2,
        xw8,
        xw7,
        _i78,
        _i81,
        i12,
        _i19,
        i71,
        i19v,
        _i2w,
        i2e,
        i82,
        i92,
        i24,
        i25,
        i26,
        i23,
        _i45,
        _i56,
        _i63,
    ) = walls
    xs1.door((12, 0), 1.0, height=2.1, exterior=True, leaf=("s0", +1, 90))  # entrance
    i12.door((12, 6), 1.0, height=2.1)  # hall -> corridor stem (a frame without leaf)
    i71.door((8, 3), 1.0, height=2.1, leaf=("s0", +1, 90))
    i19v.door((16, 3), 0.95, height=2.1, leaf=("s1", -1, 180))
    i2e.door((13, 8), 1.0, height=2.1, leaf=("s0", -1, 90))
    i82.door((5.5, 10), 1.0, height=2.1, leaf=("s0", -1, 180))
    i92.door((19, 10), 1.0, height=2.1, leaf=("s1", -1, 90))
    i24.door((2.5, 12), 1.0, height=2.1, leaf=("s0", +1, 90))
    i25.door((7.75, 12), 0.95, height=2.1, leaf=("s1", +1, 180))
    i26.door((13.25, 12), 1.0, height=2.1)
    i23.door((18.0, 12), 1.0, height=2.1, leaf=("s0", +1, 90))
    i23.door((22.0, 12), 1.0, height=2.1, leaf=("s1", +1, 45), passable=False)  # half open: blocks the robot
    for w, ps in (
        (xs7, [(2.5, 0), (5.5, 0)]),
        (xs1, [(9.8, 0), (14.2, 0)]),
        (xs9, [(18, 0), (22, 0)]),
        (xe9, [(24, 3), (24, 7.5)]),
        (xe3, [(24, 14.0), (24, 16.5)]),
        (xn3, [(20, 18)]),
        (xn5, [(7.75, 18)]),
        (xn4, [(3.75, 18)]),
        (xw4, [(0, 13.75)]),
        (xw8, [(0, 8)]),
        (xw7, [(0, 3)]),
    ):
        for p in ps:
            w.window(p)
    xd4.window((1.25, 16.75), width=1.0)
    xe2.window((24, 11), width=0.8)

    for k, w in enumerate(walls):
        m.add(f"wall_room{w.room}_{k}", WALL, w.room, w.solid())
    k = 0
    for w in walls:
        for op in sorted(w.ops, key=lambda o: o["s0"]):
            k += 1
            if op["kind"] == "window":
                m.add(f"window_room{w.room}_{k}", WINDOW, w.room, w.pane(op))
            else:
                if op.get("leaf") is not None:
                    m.add(f"door_room{w.room}_{k}", DOOR, w.room, w.leaf(op))
                m.add("floor_thresholds", FLOOR, -1, polygon_faces(w.threshold(op), 0.0, True), group_of="slab_floor")
    clear = clear_polygons(rooms, walls)
    # ONE floor slab and ONE ceiling, split along the room outlines into per-room groups
    for r, poly in clear.items():
        m.add(f"floor_room{r}", FLOOR, r, polygon_faces(poly, 0.0, True), group_of="slab_floor")
    for r, poly in clear.items():
        m.add(f"ceiling_room{r}", CEILING, r, polygon_faces(poly, H, False), group_of="slab_ceiling")

    def cl(room, what, tris):
        m.add(f"clutter_room{room}_{what}", CLUTTER, room, tris)

    # hall (clear x 8.075..15.925, y 0.15..5.925): keep x 11.3..12.7 free from the entrance to the stem
    cl(1, "reception_desk", np.concatenate([abox(13.2, 3.5, 15.2, 4.2, 0, 1.1), abox(13.2, 4.2, 13.7, 5.0, 0, 1.1)]))
    cl(1, "bench", abox(8.6, 0.15, 10.6, 0.6, 0, 0.45))
    cl(1, "coat_cabinet", abox(8.6, 5.45, 10.6, 5.925, 0, 2.0))
    cl(1, "plant_a", obox(10.8, 4.5, 0.5, 0.5, 0, 1.2, 45))
    # meeting room (clear x 16.075..23.85, y 12.075..17.85)
    cl(3, "table", table(18.0, 14.3, 22.0, 15.7))
    for i, x in enumerate((18.6, 19.6, 20.6, 21.6)):
        cl(3, f"chair_s{i}", chair(x, 13.95, 90))
        cl(3, f"chair_n{i}", chair(x, 16.05, -90))
    cl(3, "sideboard", abox(23.4, 13.5, 23.85, 16.5, 0, 0.9))
    cl(3, "screen_cabinet", abox(16.075, 14.0, 16.5, 16.0, 0, 1.0))
    # office 4 with the corner cut (clear x 0.15..4.925, y 12.075..17.85)
    cl(4, "desk_a", table(4.125, 12.9, 4.925, 14.5))
    cl(4, "desk_b", table(4.125, 14.9, 4.925, 16.5))
    cl(4, "chair_a", chair(3.8, 13.7, 0))
    cl(4, "chair_b", chair(3.8, 15.7, 0))
    n = np.array([1.0, -1.0]) / math.sqrt(2)
    c = np.array([1.25, 16.75]) + n * (0.15 + 0.26)
    cl(4, "cabinet_on_the_cut", obox(c[0], c[1], 1.4, 0.45, 0, 1.2, 45))
    cl(4, "shelf", shelf(0.15, 12.6, 0.55, 14.6, 2.0, 5, "-x"))
    # office 5 (clear x 5.075..10.425, y 12.075..17.85)
    for i, (x0, y0) in enumerate(((6.4, 14.2), (8.0, 14.2), (6.4, 15.0), (8.0, 15.0))):
        cl(5, f"desk_{i}", table(x0, y0, x0 + 1.6, y0 + 0.8))
    cl(5, "chair_0", chair(7.2, 13.8, 90))
    cl(5, "chair_1", chair(8.8, 13.8, 90))
    cl(5, "chair_2", chair(7.2, 16.2, -90))
    cl(5, "chair_3", chair(8.8, 16.2, -90))
    for i, y in enumerate((13.0, 14.0, 15.0, 16.0)):
        cl(5, f"shelf_{i}", shelf(5.075, y, 5.45, y + 1.0, 2.0, 5, "-x"))
    # storage (clear x 10.575..15.925, y 12.075..17.85): many shelves, aisles of 1.1 m
    k = 0
    for y in (13.3, 14.25, 15.2, 16.15, 17.1):  # along the west wall
        k += 1
        cl(6, f"shelf_{k:02d}", shelf(10.575, y, 11.075, y + 0.75 if y > 17 else y + 0.95, 2.2, 6, "-x"))
    for y in (13.3, 14.25, 15.2):  # the double row and the single row
        for x0, x1, back in ((12.175, 12.675, "+x"), (12.675, 13.175, "-x"), (14.275, 14.775, None)):
            k += 1
            cl(6, f"shelf_{k:02d}", shelf(x0, y, x1, y + 0.95, 2.2, 6, back))
    for x in (12.2, 13.2, 14.2):  # along the north wall
        k += 1
        cl(6, f"shelf_{k:02d}", shelf(x, 17.35, x + 1.0, 17.85, 2.2, 6, "+y"))
    # office 7 (clear x 0.15..7.925, y 0.15..5.925)
    cl(7, "desk_a", table(2.4, 2.2, 4.0, 3.0))
    cl(7, "desk_b", table(2.4, 3.0, 4.0, 3.8))
    cl(7, "chair_a", chair(3.2, 1.8, 90))
    cl(7, "chair_b", chair(3.2, 4.2, -90))
    for i, y in enumerate((0.9, 1.9, 2.9, 3.9)):
        cl(7, f"cabinet_{i}", abox(0.15, y, 0.6, y + 0.95, 0, 1.3))
    cl(7, "shelf", shelf(1.0, 5.5, 4.0, 5.925, 2.0, 5, "+y"))
    # office 8 (clear x 0.15..10.925, y 6.075..9.925)
    for i, x in enumerate((1.0, 3.0, 6.8, 8.8)):
        cl(8, f"desk_{i}", table(x, 6.075, x + 1.6, 6.875))
        cl(8, f"chair_{i}", chair(x + 0.8, 7.25, -90))
    cl(8, "cabinets_a", abox(0.6, 9.475, 3.9, 9.925, 0, 1.2))
    cl(8, "cabinets_b", abox(6.8, 9.475, 10.4, 9.925, 0, 1.2))
    # open-plan office 9 (L: x 13.075..23.85 by y 6.075..9.925, and x 16.075..23.85 by y 0.15..6.075)
    for name, (x0, y0) in (("a", (18.0, 2.0)), ("b", (18.0, 6.9))):
        cl(9, f"desks_{name}_0", table(x0, y0, x0 + 1.6, y0 + 0.8))
        cl(9, f"desks_{name}_1", table(x0 + 1.6, y0, x0 + 3.2, y0 + 0.8))
        cl(9, f"desks_{name}_2", table(x0, y0 + 0.8, x0 + 1.6, y0 + 1.6))
        cl(9, f"desks_{name}_3", table(x0 + 1.6, y0 + 0.8, x0 + 3.2, y0 + 1.6))
    cl(9, "printer", abox(23.2, 4.5, 23.85, 5.3, 0, 1.1))
    cl(9, "shelf_a", shelf(16.075, 0.4, 16.5, 2.2, 2.0, 5, "-x"))
    cl(9, "shelf_b", shelf(16.075, 4.6, 16.5, 6.4, 2.0, 5, "-x"))
    cl(9, "kitchenette", counter(13.075, 8.6, 14.8, 9.925))

    header = (
        "large_storey: a 24 x 18 m office storey; box walls; o slab_floor / o slab_ceiling split by g per room\n"
        "z up, metres"
    )
    write_obj(OUT / "large_storey.obj", m, header, "o")
    return {
        "name": "large_storey",
        "file": "large_storey.obj",
        "options": {},
        "styles": [
            "obj",
            "z-up",
            "wall-solids",
            "one-slab-split-per-room",
            "o-and-g-names",
            "large",
            "t-corridor",
            "45deg-corner",
            "l-shaped-room",
            "many-shelves",
        ],
        "description": (
            "A 24 x 18 m office storey of nine rooms: an entrance hall with an exterior door, a T-shaped central "
            "corridor (a 24 m bar and a stem down to the hall), an 8 x 6 m meeting room with two doors (the "
            "second door's leaf is half open at 45 deg and blocks it: the room is reached through the first), a "
            "storage room with 17 shelf units and 1.1 m aisles, an office with a 45 deg corner cut, an L-shaped "
            "open-plan office with two doors, three more offices. Walls are box solids (0.3 m outside, 0.15 m "
            "inside). The floor is ONE object (o slab_floor) split along the room outlines into groups "
            "floor_room<N> (and floor_thresholds under the door openings, no room); the ceiling likewise "
            "(o slab_ceiling, g ceiling_room<N>). Ceiling 2.8 m, doors 2.1 m."
        ),
        "doors": door_entries(walls),
        "start": [12.0, 2.5],
        "_clear": clear,
        "_walls": walls,
    }


# ============================================================================ corpus
def finish(entry: dict) -> dict:
    clear = entry.pop("_clear")
    walls = entry.pop("_walls")
    entry.pop("_rot", None)
    entry.setdefault("doors", door_entries(walls))
    # Room tags in the file (u_office has none: the evaluation derives its rooms from geometry).
    entry["rooms"] = 0 if entry["name"] == "u_office" else len(clear)
    entry["floor_area_m2"] = round(sum(p.area for p in clear.values()), 2)
    order = ["name", "file", "options", "styles", "description", "rooms", "floor_area_m2", "doors", "start"]
    return {k: entry[k] for k in order}


def build() -> list[dict]:
    entries = []
    for fn in (corridor_flat, u_office, open_plan, enfilade, stairwell, large_storey):
        out = fn()
        entries += out if isinstance(out, list) else [out]
    # keep the design polygons for --check before finish() drops them
    design = {e["name"]: e["_clear"] for e in entries}
    manifest = [finish(dict(e)) for e in entries]
    # corpus.json also lists entries this script does not author (IFC storeys, generated edges): keep
    # them, after the meshes, in their order.
    path = OUT / "corpus.json"
    old = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {"entries": []}
    authored = {e["name"] for e in manifest}
    others = [e for e in (old["entries"] if isinstance(old, dict) else old) if e["name"] not in authored]
    data = {"format": "nbs-corpus", "version": 1, "entries": manifest + others}
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return manifest, design


# ============================================================================ checks (print only)
def check(manifest: list[dict], design: dict) -> bool:
    import warnings

    import scenes
    from scenes.geometry import obstacle_footprint, point_is_free
    from scenes.labels import SurfaceClass

    assert [c.value for c in SurfaceClass] == [FLOOR, CEILING, WALL, DOOR, WINDOW, CLUTTER]
    assert [c.name.lower() for c in SurfaceClass] == [CLASS_NAMES[v] for v in range(6)]
    ok = True
    total = 0
    loaded = {}
    for e in manifest:
        path = OUT / e["file"]
        size = path.stat().st_size
        total += size
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            s = scenes.load_scene(str(path), **e["options"])
        loaded[e["name"]] = s
        print(f"== {e['file']}: {size / 1024:.0f} KiB, {len(s.mesh.faces)} faces; {s}")
        problems = []
        file_rooms = 0 if s.metadata.get("rooms") == "derived" else len(s.rooms)
        if file_rooms != e["rooms"]:
            problems.append(f"{file_rooms} rooms loaded from the file, manifest says {e['rooms']}")
        if s.metadata.get("rooms") == "derived":
            print(f"   no room tags in the file; the loader derived {len(s.rooms)} room(s) from the free floor")
        if size >= 1_000_000:
            problems.append("file over 1 MB")
        areas = sum(r.area for r in s.rooms)
        if e["rooms"] and abs(areas - e["floor_area_m2"]) > 0.05 * e["floor_area_m2"]:
            problems.append(f"room polygons cover {areas:.1f} m2, manifest says {e['floor_area_m2']}")
        start = np.array(e["start"], float)
        in_room = [r.name for r in s.rooms if Polygon(r.polygon).contains(Point(*start))]
        if e["rooms"] and not in_room:
            problems.append("start in no room")
        for clearance in (0.45, 0.6):
            if not point_is_free(s, start, 0.0, clearance):
                problems.append(f"start not {clearance} m clear")
        # reachability of every room by a 0.45 m disc: one free component touches every room
        lab = s.face_labels
        tri = s.mesh.vertices[s.mesh.faces]
        flo = (lab == FLOOR) & (np.abs(tri[..., 2]).max(axis=1) < 1e-3)
        polys = shapely.polygons(tri[flo][..., :2])
        region = shapely.union_all(polys[shapely.area(polys) > 1e-10]).buffer(1e-4).buffer(-1e-4)
        obstacles = obstacle_footprint(s, 0.0)
        free = region.buffer(-0.45).difference(obstacles.buffer(0.45))
        comps = [g for g in getattr(free, "geoms", [free]) if g.area > 1e-4]
        home = [g for g in comps if g.buffer(1e-6).contains(Point(*start))]
        if not home:
            problems.append("start not in the free space")
        else:
            for r, poly in design[e["name"]].items():
                # the largest free piece of every room (design outline, loaded frame) is in the start's piece
                inside = poly.intersection(free)
                pieces = [g for g in getattr(inside, "geoms", [inside]) if isinstance(g, Polygon)]
                if not pieces:
                    problems.append(f"room {r} has no free floor for a 0.45 m disc")
                    continue
                big = max(pieces, key=lambda g: g.area)
                if home[0].intersection(big).area < 0.99 * big.area:
                    problems.append(f"room {r} ({big.area:.1f} m2 free) not reachable by a 0.45 m disc from the start")
        for d in e["doors"]:
            c = Point(*d["centre"])
            if not any(r.polygon is not None for r in s.rooms) and e["rooms"]:
                break
            near = min(shapely.distance(c, shapely.geometry.Polygon(r.polygon)) for r in s.rooms) if s.rooms else 0
            if near > 0.3:
                problems.append(f"door {d['centre']} is {near:.2f} m from every room")
        print(f"   rooms {[(r.name, round(r.area, 1), round(r.ceiling_z, 2)) for r in s.rooms]}")
        print(f"   start {e['start']} in {in_room or '-'}; {len(comps)} free component(s)")
        for p in problems:
            print("   PROBLEM:", p)
        ok &= not problems
    a, b = loaded["u_office"], loaded["u_office_rooms"]
    same = np.array_equal(a.face_labels, b.face_labels) and np.allclose(a.mesh.vertices, b.mesh.vertices)
    print(
        f"u_office vs u_office_rooms: labels equal {np.array_equal(a.face_labels, b.face_labels)}, "
        f"geometry equal {np.allclose(a.mesh.vertices, b.mesh.vertices) and np.array_equal(a.mesh.faces, b.mesh.faces)}"
    )
    ok &= bool(same)
    print(f"total {total / 1024:.0f} KiB" + (" (over 4 MB!)" if total >= 4_000_000 else ""))
    ok &= total < 4_000_000
    print("ALL CHECKS PASSED" if ok else "SOME CHECKS FAILED")
    return ok


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="after writing, load and check every file")
    args = ap.parse_args()
    manifest, design = build()
    for e in manifest:
        data = (OUT / e["file"]).read_bytes()
        print(f"wrote {e['file']:22s} {len(data):>8,d} bytes  md5 {hashlib.md5(data).hexdigest()[:12]}")
    if args.check and not check(manifest, design):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
