"""Training at scale: the training fidelity, resumable runs and rollouts on Ray."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from nbs_env.errors import ConfigError
from policies import GreedyPolicy

ROOT = Path(__file__).resolve().parents[1]


def _episode(preset: str, seed: int = 4, steps: int = 6):
    env = NBSEnv(make_config(preset, **{"generator.rooms": (2, 2)}))
    obs, info = env.reset(seed=seed)
    policy = GreedyPolicy()
    out = [(obs, info, 0.0)]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        out.append((obs, info, reward))
        if terminated or truncated:
            break
    return env, out


def test_the_training_fidelity_sees_and_decides_as_the_fast_preset():
    """The training fidelity drops the ground-truth meter, not the method: on one storey its
    observations, masks, candidates' gains and path are the fast preset's, step for step, while the
    true coverage is not measured (None) and the reward is the robot's own mapped surface."""
    fast_env, fast = _episode("fast")
    train_env, train = _episode("train")
    assert len(fast) == len(train) > 2
    for (a, ia, _), (b, ib, _) in zip(fast, train, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
        np.testing.assert_array_equal(ia["candidate_gains"], ib["candidate_gains"])
        assert ia["path_length_m"] == ib["path_length_m"]
        assert ib["structure_sensed_pct"] is None and ia["structure_sensed_pct"] >= 0
    assert fast_env.storey.meter is not None and train_env.storey.meter is None
    # The robot-side reward is paid for new structure: positive where a step sensed some.
    assert sum(r for _, _, r in train[1:]) > 0
    assert train_env.storey.mapped_pct > 20.0


def test_the_mapped_reward_follows_the_true_coverage():
    """The robot's own mapped surface rises with the true one, step by step, on the same scale: a
    reward counting something else (all occupied voxels, the whole grid) would not."""
    env2 = NBSEnv(make_config("fast", **{"generator.rooms": (2, 2)}))
    obs, info = env2.reset(seed=7)
    policy = GreedyPolicy()
    coverage, mapped = [], []
    for _ in range(12):
        before = (env2.storey.coverage_pct(), env2.storey.mapped_pct)
        obs, _, terminated, truncated, info = env2.step(policy.act(obs, info))
        coverage.append(env2.storey.coverage_pct() - before[0])
        mapped.append(env2.storey.mapped_pct - before[1])
        if terminated or truncated:
            break
    coverage, mapped = np.array(coverage), np.array(mapped)
    assert len(coverage) >= 3
    assert np.corrcoef(coverage, mapped)[0, 1] > 0.6
    ratio = env2.storey.mapped_pct / env2.storey.coverage_pct()
    assert 0.5 < ratio < 2.0, ratio


def test_the_coverage_reward_needs_the_meter():
    with pytest.raises(ConfigError, match="coverage meter"):
        make_config("train", **{"reward.kind": "coverage"})
    with pytest.raises(ConfigError, match="coverage_meter must be a bool"):
        make_config("fast", coverage_meter=1)
    assert make_config("train").reward.kind == "mapped"


# ---------------------------------------------------------------------- resumable runs
def _tiny(**changes):
    from train.ppo import TrainConfig

    base = {
        "timesteps": 16, "envs": 1, "seed": 0, "rooms": (1, 1), "n_steps": 8, "batch_size": 8,
        "completion": "policy", "checkpoint_every": 8,
    }  # fmt: skip
    return TrainConfig(**{**base, **changes})


def _state(folder: Path):
    torch = pytest.importorskip("torch")
    return torch.load(folder / "training_state.pt", weights_only=True)


def test_a_resumed_run_continues_with_its_optimiser(tmp_path):
    """--resume loads the whole policy and Adam's moments and step counts: resumed with nothing left
    to do it writes back the very state it read; resumed further, Adam's step count goes on from the
    saved one (a fresh optimiser would start again from the update count of one rollout)."""
    pytest.importorskip("sb3_contrib")
    torch = pytest.importorskip("torch")
    from train.ppo import latest_state, load_model, resume_config, train

    out = tmp_path / "run"
    train(_tiny(), out, progress=False)
    saved = _state(out)
    steps_saved = max(int(s["step"]) for s in saved["optimizer"]["state"].values())
    assert steps_saved > 0
    assert latest_state(out)[1]["timesteps"] == 16

    train(resume_config(out), out, progress=False, resume=True)  # 16 of 16 done: nothing to do
    same = _state(out)
    for key, value in saved["policy"].items():
        torch.testing.assert_close(same["policy"][key], value)
    for k, s in saved["optimizer"]["state"].items():
        torch.testing.assert_close(same["optimizer"]["state"][k]["exp_avg"], s["exp_avg"])

    _, model = train(resume_config(out, timesteps=32), out, progress=False, resume=True)
    assert model.num_timesteps == 32
    later = _state(out)
    steps_later = max(int(s["step"]) for s in later["optimizer"]["state"].values())
    assert steps_later == 2 * steps_saved  # one more rollout, as many updates as the first
    assert json.loads((out / "training_state.json").read_text())["timesteps"] == 32
    # A user's own MaskablePPO from the run (docs/training.md): the same tensors, value head included.
    loaded = load_model(out)
    for key, value in loaded.policy.state_dict().items():
        torch.testing.assert_close(value.cpu(), later["policy"][key])


def test_the_room_done_head_steps_at_its_own_learning_rate(tmp_path):
    """stop_lr_scale: Adam's first step moves every parameter by its group's learning rate (the
    gradient of a plain sum is one everywhere): the "room done" head by ten times the rest, and the
    groups' ``lr`` stays the schedule's (stable-baselines3 sets it each update). A run trained with
    it saves both groups and resumes from them."""
    pytest.importorskip("sb3_contrib")
    pytest.importorskip("torch")
    from train.ppo import _env_factory, _policy_class, resume_config, train

    config = _tiny(stop_lr_scale=10.0)
    env = _env_factory(config)()
    policy = _policy_class()(
        env.observation_space, env.action_space, lambda _: 1e-3, network=config.network, stop_lr_scale=10.0
    )
    before = {name: p.detach().clone() for name, p in policy.named_parameters()}
    policy.optimizer.zero_grad()
    sum(p.sum() for p in policy.parameters()).backward()
    policy.optimizer.step()
    moved = {name: (p.detach() - before[name]).abs().max().item() for name, p in policy.named_parameters()}
    head = [name for name in moved if name.startswith("action_net.stop.")]
    assert head and all(abs(moved[name] - 1e-2) < 1e-4 for name in head)
    assert all(abs(moved[name] - 1e-3) < 1e-5 for name in moved if name not in head)
    assert [group["lr"] for group in policy.optimizer.param_groups] == [1e-3, 1e-3]
    with pytest.raises(ConfigError, match="completion='policy'"):
        _tiny(stop_lr_scale=10.0, completion="gain")

    out = tmp_path / "run"
    train(config, out, progress=False)
    groups = _state(out)["optimizer"]["param_groups"]
    assert [group.get("lr_scale", 1.0) for group in groups] == [1.0, 10.0]
    _, model = train(resume_config(out, timesteps=32), out, progress=False, resume=True)
    assert model.num_timesteps == 32 and model.policy.optimizer.param_groups[1]["lr_scale"] == 10.0


def test_a_resumed_run_extends_its_learning_curve(tmp_path):
    """The curve of a resumed run goes on from the state's timesteps: the clone's record once, at 0,
    and the greedy's and the teacher's figures the curve already holds, not evaluated again."""
    pytest.importorskip("sb3_contrib")
    from train.ppo import resume_config, train

    out = tmp_path / "run"
    small = {"eval_every": 8, "eval_storeys": 1, "bc_steps": 2, "max_episode_steps": 3}
    train(_tiny(timesteps=8, **small), out, progress=False)
    train(resume_config(out, timesteps=16), out, progress=False, resume=True)
    curve = [json.loads(line) for line in (out / "learning_curve.jsonl").read_text().splitlines()]
    assert [r["timesteps"] for r in curve] == [0, 8, 16]
    assert all(r["greedy"] == curve[0]["greedy"] for r in curve)
    # The teacher's figures on the same storeys, measured once, are the yardstick of every record.
    assert set(curve[0]["teacher"]) == {"scans", "structure_sensed_pct", "path_length_m"}
    assert all(r["teacher"] == curve[0]["teacher"] for r in curve)


def test_a_modified_state_is_refused(tmp_path):
    pytest.importorskip("sb3_contrib")
    from nbs_env.errors import ModelFileError
    from train.ppo import latest_state, train

    out = tmp_path / "run"
    train(_tiny(timesteps=8), out, progress=False)
    with (out / "training_state.pt").open("ab") as f:
        f.write(b"\0")
    with pytest.raises(ModelFileError, match="checksum"):
        train(_tiny(timesteps=16), out, progress=False, resume=True)
    with pytest.raises(ModelFileError, match="no resumable state"):
        latest_state(tmp_path)


def test_a_full_disk_during_training_keeps_the_last_state_and_resume_goes_on(tmp_path, monkeypatch, capsys):
    """torch.save on a full disk raises its own RuntimeError halfway through a file: ``nbs train`` says
    which file in one line and exits 1, the run's last state stays whole (no weights without their
    description, no temporary file), and ``--resume`` continues from it once there is room."""
    pytest.importorskip("sb3_contrib")
    torch = pytest.importorskip("torch")
    import nbs_env.atomic
    from train.ppo import latest_state, main, train

    out = tmp_path / "run"
    train(_tiny(timesteps=8), out, progress=False)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and "tb" not in p.parts}
    save = torch.save

    def full(obj, f, *args, **kwargs):
        Path(f).write_bytes(b"PK\x03\x04 half a zip")
        raise RuntimeError("[enforce fail at inline_container.cc:672] . PytorchStreamWriter failed writing file")

    nearly_full = nbs_env.atomic._nearly_full
    monkeypatch.setattr(torch, "save", full)
    # The disk is full by the time of the save (train.ppo.check_disk found room at the start).
    monkeypatch.setattr(nbs_env.atomic, "_nearly_full", lambda folder: True)
    code = main(["--resume", str(out), "--timesteps", "16", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.startswith(f"nbs train: error: {out}") and "No space left on device (RuntimeError)" in err, err
    assert f"--resume {out}" in err and len(err.strip().splitlines()) == 1, err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and "tb" not in p.parts}
    changed = sorted(str(k) for k in after if after[k] != before.get(k))
    # Only the learning-curve and progress files a resumed run rewrites whole may differ; no state did.
    assert not [c for c in changed if c.endswith((".pt", "policy.json", "training_state.json"))], changed
    assert not [p for p in out.rglob(".*.tmp*")], "a temporary file was left"
    monkeypatch.setattr(torch, "save", save)
    monkeypatch.setattr(nbs_env.atomic, "_nearly_full", nearly_full)
    assert latest_state(out)[1]["timesteps"] == 8
    assert main(["--resume", str(out), "--timesteps", "16", "--quiet"]) == 0
    assert latest_state(out)[1]["timesteps"] == 16


def _cli(*args: str, **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "train.ppo", *args], cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True, **kwargs
    )


