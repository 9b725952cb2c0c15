"""The critic of a run whose prices move (``TrainConfig.hold_coverage``): two value heads.

With ``hold_coverage`` the reward PPO learns from is ``2 (gain - w × cost) / (1 + w)``, and ``w``
moves after every rollout (:class:`train.ppo.CostWeight`). A critic with one head must learn a
new return each time ``w`` moves; in runs hold3 and hold4 its explained variance fell from about
0.5 to 0.1 as ``w`` rose past 3, and the advantages became noise. Here the critic predicts the
discounted gain ``V_g`` and the discounted price ``V_c`` apart, neither of which depends on
``w``, and the value of the reward is their combination at the rollout's weight (as PPO-Lagrangian
critics do: Ray, Achiam and Amodei (2019), "Benchmarking safe exploration in deep reinforcement
learning"; Stooke, Achiam and Abbeel (2020)):

    V = 2 (V_g - w V_c) / (1 + w)

GAE is linear in rewards and values, so the advantage of the combined reward computed from the
combined values (what stable-baselines3 computes) equals the combination of the heads' own
advantages: PPO's policy loss is unchanged. Only the value loss differs: each head is fitted to its
own GAE return (:class:`PricedRolloutBuffer` hands the train loop both, interleaved, and
:meth:`PricedValue.heads` the predictions in the same order).
"""

from __future__ import annotations

import numpy as np
import torch
from sb3_contrib.common.maskable.buffers import MaskableDictRolloutBuffer


class PricedValue(torch.nn.Module):
    """The value layer of a two-headed critic: ``latent_vf`` (B, D) → the combined value (B, 1).

    ``price_weight`` (a buffer, so that it travels with the weights to Ray's workers and into a
    saved state) is the rollout's ``w``."""

    def __init__(self, latent_dim: int) -> None:
        super().__init__()
        self.heads = torch.nn.Linear(latent_dim, 2)
        torch.nn.init.orthogonal_(self.heads.weight, gain=1.0)  # as stable-baselines3 sets its value layer
        torch.nn.init.zeros_(self.heads.bias)
        self.register_buffer("price_weight", torch.ones(()))

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        return combine(self.heads(latent), self.price_weight)


def combine(heads, weight):
    """``2 (V_g - w V_c) / (1 + w)`` of heads (..., 2) → (..., 1); torch tensors or numpy arrays."""
    return 2.0 / (1.0 + weight) * (heads[..., :1] - weight * heads[..., 1:])


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    starts: np.ndarray,
    last_values: np.ndarray,
    last_dones: np.ndarray,
    gamma: float,
    lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimates per head, as stable-baselines3's rollout buffer computes them.

    Parameters
    ----------
    rewards, values : (T, E, K) float
        Each head's reward (a truncated episode's last with ``gamma × V(terminal)`` added) and value.
    starts : (T, E) bool or float
        Whether the step began an episode (the buffer's ``episode_starts``).
    last_values : (E, K) float
        The values of the observations after the rollout's last step.
    last_dones : (E,) bool
        Whether the rollout's last step ended its episode.

    Returns
    -------
    advantages, returns : (T, E, K) float
    """
    advantages = np.zeros_like(values, dtype=np.float64)
    running = np.zeros_like(last_values, dtype=np.float64)
    for t in range(len(rewards) - 1, -1, -1):
        if t == len(rewards) - 1:
            going, following = 1.0 - np.asarray(last_dones, dtype=np.float64), last_values
        else:
            going, following = 1.0 - np.asarray(starts[t + 1], dtype=np.float64), values[t + 1]
        going = going[:, None]
        delta = rewards[t] + gamma * following * going - values[t]
        running = delta + gamma * lam * going * running
        advantages[t] = running
    return advantages, advantages + values


class PricedRolloutBuffer(MaskableDictRolloutBuffer):
    """MaskablePPO's rollout buffer with the two heads' rewards and GAE returns beside the combined ones.

    :class:`train.ppo` fills ``head_rewards`` at each step (before :meth:`add`, at ``pos``) and
    ``head_returns`` at the rollout's end; a minibatch's ``returns`` are then its samples' two
    returns, interleaved (gain, price, gain, price, ...), the order of ``heads(latent).flatten()``.
    The combined ``returns`` stay what stable-baselines3 computed (its explained variance)."""

    def reset(self) -> None:
        super().reset()
        self.head_rewards = np.zeros((self.buffer_size, self.n_envs, 2), dtype=np.float32)
        self.head_returns = np.zeros((self.buffer_size, self.n_envs, 2), dtype=np.float32)

    def get(self, batch_size: int | None = None):
        if not self.generator_ready:
            self.head_returns = self.swap_and_flatten(self.head_returns)
        yield from super().get(batch_size)

    def _get_samples(self, batch_inds: np.ndarray, env=None):
        samples = super()._get_samples(batch_inds, env)
        return samples._replace(returns=self.to_torch(self.head_returns[batch_inds].reshape(-1)))


def head_values(policy, obs: dict[str, np.ndarray], batch_size: int = 64) -> np.ndarray:
    """The two heads' values (N, 2) of ``obs`` (arrays of N observations, laid out as the policy takes them)."""
    n = len(next(iter(obs.values())))
    parts = []
    with torch.no_grad():
        for start in range(0, n, batch_size):
            tensors, _ = policy.obs_to_tensor({k: v[start : start + batch_size] for k, v in obs.items()})
            parts.append(policy.value_heads(tensors).cpu().numpy())
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.float32)


