"""The two-headed critic of a run whose prices move (train.critic)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("sb3_contrib")

from train import critic


def test_gae_per_head_is_stable_baselines3_s_own():
    """Each head's advantages and returns are what stable-baselines3's buffer computes for one value."""
    import torch
    from gymnasium import spaces
    from stable_baselines3.common.buffers import RolloutBuffer

    rng = np.random.default_rng(3)
    steps, envs = 7, 3
    rewards, values = rng.normal(size=(steps, envs, 2)), rng.normal(size=(steps, envs, 2))
    starts = rng.random((steps, envs)) < 0.3
    last_values, last_dones = rng.normal(size=(envs, 2)), np.array([True, False, False])
    advantages, returns = critic.gae(rewards, values, starts, last_values, last_dones, gamma=0.9, lam=0.8)
    for k in range(2):
        space, choice = spaces.Box(-1, 1, (1,)), spaces.Discrete(2)
        buffer = RolloutBuffer(steps, space, choice, n_envs=envs, gamma=0.9, gae_lambda=0.8)
        for t in range(steps):
            buffer.add(
                np.zeros((envs, 1)), np.zeros((envs, 1)), rewards[t, :, k], starts[t],
                torch.as_tensor(values[t, :, k]), torch.zeros(envs),
            )  # fmt: skip
        buffer.compute_returns_and_advantage(torch.as_tensor(last_values[:, k]), last_dones)
        np.testing.assert_allclose(advantages[..., k], buffer.advantages, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(returns[..., k], buffer.returns, rtol=1e-5, atol=1e-5)


def test_a_minibatch_s_returns_are_its_samples_two_head_returns_in_order():
    """PPO's value loss compares ``heads(latent).flatten()`` (gain, price, gain, price, ...) with the
    minibatch's returns: they must be the same samples' two returns, in the same order."""
    import torch
    from gymnasium import spaces

    steps, envs = 4, 2
    space = spaces.Dict({"x": spaces.Box(0, 100, (1,))})
    buffer = critic.PricedRolloutBuffer(steps, space, spaces.Discrete(3), n_envs=envs)
    for t in range(steps):
        index = np.arange(envs, dtype=np.float32) + t * envs
        buffer.add(
            {"x": index[:, None]}, np.zeros((envs, 1)), np.zeros(envs), np.zeros(envs),
            torch.zeros(envs), torch.zeros(envs), action_masks=np.ones((envs, 3)),
        )  # fmt: skip
    index = np.arange(steps * envs, dtype=np.float32).reshape(steps, envs)
    buffer.head_returns = np.stack([index, -10 * index], axis=-1)
    seen = []
    for batch in buffer.get(3):
        x = batch.observations["x"].numpy().reshape(-1)
        pairs = batch.returns.numpy().reshape(-1, 2)
        np.testing.assert_array_equal(pairs, np.stack([x, -10 * x], axis=1))
        seen.extend(x.tolist())
    assert sorted(seen) == list(range(steps * envs))


def _spy_on_rollouts(monkeypatch) -> list[tuple]:
    """What each rollout's end sees: the weight, the heads' advantages combined at it, PPO's
    advantages, the heads' rewards and the explained variances."""
    seen = []
    real = critic.finish_rollout

    def spy(buffer, policy, last_obs, last_dones, gamma, lam):
        explained = real(buffer, policy, last_obs, last_dones, gamma, lam)
        steps, envs = buffer.buffer_size, buffer.n_envs
        flat = {k: v.reshape(steps * envs, *v.shape[2:]) for k, v in buffer.observations.items()}
        values = critic.head_values(policy, flat).reshape(steps, envs, 2)
        weight = float(policy.value_net.price_weight)
        combined = critic.combine(buffer.head_returns - values, weight)[..., 0]
        seen.append((weight, combined, buffer.advantages.copy(), buffer.head_rewards.copy(), explained))
        return explained

    monkeypatch.setattr(critic, "finish_rollout", spy)
    return seen