def test_the_cli_refuses_to_resume_nothing_and_to_overwrite_a_run(tmp_path):
    pytest.importorskip("sb3_contrib")
    from train.ppo import train

    p = _cli("--resume", str(tmp_path / "none"), "--quiet")
    _, err = p.communicate(timeout=120)
    assert p.returncode == 2 and "no such run folder" in err and "Traceback" not in err
    out = tmp_path / "run"
    train(_tiny(timesteps=8), out, progress=False)
    p = _cli("--out", str(out), "--timesteps", "8", "--quiet")
    _, err = p.communicate(timeout=120)
    assert p.returncode == 2 and "--resume" in err and "Traceback" not in err


def test_a_signal_during_behaviour_cloning_ends_the_clone_at_once():
    """The stop request is read before every cloning step: a clone asked to stop after three steps
    returns None (nothing saved), one never asked runs all its steps."""
    pytest.importorskip("sb3_contrib")
    from sb3_contrib import MaskablePPO

    from train.ppo import TrainConfig, _policy_class, _teacher, behaviour_clone, make_training_envs

    class Stop:
        def __init__(self, after: int | None) -> None:
            self.after, self.reads = after, 0

        @property
        def signal(self) -> int | None:
            self.reads += 1
            return signal.SIGTERM if self.after is not None and self.reads > self.after else None

    config = TrainConfig(envs=1, seed=0, rooms=(1, 2), completion="policy")
    venv = make_training_envs(config)
    model = MaskablePPO(_policy_class(), venv, n_steps=32, batch_size=32, policy_kwargs={"network": config.network})
    try:
        stopped = Stop(3)
        assert behaviour_clone(model, 6, epochs=1, teacher=_teacher("greedy"), stop=stopped) is None
        assert stopped.reads == 4
        kept = Stop(None)
        warm = behaviour_clone(model, 6, epochs=1, teacher=_teacher("greedy"), stop=kept)
        assert warm is not None and warm["samples"] == 6 and kept.reads == 6
    finally:
        venv.close()


