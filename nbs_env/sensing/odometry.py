"""Odometry: the pose the robot believes in drifts from the true one with the distance driven (METHOD §2).

The true motion is the simulator's; the odometry returns only the robot's belief. All randomness comes
from the injected generator.
"""

from __future__ import annotations

import numpy as np

from nbs_env.config import OdometryConfig
from nbs_env.sensing.pose import check_pose, planar, pose_from_xyz_rpy, yaw_of

__all__ = ["Odometry", "path_length"]


def path_length(path: np.ndarray) -> float:
    """Length in metres of a polyline ``path`` of shape (n, 2) or (n, 3)."""
    path = np.asarray(path, dtype=float)
    if len(path) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1).sum())


class Odometry:
    """Dead reckoning with error growing with the distance driven.

    Parameters
    ----------
    config : OdometryConfig
    rng : numpy.random.Generator
        The only source of randomness.
    """

    def __init__(self, config: OdometryConfig | None, rng: np.random.Generator) -> None:
        self.config = config or OdometryConfig()
        self.rng = rng

    def true_sensor_pose(self, xy: np.ndarray, yaw: float, floor_z: float, height: float) -> np.ndarray:
        """The simulator's true scanner pose at a stop: small random roll and pitch (uneven floor)."""
        tilt = np.radians(self.config.sigma_tilt_deg)
        roll, pitch = self.rng.normal(0.0, tilt, 2) if tilt > 0 else (0.0, 0.0)
        return pose_from_xyz_rpy(float(xy[0]), float(xy[1]), floor_z + height, float(roll), float(pitch), yaw)

    def drive(self, believed: np.ndarray, true_from: np.ndarray, true_to: np.ndarray, distance: float) -> np.ndarray:
        """The believed pose after driving from ``true_from`` to ``true_to`` along ``distance`` metres.

        The true planar motion (x, y, heading) in the robot's frame is corrupted with Gaussian noise
        whose σ grows linearly with ``distance`` and applied to the ``believed`` pose. The belief has
        no roll or pitch: odometry cannot sense them.

        Returns
        -------
        (4, 4) float
            Believed sensor pose at the height of ``true_to``.
        """
        believed, true_from, true_to = (check_pose(p) for p in (believed, true_from, true_to))
        if not np.isfinite(distance) or distance < 0:
            raise ValueError(f"distance must be a finite number >= 0, got {distance}")
        a = planar(*true_from[:2, 3], yaw_of(true_from))
        b = planar(*true_to[:2, 3], yaw_of(true_to))
        rel = np.linalg.inv(a) @ b
        cfg = self.config
        dx, dy = self.rng.normal(0.0, cfg.sigma_xy_per_m * distance, 2) if distance > 0 else (0.0, 0.0)
        dyaw = self.rng.normal(0.0, np.radians(cfg.sigma_yaw_deg_per_m) * distance) if distance > 0 else 0.0
        noisy = planar(rel[0, 3] + dx, rel[1, 3] + dy, yaw_of(rel) + dyaw)
        out = planar(*believed[:2, 3], yaw_of(believed)) @ noisy
        out[2, 3] = true_to[2, 3]
        return out
