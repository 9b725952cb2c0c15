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


def test_tags_are_the_first_batch_that_reached_each_voxel():
    """With ``tags=True`` each voxel keeps the tag of the first ``add`` that put a point in it
    (the scan index the report writes as a point's source), in the order of the points."""
    rng = np.random.default_rng(7)
    batches = [rng.uniform(-1.0, 1.0, size=(300, 3)) for _ in range(4)]
    size = 0.25
    cloud = VoxelMeans(size, tags=True)
    for tag, batch in enumerate(batches):
        cloud.add(batch, tag=10 + tag)
        if tag == 1:
            copy = cloud.copy()
    first: dict[tuple[int, int, int], int] = {}
    for tag, batch in enumerate(batches):
        for cell in map(tuple, np.floor(batch / size).astype(int)):
            first.setdefault(cell, 10 + tag)
    got = {tuple(np.floor(p / size).astype(int)): int(t) for p, t in zip(cloud.points, cloud.tags, strict=True)}
    assert got == first and len(set(got.values())) == 4  # every batch reached voxels of its own
    assert cloud.tags.dtype == np.int32 and len(copy.tags) == len(copy) < len(cloud)
    assert set(copy.tags.tolist()) == {10, 11}  # the copy did not see the later batches
    with pytest.raises(ValueError, match="tag"):
        cloud.add(batches[0])
    with pytest.raises(ValueError, match="tag"):
        VoxelMeans(size).add(batches[0], tag=0)
    with pytest.raises(ValueError, match="tag must be in"):
        VoxelMeans(size, tags=True).add(batches[0], tag=-1)
    with pytest.raises(ValueError, match="no tags"):
        _ = VoxelMeans(size).tags


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


def test_covariances_are_averaged_per_voxel_and_checked():
    """With ``covariances=True`` a voxel's covariance is the mean of its points', over every scan
    added, kept apart from the normals; a copy without them, or an add without them, is refused."""
    rng = np.random.default_rng(4)
    copy = VoxelMeans(0.5, normals=True, covariances=True)
    parts = []
    for _ in range(3):
        points = rng.uniform(0, 2, (300, 3))
        a = rng.normal(0, 1, (300, 3, 3))
        covs = a @ a.transpose(0, 2, 1)
        normals = rng.normal(0, 1, (300, 3))
        copy.add(points, normals, covs)
        parts.append((points, normals, covs))
    points = np.concatenate([p for p, _, _ in parts])
    normals = np.concatenate([n for _, n, _ in parts])
    covs = np.concatenate([c for _, _, c in parts])
    cells = np.floor(points / 0.5).astype(int)
    means = copy.points
    got = copy.covariances()
    for k, mean in enumerate(means):
        members = np.all(cells == np.floor(mean / 0.5).astype(int), axis=1)
        np.testing.assert_allclose(got[k], covs[members].mean(axis=0), atol=1e-12)
        np.testing.assert_allclose(copy.normal_sums[k], normals[members].sum(axis=0), atol=1e-12)
    np.testing.assert_array_equal(copy.covariances(np.array([2, 0])), got[[2, 0]])
    # A zero matrix is no estimate: it leaves a voxel's mean alone, and a voxel with none reads zero.
    lone = VoxelMeans(0.5, normals=True, covariances=True)
    lone.add(
        np.array([[0.1, 0.1, 0.1], [0.2, 0.2, 0.2], [3.1, 3.1, 3.1]]),
        np.ones((3, 3)),
        np.stack([covs[0], 0 * covs[0], 0 * covs[0]]),
    )
    np.testing.assert_allclose(lone.covariances()[0], covs[0])
    assert not lone.covariances()[1].any()
    assert np.array_equal(copy.copy().covariances(), got)
    with pytest.raises(ValueError, match="covariances must be given"):
        copy.add(points[:5], normals[:5])
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        copy.add(points[:5], normals[:5], covs[:4])
    with pytest.raises(ValueError, match="keeps no covariances"):
        VoxelMeans(0.5).covariances()


def _numpy_add(cloud: VoxelMeans, values: np.ndarray) -> None:
    """The merge as numpy did it before the compiled one (the oracle): a sort, ``np.add.reduceat``
    per voxel, and ``np.insert`` of the new voxels."""
    cells = np.floor(values[:, :3] / cloud.voxel_size).astype(np.int64) + (1 << 20)
    keys = (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
    keys = keys[starts]
    sums = np.add.reduceat(values[order], starts, axis=0)
    counts = np.diff(np.append(starts, len(order)))
    at = np.searchsorted(cloud._keys, keys)
    held = at < len(cloud._keys)
    held[held] = cloud._keys[at[held]] == keys[held]
    cloud._sums[at[held]] += sums[held]
    cloud._counts[at[held]] += counts[held]
    new = ~held
    cloud._keys = np.insert(cloud._keys, at[new], keys[new])
    cloud._sums = np.insert(cloud._sums, at[new], sums[new], axis=0)
    cloud._counts = np.insert(cloud._counts, at[new], counts[new])


@pytest.mark.parametrize("size", [0.05, 0.5, 3.0])
def test_the_compiled_merge_is_numpys_bit_for_bit(size):
    """Sums of one to thousands of points per voxel (numpy's pairwise sum past 8 and past 128
    points), negative zeros included, equal what numpy's reduceat and insert gave, bit for bit."""
    rng = np.random.default_rng(3)
    cloud, oracle = VoxelMeans(size, normals=True), VoxelMeans(size, normals=True)
    for _ in range(4):
        n = int(rng.integers(1, 20000))
        points = rng.normal(size=(n, 3)) * rng.uniform(0.5, 6.0)
        normals = rng.normal(size=(n, 3))
        normals[rng.random(n) < 0.2] = -0.0
        cloud.add(points, normals)
        _numpy_add(oracle, np.hstack([points, normals]))
        assert np.array_equal(cloud._keys, oracle._keys) and np.array_equal(cloud._counts, oracle._counts)
        assert np.array_equal(cloud._sums, oracle._sums)
        assert np.array_equal(np.signbit(cloud._sums), np.signbit(oracle._sums))
    assert (cloud._counts == 1).any()
    assert cloud._counts.max() > {0.05: 1, 0.5: 8, 3.0: 128}[size]  # each of numpy's three sums