@pytest.mark.expensive
def test_a_signal_stops_a_run_with_its_state_saved(tmp_path):
    """SIGTERM mid-run: the run stops at its next step, saves its state and exits 143 (128 + SIGTERM,
    as nbs scan and nbs compare do) with the command that continues it; --resume then finishes it."""
    pytest.importorskip("sb3_contrib")
    out = tmp_path / "run"
    p = _cli(
        "--out", str(out), "--timesteps", "4000", "--envs", "2", "--n-steps", "8", "--rooms", "1-1",
        "--completion", "policy", "--checkpoint-every", "16", "--quiet", start_new_session=True,
    )  # fmt: skip
    deadline = time.time() + 300
    while not (out / "checkpoint_16" / "training_state.json").is_file():
        assert p.poll() is None and time.time() < deadline, p.stderr.read() if p.poll() is not None else "timeout"
        time.sleep(0.5)
    # To the whole process group, as `timeout`, a batch system or a container's stop sends it: the
    # rollout workers ignore it and the learner saves the run (workers that died of it once left the
    # learner a broken pipe).
    os.killpg(p.pid, signal.SIGTERM)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 143, err
    assert "--resume" in err and "Traceback" not in err
    done = json.loads((out / "training_state.json").read_text())["timesteps"]
    assert 8 <= done < 4000
    p = _cli("--resume", str(out), "--timesteps", str(done + 16), "--quiet")  # one rollout of 2 × 8
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert json.loads((out / "training_state.json").read_text())["timesteps"] == done + 16


