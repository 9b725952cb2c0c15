"""Compiled kernels split over threads give what the whole gives, bit for bit."""

import numpy as np
import pytest

from nbs_env import threads
from nbs_env.config import ScannerConfig
from nbs_env.labels import VoxelLabel
from nbs_env.planning.visibility import VisibilityModel


def test_split_covers_every_row_once_and_keeps_the_order(monkeypatch):
    monkeypatch.setenv("NBS_THREADS", "3")
    parts = threads.split(lambda s: np.arange(10)[s], 10, cost=10**9)
    assert [list(p) for p in parts] == [[0, 3, 6, 9], [1, 4, 7], [2, 5, 8]]
    assert len(threads.split(lambda s: s, 10, cost=10)) == 1  # too little work for threads
    monkeypatch.setenv("NBS_THREADS", "two")
    with pytest.raises(ValueError, match="NBS_THREADS"):
        threads.cores()


@pytest.mark.parametrize("n", ["1", "2", "3"])
def test_lines_of_sight_on_threads_are_the_single_thread_ones(monkeypatch, n):
    rng = np.random.default_rng(7)
    labels = np.full((40, 30, 12), VoxelLabel.EMPTY, dtype=np.uint8)
    labels[rng.random(labels.shape) < 0.04] = VoxelLabel.CLUTTER
    labels[:, :, 0] = VoxelLabel.OCCLUDED_STRUCTURE
    labels[0, :, :] = VoxelLabel.OCCLUDED_STRUCTURE
    model = VisibilityModel(labels, np.zeros(3), 0.1)
    sensors = np.column_stack([rng.uniform(0.5, 3.5, 37), rng.uniform(0.5, 2.5, 37), np.full(37, 0.6)])
    scanner = ScannerConfig(min_range=0.3)
    monkeypatch.setenv("NBS_THREADS", "1")
    want = model.sees(sensors, model.targets, scanner)
    monkeypatch.setenv("NBS_THREADS", n)
    got = model.sees(sensors, model.targets, scanner)
    assert want.any() and not want.all()
    assert np.array_equal(got, want)


def test_the_coverage_query_on_threads_is_the_single_thread_one(monkeypatch):
    from nbs_env.evaluation import _SampleColumns

    rng = np.random.default_rng(8)
    samples = rng.uniform(0, 4, size=(5000, 3))
    points = rng.uniform(-0.5, 4.5, size=(20000, 3))
    columns = _SampleColumns(samples, 0.05)
    monkeypatch.setenv("NBS_THREADS", "1")
    want = columns.query(points)
    monkeypatch.setenv("NBS_THREADS", "2")
    got = columns.query(points)
    assert want[0].any() and np.isfinite(want[2]).any()
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)


def test_carving_on_threads_gives_the_single_thread_labels(monkeypatch):
    """A scan integrated with the carving split into slabs and chunks over threads labels every
    voxel as on one thread."""
    from nbs_env.mapping.voxels import VoxelGrid
    from nbs_env.sensing.pose import pose_from_xyz_rpy
    from nbs_env.sensing.scanner import Scanner
    from scenes import load_scene

    scene = load_scene("l_room")
    config = ScannerConfig(angular_step=1.0)
    pose = pose_from_xyz_rpy(3.0, 4.5, 1.5, 0.0, 0.0, 0.3)
    scan = Scanner(scene, config).scan(pose, np.random.default_rng(0))
    labels = {}
    for n in ("1", "2", "3"):
        monkeypatch.setenv("NBS_THREADS", n)
        grid = VoxelGrid.covering(np.array([-0.5, -0.5, -0.2]), np.array([8.5, 10.5, 3.2]), 0.1)
        grid.integrate(scan.to_world(pose), np.ones(len(scan), bool), pose, scan.depth_image(), config)
        labels[n] = grid.labels.copy()
    assert (labels["1"] == VoxelLabel.EMPTY).sum() > 1000
    assert np.array_equal(labels["2"], labels["1"]) and np.array_equal(labels["3"], labels["1"])


