"""Configuration as frozen dataclasses with JSON-safe fields, checked on construction.

Defaults follow ``METHOD.md``; where a default was changed after a measurement, the docstring says
why.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from nbs_env.errors import ConfigError

__all__ = ["MAX_RAYS", "Config", "OdometryConfig", "RegistrationConfig", "ScannerConfig"]

#: Patterns above this many rays per scan are refused: they would take minutes and gigabytes.
MAX_RAYS = 50_000_000


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def _finite(**values: float) -> None:
    for name, value in values.items():
        _require(
            isinstance(value, (int, float)) and math.isfinite(value), f"{name} must be a finite number, got {value!r}"
        )


def _finite_fields(config: Any, *names: str) -> None:
    """Each named field of ``config`` is a finite number."""
    _finite(**{name: getattr(config, name) for name in names})


def _integer(config: Any, name: str, least: int) -> None:
    """Field ``name`` of ``config`` is an integer (not a bool) of at least ``least``."""
    value = getattr(config, name)
    _require(
        isinstance(value, int) and not isinstance(value, bool) and value >= least,
        f"{name} must be an integer >= {least}, got {value!r}",
    )


class Config:
    """Base of the frozen configuration dataclasses: ``to_dict()`` gives their JSON-safe fields."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]


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
        Standard deviation of the Gaussian range noise in metres.
    height : float
        Optical centre above the floor the robot stands on, in metres.
    points_per_second : float
        Acquisition rate, for the simulated acquisition time when ``station_time`` is None.
    station_time : float or None
        Seconds a station takes on the real instrument at its chosen resolution and quality setting
        (a scanner preset's datasheet figure, :mod:`nbs_env.scanners`). None: the acquisition time
        is the returned points over ``points_per_second``, the time the simulated pattern alone
        would take.
    """

    angular_step: float = 0.5
    elevation_min: float = -40.0
    elevation_max: float = 60.0
    min_range: float = 1.5
    max_range: float = 350.0
    range_noise: float = 0.005
    height: float = 1.5
    points_per_second: float = 122_000.0
    station_time: float | None = None

    def __post_init__(self) -> None:
        _finite(
            angular_step=self.angular_step,
            elevation_min=self.elevation_min,
            elevation_max=self.elevation_max,
            min_range=self.min_range,
            max_range=self.max_range,
            range_noise=self.range_noise,
            height=self.height,
            points_per_second=self.points_per_second,
        )
        _require(self.angular_step > 0, f"angular_step must be > 0 degrees, got {self.angular_step}")
        _require(
            -90.0 <= self.elevation_min < self.elevation_max <= 90.0,
            f"need -90 <= elevation_min < elevation_max <= 90, got {self.elevation_min}, {self.elevation_max}",
        )
        _require(self.min_range >= 0, f"min_range must be >= 0, got {self.min_range}")
        _require(
            self.min_range < self.max_range,
            f"min_range ({self.min_range} m) must be below max_range ({self.max_range} m)",
        )
        _require(self.range_noise >= 0, f"range_noise must be >= 0, got {self.range_noise}")
        _require(self.points_per_second > 0, f"points_per_second must be > 0, got {self.points_per_second}")
        if self.station_time is not None:
            _finite(station_time=self.station_time)
            _require(self.station_time > 0, f"station_time must be > 0 seconds or None, got {self.station_time}")
        rays = self.n_rows * self.n_cols
        _require(
            rays <= MAX_RAYS,
            f"angular_step {self.angular_step}° makes {rays:,} rays per scan; the limit is {MAX_RAYS:,}",
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
        _finite(
            sigma_xy_per_m=self.sigma_xy_per_m,
            sigma_yaw_deg_per_m=self.sigma_yaw_deg_per_m,
            sigma_tilt_deg=self.sigma_tilt_deg,
        )
        for name, value in asdict(self).items():
            _require(value >= 0, f"{name} must be >= 0, got {value}")


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
        _finite(
            convergence=self.convergence,
            voxel_size=self.voxel_size,
            min_fitness=self.min_fitness,
            max_rmse=self.max_rmse,
            max_correction_m=self.max_correction_m,
            max_correction_deg=self.max_correction_deg,
            target_radius=self.target_radius,
            min_constraint=self.min_constraint,
            overlap_distance=self.overlap_distance,
            plane_tolerance=self.plane_tolerance,
            heading_check_deg=self.heading_check_deg,
        )
        _require(self.overlap_distance > 0, f"overlap_distance must be > 0, got {self.overlap_distance}")
        _require(self.plane_tolerance > 0, f"plane_tolerance must be > 0, got {self.plane_tolerance}")
        _require(self.heading_check_deg >= 0, f"heading_check_deg must be >= 0, got {self.heading_check_deg}")
        if self.max_see_through is not None:
            _finite(max_see_through=self.max_see_through)
            _require(
                0 <= self.max_see_through <= 1,
                f"max_see_through is a share in [0, 1] or None, got {self.max_see_through}",
            )
        if self.crop_margin is not None:
            _finite(crop_margin=self.crop_margin)
            _require(self.crop_margin >= 0, f"crop_margin must be >= 0 or None, got {self.crop_margin}")
        _require(
            self.method in ("plane", "gicp", "open3d"),
            f"method must be 'plane', 'gicp' or 'open3d', got {self.method!r}",
        )
        _integer(self, "neighbours", 5)
        _integer(self, "min_points", 0)
        _integer(self, "min_inliers", 0)
        if self.min_agreement is not None:
            _finite(min_agreement=self.min_agreement)
            _require(
                0 <= self.min_agreement <= 1, f"min_agreement is a share in [0, 1] or None, got {self.min_agreement}"
            )
        _require(self.min_constraint >= 0, f"min_constraint must be >= 0, got {self.min_constraint}")
        _require(self.voxel_size > 0, f"voxel_size must be > 0, got {self.voxel_size}")
        _require(
            len(self.max_correspondence) > 0 and all(d > 0 for d in self.max_correspondence),
            f"max_correspondence must be positive distances, got {self.max_correspondence}",
        )
        _require(self.max_iterations >= 1, f"max_iterations must be >= 1, got {self.max_iterations}")
        _require(self.convergence > 0, f"convergence must be > 0, got {self.convergence}")
        if self.stage_voxels is not None:
            _require(
                len(self.stage_voxels) == len(self.max_correspondence)
                and all(isinstance(v, (int, float)) and math.isfinite(v) for v in self.stage_voxels)
                and all(v >= self.voxel_size for v in self.stage_voxels),
                f"stage_voxels must give one voxel size of at least voxel_size ({self.voxel_size}) per stage "
                f"of max_correspondence ({len(self.max_correspondence)}), got {self.stage_voxels}",
            )
        _require(0 <= self.min_fitness <= 1, f"min_fitness is a share in [0, 1], got {self.min_fitness}")