def explained_variance(predicted: np.ndarray, actual: np.ndarray) -> float | None:
    """1 - Var(actual - predicted) / Var(actual); None where ``actual`` does not vary."""
    spread = float(np.var(actual))
    return None if spread == 0 else 1.0 - float(np.var(actual - predicted)) / spread


def record_step(buffer: PricedRolloutBuffer, policy, infos: list[dict], dones: np.ndarray, gamma: float) -> None:
    """Each env's gain and price of the step about to be added at ``buffer.pos`` (from the env's
    ``reward_terms``); a truncated episode's last step bootstraps each head from its terminal
    observation, as stable-baselines3 bootstraps the combined reward (a Ray worker sends the
    heads' values as ``terminal_heads``, the observation staying with it)."""
    for i, info in enumerate(infos):
        terms = info.get("reward_terms") or {"gain": 0.0, "cost": 0.0}
        row = np.array([terms["gain"], terms["cost"]], dtype=np.float64)
        if dones[i] and info.get("TimeLimit.truncated", False):
            if info.get("terminal_heads") is not None:
                row += gamma * np.asarray(info["terminal_heads"], dtype=np.float64)
            elif info.get("terminal_observation") is not None:
                terminal = {k: np.asarray(v)[None] for k, v in info["terminal_observation"].items()}
                row += gamma * head_values(policy, terminal)[0]
        buffer.head_rewards[buffer.pos, i] = row


def finish_rollout(
    buffer: PricedRolloutBuffer,
    policy,
    last_obs: dict[str, np.ndarray],
    last_dones: np.ndarray,
    gamma: float,
    lam: float,
) -> dict[str, float | None]:
    """Each head's GAE return into ``buffer.head_returns``, once the rollout is full (before
    PPO's update reads it).

    Returns
    -------
    dict
        ``gain_explained_variance`` and ``cost_explained_variance``: how much of its return each
        head explained over the rollout (None where the return did not vary).
    """
    steps, envs = buffer.buffer_size, buffer.n_envs
    flat = {k: v.reshape(steps * envs, *v.shape[2:]) for k, v in buffer.observations.items()}
    values = head_values(policy, flat).reshape(steps, envs, 2)
    last = head_values(policy, {k: np.asarray(v) for k, v in last_obs.items()})
    _, returns = gae(buffer.head_rewards, values, buffer.episode_starts, last, last_dones, gamma, lam)
    buffer.head_returns = returns.astype(np.float32)
    return {
        f"{name}_explained_variance": explained_variance(values[..., k], returns[..., k])
        for k, name in enumerate(("gain", "cost"))
    }