def test_covariances_and_plane_normals_on_threads_are_the_single_thread_ones(monkeypatch):
    from nbs_env.sensing import gicp
    from nbs_env.sensing.registration import _plane_normals

    rng = np.random.default_rng(9)
    points = np.column_stack([rng.uniform(0, 6, 30000), rng.uniform(0, 4, 30000), rng.normal(0, 0.01, 30000)])
    points[::7, 2] += 1.0  # a second layer: some neighbourhoods mix, some radii fall back
    idx = np.argsort(rng.random((30000, 20)), axis=1).astype(np.int64) + np.arange(30000)[:, None] % 29000
    idx[::11, 15:] = -1
    sq = np.sort(rng.uniform(0, 0.5, size=idx.shape), axis=1)
    results = {}
    for n in ("1", "2", "3"):
        monkeypatch.setenv("NBS_THREADS", n)
        results[n] = (gicp.covariances_from_neighbours(points, idx, 20), _plane_normals(points, idx, sq, 0.02, 0.3, 6))
    assert np.abs(results["1"][1]).sum() > 0 and not np.allclose(results["1"][0], np.eye(3))
    for n in ("2", "3"):
        for got, want in zip(results[n], results["1"], strict=True):
            assert np.array_equal(got, want)


@pytest.mark.parametrize("n", ["1", "2"])
def test_beside_runs_the_work_and_hands_back_its_result_or_error(monkeypatch, n):
    monkeypatch.setenv("NBS_THREADS", n)
    assert threads.beside(lambda: 6 * 7).result() == 42

    def fails():
        raise KeyError("the work's own error")

    with pytest.raises(KeyError, match="own error"):
        threads.beside(fails).result()


def test_the_noise_drawn_beside_the_cast_is_the_noise_drawn_after_it(monkeypatch):
    """A noisy scan on two threads (the noise drawn while Embree casts) is the one-thread scan."""
    from nbs_env.sensing.pose import pose_from_xyz_rpy
    from nbs_env.sensing.scanner import Scanner
    from scenes import load_scene

    scanner = Scanner(load_scene("l_room"), ScannerConfig(angular_step=1.0, range_noise=0.005))
    pose = pose_from_xyz_rpy(3.0, 4.5, 1.5, 0.0, 0.0, 0.3)
    scans = {}
    for n in ("1", "2"):
        monkeypatch.setenv("NBS_THREADS", n)
        scans[n] = scanner.scan(pose, np.random.default_rng(5))
    assert np.array_equal(scans["1"].ranges, scans["2"].ranges)
    assert np.array_equal(scans["1"].points, scans["2"].points)
    # The noise is there (mixed pixels, whose range is a blend of two surfaces, aside).
    plain = ~scans["1"].truth.mixed
    assert 0.002 < np.std(scans["1"].ranges[plain] - scans["1"].truth.ranges[plain]) < 0.01


def test_an_episode_on_two_threads_is_the_one_thread_episode(monkeypatch):
    """The meter running beside the plan, the noise beside the cast and the split kernels change
    no decision and no figure: a greedy fast episode on two threads records what one thread does."""
    import gymnasium as gym

    import nbs_env  # noqa: F401  (registers the ids)
    from policies import GreedyPolicy

    records = {}
    for n in ("1", "2"):
        monkeypatch.setenv("NBS_THREADS", n)
        env = gym.make("nbs_env/NBS-Fast-v0")
        obs, info = env.reset(seed=3)
        policy, steps = GreedyPolicy(), []
        for _ in range(6):
            obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
            steps.append((reward, info["structure_sensed_pct"], env.unwrapped.storey.robot.pose.tobytes()))
            if terminated or truncated:
                break
        records[n] = steps
    assert len(records["1"]) > 2 and records["1"] == records["2"]


