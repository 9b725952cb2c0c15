"""NBSEnv against Gymnasium's and stable-baselines3's contracts, over every registered id."""

from __future__ import annotations

import pickle
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import nbs_env
from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from nbs_env.errors import ConfigError, InvalidActionError, InvalidPoseError
from nbs_env.labels import VoxelLabel
from nbs_env.observation import (
    CandidateColumn,
    ObservationConfig,
    RoomColumn,
    StoreyColumn,
    candidate_table_of,
    pool_labels,
)
from policies import GreedyPolicy, RandomPolicy
from scenes.corpus import corpus_entry

ENV_IDS = sorted(nbs_env.ENV_IDS)
#: A small scene keeps the per-id tests fast; the registered scene is exercised elsewhere.
SMALL = {"scene": "l_room"}


def make(env_id: str, **kwargs) -> gym.Env:
    return gym.make(env_id, **{**SMALL, **kwargs})


def rollout(env: gym.Env, seed: int, steps: int, policy=None):
    policy = policy or RandomPolicy(seed)
    obs, info = env.reset(seed=seed)
    trace = [(obs, info["structure_sensed_pct"])]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        trace.append((obs, info["structure_sensed_pct"], reward, terminated, truncated))
        if terminated or truncated:
            break
    return trace


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    return a == b


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env_passes_without_warnings(env_id):
    from gymnasium.utils.env_checker import check_env

    env = make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=False)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env_passes_without_warnings(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = make(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_trajectory(env_id):
    a = rollout(make(env_id), seed=3, steps=3)
    b = rollout(make(env_id), seed=3, steps=3)
    assert len(a) > 1 and same(a, b)


def test_different_seeds_draw_different_generated_storeys():
    env = gym.make("nbs_env/NBS-Fast-v0")
    env.reset(seed=1)
    first = env.unwrapped.scene.name
    env.reset(seed=2)
    assert env.unwrapped.scene.name != first and first.startswith("generated:")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickled_env_continues_the_same_episode(env_id):
    env = make(env_id)
    policy = RandomPolicy(0)
    obs, info = env.reset(seed=5)
    obs, *_, info = env.step(policy.act(obs, info))
    copy = pickle.loads(pickle.dumps(env))
    action = policy.act(obs, info)
    assert same(env.step(action)[:4], copy.step(action)[:4])
    fresh = pickle.loads(pickle.dumps(make(env_id)))
    assert same(fresh.reset(seed=2)[0], make(env_id).reset(seed=2)[0])


def test_observation_matches_the_robot_belief():
    env = gym.make("nbs_env/NBS-Fast-v0", scene="l_room")
    obs, info = env.reset(seed=0)
    robot = env.unwrapped.storey.robot
    assert env.observation_space.contains(obs)
    planned = robot.plan()
    cands, gains = planned.candidates, planned.gains
    table = candidate_table_of(obs)
    assert int(table[:, CandidateColumn.VALID].sum()) == cands.count > 0
    np.testing.assert_allclose(
        table[: cands.count, [CandidateColumn.DX, CandidateColumn.DY]], cands.points - robot.pose[:2, 3], atol=1e-4
    )
    np.testing.assert_allclose(table[: cands.count, CandidateColumn.PATH_LENGTH], cands.path_length[: cands.count])
    assert np.array_equal(info["action_mask"], cands.mask) and np.array_equal(env.unwrapped.action_masks(), cands.mask)
    assert np.array_equal(info["candidate_gains"], gains)
    # The window is centred on the robot and starts 0.2 m under its floor: the cell under the
    # robot's feet is floor it cannot see (the scanner's blind zone), Occluded-structure, while the
    # floor 3 m away is sensed Structure and the air above it is Empty.
    voxels = obs["voxels"]
    cx, cy = voxels.shape[0] // 2, voxels.shape[1] // 2
    assert voxels[cx, cy, 0] == VoxelLabel.UNKNOWN
    assert voxels[cx, cy, 1] == VoxelLabel.OCCLUDED_STRUCTURE
    assert (voxels[:, :, 1] == VoxelLabel.STRUCTURE).sum() > 100
    assert (voxels[cx - 15 : cx + 15, cy - 15 : cy + 15, 5] == VoxelLabel.EMPTY).sum() > 100
    np.testing.assert_allclose(obs["pose"][:2], robot.pose[:2, 3], atol=1e-4)
    # The room vector is the robot's own grid and counts.
    labels = robot.belief.grid.labels
    sensed = np.count_nonzero(labels == VoxelLabel.STRUCTURE)
    structural = sensed + np.count_nonzero(labels == VoxelLabel.OCCLUDED_STRUCTURE)
    room = obs["room"]
    assert room[RoomColumn.SCANS_IN_ROOM] == robot.scans_in_room == 1 and room[RoomColumn.ROOMS_DONE] == 0
    assert room[RoomColumn.STRUCTURE_SENSED_SHARE] == pytest.approx(sensed / structural, rel=1e-6)
    assert 0.2 < room[RoomColumn.STRUCTURE_SENSED_SHARE] < 1.0
    assert room[RoomColumn.STRUCTURE_AREA] == pytest.approx(structural * robot.belief.grid.voxel_size**2, rel=1e-5)
    frontier = sum(face.length for face in robot.belief.frontier)
    assert room[RoomColumn.FRONTIER_LENGTH] == pytest.approx(frontier, rel=1e-5)
    obs, _, _, _, _ = env.step(int(np.flatnonzero(info["action_mask"])[0]))
    assert obs["room"][RoomColumn.SCANS_IN_ROOM] in (2, 1)  # 1 when that scan ended the room
    assert obs["room"][RoomColumn.STRUCTURE_SENSED_SHARE] > 0


@pytest.mark.parametrize("scene", ["generated:20000002", "l_room"])
def test_the_greedy_declaring_rooms_done_scans_as_the_gain_rule(scene):
    """With completion="policy" the greedy declares each room done where the robot's gain rule
    ends it (info["gain_rule_done"]): the same scans, coverage and path as with completion="gain",
    one "room done" step more per room; the rule is the robot's plan, not ground truth."""
    runs = {}
    for completion in ("gain", "policy"):
        env = NBSEnv("fast", scene=scene, completion=completion)
        obs, info = env.reset(seed=0)
        policy, steps, declared = GreedyPolicy(), 0, 0
        while True:
            if completion == "gain":
                assert not info["gain_rule_done"]  # the session ended such rooms itself
            action = policy.act(obs, info)
            declared += action == env.stop_action
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            if terminated or truncated:
                break
        positions = [tuple(np.round(s.estimated_position, 6)) for s in env.storey.scans]
        runs[completion] = (positions, info["structure_sensed_pct"], info["path_length_m"], steps, declared)
    (gain_pos, gain_pct, gain_path, gain_steps, _), (pos, pct, path, steps, declared) = runs["gain"], runs["policy"]
    assert pos == gain_pos and pct == gain_pct and path == gain_path
    reasons = [end["reason"] for end in env.storey.room_ends]
    assert declared == reasons.count("declared") >= 1 and steps == gain_steps + declared


def test_the_gain_rule_says_nothing_when_the_robot_predicts_no_gains():
    """Without predicted gains (the compared methods' envs) the rule has nothing to read: it never
    tells the greedy to end a room, and an info without the flag is refused rather than ignored."""
    config = make_config("fast", scene="l_room", completion="policy")
    config = replace(config, robot=replace(config.robot, predict_gains=False))
    env = NBSEnv(config)
    obs, info = env.reset(seed=0)
    assert not info["gain_rule_done"] and not env.gain_rule_done()
    assert np.all(info["candidate_gains"] == 0)
    with pytest.raises(KeyError, match="gain_rule_done"):
        GreedyPolicy().act(obs, {k: v for k, v in info.items() if k != "gain_rule_done"})


def test_pooling_keeps_the_highest_priority_label():
    labels = np.full((4, 4, 4), VoxelLabel.EMPTY, dtype=np.uint8)
    labels[0, 0, 0] = VoxelLabel.STRUCTURE
    labels[1, 1, 1] = VoxelLabel.CLUTTER
    labels[2, 2, 2] = VoxelLabel.OCCLUDED_STRUCTURE
    labels[3, 3, 3] = VoxelLabel.CLUTTER
    cell = np.array([0, 0, 1, 1])
    out = pool_labels(labels, (cell, cell, cell), (2, 2, 2))
    assert out[0, 0, 0] == VoxelLabel.STRUCTURE  # beats Clutter and Empty in the same cell
    assert out[1, 1, 1] == VoxelLabel.OCCLUDED_STRUCTURE  # beats Clutter
    assert out[0, 1, 0] == VoxelLabel.EMPTY
    # Voxels outside the window are dropped; cells with no voxel stay Unknown.
    out = pool_labels(labels, (cell + 1, cell, cell), (2, 2, 2))
    assert out[1, 0, 0] == VoxelLabel.STRUCTURE and (out[0] == VoxelLabel.UNKNOWN).all()


def _numpy_pool(labels, cell_of, shape):
    """pool_labels as numpy did it before the compiled pass (the oracle): ranks, then a maximum
    reduced along each axis over the runs of equal cells."""
    from nbs_env.observation import _LABEL_OF_RANK, _RANK

    out = np.zeros(tuple(shape), dtype=np.uint8)
    ranks = _RANK[labels]
    slices, targets = [], []
    for axis in range(3):
        c = np.asarray(cell_of[axis])
        inside = np.flatnonzero((c >= 0) & (c < shape[axis]))
        if not len(inside):
            return out
        lo, hi = int(inside[0]), int(inside[-1]) + 1
        sub = c[lo:hi]
        starts = np.flatnonzero(np.r_[True, sub[1:] != sub[:-1]])
        slices.append((lo, hi, starts))
        targets.append(sub[starts])
    block = ranks[slices[0][0] : slices[0][1], slices[1][0] : slices[1][1], slices[2][0] : slices[2][1]]
    for axis in range(3):
        block = np.maximum.reduceat(block, slices[axis][2], axis=axis)
    out[np.ix_(targets[0], targets[1], targets[2])] = _LABEL_OF_RANK[block]
    return out


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_pooling_is_the_numpy_pooling(seed):
    """Random labels, windows that cut the grid and windows wider than it, 1 to 5 voxels a cell."""
    rng = np.random.default_rng(seed)
    labels = rng.choice(6, size=(37, 29, 13), p=[0.3, 0.4, 0.1, 0.05, 0.1, 0.05]).astype(np.uint8)
    per = int(rng.integers(1, 6))
    shape = (int(rng.integers(3, 20)), int(rng.integers(3, 20)), int(rng.integers(2, 8)))
    cell_of = tuple(np.floor((np.arange(n) - int(rng.integers(-8, 8))) / per).astype(np.int64) for n in labels.shape)
    assert np.array_equal(pool_labels(labels, cell_of, shape), _numpy_pool(labels, cell_of, shape))


def test_masked_action_is_penalised_without_a_scan_and_bad_actions_raise():
    # On the lattice alone, 45 of the office's 64 slots are real NVPs at the start.
    env = gym.make("nbs_env/NBS-Fast-v0", scene="office", snap=False)
    obs, info = env.reset(seed=0)
    masked = int(np.flatnonzero(~info["action_mask"])[0])
    scans = info["scans"]
    obs2, reward, terminated, truncated, info2 = env.step(masked)
    assert info2["invalid_action"] and info2["scans"] == scans and reward == -1.0
    assert not terminated and not truncated and same(obs, obs2)
    for bad in (
        -1,
        64,
        2.5,
        "a",
        None,
        "3",
        1.0,
        np.array([3]),
        float("inf"),
        True,
        [0],
        np.float64(2.0),
        np.ma.masked_array(0, mask=True),
    ):
        with pytest.raises(InvalidActionError, match="action must be an integer"):
            env.step(bad)
    # What Discrete.contains takes is taken: numpy integers and 0-d integer arrays.
    for kind in (np.int64, lambda k: np.array(k, dtype=np.int32)):
        valid = kind(int(np.flatnonzero(env.unwrapped.action_masks())[0]))
        assert env.action_space.contains(valid) and not env.step(valid)[4]["invalid_action"]
    with pytest.raises(gym.error.ResetNeeded):
        NBSEnv("fast").step(0)


def test_reset_options_and_bad_input():
    env = NBSEnv("fast")
    env.reset(seed=0, options={"scene": "l_room"})
    assert env.scene.name == "l_room"
    start = np.add(env.scene.start[:2], (0.5, 0.0))
    env.reset(seed=0, options={"scene": "l_room", "start": tuple(start)})
    np.testing.assert_allclose(env.storey.robot.true_pose[:2, 3], start, atol=0.05)
    with pytest.raises(InvalidPoseError, match="not free floor"):
        env.reset(seed=0, options={"scene": "l_room", "start": (100.0, 100.0)})
    with pytest.raises(ConfigError, match="not known"):
        env.reset(options={"scen": "l_room"})
    with pytest.raises(ConfigError, match="unknown preset"):
        NBSEnv("fastest")
    with pytest.raises(ConfigError, match="no field"):
        make_config("fast", scenes="x")
    with pytest.raises(ConfigError, match="render_mode"):
        NBSEnv("fast", render_mode="human")
    from scenes import UnknownSceneError

    with pytest.raises(UnknownSceneError):
        env.reset(options={"scene": "no_such_scene"})


def test_conversions_reward_reads_no_ground_truth(monkeypatch):
    from nbs_env.config import RewardConfig

    env = NBSEnv("fast", scene="l_room", reward=RewardConfig(kind="conversions", scan_cost=0.0, metre_cost=0.0))
    obs, info = env.reset(seed=0)
    # Evaluation must not feed the reward: a meter that reports nothing leaves it unchanged.
    monkeypatch.setattr(env.storey.meter, "percent", lambda *a, **k: 0.0)
    obs, reward, *_, info = env.step(GreedyPolicy().act(obs, info))
    assert info["conversions"] > 0 and reward > 0


def test_render_shows_the_belief():
    env = gym.make("nbs_env/NBS-Fast-v0", scene="l_room", render_mode="rgb_array")
    _obs, _info = env.reset(seed=0)
    image = env.render()
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    # The labels' colours are drawn: Structure blue and some candidate colours, not a blank figure.
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50


def test_sync_vector_env_steps_with_masks():
    envs = gym.vector.SyncVectorEnv([lambda: gym.make("nbs_env/NBS-Fast-v0", scene="l_room") for _ in range(2)])
    obs, info = envs.reset(seed=[0, 1])
    assert obs["voxels"].shape == (2, 64, 64, 16)
    for _ in range(2):
        actions = [int(np.flatnonzero(m)[0]) for m in info["action_mask"]]
        obs, _reward, _terminated, _truncated, info = envs.step(np.array(actions))
        assert not info["invalid_action"].any()
    envs.close()


def test_sb3_subproc_vec_env_runs_with_action_masks():
    vec = pytest.importorskip("stable_baselines3.common.vec_env")

    def factory():
        # "module:id" makes a fresh worker process import nbs_env, which registers the ids.
        return gym.make("nbs_env:nbs_env/NBS-Fast-v0", scene="l_room")

    envs = vec.SubprocVecEnv([factory, factory], start_method="spawn")
    try:
        envs.seed(0)
        envs.reset()
        for _ in range(2):
            masks = np.stack(envs.env_method("action_masks"))
            assert masks.shape == (2, 64) and masks.any(axis=1).all()
            envs.step_async(np.array([int(np.flatnonzero(m)[0]) for m in masks]))
            obs, _rewards, _dones, infos = envs.step_wait()
            assert candidate_table_of(obs).shape == (2, 64, 5)
            assert not any(i["invalid_action"] for i in infos)
    finally:
        envs.close()


def test_observation_window_config():
    config = make_config("fast", scene="l_room", observation=ObservationConfig(shape=(32, 32, 8), cell=0.4))
    env = NBSEnv(config)
    obs, _ = env.reset(seed=0)
    assert obs["voxels"].shape == (32, 32, 8) and env.observation_space["voxels"].shape == (32, 32, 8)


@pytest.mark.expensive
def test_200_random_masked_episodes_on_generated_storeys_raise_nothing():
    env = gym.make("nbs_env/NBS-Fast-v0", max_episode_steps=6)
    policy = RandomPolicy(0)
    for episode in range(200):
        obs, info = env.reset(seed=episode)
        while True:
            action = policy.act(obs, info)
            assert info["action_mask"][action]
            obs, reward, terminated, truncated, info = env.step(action)
            assert not info["invalid_action"] and np.isfinite(reward)
            assert env.observation_space.contains(obs)
            if terminated or truncated:
                break


@pytest.mark.expensive
def test_greedy_scans_five_rooms_to_the_target():
    env = gym.make("nbs_env/NBS-FiveRooms-v0")
    trace = rollout(env, seed=0, steps=60, policy=GreedyPolicy())
    info_scans = env.unwrapped.storey.scans
    assert trace[-1][3]  # terminated: the robot judged the storey complete
    assert env.unwrapped.storey.rooms_done == 5
    meter = env.unwrapped.storey.meter
    assert all(meter.percent(room=r.id) > 85.0 for r in env.unwrapped.scene.rooms)
    assert len(info_scans) <= 22 and meter.percent() >= 90.0


FZK = str(corpus_entry("fzk_haus_eg").path())


def greedy_episode(env: NBSEnv, seed: int = 0):
    policy = GreedyPolicy()
    obs, info = env.reset(seed=seed)
    while True:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            return terminated, info


@pytest.mark.expensive
def test_greedy_completes_the_fzk_haus_ground_floor():
    pytest.importorskip("ifcopenshell")
    # The IFC's door leaves are closed by default (IfcDoor → DOOR faces); opened here, the robot
    # must find its way through the 3.5 m passage to the hall and the three doors off it.
    env = NBSEnv(
        "default", scene=FZK, scene_options={"storey": "Erdgeschoss", "class_map": {"IfcDoor": None}}, max_scans=60
    )
    terminated, info = greedy_episode(env)
    assert terminated
    rooms = {r.name: env.storey.meter.percent(room=r.id) for r in env.scene.rooms}
    assert all(pct > 90.0 for pct in rooms.values()), rooms
    assert info["structure_sensed_pct"] > 90.0


@pytest.mark.expensive
def test_greedy_completes_a_labelled_mesh_scene(tmp_path, plan_dict):
    import json

    from scenes import load_scene
    from scenes.importers import export_scene

    path = tmp_path / "two.json"
    path.write_text(json.dumps(plan_dict))
    mesh = tmp_path / "two.glb"
    export_scene(load_scene(str(path)), mesh)
    env = NBSEnv("default", scene=str(mesh))
    terminated, info = greedy_episode(env)
    assert env.scene.name.endswith("two.glb") and len(env.scene.rooms) == 2
    assert terminated and info["rooms_done"] == 2
    assert all(env.storey.meter.percent(room=r.id) > 85.0 for r in env.scene.rooms)


@pytest.mark.expensive
def test_rooms_behind_closed_doors_are_reported_unscanned(tmp_path, capsys):
    """FZK-Haus with its door leaves closed: three rooms cannot be reached; the scan ends, and the
    report says so (0 scans) instead of hanging."""
    pytest.importorskip("ifcopenshell")
    import json

    from train.cli import main

    out = tmp_path / "fzk"
    args = [
        "scan",
        "--scene",
        FZK,
        "--storey",
        "Erdgeschoss",
        "--ifc-doors",
        "closed",
        "--resolution",
        "1",
        "--voxel",
        "0.1",
    ]
    code = main([*args, "--out", str(out), "--no-steps", "--quiet", "--max-scans", "40"])
    assert code in (0, None)
    metrics = json.loads((out / "metrics.json").read_text())
    scans = {r["name"]: r["scans"] for r in metrics["rooms"]}
    assert scans["Schlafzimmer"] == scans["Bad"] == scans["Buero"] == 0
    assert scans["Wohnen"] > 0 and metrics["complete"] and metrics["scans"] < 40
    assert "Schlafzimmer" in capsys.readouterr().out


def test_the_gain_rule_reads_at_another_fraction_on_request():
    """gain_rule_done(F) asks the robot's rule at completion fraction F (a behaviour-cloning teacher
    that ends rooms sooner): the largest predicted gain against F of the room's structural voxels,
    so it says done at a fraction above that share and not at one below it; a fraction outside
    [0, 1) is refused."""
    env = NBSEnv("fast", scene="l_room", completion="policy")
    env.reset(seed=0)
    plan = env.storey.plan
    best = int(plan.gains[: plan.count].max()) / plan.structural_voxels
    assert 0.0 < best < 0.9
    assert env.gain_rule_done(min(0.99, 2 * best)) and not env.gain_rule_done(best / 2)
    assert env.gain_rule_done() == env.gain_rule_done(env.config.rooms.completion_fraction)
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="fraction"):
            env.gain_rule_done(bad)


def test_the_storey_vector_is_the_robots_own_door_memory():
    """obs["storey"] counts the scans of the episode and the doors the robot detected and has not
    crossed or given up, with straight-line distances to them from its pose estimate: the robot's
    door memory (KnownDoor estimates), never the scene's true doors."""
    env = gym.make("nbs_env/NBS-Fast-v0", scene="generated:3")
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert list(obs["storey"]) == [1, 0, 0, 0]  # the first scan, no door known yet
    storey = env.unwrapped.storey
    seen_doors, crossed = 0, False
    for _ in range(80):
        obs, _, terminated, truncated, info = env.step(int(np.flatnonzero(info["action_mask"])[0]))
        s = obs["storey"]
        rooms = storey.rooms
        waiting = [d for d in rooms.doors if rooms.door_open(d)]
        assert s[StoreyColumn.SCANS_TAKEN] == len(storey.scans) == info["scans"]
        assert s[StoreyColumn.DOORS_WAITING] == len(waiting)
        here = storey.robot.pose[:2, 3]
        distance = [float(np.linalg.norm(d.centre[:2] - here)) for d in waiting]
        assert s[StoreyColumn.NEAREST_DOOR] == pytest.approx(min(distance, default=0.0), rel=1e-5, abs=1e-5)
        assert s[StoreyColumn.DOOR_DISTANCE] == pytest.approx(sum(distance), rel=1e-5, abs=1e-5)
        crossed |= seen_doors > 0 and len(waiting) < seen_doors
        seen_doors = len(waiting)
        if terminated or truncated:
            break
    # The storey has several rooms: doors were found, and crossing one took it off the list.
    assert len(storey.rooms.doors) >= 2 and crossed


def test_a_registered_env_steps_after_a_refused_first_reset():
    """Probe 44: through gymnasium's passive checker (gymnasium 1.4), a first ``reset`` that raised
    (a seed of -1) left every later ``step`` raising a TypeError after its scan was taken."""
    import gymnasium

    from nbs_env.errors import ConfigError

    env = gymnasium.make("nbs_env/NBS-Fast-v0")
    with pytest.raises(ConfigError, match="seed must be None or an integer >= 0"):
        env.reset(seed=-1)
    env.reset(seed=1)
    action = int(np.flatnonzero(env.unwrapped.action_masks())[0])
    obs, reward, *_, info = env.step(action)
    assert env.observation_space.contains(obs) and np.isfinite(reward) and info["scans"] == 2
    env.close()
