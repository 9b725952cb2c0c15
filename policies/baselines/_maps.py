"""Shared machinery of the compared methods: structure-agnostic views of the robot's voxel space,
2-D line of sight, 3-D ray marching, and the policy base class with its own stopping rule.

The compared methods got the paper's dynamic voxel space and door detection, not its SE
classification: here the five labels collapse to free (Empty), occupied (Clutter or Structure) and
unknown (Unknown, Occluded-clutter, Occluded-structure), read from the planner's view of the room
(the blind zone under each stop free, as for the greedy) with the rays' semantics of their papers
(:func:`collapse`).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
from scipy import ndimage

from nbs_env.labels import VoxelLabel, is_occupied
from nbs_env.mapping.voxels import FRONTIER_REACH, frontier_strips
from nbs_env.observation import BeliefView

__all__ = [
    "STOP_FORMS",
    "WORKSPACE_REACH",
    "MappingPolicy",
    "band_columns",
    "collapse",
    "march",
    "sphere_directions",
    "stop_value",
    "visible_cells_2d",
    "workspace",
]


#: The forms of the stopping rule, by name: the exponent of the RoI's floor area that divides the
#: statistic (:attr:`MappingPolicy.stop_area_power`; ``train.calibrate_stops`` sweeps them all).
STOP_FORMS = {"absolute": 0.0, "per_sqrt_m2": 0.5, "per_m2": 1.0}


def stop_value(statistic: float, area_m2: float, power: float) -> float:
    """A stop statistic in the rule's form: divided by the RoI's floor area (m²) to ``power``."""
    return float(statistic) if power == 0 else float(statistic) / max(float(area_m2), 1e-9) ** power


def collapse(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(free, occupied, unknown) bool arrays of the labels' shape: what a structure-agnostic method
    sees, with the rays' semantics of its papers (OctoMap's: every voxel a ray crosses before its
    end point is free).

    Our carving is conservative: a voxel is Empty only when its whole angular footprint lies before
    the measured range, so the one-voxel skin in front of every measured surface stays unknown,
    though the rays that measured the surface crossed it. To the compared methods that skin was
    unknown space any view would see and none ever did: on ``generated:0`` (fast preset) it held
    97% of Potthast & Sukhatme's best gain after ten scans of a room whose coverage had stopped
    growing, so no stopping rule could fire. An unknown voxel with an occupied and a free voxel
    among its six face neighbours counts here as free (crossed)."""
    free = labels == VoxelLabel.EMPTY
    occupied = is_occupied(labels)
    unknown = ~(free | occupied)
    cross = ndimage.generate_binary_structure(3, 1)
    crossed = unknown & ndimage.binary_dilation(occupied, cross) & ndimage.binary_dilation(free, cross)
    free = free | crossed
    return free, occupied, unknown & ~crossed


#: How far past a frontier face of the RoI the workspace reaches, metres: the greedy's
#: (:data:`~nbs_env.mapping.voxels.FRONTIER_REACH`).
WORKSPACE_REACH = FRONTIER_REACH


