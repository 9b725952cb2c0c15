"""Pictures of the robot's belief, for reports: the top projection with the RoI and its SE faces."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nbs_env.labels import LABEL_COLOURS as LABEL_PALETTE
from nbs_env.perception.roi import RoI

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["STOP_STYLES", "draw", "plot_roi", "render_topdown", "save_roi_png", "topdown_figure"]

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


#: How each kind of scan position is drawn in the top-down picture (:func:`topdown_figure`), by the
#: kind :meth:`~nbs_env.env.NBSEnv.render_figure` gives it, with its legend label. Each has its own
#: shape and a black edge, and no colour of the labels' palette: the label colours fill the rooms.
STOP_STYLES: dict[str, dict[str, object]] = {
    "start": {"marker": "s", "markersize": 8, "color": "white", "markeredgecolor": "black", "label": "start"},
    "nvp": {"marker": "*", "markersize": 9, "color": "black", "markeredgecolor": "black", "label": "scan at an NVP"},
    "door": {
        "marker": "D",
        "markersize": 6,
        "color": "#e600e6",
        "markeredgecolor": "black",
        "label": "door-frame scan (first of a room)",
    },
    "search": {
        "marker": "^",
        "markersize": 7,
        "color": "#00bcd4",
        "markeredgecolor": "black",
        "label": "search scan (wall or door)",
    },
}
#: The last scan position (where the robot stands), drawn over its kind's marker.
LAST_STOP_STYLE: dict[str, object] = {
    "marker": "*",
    "markersize": 13,
    "color": "#ffd700",
    "markeredgecolor": "black",
    "label": "last scan (the robot)",
}
#: The driven paths: the robot's own plans, in its map frame.
PATH_STYLE: dict[str, object] = {"color": "black", "lw": 1.0, "alpha": 0.75, "label": "driven path (planned)"}
#: The ``gid`` of each driven path's line, so that a reader of the figure finds them.
PATH_GID = "driven path"
#: The outline of a finished room (its RoI).
ROOM_OUTLINE_STYLE: dict[str, object] = {"color": "0.6", "lw": 1.0, "label": "finished room's outline (RoI)"}
#: A candidate's marker in the legend (the picture colours each by its gain, viridis's middle here).
CANDIDATE_STYLE: dict[str, object] = {
    "marker": "o",
    "markersize": 5,
    "color": "#21918c",
    "markeredgecolor": "black",
    "markeredgewidth": 0.3,
}
#: Legend labels of the voxel labels' colours, by label value 1-5 (Unknown, 0, is not drawn).
LABEL_NAMES = ("Empty", "Clutter", "Structure", "Occluded clutter", "Occluded structure")


def topdown_figure(
    *,
    grid=None,
    roi: RoI | None = None,
    se: Sequence[bool] | np.ndarray = (),
    candidates_xy: np.ndarray | None = None,
    gains: np.ndarray | None = None,
    paths: Sequence[np.ndarray] = (),
    stops: np.ndarray | None = None,
    stop_kinds: Sequence[str] = (),
    rooms: Sequence = (),
    title: str = "",
    size: tuple[int, int] = (640, 640),
) -> Figure:
    """A top-down picture of the robot's belief as a matplotlib Figure, with a legend of what it draws.

    Everything is in the robot's map frame and from its belief (no ground truth).

    Parameters
    ----------
    grid : VoxelGrid, optional
        The current room's V(t), drawn by label (:data:`LABEL_COLOURS`).
    roi : RoI, optional
        The current RoI; ``se`` gives its faces' classification (SE solid blue, non-SE dashed red).
    candidates_xy : (k, 2) float, optional
        The NVPs, coloured by ``gains`` (k,).
    paths : sequence of (p, 2) float
        Driven paths (the robot's plans, each the polyline it drove), drawn in order; each line's
        ``gid`` is :data:`PATH_GID`.
    stops : (s, 2) float, optional
        Scan positions, in order; the last is marked as the robot's position.
    stop_kinds : sequence of str
        Each stop's kind, a key of :data:`STOP_STYLES` (``"start"``, ``"nvp"``, ``"door"``,
        ``"search"``); empty: every stop is ``"nvp"``.
    rooms : sequence of RoomModel
        Rooms finished before: their outline, points (Structure and Clutter colours) and SE faces.
    title : str
    size : (int, int)
        Width and height in pixels (at 100 dpi); the legend takes the bottom of it.

    Returns
    -------
    matplotlib.figure.Figure
        With an Agg canvas; its axes' legend (``fig.axes[0].get_legend()``) names every kind of
        marker, line and colour drawn.

    Raises
    ------
    ValueError
        ``stop_kinds`` is neither empty nor one known kind per stop.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n_stops = 0 if stops is None else len(stops)
    kinds = list(stop_kinds) or ["nvp"] * n_stops
    if len(kinds) != n_stops or not set(kinds) <= set(STOP_STYLES):
        raise ValueError(
            f"stop_kinds must give one of {sorted(STOP_STYLES)} per stop ({n_stops}), got {list(stop_kinds)}"
        )
    dpi = 100
    width, height = size
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    # Fixed margins in pixels: the legend's rows (up to six) and the x label below, the title above.
    bottom, top = 125 / height, 25 / height
    ax = fig.add_axes((0.1, bottom, 0.82, 1.0 - bottom - top))
    # An equal aspect shrinks the axes inside their box: kept at its foot, above the legend.
    ax.set_anchor("S")
    handles: list[Line2D | Patch] = []
    drawn_labels: set[int] = set()
    outline = {k: v for k, v in ROOM_OUTLINE_STYLE.items() if k != "label"}
    for room in rooms:
        poly = np.vstack([room.polygon, room.polygon[:1]])
        ax.plot(poly[:, 0], poly[:, 1], **outline)
        # Walls and furniture, not the floor and ceiling that would cover the picture.
        z = room.points[:, 2]
        band = (z > room.floor_z + 0.3) & (z < room.ceiling_z - 0.3)
        for which, label in ((room.structure & band, 3), (~room.structure & band, 2)):
            pts = room.points[which]
            step = max(1, len(pts) // 6000)
            ax.scatter(pts[::step, 0], pts[::step, 1], s=0.4, color=LABEL_COLOURS[label], linewidths=0)
            drawn_labels.add(label)
        for face in room.se_faces:
            ax.plot([face.p0[0], face.p1[0]], [face.p0[1], face.p1[1]], color=SE_COLOUR, lw=2, alpha=0.6)
    if grid is not None and roi is not None:
        top_view = top_labels(grid.labels, grid.origin[2], grid.voxel_size, roi.floor_z, roi.ceiling_z)
        rgba = np.ones((*top_view.T.shape, 4))
        rgba[..., :3] = LABEL_COLOURS[top_view.T]
        rgba[..., 3] = np.where(top_view.T == 0, 0.0, 1.0)
        x0, y0 = grid.origin[:2]
        extent = (x0, x0 + top_view.shape[0] * grid.voxel_size, y0, y0 + top_view.shape[1] * grid.voxel_size)
        ax.imshow(rgba, origin="lower", extent=extent, interpolation="nearest")
        # Every label the palette has: one missing now may appear in the next step's picture.
        drawn_labels |= set(range(1, len(LABEL_NAMES) + 1))
    handles += [Patch(color=LABEL_COLOURS[k], label=LABEL_NAMES[k - 1]) for k in sorted(drawn_labels)]
    if rooms:
        handles.append(Line2D([], [], **ROOM_OUTLINE_STYLE))
    # The current RoI's faces as _draw_faces classifies them (a face with no entry is non-SE).
    faces_se = np.zeros(0, dtype=bool)
    if roi is not None:
        _draw_faces(ax, roi.polygon, se, lw=2.5)
        given = np.asarray(se, dtype=bool)[: len(roi.polygon)]
        faces_se = np.concatenate([given, np.zeros(len(roi.polygon) - len(given), dtype=bool)])
    if faces_se.any() or any(len(room.se_faces) for room in rooms):
        handles.append(Line2D([], [], color=SE_COLOUR, lw=2.5, label="SE wall face"))
    if not faces_se.all():
        handles.append(Line2D([], [], color=NON_SE_COLOUR, lw=2.5, ls="--", label="non-SE wall face"))
    line = {k: v for k, v in PATH_STYLE.items() if k != "label"}
    drawn_paths = [np.asarray(path, dtype=float).reshape(-1, 2) for path in paths]
    for path in drawn_paths:
        if len(path):
            ax.plot(path[:, 0], path[:, 1], gid=PATH_GID, **line)
    if any(len(path) for path in drawn_paths):
        handles.append(Line2D([], [], **PATH_STYLE))
    if candidates_xy is not None and len(candidates_xy):
        g = np.zeros(len(candidates_xy)) if gains is None else np.asarray(gains, dtype=float)
        sc = ax.scatter(
            candidates_xy[:, 0], candidates_xy[:, 1], c=g, cmap="viridis", s=18, edgecolors="k", linewidths=0.3
        )
        fig.colorbar(sc, ax=ax, fraction=0.04, pad=0.01, label="predicted conversions")
        handles.append(Line2D([], [], ls="none", label="candidate NVP (colour: gain)", **CANDIDATE_STYLE))
    if n_stops:
        stops = np.asarray(stops, dtype=float)
        kind_array = np.array(kinds)
        for kind, style in STOP_STYLES.items():
            mine = kind_array == kind
            if not mine.any():
                continue
            marker = {k: v for k, v in style.items() if k != "label"}
            ax.plot(stops[mine, 0], stops[mine, 1], ls="none", **marker)
            handles.append(Line2D([], [], ls="none", **style))
        last = {k: v for k, v in LAST_STOP_STYLE.items() if k != "label"}
        ax.plot(stops[-1, 0], stops[-1, 1], ls="none", **last)
        handles.append(Line2D([], [], ls="none", **LAST_STOP_STYLE))
    ax.legend(
        handles=handles,
        loc="lower center",
        bbox_to_anchor=(0.5, 2 / height),
        bbox_transform=fig.transFigure,
        ncol=3,
        fontsize=7,
        frameon=False,
        handlelength=1.8,
        columnspacing=1.2,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)", labelpad=1)
    ax.set_ylabel("y (m)")
    if title:
        ax.set_title(title, fontsize=9)
    return fig


def draw(fig: Figure) -> np.ndarray:
    """(h, w, 3) uint8: a Figure with an Agg canvas (:func:`topdown_figure`'s) drawn as an RGB array."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def render_topdown(**kwargs: Any) -> np.ndarray:
    """:func:`topdown_figure` (same keyword arguments) drawn as an RGB array.

    Returns
    -------
    (h, w, 3) uint8
    """
    return draw(topdown_figure(**kwargs))
