"""The planning pipeline of one decision, assembled in one place (METHOD §6-7).

Everything the robot, the compared methods, ``train.evaluate_gain`` and the example plan of
docs/environment.md goes through here::

    plan(belief, pose, stops, visited, config) -> Plan(candidates, gains, structural_voxels, seconds)

1. :func:`unseeable_free`: V(t) with what no scan from the room's stops could measure (the blind
   zone under each stop: the scanner's lowest elevation *and* its minimum range) taken as free,
   the one view every method plans on; :func:`traversable_floor`: the traversability test with
   the robot's footprint on it;
2. the next valid positions (NVPs) on that floor
   (:func:`~nbs_env.planning.navigation.candidates`);
3. :func:`sensor_positions`: the scanner above each NVP, at its height over the room's floor;
4. :func:`predict_gains`: each NVP's predicted Occluded-structure→Structure conversions, from the
   gain model that :attr:`GainConfig.model` names in :data:`GAIN_MODELS` (the paper's
   :class:`~nbs_env.planning.visibility.VisibilityModel` by default);
5. :meth:`Plan.order`: most gain first, ties to the shorter path (:func:`greedy_order`).

The gain's unit is voxels converted. Room completion (:meth:`Plan.gain_below`) and the
observation (:meth:`Plan.gain_share`) read it as a share of the room's structural voxels
(Structure + Occluded-structure), computed here and nowhere else, so that a new gain model changes
one entry of :data:`GAIN_MODELS` and nothing downstream.

Only the robot's belief is read, never a scene.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import shapely
from scipy.spatial.distance import cdist
from shapely.geometry import Polygon

from nbs_env.config import PlanningConfig, ScannerConfig
from nbs_env.errors import ConfigError
from nbs_env.labels import VoxelLabel
from nbs_env.mapping.voxels import VoxelGrid
from nbs_env.planning.navigation import (
    Candidates,
    NavigationConfig,
    Passage,
    TraversabilityMap,
    assume_blind_zone_free,
    candidates,
    traversability,
)
from nbs_env.planning.visibility import GainConfig, VisibilityModel

if TYPE_CHECKING:
    from nbs_env.belief import MissedVoxels, RoomBelief

__all__ = [
    "GAIN_MODELS",
    "GainModel",
    "Plan",
    "PlanningConfig",
    "check_gain_model",
    "greedy_order",
    "make_gain_model",
    "plan",
    "predict_gains",
    "register_gain_model",
    "sensor_positions",
    "structural_voxels",
    "traversable_floor",
    "unseeable_free",
    "without_unobservable",
]


class GainModel(Protocol):
    """What a gain model does: predicted conversions of scanner positions in one state of V(t)."""

    def gains(self, sensors: np.ndarray, scanner: ScannerConfig) -> np.ndarray:
        """(m,) int: predicted Occluded-structure→Structure conversions (voxels) for (m, 3) sensors."""
        ...


#: Builds a gain model from one state of V(t): ``factory(labels, origin, voxel_size, config)``.
GainModelFactory = Callable[[np.ndarray, np.ndarray, float, GainConfig], GainModel]

#: Gain models by the name :attr:`GainConfig.model` selects; :func:`register_gain_model` adds one.
GAIN_MODELS: dict[str, GainModelFactory] = {"visibility": VisibilityModel}


def register_gain_model(name: str, factory: GainModelFactory, *, replace: bool = False) -> None:
    """Make a gain model selectable as ``GainConfig(model=name)``.

    Parameters
    ----------
    name : str
        The name configurations use.
    factory : callable
        ``factory(labels, origin, voxel_size, config) -> GainModel``: ``labels`` (nx, ny, nz) uint8
        VoxelLabels of V(t), ``origin`` (3,) float, ``voxel_size`` float, ``config`` GainConfig.
    replace : bool
        Allow replacing a registered model of the same name.

    Raises
    ------
    ConfigError
        ``name`` is empty or taken (and ``replace`` is False), or ``factory`` is not callable.
    """
    if not isinstance(name, str) or not name:
        raise ConfigError(f"a gain model needs a non-empty name, got {name!r}")
    if not callable(factory):
        raise ConfigError(f"gain model {name!r}: the factory must be callable, got {type(factory).__name__}")
    if name in GAIN_MODELS and not replace:
        raise ConfigError(f"gain model {name!r} is registered already; pass replace=True to replace it")
    GAIN_MODELS[name] = factory


def check_gain_model(config: GainConfig) -> None:
    """Refuse a configuration whose gain model is not registered (before a robot takes a scan).

    Raises
    ------
    ConfigError
        ``config.model`` names no registered model; the message lists those that are.
    """
    if config.model not in GAIN_MODELS:
        raise ConfigError(f"unknown gain model {config.model!r}; registered: {', '.join(sorted(GAIN_MODELS))}")


def make_gain_model(labels: np.ndarray, origin: np.ndarray, voxel_size: float, config: GainConfig) -> GainModel:
    """The gain model ``config.model`` names, built on one state of V(t)."""
    check_gain_model(config)
    return GAIN_MODELS[config.model](labels, origin, voxel_size, config)


def greedy_order(gains: np.ndarray, path_lengths: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Candidate indices ranked by gain, ties to the shorter path; masked-out entries last."""
    gains = np.asarray(gains, dtype=float)
    path_lengths = np.asarray(path_lengths, dtype=float)
    valid = np.ones(len(gains), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    return np.lexsort((path_lengths, -gains, ~valid))


@dataclass(frozen=True, eq=False)
class Plan:
    """The planner's answer for one decision.

    Attributes
    ----------
    candidates : Candidates
        The NVPs (K slots, the real ones first).
    gains : (K,) int64
        Predicted conversions of each slot, voxels; 0 for padding and when gains are not predicted.
    structural_voxels : int
        Structure + Occluded-structure voxels of the room's V(t): the unit the gain is read in.
    seconds : float
        How long planning took.
    model : GainModel or None
        The gain model the gains came from (None when gains were not predicted): the robot asks it
        which voxels the chosen NVP was to see (:func:`unobservable_after`).
    labels : (nx, ny, nz) uint8 or None
        The room's V(t) as every method plans on it (:func:`unseeable_free`): what no scan from the
        room's stops could measure taken as free. The greedy navigates on it, and the compared
        methods build their maps from it (``info["belief"].labels``).
    """

    candidates: Candidates
    gains: np.ndarray
    structural_voxels: int
    seconds: float
    model: Any = field(default=None, repr=False, compare=False)
    labels: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def count(self) -> int:
        """How many slots are real NVPs."""
        return self.candidates.count

    def gain_share(self) -> np.ndarray:
        """(K,) float: the gains as shares of the room's structural voxels (0 for padding)."""
        return np.asarray(self.gains, dtype=float) / max(1, int(self.structural_voxels))

    def order(self) -> np.ndarray:
        """(count,) int: the real NVPs ranked by gain, ties to the shorter path."""
        n = self.count
        return greedy_order(self.gains[:n], self.candidates.path_length[:n])

    def best(self) -> int:
        """The next best scan: the NVP with the most predicted gain, ties to the shorter path.

        Raises
        ------
        IndexError
            There is no NVP.
        """
        if self.count == 0:
            raise IndexError("the plan has no next valid position")
        return int(self.order()[0])

    def gain_below(self, fraction: float) -> bool:
        """Whether no NVP predicts ``fraction`` of the room's structural voxels (METHOD §7); True
        when there is no NVP."""
        if self.count == 0:
            return True
        return int(self.gains[: self.count].max()) < fraction * self.structural_voxels


def structural_voxels(labels: np.ndarray) -> int:
    """Structure + Occluded-structure voxels of (nx, ny, nz) uint8 labels."""
    return int(np.count_nonzero((labels == VoxelLabel.STRUCTURE) | (labels == VoxelLabel.OCCLUDED_STRUCTURE)))


def unseeable_free(
    grid: VoxelGrid,
    stops: np.ndarray | Sequence[Sequence[float]],
    scanner: ScannerConfig,
    blocked: Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """V(t)'s labels with what no scan from the room's stops could measure taken as free: the cone
    under each stop below the scanner's lowest elevation and the ball within its minimum range
    (:func:`~nbs_env.planning.navigation.assume_blind_zone_free`), but for what each stop's low rays
    that returned nothing say is blocked.

    This is the one treatment of the scanner's blind zone in the project: the greedy's navigation
    (:func:`traversable_floor`) and every compared method's map (``BeliefView.labels``) read it, so
    that no method is drawn back to the unseen cone under the stop it stands on.

    Parameters
    ----------
    grid : VoxelGrid
        The room's V(t).
    stops : (m, 3) float
        Scanner positions of the room's stops (the robot's estimates).
    scanner : ScannerConfig
    blocked : sequence of (k, 3) float, optional
        Per stop, its low no-return directions (:attr:`~nbs_env.perception.roi.RoIScan.low_directions`).

    Returns
    -------
    (nx, ny, nz) uint8
        A copy: V(t) itself keeps its labels.
    """
    return assume_blind_zone_free(
        grid.labels, grid.origin, grid.voxel_size, stops, scanner.elevation_min, scanner.min_range, blocked
    )


def traversable_floor(
    grid: VoxelGrid,
    floor_z: float,
    stops: np.ndarray | Sequence[Sequence[float]],
    visited: np.ndarray | Sequence[Sequence[float]],
    scanner: ScannerConfig,
    navigation: NavigationConfig,
    blocked: Sequence[np.ndarray] | None = None,
    labels: np.ndarray | None = None,
    passages: Sequence[Passage] = (),
) -> TraversabilityMap:
    """Where the robot may stand in the room: V(t) with each stop's blind zone free
    (:func:`unseeable_free`) and the unsensed voxels near the floor that a measured ray crossed
    free (:attr:`VoxelGrid.crossed`), then the footprint's traversability test.

    Parameters
    ----------
    grid : VoxelGrid
        The room's V(t).
    floor_z : float
        The room's floor height (the RoI's).
    stops : (m, 3) float
        Scanner positions of the room's stops (the robot's estimates).
    visited : (v, 2) float
        Where the robot has stood in the room (its footprint there is known to be free).
    scanner : ScannerConfig
    navigation : NavigationConfig
    blocked : sequence of (k, 3) float, optional
        Per stop, its low no-return directions (:attr:`~nbs_env.perception.roi.RoIScan.low_directions`).
    labels : (nx, ny, nz) uint8, optional
        :func:`unseeable_free`'s answer for these stops, when the caller has it already.
    passages : sequence of Passage, optional
        The door the robot came in by (:class:`~nbs_env.planning.navigation.Passage`).
    """
    walkable = unseeable_free(grid, stops, scanner, blocked) if labels is None else labels
    crossed = grid.crossed & ((walkable == VoxelLabel.UNKNOWN) | (walkable == VoxelLabel.OCCLUDED_CLUTTER))
    if crossed.any():
        walkable = np.where(crossed, np.uint8(VoxelLabel.EMPTY), walkable)
    return traversability(walkable, grid.origin, grid.voxel_size, floor_z, navigation, visited, passages)


def within_roi(tmap: TraversabilityMap, polygon: np.ndarray) -> TraversabilityMap:
    """``tmap`` with its free cells limited to the RoI polygon (and the cells the robot stood on).

    The room's grid is the RoI's bounding box; where the room is not a rectangle, or the box reaches
    through a door, the box holds floor of other rooms that the scans saw, and an NVP there would
    scan the wrong room (measured on corpus:open_plan: a bathroom's first NVP lay in the living room
    it was entered from, and the RoI followed the robot there)."""
    # Every cell is tested: free cells the robot did not stand on are limited to the polygon, and
    # the outline keeps snapped candidates out of door openings.
    centres = tmap.centre_of(np.argwhere(np.ones(tmap.shape, dtype=bool)))
    inside = shapely.contains_xy(Polygon(polygon), centres[:, 0], centres[:, 1]).reshape(tmap.shape)
    return replace(tmap, free=tmap.free & (inside | tmap.visited), outline=inside)


def blocked_directions(belief, stops) -> list[np.ndarray] | None:
    """Per stop, the low no-return directions of the belief's scan taken there (None when the stops
    are not the belief's scans, one for one)."""
    scans = belief.scans
    if len(scans) != len(stops):
        return None
    return [np.asarray(s.low_directions, dtype=float).reshape(-1, 3) for s in scans]


def sensor_positions(points_xy: np.ndarray, floor_z: float, scanner: ScannerConfig) -> np.ndarray:
    """(m, 3) float: the scanner's optical centre above each of the (m, 2) floor points."""
    points_xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    return np.column_stack([points_xy, np.full(len(points_xy), floor_z + scanner.height)])


def predict_gains(
    labels: np.ndarray,
    origin: np.ndarray,
    voxel_size: float,
    points_xy: np.ndarray,
    floor_z: float,
    scanner: ScannerConfig,
    config: GainConfig | None = None,
) -> np.ndarray:
    """(m,) int64: predicted conversions of a scan from each of the (m, 2) floor points.

    ``labels``, ``origin`` and ``voxel_size`` describe V(t) (or a proxy of it a compared method
    builds); the model is :attr:`GainConfig.model`'s.
    """
    config = config or GainConfig()
    points_xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    if not len(points_xy):
        return np.zeros(0, dtype=np.int64)
    model = make_gain_model(labels, origin, voxel_size, config)
    gains = np.asarray(model.gains(sensor_positions(points_xy, floor_z, scanner), scanner))
    if gains.shape != (len(points_xy),):
        raise ValueError(f"gain model {config.model!r} returned shape {gains.shape} for {len(points_xy)} sensors")
    return gains.astype(np.int64, copy=False)


def plan(
    belief: RoomBelief,
    pose: np.ndarray,
    stops: np.ndarray | Sequence[Sequence[float]],
    visited: np.ndarray | Sequence[Sequence[float]],
    config: PlanningConfig,
    passages: Sequence[Passage] = (),
) -> Plan:
    """Plan the next decision from the robot's belief (module docstring).

    Parameters
    ----------
    belief : RoomBelief
        The current room's belief, after at least one scan.
    pose : (4, 4) float
        The robot's pose estimate.
    stops : (m, 3) float
        Scanner positions of the room's stops.
    visited : (v, 2) float
        Floor points the robot stood on in the room.
    config : PlanningConfig
    passages : sequence of Passage, optional
        The door the robot came in by: paths may leave it with the robot's radius of clearance.

    Raises
    ------
    ValueError
        The belief has no scan yet.
    """
    t = time.perf_counter()
    grid, roi = belief.grid, belief.roi
    if grid is None or roi is None:
        raise ValueError("plan needs a belief with at least one scan")
    xy = np.asarray(pose, dtype=float)[:2, 3]
    view = unseeable_free(grid, stops, config.scanner, blocked_directions(belief, stops))
    tmap = traversable_floor(
        grid, roi.floor_z, stops, visited, config.scanner, config.navigation, labels=view, passages=passages
    )
    cands = candidates(within_roi(tmap, roi.polygon), xy, config.navigation)
    gains = np.zeros(config.navigation.max_candidates, dtype=np.int64)
    model = None
    if config.predict_gains and cands.count:
        labels = without_unobservable(grid, belief.unobservable)
        model = make_gain_model(labels, grid.origin, grid.voxel_size, config.gain)
        sensors = sensor_positions(cands.points, roi.floor_z, config.scanner)
        gains[: cands.count] = np.asarray(model.gains(sensors, config.scanner), dtype=np.int64)
        again = missed_again(model, sensors, config.scanner, belief.missed_from_afar(labels), grid.voxel_size)
        gains[: cands.count] = np.maximum(gains[: cands.count] - again, 0)
    return Plan(cands, gains, structural_voxels(grid.labels), time.perf_counter() - t, model, view)


#: Metres: a voxel a scan missed beyond the dense range is out of the gains of views from within
#: this distance of that scan, in plan (:func:`missed_again`).
MISSED_NEIGHBOURHOOD = 1.0


def without_unobservable(grid: VoxelGrid, unobservable: np.ndarray) -> np.ndarray:
    """V(t)'s labels with the Occluded-structure voxels at the ``unobservable`` (n, 3) world points
    taken as Unknown (no target of a gain, no obstacle to a line of sight)."""
    points = np.asarray(unobservable, dtype=float).reshape(-1, 3)
    if not len(points):
        return grid.labels
    labels = grid.labels.copy()
    idx = grid.index_of(points)
    idx = idx[grid.inside(idx)]
    cells = tuple(idx.T)
    labels[cells] = np.where(labels[cells] == VoxelLabel.OCCLUDED_STRUCTURE, VoxelLabel.UNKNOWN, labels[cells])
    return labels


def unobservable_after(
    planned: Plan,
    index: int,
    floor_z: float,
    scanner: ScannerConfig,
    voxel_size: float,
    speculative: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Which voxels a scan from NVP ``index`` must convert if the gain model is right: the (n, 3)
    centres of the Occluded-structure voxels it predicted the scan to see, within the range where
    the scan's point spacing is finer than a voxel; and the sensor position.

    A voxel among them that the scan leaves Occluded-structure was no surface the scanner can see
    (a face of the RoI prism with no wall behind it under a sloped roof or an open top, a shadow the
    model got wrong); :attr:`~nbs_env.belief.RoomBelief.unobservable` keeps it out of later gains,
    so that a phantom gain cannot hold a room open to its scan cap. ``speculative`` tells which
    targets were guessed past a frontier face (:meth:`VoxelGrid.speculative`): those are checked
    at any range."""
    sensor = sensor_positions(planned.candidates.points[index : index + 1], floor_z, scanner)[0]
    model = planned.model
    if model is None or not hasattr(model, "visible"):
        return np.zeros((0, 3)), sensor, np.zeros((0, 3)), np.zeros(0)
    targets = model.targets[model.visible(sensor, scanner)]
    dense = voxel_size / np.radians(scanner.angular_step)
    distance = np.linalg.norm(targets - sensor, axis=1)
    near = distance <= dense
    # A voxel guessed past a frontier face is tested at any range: a scan that should see it and
    # does not refutes the guess (far beyond a window, an edge of the RoI outside the building).
    if speculative is not None:
        near |= speculative(targets)
    return targets[near], sensor, targets[~near], distance[~near]


def missed_again(
    model: GainModel | None,
    sensors: np.ndarray,
    scanner: ScannerConfig,
    missed: MissedVoxels,
    voxel_size: float,
) -> np.ndarray:
    """(c,) int: of each sensor's predicted conversions, those of ``missed`` voxels a scan had in view
    and left Occluded-structure from within :data:`MISSED_NEIGHBOURHOOD` of the sensor and no
    farther from the voxel.

    Beyond the dense range a scan's points land farther apart than a voxel (farther still at a
    grazing incidence), so a voxel it missed there may yet be hit from nearer or from another side;
    from about the same place, as far or farther, it will be missed again. Without this the greedy
    went back to one spot of a 7.7 m garage three times for its far ceiling (``ifc_garage_house``).

    Parameters
    ----------
    model : GainModel or None
        The plan's gain model; only a model with ``sees`` (:class:`VisibilityModel`) is corrected.
    sensors : (c, 3) float
    scanner : ScannerConfig
    missed : MissedVoxels
        The misses still Occluded-structure (:meth:`~nbs_env.belief.RoomBelief.missed_from_afar`).
    voxel_size : float
    """
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    if model is None or not hasattr(model, "sees") or not len(missed.voxels) or not len(sensors):
        return np.zeros(len(sensors), dtype=np.int64)
    near = cdist(sensors[:, :2], missed.sensors[:, :2]) <= MISSED_NEIGHBOURHOOD
    rows, records = np.nonzero(near)
    distance = np.linalg.norm(sensors[rows] - missed.voxels[missed.voxel[records]], axis=1)
    far = distance >= missed.ranges[records] - voxel_size
    out = np.zeros((len(sensors), len(missed.voxels)), dtype=bool)
    out[rows[far], missed.voxel[records[far]]] = True
    columns = np.flatnonzero(out.any(axis=0))
    if not len(columns):
        return np.zeros(len(sensors), dtype=np.int64)
    seen = model.sees(sensors, missed.voxels[columns], scanner)
    return np.count_nonzero(seen & out[:, columns], axis=1).astype(np.int64)