def workspace(belief: BeliefView) -> tuple[np.ndarray, np.ndarray]:
    """The room's dynamic workspace in its grid: the RoI prism (one voxel wider, for the walls'
    voxels) and, past each frontier face, the strip :data:`WORKSPACE_REACH` deep (its floor and
    ceiling layers in 3-D): the greedy's targets' region (``VoxelGrid.update_occlusion``).

    The paper gave the compared methods its dynamic voxel space (their fixed-size grids were resized
    to it at every scan); what lies outside the room's RoI is no part of the room's task, for them as
    for the greedy, whose targets are the RoI's. Counting it kept gains up that no scan of the room
    could take: on ``generated:0`` (fast preset), 94% of Stachniss & Burgard's best gain after ten
    scans of its first room lay in unobserved cells outside the RoI. A margin all round the RoI is
    not enough: on ``five_rooms`` a 0.5 m margin reached through the doors, and after ten scans of
    the living room 73% of Potthast & Sukhatme's best gain lay in that margin, in the next rooms,
    where no view from inside the room sees more than a sliver (three of its fifteen rooms ended at
    the cap). A door face is no frontier (its lintel is measured), so the greedy's region stops there.

    Returns
    -------
    plan : (nx, ny) bool
        Columns inside the workspace.
    prism : (nx, ny, nz) bool
        Voxels of the RoI's columns from the floor to the ceiling (one voxel either side), and the
        floor's and ceiling's layers of the strips.
    """
    import shapely
    from shapely.geometry import Polygon

    grid, roi = belief.grid, belief.roi
    s = grid.voxel_size
    nx, ny, nz = grid.shape
    gx, gy = np.meshgrid(grid.origin[0] + (np.arange(nx) + 0.5) * s, grid.origin[1] + (np.arange(ny) + 0.5) * s,
                         indexing="ij")  # fmt: skip
    room = shapely.contains_xy(Polygon(roi.polygon).buffer(s), gx, gy)
    strips = frontier_strips(belief.frontier, WORKSPACE_REACH)
    beyond = shapely.contains_xy(shapely.union_all(strips), gx, gy) & ~room if strips else np.zeros_like(room)
    zs = grid.origin[2] + (np.arange(nz) + 0.5) * s
    height = (zs >= roi.floor_z - s) & (zs <= roi.ceiling_z + s)
    # Past a frontier face the greedy assumes only that the floor and ceiling go on, so only their
    # layers are targets there; the full height past it would be the next space's volume.
    slabs = (np.abs(zs - roi.floor_z) <= s) | ((np.abs(zs - roi.ceiling_z) <= s) & roi.has_ceiling)
    prism = (room[:, :, None] & height[None, None, :]) | (beyond[:, :, None] & slabs[None, None, :])
    return room | beyond, prism


def band_columns(grid, floor_z: float, lo: float = 0.3, hi: float = 2.0) -> slice:
    """The z slice of ``grid`` from ``lo`` to ``hi`` metres above the floor (a 2-D map's band)."""
    k0 = int(np.clip(math.floor((floor_z + lo - grid.origin[2]) / grid.voxel_size), 0, grid.shape[2] - 1))
    k1 = int(np.clip(math.ceil((floor_z + hi - grid.origin[2]) / grid.voxel_size), k0 + 1, grid.shape[2]))
    return slice(k0, k1)


def visible_cells_2d(
    blocked: np.ndarray,
    origin_xy: np.ndarray,
    cell: float,
    sensor_xy: np.ndarray,
    min_range: float,
    max_range: float,
    n_rays: int = 360,
) -> np.ndarray:
    """Flat indices of the cells of a 2-D map a 360° sensor at ``sensor_xy`` sees.

    Parameters
    ----------
    blocked : (nx, ny) bool
        Cells that stop a ray (the first blocked cell on a ray is itself seen).
    origin_xy : (2,) float
        World xy of the corner of cell (0, 0).
    cell : float
        Cell size, metres.
    sensor_xy : (2,) float
    min_range, max_range : float
        Cells nearer than ``min_range`` are not measured (but do block).

    Returns
    -------
    (v,) int64, unique flat indices into ``blocked``.
    """
    nx, ny = blocked.shape
    theta = (np.arange(n_rays) + 0.5) * (2 * np.pi / n_rays)
    radii = np.arange(cell / 2, max_range, cell / 2)
    xy = sensor_xy[None, None, :] + radii[None, :, None] * np.stack([np.cos(theta), np.sin(theta)], -1)[:, None, :]
    ij = np.floor((xy - origin_xy) / cell).astype(np.int64)
    inside = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
    flat = np.where(inside, ij[..., 0] * ny + ij[..., 1], 0)
    hit = blocked.reshape(-1)[flat] & inside
    # A ray stops after its first blocked cell, and at the edge of the map.
    before = np.cumsum(hit, axis=1) - hit
    ok = inside & (before == 0) & (np.cumsum(~inside, axis=1) == 0) & (radii[None, :] >= min_range)
    return np.unique(flat[ok])


def sphere_directions(step_deg: float, elevation_min: float, elevation_max: float) -> np.ndarray:
    """(r, 3) float unit directions on a regular azimuth-elevation grid of the scanner's field."""
    az = np.radians(np.arange(0.0, 360.0, step_deg))
    el = np.radians(np.arange(elevation_min + step_deg / 2, elevation_max, step_deg))
    a, e = np.meshgrid(az, el, indexing="ij")
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)


