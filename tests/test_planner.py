"""The planning pipeline in one place: the gain model chosen by configuration, the plan's units."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbs_env.config import RobotConfig, make_config
from nbs_env.env import NBSEnv
from nbs_env.errors import ConfigError
from nbs_env.labels import VoxelLabel
from nbs_env.observation import CandidateColumn, candidate_table_of
from nbs_env.planning.planner import (
    GAIN_MODELS,
    PlanningConfig,
    greedy_order,
    plan,
    predict_gains,
    register_gain_model,
)
from nbs_env.planning.visibility import GainConfig
from policies import GreedyPolicy

TOY = "toy_within_3m"


class WithinThreeMetres:
    """A toy gain: every Occluded-structure voxel within 3 m of the scanner counts, seen or not."""

    def __init__(self, labels, origin, voxel_size, config):
        self.targets = origin + (np.argwhere(labels == VoxelLabel.OCCLUDED_STRUCTURE) + 0.5) * voxel_size

    def gains(self, sensors, scanner):
        d = np.linalg.norm(self.targets[None, :, :] - sensors[:, None, :], axis=-1)
        return (d < 3.0).sum(axis=1)


@pytest.fixture
def toy_model():
    register_gain_model(TOY, WithinThreeMetres)
    yield TOY
    GAIN_MODELS.pop(TOY, None)


def test_the_greedy_follows_a_gain_model_chosen_by_configuration(toy_model):
    base = make_config("fast", scene="l_room")
    config = replace(base, robot=replace(base.robot, gain=GainConfig(model=toy_model)))
    env = NBSEnv(config)
    obs, info = env.reset(seed=0)
    view = env.belief_view()
    n = view.count
    assert n > 3
    # The plan's gains are the toy's, computed here from the robot's own grid and NVPs.
    grid = view.grid
    sensors = np.column_stack([view.candidates_xy[:n], np.full(n, view.roi.floor_z + config.robot.scanner.height)])
    expected = WithinThreeMetres(grid.labels, grid.origin, grid.voxel_size, None).gains(sensors, None)
    assert np.array_equal(info["candidate_gains"][:n], expected)
    # The observation reads them in the one unit, a share of the room's structural voxels.
    structural = np.count_nonzero(np.isin(grid.labels, [VoxelLabel.STRUCTURE, VoxelLabel.OCCLUDED_STRUCTURE]))
    share = candidate_table_of(obs)[:n, CandidateColumn.PREDICTED_GAIN]
    np.testing.assert_allclose(share, expected / structural, rtol=1e-6)
    # The visibility model ranks these NVPs otherwise, so following the toy is a choice it makes.
    visibility = predict_gains(
        grid.labels, grid.origin, grid.voxel_size, view.candidates_xy[:n], view.roi.floor_z, config.robot.scanner
    )
    path = view.path_length[:n]
    assert not np.array_equal(greedy_order(visibility, path), greedy_order(expected, path))
    # The greedy takes the toy's best, and the scan records the toy's predicted gain.
    action = GreedyPolicy().act(obs, info)
    assert action == int(greedy_order(expected, path)[0])
    env.step(action)
    assert env.storey.scans[1].predicted_gain == expected[action]


def test_an_unknown_gain_model_is_refused_before_a_scan():
    with pytest.raises(ConfigError, match=r"unknown gain model 'nope'.*visibility"):
        NBSEnv("fast", scene="l_room", **{"robot.gain.model": "nope"}).reset(seed=0)
    with pytest.raises(ConfigError, match="registered already"):
        register_gain_model("visibility", WithinThreeMetres)
    with pytest.raises(ConfigError, match="gain model"):
        GainConfig(model="")
    with pytest.raises(ConfigError, match="group"):
        GainConfig(group=0)


def test_plan_units_and_completion_rule():
    env = NBSEnv("fast", scene="office")
    env.reset(seed=1)
    robot = env.storey.robot
    planned = robot.plan()
    assert planned is robot.plan()  # a query, kept until the next scan
    # The planner run again on the same belief gives the same NVPs and gains.
    again = plan(robot.belief, robot.pose, robot.stops, robot.visited, robot.config.planning)
    assert np.array_equal(again.candidates.xy, planned.candidates.xy)
    assert np.array_equal(again.gains, planned.gains)
    n = planned.count
    best = int(planned.gains[:n].max())
    share = planned.gain_share()
    assert share[:n].max() == pytest.approx(best / planned.structural_voxels)
    assert not planned.gain_below(best / planned.structural_voxels * 0.99)
    assert planned.gain_below(best / planned.structural_voxels * 1.01)
    assert planned.best() == int(planned.order()[0])
    # Without gains the planner still lists the NVPs.
    bare = plan(robot.belief, robot.pose, robot.stops, robot.visited, PlanningConfig(predict_gains=False))
    assert bare.count > 0 and not bare.gains.any()


def test_a_gain_model_of_the_wrong_shape_is_reported(toy_model):
    class Broken:
        def __init__(self, *args):
            pass

        def gains(self, sensors, scanner):
            return np.zeros(len(sensors) + 1)

    register_gain_model(toy_model, Broken, replace=True)
    labels = np.full((10, 10, 10), VoxelLabel.OCCLUDED_STRUCTURE, dtype=np.uint8)
    with pytest.raises(ValueError, match="returned shape"):
        predict_gains(
            labels, np.zeros(3), 0.1, np.ones((4, 2)), 0.0, RobotConfig().scanner, GainConfig(model=toy_model)
        )


def test_within_roi_tests_the_free_cells_as_the_whole_grid_test_did():
    """The polygon test of only the free cells the robot did not stand on gives the whole grid's."""
    import shapely
    from shapely.geometry import Polygon

    from nbs_env.planning.navigation import TraversabilityMap
    from nbs_env.planning.planner import within_roi

    rng = np.random.default_rng(4)
    shape = (90, 70)
    tmap = TraversabilityMap(
        free=rng.random(shape) < 0.6,
        clearance=np.full(shape, np.inf),
        obstacle=np.zeros(shape, dtype=bool),
        column_empty=np.ones(shape, dtype=bool),
        visited=rng.random(shape) < 0.05,
        origin=np.array([-1.03, 0.51]),
        voxel_size=0.05,
        robot_radius=0.3,
        required_clearance=0.4,
    )
    polygon = np.array([[0.0, 1.0], [3.0, 1.0], [3.0, 2.5], [1.2, 2.5], [1.2, 3.9], [0.0, 3.9]])
    i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    centres = tmap.centre_of(np.column_stack([i.ravel(), j.ravel()]))
    inside = shapely.contains_xy(Polygon(polygon), centres[:, 0], centres[:, 1]).reshape(shape)
    got = within_roi(tmap, polygon).free
    assert np.array_equal(got, tmap.free & (inside | tmap.visited))
    assert got.any() and (tmap.free & ~got).any() and (got & ~inside).any()  # visited cells kept outside


def test_a_voxel_missed_from_afar_is_out_of_the_gains_of_views_as_far_from_about_there():
    """A scan that had a voxel in view 6 m off and left it Occluded-structure: a view from within a
    metre of that scan and no nearer to the voxel will miss it again and gains nothing for it; a view
    nearer to it, or from elsewhere, still counts it."""
    from nbs_env.belief import MissedVoxels
    from nbs_env.planning.planner import missed_again

    class SeesAll:
        def sees(self, sensors, targets, scanner):
            return np.ones((len(sensors), len(targets)), dtype=bool)

    voxel = np.array([[6.0, 0.0, 2.5]])
    missed = MissedVoxels(voxel, np.array([0]), np.array([[0.0, 0.0, 1.5]]), np.array([np.hypot(6.0, 1.0)]))
    sensors = np.array([[0.0, 0.0, 1.5], [-0.5, 0.5, 1.5], [0.9, 0.0, 1.5], [3.0, 2.0, 1.5], [0.0, -2.0, 1.5]])
    again = missed_again(SeesAll(), sensors, make_config().robot.scanner, missed, 0.05)
    # The same place and one farther back within a metre: out; 0.9 m nearer, elsewhere: in.
    assert again.tolist() == [1, 1, 0, 0, 0]
