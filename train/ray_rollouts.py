"""Rollouts on Ray: ``nbs train --backend ray`` (on a local instance, or ``--address`` a cluster).

A local ``SubprocVecEnv`` steps its envs in lockstep: every step of a rollout waits for the slowest
env of the batch (a step that ends a room costs three times one inside it). Here each env lives in
a Ray actor with a copy of the policy: the learner sends the weights once per rollout, each actor
plays its ``n_steps`` on its own, choosing with the same network, values and log-probabilities as
the learner would (a timeout bootstrapped with its value, as stable-baselines3 does), and sends the
segment back. The learner fills MaskablePPO's rollout buffer from the segments and updates as
usual: the algorithm is PPO's, only where the steps are taken changes. Workers wait for one another
once a rollout, not once a step.

The same object is a ``VecEnv`` whose ``step`` runs in lockstep on the actors, for what needs
one (behaviour cloning, ``env_method``).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from sb3_contrib import MaskablePPO
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from nbs_env.errors import ConfigError

__all__ = ["RayMaskablePPO", "RayRollouts"]


def _require_ray():
    try:
        import ray
    except ImportError:
        raise ConfigError('--backend ray needs Ray: pip install "nbs-env[cluster]"') from None
    return ray


class _Worker:
    """One env and a copy of the policy, in a Ray actor."""

    def __init__(self, make_env, make_policy, seed: int, threads: int) -> None:
        # The worker's share of the machine, read by nbs_env.threads and torch when they start.
        os.environ["NBS_THREADS"] = str(threads)
        import torch

        torch.set_num_threads(threads)
        self.env = make_env()
        self.make_policy = make_policy
        self.obs, _ = self.env.reset(seed=seed)
        self.episode_start = True
        self.policy = None

    def spaces(self):
        return self.env.observation_space, self.env.action_space

    def reset(self):
        self.obs, _ = self.env.reset()
        self.episode_start = True
        return self.obs

    def step(self, action: int):
        """One step with stable-baselines3's conventions: auto-reset, the terminal observation in info."""
        obs, reward, terminated, truncated, info = self.env.step(int(action))
        done = terminated or truncated
        info = dict(info)
        info["TimeLimit.truncated"] = truncated and not terminated
        if done:
            info["terminal_observation"] = obs
            obs, _ = self.env.reset()
        self.obs, self.episode_start = obs, done
        return obs, float(reward), done, _portable(info)

    def env_method(self, name: str, args: tuple, kwargs: dict):
        return getattr(self.env.unwrapped, name)(*args, **kwargs)

    def get_attr(self, name: str):
        return getattr(self.env.unwrapped, name)

    def collect(self, weights: dict, n_steps: int, gamma: float, space) -> dict[str, Any]:
        """``n_steps`` steps with the learner's ``weights``: what MaskablePPO's rollout buffer takes.

        ``space``: the learner's observation space. stable-baselines3 puts image-like arrays channel
        first (``VecTransposeImage``); the observations are laid out as the learner's are."""
        import torch

        if self.policy is None:
            self.policy = self.make_policy(space, self.env.action_space)
            self.transposed = [k for k in space.spaces if space[k].shape != self.env.observation_space[k].shape]

        def laid_out(obs: dict) -> dict:
            return {k: np.transpose(v, (2, 0, 1)) if k in self.transposed else v for k, v in obs.items()}

        self.policy.load_state_dict(weights)
        self.policy.set_training_mode(False)
        keys = list(self.obs)
        out: dict[str, Any] = {
            "obs": {k: [] for k in keys},
            "actions": [],
            "rewards": [],
            "starts": [],
            "values": [],
            "log_probs": [],
            "masks": [],
            "dones": [],
            "infos": [],
        }
        for _ in range(n_steps):
            mask = self.env.unwrapped.action_masks()
            obs = laid_out(self.obs)
            with torch.no_grad():
                tensor, _ = self.policy.obs_to_tensor(obs)
                action, value, log_prob = self.policy(tensor, action_masks=mask[None])
            a = int(action.cpu().numpy()[0])
            for k in keys:
                out["obs"][k].append(obs[k])
            out["starts"].append(self.episode_start)
            out["masks"].append(mask)
            _, reward, done, info = self.step(a)
            if done and info["TimeLimit.truncated"]:
                with torch.no_grad():
                    terminal, _ = self.policy.obs_to_tensor(laid_out(info["terminal_observation"]))
                    reward += gamma * float(self.policy.predict_values(terminal)[0, 0])
                    if getattr(self.policy, "split_critic", False):  # train.critic bootstraps each head
                        info["terminal_heads"] = self.policy.value_heads(terminal)[0].tolist()
            info.pop("terminal_observation", None)
            out["actions"].append(a)
            out["rewards"].append(reward)
            out["values"].append(float(value[0, 0]))
            out["log_probs"].append(float(log_prob[0]))
            out["dones"].append(done)
            out["infos"].append(info)
        with torch.no_grad():
            tensor, _ = self.policy.obs_to_tensor(laid_out(self.obs))
            out["last_value"] = float(self.policy.predict_values(tensor)[0, 0])
        out["last_obs"] = laid_out(self.obs)
        out["last_done"] = self.episode_start
        out["obs"] = {k: np.stack(v) for k, v in out["obs"].items()}
        for k in ("actions", "rewards", "starts", "values", "log_probs", "masks", "dones"):
            out[k] = np.asarray(out[k])
        return out


