"""Rigid poses as 4x4 homogeneous matrices (sensor to world), and their errors."""

from __future__ import annotations

import numpy as np

from nbs_env.errors import InvalidPoseError

__all__ = ["check_pose", "planar", "pose_error", "pose_from_xyz_rpy", "yaw_of"]


def pose_from_xyz_rpy(
    x: float, y: float, z: float, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0
) -> np.ndarray:
    """(4, 4) float: the pose with translation (x, y, z) and rotation Rz(yaw) Ry(pitch) Rx(roll), radians."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    T[:3, 3] = (x, y, z)
    return T


def planar(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    """(4, 4) float: a pose with only a heading (radians) and a height."""
    return pose_from_xyz_rpy(x, y, z, 0.0, 0.0, yaw)


def yaw_of(pose: np.ndarray) -> float:
    """Heading of a pose in radians."""
    return float(np.arctan2(pose[1, 0], pose[0, 0]))


def check_pose(pose: np.ndarray, what: str = "pose") -> np.ndarray:
    """Return ``pose`` as a (4, 4) float array, or raise :class:`InvalidPoseError` saying why.

    A pose must be finite, have a rotation block with R Rᵀ = I and det R = 1, and a last row (0, 0, 0, 1).
    """
    T = np.asarray(pose, dtype=float)
    if T.shape != (4, 4):
        raise InvalidPoseError(f"{what} must be a (4, 4) matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise InvalidPoseError(f"{what} holds NaN or infinite values: {T.tolist()}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or abs(np.linalg.det(R) - 1.0) > 1e-6:
        raise InvalidPoseError(f"{what} has a rotation block that is not a rotation: {R.tolist()}")
    if not np.allclose(T[3], [0, 0, 0, 1]):
        raise InvalidPoseError(f"{what} must end in the row (0, 0, 0, 1), got {T[3].tolist()}")
    return T


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation error (m) and rotation error (degrees, the angle of R_estᵀ R_true) between two poses."""
    dt = float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))
    R = estimate[:3, :3].T @ truth[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    return dt, float(angle)
