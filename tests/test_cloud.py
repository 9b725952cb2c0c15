"""The room's working copy: points averaged in world-anchored voxels."""

import numpy as np
import pytest

from nbs_env.mapping.cloud import VoxelMeans


def _brute_force(points: np.ndarray, size: float) -> dict[tuple[int, int, int], np.ndarray]:
    cells = np.floor(points / size).astype(int)
    out: dict[tuple[int, int, int], list] = {}
    for cell, p in zip(map(tuple, cells), points, strict=True):
        out.setdefault(cell, []).append(p)
    return {c: np.mean(ps, axis=0) for c, ps in out.items()}


@pytest.mark.parametrize("seed", [0, 1])
def test_scan_by_scan_means_are_the_means_of_all_points_per_voxel(seed):
    """Three batches added in turn, with negative coordinates and voxels shared between batches:
    one point per voxel, the mean of every point that fell in it, whatever the order."""
    rng = np.random.default_rng(seed)
    batches = [rng.uniform(-1.0, 1.0, size=(400, 3)) * [3, 2, 1] for _ in range(3)]
    size = 0.25
    cloud, reversed_cloud = VoxelMeans(size), VoxelMeans(size)
    for b in batches:
        cloud.add(b)
    for b in batches[::-1]:
        reversed_cloud.add(b)
    want = _brute_force(np.concatenate(batches), size)
    assert len(cloud) == len(want) < 1200  # voxels are shared
    got = {tuple(np.floor(p / size).astype(int)): p for p in cloud.points}
    assert got.keys() == want.keys()
    for cell, mean in want.items():
        np.testing.assert_allclose(got[cell], mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.sort(reversed_cloud.points, axis=0), np.sort(cloud.points, axis=0), atol=1e-12)


def test_bad_points_are_refused():
    cloud = VoxelMeans(0.05)
    with pytest.raises(ValueError, match="finite"):
        cloud.add(np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        cloud.add(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="farther"):
        cloud.add(np.array([[1e6, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="voxel_size"):
        VoxelMeans(0.0)
    assert len(cloud) == 0 and cloud.points.shape == (0, 3)


def test_normals_are_summed_per_voxel_with_the_points():
    rng = np.random.default_rng(4)
    points = rng.uniform(-1.0, 1.0, size=(500, 3))
    normals = rng.normal(size=(500, 3))
    cloud = VoxelMeans(0.5, normals=True)
    cloud.add(points[:250], normals[:250])
    copy = cloud.copy()
    cloud.add(points[250:], normals[250:])
    cells = np.floor(points / 0.5).astype(int)
    for k, p in enumerate(cloud.points):
        mine = np.all(cells == np.floor(p / 0.5).astype(int), axis=1)
        np.testing.assert_allclose(cloud.normal_sums[k], normals[mine].sum(axis=0), atol=1e-12)
        assert cloud.counts[k] == mine.sum()
    assert copy.counts.sum() == 250  # the copy did not see the second batch
    with pytest.raises(ValueError, match="normals"):
        cloud.add(points)
    with pytest.raises(ValueError, match="normals"):
        VoxelMeans(0.5).add(points, normals)
    with pytest.raises(ValueError, match="no normals"):
        _ = VoxelMeans(0.5).normal_sums
