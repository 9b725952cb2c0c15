"""Pictures of the robot's belief, for reports: the top projection with the RoI and its SE faces."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from nbs_env.perception.roi import RoI

__all__ = ["plot_roi", "save_roi_png"]

SE_COLOUR = "#1f77b4"
NON_SE_COLOUR = "#d62728"


def plot_roi(
    roi: RoI,
    se: Sequence[bool] | np.ndarray,
    ax=None,
    *,
    points: np.ndarray | None = None,
    origins: Sequence[np.ndarray] = (),
    title: str | None = None,
):
    """Draw the RoI as the paper's Fig. 3: the binary top projection, the polygon, faces SE or not.

    Parameters
    ----------
    roi : RoI
        The region of interest.
    se : (n_faces,) bool
        Classification of ``roi.wall_faces``: True is SE (blue), False non-SE (red, dashed).
    points : (n, 3) float, optional
        Registered points to overlay (magenta), subsampled to 20 000.
    origins : sequence of (3,) float
        Scan positions to mark.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    se = np.asarray(se, dtype=bool)
    if se.shape != (len(roi.polygon),):
        raise ValueError(f"se must have one entry per wall face ({len(roi.polygon)}), got shape {se.shape}")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 8))
    h, w = roi.image.shape
    extent = (roi.origin[0], roi.origin[0] + w * roi.pixel, roi.origin[1], roi.origin[1] + h * roi.pixel)
    ax.imshow(roi.image, origin="lower", extent=extent, cmap="Greys", alpha=0.25, interpolation="nearest")
    if points is not None and len(points):
        step = max(1, len(points) // 20_000)
        ax.scatter(points[::step, 0], points[::step, 1], s=0.2, c="#c837ab", alpha=0.5, linewidths=0)
    p = roi.polygon
    for k, is_se in enumerate(se):
        a, b = p[k], p[(k + 1) % len(p)]
        ax.plot(
            [a[0], b[0]],
            [a[1], b[1]],
            color=SE_COLOUR if is_se else NON_SE_COLOUR,
            lw=3,
            ls="-" if is_se else "--",
        )
    for o in origins:
        ax.plot(o[0], o[1], marker="*", color="black", markersize=12)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        title or f"RoI: {len(p)} faces, {int(se.sum())} SE; floor {roi.floor_z:.2f} m, ceiling {roi.ceiling_z:.2f} m"
    )
    from matplotlib.lines import Line2D

    ax.legend(
        handles=[
            Line2D([], [], color=SE_COLOUR, lw=3, label="SE face"),
            Line2D([], [], color=NON_SE_COLOUR, lw=3, ls="--", label="non-SE face"),
        ],
        loc="upper right",
        fontsize=8,
    )
    return ax


def save_roi_png(roi: RoI, se: Sequence[bool] | np.ndarray, path: str | Path, **kwargs) -> Path:
    """:func:`plot_roi` written to a PNG file."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 8))
    plot_roi(roi, se, ax, **kwargs)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