def test_a_second_signal_mid_rollout_keeps_the_last_update(tmp_path, monkeypatch):
    """A second Ctrl-C does not wait for the rollout's end, yet the run keeps what it learned: the
    weights and Adam's state are the last update's until the rollout ends, so they are saved with
    that update's count of steps (the rollout under way is collected again by --resume)."""
    pytest.importorskip("sb3_contrib")
    from stable_baselines3.common.vec_env import DummyVecEnv

    from train.ppo import latest_state, train

    original, calls = DummyVecEnv.step_wait, []

    def step_wait(self):
        calls.append(1)
        if len(calls) == 8 + 3:  # 3 steps into the second rollout of 8
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(DummyVecEnv, "step_wait", step_wait)
    with pytest.raises(KeyboardInterrupt):
        train(_tiny(n_steps=8, timesteps=64, checkpoint_every=0, eval_every=0), tmp_path / "run")
    folder, state = latest_state(tmp_path / "run")
    assert folder == tmp_path / "run" and state["timesteps"] == 8


@pytest.mark.parametrize("steps", [-5, True, 10**13, 1.5])
def test_a_saved_state_with_an_impossible_step_count_is_refused(tmp_path, steps):
    from nbs_env.errors import ModelFileError
    from train.ppo import STATE_FORMAT, STATE_JSON, latest_state

    (tmp_path / STATE_JSON).write_text(
        json.dumps({"format": STATE_FORMAT, "version": 1, "timesteps": steps, "run": {}, "tensors": "x.pt"})
    )
    with pytest.raises(ModelFileError, match="timesteps"):
        latest_state(tmp_path)