def march(
    shape: tuple[int, int, int],
    origin: np.ndarray,
    voxel: float,
    sensor: np.ndarray,
    directions: np.ndarray,
    max_range: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Walk rays through a voxel array in steps of one voxel from ``sensor``.

    Returns
    -------
    flat : (r, s) int64
        Flat index of the voxel of each sample (0 outside: mask with ``inside``); gather any array
        of ``shape`` with ``array.reshape(-1)[flat]``.
    first : (r, s) bool
        The sample is the first of its voxel on the ray.
    inside : (r, s) bool
        The sample lies in the array.
    distance : (s,) float
        Distance of each step from the sensor.
    """
    distance = np.arange(voxel / 2, max_range, voxel, dtype=np.float32)
    pts = sensor.astype(np.float32)[None, None, :] + distance[None, :, None] * directions.astype(np.float32)[:, None, :]
    idx = np.floor((pts - origin.astype(np.float32)) / np.float32(voxel)).astype(np.int64)
    dims = np.asarray(shape)
    inside = np.all((idx >= 0) & (idx < dims), axis=-1)
    idx[~inside] = 0
    flat = (idx[..., 0] * dims[1] + idx[..., 1]) * dims[2] + idx[..., 2]
    first = np.ones(flat.shape, dtype=bool)
    first[:, 1:] = (flat[:, 1:] != flat[:, :-1]) | (inside[:, 1:] != inside[:, :-1])
    return flat, first, inside, distance


class MappingPolicy:
    """Base of the compared methods: keeps per-room state from ``info["belief"]`` and ends a room by
    its own stopping rule, or, in the controlled mode, by the greedy's.

    Every method reads the planner's view of the room (``belief.labels``: what no scan from the
    room's stops could measure taken as free, the treatment the greedy's navigation gets) and the
    planner's NVPs, so the methods differ only where their papers do: the utility, what counts as
    seen, and the stopping rule.

    The stopping rule is the papers' "stop when no candidate's gain is above ε": a room ends when
    :meth:`stop_statistic`, the method's best gain in its own unit (made independent of the voxel
    size where the gain counts voxels or cells), divided by the RoI's floor area to the power
    :attr:`stop_area_power` (0: ε in the method's unit; 0.5: per √m²; 1: per m²), falls below
    ``stop_below``. Each method's default
    ``stop_below`` was calibrated on generated training storeys (``python -m train.calibrate_stops``;
    the figures are in its module docstring and ``docs/experiments/stopping.md``).

    Parameters
    ----------
    stop_below : float
        ε of the stopping rule, in the method's unit; 0 never stops by the rule (the per-room scan
        cap then ends every room).
    controlled : bool
        The controlled mode: the room ends by the greedy's rule (``rooms.completion="gain"``: its predicted
        conversions below ``rooms.completion_fraction`` of the room's structural voxels) and the method
        only chooses where to scan, so that "where to scan" can be told from "when to stop".

    Raises
    ------
    ValueError
        ``stop_below`` is not a finite number >= 0.
    """

    name = "mapping"
    #: What the policy runs with (:func:`policies.config_for` applies it): its own stopping rule
    #: through "room done", its own maps from the belief view, and no greedy gains to pay for.
    config_overrides: ClassVar[dict[str, Any]] = {
        "rooms.completion": "policy",
        "expose_belief": True,
        "robot.predict_gains": False,
    }
    #: It runs on any robot.
    requires: ClassVar[dict[str, Any]] = {}
    #: Structure-agnostic methods process every point (METHOD §9).
    structure_aware = False
    #: The calibrated ε (subclasses set theirs).
    default_stop_below: ClassVar[float] = 0.0
    #: ε is per (m² of the RoI's floor) to this power: 0 in the method's own unit, 1 per m² (as the
    #: greedy's threshold is a share of its room's structural voxels), 0.5 between (a room's wall
    #: length grows with √area); which form each method takes was chosen by the calibration.
    stop_area_power: ClassVar[float] = 0.0

    def __init__(self, stop_below: float | None = None, controlled: bool = False) -> None:
        stop_below = self.default_stop_below if stop_below is None else float(stop_below)
        if not (math.isfinite(stop_below) and stop_below >= 0):
            raise ValueError(f"stop_below must be a finite number >= 0, got {stop_below!r}")
        self.stop_below = stop_below
        self.controlled = bool(controlled)
        if self.controlled:
            # The greedy's room completion needs its predicted gains.
            self.config_overrides = {"rooms.completion": "gain", "expose_belief": True}  # type: ignore[misc]
        self.reset()

    def reset(self) -> None:
        """Forget the maps, the dropped points and the trace of the previous episode."""
        self._room: int | None = None
        self._expected: tuple[np.ndarray, Any] | None = None
        #: World points of the room (voxel centres, or cell centres at floor height) that a scan
        #: was predicted to observe and did not: no longer counted (:meth:`expect`).
        self.dropped = np.zeros((0, 3))
        #: Per decision: the room, the method's stop statistic, the RoI's floor area and whether the
        #: rule ended the room (what ``train.calibrate_stops`` reads).
        self.trace: list[dict[str, Any]] = []

    def _belief(self, info: dict[str, Any]) -> BeliefView:
        if "belief" not in info:
            raise KeyError(
                f"{type(self).__name__} keeps its own map and needs info['belief']: make the env with "
                f"expose_belief=True and rooms.completion='policy' (see {type(self).__name__}.config_overrides)"
            )
        return info["belief"]

    @staticmethod
    def labels_of(belief: BeliefView) -> np.ndarray:
        """The room's labels as the planner reads them (``belief.labels``), else V(t)'s own.

        Parameters
        ----------
        belief : BeliefView

        Returns
        -------
        (nx, ny, nz) uint8
            VoxelLabel values.
        """
        return belief.labels if getattr(belief, "labels", None) is not None else belief.grid.labels

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        """The valid candidate of the largest :meth:`utilities`, or "room done" by the stopping rule.

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            The env's observation (not read: the method keeps its own maps).
        info : dict of str to Any
            The env's ``info``; its ``"belief"`` (:class:`~nbs_env.observation.BeliefView`, from
            ``expose_belief=True``) is read.

        Returns
        -------
        int
            A candidate slot, or K = ``len(belief.mask)`` ("room done") when the rule fires or no
            candidate is valid; in the controlled mode the rule never fires and no valid candidate
            gives 0.

        Raises
        ------
        KeyError
            ``info`` has no ``"belief"``.
        """
        belief = self._belief(info)
        stop = len(belief.mask)  # the "room done" action (completion="policy")
        self._track_room(belief)
        self.observe(belief)
        self._settle(belief)
        valid = np.flatnonzero(belief.mask)
        if not len(valid):
            return 0 if self.controlled else stop
        utility = self.utilities(belief, valid)
        return self._choose(belief, valid, utility, self.stop_statistic(belief, valid, utility))

    def _choose(self, belief: BeliefView, valid: np.ndarray, utility: np.ndarray, statistic: float) -> int:
        """The best candidate, or "room done" when the rule fires (never in the controlled mode)."""
        import shapely
        from shapely.geometry import Polygon

        area = float(shapely.area(Polygon(belief.roi.polygon))) if belief.roi is not None else 0.0
        value = stop_value(statistic, area, self.stop_area_power)
        stop = not self.controlled and value < self.stop_below
        self.trace.append(
            {"room": int(belief.room), "statistic": float(statistic), "area_m2": area, "stop": bool(stop)}
        )
        if stop:
            return len(belief.mask)
        best = int(np.argmax(utility))
        self._expected = self.expect(belief, int(valid[best]))
        return int(valid[best])

    def _track_room(self, belief: BeliefView) -> None:
        """Start afresh when the robot has entered a room."""
        if belief.room != self._room or belief.new_room:
            self._room = belief.room
            self._expected = None
            self.dropped = np.zeros((0, 3))
            self.new_room(belief)

    def _settle(self, belief: BeliefView) -> None:
        """Drop what the last chosen view was to observe and did not."""
        if self._expected is None:
            return
        points, memo = self._expected
        self._expected = None
        if len(points):
            missed = np.asarray(points, dtype=float)[self.still_unseen(belief, points, memo)]
            self.dropped = np.concatenate([self.dropped, missed.reshape(-1, 3)])

    def dropped_mask(self, grid, plan: bool = False) -> np.ndarray:
        """The grid's voxels (or columns) that hold a dropped point (:meth:`expect`).

        Parameters
        ----------
        grid : VoxelGrid
            The room's grid.
        plan : bool
            Columns (2-D) instead of voxels.

        Returns
        -------
        (nx, ny, nz) bool, or (nx, ny) bool with ``plan``
        """
        shape = grid.shape[:2] if plan else grid.shape
        out = np.zeros(shape, dtype=bool)
        if len(self.dropped):
            idx = grid.index_of(self.dropped)[:, : len(shape)]
            ok = np.all((idx >= 0) & (idx < np.asarray(shape)), axis=1)
            out[tuple(idx[ok].T)] = True
        return out

    @staticmethod
    def dense_range(belief: BeliefView) -> float:
        """Metres within which a scan's point spacing is finer than a voxel: a voxel there that a
        scan had in view and left unseen was not to be seen (the greedy's rule,
        :func:`nbs_env.planning.planner.unobservable_after`).

        Parameters
        ----------
        belief : BeliefView
            Read for its grid's voxel size and its scanner's angular step.

        Returns
        -------
        float
        """
        return float(belief.grid.voxel_size / np.radians(belief.scanner.angular_step))

    # ------------------------------------------------------------------ hooks
    def new_room(self, belief: BeliefView) -> None:
        """Start the maps of a new room (a hook: nothing by default).

        Parameters
        ----------
        belief : BeliefView
            The robot's belief at the room's first decision.
        """

    def observe(self, belief: BeliefView) -> None:
        """Take in this step's measurements (a hook: nothing by default).

        Parameters
        ----------
        belief : BeliefView
            The belief of the decision.
        """

    def utilities(self, belief: BeliefView, valid: np.ndarray) -> np.ndarray:
        """The utility of each valid candidate (the argmax is the next scan); each method defines it.

        Parameters
        ----------
        belief : BeliefView
            The belief of the decision.
        valid : (m,) int64
            The slots of the valid candidates (``np.flatnonzero(belief.mask)``).

        Returns
        -------
        (m,) float
        """
        raise NotImplementedError

    def stop_statistic(self, belief: BeliefView, valid: np.ndarray, utility: np.ndarray) -> float:
        """The best gain in the method's unit, which the rule compares with ``stop_below`` (after
        dividing by the RoI's floor area to the power :attr:`stop_area_power`).

        Parameters
        ----------
        belief : BeliefView
            The belief of the decision.
        valid : (m,) int64
            The slots of the valid candidates.
        utility : (m,) float
            Their :meth:`utilities`.

        Returns
        -------
        float
            By default the largest utility.
        """
        return float(np.max(utility))

    def expect(self, belief: BeliefView, index: int) -> tuple[np.ndarray, Any] | None:
        """What the method's gain says candidate ``index`` will observe.

        As the greedy does (:func:`nbs_env.planning.planner.unobservable_after`), what a chosen
        scan was predicted to observe within :meth:`dense_range` and did not is dropped from later
        gains (:meth:`still_unseen` tells which), so that a gain no scan can take does not hold a
        room open to its cap.

        Parameters
        ----------
        belief : BeliefView
            The belief of the decision.
        index : int
            The chosen candidate's slot.

        Returns
        -------
        tuple of ((n, 3) float, Any), or None
            World points and a memo for :meth:`still_unseen`; None (the default): the method
            predicts nothing checkable.
        """
        return None

    def still_unseen(self, belief: BeliefView, points: np.ndarray, memo: Any) -> np.ndarray:
        """Which of :meth:`expect`'s points the scans since have left unobserved.

        Parameters
        ----------
        belief : BeliefView
            The belief after the scan.
        points : (n, 3) float
            The world points :meth:`expect` returned.
        memo : Any
            :meth:`expect`'s memo.

        Returns
        -------
        (n,) bool
            By default all False.
        """
        return np.zeros(len(points), dtype=bool)
