"""The greedy NBS gain on hand-built grids: occlusion, field of view, range, ranking."""

from __future__ import annotations

import numpy as np
import pytest

from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.planner import greedy_order
from nbs_env.planning.visibility import GainConfig, VisibilityModel, occupied_surface

S = 0.1


def room_with_cabinet() -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 6 x 3 m grid at 10 cm: the wall at x = 5.95 m is still Occluded-structure, and a cabinet
    (Clutter, 0.5 m deep, 1.5 m wide, 2 m tall) stands 0.3 m in front of it for y in [1, 2.5]."""
    labels = np.full((60, 60, 30), VoxelLabel.EMPTY, dtype=np.uint8)
    labels[59, :, :] = VoxelLabel.OCCLUDED_STRUCTURE
    labels[51:56, 10:25, 0:20] = VoxelLabel.CLUTTER
    return labels, np.zeros(3)


def test_exposed_faces_of_a_single_voxel_and_a_block():
    one = np.zeros((3, 3, 3), bool)
    one[1, 1, 1] = True
    vertices, triangles = occupied_surface(one)
    assert len(triangles) == 12 and vertices.min() == 1 and vertices.max() == 2
    block = np.ones((2, 2, 2), bool)
    _, triangles = occupied_surface(block)
    assert len(triangles) == 6 * 4 * 2  # inner faces are not exposed


@pytest.mark.parametrize("group", [1, 2, 3])
def test_target_groups_are_the_voxels_sharing_their_index_over_group(group):
    """The groups are those of np.unique over the rows of index // group (the oracle), in its order,
    with its counts and the mean centres of their members."""
    rng = np.random.default_rng(5)
    labels = rng.choice(
        np.array([VoxelLabel.EMPTY, VoxelLabel.OCCLUDED_STRUCTURE, VoxelLabel.CLUTTER], dtype=np.uint8),
        p=[0.6, 0.3, 0.1],
        size=(37, 23, 11),
    )
    origin = np.array([1.25, -3.5, 0.05])
    model = VisibilityModel(labels, origin, S, GainConfig(group=group))
    idx = np.argwhere(labels == VoxelLabel.OCCLUDED_STRUCTURE)
    _, inverse, counts = np.unique(idx // group, axis=0, return_inverse=True, return_counts=True)
    centres = origin + (idx + 0.5) * S
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.reshape(-1), centres)
    np.testing.assert_array_equal(model.group_counts, counts)
    np.testing.assert_array_equal(model.group_centres, sums / counts[:, None])


def test_exposed_faces_of_random_blocks_match_the_neighbour_by_neighbour_oracle():
    """Each face of a blocking voxel whose neighbour across it is not blocking, in the order of the
    axes, the two sides and the voxels: the same mesh as shifting the padded grid with np.roll."""
    rng = np.random.default_rng(2)
    blocking = rng.random((13, 9, 7)) < 0.35
    corners = {
        0: np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]),
        1: np.array([[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]),
        2: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
    }
    padded = np.pad(blocking, 1)
    quads = []
    for axis in range(3):
        for side in (0, 1):
            neighbour = np.roll(padded, -1 if side else 1, axis=axis)
            idx = np.argwhere((padded & ~neighbour)[1:-1, 1:-1, 1:-1]).astype(np.float32)
            idx[:, axis] += side
            quads.append(idx[:, None, :] + corners[axis][None, :, :])
    want = np.concatenate(quads).reshape(-1, 3)
    vertices, triangles = occupied_surface(blocking)
    np.testing.assert_array_equal(vertices, want)
    assert len(triangles) == 2 * len(want) // 4


def test_a_wall_hidden_behind_a_cabinet_favours_the_far_side():
    labels, origin = room_with_cabinet()
    model = VisibilityModel(labels, origin, S)
    scanner = ScannerConfig(min_range=0.5)
    behind = model.targets[(model.targets[:, 1] > 1.1) & (model.targets[:, 1] < 2.4) & (model.targets[:, 2] < 1.9)]
    assert len(behind) > 0
    # In front of the cabinet, looking at it: the wall part behind it is hidden.
    front = np.array([3.0, 1.75, 1.5])
    # Beside the cabinet, close to the wall: the wall part behind the cabinet is seen at an angle.
    side = np.array([5.4, 4.0, 1.5])
    vis_front = model.visible(front, scanner)
    vis_side = model.visible(side, scanner)
    hidden = (model.targets[:, 1] > 1.2) & (model.targets[:, 1] < 2.3) & (model.targets[:, 2] < 1.9)
    assert not vis_front[hidden].any()
    assert vis_side[hidden].sum() > 0
    assert vis_side[hidden].sum() > vis_front[hidden].sum()
    # When the rest of the wall is already Structure, the whole gain is the hidden part: the far side wins.
    seen = labels.copy()
    wall = seen[59]
    wall[wall == VoxelLabel.OCCLUDED_STRUCTURE] = VoxelLabel.STRUCTURE
    wall[10:25, 0:20] = VoxelLabel.OCCLUDED_STRUCTURE
    gains = VisibilityModel(seen, origin, S).gains(np.array([front, side]), scanner)
    assert gains[1] > gains[0]
    assert gains[0] < 0.1 * 15 * 20


def test_field_of_view_and_range_limits_are_never_counted():
    labels, origin = room_with_cabinet()
    model = VisibilityModel(labels, origin, S)
    scanner = ScannerConfig(min_range=1.5, elevation_min=-40.0, elevation_max=60.0)
    sensor = np.array([4.8, 4.0, 1.5])
    visible = model.visible(sensor, scanner)
    rel = model.targets[visible] - sensor
    dist = np.linalg.norm(rel, axis=1)
    elevation = np.degrees(np.arcsin(rel[:, 2] / dist))
    assert visible.sum() > 100
    assert dist.min() >= 1.5
    assert elevation.min() >= -40.0 and elevation.max() <= 60.0
    # Some wall voxels are close enough, or steep enough, to be left out.
    rel_all = model.targets - sensor
    d_all = np.linalg.norm(rel_all, axis=1)
    assert np.any(d_all < 1.5) and not visible[d_all < 1.5].any()


def test_occluded_clutter_switch_blocks_lines_of_sight():
    labels, origin = room_with_cabinet()
    labels[40:45, 30:40, :25] = VoxelLabel.OCCLUDED_CLUTTER
    sensor = np.array([2.0, 3.5, 1.5])
    scanner = ScannerConfig(min_range=0.5)
    free = VisibilityModel(labels, origin, S, GainConfig(occluded_clutter_blocks=False)).gains(sensor[None], scanner)
    blocked = VisibilityModel(labels, origin, S, GainConfig(occluded_clutter_blocks=True)).gains(sensor[None], scanner)
    assert blocked[0] < free[0]


def test_greedy_order_ties_go_to_the_shorter_path():
    gains = np.array([10, 30, 30, 5, 99])
    paths = np.array([1.0, 4.0, 2.0, 0.5, 0.1])
    mask = np.array([True, True, True, True, False])
    assert greedy_order(gains, paths, mask).tolist() == [2, 1, 0, 3, 4]


@pytest.mark.expensive
def test_predicted_gain_ranks_like_realised_conversions_on_generated_rooms():
    from train.evaluate_gain import room_correlations

    rows = room_correlations(20, GainConfig())
    rho = [r["spearman"] for r in rows]
    assert len(rho) == 20
    # Measured on the NVPs the robot plans over (0.63 mean, 0.72 median on this machine); a gain
    # unrelated to what a scan converts would give about 0.
    assert np.mean(rho) >= 0.5 and np.median(rho) >= 0.6, rho
    # Few NVPs lie inside furniture the robot never measured (the blind zone taken as free).
    assert sum(r["inside_obstacles"] for r in rows) <= 0.1 * sum(r["candidates"] for r in rows)
