"""A 3D replay of a scanning episode in the rerun viewer (https://rerun.io).

:class:`RunRecorder` logs an episode of :class:`~nbs_env.env.NBSEnv` to a rerun recording (``.rrd``)
on one sequence timeline, ``scan``, whose value is the number of scans taken so far: scan 1 is the
first scan (after ``reset``), and a decision step that also crosses a door adds two entries. Call
:meth:`RunRecorder.log_step` after ``reset`` and after every ``step``; :func:`view` opens a recording
in the native viewer, :func:`serve_web` serves it to a browser (no display needed)::

    with RunRecorder("five_rooms.rrd", "five_rooms") as recorder:
        obs, info = env.reset(seed=0)
        recorder.log_step(env)
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
            recorder.log_step(env)
            done = terminated or truncated
    view("five_rooms.rrd")

The recording keeps the robot's belief and the ground truth apart. Everything under ``world/`` except
``world/truth`` is the robot's own (measured points placed with its pose estimates, its voxel space,
RoI and plan); ``world/truth`` holds the true building and the true scan positions, for evaluation,
and the recording's blueprint hides it (as it hides ``world/ceiling``; the blueprint panel shows
them on a click). Entity paths (``{t}``: the scan number, three digits;
``{r}``: the robot's room number):

===================================  ==========================================================
``world/truth/mesh``                 the scene's mesh, coloured by surface class (static, hidden)
``world/truth/stops``                the true scan positions (hidden)
``world/scans/{t}``                  scan ``t``'s registered points (world frame), downsampled,
                                     below the cut (see ``world/ceiling``)
``world/robot/position``             where the last scan was taken (estimated)
``world/robot/stops``                every scan position so far, labelled with its number
``world/robot/path``                 the planned paths driven so far, on the floor
``world/belief/rooms/{r}/voxels/*``  V(t) of room ``r`` (the grid's labels), one entity per label:
                                     ``structure`` and ``clutter`` as solid boxes,
                                     ``occluded_structure`` and ``occluded_clutter`` as dots
                                     at the voxel centres (Empty and Unknown are not drawn)
``world/belief/rooms/{r}/roi``       the RoI prism: floor and ceiling polygons and verticals
``world/belief/rooms/{r}/se_faces``  outlines of the RoI faces classified SE
``world/belief/doors/{i}/frame``     door ``i`` as the robot detected it, coloured by state
``world/belief/doors/{i}/outward``   the direction the door leads out of its room
``world/plan/candidates``            the NVPs of the next decision, coloured by predicted gain
``world/plan/nbs``                   the NVP the policy chose (where the next scan was taken)
``world/ceiling/scans/{t}``          scan ``t``'s points and ...
``world/ceiling/rooms/{r}/*``        ... room ``r``'s drawn voxels (``sensed`` boxes, ``occluded``
                                     dots) less than :data:`CEILING_CUT` under the RoI's ceiling
                                     (hidden: they would roof the rooms over)
``stats/robot/*``                    path length, the chosen scan's predicted gain (scalars)
``stats/evaluation/*``               structural surface sensed, % (ground truth, scalars)
===================================  ==========================================================

rerun is an optional dependency (``pip install "nbs-env[viz]"``); it is imported only when a
recorder is made or a recording is viewed.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import uuid
import warnings
from collections.abc import Callable
from pathlib import Path
from types import ModuleType, TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from nbs_env.atomic import _nearly_full, temporary_path
from nbs_env.labels import LABEL_COLOURS, VoxelLabel

if TYPE_CHECKING:
    from nbs_env.env import NBSEnv
    from nbs_env.perception.faces import WallFace
    from nbs_env.planning.rooms import KnownDoor
    from nbs_env.storey import Storey
    from scenes import Scene

__all__ = [
    "APPLICATION_ID",
    "INSTALL_HINT",
    "TIMELINE",
    "NoViewerError",
    "NotARecordingError",
    "RunRecorder",
    "check_recording",
    "require_rerun",
    "serve_web",
    "view",
]

#: The application id of every recording (the viewer keeps one blueprint per application id).
APPLICATION_ID = "nbs-env"
#: The sequence timeline: the number of scans taken so far.
TIMELINE = "scan"
#: How to get the optional dependency.
INSTALL_HINT = 'pip install "nbs-env[viz]"'

#: The voxel labels drawn, each as its own entity so that the viewer can toggle it; Empty and Unknown
#: fill most of the grid and would hide everything else.
DRAWN_LABELS = (
    VoxelLabel.STRUCTURE,
    VoxelLabel.OCCLUDED_STRUCTURE,
    VoxelLabel.CLUTTER,
    VoxelLabel.OCCLUDED_CLUTTER,
)
#: The labels of voxels that hold points (drawn as solid boxes); the others are inferred (dots).
SENSED_LABELS = (VoxelLabel.STRUCTURE, VoxelLabel.CLUTTER)
#: Radius of an inferred voxel's dot, in voxels.
OCCLUDED_DOT = 0.2

#: RGB of the scene's surface classes (``scenes.SurfaceClass`` values 0-5: floor, ceiling, wall, door,
#: window, clutter), as ``scenes.render.CLASS_COLOURS`` draws them, with a grey ceiling so that the
#: mesh's top does not read as empty space.
_SURFACE_COLOURS = np.array(
    [[242, 239, 233], [200, 200, 200], [120, 120, 120], [224, 123, 0], [61, 143, 209], [156, 107, 60]],
    dtype=np.uint8,
)
#: One colour per scan, cycled (matplotlib's tab10): neighbouring scans tell apart.
_SCAN_COLOURS = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ],
    dtype=np.uint8,
)
#: Viridis at five stops, for the candidates' gains (a low gain dark blue, the best yellow).
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=float)
#: The door states' colours: not yet crossed, crossed (or leading into a scanned room), given up,
#: and onto the outside (left by default).
_DOOR_COLOURS = {
    "open": (255, 140, 0),
    "crossed": (44, 160, 44),
    "abandoned": (214, 39, 40),
    "exterior": (127, 127, 127),
}
#: Drawn height of a door frame, metres. The robot keeps no door height (KnownDoor); a nominal frame
#: makes a door stand out in 3D, where a line on the floor would vanish among the floor's points.
DOOR_FRAME_HEIGHT = 2.0
#: How far above the floor paths and candidates are drawn, metres: on the floor they would flicker
#: through the floor's points and voxels.
_LIFT = 0.05
#: Points and voxels higher than this below the RoI's ceiling go to ``world/ceiling`` (hidden), metres:
#: the ceiling slab and what hangs from it, so that a view from above looks into the rooms.
CEILING_CUT = 0.25


#: rerun's log filter (read when rerun is first imported): warnings, but not the writer's own
#: lines about a failed write, which :meth:`RunRecorder.close` turns into an OSError.
RERUN_LOG = "warn,re_log_encoding::rrd::file_sink=off,re_log_encoding::rrd::encoder=off,re_sdk::recording_stream=off"
#: How long a flush may go without the recording growing before it is called failed (rerun's own
#: flush waits forever on a full disk).
FLUSH_WAIT_S = 30.0


def require_rerun() -> tuple[ModuleType, ModuleType]:
    """``rerun`` and ``rerun.blueprint``, or an ImportError that says how to install them."""
    # rerun's writer reports a failed write in log lines of its own (a full disk: an ERROR and a
    # WARN per failure); RunRecorder.close says it in one line that names the file. The rest of
    # rerun's log stays on at warnings; a RUST_LOG of the user's own is theirs.
    os.environ.setdefault("RUST_LOG", RERUN_LOG)
    try:
        import rerun as rr
        import rerun.blueprint as rrb
    except ImportError as error:
        raise ImportError(f"the 3D replay needs rerun-sdk, which is not installed: {INSTALL_HINT}") from error
    return rr, rrb


class NotARecordingError(ValueError):
    """A file that is not a rerun recording (``.rrd``)."""


def downsample(points: np.ndarray, limit: int) -> np.ndarray:
    """At most ``limit`` of ``points`` with a fixed stride (every k-th point, from the first).

    A stride, not a random draw: a replay of the same episode logs the same points, and the scanner's
    row-by-row order spreads a stride evenly over the scan.

    Parameters
    ----------
    points : (n, d) float
    limit : int
        At least 1.

    Returns
    -------
    (m, d) float
        A view of ``points``, m = ceil(n / ceil(n / limit)) <= limit.
    """
    n = len(points)
    if n <= limit:
        return points
    return points[:: -(-n // limit)]


def gain_colours(gains: np.ndarray) -> np.ndarray:
    """(k, 3) uint8: viridis colours of the (k,) gains, scaled from 0 to the largest.

    The scale is per decision: colours compare the candidates of one plan, not plans over time.
    """
    g = np.asarray(gains, dtype=float)
    if not len(g):
        return np.zeros((0, 3), dtype=np.uint8)
    top = g.max()
    s = np.clip(g / top, 0.0, 1.0) if top > 0 else np.zeros_like(g)
    at = s * (len(_VIRIDIS) - 1)
    lo = np.minimum(np.floor(at).astype(int), len(_VIRIDIS) - 2)
    w = (at - lo)[:, None]
    return np.round(_VIRIDIS[lo] * (1 - w) + _VIRIDIS[lo + 1] * w).astype(np.uint8)


def prism_strips(polygon: np.ndarray, floor_z: float, ceiling_z: float) -> list[np.ndarray]:
    """The RoI prism as line strips: the closed floor and ceiling polygons, and one vertical per corner.

    Parameters
    ----------
    polygon : (n, 2) float
        The RoI outline, not closed.
    floor_z, ceiling_z : float

    Returns
    -------
    list of (p, 3) float
        Two closed (n + 1, 3) rings, then n (2, 3) verticals.
    """
    p = np.asarray(polygon, dtype=float)
    ring = np.vstack([p, p[:1]])
    lo = np.column_stack([ring, np.full(len(ring), floor_z)])
    hi = np.column_stack([ring, np.full(len(ring), ceiling_z)])
    return [lo, hi, *(np.array([lo[k], hi[k]]) for k in range(len(p)))]


def face_outlines(faces: list[WallFace]) -> list[np.ndarray]:
    """(5, 3) float closed outline of each wall face, with its diagonal (so that an SE face reads as
    a surface, not as the prism's edges it shares)."""
    out = []
    for face in faces:
        c = face.corners()
        out.append(np.vstack([c, c[:1]]))
        out.append(np.array([c[0], c[2]]))
    return out


def _door_state(door: KnownDoor) -> str:
    if door.failed:
        return "abandoned"
    if door.visited:
        return "crossed"
    return "exterior" if door.exterior else "open"


class RunRecorder:
    """Logs one episode of :class:`~nbs_env.env.NBSEnv` to a rerun recording (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file written (its folder is made).
    scene_name : str
        Names the recording in the viewer.
    max_points_per_scan : int
        Each scan's registered points are downsampled to at most this many (:func:`downsample`).

    Raises
    ------
    ImportError
        rerun-sdk is not installed (the message gives the install command).
    ValueError
        ``max_points_per_scan`` below 1.

    Notes
    -----
    A step that ends a room and crosses a door gives two scans (or more: a room found complete at its
    first scan is left at once), but the env keeps only the belief at the step's end: at an earlier
    scan's index the replay shows its points and position and the room's final RoI and SE faces (the
    robot's room model), while that room's voxels stay as the last step's end left them (none for a
    room the step both entered and left).
    """

    def __init__(self, path: str | Path, scene_name: str, *, max_points_per_scan: int = 50_000) -> None:
        if int(max_points_per_scan) < 1:
            raise ValueError(f"max_points_per_scan must be at least 1, got {max_points_per_scan}")
        rr, rrb = require_rerun()
        self._rr, self._rrb = rr, rrb
        self.path = Path(path)
        self.scene_name = str(scene_name)
        self.max_points_per_scan = int(max_points_per_scan)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Written under a temporary name beside it and renamed by close(): until then no file at
        # ``path`` passes for a whole recording (nbs view would serve half of one).
        self._partial = temporary_path(self.path, "partial")
        # A stream of its own (never the global one), with a fresh id: two recorders never mix.
        self._rec = rr.RecordingStream(application_id=APPLICATION_ID, recording_id=uuid.uuid4())
        # Rows carry the scan timeline only: wall-clock and tick stamps would make a replay of the
        # same episode differ, and offer the viewer timelines that mean nothing here.
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        self._rec.save(self._partial)
        self._rec.send_recording_name(self.scene_name)
        self._storey: Storey | None = None
        self._scans = 0  # scans logged
        self._models = 0  # finished rooms' models logged
        self._doors: list[str] = []  # logged state of each door
        self._closed = False

    # ------------------------------------------------------------------ context manager
    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ public
    @property
    def scans_logged(self) -> int:
        """How many scans are in the recording."""
        return self._scans

    def log_step(self, env: NBSEnv) -> None:
        """Log what is new in ``env``'s episode since the last call: its new scans, each at its own
        index of the ``scan`` timeline, and the belief and plan at the last of them.

        Parameters
        ----------
        env : NBSEnv or a gymnasium wrapper of one
            After ``reset`` (the first call) or ``step``. A step that took no scan (a masked action,
            a step past the end) logs nothing.

        Raises
        ------
        RuntimeError
            The recorder is closed, ``env`` was never reset, or it was reset since the first call (a
            recorder holds one episode).
        """
        if self._closed:
            raise RuntimeError(f"the recorder of {self.path} is closed")
        # gym.make's wrappers do not forward attributes.
        storey = getattr(getattr(env, "unwrapped", env), "storey", None)
        if storey is None:
            raise RuntimeError("call env.reset() before log_step(env)")
        if self._storey is None:
            self._storey = storey
            self._log_static(storey)
        elif storey is not self._storey:
            raise RuntimeError("env was reset since the recording started: a RunRecorder holds one episode")
        new = len(storey.scans) - self._scans
        if new <= 0:
            return
        # step_scans holds this step's scans only; a caller who skipped calls loses earlier points.
        pairs: list[tuple[np.ndarray, np.ndarray] | None] = list(storey.step_scans[-new:])
        if len(pairs) < new:
            warnings.warn(
                f"log_step was not called after every step: scans {self._scans + 1}-{len(storey.scans) - len(pairs)} "
                "are logged without their points",
                stacklevel=2,
            )
            pairs = [None] * (new - len(pairs)) + pairs
        for k, pair in zip(range(self._scans, len(storey.scans)), pairs, strict=True):
            self._log_scan(storey, k, None if pair is None else pair[0], last=k == len(storey.scans) - 1)
        self._scans = len(storey.scans)
        self._log_room_models(storey)
        self._log_doors(storey)

    def close(self, keep: bool = True) -> None:
        """Flush and close the recording, with its footer, and rename it to :attr:`path` (an earlier
        file there is replaced); ``keep=False`` removes it instead (a run that failed). Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._flush()
            self._rec.disconnect()
            if keep:
                os.replace(self._partial, self.path)
        finally:
            if self._partial.exists():
                self._partial.unlink()

    def _flush(self) -> None:
        """rerun's flush, waited on while the file grows; an OSError naming :attr:`path` if it fails."""
        size = -1
        while True:
            try:
                self._rec.flush(timeout_sec=FLUSH_WAIT_S)
                return
            except RuntimeError as exc:  # "Flush timed out", "File-writer thread shut down prematurely"
                now = self._partial.stat().st_size if self._partial.exists() else 0
                if "timed out" in str(exc) and now > size:  # still writing: a large recording, a slow disk
                    size = now
                    continue
                if _nearly_full(self._partial.parent):
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path)) from None
                raise OSError(errno.EIO, f"the recording could not be written ({exc})", str(self.path)) from None

    # ------------------------------------------------------------------ inside
    def _at(self, t: int) -> None:
        self._rec.set_time(TIMELINE, sequence=int(t))

    def _log_static(self, storey: Storey) -> None:
        """The coordinate frame, the truth mesh and the blueprint: once, timeless."""
        rr = self._rr
        rec = self._rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        scene = storey.scene
        vertices, normals, colours = _mesh_arrays(scene)
        rec.log(
            "world/truth/mesh",
            rr.Mesh3D(
                vertex_positions=vertices,
                vertex_normals=normals,
                vertex_colors=colours,
                triangle_indices=np.arange(len(vertices), dtype=np.uint32).reshape(-1, 3),
            ),
            static=True,
        )
        rec.send_blueprint(self._blueprint(scene), make_active=True, make_default=True)

    def _blueprint(self, scene: Scene) -> Any:
        """The layout: the 3D view with ``world/truth`` hidden, and the time series beside it."""
        rrb = self._rrb
        lo, hi = np.asarray(scene.mesh.bounds, dtype=float)
        centre, size = (lo + hi) / 2, hi - lo
        # Looking down from the south-west at the storey's middle (the scene's bounds only place the
        # camera, as a user would; nothing the robot decides reads them).
        reach = float(max(size[0], size[1]))
        eye = centre + np.array([-0.22 * reach, -0.62 * reach, 0.75 * reach])
        view3d = rrb.Spatial3DView(
            name=f"{self.scene_name}: the robot's belief",
            origin="world",
            contents="world/**",
            # Ground truth is for evaluation: hidden, one click away in the blueprint panel.
            overrides={
                "world/truth": rrb.EntityBehavior(visible=False),
                # Seen from above, the ceiling hides the rooms: a cutaway, one click away too.
                "world/ceiling": rrb.EntityBehavior(visible=False),
            },
            eye_controls=rrb.EyeControls3D(position=eye.tolist(), look_target=centre.tolist(), eye_up=[0, 0, 1]),
        )
        series = rrb.Vertical(
            rrb.TimeSeriesView(name="SE sensed % (evaluation)", origin="stats/evaluation"),
            rrb.TimeSeriesView(name="path length m", origin="stats/robot/path_length_m"),
            rrb.TimeSeriesView(name="predicted gain of each scan", origin="stats/robot/predicted_gain"),
        )
        return rrb.Blueprint(
            rrb.Horizontal(view3d, series, column_shares=[4, 1]),
            # Following: a finished recording opens at its last scan, a live one follows the robot.
            rrb.TimePanel(timeline=TIMELINE, play_state="following"),
            # The selection panel (hover a candidate for its gain) opens on a click; closed, the 3D
            # view gets the room.
            rrb.SelectionPanel(state="collapsed"),
            collapse_panels=False,
        )

    def _log_scan(self, storey: Storey, k: int, points: np.ndarray | None, last: bool) -> None:
        """Scan ``k`` (0-based) at timeline index k + 1, and at the last scan of a step the belief."""
        rr = self._rr
        rec = self._rec
        t = k + 1
        record = storey.scans[k]
        scanner_height = storey.config.robot.scanner.height
        if not record.door and k > 0:
            # The decision that led here was taken at index k, where its candidates are: mark the one
            # chosen there. storey.paths[j] is the path driven to scan j + 1 (every scan but the first
            # drives one), and a planned path ends at its NVP.
            self._at(k)
            end = np.asarray(storey.paths[k - 1], dtype=float)[-1]
            floor = float(record.estimated_position[2]) - scanner_height
            rec.log(
                "world/plan/nbs",
                rr.Points3D(
                    [[end[0], end[1], floor + _LIFT]],
                    radii=0.14,
                    colors=[[230, 0, 230]],
                    labels=[f"NBS: scan {t}"],
                    show_labels=True,
                ),
            )
        self._at(t)
        if points is not None:
            colour = _SCAN_COLOURS[k % len(_SCAN_COLOURS)]
            kept = downsample(points, self.max_points_per_scan)
            cut = _cut_height(storey, record.room)
            high = kept[:, 2] > cut if cut is not None else np.zeros(len(kept), dtype=bool)
            rec.log(f"world/scans/{t:03d}", rr.Points3D(kept[~high], radii=0.012, colors=colour))
            rec.log(f"world/ceiling/scans/{t:03d}", rr.Points3D(kept[high], radii=0.012, colors=colour))
        stops = np.array([s.estimated_position for s in storey.scans[: k + 1]], dtype=float)
        rec.log("world/robot/position", rr.Points3D(stops[-1:], radii=0.12, colors=[[255, 215, 0]]))
        rec.log(
            "world/robot/stops",
            rr.Points3D(stops, radii=0.07, colors=[[20, 20, 20]], labels=[str(j + 1) for j in range(len(stops))]),
        )
        strips = []
        for j in range(k):
            path = np.asarray(storey.paths[j], dtype=float)
            floor = float(storey.scans[j + 1].estimated_position[2]) - scanner_height
            strips.append(np.column_stack([path, np.full(len(path), floor + _LIFT)]))
        if strips:
            rec.log("world/robot/path", rr.LineStrips3D(strips, radii=0.025, colors=[[20, 20, 20]]))
        truth = np.array([s.true_position for s in storey.scans[: k + 1]], dtype=float)
        rec.log("world/truth/stops", rr.Points3D(truth, radii=0.05, colors=[[255, 0, 0]]))
        rec.log("stats/evaluation/structure_sensed_pct", rr.Scalars(float(record.structure_sensed_pct)))
        rec.log("stats/robot/path_length_m", rr.Scalars(float(record.path_length)))
        rec.log("stats/robot/predicted_gain", rr.Scalars(float(record.predicted_gain)))
        # The NBS is marked when the next scan is logged; until then (and at the episode's end)
        # nothing is chosen here.
        rec.log("world/plan/nbs", rr.Clear(recursive=False))
        if last:
            self._log_belief(storey)
        else:
            # No plan is known at a scan inside a step (the room ended there): last index's
            # candidates must not linger.
            rec.log("world/plan/candidates", rr.Clear(recursive=False))

    def _log_belief(self, storey: Storey) -> None:
        """The current room's V(t), RoI and SE faces, and the plan's candidates, at the current index."""
        rr = self._rr
        rec = self._rec
        view = storey.view()
        base = f"world/belief/rooms/{view.room}"
        grid = view.grid
        if grid is not None:
            cut = _cut_height(storey, view.room)
            high: dict[VoxelLabel, np.ndarray] = {}
            for label in DRAWN_LABELS:
                centres = grid.centres(np.argwhere(grid.labels == label)).astype(np.float32)
                if cut is not None:
                    above = centres[:, 2] > cut
                    high[label], centres = centres[above], centres[~above]
                self._log_voxels(f"{base}/voxels/{label.name.lower()}", {label: centres}, grid.voxel_size)
            if high:
                sensed = {k: v for k, v in high.items() if k in SENSED_LABELS}
                self._log_voxels(f"world/ceiling/rooms/{view.room}/sensed", sensed, grid.voxel_size)
                occluded = {k: v for k, v in high.items() if k not in SENSED_LABELS}
                self._log_voxels(f"world/ceiling/rooms/{view.room}/occluded", occluded, grid.voxel_size)
        if view.roi is not None:
            self._log_roi(base, view.roi.polygon, view.roi.floor_z, view.roi.ceiling_z, self._se_faces(view))
        count = view.count
        if count and view.roi is not None:
            m = np.asarray(view.mask, dtype=bool)
            xy = np.asarray(view.candidates_xy, dtype=float)[m]
            gains = np.asarray(view.gains)[m]
            z = np.full(len(xy), view.roi.floor_z + _LIFT)
            rec.log(
                "world/plan/candidates",
                rr.Points3D(
                    np.column_stack([xy, z]),
                    radii=0.13,
                    colors=gain_colours(gains),
                    labels=[str(int(g)) for g in gains],
                    show_labels=False,
                ),
                rr.AnyValues(
                    predicted_gain=gains.astype(np.int64),
                    gain_share=np.asarray(view.gain_share, dtype=float)[m],
                    path_length_m=np.asarray(view.path_length, dtype=float)[m],
                ),
            )
        else:
            rec.log("world/plan/candidates", rr.Clear(recursive=False))

    def _log_voxels(self, path: str, centres: dict[VoxelLabel, np.ndarray], size: float) -> None:
        """Voxels by label, all sensed (solid boxes) or all occluded (dots at their centres).

        Sensed voxels are solid cubes, exact in place and size. What the robot only infers is drawn
        as dots, so that one sees through it: its volumes behind furniture would wall the rooms off
        (0.41's Boxes3D draws no alpha, and rr.VoxelGridMap, given explicit colours, is flagged
        with a warning in the viewer).
        """
        rr = self._rr
        labels = list(centres)
        if not labels:
            return
        points = np.concatenate([centres[k] for k in labels])
        colours = np.concatenate([np.broadcast_to(LABEL_COLOURS[int(k)], (len(centres[k]), 3)) for k in labels])
        if labels[0] in SENSED_LABELS:
            archetype = rr.Boxes3D(centers=points, half_sizes=[[size / 2] * 3], colors=colours, fill_mode="solid")
        else:
            archetype = rr.Points3D(points, radii=OCCLUDED_DOT * size, colors=colours)
        self._rec.log(path, archetype)

    @staticmethod
    def _se_faces(view: Any) -> list[WallFace]:
        se = np.asarray(view.se, dtype=bool)
        return [f for f, s in zip(view.roi.wall_faces, se, strict=False) if s]

    def _log_roi(self, base: str, polygon: np.ndarray, floor_z: float, ceiling_z: float, se: list[WallFace]) -> None:
        rr = self._rr
        self._rec.log(
            f"{base}/roi",
            rr.LineStrips3D(prism_strips(polygon, floor_z, ceiling_z), radii=0.015, colors=[[90, 90, 90]]),
        )
        self._rec.log(f"{base}/se_faces", rr.LineStrips3D(face_outlines(se), radii=0.03, colors=[[31, 119, 180]]))

    def _log_room_models(self, storey: Storey) -> None:
        """Each room finished since the last call: its final RoI and SE faces, at its last scan."""
        models = storey.rooms.models
        for model in models[self._models :]:
            last = max((s.scan for s in storey.scans if s.room == model.index), default=len(storey.scans) - 1)
            self._at(last + 1)
            self._log_roi(
                f"world/belief/rooms/{model.index}", model.polygon, model.floor_z, model.ceiling_z, model.se_faces
            )
        self._models = len(models)
        self._at(len(storey.scans))

    def _log_doors(self, storey: Storey) -> None:
        """Doors new or changed since the last call; a new one at the index it was detected at."""
        rr = self._rr
        rec = self._rec
        now = len(storey.scans)
        detected = [e for e in storey.door_events if e["event"] == "detected"]
        for i, door in enumerate(storey.rooms.doors):
            state = _door_state(door)
            if i < len(self._doors) and self._doors[i] == state:
                continue
            t = now
            if i >= len(self._doors):
                at = [e["scan"] for e in detected if np.allclose(e["centre"], door.centre[:2], atol=2e-3)]
                t = max(1, min(at)) if at else now
                self._doors.append(state)
            self._doors[i] = state
            self._at(t)
            centre = np.asarray(door.centre, dtype=float)
            outward = np.asarray(door.outward, dtype=float)[:2]
            across = np.array([-outward[1], outward[0]]) * door.width / 2
            z0 = float(centre[2]) if len(centre) > 2 else 0.0
            a, b = centre[:2] - across, centre[:2] + across
            frame = np.array([[*a, z0], [*a, z0 + DOOR_FRAME_HEIGHT], [*b, z0 + DOOR_FRAME_HEIGHT], [*b, z0], [*a, z0]])
            colour = _DOOR_COLOURS[state]
            rec.log(
                f"world/belief/doors/{i}/frame",
                rr.LineStrips3D([frame], radii=0.03, colors=[colour], labels=[f"door {i}: {state}"], show_labels=True),
            )
            rec.log(
                f"world/belief/doors/{i}/outward",
                rr.Arrows3D(
                    origins=[[*centre[:2], z0 + 1.0]], vectors=[[*(0.6 * outward), 0.0]], radii=0.025, colors=[colour]
                ),
            )
        self._at(now)


