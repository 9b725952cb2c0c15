"""Door detection in the SE wall faces of the RoI (METHOD §8), from measured points only.

An opening is an empty rectangle of a wall face's image (points within ±10 cm of the face, 5 cm
pixels) that stands on the floor, is 0.6-4.0 m wide and 1.8-2.3 m high (a lintel was seen above it),
and through which the scanner saw: registered points lie behind the face plane within the opening.
That last test tells a door from the shadow a cabinet casts on the wall behind it.

Two things the robot's own scans do to a door, which the search allows for:

- The lintel is often seen only in stripes. Nothing nearer than the scanner's minimum range
  (1.5 m) is measured, so from a scan taken close to the door the lintel is not seen at all; it
  is then seen only from farther scans, at grazing incidence, where consecutive azimuths land
  several pixels apart on the wall. Columns with no lintel point would cut the opening into pieces
  narrower than a door, so gaps of up to ``fill_gap`` in each row of the face image are filled
  first (an opening itself is at least ``min_width`` wide and stays empty).
- The RoI outline may have no edge over the door. From a scan near the door, rays pass under the
  lintel steeply enough to reach the RoI's band beyond it, and the outline bulges through the
  opening into the next room; the wall's face then stops at the bulge. Each face is therefore
  searched along its line, extended over such a bulge (or over a stretch of faces not given, not
  SE) up to where the outline comes back to the line, at most ``max_bridge`` farther.

An opening onto the outside (METHOD §8) has no ceiling beyond it: the scanner's upward rays through
it return nothing. Of the rising rays of the room's scans that cross the opening farther than the
scanner's minimum range, those that returned a point beyond the face are counted against those that
returned nothing (the scan's no-return directions, which the robot knows from its own pattern);
when fewer than ``covered_share`` of them returned, the door is ``exterior``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nbs_env.config import Config, _finite_fields, _integer, _require
from nbs_env.perception.faces import WallFace
from nbs_env.perception.structure import face_image

__all__ = ["DetectedDoor", "DoorConfig", "detect_doors"]


@dataclass(frozen=True)
class DoorConfig(Config):
    """Limits of a door opening (METHOD §8).

    Attributes
    ----------
    min_width, max_width : float
        Clear width, metres. Up to 4 m, so that a wide passage under a lintel between open-plan
        rooms counts (FZK-Haus: 3.5 m from the living room to the hall; with 1.5 m the robot never
        left the living room).
    min_height, max_height : float
        Clear height, metres; the lintel must have been seen within this range.
    floor_gap : float
        How far above the floor the opening must start at the latest (a threshold), metres.
    behind : float
        Points at least this far behind the face plane count as seen through the opening, metres.
    min_behind_points : int
        Least number of such points.
    pixel : float
        Pixel size of the face image, metres.
    covered_share : float
        Least share of the rising rays through an opening that must return a point beyond it for
        the opening to lead indoors (module docstring).
    min_rising_rays : int
        Fewer rising rays through an opening than this decide nothing: the door counts as interior.
    cross_exterior : bool
        Cross exterior doors as if they led into rooms (off by default: the robot stays inside).
    fill_gap : float
        Gaps up to this wide between points of a row of the face image are filled before the
        search (a lintel seen in stripes, module docstring), metres; below ``min_width``.
    line_tolerance : float
        How far from a face's line (metres) the RoI outline counts as back on the wall after a
        bulge (module docstring).
    max_bridge : float
        Longest stretch (metres) beyond a face's end over which it is extended.
    """

    min_width: float = 0.6
    max_width: float = 4.0
    min_height: float = 1.8
    max_height: float = 2.3
    floor_gap: float = 0.15
    behind: float = 0.3
    min_behind_points: int = 50
    pixel: float = 0.05
    covered_share: float = 0.5
    min_rising_rays: int = 20
    cross_exterior: bool = False
    fill_gap: float = 0.2
    line_tolerance: float = 0.1
    max_bridge: float = 8.0

    def __post_init__(self) -> None:
        _finite_fields(
            self,
            "min_width",
            "max_width",
            "min_height",
            "max_height",
            "floor_gap",
            "behind",
            "pixel",
            "covered_share",
            "fill_gap",
            "line_tolerance",
            "max_bridge",
        )
        _require(
            0 < self.min_width <= self.max_width,
            f"need 0 < min_width <= max_width, got {self.min_width}, {self.max_width}",
        )
        _require(
            0 < self.min_height <= self.max_height,
            f"need 0 < min_height <= max_height, got {self.min_height}, {self.max_height}",
        )
        _require(self.floor_gap >= 0, f"floor_gap must be >= 0 metres, got {self.floor_gap}")
        _require(self.behind >= 0, f"behind must be >= 0 metres, got {self.behind}")
        _require(self.pixel > 0, f"pixel must be > 0 metres, got {self.pixel}")
        _integer(self, "min_behind_points", 0)
        _integer(self, "min_rising_rays", 1)
        _require(0 <= self.covered_share <= 1, f"covered_share must be in [0, 1], got {self.covered_share}")
        _require(isinstance(self.cross_exterior, bool), f"cross_exterior must be a bool, got {self.cross_exterior!r}")
        _require(
            0 <= self.fill_gap < self.min_width,
            f"need 0 <= fill_gap < min_width, got {self.fill_gap}, {self.min_width}",
        )
        _require(self.line_tolerance >= 0, f"line_tolerance must be >= 0 metres, got {self.line_tolerance}")
        _require(self.max_bridge >= 0, f"max_bridge must be >= 0 metres, got {self.max_bridge}")


@dataclass(frozen=True)
class DetectedDoor:
    """A door found in a wall face.

    Attributes
    ----------
    face : int
        Index of the wall face in the list given. The door lies on the face's line, possibly beyond
        its ends where the RoI outline bulged through the opening (module docstring).
    centre : (3,) float
        Centre of the opening's bottom edge on the face plane (world).
    width, height : float
        Clear opening, metres.
    outward : (2,) float
        Horizontal unit normal pointing out of the room, through the door.
    behind_points : int
        Points seen through it.
    covered : float
        Share of the rising rays through it that returned a point beyond it (nan: too few rays).
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


