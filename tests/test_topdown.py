"""The top-down picture (``env.render()``, ``topdown.png`` and ``steps/``): the paths the robot drove,
as it planned them, and a legend of what it draws."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from shapely.geometry import LineString, MultiLineString

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from nbs_env.render import PATH_GID, STOP_STYLES, topdown_figure
from nbs_env.storey import join_paths
from policies import GreedyPolicy
from scenes.labels import SurfaceClass


def length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(np.asarray(path, dtype=float), axis=0), axis=1).sum())


def true_walls(scene, height: float = 1.0) -> MultiLineString:
    """The scene's wall faces cut ``height`` metres above its floor, as 2-D segments (ground truth,
    the test's yardstick: under a door's lintel, over a window's sill)."""
    walls = np.flatnonzero(np.asarray(scene.face_labels) == SurfaceClass.WALL)
    mesh = scene.mesh.submesh([walls], append=True)
    segments = trimesh.intersections.mesh_plane(mesh, [0, 0, 1], [0, 0, float(scene.start[2]) + height])
    return MultiLineString([s[:, :2] for s in segments])


@pytest.fixture(scope="module")
def two_crossings():
    """generated:1 on the fast preset (perfect localisation: the robot's map frame is the world's),
    run by the greedy until its second door crossing, which goes back through the first room."""
    env = NBSEnv(make_config("fast", scene="generated:1"))
    obs, info = env.reset(seed=0)
    policy = GreedyPolicy()
    storey = env.storey
    while storey.open and sum(s.door for s in storey.scans) < 2:
        obs, _reward, _terminated, _truncated, info = env.step(policy.act(obs, info))
    assert sum(s.door for s in storey.scans) == 2
    return env


def test_each_scan_records_the_path_driven_to_it(two_crossings):
    storey = two_crossings.storey
    assert storey.scans[0].path.shape == (0, 2)
    assert len(storey.paths) == len(storey.scans) - 1
    for j, path in enumerate(storey.paths):
        record = storey.scans[j + 1]
        assert path is record.path
        # From where the robot stood to where it scanned next, as it estimates both.
        np.testing.assert_allclose(path[0], storey.scans[j].estimated_position[:2], atol=1e-6)
        np.testing.assert_allclose(path[-1], record.estimated_position[:2], atol=1e-6)
        # Its length is the travel the robot counted (info["path_length_m"]).
        assert length(path) == pytest.approx(record.path_length - storey.scans[j].path_length, abs=1e-3)
    assert sum(length(p) for p in storey.paths) == pytest.approx(storey.path_length, abs=1e-3)


def test_a_door_crossing_drives_around_the_walls_not_through_them(two_crossings):
    storey = two_crossings.storey
    walls = true_walls(storey.scene)
    crossings = [s for s in storey.scans if s.door]
    # The second crossing leaves the second room for a door of the first: a straight line from
    # where the robot stood to that door runs through a wall.
    through = [s for s in crossings if LineString([s.path[0], s.path[-1]]).intersects(walls)]
    assert through, "no crossing whose straight line would cross a wall: the test lost its case"
    for record in crossings:
        assert len(record.path) > 2, record.path  # the approach, or the doors on the way
        assert not LineString(record.path).intersects(walls), record.path


def test_the_picture_draws_the_driven_paths_and_a_legend(two_crossings):
    storey = two_crossings.storey
    fig = two_crossings.render_figure()
    ax = fig.axes[0]
    lines = [line for line in ax.lines if line.get_gid() == PATH_GID]
    assert len(lines) == len(storey.paths)
    for line, path in zip(lines, storey.paths, strict=True):
        np.testing.assert_allclose(np.column_stack(line.get_data()), path)
    legend = ax.get_legend()
    assert legend is not None
    labels = {text.get_text() for text in legend.get_texts()}
    expected = {
        "start",
        "scan at an NVP",
        "door-frame scan (first of a room)",
        "last scan (the robot)",
        "driven path (planned)",
        "finished room's outline (RoI)",
        "SE wall face",
        "candidate NVP (colour: gain)",
        "Empty",
        "Clutter",
        "Structure",
        "Occluded clutter",
        "Occluded structure",
    }
    assert expected <= labels, expected - labels
    if storey.wall_searches:
        assert "search scan (wall or door)" in labels


def test_the_legend_names_only_what_is_drawn():
    stops = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]])
    fig = topdown_figure(stops=stops, stop_kinds=["start", "door", "door"], paths=[stops[:2], stops[1:]])
    labels = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert labels == [
        "driven path (planned)",
        STOP_STYLES["start"]["label"],
        STOP_STYLES["door"]["label"],
        "last scan (the robot)",
    ]
    with pytest.raises(ValueError, match="stop_kinds"):
        topdown_figure(stops=stops, stop_kinds=["start", "wander", "nvp"])


def test_join_paths_drops_the_repeated_junction_and_keeps_a_jump():
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[1.0, 0.0], [1.0, 2.0]])
    c = np.array([[1.1, 2.0], [3.0, 2.0]])
    np.testing.assert_array_equal(join_paths([a, np.zeros((0, 2)), b]), [[0, 0], [1, 0], [1, 2]])
    np.testing.assert_array_equal(join_paths([a, b, c]), [[0, 0], [1, 0], [1, 2], [1.1, 2], [3, 2]])
    assert join_paths([]).shape == (0, 2)
