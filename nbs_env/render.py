"""Pictures of the robot's belief, for reports: the top projection with the RoI and its SE faces."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from nbs_env.labels import LABEL_COLOURS as LABEL_PALETTE
from nbs_env.perception.roi import RoI

__all__ = ["plot_roi", "save_roi_png"]

SE_COLOUR = "#1f77b4"
NON_SE_COLOUR = "#d62728"


def _draw_faces(ax, polygon: np.ndarray, se: Sequence[bool] | np.ndarray, lw: float) -> None:
    """The polygon's edges as wall faces: SE solid blue, non-SE dashed red (missing entries non-SE)."""
    se = np.asarray(se, dtype=bool)
    for k in range(len(polygon)):
        a, b = polygon[k], polygon[(k + 1) % len(polygon)]
        is_se = bool(se[k]) if k < len(se) else False
        ax.plot(
            [a[0], b[0]],
            [a[1], b[1]],
            color=SE_COLOUR if is_se else NON_SE_COLOUR,
            lw=lw,
            ls="-" if is_se else "--",
        )


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
    _draw_faces(ax, p, se, lw=3)
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


#: The voxel labels' palette (nbs_env.labels.LABEL_COLOURS) as RGB in 0..1, for matplotlib.
LABEL_COLOURS = np.asarray(LABEL_PALETTE, dtype=float) / 255.0


def top_labels(labels: np.ndarray, origin_z: float, voxel_size: float, floor_z: float, ceiling_z: float) -> np.ndarray:
    """(nx, ny) uint8: the labels of a grid seen from above, between 0.3 m over the floor and 0.3 m
    under the ceiling (the floor and ceiling slabs would hide everything), pooled by the observation's
    priority (Structure first)."""
    from nbs_env.observation import pool_labels

    nz = labels.shape[2]
    centres = origin_z + (np.arange(nz) + 0.5) * voxel_size
    # -1 below the band and 1 above it fall outside the single output cell.
    cell_z = np.where(centres <= floor_z + 0.3, -1, np.where(centres >= ceiling_z - 0.3, 1, 0))
    if not (cell_z == 0).any():
        cell_z = np.zeros(nz, dtype=np.int64)
    shape = (labels.shape[0], labels.shape[1], 1)
    return pool_labels(labels, (np.arange(shape[0]), np.arange(shape[1]), cell_z), shape)[:, :, 0]


def render_topdown(
    *,
    grid=None,
    roi: RoI | None = None,
    se: Sequence[bool] | np.ndarray = (),
    candidates_xy: np.ndarray | None = None,
    gains: np.ndarray | None = None,
    paths: Sequence[np.ndarray] = (),
    stops: np.ndarray | None = None,
    rooms: Sequence = (),
    title: str = "",
    size: tuple[int, int] = (640, 640),
) -> np.ndarray:
    """A top-down picture of the robot's belief as an RGB array.

    Parameters
    ----------
    grid : VoxelGrid, optional
        The current room's V(t), drawn by label (:data:`LABEL_COLOURS`).
    roi : RoI, optional
        The current RoI; ``se`` gives its faces' classification (SE solid blue, non-SE dashed red).
    candidates_xy : (k, 2) float, optional
        The NVPs, coloured by ``gains`` (k,).
    paths : sequence of (p, 2) float
        Driven paths (the robot's estimate), drawn in order.
    stops : (s, 2) float, optional
        Scan positions.
    rooms : sequence of RoomModel
        Rooms finished before: their outline and SE faces.

    Returns
    -------
    (h, w, 3) uint8
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    dpi = 100
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.08, 0.12, 0.84, 0.8))
    for room in rooms:
        poly = np.vstack([room.polygon, room.polygon[:1]])
        ax.plot(poly[:, 0], poly[:, 1], color="0.6", lw=1)
        # Walls and furniture, not the floor and ceiling that would cover the picture.
        z = room.points[:, 2]
        band = (z > room.floor_z + 0.3) & (z < room.ceiling_z - 0.3)
        for which, colour in ((room.structure & band, LABEL_COLOURS[3]), (~room.structure & band, LABEL_COLOURS[2])):
            pts = room.points[which]
            step = max(1, len(pts) // 6000)
            ax.scatter(pts[::step, 0], pts[::step, 1], s=0.4, color=colour, linewidths=0)
        for face in room.se_faces:
            ax.plot([face.p0[0], face.p1[0]], [face.p0[1], face.p1[1]], color=SE_COLOUR, lw=2, alpha=0.6)
    if grid is not None and roi is not None:
        top = top_labels(grid.labels, grid.origin[2], grid.voxel_size, roi.floor_z, roi.ceiling_z)
        rgba = np.ones((*top.T.shape, 4))
        rgba[..., :3] = LABEL_COLOURS[top.T]
        rgba[..., 3] = np.where(top.T == 0, 0.0, 1.0)
        x0, y0 = grid.origin[:2]
        extent = (x0, x0 + top.shape[0] * grid.voxel_size, y0, y0 + top.shape[1] * grid.voxel_size)
        ax.imshow(rgba, origin="lower", extent=extent, interpolation="nearest")
    if roi is not None:
        _draw_faces(ax, roi.polygon, se, lw=2.5)
    for path in paths:
        ax.plot(path[:, 0], path[:, 1], color="black", lw=1, alpha=0.7)
    if candidates_xy is not None and len(candidates_xy):
        g = np.zeros(len(candidates_xy)) if gains is None else np.asarray(gains, dtype=float)
        sc = ax.scatter(
            candidates_xy[:, 0], candidates_xy[:, 1], c=g, cmap="viridis", s=18, edgecolors="k", linewidths=0.3
        )
        fig.colorbar(sc, ax=ax, fraction=0.04, pad=0.01, label="predicted conversions")
    if stops is not None and len(stops):
        ax.plot(stops[:, 0], stops[:, 1], ls="none", marker="*", color="black", markersize=9)
        ax.plot(stops[-1, 0], stops[-1, 1], ls="none", marker="*", color="#ffd700", markeredgecolor="k", markersize=13)
    from matplotlib.patches import Patch

    names = ("Empty", "Clutter", "Structure", "Occluded clutter", "Occluded structure")
    ax.legend(
        handles=[Patch(color=LABEL_COLOURS[k + 1], label=n) for k, n in enumerate(names)],
        loc="upper left",
        bbox_to_anchor=(0.0, -0.11),
        ncol=5,
        fontsize=7,
        frameon=False,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)", labelpad=1)
    ax.set_ylabel("y (m)")
    if title:
        ax.set_title(title, fontsize=9)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
