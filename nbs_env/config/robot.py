"""What the robot is made of: the scanner, its drift, the registration, the base and its footprint,
and the per-scan stages of the method (the RoI, the doors, the gain).

Defaults follow ``METHOD.md``; where a default was changed after a measurement, the docstring says
why. The rules that end a room and search for doors are the storey's (:mod:`nbs_env.config.rooms`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from nbs_env.config.checks import (
    Config,
    _at_most,
    _finite,
    _finite_fields,
    _integer,
    _plain_numbers,
    _require,
    _within,
)
from scenes.limits import is_finite

__all__ = [
    "MAX_ANGULAR_STEP",
    "MAX_ICP_ITERATIONS",
    "MAX_RAYS",
    "DoorConfig",
    "GainConfig",
    "NavigationConfig",
    "OdometryConfig",
    "PlanningConfig",
    "RegistrationConfig",
    "RoIConfig",
    "RobotConfig",
    "ScannerConfig",
]

#: Patterns above this many rays per scan are refused: they would take minutes and gigabytes.
MAX_RAYS = 50_000_000

#: The coarsest simulated angular step, degrees: 8 columns over 360°, the fewest the RoI's free-space
#: outline (at least 4 azimuth bins, capped at the scanner's columns) and the door search work with.
MAX_ANGULAR_STEP = 45.0

#: Iterations per ICP stage, at most: the default's 40 converge; a million is an hour per scan.
MAX_ICP_ITERATIONS = 10_000


@dataclass(frozen=True)
class ScannerConfig(Config):
    """The simulated terrestrial laser scanner (a Riegl VZ-400 on a mobile base), METHOD §1.

    Attributes
    ----------
    angular_step : float
        Degrees between neighbouring rays, horizontally and vertically. 0.5 is the env default
        (~145 k rays), 0.2 report quality (~0.9 M), 1.0 or coarser for fast RL.
    elevation_min, elevation_max : float
        Vertical field of view in degrees (-40 to +60: 100°). The horizontal field is 360°.
    min_range, max_range : float
        Returns outside [min_range, max_range] metres are dropped.
    range_noise : float
        Standard deviation of the Gaussian range noise in metres, at ``noise_range`` on a surface seen
        head-on. How it changes with range and incidence: ``noise_exponent``.
    noise_floor : float
        The part of the noise that does not depend on the returned signal (clock, quantisation), in
        metres; counted as at most ``range_noise`` (so that ``range_noise=0`` turns the noise off).
    noise_range : float
        The range at which the datasheet states ``range_noise``, metres.
    noise_exponent : float
        How the rest of the noise grows as the returned power P falls, P ∝ cos(incidence) / range²
        (one reflectance for every surface):
        ``σ² = noise_floor² + (range_noise² - noise_floor²) · (P(noise_range, 0°) / P)^(2 · noise_exponent)``.
        0 (METHOD's constant σ), 0.5 (a shot-noise-limited receiver: σ grows with range over
        sqrt(cos)), 1 (σ ∝ 1/P). Incidence is counted up to 85° from the normal.
    beam_divergence : float
        Full angle of the laser beam, radians. A beam whose footprint straddles a depth
        discontinuity returns a **mixed pixel**: its range is the power-weighted mean of the surfaces
        in the footprint (within ``echo_separation``), a point floating between them. 0 turns mixed
        pixels off (METHOD's ideal thin ray).
    beam_diameter : float
        Diameter of the beam at the exit window, metres; the footprint at range R is
        ``beam_diameter + beam_divergence · R``.
    echo_separation : float or None
        Surfaces farther apart along the beam than this (metres) return separate echoes, of which the
        scanner keeps the strongest (a pulsed scanner: c·τ/2 of its pulse length τ); nearer ones blend
        into one. None: every footprint blends (a phase-based scanner).
    instrument_step : float or None
        The real instrument's angular step at its resolution setting, degrees: each simulated return
        stands for
        ``(angular_step / instrument_step)²`` of the instrument's, so that the scan-quality density
        (:meth:`nbs_env.evaluation.CoverageMeter.quality`) is the instrument's. None: the simulated
        pattern is the instrument's.
    setup_time : float
        Seconds a station spends before the scan starts (the base stops and settles, the tilt is read),
        counted in every scan's acquisition time.
    height : float
        Optical centre above the floor the robot stands on, in metres.
    points_per_second : float
        Acquisition rate, for the simulated acquisition time when ``station_time`` is None.
    station_time : float or None
        Seconds the scan itself takes on the real instrument at its chosen resolution and quality
        setting (a scanner preset's figure, :mod:`nbs_env.config.scanners`), without ``setup_time``.
        None: the returned points over ``points_per_second``, the time the simulated pattern alone
        would take.
    preset : str or None
        The scanner preset (``"NAME:SETTING"``) the datasheet values came from
        (:func:`nbs_env.config.scanners.scanner_config`); None for values set by hand.
    """

    angular_step: float = 0.5
    elevation_min: float = -40.0
    elevation_max: float = 60.0
    min_range: float = 1.5
    max_range: float = 350.0
    range_noise: float = 0.005
    noise_floor: float = 0.0
    noise_range: float = 10.0
    noise_exponent: float = 0.0
    # The VZ-400's 0.3 mrad beam and 5 ns pulse (HELIOS++'s riegl_vz400 [S2]): c·τ/2 = 0.75 m.
    beam_divergence: float = 0.0003
    beam_diameter: float = 0.0
    echo_separation: float | None = 0.75
    instrument_step: float | None = None
    setup_time: float = 0.0
    height: float = 1.5
    points_per_second: float = 122_000.0
    station_time: float | None = None
    preset: str | None = None

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(
            angular_step=self.angular_step,
            elevation_min=self.elevation_min,
            elevation_max=self.elevation_max,
            min_range=self.min_range,
            max_range=self.max_range,
            range_noise=self.range_noise,
            noise_floor=self.noise_floor,
            noise_range=self.noise_range,
            noise_exponent=self.noise_exponent,
            beam_divergence=self.beam_divergence,
            beam_diameter=self.beam_diameter,
            setup_time=self.setup_time,
            height=self.height,
            points_per_second=self.points_per_second,
        )
        _require(self.angular_step > 0, f"angular_step must be > 0 degrees, got {self.angular_step}")
        _at_most(self, "angular_step", MAX_ANGULAR_STEP, "degrees")
        _require(
            -90.0 <= self.elevation_min < self.elevation_max <= 90.0,
            f"need -90 <= elevation_min < elevation_max <= 90, got {self.elevation_min}, {self.elevation_max}",
        )
        _require(self.min_range >= 0, f"min_range must be >= 0, got {self.min_range}")
        # The longest-ranging terrestrial scanners reach about 6 km; beyond 10 km a figure is a typo.
        _require(self.max_range <= 10_000, f"max_range must be at most 10,000 m, got {self.max_range}")
        _require(
            self.min_range < self.max_range,
            f"min_range ({self.min_range} m) must be below max_range ({self.max_range} m)",
        )
        _require(self.range_noise >= 0, f"range_noise must be >= 0, got {self.range_noise}")
        _require(self.noise_floor >= 0, f"noise_floor must be >= 0 m, got {self.noise_floor}")
        # The range a datasheet's noise figure is given at: 10 m, 100 m. Below a decimetre its square
        # divides the noise model by nearly nothing (1e-300 m overflowed to a ZeroDivisionError).
        _require(self.noise_range >= 0.1, f"noise_range must be >= 0.1 m, got {self.noise_range}")
        # A metre of noise scatters a room's walls over the room; more scatters points past the storey.
        _at_most(self, "range_noise", 1.0, "metre")
        _at_most(self, "noise_floor", 1.0, "metre")
        _at_most(self, "noise_range", 10_000.0, "metres")
        _require(0 <= self.noise_exponent <= 2, f"noise_exponent must be in [0, 2], got {self.noise_exponent}")
        _require(
            0 <= self.beam_divergence <= 0.05, f"beam_divergence must be in [0, 0.05] rad, got {self.beam_divergence}"
        )
        _require(0 <= self.beam_diameter <= 0.1, f"beam_diameter must be in [0, 0.1] m, got {self.beam_diameter}")
        if self.echo_separation is not None:
            _finite(echo_separation=self.echo_separation)
            _require(self.echo_separation > 0, f"echo_separation must be > 0 m or None, got {self.echo_separation}")
            _at_most(self, "echo_separation", 100.0, "metres")
        if self.instrument_step is not None:
            _finite(instrument_step=self.instrument_step)
            _require(
                self.instrument_step > 0, f"instrument_step must be > 0 degrees or None, got {self.instrument_step}"
            )
            # The finest real step is the VZ-400's 0.0024°: (angular_step / instrument_step)² weighs
            # each return, and a step of 1e-300° makes it infinite.
            _within(self, "instrument_step", 0.001, MAX_ANGULAR_STEP, "degrees")
        _require(
            0 <= self.setup_time <= 86_400, f"setup_time must be within [0, 86,400] seconds, got {self.setup_time}"
        )
        _require(self.points_per_second > 0, f"points_per_second must be > 0, got {self.points_per_second}")
        # Times are points over the rate: below one a second, a scan's time overflows to infinity.
        _within(self, "points_per_second", 1.0, 1e9, "points per second")
        # The optical centre: above the floor, below any storey's ceiling (the storey limits' 50 m).
        _within(self, "height", 0.0, 10.0, "metres", open_low=True)
        if self.station_time is not None:
            _finite(station_time=self.station_time)
            _require(self.station_time > 0, f"station_time must be > 0 seconds or None, got {self.station_time}")
            _at_most(self, "station_time", 86_400.0, "seconds")
        _require(
            self.preset is None or isinstance(self.preset, str), f"preset must be a name or None, got {self.preset!r}"
        )
        # In floats first: a step of 1e-320° makes the exact count's round() overflow.
        rays = 360.0 / self.angular_step * ((self.elevation_max - self.elevation_min) / self.angular_step + 1)
        if rays <= 2 * MAX_RAYS:
            rays = self.n_rows * self.n_cols
        _require(
            rays <= MAX_RAYS,
            f"angular_step {self.angular_step}° makes {rays:,.0f} rays per scan; the limit is {MAX_RAYS:,}",
        )

    @property
    def n_cols(self) -> int:
        """Columns of the pattern: azimuths over 360°."""
        return max(1, round(360.0 / self.angular_step))

    @property
    def n_rows(self) -> int:
        """Rows of the pattern: elevations from ``elevation_min`` to ``elevation_max`` inclusive."""
        return math.floor((self.elevation_max - self.elevation_min) / self.angular_step + 1e-9) + 1

    @property
    def n_rays(self) -> int:
        return self.n_rows * self.n_cols

    @property
    def density_weight(self) -> float:
        """Instrument returns each simulated return stands for: ``(angular_step / instrument_step)²``, else 1."""
        if self.instrument_step is None:
            return 1.0
        return (self.angular_step / self.instrument_step) ** 2

    @property
    def mixed_pixels(self) -> bool:
        """Whether beams have a footprint (mixed pixels at depth discontinuities)."""
        return self.beam_divergence > 0 or self.beam_diameter > 0


@dataclass(frozen=True)
class OdometryConfig(Config):
    """How the pose the robot believes in drifts from the true one, METHOD §2.

    Attributes
    ----------
    sigma_xy_per_m : float
        Standard deviation of the x and y error per metre driven.
    sigma_yaw_deg_per_m : float
        Standard deviation of the heading error, degrees per metre driven.
    sigma_tilt_deg : float
        Standard deviation of the scanner's true roll and pitch at each stop (uneven floor); the
        odometry reports them as zero, so only the 6-DoF ICP can find them.
    """

    sigma_xy_per_m: float = 0.02
    sigma_yaw_deg_per_m: float = 0.5
    sigma_tilt_deg: float = 0.2

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(
            sigma_xy_per_m=self.sigma_xy_per_m,
            sigma_yaw_deg_per_m=self.sigma_yaw_deg_per_m,
            sigma_tilt_deg=self.sigma_tilt_deg,
        )
        for name, value in asdict(self).items():
            _require(value >= 0, f"{name} must be >= 0, got {value}")
        # Drift of a metre per metre driven, half a turn per metre, or a scanner tilted past 45°
        # are no odometry.
        _at_most(self, "sigma_xy_per_m", 1.0, "metre per metre")
        _at_most(self, "sigma_yaw_deg_per_m", 180.0, "degrees per metre")
        _at_most(self, "sigma_tilt_deg", 45.0, "degrees")


@dataclass(frozen=True)
class RegistrationConfig(Config):
    """ICP of a new scan against the accumulated cloud S(t), METHOD §2 (GICP by default).

    Attributes
    ----------
    voxel_size : float
        Voxel size of the downsampled working copies (source and target), metres.
    max_correspondence : tuple of float
        Correspondence distances of the coarse-to-fine ICP stages, metres.
    max_iterations : int
        Iterations per stage.
    stage_voxels : tuple of float or None
        Per stage, the voxel size of the scan's copy it aligns, at least ``voxel_size`` (None:
        ``voxel_size`` for every stage). A stage's time grows with the scan's points, and the coarse
        stages need only bring the pose within the next stage's reach.
    convergence : float
        A stage stops when its update turns less than this (radians) and moves less (metres).
    min_fitness : float
        Least share of source points with a correspondence at the finest stage (only when
        ``min_agreement`` is None).
    max_rmse : float
        Largest inlier RMSE at the finest stage, metres (only when ``min_agreement`` is None).
    max_correction_m, max_correction_deg : float
        Largest move away from the odometry pose that is accepted after a short leg; odometry drift
        never explains more, so a larger correction means ICP locked onto the wrong structure.
    correction_per_metre_m, correction_per_metre_deg : float
        The gates grow with the distance driven since the last scan (4 σ of the default odometry
        drift per metre), so that the correct pose after a long transit is not refused.
    target_radius : float
        Only the part of S(t) within this distance of the odometry pose is matched.
    crop_margin : float or None
        ... and only within this distance of the scan's bounding box at the odometry pose, metres.
        None: the box of ``target_radius`` alone.
    deterministic : bool
        Run ICP on one thread so that a seed always gives the same poses. open3d's parallel
        reductions vary in the last bits between runs, and ICP occasionally turns that into a
        different result; one thread costs about 1.7x the ICP time (see benchmarks/README.md).
    method : {"plane", "gicp", "open3d"}
        ``"plane"``: small_gicp's point-to-plane ICP with the target's normals estimated afresh
        from its own points at each registration. ``"gicp"``: generalised ICP (plane to plane;
        :mod:`nbs_env.sensing.gicp`, small_gicp's algorithm and k-d trees, with the covariances S(t)
        keeps instead of ones estimated on the target at each registration). ``"open3d"``:
        open3d's point-to-plane ICP with the working copy's normals (the method before the study).
    neighbours : int
        Nearest points for the normals and covariances: of each scan's copy (in the scan itself),
        and of the target for ``"plane"`` and ``"gicp"``.
    min_points : int
        Fewest downsampled points a scan, and the part of S(t) facing it, must have to be
        registered (an empty scan: the scanner in a wall, every return under the minimum range).
    min_inliers : int
        Fewest matches for an accepted pose: points on S(t)'s planes (with ``min_agreement``),
        else correspondences at the finest stage.
    min_agreement : float or None
        Least share of the scan's overlap with S(t) (its points within ``overlap_distance`` of S(t)
        at the final pose) that lies within ``plane_tolerance`` of S(t)'s local plane. This gate
        replaces ``min_fitness`` and ``max_rmse``, which measure distances to the nearest target
        point and so refuse correct poses where S(t) is sparse or the scan sees mostly new
        surface. None: the old gates (``min_fitness``, ``max_rmse``) instead.
    overlap_distance : float
        A source point within this distance of S(t) at the final pose is in the overlap, metres.
    plane_tolerance : float
        Largest distance of an agreeing point from S(t)'s local plane, metres.
    max_see_through : float or None
        Largest share of the points of S(t) in the scan's view that may lie clearly in front of
        everything the scan measured in their direction (the scan would have seen through them):
        the gate that refuses a pose ICP left in a wrong basin with its planes agreeing (a room
        shifted along its length). None: off.
    heading_check_deg : float
        When the heading that aligns the histograms of wall-normal headings (scan against S(t))
        differs by more than this from ICP's, ICP is run again from the walls' heading and the
        better result kept: after a long leg the odometry's heading can be too far off for ICP's
        coarsest stage. 0 turns the check off.
    min_constraint : float
        Directions of the pose whose point-to-plane information (an eigenvalue of JᵀJ over the
        finest-stage matches, in point-equivalents; rotations about the scanner counted with their
        lever arm in metres) is below this keep the odometry's value: along a corridor with no end
        in view ICP's move is noise. 0 turns it off.
    exclude_rejected : bool
        Leave scans whose registration was rejected out of later ICP targets (they lie in S(t) at
        their odometry pose and double the surfaces they share with registered scans).

    ``benchmarks/registration.py`` measures these defaults against open3d's ICP on the same scans
    (figures and commands in ``benchmarks/README.md``). The corpus of scenes/corpus.py was
    measured with them; of its storeys, only large_storey informed a choice (the heading check and
    the see-through gate were written for failures seen there and in tests/test_registration.py).
    """

    voxel_size: float = 0.1
    max_correspondence: tuple[float, ...] = (0.5, 0.2, 0.08)
    max_iterations: int = 40
    min_fitness: float = 0.3
    max_rmse: float = 0.04
    max_correction_m: float = 0.75
    max_correction_deg: float = 10.0
    correction_per_metre_m: float = 0.08
    correction_per_metre_deg: float = 2.0
    target_radius: float = 100.0
    deterministic: bool = True
    crop_margin: float | None = 2.0
    method: str = "gicp"
    neighbours: int = 20
    min_points: int = 200
    min_inliers: int = 1000
    min_agreement: float | None = 0.65
    overlap_distance: float = 0.3
    plane_tolerance: float = 0.03
    max_see_through: float | None = 0.02
    heading_check_deg: float = 2.0
    min_constraint: float = 0.0
    exclude_rejected: bool = True
    stage_voxels: tuple[float, ...] | None = (0.3, 0.2, 0.1)
    convergence: float = 1e-4

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(
            convergence=self.convergence,
            voxel_size=self.voxel_size,
            min_fitness=self.min_fitness,
            max_rmse=self.max_rmse,
            max_correction_m=self.max_correction_m,
            max_correction_deg=self.max_correction_deg,
            correction_per_metre_m=self.correction_per_metre_m,
            correction_per_metre_deg=self.correction_per_metre_deg,
            target_radius=self.target_radius,
            min_constraint=self.min_constraint,
            overlap_distance=self.overlap_distance,
            plane_tolerance=self.plane_tolerance,
            heading_check_deg=self.heading_check_deg,
        )
        for name in ("deterministic", "exclude_rejected"):
            _require(isinstance(getattr(self, name), bool), f"{name} must be a bool, got {getattr(self, name)!r}")
        _require(self.overlap_distance > 0, f"overlap_distance must be > 0, got {self.overlap_distance}")
        _require(self.plane_tolerance > 0, f"plane_tolerance must be > 0, got {self.plane_tolerance}")
        _require(self.heading_check_deg >= 0, f"heading_check_deg must be >= 0, got {self.heading_check_deg}")
        _at_most(self, "overlap_distance", 10.0, "metres")
        _at_most(self, "plane_tolerance", 10.0, "metres")
        _at_most(self, "heading_check_deg", 180.0, "degrees")
        _within(self, "max_rmse", 0.0, 10.0, "metres", open_low=True)
        _within(self, "max_correction_m", 0.0, 1000.0, "metres")
        _within(self, "max_correction_deg", 0.0, 180.0, "degrees")
        _within(self, "correction_per_metre_m", 0.0, 10.0, "metres per metre")
        _within(self, "correction_per_metre_deg", 0.0, 180.0, "degrees per metre")
        # The scanner's range is at most 10 km (ScannerConfig.max_range).
        _within(self, "target_radius", 0.0, 10_000.0, "metres", open_low=True)
        if self.max_see_through is not None:
            _finite(max_see_through=self.max_see_through)
            _require(
                0 <= self.max_see_through <= 1,
                f"max_see_through is a share in [0, 1] or None, got {self.max_see_through}",
            )
        if self.crop_margin is not None:
            _finite(crop_margin=self.crop_margin)
            _require(self.crop_margin >= 0, f"crop_margin must be >= 0 or None, got {self.crop_margin}")
            _at_most(self, "crop_margin", 10_000.0, "metres")
        _require(
            self.method in ("plane", "gicp", "open3d"),
            f"method must be 'plane', 'gicp' or 'open3d', got {self.method!r}",
        )
        # Neighbours per point for the normals and covariances: the k-d tree's query is sized by it
        # (a thousand is a point's whole room at the working copies' 10 cm).
        _integer(self, "neighbours", 5, 1000)
        # A scan has at most MAX_RAYS returns: a larger least count refuses every scan.
        _integer(self, "min_points", 0, MAX_RAYS)
        _integer(self, "min_inliers", 0, MAX_RAYS)
        if self.min_agreement is not None:
            _finite(min_agreement=self.min_agreement)
            _require(
                0 <= self.min_agreement <= 1, f"min_agreement is a share in [0, 1] or None, got {self.min_agreement}"
            )
        _require(self.min_constraint >= 0, f"min_constraint must be >= 0, got {self.min_constraint}")
        _at_most(self, "min_constraint", float(MAX_RAYS), "point-equivalents")
        _require(self.voxel_size > 0, f"voxel_size must be > 0, got {self.voxel_size}")
        # The working copies' voxels: below a centimetre they hold every point of a scan (and the
        # downsampling's voxel keys overflow); above 2 m a room is a handful of points.
        _within(self, "voxel_size", 0.01, 2.0, "metres")
        correspondence = tuple(self.max_correspondence)
        _require(
            0 < len(correspondence) <= 10
            and all(
                isinstance(d, (int, float)) and not isinstance(d, bool) and is_finite(d) and 0 < d <= 100
                for d in correspondence
            ),
            f"max_correspondence must be 1 to 10 distances within (0, 100] metres, got {self.max_correspondence}",
        )
        _integer(self, "max_iterations", 1, MAX_ICP_ITERATIONS)
        _require(self.convergence > 0, f"convergence must be > 0, got {self.convergence}")
        _at_most(self, "convergence", 1.0, "(radians and metres)")
        if self.stage_voxels is not None:
            _require(
                len(self.stage_voxels) == len(self.max_correspondence)
                and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and is_finite(v) for v in self.stage_voxels
                )
                and all(self.voxel_size <= v <= 2.0 for v in self.stage_voxels),
                f"stage_voxels must give one voxel size within [voxel_size ({self.voxel_size}), 2] metres per stage "
                f"of max_correspondence ({len(self.max_correspondence)}), got {self.stage_voxels}",
            )
        _require(0 <= self.min_fitness <= 1, f"min_fitness is a share in [0, 1], got {self.min_fitness}")


@dataclass(frozen=True)
class NavigationConfig(Config):
    """The robot's footprint and the NVP candidate list, METHOD §6.

    Attributes
    ----------
    robot_radius : float
        Radius of the robot's footprint, metres.
    safety_distance : float
        Extra distance to any occupied voxel, metres (the paper's 20 cm).
    robot_height : float
        Top of the column above the floor that must be Empty, metres.
    floor_clearance : float
        Voxels whose centre is less than this above the floor are ignored, metres: the floor itself
        is Structure, and range noise spreads it over a voxel or two.
    lattice : float
        Spacing of the candidate lattice, metres. The lattice is anchored at world multiples of it.
    max_candidates : int
        K, the length of the candidate list (the action space).
    min_distance : float
        Candidates closer than this to the robot (Euclidean, metres) are dropped: scanning again
        from where the robot stands gains nothing.
    snap : bool
        Fill the lattice's holes: where neither a lattice point nor any of its eight neighbours is a
        candidate (too near an obstacle) but its lattice cell (the ``lattice``-wide square around
        it) holds reachable floor with the clearance, the cell of that floor nearest the point, kept
        the clearance from the room's outline too, stands in for it. An aisle narrower than the
        lattice spacing but wide enough for the robot keeps candidates. Off, only lattice points are
        candidates (the paper's sampling).
    """

    robot_radius: float = 0.25
    safety_distance: float = 0.20
    robot_height: float = 1.8
    floor_clearance: float = 0.10
    lattice: float = 0.5
    max_candidates: int = 64
    min_distance: float = 0.5
    snap: bool = True

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(
            robot_radius=self.robot_radius,
            safety_distance=self.safety_distance,
            robot_height=self.robot_height,
            floor_clearance=self.floor_clearance,
            lattice=self.lattice,
            min_distance=self.min_distance,
        )
        _require(self.robot_radius > 0, f"robot_radius must be > 0, got {self.robot_radius}")
        _require(self.safety_distance >= 0, f"safety_distance must be >= 0, got {self.safety_distance}")
        _require(self.floor_clearance >= 0, f"floor_clearance must be >= 0, got {self.floor_clearance}")
        _require(
            self.robot_height > self.floor_clearance,
            f"robot_height ({self.robot_height} m) must exceed floor_clearance ({self.floor_clearance} m)",
        )
        # Positions on a lattice finer than 5 cm are finer than the maps they are checked on, and
        # their count (storey area / lattice²) grows past memory.
        _require(0.05 <= self.lattice <= 5, f"lattice must be within [0.05, 5] metres, got {self.lattice}")
        _require(
            isinstance(self.max_candidates, int) and not isinstance(self.max_candidates, bool),
            f"max_candidates must be an integer, got {self.max_candidates!r}",
        )
        _require(
            1 <= self.max_candidates <= 100_000,
            f"max_candidates must be within [1, 100,000], got {self.max_candidates}",
        )
        _require(self.min_distance >= 0, f"min_distance must be >= 0, got {self.min_distance}")
        _require(isinstance(self.snap, bool), f"snap must be a bool, got {self.snap!r}")
        # Footprints are discs of voxels: a radius of kilometres is a kernel larger than memory.
        _at_most(self, "robot_radius", 5.0, "metres")
        _at_most(self, "safety_distance", 5.0, "metres")
        _at_most(self, "floor_clearance", 5.0, "metres")
        _at_most(self, "robot_height", 10.0, "metres")
        _at_most(self, "min_distance", 1000.0, "metres")

    @property
    def required_clearance(self) -> float:
        """Least distance from a traversable cell to an occupied voxel: radius plus safety distance."""
        return self.robot_radius + self.safety_distance


@dataclass(frozen=True)
class GainConfig(Config):
    """Options of the gain.

    Attributes
    ----------
    model : str
        The gain model, by its name in :data:`nbs_env.planning.planner.GAIN_MODELS`: ``"visibility"``
        (this module's :class:`VisibilityModel`, the paper's gain) or one registered with
        :func:`nbs_env.planning.planner.register_gain_model`. The options below are the visibility
        model's; another model may read them or not.
    occluded_clutter_blocks : bool
        Whether OCCLUDED_CLUTTER voxels block lines of sight as occupied ones do. Unsensed space
        may hold furniture; blocking is the pessimistic reading (see benchmarks/README.md for the
        measurement that chose the default).
    tolerance_voxels : float
        A line of sight that reaches within this many voxels of the target counts: the target's own
        neighbours on the same wall must not hide it at grazing angles.
    group : int
        Occluded-structure voxels are cast to in groups of ``group``³ voxels: one line of sight to
        the mean centre of a group's members stands for all of them. Surfaces are thin, so groups of
        2 cut the rays about fourfold at 5 cm (measured in benchmarks/gain.py); 1 casts to every voxel.
    """

    model: str = "visibility"
    occluded_clutter_blocks: bool = False
    tolerance_voxels: float = 1.0
    group: int = 2

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _require(
            isinstance(self.model, str) and self.model != "", f"model must be a gain model's name, got {self.model!r}"
        )
        _require(
            isinstance(self.occluded_clutter_blocks, bool),
            f"occluded_clutter_blocks must be true or false, got {self.occluded_clutter_blocks!r}",
        )
        _finite_fields(self, "tolerance_voxels")
        _require(self.tolerance_voxels >= 0, f"tolerance_voxels must be >= 0, got {self.tolerance_voxels}")
        _at_most(self, "tolerance_voxels", 100.0, "voxels")
        _integer(self, "group", 1)
        _require(self.group <= 64, f"group must be at most 64 voxels, got {self.group}")


@dataclass(frozen=True)
class RoIConfig(Config):
    """Options of the RoI computation.

    Attributes
    ----------
    pixel : float
        Grid size of the top projection, metres.
    histogram_bin : float
        Bin width of the z histogram, metres.
    band_above_floor : float
        Lower edge of the band whose points bound the seen free space, metres above the floor. It
        must clear door heads (2.0-2.1 m in most buildings) and tall furniture, yet stay inside the
        scanner's +60° field of view from the robot's 0.45 m clearance to a wall: at 2.25 m the wall
        above a door is seen from 0.45 m away (59°).
    band_below_ceiling : float
        Upper edge of that band, metres below the ceiling.
    azimuth_bins : int
        Angular bins per scan for the free-space outline.
    max_range : float
        Free space farther than this from a scan position is ignored, metres.
    corner_distance : float
        Least distance between two polygon vertices, metres.
    collinear_deg : float
        Consecutive edges closer than this in direction merge into one.
    """

    pixel: float = 0.05
    histogram_bin: float = 0.02
    band_above_floor: float = 2.25
    band_below_ceiling: float = 0.05
    azimuth_bins: int = 1440
    max_range: float = 30.0
    corner_distance: float = 0.30
    collinear_deg: float = 8.0

    def __post_init__(self) -> None:
        _plain_numbers(self)
        lengths = ("pixel", "histogram_bin", "band_above_floor", "max_range")
        _finite_fields(self, *lengths, "band_below_ceiling", "corner_distance", "collinear_deg")
        for name in lengths:
            _require(getattr(self, name) > 0, f"{name} must be > 0 metres, got {getattr(self, name)}")
        # Grids of the room's extent: a pixel or bin below a millimetre asks for more cells than memory.
        _require(0.005 <= self.pixel <= 1, f"pixel must be within [0.005, 1] metres, got {self.pixel}")
        _require(
            0.001 <= self.histogram_bin <= 1,
            f"histogram_bin must be within [0.001, 1] metres, got {self.histogram_bin}",
        )
        _require(self.max_range <= 1000, f"max_range must be at most 1,000 metres, got {self.max_range}")
        _require(self.band_below_ceiling >= 0, f"band_below_ceiling must be >= 0, got {self.band_below_ceiling}")
        _require(self.corner_distance >= 0, f"corner_distance must be >= 0, got {self.corner_distance}")
        _require(0 <= self.collinear_deg < 90, f"collinear_deg must be in [0, 90), got {self.collinear_deg}")
        _at_most(self, "band_above_floor", 10.0, "metres")
        _at_most(self, "band_below_ceiling", 10.0, "metres")
        _at_most(self, "corner_distance", 100.0, "metres")
        _integer(self, "azimuth_bins", 4)
        _require(self.azimuth_bins <= 36_000, f"azimuth_bins must be at most 36,000, got {self.azimuth_bins}")


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
        Clear height, metres; the lintel must have been seen within this range. Up to 3.0 m, not
        METHOD §8's 2.3 m: public buildings' doors are 2.4-3.0 m high, and a storey of 2.6 m doors
        was scanned in its first room only (43% sensed).
    flush_height : float
        Openings up to this high may reach the ceiling (a door flush with a low ceiling, METHOD's
        doors); a taller one is a door only under ``ceiling_clearance`` of wall, metres.
    ceiling_clearance : float
        How far below the RoI's ceiling the top of an opening taller than ``flush_height`` must lie,
        metres: its lintel is then wall. A face empty from the floor to the ceiling's edge (where the
        RoI's outline crosses open floor, or clutter hides a wall from floor to ceiling) is no door;
        its run ends up to 0.21 m below the ceiling, whose edge the beam's mixed pixels blur.
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
    level_elevation_deg : float
        The rising rays through an opening below this elevation are its level rays: beyond a door
        onto a porch, a balcony or a carport under a roof they pass under the roof's edge and return
        nothing, where beyond an interior door they meet the next room's walls. Fewer than
        ``covered_share`` of them returning (of at least ``min_rising_rays``) also makes the door
        exterior (module docstring of :mod:`nbs_env.perception.doors`); 0 turns the test off.
    cross_exterior : bool
        Cross exterior doors as if they led into rooms (off by default: the robot stays inside).
    fill_gap : float
        Gaps up to this wide between points of a row of the face image are filled before the
        search (a lintel seen in stripes, module docstring), metres; below ``min_width``.
    max_extension : float
        How far beyond either end of a face its line may be followed along measured points
        (module docstring), metres; 0 searches the faces as given.
    """

    min_width: float = 0.6
    max_width: float = 4.0
    min_height: float = 1.8
    max_height: float = 3.0
    flush_height: float = 2.3
    ceiling_clearance: float = 0.25
    floor_gap: float = 0.15
    behind: float = 0.3
    min_behind_points: int = 50
    pixel: float = 0.05
    covered_share: float = 0.5
    min_rising_rays: int = 20
    level_elevation_deg: float = 10.0
    cross_exterior: bool = False
    fill_gap: float = 0.2
    max_extension: float = 8.0

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite_fields(
            self,
            "min_width",
            "max_width",
            "min_height",
            "max_height",
            "flush_height",
            "ceiling_clearance",
            "floor_gap",
            "behind",
            "pixel",
            "covered_share",
            "level_elevation_deg",
            "fill_gap",
            "max_extension",
        )
        _require(
            0 < self.min_width <= self.max_width,
            f"need 0 < min_width <= max_width, got {self.min_width}, {self.max_width}",
        )
        _require(
            0 < self.min_height <= self.max_height,
            f"need 0 < min_height <= max_height, got {self.min_height}, {self.max_height}",
        )
        _require(self.flush_height >= 0, f"flush_height must be >= 0 metres, got {self.flush_height}")
        _require(self.ceiling_clearance >= 0, f"ceiling_clearance must be >= 0 metres, got {self.ceiling_clearance}")
        _require(self.floor_gap >= 0, f"floor_gap must be >= 0 metres, got {self.floor_gap}")
        _require(self.behind >= 0, f"behind must be >= 0 metres, got {self.behind}")
        _require(0.005 <= self.pixel <= 1, f"pixel must be within [0.005, 1] metres, got {self.pixel}")
        _integer(self, "min_behind_points", 0)
        _integer(self, "min_rising_rays", 1)
        _require(0 <= self.covered_share <= 1, f"covered_share must be in [0, 1], got {self.covered_share}")
        _require(
            0 <= self.level_elevation_deg < 90,
            f"level_elevation_deg must be in [0, 90), got {self.level_elevation_deg}",
        )
        _require(isinstance(self.cross_exterior, bool), f"cross_exterior must be a bool, got {self.cross_exterior!r}")
        _require(
            0 <= self.fill_gap < self.min_width,
            f"need 0 <= fill_gap < min_width, got {self.fill_gap}, {self.min_width}",
        )
        _require(self.max_extension >= 0, f"max_extension must be >= 0 metres, got {self.max_extension}")
        # Openings and distances of a building: a storey is at most 500 m across (scenes.limits).
        _at_most(self, "max_width", 100.0, "metres")
        _at_most(self, "max_height", 100.0, "metres")
        _at_most(self, "flush_height", 100.0, "metres")
        _at_most(self, "ceiling_clearance", 100.0, "metres")
        _at_most(self, "floor_gap", 10.0, "metres")
        _at_most(self, "behind", 100.0, "metres")
        _at_most(self, "max_extension", 1000.0, "metres")
        # A scan has at most MAX_RAYS returns: larger least counts refuse every door.
        _at_most(self, "min_behind_points", MAX_RAYS)
        _at_most(self, "min_rising_rays", MAX_RAYS)


@dataclass(frozen=True)
class PlanningConfig(Config):
    """What the planner is given: the scanner, the robot's footprint, the gain (JSON-safe, frozen).

    Attributes
    ----------
    scanner : ScannerConfig
        Its height over the floor places the sensors; its lowest elevation and minimum range make
        the blind zone; its field of view and range limit the gain.
    navigation : NavigationConfig
        The robot's footprint and the candidate list.
    gain : GainConfig
        Which gain model, and its options.
    predict_gains : bool
        Predict the gain of every NVP. Off for policies with their own utility (their processing
        time then does not carry the greedy's); the plan's gains are all zero.
    """

    scanner: ScannerConfig = field(default_factory=ScannerConfig)
    navigation: NavigationConfig = field(default_factory=NavigationConfig)
    gain: GainConfig = field(default_factory=GainConfig)
    predict_gains: bool = True

    def __post_init__(self) -> None:
        _require(
            isinstance(self.predict_gains, bool), f"predict_gains must be true or false, got {self.predict_gains!r}"
        )


@dataclass(frozen=True)
class RobotConfig(Config):
    """The robot: its hardware and the stages of one scan cycle (JSON-safe, frozen).

    The rules that end a room and look for its doors are not the robot's but the storey's
    (:class:`~nbs_env.config.rooms.RoomRules`).

    Attributes
    ----------
    scanner, odometry, registration : ScannerConfig, OdometryConfig, RegistrationConfig
        The sensor, its motion drift and the ICP.
    navigation : NavigationConfig
        The robot's footprint and the candidate list.
    gain : GainConfig
        The greedy's gain model (``gain.model`` selects it, among the models registered with
        :func:`nbs_env.planning.planner.register_gain_model`) and its options.
    roi : RoIConfig
        The dynamic RoI. Its ``azimuth_bins`` is capped at the scanner's columns (more bins than
        columns leave most bins empty, and the RoI would refuse a door-frame scan).
    doors : DoorConfig
        The limits of a door opening.
    voxel_size : float
        Edge of the voxels of V(t), metres.
    perfect_localisation : bool
        Skip odometry drift and registration (the belief is the true pose): for fast RL.
    predict_gains : bool
        Compute the greedy's predicted gain of every NVP. Policies with their own utility turn it
        off, so that their processing time does not carry the greedy's; room completion by gain
        (METHOD §7) then cannot run.
    """

    scanner: ScannerConfig = field(default_factory=ScannerConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    navigation: NavigationConfig = field(default_factory=NavigationConfig)
    gain: GainConfig = field(default_factory=GainConfig)
    roi: RoIConfig = field(default_factory=RoIConfig)
    doors: DoorConfig = field(default_factory=DoorConfig)
    voxel_size: float = 0.05
    perfect_localisation: bool = False
    predict_gains: bool = True

    def __post_init__(self) -> None:
        _plain_numbers(self)
        _finite(voxel_size=self.voxel_size)
        _require(0.01 <= self.voxel_size <= 1.0, f"voxel_size must be within [0.01, 1] metres, got {self.voxel_size}")
        for name in ("perfect_localisation", "predict_gains"):
            _require(
                isinstance(getattr(self, name), bool), f"{name} must be true or false, got {getattr(self, name)!r}"
            )

    @property
    def planning(self) -> PlanningConfig:
        """What the planner reads of this configuration."""
        return PlanningConfig(self.scanner, self.navigation, self.gain, self.predict_gains)