# ---------------------------------------------------------------------- Ray
@pytest.mark.expensive
def test_rollouts_on_a_local_ray_instance(tmp_path):
    """--backend ray: two actors each play their segment with the learner's weights; the learner's
    own policy gives the same log-probabilities and values of their choices on the same
    observations (the layout, masks and weights are the learner's), and a run trains and saves."""
    pytest.importorskip("sb3_contrib")
    pytest.importorskip("ray")
    torch = pytest.importorskip("torch")
    from train.ppo import build_model, ray_rollouts, train

    config = _tiny(envs=2, n_steps=4)
    venv = ray_rollouts(config, seed=5)
    try:
        model = build_model(config, venv)
        venv.attach(model)
        weights = {k: v.detach().cpu() for k, v in model.policy.state_dict().items()}
        segments = venv.collect(weights, 4, model.gamma, model.observation_space)
        assert len(segments) == 2
        for seg in segments:
            obs, _ = model.policy.obs_to_tensor(seg["obs"])
            actions = torch.as_tensor(np.array(seg["actions"]))
            assert seg["masks"][np.arange(4), seg["actions"]].all()
            with torch.no_grad():
                values, log_prob, _ = model.policy.evaluate_actions(obs, actions, action_masks=seg["masks"])
            np.testing.assert_allclose(log_prob.numpy(), seg["log_probs"], atol=1e-4)
            np.testing.assert_allclose(values.numpy().ravel(), seg["values"], atol=1e-4)
    finally:
        venv.close()
    path, model = train(_tiny(envs=2, n_steps=4, timesteps=16, checkpoint_every=0), tmp_path / "ray", backend="ray")
    assert model.num_timesteps == 16
    assert json.loads(path.read_text())["training"]["backend"] == "ray"


def test_commands_that_report_coverage_refuse_the_training_fidelity(tmp_path):
    """nbs scan and nbs compare report the true coverage, which the training fidelity does not
    measure: they refuse --preset train with a message that names the preset to use instead."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for args in (
        ["scan", "--scene", "l_room", "--preset", "train", "--out", str(tmp_path / "s")],
        ["compare", "--scenes", "l_room", "--policies", "greedy", "--preset", "train", "--out", str(tmp_path / "c")],
    ):
        command = [sys.executable, "-m", "train.cli", *args]
        p = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
        assert p.returncode == 2, p.stderr
        assert "--preset fast" in p.stderr and "Traceback" not in p.stderr
        assert not (tmp_path / "s").exists() and not (tmp_path / "c").exists()


# ---------------------------------------------------------------------- a coverage constraint
def test_the_reward_is_its_two_terms():
    """info["reward_terms"] splits each step's reward into the gain and what the prices took, so that
    a learner may weigh them; a masked action's cost is the penalty."""
    env = NBSEnv(make_config("train", **{"generator.rooms": (2, 2), "reward.scan_cost": 0.7}))
    obs, info = env.reset(seed=3)
    obs, reward, *_, info = env.step(GreedyPolicy().act(obs, info))
    terms = info["reward_terms"]
    assert terms["gain"] > 0 and terms["cost"] >= 0.7  # one scan at least, and the drive to it
    assert reward == pytest.approx(terms["gain"] - terms["cost"])
    assert info["mapped_pct"] == env.storey.mapped_pct > terms["gain"]  # the first scan's share too
    masked = int(np.flatnonzero(~info["action_mask"])[0])
    _, reward, *_, info = env.step(masked)
    assert info["reward_terms"] == {"gain": 0.0, "cost": env.config.reward.invalid_action_penalty} and reward < 0