def _portable(info: dict) -> dict:
    """What of a step's info travels back to the learner: numbers, arrays and the episode's figures
    (the belief view and stage timings stay in the actor)."""
    keep = {}
    for key, value in info.items():
        if key in ("belief", "times", "door_events"):
            continue
        keep[key] = value
    return keep


class RayRollouts(VecEnv):
    """``n_envs`` envs in Ray actors: a ``VecEnv`` for lockstep steps, and :meth:`collect` for
    rollouts the actors play on their own. The learner (:func:`train.ppo.ray_rollouts`) says what
    an actor builds, so that this module needs nothing of it.

    Parameters
    ----------
    make_env : callable
        ``make_env()`` builds one env (cloudpickled to each actor).
    make_policy : callable
        ``make_policy(observation_space, action_space)`` builds the learner's policy, whose weights
        :meth:`collect` loads.
    n_envs : int
        Actors, one env each.
    address : str, optional
        The cluster to join (``host:port``, checked to answer first; ``"auto"``; ``"local"``); None joins
        the cluster ``RAY_ADDRESS`` names or ``ray start`` runs on this machine, else starts a local
        instance with one CPU per env (:func:`train.ray_connect.connect_ray`).
    seed : int
        Actor ``i``'s env is seeded with ``seed + i``.

    Raises
    ------
    ConfigError
        Ray is missing, or no cluster answers at the address (:class:`train.ray_connect.RayConnectionError`).
    """

    def __init__(self, make_env, make_policy, n_envs: int, address: str | None = None, seed: int = 0) -> None:
        from train.ray_connect import connect_ray

        ray = _require_ray()
        self._ray = ray
        self._started = False
        local = not address
        if not ray.is_initialized():
            local = connect_ray(address, num_cpus=n_envs).local
            self._started = True
        cores = int(ray.cluster_resources().get("CPU", n_envs))
        # On an instance of its own the actors share this machine's cores; on a cluster each gets one.
        threads = max(1, cores // n_envs) if local else 1
        actor = ray.remote(num_cpus=1)(_Worker)
        self.workers = [actor.remote(make_env, make_policy, seed + i, threads) for i in range(n_envs)]
        observation_space, action_space = ray.get(self.workers[0].spaces.remote())
        super().__init__(n_envs, observation_space, action_space)
        self._actions: np.ndarray | None = None
        self.model = None

    # ------------------------------------------------------------------ rollouts
    def attach(self, model) -> None:
        """The model whose policy the actors play (:class:`RayMaskablePPO` calls :meth:`collect`)."""
        self.model = model

    def collect(self, weights: dict, n_steps: int, gamma: float, space) -> list[dict[str, Any]]:
        """Each actor's segment of ``n_steps``, played with ``weights`` on its own; ``space`` is the
        learner's observation space (its layout)."""
        ray = self._ray
        ref = ray.put(weights)
        return ray.get([w.collect.remote(ref, n_steps, gamma, space) for w in self.workers])

    # ------------------------------------------------------------------ VecEnv
    def reset(self):
        obs = self._ray.get([w.reset.remote() for w in self.workers])
        return {k: np.stack([o[k] for o in obs]) for k in obs[0]}

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        assert self._actions is not None
        results = self._ray.get([w.step.remote(int(a)) for w, a in zip(self.workers, self._actions, strict=True)])
        obs = {k: np.stack([r[0][k] for r in results]) for k in results[0][0]}
        return (
            obs,
            np.array([r[1] for r in results], dtype=np.float32),
            np.array([r[2] for r in results]),
            [r[3] for r in results],
        )

    def _chosen(self, indices):
        if indices is None:
            return self.workers
        if isinstance(indices, int):
            return [self.workers[indices]]
        return [self.workers[i] for i in indices]

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        calls = [w.env_method.remote(method_name, method_args, method_kwargs) for w in self._chosen(indices)]
        return self._ray.get(calls)

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return self._ray.get([w.get_attr.remote(attr_name) for w in self._chosen(indices)])

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise NotImplementedError("the Ray actors' envs are not set from the learner")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._chosen(indices))

    def seed(self, seed: int | None = None):
        return [None] * self.num_envs  # each actor's env was seeded when it started

    def close(self) -> None:
        for w in self.workers:
            self._ray.kill(w)
        self.workers = []
        if self._started:
            self._ray.shutdown()


