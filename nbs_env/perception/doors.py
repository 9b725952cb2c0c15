"""Door detection in the SE wall faces of the RoI (METHOD §8), from measured points only.

An opening is an empty rectangle of a wall face's image (points within ±10 cm of the face, 5 cm
pixels) that stands on the floor, is 0.6-4.0 m wide and 1.8-3.0 m high (a lintel was seen above it;
above 2.3 m, METHOD §8's tallest door, a lintel of wall at least 0.25 m deep below the ceiling),
and through which the scanner saw: registered points lie behind the face plane within the opening.
That last test tells a door from the shadow a cabinet casts on the wall behind it.

Two things the robot's own scans do to a door, which the search allows for:

- The lintel is often seen only in stripes. Nothing nearer than the scanner's minimum range
  (1.5 m) is measured, so from a scan taken close to the door the lintel is not seen at all; it
  is then seen only from farther scans, at grazing incidence, where consecutive azimuths land
  several pixels apart on the wall. Columns with no lintel point would cut the opening into pieces
  narrower than a door, so gaps of up to ``fill_gap`` in each row of the face image are filled
  first (an opening itself is at least ``min_width`` wide and stays empty). Where the stripes do
  not share a row (the lintel's lower edge seen a pixel higher or lower from column to column),
  columns empty from the floor to above ``max_height`` may still split the opening: up to
  ``fill_gap`` of them between columns with a lintel count as part of the opening.
  When no scan saw the lintel at all (every scan of the room in front of the face stood nearer
  than the minimum range to it), the empty run of a column goes on up through the pixels no scan
  could measure; the lintel may lie anywhere in them, so the column counts as tall enough when the
  run's highest measurable empty pixel is below ``max_height``.
- The RoI outline may have no edge over the door. From a scan near the door, rays pass under the
  lintel steeply enough to reach the RoI's band beyond it, and the outline bulges through the
  opening into the next room (or its line fit is drawn off the wall there); the wall's face then
  stops short of the door. Each face is therefore first moved onto the wall its points show (a
  line fitted to them) and then followed along that line beyond its ends for as long as measured
  points continue on it (a wall does, and so does an opening whose lintel was seen), at most
  ``max_extension`` farther. Where the lintel was seen in stripes too far apart to follow the
  line across, the two faces either side of the bulge are searched as one (a bridge), when the
  outline between them leaves their line outward only, no deeper than the gap is wide.

An opening onto the outside (METHOD §8) has no ceiling beyond it: the scanner's upward rays through
it return nothing. Of the rising rays of the room's scans that cross the opening farther than the
scanner's minimum range, those that returned a point beyond the face are counted against those that
returned nothing (the scan's no-return directions, which the robot knows from its own pattern);
when fewer than ``covered_share`` of them returned, the door is ``exterior``.

A porch, a balcony, a loggia or a carport has a roof, and its rising rays return from it. What
tells it from a room is that it is not closed in: of the rising rays through the opening flatter
than ``level_elevation_deg`` (its level rays), which beyond an interior door meet the next room's
far wall, most pass under the roof's edge and return nothing. When fewer than ``covered_share`` of
them returned, the door is ``exterior`` too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
import shapely
from scipy.spatial import cKDTree

from nbs_env.config import DoorConfig
from nbs_env.perception.faces import PointIndex, WallFace
from nbs_env.perception.structure import face_image

__all__ = ["DetectedDoor", "DoorConfig", "detect_doors"]


@dataclass(frozen=True)
class DetectedDoor:
    """A door found in a wall face.

    Attributes
    ----------
    face : int
        Index of the wall face in the list given. The door lies on the face's wall, possibly beyond
        the face's ends (module docstring).
    centre : (3,) float
        Centre of the opening's bottom edge on the face plane (world).
    width, height : float
        Clear opening, metres.
    outward : (2,) float
        Horizontal unit normal pointing out of the room, through the door.
    behind_points : int
        Points seen through it.
    covered : float
        Share of the rising rays through it that returned a point beyond it, or of its level rays
        when that is less (module docstring; nan: too few rays).
    exterior : bool
        It opens onto the outside: ``covered`` below the config's ``covered_share``.
    """

    face: int
    centre: np.ndarray
    width: float
    height: float
    outward: np.ndarray
    behind_points: int
    covered: float = float("nan")
    exterior: bool = False


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of True in a 1-D boolean array."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _bridged(mask: np.ndarray, passable: np.ndarray, gap: int) -> np.ndarray:
    """``mask`` with its runs of False of at most ``gap`` entries between two True ones set True,
    where every entry of the run is ``passable`` (1-D boolean arrays)."""
    out = mask.copy()
    for a, b in _runs(~mask):
        if a > 0 and b < len(mask) and b - a <= gap and passable[a:b].all():
            out[a:b] = True
    return out


#: A ray that returned nothing passed this near (metres) to a measured point within the minimum range:
#: it may have met that surface there and tells nothing of what lies beyond (:func:`_rising_rays`).
#: One voxel of the default map; the points are the room's own, so a surface the scans sampled
#: at their spacing lies within it.
_CLEARANCE = 0.05
#: Faces shorter than this (metres) are not followed: their direction is too uncertain.
_MIN_LINE = 0.5
#: Fewest points for refitting a face's line to its wall.
_MIN_FIT = 20
#: Most a face may be turned onto the line its points show (degrees): an outline's line fit is off
#: its wall by a few degrees at most, while a steeper fit is drawn by what stands before the wall.
_MAX_TURN = 5.0
#: Points within this of a line (metres) lie on it: a wall's points scatter by the scanner's range
#: noise and the registration error, both below a centimetre or two.
_ON_LINE = 0.02
#: Most points the search for a face's wall line looks at.
_FIT_SAMPLE = 4000
#: Half-thickness of the slab around a face whose points make its image (``face_image``'s default).
_BAND = 0.10
#: A face's line is followed over runs of columns with no point at all only when they are shorter than
#: this (metres): thinner than most walls, so that the line does not run through a partition into
#: the next room's wall, yet wider than the gaps between the stripes in which scans along a corridor
#: see a lintel at a grazing angle (corpus:large_storey: a 0.1 m limit stopped the corridor's wall
#: line 0.4 m into a door whose lintel showed in columns two pixels apart, and the room behind it was
#: never entered).
_FOLLOW_GAP = 0.15
#: Most faces an outline's bulge through a door is walked over (:func:`_bridges`).
_BULGE_FACES = 8


def _fill_row_gaps(image: np.ndarray, gap: int) -> np.ndarray:
    """``image`` with every run of at most ``gap`` empty pixels between two white ones in a row set white."""
    if gap <= 0 or image.size == 0:
        return image
    cols = image.shape[1]
    idx = np.broadcast_to(np.arange(cols), image.shape)
    last = np.maximum.accumulate(np.where(image, idx, -1), axis=1)  # last white at or before
    following = np.minimum.accumulate(np.where(image, idx, cols)[:, ::-1], axis=1)[:, ::-1]  # next at or after
    return image | ((last >= 0) & (following < cols) & (following - last - 1 <= gap))


@numba.njit(cache=True, nogil=True)
def _densest_window(offsets: np.ndarray, window: float) -> tuple[int, int]:
    """(i, count): the window [offsets[i], offsets[i] + window] that holds the most of the (sorted)
    offsets, and how many it holds; ties go to the lowest window (the ``np.argmax`` of the counts
    that ``np.searchsorted`` gives)."""
    best, best_i, end = 0, 0, 0
    for i in range(len(offsets)):
        top = offsets[i] + window
        while end < len(offsets) and offsets[end] <= top:
            end += 1
        if end - i > best:
            best, best_i = end - i, i
    return best_i, best


@numba.njit(cache=True, nogil=True)
def _window_bounds(u: np.ndarray, w: np.ndarray, slopes: np.ndarray, window: float) -> np.ndarray:
    """(len(slopes),) int: for each slope b, at least the most offsets w - b u that one window of
    ``window`` holds (the fullest three consecutive bins of a histogram with bins of ``window``)."""
    out = np.zeros(len(slopes), dtype=np.int64)
    for k in range(len(slopes)):
        lo, hi = np.inf, -np.inf
        for n in range(len(u)):
            x = w[n] - slopes[k] * u[n]
            lo, hi = min(lo, x), max(hi, x)
        counts = np.zeros(int((hi - lo) / window) + 3, dtype=np.int64)
        for n in range(len(u)):
            counts[int((w[n] - slopes[k] * u[n] - lo) / window)] += 1
        for b in range(len(counts) - 2):
            out[k] = max(out[k], counts[b] + counts[b + 1] + counts[b + 2])
    return out


def _densest_line(u: np.ndarray, w: np.ndarray, slopes: np.ndarray, window: float) -> tuple[int, float]:
    """(k, lowest): the line w = a + slopes[k] u whose window of ``window`` above the offset
    ``lowest`` (one of the points') holds the most points less 1e-6 |slope| (ties: least turn, then
    the first slope, then the lowest window): the argmax over every slope's sorted offsets, sorting
    only the slopes whose histogram bound can reach the best found."""
    penalty = 1e-6 * np.abs(slopes)
    bound = _window_bounds(np.ascontiguousarray(u), np.ascontiguousarray(w), slopes, window) - penalty
    best, best_k, best_lowest = -np.inf, 0, 0.0
    for k in np.argsort(-bound, kind="stable"):
        if bound[k] < best:
            break
        offsets = np.sort(w - slopes[k] * u)
        i, count = _densest_window(offsets, window)
        score = count - penalty[k]
        if score > best or (score == best and k < best_k):
            best, best_k, best_lowest = score, int(k), float(offsets[i])
    return best_k, best_lowest


def _refit(face: WallFace, index: PointIndex, band: float, margin: float) -> WallFace:
    """The face moved onto the wall its points show.

    Of the points within ``band`` of the face, over its length and between ``margin`` above the
    floor and below the ceiling, the wall is the line that most of them lie on: the line, turned
    at most :data:`_MAX_TURN` from the face, with the most points within :data:`_ON_LINE` of it,
    then fitted to those points by least squares. A plain fit to every point in the band is drawn
    off the wall by the reveals of its openings and whatever stands against it (corpus:enfilade:
    1.4° off, 10 cm at one end). The face itself when fewer than :data:`_MIN_FIT` points are on
    the line, they cover less than half the face, or the line leaves the band at their middle.
    """
    p0, p1 = np.asarray(face.p0, dtype=float), np.asarray(face.p1, dtype=float)
    box = index.within(np.minimum(p0, p1) - band, np.maximum(p0, p1) + band)  # a cheap first cut
    u, v, w = face.local(index.points[box]).T
    keep = (np.abs(w) <= band) & (u >= 0) & (u <= face.length) & (v > margin) & (v < face.height - margin)
    u, w = u[keep], w[keep]
    if len(u) < _MIN_FIT:
        return face
    # The search runs on at most _FIT_SAMPLE points (an even stride: the same points every run).
    step = max(1, len(u) // _FIT_SAMPLE)
    su, sw = u[::step], w[::step]
    turn = np.tan(np.radians(_MAX_TURN))
    slopes = np.linspace(-turn, turn, 2 * int(np.ceil(turn * face.length / _ON_LINE)) + 1)
    k, lowest = _densest_line(su, sw, slopes, 2 * _ON_LINE)
    b = slopes[k]
    a = lowest + _ON_LINE
    near = np.abs(w - (a + b * u)) <= _ON_LINE
    if np.count_nonzero(near) < _MIN_FIT or np.ptp(u[near]) < face.length / 2:
        return face
    b, a = np.polyfit(u[near], w[near], 1)
    # The line must pass within the band where its points are; at the face's ends it may leave the
    # band when the face is turned off its wall (generated:10000005: a face 3.3° off, 0.2 m off
    # the wall at one end, where the outline zig-zagged through another door of the same wall).
    centre = (u[near].min() + u[near].max()) / 2
    if abs(a + b * centre) > band or abs(b) > turn:
        return face
    n = face.normal
    return WallFace(p0 + a * n, p1 + (a + b * face.length) * n, face.z0, face.z1)


def _crossing(face: WallFace, others: Sequence[WallFace], margin: float) -> tuple[float, float]:
    """(lo, hi): where along the face's line (u, from p0) the nearest of the ``others`` that meet
    it lie, at or before its start and at or past its end (-inf, inf where none does).

    A face meets the line where its segment, grown by ``margin`` at both ends, crosses it and it
    reaches more than ``margin`` into the room: a wall of the room that the line runs into at a
    corner. (A face that only leaves the line outward, as the RoI outline does where it bulges
    through a door, does not stop it.)
    """
    lo, hi = -np.inf, np.inf
    for other in others:
        (ua, wa), (ub, wb) = face.local(np.array([[*other.p0, face.z0], [*other.p1, face.z0]]))[:, [0, 2]]
        if max(wa, wb) <= margin or abs(wb - wa) < 1e-9:
            continue
        t = -wa / (wb - wa)
        grow = margin / max(other.length, 1e-9)
        if not (-grow <= t <= 1 + grow):
            continue
        u = ua + t * (ub - ua)
        if u <= margin:
            lo = max(lo, min(u, 0.0))
        if u >= face.length - margin:
            hi = min(hi, max(u, face.length))
    return lo, hi


def _followed(
    face: WallFace,
    others: Sequence[WallFace],
    points: PointIndex,
    pixel: float,
    gap: int,
    reach: float,
    margin: float,
) -> tuple[WallFace, np.ndarray]:
    """The face extended along its line as far as measured points continue on it (at most
    ``reach`` beyond either end, never across another of the room's faces), and its face image
    with row gaps of up to ``gap`` pixels filled.

    The line is followed while the columns of the image hold points between ``margin`` above the
    floor and below the ceiling: a wall's do, and so do an opening's whose lintel was seen (in
    the filled image). Past the end of the wall the line runs in a wall's inside or in open space,
    where none do; a run of columns with no point at all as wide as :data:`_FOLLOW_GAP` (a
    partition's inside) ends it.
    """
    if face.length < _MIN_LINE or reach <= 0:
        return face, _fill_row_gaps(face_image(face, points, pixel=pixel), gap)
    d = face.direction
    lo, hi = _crossing(face, others, _BAND)
    before = max(0, int(np.floor(min(reach, -lo) / pixel + 1e-9)))
    after = max(0, int(np.floor(min(reach, hi - face.length) / pixel + 1e-9)))
    start = np.asarray(face.p0, dtype=float) - before * pixel * d
    wide = WallFace(start, np.asarray(face.p1, dtype=float) + after * pixel * d, face.z0, face.z1)
    raw = face_image(wide, points, pixel=pixel)
    image = _fill_row_gaps(raw, gap)
    rows = image.shape[0]
    lo_row = int(np.ceil(margin / pixel))
    hi_row = max(lo_row + 1, rows - int(np.ceil(margin / pixel)))
    evidence = image[lo_row:hi_row, :].any(axis=0)
    seen = raw[lo_row:hi_row, :].any(axis=0)
    allowed = max(0, int(np.ceil(_FOLLOW_GAP / pixel - 1e-9)) - 1)  # empty columns in a row, fewer than _FOLLOW_GAP
    own = int(np.ceil(face.length / pixel - 1e-9))
    first, last = before, min(image.shape[1], before + own)

    def runs_on(c: int, step: int) -> bool:
        """Whether the line runs on into column c (walking by ``step``)."""
        if not evidence[c]:
            return False
        empty = 0  # columns with no point at all from c on
        while empty <= allowed and 0 <= c + empty * step < len(seen) and not seen[c + empty * step]:
            empty += 1
        return empty <= allowed

    while first > 0 and runs_on(first - 1, -1):
        first -= 1
    while last < image.shape[1] and runs_on(last, 1):
        last += 1
    followed = WallFace(start + first * pixel * d, start + last * pixel * d, face.z0, face.z1)
    return followed, image[:, first:last]


def _out_of_range(
    face: WallFace,
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    shape: tuple[int, int],
    pixel: float,
    min_range: float,
) -> np.ndarray:
    """Which pixels of the face image (by their centres) lie nearer than ``min_range`` to every scanner
    in front of the face: none of the room's scans could have measured them."""
    if min_range <= 0:
        return np.zeros(shape, dtype=bool)
    rows, cols = shape
    v = (np.arange(rows) + 0.5) * pixel
    u = (np.arange(cols) + 0.5) * pixel
    unseen = np.ones(shape, dtype=bool)
    for _, origin in scans:
        o = face.local(np.asarray(origin, dtype=float).reshape(1, 3))[0]
        if o[2] <= 0:
            continue  # behind the face: it does not see it
        unseen &= ((v[:, None] - o[1]) ** 2 + (u[None, :] - o[0]) ** 2 + o[2] ** 2) < min_range**2
    return unseen


@numba.njit(cache=True, nogil=True)
def _plane_crossings(
    points: np.ndarray,
    p0: np.ndarray,
    direction: np.ndarray,
    normal: np.ndarray,
    z0: float,
    o: np.ndarray,
    behind: float,
) -> np.ndarray:
    """(k, 2) float: the face-frame (u, v) where the ray from ``o`` (in the face frame) to each of the
    (n, 3) world ``points`` lying ``behind`` m or more beyond the face crosses its plane."""
    out = np.empty((len(points), 2))
    k = 0
    for i in range(len(points)):
        x, y = points[i, 0] - p0[0], points[i, 1] - p0[1]
        w = x * normal[0] + y * normal[1]
        if w < -behind:
            t = o[2] / (o[2] - w)
            out[k, 0] = o[0] + t * ((x * direction[0] + y * direction[1]) - o[0])
            out[k, 1] = o[1] + t * ((points[i, 2] - z0) - o[1])
            k += 1
    return out[:k]


def _crossings(face: WallFace, scans: Sequence[tuple[np.ndarray, np.ndarray]], behind: float) -> np.ndarray:
    """(k, 2) float: (u, v) where the face plane is crossed by the ray from each scan's origin (in
    front of the face) to each of its points ``behind`` m or more beyond the face."""
    crossings = [np.zeros((0, 2))]
    p0 = np.asarray(face.p0, dtype=float)
    for points, origin in scans:
        o = face.local(np.asarray(origin, dtype=float).reshape(1, 3))[0]
        if o[2] <= 0:
            continue
        points = np.ascontiguousarray(points, dtype=float)
        crossings.append(_plane_crossings(points, p0, face.direction, face.normal, float(face.z0), o, float(behind)))
    return np.concatenate(crossings)


def _through_image(crossings: np.ndarray, shape: tuple[int, int], pixel: float) -> np.ndarray:
    """Which pixels of the face image a measured ray passed through (its ``crossings``, from
    :func:`_crossings`). Such a pixel is open; an empty pixel no ray passed through may hide a wall
    the scans did not reach (out of range, or behind something in the room)."""
    rows, cols = shape
    through = np.zeros(shape, dtype=bool)
    c, r = np.floor(crossings[:, 0] / pixel), np.floor(crossings[:, 1] / pixel)
    ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
    through[r[ok].astype(np.intp), c[ok].astype(np.intp)] = True
    return through


def _seen_through(crossings: np.ndarray, u0: float, u1: float, height: float) -> int:
    """How many of the rays to points beyond the face (their ``crossings``) passed through
    [u0, u1] x [0, height]."""
    u, v = crossings[:, 0], crossings[:, 1]
    return int(np.count_nonzero((u > u0) & (u < u1) & (v > 0.0) & (v < height)))


def _rising_rays(
    face: WallFace,
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    no_return: Sequence[np.ndarray],
    u0: float,
    u1: float,
    height: float,
    min_range: float,
    blockers: Sequence[WallFace] = (),
    measured: cKDTree | None = None,
    level_sin: float = 0.0,
) -> tuple[int, int, int, int]:
    """(returned, empty, level returned, level empty): the rising rays through [u0, u1] x [0, height]
    that crossed farther than ``min_range`` from their scanner, by whether they returned a point
    beyond the face; then those of them whose elevation's sine is at most ``level_sin``.

    A ray that returned nothing may have met something within the minimum range before it reached
    the opening: it tells of the sky beyond only when its way there crosses none of the room's
    ``blockers`` (its other faces; generated:10000019: from round a corner of an L room, 71 rays
    toward a door 4 m off met the corner's wall 1.2 m out and made an interior door exterior) and,
    given the ``measured`` points of the room, passes no nearer than :data:`_CLEARANCE` to one of
    them within the minimum range (edge_8rooms_3: 392 rays toward a door 2.75 m off skimmed a box
    whose top stood 1 cm above the scanner, 1.1 m out, and made an interior door exterior; a
    scan in a door frame loses its rays to the frame's jambs in the same way)."""
    returned = empty = level_returned = level_empty = 0
    for (points, origin), directions in zip(scans, no_return, strict=True):
        o = face.local(np.asarray(origin, dtype=float).reshape(1, 3))[0]
        if o[2] <= 0:
            continue
        local = face.local(np.asarray(points, dtype=float))
        far = local[(local[:, 2] < 0) & (local[:, 1] > o[1])]
        if len(far):
            t = o[2] / (o[2] - far[:, 2])
            u, v = o[0] + t * (far[:, 0] - o[0]), o[1] + t * (far[:, 1] - o[1])
            length = np.linalg.norm(far - o, axis=1)
            crossed = (u > u0) & (u < u1) & (v > 0) & (v < height) & (t * length >= min_range)
            returned += int(np.count_nonzero(crossed))
            level_returned += int(np.count_nonzero(crossed & ((far[:, 1] - o[1]) <= level_sin * length)))
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        if not len(d):
            continue
        # Directions in the face frame: (along, up, into the room).
        dl = np.column_stack([d[:, :2] @ face.direction, d[:, 2], d[:, :2] @ face.normal])
        out = (dl[:, 2] < -1e-9) & (dl[:, 1] > 0)
        dl = dl[out]
        t = o[2] / -dl[:, 2]
        u, v = o[0] + t * dl[:, 0], o[1] + t * dl[:, 1]
        through = (u > u0) & (u < u1) & (v > 0) & (v < height) & (t >= min_range)
        if through.any() and blockers:
            start = np.asarray(origin, dtype=float)[:2]
            ends = start + t[through, None] * d[out][through, :2]
            through[np.flatnonzero(through)] = ~_blocked(start, ends, blockers)
        if through.any() and measured is not None and min_range > 0:
            through[np.flatnonzero(through)] = ~_near_measured(origin, d[out][through], min_range, measured)
        empty += int(np.count_nonzero(through))
        level_empty += int(np.count_nonzero(through & (dl[:, 1] <= level_sin)))
    return returned, empty, level_returned, level_empty


def _near_measured(origin: np.ndarray, directions: np.ndarray, reach: float, measured: cKDTree) -> np.ndarray:
    """(m,) bool: whether the ray from ``origin`` along each of the (m, 3) unit ``directions`` passes
    within :data:`_CLEARANCE` of a ``measured`` point in its first ``reach`` metres."""
    steps = np.arange(_CLEARANCE, reach + _CLEARANCE / 2, _CLEARANCE)
    samples = np.asarray(origin, dtype=float) + steps[None, :, None] * directions[:, None, :]
    distance, _ = measured.query(samples.reshape(-1, 3), distance_upper_bound=_CLEARANCE)
    return np.isfinite(distance).reshape(len(directions), len(steps)).any(axis=1)


def _within(index: PointIndex, origins: Sequence[np.ndarray], reach: float) -> np.ndarray:
    """The (n, 3) points of the ``index`` within ``reach`` of one of the ``origins``: all
    :func:`_near_measured` can meet, so its tree holds a few thousand points instead of the room's
    hundreds of thousands."""
    points = index.points
    keep = np.zeros(len(points), dtype=bool)
    for origin in origins:
        origin = np.asarray(origin, dtype=float)
        near = index.within(origin[:2] - reach, origin[:2] + reach)
        keep[near] |= np.sum((points[near] - origin) ** 2, axis=1) <= reach**2
    return points[keep]


def _blocked(start: np.ndarray, ends: np.ndarray, faces: Sequence[WallFace], margin: float = 0.05) -> np.ndarray:
    """(m,) bool: whether the plan segment from ``start`` to each of ``ends`` crosses one of the
    ``faces`` more than ``margin`` before its end (a face that touches the end does not count)."""
    d = ends - start
    length = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    short = start + d * np.clip(1.0 - margin / length, 0.0, None)
    paths = shapely.linestrings(np.stack([np.broadcast_to(start, short.shape), short], axis=1))
    walls = shapely.MultiLineString([[tuple(f.p0), tuple(f.p1)] for f in faces])
    return shapely.intersects(paths, walls)


def detect_doors(
    faces: Sequence[WallFace],
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    config: DoorConfig | None = None,
    no_return: Sequence[np.ndarray] | None = None,
    min_range: float = 0.0,
) -> list[DetectedDoor]:
    """Find door openings in the given (SE) wall faces.

    Parameters
    ----------
    faces : sequence of WallFace
        The RoI's wall faces classified SE (the room lies to their left). Each is searched along
        its wall's line, also beyond its ends (module docstring).
    scans : sequence of (points, origin)
        The room's registered scans: (n, 3) world points and the (3,) scanner position, both the
        robot's estimates. A point counts as seen through an opening when the ray from its scan's
        origin crosses the face plane inside the opening.
    config : DoorConfig
    no_return : sequence of (m, 3) float, optional
        Per scan, the world directions of its rising rays that returned nothing; with them each
        door is told interior or exterior (module docstring), without them every door is interior.
    min_range : float
        The scanner's minimum range, metres: a ray that returned nothing nearer than this may have
        hit something there.

    Returns
    -------
    list of DetectedDoor
    """
    cfg = config or DoorConfig()
    points = np.concatenate([np.asarray(p, dtype=float) for p, _ in scans]) if scans else np.zeros((0, 3))
    index = PointIndex(points)
    measured: cKDTree | None = None  # built for the first opening whose rays are counted
    px = cfg.pixel
    gap = int(np.floor(cfg.fill_gap / px + 1e-9))
    level_sin = float(np.sin(np.radians(cfg.level_elevation_deg))) if cfg.level_elevation_deg > 0 else -1.0

    def search(k: int, given: WallFace, others: list[WallFace]) -> list[DetectedDoor]:
        """The openings on the wall of ``given``, reported as on face ``k``."""
        nonlocal measured
        doors: list[DetectedDoor] = []
        face = _refit(given, index, _BAND, cfg.floor_gap)
        # The image's rows run from the floor, its columns along the (followed) face.
        face, image = _followed(face, others, index, px, gap, cfg.max_extension, cfg.floor_gap)
        rows = image.shape[0]
        # Height of the empty run from the floor (allowing a threshold) in every column.
        start = int(np.ceil(cfg.floor_gap / px))
        above = image[start:, :]
        first_white = np.where(above.any(axis=0), above.argmax(axis=0), rows - start)
        empty_height = (start + first_white) * px
        lintel_seen = above.any(axis=0)
        # An empty run too tall for a door may be a door whose lintel no scan reached: the lintel
        # may lie anywhere above the run's highest pixel known to be open. Where rays were seen
        # through the column, that is the highest pixel one passed through (above it the wall may
        # have been out of range or hidden behind something in the room: edge_8rooms_3, a lintel
        # 1.2 m from the two scans by the door and behind a box from the third); where none was,
        # the highest pixel some scan could measure (not nearer than the minimum range to all).
        in_run = np.arange(rows - start)[:, None] < first_white
        level = np.arange(1, rows - start + 1)[:, None]
        crossings = _crossings(face, scans, cfg.behind)
        open_run = _through_image(crossings, image.shape, px)[start:, :] & in_run
        unseen = _out_of_range(face, scans, image.shape, px, min_range)[start:, :]
        measurable = np.where(
            open_run.any(axis=0),
            np.where(open_run, level, 0).max(axis=0, initial=0),
            np.where(in_run & ~unseen, level, 0).max(axis=0, initial=0),
        )
        # The tallest door this face may hold: above the doors METHOD §8 knows, the lintel must be
        # wall, so a run ending at the ceiling's edge is no door (an outline across open floor, a
        # wall hidden from floor to ceiling: edge_8rooms_2's two "doors" of 2.60-2.65 m under 2.81 m,
        # whose columns' runs ended 0.11-0.21 m below the ceiling, its edge blurred by mixed pixels).
        # (Compared as the one limit was, without a tolerance: a run of 47 pixels, 2.35 m in floats,
        # stays above 2.3 m + a pixel, as it was, so that doors within METHOD's range are as found.)
        highest = min(cfg.max_height + px, max(cfg.flush_height + px, face.z1 - face.z0 - cfg.ceiling_clearance))
        lowest = np.maximum((start + measurable) * px, cfg.min_height)
        hidden = (empty_height > highest) & (lowest <= highest)
        empty_height = np.where(hidden, lowest, empty_height)
        tall = (empty_height >= cfg.min_height) & (empty_height <= highest) & lintel_seen
        tall = _bridged(tall, empty_height >= cfg.min_height, gap)
        for a, b in _runs(tall):
            width = (b - a) * px
            if not (cfg.min_width <= width <= cfg.max_width + px):
                continue
            height = float(np.median(empty_height[a:b]))
            u0, u1 = a * px, b * px
            behind = _seen_through(crossings, u0, u1, height)
            if behind < cfg.min_behind_points:
                continue
            covered = float("nan")
            if no_return is not None:
                if measured is None:
                    measured = cKDTree(_within(index, [o for _, o in scans], min_range + 2 * _CLEARANCE))
                hits, misses, level_hits, level_misses = _rising_rays(
                    face, scans, no_return, u0, u1, height, min_range, others, measured, level_sin
                )
                if hits + misses >= cfg.min_rising_rays:
                    covered = hits / (hits + misses)
                if level_hits + level_misses >= cfg.min_rising_rays:
                    # A roof beyond returns the steep rays; an open side loses the level ones.
                    level = level_hits / (level_hits + level_misses)
                    covered = level if np.isnan(covered) else min(covered, level)
            width = width + px  # the run counts whole pixels; the opening's edges fall inside its end pixels
            mid = (u0 + u1) / 2
            xy = np.asarray(face.p0, dtype=float) + mid * face.direction
            doors.append(
                DetectedDoor(
                    face=k,
                    centre=np.array([xy[0], xy[1], face.z0]),
                    width=float(width),
                    height=height,
                    outward=-face.normal,
                    behind_points=behind,
                    covered=covered,
                    exterior=bool(covered < cfg.covered_share),
                )
            )
        return doors

    doors = _distinct(
        [d for k, f in enumerate(faces) for d in search(k, f, [o for j, o in enumerate(faces) if j != k])],
        cfg.min_width / 2,
    )
    # The bridges over the outline's bulges (module docstring) add the openings no face held whole;
    # a face's door stays as it is found without them.
    bridged = [
        d
        for bridge, (k, j) in _bridges(faces, cfg.max_width)
        for d in search(k, bridge, [o for m, o in enumerate(faces) if m not in (k, j)])
        if _in_gap(d.centre[:2], faces[k], faces[j])
    ]
    found = len(doors)
    for door in _distinct(bridged, cfg.min_width / 2):
        if not any(_same_opening(door, other, cfg.min_width / 2) for other in doors[:found]):
            doors.append(door)
    return doors


def _bridges(faces: Sequence[WallFace], reach: float) -> list[tuple[WallFace, tuple[int, int]]]:
    """Faces joined over a bulge of the outline: ``(bridge, (k, j))`` where, walking the outline on
    from face k's end (each next face starts where the last ended), the faces leave k's line
    outward only and return to it within ``reach`` metres along it, at face j, which continues the
    line (parallel within :data:`_MAX_TURN`, starting within :data:`_BAND` of it), and the bulge is
    no deeper than the gap is wide.

    Where the RoI outline bulges through a door, the wall's faces stop at the bulge on both sides
    of it, and following each along its line stops at the first run of empty columns of the door's
    lintel (``corpus:large_storey``: the lintel seen only at grazing incidence from the corridor's
    far scans, in stripes three pixels apart; neither face's image then held the whole opening).
    The bridge runs on k's line from k's start to a metre into j: its image holds the opening whole.
    Faces that do not make an outline (no face starts where another ends) have no bridges.
    """
    turn = np.cos(np.radians(_MAX_TURN))
    starts = np.array([np.asarray(f.p0, dtype=float) for f in faces]).reshape(-1, 2)
    out = []
    for k, face in enumerate(faces):
        if face.length < _MIN_LINE:
            continue
        at, depth = k, 0.0
        for bulge in range(_BULGE_FACES + 1):  # bulge: the faces walked before this one
            nxt = np.flatnonzero(np.linalg.norm(starts - np.asarray(faces[at].p1, dtype=float), axis=1) < 1e-6)
            if len(nxt) != 1 or nxt[0] == k:
                break
            at = int(nxt[0])
            other = faces[at]
            (ua, _, wa), (ub, _, wb) = face.local(np.array([[*other.p0, face.z0], [*other.p1, face.z0]]))
            if max(wa, wb) > _BAND or min(ua, ub) > face.length + reach:
                break  # into the room, or too far along to be a door's bulge
            back = abs(wa) <= _BAND and ub > ua > face.length
            # A bulge through a door is shallow (the RoI's band seen under the lintel): deeper than
            # the gap is wide, it is the room going on (corpus:large_storey, the corridor's 2 m wide
            # arm 3.9 m deep, where a bridge found a door into the corridor itself).
            shallow = depth <= ua - face.length
            if back and bulge and shallow and other.length >= _MIN_LINE and face.direction @ other.direction >= turn:
                # Into j by at most a metre: j may be turned off k's line by up to _MAX_TURN.
                p1 = np.asarray(face.p0, dtype=float) + min(ub, ua + 1.0) * face.direction
                out.append((WallFace(face.p0, p1, min(face.z0, other.z0), max(face.z1, other.z1)), (k, at)))
                break
            if back:
                break  # on the line again without a bulge, too deep a one, or too short to say which way it runs
            depth = max(depth, -wa, -wb)
    return out


def _in_gap(point: np.ndarray, face: WallFace, other: WallFace) -> bool:
    """Whether ``point`` lies, along ``face``'s line, between its end and the start of ``other``:
    a bridge's doors are those of its bulge (elsewhere the faces were searched themselves)."""
    u, gap = face.local(np.array([[*point[:2], face.z0], [*other.p0, face.z0]]))[:, 0]
    return bool(face.length <= u <= gap)


def _same_opening(door: DetectedDoor, other: DetectedDoor, distance: float) -> bool:
    """Two detections of one opening: closer than ``distance``, opening the same way."""
    return bool(np.linalg.norm(door.centre[:2] - other.centre[:2]) < distance and door.outward @ other.outward > 0.9)


def _distinct(doors: list[DetectedDoor], distance: float) -> list[DetectedDoor]:
    """One door per opening: of those found (on faces followed onto the same wall) closer than
    ``distance`` to each other and opening the same way, the one seen through most."""
    kept: list[DetectedDoor] = []
    for door in sorted(doors, key=lambda d: -d.behind_points):
        if not any(_same_opening(door, other, distance) for other in kept):
            kept.append(door)
    return [d for d in doors if any(d is k for k in kept)]