def test_the_cost_weight_holds_the_teachers_coverage():
    """CostWeight reweighs the rewards as 2 (gain - weight x cost) / (1 + weight) (the env's reward at
    weight 1, bounded by twice the gain or the cost at any weight), counts each env's episode, and moves
    the weight up while the episodes map more than the teacher, down while they map less, by a
    bounded step."""
    from train.ppo import CostWeight

    dual = CostWeight(rate=0.1, target=50.0)
    rewards = np.array([3.0, 1.0], dtype=np.float32)
    infos = [
        {"reward_terms": {"gain": 4.0, "cost": 1.0}, "mapped_pct": 30.0},
        {"reward_terms": {"gain": 1.5, "cost": 0.5}, "mapped_pct": 1.5},
    ]
    dual.weight = 2.0
    dual.reweigh(rewards, infos, np.array([False, True]))
    np.testing.assert_allclose(rewards, [2 * (4.0 - 2.0) / 3, 2 * (1.5 - 1.0) / 3])
    same = np.array([3.0], dtype=np.float32)
    CostWeight(rate=0.1, target=50.0).reweigh(same, infos[:1], np.array([False]))
    assert same[0] == 3.0  # weight 1: the env's own reward, the one the critic was fitted to
    heavy = CostWeight(rate=0.1, target=50.0, weight=CostWeight.HIGH)
    heavy.reweigh(big := np.array([3.0], dtype=np.float32), infos[:1], np.array([False]))
    assert -2.0 <= big[0] < 0  # the price dominates, at twice the cost at most
    assert dual.finished == [1.5]  # env 1's episode ended, env 0's goes on
    dual.weight = 1.0
    dual.update()
    assert dual.weight == pytest.approx(np.exp(-0.25))  # far below the target: the largest step down
    dual.finished = [51.0, 53.0]
    before = dual.weight
    dual.update()
    assert dual.weight == pytest.approx(before * np.exp(0.1 * 2.0)) and dual.last_mean == 52.0
    dual.update()  # no episode finished: no information, no change
    assert dual.weight == pytest.approx(before * np.exp(0.2))


def test_hold_coverage_needs_a_teacher_and_a_run_keeps_its_weight(tmp_path):
    """The constraint holds the behaviour-cloning teacher's coverage: refused without cloning; a run
    with it records the weight in its state and its curve, and a resumed run starts from that weight."""
    pytest.importorskip("sb3_contrib")
    from train.ppo import latest_state, resume_config, train

    with pytest.raises(ConfigError, match="bc_steps"):
        _tiny(hold_coverage=0.1)
    with pytest.raises(ConfigError, match="hold_coverage"):
        _tiny(hold_coverage=2.0, bc_steps=8)
    out = tmp_path / "run"
    train(_tiny(hold_coverage=0.5, bc_steps=24, eval_every=16, eval_storeys=1), out, progress=False)
    teacher = json.loads((out / "behaviour_cloning.json").read_text())
    assert teacher["episodes"] >= 1 and teacher["mapped"] > 0
    weight = latest_state(out)[1]["cost_weight"]
    assert weight != 1.0  # a rollout of one-room storeys never maps exactly the teacher's mean
    curve = [json.loads(line) for line in (out / "learning_curve.jsonl").read_text().splitlines()]
    # The curve records the weight at each evaluation (mid-rollout here: the last update's weight).
    assert curve[-1]["cost_weight"] != 1.0 and curve[-1]["mapped"] > 0
    _, model = train(resume_config(out, timesteps=24), out, progress=False, resume=True)
    assert model.num_timesteps == 24 and latest_state(out)[1]["cost_weight"] != weight  # moved on from it
    document = json.loads((out / "training_state.json").read_text())
    document["cost_weight"] = float("nan")
    (out / "training_state.json").write_text(json.dumps(document))
    from policies.learned import ModelFileError

    with pytest.raises(ModelFileError, match="cost_weight"):
        latest_state(out)


def test_discounted_returns_end_at_each_episode_s_end_and_mark_cut_ones():
    from train.ppo import discounted_returns

    rewards = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0]])
    ends = np.array([[False, False], [True, False], [False, False]])
    returns, complete = discounted_returns(rewards, ends, gamma=0.5)
    # env 0: 1 + 0.5 * 2 (its episode ends at step 1), then a new one cut at the rollout's end: 3
    # env 1: never ends: 10 + 0.5 * (20 + 0.5 * 30), cut short
    assert returns.tolist() == [2.0, 27.5, 2.0, 35.0, 3.0, 30.0]
    assert complete.tolist() == [True, False, True, False, False, False]


