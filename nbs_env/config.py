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
        Acquisition rate, for the simulated acquisition time.
    """

    angular_step: float = 0.5
    elevation_min: float = -40.0
    elevation_max: float = 60.0
    min_range: float = 1.5
    max_range: float = 350.0
    range_noise: float = 0.005
    height: float = 1.5
    points_per_second: float = 122_000.0

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
    """Point-to-plane ICP of a new scan against the accumulated cloud S(t), METHOD §2.

    Attributes
    ----------
    voxel_size : float
        Voxel size of the downsampled working copies (source and target), metres.
    max_correspondence : tuple of float
        Correspondence distances of the coarse-to-fine ICP stages, metres.
    max_iterations : int
        Iterations per stage.
    normal_radius : float
        Radius for the target's normal estimation, metres.
    min_fitness : float
        Least share of source points with a correspondence at the finest stage.
    max_rmse : float
        Largest inlier RMSE at the finest stage, metres.
    max_correction_m, max_correction_deg : float
        Largest move away from the odometry pose that is accepted after a short leg; odometry drift
        never explains more, so a larger correction means ICP locked onto the wrong structure.
    correction_per_metre_m, correction_per_metre_deg : float
        The gates grow with the distance driven since the last scan (4 σ of the default odometry
        drift per metre), so that the correct pose after a long transit is not refused.
    target_radius : float
        Only the part of S(t) within this distance of the odometry pose is matched.
    deterministic : bool
        Run ICP on one thread so that a seed always gives the same poses. open3d's parallel
        reductions vary in the last bits between runs, and ICP occasionally turns that into a
        different result; one thread costs about 1.7x the ICP time (see benchmarks/README.md).
    min_points : int
        Fewest downsampled points a scan, and the part of S(t) facing it, must have to be
        registered (an empty scan: the scanner in a wall, every return under the minimum range).
    min_inliers : int
        Fewest matches at the finest stage for an accepted pose.
    min_overlap_fitness : float or None
        A pose whose fitness is below ``min_fitness`` is still accepted when this share of the
        scan's overlap with S(t) (its points within the coarsest correspondence distance of S(t))
        matches at the finest stage: a scan into a new room matches little of itself but most of
        what S(t) holds. None: the rule is off (``min_fitness`` alone decides).
    robust_kernel : {"none", "tukey", "huber", "cauchy"}
        M-estimator of the point-to-plane residuals ("none": least squares).
    kernel_width : float
        The kernel's scale as a share of each stage's correspondence distance.
    min_constraint : float
        Directions of the pose whose point-to-plane information (an eigenvalue of JᵀJ over the
        finest-stage matches, in point-equivalents; rotations about the scanner counted with their
        lever arm in metres) is below this keep the odometry's value: along a corridor with no end
        in view ICP's move is noise. 0 turns it off.
    exclude_rejected : bool
        Leave scans whose registration was rejected out of later ICP targets (they lie in S(t) at
        their odometry pose and double the surfaces they share with registered scans).

    The defaults of the last seven fields come from docs/registration_study.md (measured on tours
    and episodes of five_rooms, the FZK-Haus storeys and a synthetic corridor; the corpus of
    scenes/corpus.py was measured with them, not used to choose them).
    """

    voxel_size: float = 0.05
    max_correspondence: tuple[float, ...] = (0.5, 0.2, 0.08)
    max_iterations: int = 40
    normal_radius: float = 0.15
    min_fitness: float = 0.3
    max_rmse: float = 0.04
    max_correction_m: float = 0.75
    max_correction_deg: float = 10.0
    correction_per_metre_m: float = 0.08
    correction_per_metre_deg: float = 2.0
    target_radius: float = 30.0
    deterministic: bool = True
    min_points: int = 200
    min_inliers: int = 1000
    min_overlap_fitness: float | None = 0.6
    robust_kernel: str = "none"
    kernel_width: float = 0.5
    min_constraint: float = 0.0
    exclude_rejected: bool = True

    def __post_init__(self) -> None:
        _finite(
            voxel_size=self.voxel_size,
            normal_radius=self.normal_radius,
            min_fitness=self.min_fitness,
            max_rmse=self.max_rmse,
            max_correction_m=self.max_correction_m,
            max_correction_deg=self.max_correction_deg,
            target_radius=self.target_radius,
            kernel_width=self.kernel_width,
            min_constraint=self.min_constraint,
        )
        _integer(self, "min_points", 0)
        _integer(self, "min_inliers", 0)
        if self.min_overlap_fitness is not None:
            _finite(min_overlap_fitness=self.min_overlap_fitness)
            _require(
                0 <= self.min_overlap_fitness <= 1,
                f"min_overlap_fitness is a share in [0, 1] or None, got {self.min_overlap_fitness}",
            )
        _require(
            self.robust_kernel in ("none", "tukey", "huber", "cauchy"),
            f"robust_kernel must be 'none', 'tukey', 'huber' or 'cauchy', got {self.robust_kernel!r}",
        )
        _require(self.kernel_width > 0, f"kernel_width must be > 0, got {self.kernel_width}")
        _require(self.min_constraint >= 0, f"min_constraint must be >= 0, got {self.min_constraint}")
        _require(self.voxel_size > 0, f"voxel_size must be > 0, got {self.voxel_size}")
        _require(
            len(self.max_correspondence) > 0 and all(d > 0 for d in self.max_correspondence),
            f"max_correspondence must be positive distances, got {self.max_correspondence}",
        )
        _require(self.max_iterations >= 1, f"max_iterations must be >= 1, got {self.max_iterations}")
        _require(0 <= self.min_fitness <= 1, f"min_fitness is a share in [0, 1], got {self.min_fitness}")