def _check_rollouts(seen: list[tuple], rollouts: int) -> None:
    assert len(seen) == rollouts
    for _, combined, advantages, head_rewards, explained in seen:
        np.testing.assert_allclose(combined, advantages, rtol=1e-4, atol=1e-4 * np.abs(advantages).max())
        assert (head_rewards[..., 0] > 0).any() and (head_rewards[..., 1] > 0).any()  # gains and prices apart
        assert set(explained) == {"gain_explained_variance", "cost_explained_variance"}
    weights = [w for w, *_ in seen]
    # Checked at a weight that moved, too (up or down: which way turns on the episodes each rollout
    # ends, and Ray's actors end them as their timing falls).
    assert weights[0] == 1.0 and max(abs(w - 1.0) for w in weights) > 0.01


def _config(**changes):
    from train.ppo import TrainConfig

    base = {
        "timesteps": 48, "envs": 2, "seed": 1, "rooms": (1, 1), "n_steps": 8, "batch_size": 8,
        "completion": "policy", "max_episode_steps": 3, "bc_steps": 12, "hold_coverage": 0.5,
    }  # fmt: skip
    return TrainConfig(**{**base, **changes})


def test_the_two_heads_advantages_combine_into_ppo_s(tmp_path, monkeypatch):
    """In a real run with moving prices, the heads' GAE advantages combined at the rollout's weight,
    2 (A_g - w A_c) / (1 + w), are the advantages PPO's update uses (stable-baselines3's, from the
    reweighed rewards and the combined values): episodes cut at 3 steps bootstrap each head, and two
    envs keep their own columns. A head fitted to a return of the wrong step, env or bootstrap fails."""
    import torch

    from train.ppo import train

    seen = _spy_on_rollouts(monkeypatch)
    out = tmp_path / "run"
    train(_config(), out, progress=False)
    _check_rollouts(seen, 3)
    # The saved state's critic combines at the weight the state records (what a resumed run goes on with).
    state = torch.load(out / "training_state.pt", weights_only=True)["policy"]
    recorded = json.loads((out / "training_state.json").read_text())["cost_weight"]
    assert float(state["value_net.price_weight"]) == pytest.approx(recorded) and recorded != 1.0


def test_the_two_heads_advantages_combine_on_ray_rollouts_too(tmp_path, monkeypatch):
    """The same on Ray's actors: their truncated episodes bootstrap each head from the terminal
    observation they keep (``terminal_heads``), and the learner reads their last observations."""
    pytest.importorskip("ray")
    from train.ppo import train

    seen = _spy_on_rollouts(monkeypatch)
    train(_config(), tmp_path / "ray", progress=False, backend="ray")
    _check_rollouts(seen, 3)


@pytest.mark.parametrize("split", [False, True])
def test_the_critic_reads_the_storey_vector_and_the_policy_does_not(split):
    """The scans and metres still to come turn on the doors the robot found: the critic reads the
    observation's storey vector, while the policy's logits (what a checkpoint runs) stay those of
    the voxels, the candidates and the room vector alone."""
    import torch

    from nbs_env import NBSEnv
    from train.ppo import _policy_class

    config = _config()
    env = NBSEnv(config.env_config(), scene="generated:3")
    obs, _ = env.reset(seed=0)
    policy = _policy_class()(
        env.observation_space, env.action_space, lambda _: 1e-3, network=config.network, split_critic=split
    )
    torch.manual_seed(0)
    with torch.no_grad():
        for p in policy.parameters():
            p.add_(0.1 * torch.randn_like(p))
    other = {**obs, "storey": obs["storey"] + np.array([5, 2, 7, 11], dtype=np.float32)}
    tensors, _ = policy.obs_to_tensor({k: np.stack([obs[k], other[k]]) for k in obs})
    with torch.no_grad():
        logits = policy.get_distribution(tensors).distribution.logits
        values = policy.value_heads(tensors) if split else policy.predict_values(tensors)
    torch.testing.assert_close(logits[0], logits[1])
    assert (values[0] - values[1]).abs().max() > 1e-4
