"""Top-down pictures of a scene: walls, doors, windows, clutter, room names and the start."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes.model import Scene, SurfaceClass

__all__ = ["CLASS_COLOURS", "plot_scene", "save_scene_png"]

CLASS_COLOURS: dict[SurfaceClass, str] = {
    SurfaceClass.FLOOR: "#f2efe9",
    SurfaceClass.CEILING: "#ffffff",
    SurfaceClass.WALL: "#2b2b2b",
    SurfaceClass.DOOR: "#e07b00",
    SurfaceClass.WINDOW: "#3d8fd1",
    SurfaceClass.CLUTTER: "#9c6b3c",
}


def plot_scene(scene: Scene, ax=None, *, title: str | None = None):
    """Draw ``scene`` seen from above on a matplotlib axes and return the axes.

    Every face is projected to the floor: floors fill the rooms, vertical faces draw as their plan
    outline coloured by class, horizontal clutter faces fill. Works for any scene (plan, mesh, IFC).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection

    if ax is None:
        _, ax = plt.subplots(figsize=(10, 8))
    tri = scene.mesh.vertices[scene.mesh.faces]
    normals = scene.mesh.face_normals
    labels = scene.face_labels
    horizontal = np.abs(normals[:, 2]) > 0.7
    floor_z = float(tri[labels == SurfaceClass.FLOOR][..., 2].min())
    # Only what stands on this storey's floors and below its ceilings is drawn.
    floor = labels == SurfaceClass.FLOOR
    ax.add_collection(
        PolyCollection(tri[floor][..., :2], facecolors=CLASS_COLOURS[SurfaceClass.FLOOR], edgecolors="none")
    )
    clutter_top = (labels == SurfaceClass.CLUTTER) & horizontal
    order = np.argsort(tri[clutter_top][..., 2].mean(axis=1))
    ax.add_collection(
        PolyCollection(
            tri[clutter_top][order][..., :2],
            facecolors=CLASS_COLOURS[SurfaceClass.CLUTTER],
            edgecolors="none",
            alpha=0.55,
        )
    )
    for cls, width in (
        (SurfaceClass.CLUTTER, 0.6),
        (SurfaceClass.WALL, 1.6),
        (SurfaceClass.WINDOW, 2.5),
        (SurfaceClass.DOOR, 2.5),
    ):
        sel = (labels == cls) & ~horizontal & (tri[..., 2].min(axis=1) < floor_z + 2.0)
        if cls == SurfaceClass.DOOR:
            sel = (labels == cls) & (tri[..., 2].min(axis=1) < floor_z + 2.0)
        edges = tri[sel][:, [[0, 1], [1, 2], [2, 0]]][..., :2].reshape(-1, 2, 2)
        edges = edges[np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1) > 1e-6]
        ax.add_collection(LineCollection(edges, colors=CLASS_COLOURS[cls], linewidths=width))
    for room in scene.rooms:
        from shapely.geometry import Polygon
        from shapely.ops import polylabel

        poly = Polygon(room.polygon)
        p = polylabel(poly, tolerance=0.05) if poly.is_valid else poly.centroid
        ax.text(p.x, p.y, f"{room.name}\n{room.area:.1f} m²", ha="center", va="center", fontsize=8, color="#444444")
    for door in scene.doors:
        ax.plot(*door.position[:2], marker="s", color=CLASS_COLOURS[SurfaceClass.DOOR], markersize=4)
    s = scene.start
    ax.plot(s[0], s[1], marker="*", color="#d62728", markersize=16, markeredgecolor="black", zorder=5)
    ax.annotate("start", (s[0], s[1]), textcoords="offset points", xytext=(8, 8), color="#d62728")
    lo, hi = scene.bounds
    pad = 0.5
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    areas = scene.class_areas()
    ax.set_title(
        title
        or f"{scene.name}: {len(scene.rooms)} rooms, {len(scene.doors)} doors, "
        f"floor {areas[SurfaceClass.FLOOR]:.0f} m², walls {areas[SurfaceClass.WALL]:.0f} m²"
    )
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=CLASS_COLOURS[c], lw=3, label=c.name.lower())
        for c in (SurfaceClass.WALL, SurfaceClass.DOOR, SurfaceClass.WINDOW, SurfaceClass.CLUTTER)
    ]
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return ax


def save_scene_png(scene: Scene, path: str | Path, *, dpi: int = 120) -> Path:
    """Render :func:`plot_scene` to a PNG file and return its path."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 8))
    plot_scene(scene, ax)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