def _cut_height(storey: Storey, room: int) -> float | None:
    """Where ``world/ceiling`` starts in the robot's room ``room`` (:data:`CEILING_CUT` below its RoI's
    ceiling), or None: a room open to the sky, or no RoI known."""
    robot = storey.robot
    roi = robot.belief.roi if room == storey.rooms.current else None
    if roi is not None:
        return roi.ceiling_z - CEILING_CUT if roi.has_ceiling else None
    model = next((m for m in storey.rooms.models if m.index == room), None)
    if model is None or not model.has_ceiling:
        return None
    return model.ceiling_z - CEILING_CUT


def _mesh_arrays(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scene's triangles with their own vertices, so that each takes its face's class colour.

    Returns
    -------
    vertices : (3F, 3) float32
    normals : (3F, 3) float32
        Each face's normal on its three vertices (flat shading).
    colours : (3F, 3) uint8
    """
    mesh = scene.mesh
    faces = np.asarray(mesh.faces)
    vertices = np.asarray(mesh.vertices, dtype=np.float32)[faces].reshape(-1, 3)
    normals = np.repeat(np.asarray(mesh.face_normals, dtype=np.float32), 3, axis=0)
    labels = np.clip(np.asarray(scene.face_labels, dtype=np.int64), 0, len(_SURFACE_COLOURS) - 1)
    colours = np.repeat(_SURFACE_COLOURS[labels], 3, axis=0)
    return vertices, normals, colours


#: rerun's default ports: its gRPC server (the recording's data) and the web viewer's HTTP server.
GRPC_PORT = 9876
WEB_PORT = 9090
#: How long :func:`serve_web` waits for the web viewer to answer before it gives up, seconds.
SERVE_TIMEOUT = 60.0


class NoViewerError(RuntimeError):
    """No viewer could start: no display for the native viewer, or rerun's process failed."""


def check_recording(path: str | Path) -> Path:
    """``path`` as a Path, once it is known to hold a rerun recording that rerun can read.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    NotARecordingError
        The file is not a rerun recording, or rerun cannot read it (damaged, cut short, empty).
    ImportError
        rerun-sdk is not installed (the message gives the install command).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no recording at {path}: record one with nbs scan --record RUN.rrd")
    with path.open("rb") as f:
        magic = f.read(4)
    # Every version of the .rrd format starts with "RRF" and a version character.
    if not magic.startswith(b"RRF"):
        raise NotARecordingError(f"{path} is not a rerun recording (.rrd): it starts with {magic!r}, not b'RRF'")
    rr, _ = require_rerun()
    # The viewer would open a damaged file on an empty screen (or its server serve nothing) and
    # say why only in its log: rerun's own reader says it here. A finished recording's footer
    # lists its recordings, so this reads little of a large file.
    try:
        with warnings.catch_warnings():
            # A recording cut short has no footer; the warning says so before the read fails.
            warnings.simplefilter("ignore")
            recordings = list(rr.chunk.RrdReader(path).recordings())
    except (RuntimeError, OSError, ValueError) as error:
        raise NotARecordingError(f"{path} cannot be read as a rerun recording: {error}") from error
    if not recordings:
        raise NotARecordingError(f"{path} holds no recording")
    return path


def rerun_binary() -> Path:
    """The viewer binary of the installed rerun-sdk (what ``python -m rerun_cli`` runs).

    Run directly, not through ``python -m rerun_cli``: that wrapper exits 0 whatever the viewer
    returns, so a viewer that failed to start would look like one the user closed.

    Raises
    ------
    ImportError
        rerun-sdk, or its viewer binary, is not installed.
    """
    import os

    require_rerun()
    try:
        import rerun_cli
    except ImportError as error:
        raise ImportError(f"rerun-sdk's viewer (rerun_cli) is not installed: {INSTALL_HINT}") from error
    override = os.environ.get("RERUN_CLI_PATH")  # as rerun_cli honours it
    folder = Path(rerun_cli.__file__).parent
    if override:
        binary = Path(override)
    elif sys.platform == "darwin" and (folder / "Rerun.app").exists():
        binary = folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun"
    else:
        binary = folder / ("rerun.exe" if sys.platform.startswith("win") else "rerun")
    if not binary.is_file():
        raise ImportError(f"rerun-sdk's viewer binary is missing at {binary}: reinstall it, {INSTALL_HINT}")
    return binary


def display_problem() -> str | None:
    """Why a native window cannot open here, or None: on Linux and other X11 or Wayland systems,
    neither ``DISPLAY`` nor ``WAYLAND_DISPLAY`` (nor ``WAYLAND_SOCKET``) is set. macOS and Windows
    always have a desktop to try."""
    import os

    if sys.platform == "darwin" or sys.platform.startswith("win"):
        return None
    if any(os.environ.get(name) for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return None
    return "no display to open rerun's viewer on (neither DISPLAY nor WAYLAND_DISPLAY is set)"


def view(path: str | Path) -> int:
    """Open a recording in rerun's native viewer (the binary shipped with rerun-sdk) and wait for it
    to close.

    Parameters
    ----------
    path : str or Path
        A ``.rrd`` file, e.g. written by :class:`RunRecorder`.

    Returns
    -------
    int
        0: the viewer was closed (or stopped with Ctrl-C).

    Raises
    ------
    FileNotFoundError, NotARecordingError, ImportError
        As :func:`check_recording`.
    NoViewerError
        No display (:func:`display_problem`), or the viewer exited with an error (its own message
        is on stderr before it); :func:`serve_web` needs no display.
    """
    path = check_recording(path)
    binary = rerun_binary()
    problem = display_problem()
    if problem is not None:
        raise NoViewerError(problem)
    process = subprocess.Popen([str(binary), str(path)], preexec_fn=_die_with_parent)
    try:
        code = process.wait()
    except KeyboardInterrupt:
        # Ctrl-C reached the viewer too (one process group): it closes as the user asked.
        _stop(process)
        return 0
    if code != 0:
        raise NoViewerError(f"rerun's viewer exited with code {code}")
    return 0


def _free_port(host: str) -> int:
    """A TCP port free on ``host`` now (the system picks it)."""
    import socket

    family, kind, proto, _, address = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)[0]
    with socket.socket(family, kind, proto) as sock:
        sock.bind(address)
        return int(sock.getsockname()[1])


def _port_problem(host: str, port: int) -> str | None:
    """Why a server could not listen on ``host:port`` now ("in use", ...), or None when it could."""
    import errno
    import socket

    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as sock:
            sock.bind(address)
    except OSError as exc:
        return "in use by another program" if exc.errno == errno.EADDRINUSE else (exc.strerror or str(exc))
    return None


def _url_host(bind: str) -> str:
    """The host a browser on this machine reaches a server bound to ``bind`` at."""
    if bind in ("0.0.0.0", "::", ""):
        return "127.0.0.1"
    return f"[{bind}]" if ":" in bind else bind


def web_viewer_url(host: str, web_port: int, grpc_port: int) -> str:
    """The address to open in a browser: rerun's web viewer, told where the recording's server is
    (as rerun itself prints it)."""
    from urllib.parse import quote

    proxy = f"rerun+http://{host}:{grpc_port}/proxy"
    return f"http://{host}:{web_port}/?url={quote(proxy, safe='')}"


def serve_web(
    path: str | Path,
    *,
    port: int = GRPC_PORT,
    web_port: int = WEB_PORT,
    bind: str = "127.0.0.1",
    on_ready: Callable[[str], None] | None = None,
    timeout: float = SERVE_TIMEOUT,
) -> int:
    """Serve a recording to a browser with rerun's web viewer until Ctrl-C (or SIGTERM).

    rerun's binary hosts the recording on a gRPC server and the web viewer over HTTP
    (``rerun --serve-web``); no display is needed.

    Parameters
    ----------
    path : str or Path
        A ``.rrd`` file.
    port : int
        The gRPC server's port (0: a free one).
    web_port : int
        The web viewer's HTTP port (0: a free one).
    bind : str
        The address both servers listen on: ``127.0.0.1`` this machine only (forward both ports to
        view from another, e.g. ``ssh -L``), ``0.0.0.0`` every interface.
    on_ready : callable, optional
        Called with the viewer's URL once it answers HTTP.
    timeout : float
        Seconds to wait for it to answer.

    Returns
    -------
    int
        0 once stopped by Ctrl-C or SIGTERM.

    Raises
    ------
    FileNotFoundError, NotARecordingError, ImportError
        As :func:`check_recording`.
    NoViewerError
        rerun's server exited (a port in use, an address it cannot bind) or did not answer within
        ``timeout`` seconds; the message ends with its log's last lines.
    """
    import signal
    import tempfile
    import time
    import urllib.request

    path = check_recording(path)
    binary = rerun_binary()
    # A port the user named is tried here first: rerun, given one in use, may neither exit nor serve
    # within the timeout, and the error would blame its start-up instead of the port.
    import socket

    try:
        socket.getaddrinfo(bind, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise NoViewerError(
            f"the address to serve on (--bind) {bind!r}: {getattr(exc, 'strerror', None) or exc}"
        ) from None
    for what, wanted in (("the recording's port (--port)", port), ("the web viewer's port (--web-port)", web_port)):
        problem = _port_problem(bind, wanted) if wanted else None
        if problem is not None:
            raise NoViewerError(f"{what} {wanted} on {bind}: {problem}")
    try:
        port = port or _free_port(bind)
        web_port = web_port or _free_port(bind)
    except (OSError, UnicodeError) as exc:  # a name that resolves to nothing, an address not this machine's
        raise NoViewerError(
            f"the address to serve on (--bind) {bind!r}: {getattr(exc, 'strerror', None) or exc}"
        ) from None
    host = _url_host(bind)
    url = web_viewer_url(host, web_port, port)
    command = [str(binary), "--serve-web", "--bind", bind, "--port", str(port), "--web-viewer-port", str(web_port)]
    # rerun's log (INFO lines, its first-run banner) goes to a file, shown when it fails: on the
    # terminal it would bury the URL. A pipe would fill while nobody reads it.
    with tempfile.TemporaryFile(mode="w+b") as log:
        process = subprocess.Popen(
            [*command, str(path)], stdout=log, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent
        )

        def failure(what: str) -> NoViewerError:
            log.seek(0)
            return NoViewerError(what + _log_tail(log.read().decode(errors="replace")))

        def terminate(signum: int, frame: object) -> None:
            raise KeyboardInterrupt

        # SIGTERM stops the server as Ctrl-C does; left to its default, it would orphan rerun's process.
        previous = signal.signal(signal.SIGTERM, terminate) if _main_thread() else None
        try:
            deadline = time.monotonic() + timeout
            while True:
                if process.poll() is not None:
                    raise failure(f"rerun's web viewer exited with code {process.returncode} before it served")
                try:
                    with urllib.request.urlopen(f"http://{host}:{web_port}/", timeout=1.0):
                        break
                except OSError:  # urllib's URLError included: not listening yet
                    if time.monotonic() > deadline:
                        _stop(process)
                        raise failure(f"rerun's web viewer did not answer at {url} within {timeout:.0f} s") from None
                    time.sleep(0.2)
            if on_ready is not None:
                on_ready(url)
            code = process.wait()
            raise failure(f"rerun's web viewer stopped with code {code}")
        except KeyboardInterrupt:
            _stop(process)
            return 0
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)
            if process.poll() is None:
                _stop(process)


def _log_tail(text: str, lines: int = 3) -> str:
    """The last warnings and errors of rerun's log (colour codes removed, INFO lines dropped), as
    the end of an error message; empty when it said nothing."""
    import re

    said = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip() for line in text.splitlines()]
    said = [line for line in said if line and " INFO " not in line]
    return "; rerun said:\n  " + "\n  ".join(said[-lines:]) if said else ""


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _die_with_parent() -> None:
    """In rerun's process before it starts: on Linux, end it when its parent dies, so that a killed
    ``nbs view`` (SIGKILL, a closed session) leaves no server behind holding ports and a core."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG


def _stop(process: subprocess.Popen, grace: float = 5.0) -> None:
    """Stop rerun's process: it may have had Ctrl-C already (one process group); else SIGINT, which
    it handles as Ctrl-C, then SIGKILL after ``grace`` seconds."""
    import signal

    if process.poll() is None:
        try:
            process.wait(timeout=0.5)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGINT if sys.platform != "win32" else signal.SIGTERM)
    try:
        process.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