#: Faces shorter than this (metres) are not extended: their direction is too uncertain to follow
#: their line over a bulge of the RoI outline.
_MIN_LINE = 0.5


def _fill_row_gaps(image: np.ndarray, gap: int) -> np.ndarray:
    """``image`` with every run of at most ``gap`` empty pixels between two white ones in a row set white."""
    if gap <= 0 or image.size == 0:
        return image
    cols = image.shape[1]
    idx = np.broadcast_to(np.arange(cols), image.shape)
    last = np.maximum.accumulate(np.where(image, idx, -1), axis=1)  # last white at or before
    following = np.minimum.accumulate(np.where(image, idx, cols)[:, ::-1], axis=1)[:, ::-1]  # next at or after
    return image | ((last >= 0) & (following < cols) & (following - last - 1 <= gap))


def _bridge(
    end: np.ndarray,
    axis: np.ndarray,
    normal: np.ndarray,
    segments: Sequence[tuple[np.ndarray, np.ndarray, bool]],
    tolerance: float,
    reach: float,
) -> float:
    """How far (metres, >= 0) a face's line runs on past its ``end`` along ``axis``.

    ``segments`` is the RoI outline from ``end`` on: (a, b, hidden) pieces, hidden where faces not
    given (not SE) lie between two given ones. In the face frame (u along ``axis`` from ``end``,
    w along ``normal``, into the room) the line runs on over pieces within ``tolerance`` of it
    (a collinear face) and over a bulge: pieces behind it (w < -tolerance, outside the room) or
    hidden, up to where the outline comes back to the line, or crosses it into the room (a
    corner). It stops where the outline turns into the room, or beyond ``reach``.
    """
    far = 0.0
    behind = False  # the outline has left the line, outward or unseen
    for a, b, hidden in segments:
        ua, wa = float((a - end) @ axis), float((a - end) @ normal)
        ub, wb = float((b - end) @ axis), float((b - end) @ normal)
        if ub > reach and wb < -tolerance:
            break  # too far along: whatever comes back to the line there is another wall
        if hidden:
            behind = True
        if wb > tolerance:
            if behind and not hidden and wa <= tolerance and wb > wa:
                # Back across the line into the room: the outline came back at a corner.
                u = ua + (ub - ua) * (0.0 - wa) / (wb - wa)
                if far < u <= reach:
                    far = u
            break
        if wb >= -tolerance:  # on the line (again)
            if ub > far and ub <= reach:
                far = ub
            elif ub > reach:
                break
            behind = False
        else:
            behind = True
    return far


def _extended(faces: Sequence[WallFace], k: int, tolerance: float, reach: float) -> WallFace:
    """Face ``k`` extended along its line over bulges of the RoI outline at either end (:func:`_bridge`).

    The faces are the RoI's (SE) faces in outline order; a gap between one's end and the next's
    start stands for faces left out.
    """
    face, n = faces[k], len(faces)
    if n < 2 or reach <= 0 or face.length < _MIN_LINE:
        return face
    p0, p1 = np.asarray(face.p0, dtype=float), np.asarray(face.p1, dtype=float)
    d, normal = face.direction, face.normal
    forward: list[tuple[np.ndarray, np.ndarray, bool]] = []
    backward: list[tuple[np.ndarray, np.ndarray, bool]] = []
    at_end, at_start = p1, p0
    for j in range(1, n):
        after, before = faces[(k + j) % n], faces[(k - j) % n]
        a0, a1 = np.asarray(after.p0, dtype=float), np.asarray(after.p1, dtype=float)
        b0, b1 = np.asarray(before.p0, dtype=float), np.asarray(before.p1, dtype=float)
        if np.linalg.norm(a0 - at_end) > 1e-6:
            forward.append((at_end, a0, True))
        forward.append((a0, a1, False))
        if np.linalg.norm(b1 - at_start) > 1e-6:
            backward.append((at_start, b1, True))
        backward.append((b1, b0, False))
        at_end, at_start = a1, b0
    ahead = _bridge(p1, d, normal, forward, tolerance, reach)
    back = _bridge(p0, -d, normal, backward, tolerance, reach)
    if ahead == 0.0 and back == 0.0:
        return face
    return WallFace(p0 - back * d, p1 + ahead * d, face.z0, face.z1)