class RayMaskablePPO(MaskablePPO):
    """MaskablePPO whose rollouts are the Ray actors' segments (:meth:`RayRollouts.collect`)."""

    def collect_rollouts(self, env, callback, rollout_buffer, n_rollout_steps, use_masking=True) -> bool:
        import torch

        self.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        weights = {k: v.detach().cpu() for k, v in self.policy.state_dict().items()}
        segments = env.collect(weights, n_rollout_steps, self.gamma, self.observation_space)
        for t in range(n_rollout_steps):
            obs = {k: np.stack([s["obs"][k][t] for s in segments]) for k in segments[0]["obs"]}
            actions = np.array([s["actions"][t] for s in segments]).reshape(-1, 1)
            rewards = np.array([s["rewards"][t] for s in segments], dtype=np.float32)
            starts = np.array([s["starts"][t] for s in segments], dtype=np.float32)
            values = torch.as_tensor([[s["values"][t]] for s in segments], dtype=torch.float32)
            log_probs = torch.as_tensor([s["log_probs"][t] for s in segments], dtype=torch.float32)
            masks = np.stack([s["masks"][t] for s in segments])
            dones = np.array([s["dones"][t] for s in segments])
            infos = [s["infos"][t] for s in segments]
            self.num_timesteps += env.num_envs
            callback.update_locals({"infos": infos, "dones": dones, "rewards": rewards})
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            rollout_buffer.add(obs, actions, rewards, starts, values, log_probs, action_masks=masks)
        last_values = torch.as_tensor([[s["last_value"]] for s in segments], dtype=torch.float32)
        last_dones = np.array([s["last_done"] for s in segments])
        self._last_episode_starts = last_dones
        # What the learner's own collection leaves: the observations after the rollout (train.critic reads them).
        self._last_obs = {k: np.stack([s["last_obs"][k] for s in segments]) for k in segments[0]["last_obs"]}
        rollout_buffer.compute_returns_and_advantage(last_values=last_values, dones=last_dones)
        callback.update_locals({"infos": [], "dones": last_dones})
        callback.on_rollout_end()
        return True


#: The algorithm :func:`train.ppo.build_model` builds on these rollouts.
RayRollouts.ppo_class = RayMaskablePPO