def test_s_of_t_merged_beside_is_the_s_of_t_merged_when_asked(monkeypatch):
    """Three registered scans of l_room: with two threads each scan's merge into S(t) runs beside
    (and waits before the next add, the next registration, and pickling); the poses and the working
    copies are those of one thread, bit for bit."""
    import pickle

    from nbs_env.mapping.cloud import AccumulatedCloud
    from nbs_env.sensing.pose import pose_from_xyz_rpy
    from nbs_env.sensing.registration import register
    from nbs_env.sensing.scanner import Scanner
    from scenes import load_scene

    scanner = Scanner(load_scene("l_room"), ScannerConfig(angular_step=1.0))
    stops = [pose_from_xyz_rpy(3.0, 4.5, 1.5), pose_from_xyz_rpy(2.0, 5.5, 1.5, 0, 0, 0.5)]
    stops.append(pose_from_xyz_rpy(4.0, 3.5, 1.5, 0, 0, -0.4))
    results = {}
    for n in ("1", "2"):
        monkeypatch.setenv("NBS_THREADS", n)
        rng, cloud, poses = np.random.default_rng(2), AccumulatedCloud(voxel_size=0.05), []
        for k, truth in enumerate(stops):
            scan = scanner.scan(truth, rng)
            prior = truth.copy()
            prior[:2, 3] += [0.04, -0.03]
            pose = register(scan.points, prior, cloud).pose if k else truth
            cloud.add(scan.to_world(pose), pose[:3, 3], pose=pose if k else None)
            poses.append(pose)
        copy = pickle.loads(pickle.dumps(cloud))._copy(None)  # waits for the last merge
        results[n] = (np.array(poses), copy._keys, copy._sums, cloud._copy(0)._sums)
    assert len(results["1"][1]) > 1000
    for got, want in zip(results["2"], results["1"], strict=True):
        assert np.array_equal(got, want)


def test_the_cast_waits_until_the_noise_draw_has_begun(monkeypatch):
    """open3d's cast holds the GIL and numpy's draw releases it: the scan starts the cast only once
    the draw beside it has begun, so the two overlap (else the draw would begin after the cast).
    The draw's thread is made to start late, as a busy machine may."""
    import time

    from nbs_env.sensing.pose import pose_from_xyz_rpy
    from nbs_env.sensing.scanner import Scanner
    from scenes import load_scene

    monkeypatch.setenv("NBS_THREADS", "2")
    scanner = Scanner(load_scene("l_room"), ScannerConfig(angular_step=1.0, range_noise=0.005))
    pose = pose_from_xyz_rpy(3.0, 4.5, 1.5)
    scanner.scan(pose, np.random.default_rng(0))  # the kernels loaded: the cast comes at once
    casts = []
    draw, beside = np.random.default_rng(5).standard_normal, threads.beside
    cast, cast_with_normals = scanner.cast, scanner._cast_with_normals

    class Watched:
        def standard_normal(self, *args, **kwargs):
            self.casts_before = len(casts)
            return draw(*args, **kwargs)

    def late(work):
        return beside(lambda: (time.sleep(0.05), work())[1])

    monkeypatch.setattr(threads, "beside", late)
    monkeypatch.setattr(scanner, "cast", lambda rays: (casts.append(1), cast(rays))[1])
    monkeypatch.setattr(scanner, "_cast_with_normals", lambda rays: (casts.append(1), cast_with_normals(rays))[1])
    rng = Watched()
    scanner.scan(pose, rng)
    # The pattern's cast, and the footprints' where beams straddle an edge: none before the draw began.
    assert casts and rng.casts_before == 0


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="fork is POSIX's")
def test_a_forked_child_starts_its_own_kernel_threads():
    """Probe 41: the pools' threads are not copied by ``fork``, and work handed to them in the child
    waited for ever (gymnasium's ``AsyncVectorEnv`` forked after an env had stepped hung at reset)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = (
        "import os, signal, sys\n"
        "from nbs_env import threads\n"
        "assert threads.split(lambda s: s.start, rows=4, cost=10**7) == [0, 1]\n"  # the pools exist
        "assert threads.beside(lambda: 5).result() == 5\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    signal.alarm(20)\n"  # a child that hangs ends itself, and fails the test
        "    ok = threads.split(lambda s: s.start, rows=4, cost=10**7) == [0, 1]\n"
        "    ok = ok and threads.beside(lambda: 5).result() == 5\n"
        "    os._exit(0 if ok else 3)\n"
        "_, status = os.waitpid(pid, 0)\n"
        "sys.exit(os.waitstatus_to_exitcode(status))\n"
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "NBS_THREADS": "2", "PYTHONPATH": str(root)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-500:])