def _seen_through(
    face: WallFace,
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    u0: float,
    u1: float,
    height: float,
    behind: float,
) -> int:
    """How many points lie ``behind`` m beyond the face and were seen through [u0, u1] x [0, height]."""
    count = 0
    for points, origin in scans:
        local = face.local(np.asarray(points, dtype=float))
        o = face.local(np.asarray(origin, dtype=float).reshape(1, 3))[0]
        far = local[local[:, 2] < -behind]
        if not len(far) or o[2] <= 0:
            continue
        # Where the ray from the scanner to the point crosses the face plane (w = 0).
        t = o[2] / (o[2] - far[:, 2])
        u = o[0] + t * (far[:, 0] - o[0])
        v = o[1] + t * (far[:, 1] - o[1])
        count += int(np.count_nonzero((u > u0) & (u < u1) & (v > 0.0) & (v < height)))
    return count


def _rising_rays(
    face: WallFace,
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    no_return: Sequence[np.ndarray],
    u0: float,
    u1: float,
    height: float,
    min_range: float,
) -> tuple[int, int]:
    """(returned, empty): the rising rays through [u0, u1] x [0, height] that crossed farther than
    ``min_range`` from their scanner, by whether they returned a point beyond the face."""
    returned = empty = 0
    for (points, origin), directions in zip(scans, no_return, strict=True):
        o = face.local(np.asarray(origin, dtype=float).reshape(1, 3))[0]
        if o[2] <= 0:
            continue
        local = face.local(np.asarray(points, dtype=float))
        far = local[(local[:, 2] < 0) & (local[:, 1] > o[1])]
        if len(far):
            t = o[2] / (o[2] - far[:, 2])
            u, v = o[0] + t * (far[:, 0] - o[0]), o[1] + t * (far[:, 1] - o[1])
            reach = t * np.linalg.norm(far - o, axis=1)
            returned += int(np.count_nonzero((u > u0) & (u < u1) & (v > 0) & (v < height) & (reach >= min_range)))
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        if not len(d):
            continue
        # Directions in the face frame: (along, up, into the room).
        dl = np.column_stack([d[:, :2] @ face.direction, d[:, 2], d[:, :2] @ face.normal])
        out = (dl[:, 2] < -1e-9) & (dl[:, 1] > 0)
        dl = dl[out]
        t = o[2] / -dl[:, 2]
        u, v = o[0] + t * dl[:, 0], o[1] + t * dl[:, 1]
        empty += int(np.count_nonzero((u > u0) & (u < u1) & (v > 0) & (v < height) & (t >= min_range)))
    return returned, empty


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
        The RoI's wall faces classified SE (the room lies to their left), in the order of the RoI
        outline (each is searched along its line over bulges of the outline, module docstring).
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
    doors: list[DetectedDoor] = []
    px = cfg.pixel
    gap = int(np.floor(cfg.fill_gap / px + 1e-9))
    for k in range(len(faces)):
        face = _extended(faces, k, cfg.line_tolerance, cfg.max_bridge)
        image = face_image(face, points, pixel=px)  # (rows from the floor, columns along the face)
        image = _fill_row_gaps(image, gap)
        rows = image.shape[0]
        # Height of the empty run from the floor (allowing a threshold) in every column.
        start = int(np.ceil(cfg.floor_gap / px))
        above = image[start:, :]
        first_white = np.where(above.any(axis=0), above.argmax(axis=0), rows - start)
        empty_height = (start + first_white) * px
        lintel_seen = above.any(axis=0)
        tall = (empty_height >= cfg.min_height) & (empty_height <= cfg.max_height + px) & lintel_seen
        for a, b in _runs(tall):
            width = (b - a) * px
            if not (cfg.min_width <= width <= cfg.max_width + px):
                continue
            height = float(np.median(empty_height[a:b]))
            u0, u1 = a * px, b * px
            behind = _seen_through(face, scans, u0, u1, height, cfg.behind)
            if behind < cfg.min_behind_points:
                continue
            covered = float("nan")
            if no_return is not None:
                hits, misses = _rising_rays(face, scans, no_return, u0, u1, height, min_range)
                if hits + misses >= cfg.min_rising_rays:
                    covered = hits / (hits + misses)
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
    return _distinct(doors, cfg.min_width / 2)


def _distinct(doors: list[DetectedDoor], distance: float) -> list[DetectedDoor]:
    """One door per opening: of those found (on overlapping extended faces) closer than
    ``distance`` to each other and opening the same way, the one seen through most."""
    kept: list[DetectedDoor] = []
    for door in sorted(doors, key=lambda d: -d.behind_points):
        if not any(
            np.linalg.norm(door.centre[:2] - other.centre[:2]) < distance and door.outward @ other.outward > 0.9
            for other in kept
        ):
            kept.append(door)
    return [d for d in doors if any(d is k for k in kept)]