def _first_choices(split_critic: bool = False):
    """A MaskablePPO with the run's network, and 30 observations of one env taking its first valid
    candidate each step."""
    from sb3_contrib import MaskablePPO
    from sb3_contrib.common.maskable.utils import get_action_masks

    from train.ppo import TrainConfig, _policy_class, make_training_envs

    config = TrainConfig(envs=1, seed=0, rooms=(1, 2), completion="policy")
    venv = make_training_envs(config)
    model = MaskablePPO(
        _policy_class(), venv, n_steps=32, batch_size=32, seed=0,
        policy_kwargs={"network": config.network, "split_critic": split_critic},
    )  # fmt: skip
    try:
        obs, samples = venv.reset(), []
        for _ in range(30):
            samples.append({k: v.copy() for k, v in obs.items()})
            obs, *_ = venv.step(np.array([int(np.flatnonzero(get_action_masks(venv)[0])[0])]))
    finally:
        venv.close()
    return model, {k: np.concatenate([s[k] for s in samples]) for k in samples[0]}


def test_the_critic_learns_the_teacher_s_returns_and_the_clone_stays_as_it_was():
    """Run hold1's critic explained none of the return over 41 updates: after cloning, the value
    branch is fitted to the teacher's returns, and the policy (shared encoder, scorer) is not touched."""
    pytest.importorskip("sb3_contrib")
    import torch

    from train.ppo import fit_value

    model, all_obs = _first_choices()
    rewards, ends = np.ones((30, 1)), (np.arange(30) % 10 == 9)[:, None]  # episodes of 10 steps
    policy = model.policy
    kept = {k: v.clone() for k, v in policy.state_dict().items() if not k.startswith(("value_net", "mlp_extractor"))}

    target = (1 - model.gamma ** (10 - np.arange(30) % 10)) / (1 - model.gamma)  # 10 steps to the end, 9, ...

    def error() -> float:
        with torch.no_grad():
            values = policy.predict_values(policy.obs_to_tensor(all_obs)[0]).flatten().numpy()
        return float(((values - target) ** 2).mean())

    before = error()
    fitted = fit_value(model, all_obs, rewards, ends)
    assert fitted["value_samples"] == 30 and fitted["value_explained_variance"] is not None
    # Better than the best constant (the mean return): the critic reads the observations.
    assert error() < 0.8 * target.var() < 0.2 * before
    assert all(torch.equal(v, policy.state_dict()[k]) for k, v in kept.items())


def test_a_split_critic_is_fitted_to_the_teacher_s_gain_and_price_apart():
    """After cloning, each head learns its own discounted term; the policy is not touched."""
    pytest.importorskip("sb3_contrib")
    import torch

    from train.ppo import fit_value

    model, all_obs = _first_choices(split_critic=True)
    to_go = 10 - np.arange(30) % 10  # episodes of 10 steps
    rewards = np.stack([np.full(30, 3.0), 0.5 + 0.1 * (to_go == 1)], axis=1)[:, None, :]  # a dearer last step
    ends = (to_go == 1)[:, None]
    policy = model.policy
    kept = {k: v.clone() for k, v in policy.state_dict().items() if not k.startswith(("value_net", "mlp_extractor"))}
    fitted = fit_value(model, all_obs, rewards, ends)
    assert fitted["value_samples"] == 30 and fitted["value_explained_variance"] is not None
    gamma = model.gamma
    gain = 3.0 * (1 - gamma**to_go) / (1 - gamma)
    price = 0.5 * (1 - gamma**to_go) / (1 - gamma) + 0.1 * gamma ** (to_go - 1)
    with torch.no_grad():
        heads = policy.value_heads(policy.obs_to_tensor(all_obs)[0]).numpy()
    # Each head nearer its own return than the other's, and than the best constant.
    assert ((heads[:, 0] - gain) ** 2).mean() < 0.8 * gain.var()
    assert ((heads[:, 1] - price) ** 2).mean() < 0.8 * price.var()
    assert ((heads[:, 1] - gain) ** 2).mean() > 10 * ((heads[:, 1] - price) ** 2).mean()
    assert all(torch.equal(v, policy.state_dict()[k]) for k, v in kept.items())
