"""Train a masked PPO agent on generated storeys: ``nbs train`` / ``python -m train.ppo``.

sb3-contrib's MaskablePPO reads the env's own ``action_masks()`` through ``SubprocVecEnv`` workers;
every episode scans a fresh generated storey. The policy is :mod:`policies.learned`'s network: a
3-D CNN over the one-hot voxel labels, and one MLP shared by all candidate slots. Checkpoints are
written in the safe format of :func:`policies.learned.save_checkpoint` (tensors + JSON), never as
SB3's pickled zip; a masked evaluation on held-out storeys against the greedy runs periodically.

Needs the ``rl`` extra (torch, stable-baselines3, sb3-contrib; install ``torch==2.13.0`` first for
the CPU build). Uses a GPU when torch sees one.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import errno
import json
import math
import os
import re
import secrets
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nbs_env import threads
from nbs_env.atomic import NEARLY_FULL, replacing, write_text
from nbs_env.config import Config, EnvConfig, _integer, _require
from nbs_env.config.checks import _plain_numbers, _plain_values, _within, parse_float, same_json
from nbs_env.config.rooms import MAX_SCANS
from nbs_env.errors import ConfigError, ModelFileError
from nbs_env.observation import CANDIDATE_FEATURES, ROOM_FEATURES, STOREY_FEATURES
from policies.learned import NetworkConfig, build_network, save_checkpoint
from scenes.jsonio import MAX_JSON_BYTES, json_text, read_json, read_json_file
from train.arguments import (
    add_robot_arguments,
    config_from_arguments,
    number,
    parse_range,
    scene_option_error,
    whole,
)

__all__ = ["TrainConfig", "check_memory", "main", "memory_claim", "train"]

#: Seeds of the held-out test storeys (``generated:10000000`` on, docs/results.md).
#: Training storeys are drawn by the env's own generator from the whole 31-bit range, with the
#: training run's room range; a clash with one of these seeds has odds of about 1e-5 per run.
HELD_OUT_BASE = 10_000_000
#: Seeds of the validation storeys the periodic evaluation plays, kept apart from the test storeys
#: so that choosing a checkpoint by the learning curve does not peek at the test table.
VALIDATION_BASE = 20_000_000
#: The most validation storeys a run evaluates on (:attr:`TrainConfig.eval_storeys`).
MAX_EVAL_STOREYS = 10_000


def _require_rl():
    try:
        import sb3_contrib  # noqa: F401
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError:
        raise SystemExit('nbs train needs the rl extra: pip install torch==2.13.0 "nbs-env[rl]"') from None


#: Environment fields a run sets from its own settings: dotted path -> (TrainConfig field, option).
RUN_FIELDS = {
    "generator.rooms": ("rooms", "--rooms"),
    "generator.cell_size": ("cell_size", "--cell-size"),
    "reward.metre_cost": ("metre_cost", "--metre-cost"),
    "reward.scan_cost": ("scan_cost", "--scan-cost"),
    "rooms.completion": ("completion", "--completion"),
}


def _leaf_paths(overrides: dict[str, Any], prefix: str = "") -> list[str]:
    """The dotted fields ``overrides`` sets, a field's own name as its path (``scan_cost`` is
    ``reward.scan_cost``): a section given as a dict opened into its fields, one given as a
    configuration into the fields it holds at other values than its class's defaults."""
    from nbs_env.config.presets import resolve_path

    paths = []
    for key, value in overrides.items():
        path = f"{prefix}{key}"
        if not prefix:
            with contextlib.suppress(ConfigError):  # an unknown name: make_config names it
                path = resolve_path(key)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            defaults = dataclasses.asdict(type(value)())
            value = {k: v for k, v in dataclasses.asdict(value).items() if v != defaults[k]}
            if not value:
                continue
        if isinstance(value, dict) and value and path != "scene_options":
            paths.extend(_leaf_paths(value, path + "."))
        else:
            paths.append(path)
    return paths


@dataclass(frozen=True)
class TrainConfig(Config):
    """What a training run is (JSON-safe, frozen, checked on construction); ``nbs train --help``
    names the same options.

    Attributes
    ----------
    timesteps : int
        Environment steps to train for (every worker's together).
    envs : int
        Worker processes, one env each.
    seed : int
        Seeds the networks, the workers' storeys and the evaluation.
    rooms : (int, int)
        The range of rooms of the generated training storeys.
    n_steps : int
        Steps per worker between PPO updates.
    batch_size : int
        PPO's minibatch.
    learning_rate : float
        PPO's learning rate.
    eval_every : int
        Timesteps between evaluations on the validation storeys (0: none).
    eval_storeys : int
        Validation storeys per evaluation.
    checkpoint_every : int
        Timesteps between checkpoints (0: none).
    max_episode_steps : int
        Decisions per episode at the most.
    bc_steps : int
        Vector steps of greedy play to behaviour-clone from before PPO (0: none).
    bc_teacher : str
        The greedy the behaviour cloning copies, by policy name: ``"greedy"`` (the paper's, the
        default) or a variant such as ``"greedy:stop=0.05"`` or ``"greedy:0.8+stop=0.05"``
        (:class:`policies.GreedyPolicy`); its ``stop`` is where it declares rooms done.
    metre_cost : float
        Reward subtracted per metre driven.
    scan_cost : float
        Reward subtracted per scan (the env's 0.5 by default). The reward's first term is the true
        structural surface sensed in percentage points, so lower prices of scans and metres make a
        missed point dearer relative to them.
    ent_coef : float
        PPO's entropy bonus (stable-baselines3's ``ent_coef``; 0 is its default).
    preset : str
        The configuration preset of the training envs: ``"train"`` (the default), the training
        fidelity (the fast preset's robot, observations and decisions, without the ground-truth
        coverage meter, rewarded by the surface the robot itself mapped), or any other preset. The
        validation envs run the same robot with the coverage meter on: coverage is what they report.
    overrides : dict
        Dotted configuration overrides on the preset (:func:`nbs_env.config.make_config`): the
        robot options of ``nbs train``'s command line (``--scanner``, ``--wall-search``, ``--set``
        ...), the same as ``nbs scan`` and ``nbs compare`` take. The checkpoint records the
        resulting configuration, and a policy trained with room rules requires them
        (:attr:`policies.Policy.requires`).
    cell_size : (float, float)
        The range of the generator's cell edge, metres: rooms are unions of such cells, so larger
        cells make larger rooms and open spaces.
    init : str
        A checkpoint (folder or ``policy.json``) to start the policy's network from, instead of
        random weights; its network must be this run's. Empty: none.
    completion : {"policy", "gain"}
        Who ends a room: ``"policy"``, the agent through its "room done" action (K + 1 actions; the
        network also reads the observation's ``room`` vector); ``"gain"``, the robot's gain rule
        (the agent only chooses where to scan).
    hold_coverage : float
        A coverage constraint (0: none, fixed prices): between rollouts the prices are scaled by
        ``exp(hold_coverage × (mapped - teacher))``, where ``mapped`` is the mean structure the
        rollout's finished episodes mapped (``info["mapped_pct"]`` at their end: the robot's own
        Structure, % of the storey's structural surface) and ``teacher`` the behaviour-cloning
        teacher's mean on its own episodes: the prices rise while the policy maps
        more than its teacher and fall while it maps less, so that PPO lowers scans and metres at the
        teacher's coverage (a Lagrangian multiplier on the costs, :class:`CostWeight`; the reward is
        divided by ``(1 + weight) / 2`` so that its scale stays the critic's). Needs ``bc_steps``.
    stop_lr_scale : float
        The "room done" head's learning rate as a multiple of ``learning_rate`` (1: the same). With
        Adam a parameter's step is about the learning rate whatever its gradient, so a cloned
        policy's room-ending choice moves this many times faster than where it scans.
        Needs ``completion="policy"`` unless 1.
    """

    timesteps: int = 2048
    envs: int = 2
    seed: int = 0
    rooms: tuple[int, int] = (1, 5)
    n_steps: int = 64
    batch_size: int = 64
    learning_rate: float = 3e-4
    eval_every: int = 0
    eval_storeys: int = 4
    checkpoint_every: int = 0
    max_episode_steps: int = 40
    bc_steps: int = 0
    bc_teacher: str = "greedy"
    metre_cost: float = 0.05
    scan_cost: float = 0.5
    ent_coef: float = 0.0
    preset: str = "train"
    overrides: dict[str, Any] = field(default_factory=dict)
    completion: str = "gain"
    cell_size: tuple[float, float] = (2.0, 3.6)
    init: str = ""
    hold_coverage: float = 0.0
    stop_lr_scale: float = 1.0

    def __post_init__(self) -> None:
        _plain_numbers(self)  # numpy numbers in rooms, cell_size: plain, as every configuration takes them
        object.__setattr__(self, "rooms", tuple(self.rooms))
        object.__setattr__(self, "cell_size", tuple(self.cell_size))
        _require(
            len(self.cell_size) == 2
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in self.cell_size)
            and 1.8 <= self.cell_size[0] <= self.cell_size[1] <= 10.0,
            f"cell_size must be (A, B) metres with 1.8 <= A <= B <= 10, got {json_text(self.cell_size)}",
        )
        _require(isinstance(self.init, str), f"init must be a checkpoint path (str), got {self.init!r}")
        _require(isinstance(self.bc_teacher, str), f"bc_teacher must be a policy name, got {self.bc_teacher!r}")
        _teacher(self.bc_teacher)  # an unknown or non-greedy teacher fails here, before any worker starts
        for name in ("timesteps", "envs", "n_steps", "batch_size", "eval_storeys", "max_episode_steps"):
            _integer(self, name, 1)
        for name in ("seed", "eval_every", "checkpoint_every", "bc_steps"):
            _integer(self, name, 0)
        # stable-baselines3 counts steps in floats (10**400 steps: an OverflowError after the first
        # rollout) and a saved state claims at most this many.
        for name in ("timesteps", "eval_every", "checkpoint_every", "bc_steps"):
            _require(
                getattr(self, name) <= MAX_STATE_TIMESTEPS,
                f"{name} must be at most {MAX_STATE_TIMESTEPS:,}, got {str(getattr(self, name))[:40]}",
            )
        # stable-baselines3 seeds numpy's legacy generator, which takes 32 bits (a traceback beyond).
        _require(self.seed < 2**32, f"seed must be below 2**32 = {2**32:,}, got {self.seed:,}")
        # An episode's steps are its scans at most (evaluation runs with max_scans = this).
        _require(
            self.max_episode_steps <= MAX_SCANS,
            f"max_episode_steps must be at most {MAX_SCANS:,} (a run's most scans), got {self.max_episode_steps:,}",
        )
        # Each validation storey is an episode per evaluation: ten thousand is days of evaluating.
        _require(
            self.eval_storeys <= MAX_EVAL_STOREYS,
            f"eval_storeys must be at most {MAX_EVAL_STOREYS:,}, got {self.eval_storeys:,}",
        )
        # PPO normalises each minibatch's advantages by their spread: a rollout of one step has none
        # (NaN logits after the first update).
        _require(
            self.n_steps * self.envs >= 2,
            f"n_steps x envs must be at least 2 (a rollout PPO can normalise), got {self.n_steps} x {self.envs}",
        )
        # The same for every minibatch: the rollout's last one holds its remainder (65 steps in
        # minibatches of 64 left one: NaN logits and a traceback after the rollout, the run lost).
        rollout = self.n_steps * self.envs
        _require(
            self.batch_size >= 2 and rollout % self.batch_size != 1,
            f"n_steps x envs = {rollout:,} in minibatches of batch_size {self.batch_size} leaves a minibatch of "
            "one sample, which PPO cannot normalise: make n_steps x envs a multiple of batch_size "
            "(or not one more than a multiple), and batch_size at least 2",
        )
        _require(
            len(self.rooms) == 2
            and all(isinstance(r, int) and not isinstance(r, bool) for r in self.rooms)
            and 1 <= self.rooms[0] <= self.rooms[1] <= 8,
            f"rooms must be (A, B) with 1 <= A <= B <= 8, got {json_text(self.rooms)}",
        )
        # Adam's step and the entropy bonus beyond these turn the network's weights to inf or NaN within
        # an update (a traceback from torch after the first rollout); PPO runs use 1e-5 to 1e-3 and 0 to 0.05.
        _within(self, "learning_rate", 0.0, MAX_LEARNING_RATE, open_low=True)
        _within(self, "ent_coef", 0.0, MAX_ENT_COEF)
        # The env's reward bounds its prices (reward.scan_cost, reward.metre_cost): the same range.
        _within(self, "metre_cost", 0.0, 1000.0)
        _within(self, "scan_cost", 0.0, 1000.0)
        _within(self, "hold_coverage", 0.0, 1.0)
        _require(
            not self.hold_coverage or self.bc_steps > 0,
            "hold_coverage holds the behaviour-cloning teacher's coverage: it needs bc_steps > 0",
        )
        _require(
            self.completion in ("policy", "gain"), f"completion must be 'policy' or 'gain', got {self.completion!r}"
        )
        # Below 1/1000 the head hardly moves (1e-320: frozen, without a word); beyond 100 times a PPO
        # learning rate its steps are those MAX_LEARNING_RATE bounds.
        _within(self, "stop_lr_scale", 1e-3, 100.0)
        _require(
            self.stop_lr_scale == 1.0 or self.completion == "policy",
            "stop_lr_scale scales the 'room done' head's learning rate: it needs completion='policy'",
        )
        _require(isinstance(self.overrides, dict), f"overrides must be a dict, got {type(self.overrides).__name__}")
        odd = [key for key in self.overrides if not isinstance(key, str)]
        _require(not odd, f"overrides' keys are field names (str, dotted), got {str(odd[:1])[1:-1][:40]}")
        # Numpy numbers the env's configuration takes; the run's records write them as JSON.
        object.__setattr__(self, "overrides", _plain_values(self.overrides))
        # A run trains on generated storeys, which read no scene_options ({"rooms": 8} was taken
        # without a word): the generator's own fields say what the storeys are.
        _require(
            not self.overrides.get("scene_options"),
            "overrides set scene_options, which a run's generated storeys do not read: set generator.* "
            "(or --rooms, --cell-size) instead",
        )
        for path in _leaf_paths(self.overrides):
            # The run's own settings win over an override of the same field (env_config): one set
            # there would be recorded and not applied.
            owner = next((o for p, o in RUN_FIELDS.items() if path == p or path.startswith(p + ".")), None)
            if owner is not None:
                raise ConfigError(
                    f"{path} is the run's own {owner[0]} (nbs train {owner[1]}): set it there, not as an "
                    "override (--set)"
                )
        self.env_config()  # a bad preset or override fails here, before any worker starts

    def env_config(self, **overrides: Any) -> EnvConfig:
        """The configuration of the run's envs: the preset with the run's overrides, its storeys,
        prices and room completion, and ``overrides`` (e.g. ``scene=``) on top.

        Raises
        ------
        ConfigError
            The preset or an override is refused.
        """
        from nbs_env.config import make_config

        run = {
            "generator.rooms": self.rooms,
            "generator.cell_size": self.cell_size,
            "reward.metre_cost": self.metre_cost,
            "reward.scan_cost": self.scan_cost,
            "rooms.completion": self.completion,
        }
        return make_config(make_config(self.preset, **{**self.overrides, **run}), **overrides)

    def evaluation_config(self) -> EnvConfig:
        """The validation envs' configuration: the run's robot with the coverage meter on and the
        coverage reward (what the periodic evaluation reports is the true surface sensed)."""
        from nbs_env.config import make_config

        return make_config(self.env_config(), coverage_meter=True, **{"reward.kind": "coverage"})

    @property
    def network(self) -> NetworkConfig:
        """The network this run trains, for its envs' observation: their voxel window and K candidates
        (``--set observation.shape=...`` or ``robot.navigation.max_candidates=...`` were once left at
        the network's defaults: a traceback from torch, or a checkpoint recording a window it never
        saw); K + 1 actions and the room vector with ``completion="policy"``."""
        env = self.env_config()
        shape, candidates = tuple(env.observation.shape), env.robot.navigation.max_candidates
        try:
            if self.completion == "policy":
                return NetworkConfig(
                    voxel_shape=shape, candidates=candidates, actions=candidates + 1, room_features=len(ROOM_FEATURES)
                )
            return NetworkConfig(voxel_shape=shape, candidates=candidates, actions=candidates)
        except ConfigError as exc:  # the network's field names are not what the user set
            raise ConfigError(
                f"no network takes observation.shape={list(shape)} with robot.navigation.max_candidates={candidates} "
                f"(the network's {exc})"
            ) from None


#: The share of this machine's memory a run's own arrays may claim (:func:`memory_claim`): the rest is
#: for what the estimate leaves out and cannot bound from the options alone: the env workers (about
#: 1 GiB each with their storeys and maps), torch and PPO's minibatches, and the rest of the machine.
MEMORY_SHARE = 0.5


def _bytes(n: float) -> str:
    """``n`` bytes as a person reads them: ``65.6 KiB``, ``12.2 TiB``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:,.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:,.1f} TiB"


def memory_claim(config: TrainConfig, backend: str = "local", behaviour_cloning: bool = True) -> dict[str, int]:
    """The memory a run's options make it claim, in bytes, estimated from the options alone before
    anything is built: the rollout buffer and the behaviour-cloning samples, the arrays that grow with
    ``n_steps``, ``bc_steps`` and ``envs``.

    Parameters
    ----------
    config : TrainConfig
    backend : {"local", "ray"}
        With ``"ray"`` the actors' segments arrive at the learner as well, one more copy of a rollout.
    behaviour_cloning : bool
        Count behaviour cloning (a resumed run does not clone again).

    Returns
    -------
    dict
        ``"step"``: bytes of one step of one env in the rollout buffer (its observation as
        stable-baselines3 stores it, the action and its mask, PPO's six figures); ``"rollout"``: the
        buffer, twice over (an update flattens each observation array into a copy), three times with
        Ray; ``"sample"``: bytes of one behaviour-cloning sample (its observation kept twice, then read
        as float32 and one-hot in one batch, 40 bytes a voxel cell); ``"cloning"``: all of them.
    """
    env = config.env_config()
    cells = int(np.prod(env.observation.shape))
    k = env.robot.navigation.max_candidates
    actions = k + (env.rooms.completion == "policy")
    floats = k * len(CANDIDATE_FEATURES) + 4 + len(ROOM_FEATURES) + len(STOREY_FEATURES)  # all float32
    step = cells + 4 * floats + 8 + 4 * actions + 4 * 6  # voxels uint8, action int64, mask float32, figures
    rollout = config.n_steps * config.envs * step * (3 if backend == "ray" else 2)
    sample = 40 * cells + 2 * 4 * floats + actions + 8
    cloning = config.bc_steps * config.envs * sample if behaviour_cloning else 0
    return {"step": step, "rollout": rollout, "sample": sample, "cloning": cloning}


def check_memory(config: TrainConfig, backend: str = "local", behaviour_cloning: bool = True) -> None:
    """Refuse a run whose options claim more than :data:`MEMORY_SHARE` of this machine's memory
    (:func:`memory_claim`), before anything is built: numpy's or torch's allocation would fail only
    after the workers started, or the machine would start swapping.

    Parameters
    ----------
    config : TrainConfig
    backend : {"local", "ray"}
    behaviour_cloning : bool
        Count behaviour cloning.

    Raises
    ------
    ConfigError
        The run claims too much; the message names the options to lower and what they claim.
    """
    from scenes.limits import machine_memory

    claim = memory_claim(config, backend, behaviour_cloning)
    budget = MEMORY_SHARE * machine_memory()
    total = claim["rollout"] + claim["cloning"]
    if total <= budget:
        return
    if claim["rollout"] >= claim["cloning"]:
        options = f"--n-steps {config.n_steps} x --envs {config.envs}"
        copies = "three times with Ray" if backend == "ray" else "twice"
        what = f"rollouts of {_bytes(claim['rollout'])} ({_bytes(claim['step'])} a step of each env, held {copies})"
        lower = "--n-steps or --envs"
    else:
        options = f"--bc-steps {config.bc_steps} x --envs {config.envs}"
        what = f"behaviour-cloning samples of {_bytes(claim['cloning'])} ({_bytes(claim['sample'])} each)"
        lower = "--bc-steps or --envs"
    # The whole only where the other part adds to it noticeably.
    in_all = f", {_bytes(total)} in all" if min(claim["rollout"], claim["cloning"]) > 0.01 * total else ""
    raise ConfigError(
        f"{options} asks for {what}{in_all}, more than {MEMORY_SHARE:.0%} of this machine's "
        f"{_bytes(machine_memory())} of memory: lower {lower}"
    )


#: Copies of the network's float32 parameters one saved state writes: the policy's own file, and the
#: training state's policy (value head included, about 1.2 x) with Adam's two moments of each.
STATE_COPIES = 6


def check_disk(config: TrainConfig, out: str | Path) -> None:
    """Refuse a run where the disk that will hold ``out`` has no room for one saved state (a
    checkpoint and its training state, :data:`STATE_COPIES` copies of the network) and
    :data:`~nbs_env.atomic.NEARLY_FULL` more for the curve and logs: on a full disk it failed at its
    first save, after the workers started and behaviour cloning ran.

    Raises
    ------
    OSError
        ``errno.ENOSPC`` naming the folder, with the free and the needed bytes.
    """
    folder = Path(out).absolute()
    while not folder.exists() and folder.parent != folder:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # a folder whose disk cannot be asked: its first write will say what is wrong
        return
    need = STATE_COPIES * 4 * config.network.parameters + NEARLY_FULL
    if free < need:
        raise OSError(
            errno.ENOSPC,
            f"{os.strerror(errno.ENOSPC)}: {_bytes(free)} free, where a saved state of this network and the "
            f"run's logs take about {_bytes(need)}",
            str(folder),
        )


def check_workers(config: TrainConfig, backend: str = "local", address: str | None = None) -> None:
    """Refuse more env workers than twice this machine's cores where they would all run here (the
    local backend, or a Ray instance started here), as ``nbs compare --jobs`` is refused.

    Each worker imports torch and holds a storey, its maps and a scanner's rays (about 1 GB): beyond
    the cores they only share them, and 500 of them were killed for memory with no message. Twice the
    cores leaves room for a machine whose count is read low (a container's).

    Raises
    ------
    ConfigError
        Naming ``--envs`` and the most this machine takes.
    """
    cores = os.cpu_count() or 1
    if config.envs > 2 * cores and (backend == "local" or address is None):
        where = "local env workers" if backend == "local" else "env workers of a Ray instance started here"
        raise ConfigError(
            f"--envs {config.envs}: this machine has {cores} cores, and {where} beyond them only share them "
            f"(each holds a storey and its maps, about 1 GB); pass at most --envs {2 * cores}, or --backend ray "
            "--address for a cluster"
        )


def _env_factory(run: TrainConfig):
    """A picklable maker of one training env: the fast preset on the run's generated storeys, with
    its prices, completion and episode length."""

    def make():
        import multiprocessing

        import gymnasium as gym
        from stable_baselines3.common.monitor import Monitor

        if multiprocessing.parent_process() is not None:
            # A worker process: Ctrl-C and SIGHUP (sent by the terminal to the whole process group) and SIGTERM
            # (sent to the group by `timeout`, a batch system or a container's stop) are the
            # learner's to handle: it saves the run, then closes the workers. A worker that died of
            # them mid-step would leave the learner a broken pipe instead of a saved run.
            import signal

            from train.stopping import STOP_SIGNALS

            for sig in STOP_SIGNALS:
                signal.signal(sig, signal.SIG_IGN)
        config = run.env_config()
        # Monitor puts each episode's return in info["episode"], for the learning-curve log.
        env = gym.make("nbs_env:nbs_env/NBS-Fast-v0", config=config, max_episode_steps=run.max_episode_steps)
        return Monitor(env)

    return make


def ray_rollouts(config: TrainConfig, address: str | None = None, seed: int = 0):
    """The run's envs in Ray actors (:class:`train.ray_rollouts.RayRollouts`), each with a copy of
    the run's policy.

    Parameters
    ----------
    config : TrainConfig
        The run: its envs, their number and its network.
    address : str, optional
        The Ray cluster to join; None starts a local instance.
    seed : int
        Actor ``i``'s env is seeded with ``seed + i``.
    """
    from train.ray_rollouts import RayRollouts

    network = config.network

    def make_policy(observation_space, action_space):
        return _policy_class()(
            observation_space, action_space, lambda _: 0.0, network=network, split_critic=bool(config.hold_coverage)
        )

    return RayRollouts(_env_factory(config), make_policy, config.envs, address=address, seed=seed)


def _check_ray(address: str | None) -> None:
    """That the cluster a Ray run would join answers (:func:`train.ray_connect.resolve_address`), unless
    this process already joined one (a user's own ``ray.init``)."""
    from train.ray_connect import resolve_address

    try:
        import ray
    except ImportError:
        raise ConfigError('--backend ray needs Ray: pip install "nbs-env[cluster]"') from None
    if not ray.is_initialized():
        resolve_address(address)


def _policy_class():
    from sb3_contrib.common.maskable.policies import MaskableMultiInputActorCriticPolicy
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class Features(BaseFeaturesExtractor):
        """g from the voxels, the flat candidate table and the room vector, which the scorer splits
        again; then the storey vector (log scale), which only the critic reads: the scans and metres
        still to come turn on the rooms beyond the doors the robot found (run hold5: a critic without
        it explained a quarter to a third of that price)."""

        def __init__(self, observation_space, network: NetworkConfig) -> None:
            extra = len(STOREY_FEATURES) if "storey" in observation_space.spaces else 0
            super().__init__(observation_space, features_dim=network.latent_dim + extra)
            self.network = network
            self.encoder, _ = build_network(network)

        def forward(self, obs):
            import torch

            parts = [self.encoder(obs["voxels"]), obs["candidates"].float()]
            if self.network.room_features:
                parts.append(obs["room"].float())
            if "storey" in obs:
                parts.append(torch.log1p(obs["storey"].float().clamp(min=0)))
            return torch.cat(parts, dim=1)

    class ScanNetPolicy(MaskableMultiInputActorCriticPolicy):
        """MaskablePPO's policy with :mod:`policies.learned`'s slot-independent candidate scorer."""

        def __init__(
            self, *args, network: NetworkConfig, stop_lr_scale: float = 1.0, split_critic: bool = False, **kwargs
        ) -> None:
            self.network = network
            self.stop_lr_scale = stop_lr_scale
            self.split_critic = split_critic
            kwargs["features_extractor_class"] = Features
            kwargs["features_extractor_kwargs"] = {"network": network}
            kwargs["net_arch"] = {"pi": [], "vf": [128, 64]}
            kwargs["normalize_images"] = False
            super().__init__(*args, **kwargs)

        def _build(self, lr_schedule) -> None:
            super()._build(lr_schedule)
            _, self.action_net = build_network(self.network)
            self.action_net.to(self.device)
            if self.split_critic:  # train.critic: the gain and the price apart, combined at the rollout's weight
                from train.critic import PricedValue

                self.value_net = PricedValue(self.mlp_extractor.latent_dim_vf).to(self.device)
            params = list(self.parameters())
            if self.stop_lr_scale != 1.0 and self.action_net.stop is not None:
                head = {id(p) for p in self.action_net.stop.parameters()}
                params = [
                    {"params": [p for p in params if id(p) not in head]},
                    {"params": list(self.action_net.stop.parameters()), "lr_scale": self.stop_lr_scale},
                ]
                self.optimizer_class = _scaled(self.optimizer_class)
            self.optimizer = self.optimizer_class(params, lr=lr_schedule(1), **self.optimizer_kwargs)

        def value_heads(self, obs):
            """A split critic's two values (B, 2): the discounted gain and the discounted price."""
            return self.value_net.heads(self.mlp_extractor.forward_critic(self.extract_features(obs)))

        def evaluate_actions(self, obs, actions, action_masks=None):
            # PPO's update: a split critic's two heads, each fitted to its own return
            # (train.critic.PricedRolloutBuffer gives the returns in the same order).
            if not self.split_critic:
                return super().evaluate_actions(obs, actions, action_masks=action_masks)
            latent_pi, latent_vf = self.mlp_extractor(self.extract_features(obs))
            distribution = self._get_action_dist_from_latent(latent_pi)
            if action_masks is not None:
                distribution.apply_masking(action_masks)
            return self.value_net.heads(latent_vf), distribution.log_prob(actions), distribution.entropy()

    return ScanNetPolicy


def _scaled(optimizer_class):
    """``optimizer_class`` whose parameter groups step at ``lr × group["lr_scale"]``.

    stable-baselines3 sets every group's ``lr`` to the schedule's value before each update, so the
    scale is applied for the step only, not kept in ``lr``.
    """

    class Scaled(optimizer_class):
        def step(self, closure=None):
            base = [group["lr"] for group in self.param_groups]
            for group in self.param_groups:
                group["lr"] = group["lr"] * group.get("lr_scale", 1.0)
            try:
                return super().step(closure)
            finally:
                for group, lr in zip(self.param_groups, base, strict=True):
                    group["lr"] = lr

    Scaled.__name__ = Scaled.__qualname__ = f"Scaled{optimizer_class.__name__}"
    return Scaled


def _state_dict(model) -> dict:
    policy = model.policy
    out = {f"encoder.{k}": v for k, v in policy.features_extractor.encoder.state_dict().items()}
    out.update({f"scorer.{k}": v for k, v in policy.action_net.state_dict().items()})
    return out


def _layout(model) -> str:
    shape = tuple(model.observation_space["voxels"].shape)
    return "xyz" if shape == (64, 64, 16) else "zxy"


def evaluate(
    policy_fn, storeys: list[int], max_episode_steps: int, config: EnvConfig, room_rule: float | None = None
) -> dict[str, float]:
    """Mean scans, SE % and path of a policy over held-out generated storeys.

    Parameters
    ----------
    policy_fn : callable
        ``policy_fn(obs, info) -> action``.
    storeys : list of int
        Seeds of the generated storeys.
    max_episode_steps : int
        Decisions per episode at the most, and its scan budget where ``config``'s is larger.
    config : EnvConfig
        The envs' configuration (:meth:`TrainConfig.env_config`); its scene is replaced.
    room_rule : float, optional
        Where the env has a "room done" action: the completion fraction at which
        ``info["gain_rule_done"]`` says a room is done (a greedy teacher's ``stop``, as behaviour
        cloning gives it); None: the robot's own.
    """
    from nbs_env.config import make_config
    from nbs_env.env import NBSEnv

    scans, pct, path = [], [], []
    for seed in storeys:
        # The run's own budget where it is the lower (`--max-scans 2` was evaluated with 40 scans).
        budget = min(config.max_scans, max_episode_steps)
        env = NBSEnv(make_config(config, scene=f"generated:{seed}", max_scans=budget))
        obs, info = env.reset(seed=seed)
        # At most max_episode_steps decisions, as training's TimeLimit, and as many scans: with the
        # gain rule a step takes at least one scan, with "room done" steps the decisions bind first.
        for _ in range(max_episode_steps):
            if room_rule is not None and "gain_rule_done" in info:
                info = {**info, "gain_rule_done": env.gain_rule_done(room_rule)}
            obs, _, terminated, truncated, info = env.step(policy_fn(obs, info))
            if terminated or truncated:
                break
        scans.append(info["scans"])
        pct.append(info["structure_sensed_pct"])
        path.append(info["path_length_m"])
    return {
        "scans": float(np.mean(scans)),
        "structure_sensed_pct": float(np.mean(pct)),
        "path_length_m": float(np.mean(path)),
    }


def make_training_envs(config: TrainConfig, seed: int | None = None):
    """The vector env ``nbs train`` steps: ``config.envs`` generated-storey envs, each in a worker
    process of its own (``SubprocVecEnv``) when there are several, seeded with ``seed`` (None:
    ``config.seed``)."""
    _require_rl()
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    workers = [_env_factory(config)] * config.envs
    if config.envs > 1:
        # Each worker's kernels share the cores with the others' (nbs_env.threads): a worker gets
        # its share, unless NBS_THREADS says otherwise. The workers read it when they start.
        previous = os.environ.get("NBS_THREADS")
        os.environ.setdefault("NBS_THREADS", str(max(1, threads.cores() // config.envs)))
        from train.stopping import start_resource_tracker

        start_resource_tracker()
        try:
            venv = SubprocVecEnv(workers, start_method="spawn")
        finally:
            if previous is None:
                del os.environ["NBS_THREADS"]
    else:
        venv = DummyVecEnv(workers)
    venv.seed(config.seed if seed is None else seed)
    return venv


#: Seconds a stop signal waits for the training step under way before it stops the run at once,
#: keeping its last update's state: within the grace a supervisor gives before SIGKILL (Docker's 10 s
#: by default, Kubernetes' 30 s) on most machines.
STOP_WAIT_S = 8.0

#: The largest learning rate and entropy bonus a run takes: a hundred times what PPO is run with.
MAX_LEARNING_RATE = 0.1
MAX_ENT_COEF = 1.0

#: The file of a run's resumable state: every tensor of the policy (value head included) and the
#: optimiser's state, tensors and numbers only (``torch.load(weights_only=True)`` reads it).
STATE_FILE = "training_state.pt"
#: Its description: the format, the timesteps it holds, the run's settings and the tensors' checksum.
STATE_JSON = "training_state.json"
STATE_FORMAT = "nbs-env-training-state"
#: The most steps a saved state may claim (10¹², ten thousand times the largest runs in the field).
MAX_STATE_TIMESTEPS = 10**12


class CostWeight:
    """The multiplier of :attr:`TrainConfig.hold_coverage`: the weight of the prices in the reward
    PPO learns from, raised while the training episodes map more structure than the teacher's and
    lowered while they map less (dual ascent on a coverage constraint, in log space).

    Parameters
    ----------
    rate : float
        The step of ``log(weight)`` per percentage point between the rollout's mean and ``target``.
    target : float
        The teacher's mean mapped structure at the end of an episode, % of the storey's structure.
    weight : float
        The weight to start from (a resumed run's).
    """

    #: The weight's range: the prices at most 20 times lower or higher than the run's.
    LOW, HIGH = 0.05, 20.0
    MAX_STEP = 0.25

    def __init__(self, rate: float, target: float, weight: float = 1.0) -> None:
        self.rate, self.target, self.weight = float(rate), float(target), float(weight)
        self.finished: list[float] = []
        self.last_mean: float | None = None

    def reweigh(self, rewards: np.ndarray, infos: list[dict], dones: np.ndarray) -> None:
        """Reweigh a vector step's ``rewards`` in place (before the rollout buffer holds them):
        ``2 (gain - weight × cost) / (1 + weight)`` from the env's ``reward_terms``; keep the
        mapped structure of the episodes that ended.

        The division keeps the reward's scale whatever the weight (between twice the gain and
        twice the cost, the env's own reward at weight 1): with ``gain - weight × cost`` alone the
        return grew with the weight faster than the critic followed (its explained variance fell
        from 0.5 to 0.01 as the weight rose from 1.8 to 5.1). Stooke, Achiam and Abbeel (2020),
        "Responsive safety in reinforcement learning by PID Lagrangian methods", normalise so."""
        scale = 2.0 / (1.0 + self.weight)
        for i, info in enumerate(infos):
            terms = info.get("reward_terms")
            if terms is not None:
                # What the reward holds beyond gain - cost (a Ray worker's bootstrap of a truncated
                # episode, already a value at this weight) is kept as it is.
                beyond = rewards[i] - (terms["gain"] - terms["cost"])
                rewards[i] = scale * (terms["gain"] - self.weight * terms["cost"]) + beyond
            if dones[i] and "mapped_pct" in info:
                self.finished.append(float(info["mapped_pct"]))

    def update(self) -> None:
        """After a rollout: move the weight by the finished episodes' mean against the target."""
        if not self.finished:
            return
        self.last_mean = float(np.mean(self.finished))
        # At most a quarter in log space per rollout: a rollout of a few storeys is a noisy mean.
        step = float(np.clip(self.rate * (self.last_mean - self.target), -self.MAX_STEP, self.MAX_STEP))
        self.weight = float(np.clip(self.weight * np.exp(step), self.LOW, self.HIGH))
        self.finished = []


def save_training_state(
    model, folder: str | Path, run: TrainConfig, cost_weight: float = 1.0, run_id: str | None = None
) -> Path:
    """Write what a run continues from into ``folder``: :data:`STATE_FILE` (the whole policy's
    tensors and the optimiser's state) and :data:`STATE_JSON` (the timesteps done and the run's
    settings, and :class:`CostWeight`'s weight). Never a pickle of objects: tensors and numbers,
    and JSON.

    The tensors file keeps the settings and ``run_id`` (which run's records the folder holds) as a
    JSON string too, under its checksum: a resume refuses settings edited in :data:`STATE_JSON`
    after the state was saved, which it would otherwise train with and record as the whole run's.

    Returns
    -------
    Path
        The JSON file.
    """
    import torch

    from policies.learned import _sha256

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tensors = folder / STATE_FILE
    policy = model.policy
    state = {
        "policy": {k: v.detach().cpu() for k, v in policy.state_dict().items()},
        "optimizer": policy.optimizer.state_dict(),
        "record": json.dumps({"run": run.to_dict(), "run_id": run_id}, sort_keys=True),
    }
    path = folder / STATE_JSON
    # Both whole under temporary names, then renamed, the tensors first: a full disk, a signal or a
    # crash leaves the previous state (a pair whose checksum holds), never half of a new one.
    with replacing(path) as description, replacing(tensors, writer_errors=(RuntimeError,)) as temporary:
        torch.save(state, temporary)
        document = {
            "format": STATE_FORMAT,
            "version": 1,
            "timesteps": int(model.num_timesteps),
            "tensors": tensors.name,
            "sha256": _sha256(temporary),
            "run": run.to_dict(),
            "cost_weight": float(cost_weight),
            "run_id": run_id,
        }
        description.write_text(json.dumps(document, indent=1))
    return path


def latest_state(run_folder: str | Path) -> tuple[Path, dict]:
    """The latest resumable state of a run folder: its own, or its newest ``checkpoint_N``'s.

    Returns
    -------
    (Path, dict)
        The state's folder and its :data:`STATE_JSON` document.

    Raises
    ------
    ModelFileError
        No state in the folder, or a state file that is not this format.
    """
    run_folder = Path(run_folder)
    if not run_folder.is_dir():
        raise ModelFileError(f"{run_folder}: no such run folder")
    found = []
    for path in [run_folder / STATE_JSON, *run_folder.glob(f"checkpoint_*/{STATE_JSON}")]:
        if not path.is_file():
            continue
        if path.parent != run_folder and (path.parent / CURVE).exists():
            continue  # a run folder of its own named like a checkpoint (checkpoint_problem), not this run's
        document = _json_record(path, "a JSON training state")
        if (
            not isinstance(document, dict)
            or document.get("format") != STATE_FORMAT
            or not same_json(document.get("version"), 1)
        ):
            raise ModelFileError(f"{path}: not an {STATE_FORMAT!r} file of version 1")
        steps = document.get("timesteps")
        if type(steps) is not int or not isinstance(document.get("run"), dict):
            raise ModelFileError(f"{path}: malformed training state (timesteps, run)")
        if not 0 <= steps <= MAX_STATE_TIMESTEPS:
            raise ModelFileError(f"{path}: timesteps {steps} is not a count of steps (0..{MAX_STATE_TIMESTEPS:,})")
        weight = document.get("cost_weight", 1.0)
        if type(weight) not in (int, float) or not CostWeight.LOW <= weight <= CostWeight.HIGH:
            raise ModelFileError(
                f"{path}: cost_weight must be a number in [{CostWeight.LOW}, {CostWeight.HIGH}], "
                f"got {json_text(weight, 40)}"
            )
        name = document.get("tensors", STATE_FILE)
        if not isinstance(name, str) or Path(name).name != name or name in ("", ".", ".."):
            # A name in the state's own folder: "../other/training_state.pt" resumed another run's
            # state without a word, and "/etc/passwd" was read whole.
            raise ModelFileError(f"{path}: tensors must name a file beside it, got {str(name)[:80]!r}")
        found.append((document["timesteps"], path.parent, document))
    if not found:
        raise ModelFileError(
            f"{run_folder}: no resumable state ({STATE_JSON}); runs save one with each checkpoint and when stopped"
        )
    _, folder, document = max(found, key=lambda f: f[0])
    return folder, document


#: The learning curve every run folder holds from its start (a checkpoint folder holds none).
CURVE = "learning_curve.jsonl"
#: What behaviour cloning measured (:func:`behaviour_clone`), in a run folder that cloned.
CLONE_RECORD = "behaviour_cloning.json"
#: The largest structure a robot maps, % of the storey's structural surface (walls a voxel and a
#: half thick map at 1.1-1.25 times their surface).
MAX_MAPPED_PCT = 1000.0


def _clone_record(out: Path, config: TrainConfig) -> dict | None:
    """A resumed run's :data:`CLONE_RECORD` (None where it cloned nothing), checked: a JSON object,
    and with ``hold_coverage`` the teacher's ``mapped`` figure the constraint holds.

    Raises
    ------
    ModelFileError
        Naming the file and what is wrong with it.
    """
    path = out / CLONE_RECORD
    if not os.path.lexists(path):
        if config.hold_coverage and config.bc_steps:
            raise ModelFileError(f"{path}: missing; the run holds the teacher's coverage it records (hold_coverage)")
        return None
    record = _json_record(path, "JSON")
    if not isinstance(record, dict):
        raise ModelFileError(f"{path}: not a behaviour-cloning record (a JSON object)")
    mapped = record.get("mapped")
    if config.hold_coverage and (
        type(mapped) not in (int, float) or not 0 < mapped <= MAX_MAPPED_PCT  # NaN fails too
    ):
        raise ModelFileError(
            f"{path}: mapped is {str(mapped)[:40]}, not the teacher's mapped structure in % (0..{MAX_MAPPED_PCT:g}] "
            "that hold_coverage holds; restore the file the run wrote"
        )
    return record


def _json_record(path: Path, what: str) -> Any:
    """A run's JSON file, read: a :class:`ModelFileError` naming it when it is not ``what``."""
    try:
        return read_json_file(path)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        from policies.learned import _one_line

        raise ModelFileError(f"{path}: not {what} ({_one_line(exc)})") from None
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None


def checkpoint_problem(folder: str | Path) -> str | None:
    """Why ``folder`` cannot be resumed as a run: it is a ``checkpoint_N`` folder inside a run folder
    (None when it is not). :func:`latest_state` reads a checkpoint as it reads a run, for
    :func:`load_model`; resumed as a run, its checkpoints would be written inside it."""
    folder = Path(folder)
    real = folder.resolve()
    if not re.fullmatch(r"checkpoint_\d+", real.name) or (real / CURVE).exists():
        return None  # a run folder named checkpoint_N holds its own curve
    parent = real.parent
    if not ((parent / CURVE).is_file() or (parent / STATE_JSON).is_file()):
        return None
    run = folder.parent if folder.name == real.name else parent
    return (
        f"{folder} is a checkpoint of the run {run}: continue the run with --resume {run} (it resumes from its "
        f"newest checkpoint), or start a new run from its weights with --init {folder} --out NEW"
    )


def resume_config(run_folder: str | Path, timesteps: int | None = None) -> TrainConfig:
    """The settings of the run in ``run_folder``, with a new total of ``timesteps`` if given.

    Raises
    ------
    ModelFileError
        No resumable state, or settings this version refuses.
    """
    folder, document = latest_state(run_folder)
    run = document["run"]
    missing = [f.name for f in dataclasses.fields(TrainConfig) if isinstance(run, dict) and f.name not in run]
    if missing:
        # The run's own settings, every one written: a default in place of one changes the run.
        raise ModelFileError(
            f"{folder / STATE_JSON}: its run settings lack {', '.join(missing[:4])}"
            f"{f' and {len(missing) - 4} more' if len(missing) > 4 else ''}, which every state holds: restore "
            "them as the run had them, or start a new run from its weights with --init"
        )
    try:
        config = TrainConfig.from_dict(run)
        if timesteps is not None:
            config = dataclasses.replace(config, timesteps=timesteps)
        # The file's settings, not options the user typed: "--n-steps 10...0 asks for TiB" named none.
        check_memory(config, behaviour_cloning=False)
    except (ConfigError, TypeError) as exc:
        raise ModelFileError(
            f"{folder / STATE_JSON}: its run settings are refused ({exc}); a resumed run keeps its own: "
            "correct them in the file, or start a new run from its weights with --init"
        ) from None
    return config


def _load_state(model, folder: Path, document: dict) -> None:
    from policies.learned import _one_line, _sha256, check_tensors, read_tensors, recorded_digest, tensor_file_bound

    tensors = folder / str(document.get("tensors", STATE_FILE))
    if not tensors.is_file():
        raise ModelFileError(f"{tensors}: missing (named by {folder / STATE_JSON})")
    # The policy's parameters (its value head's included) and Adam's two moments of each.
    parameters = sum(p.numel() for p in model.policy.parameters())
    if _sha256(tensors, tensor_file_bound(parameters, copies=3)) != recorded_digest(document, folder / STATE_JSON):
        raise ModelFileError(f"{tensors}: its checksum is not the one {STATE_JSON} records (a modified file)")
    state = read_tensors(tensors)
    if not isinstance(state, dict) or not isinstance(state.get("policy"), dict) or "optimizer" not in state:
        raise ModelFileError(f"{tensors}: not a training state (the policy's tensors and the optimiser's state)")
    check_tensors(state, tensors)
    _check_record(state.get("record"), document, folder / STATE_JSON)
    try:
        model.policy.load_state_dict(state["policy"])
        model.policy.optimizer.load_state_dict(state["optimizer"])
    except (RuntimeError, KeyError, ValueError, TypeError, IndexError) as exc:
        raise ModelFileError(f"{tensors}: does not fit this run's network ({_one_line(exc)})") from None
    for group in model.policy.optimizer.param_groups:
        if "lr_scale" in group:  # the run's setting, as its record says, not the one the tensors kept
            group["lr_scale"] = model.policy.stop_lr_scale
    model.num_timesteps = int(document["timesteps"])


def _check_record(record: Any, document: dict, path: Path) -> None:
    """That the settings and run id of a state's JSON are those its tensors were saved with (the
    ``record`` string :func:`save_training_state` keeps under the checksum; states written before it
    hold none, and are taken as they are).

    Raises
    ------
    ModelFileError
        Naming the settings that differ.
    """
    if record is None:
        return
    try:
        saved = read_json(record) if isinstance(record, str) else None
    except json.JSONDecodeError:
        saved = None
    if not isinstance(saved, dict) or not isinstance(saved.get("run"), dict):
        raise ModelFileError(f"{path}: its tensors' record of the run is not one this version writes")
    run = document["run"]
    changed = [k for k in sorted(set(run) | set(saved["run"])) if not same_json(run.get(k), saved["run"].get(k))]
    if changed:
        shown = ", ".join(
            f"{k} {json_text(run.get(k), 30)} against {json_text(saved['run'].get(k), 30)}" for k in changed[:4]
        )
        raise ModelFileError(
            f"{path}: its run settings are not those the state was saved with ({shown}"
            f"{f' and {len(changed) - 4} more' if len(changed) > 4 else ''}); a resumed run keeps its own "
            "settings: restore the file, or start a new run from its weights with --init"
        )
    if document.get("run_id") != saved.get("run_id"):
        raise ModelFileError(f"{path}: its run_id is not the one the state was saved with; restore the file")


def build_model(config: TrainConfig, venv, device: str = "cpu", tensorboard: str | None = None):
    """The MaskablePPO of a run: :mod:`policies.learned`'s network as its policy, with the run's
    PPO settings, on ``venv``. Also what loads a checkpoint into a user's own code (docs/training.md)."""
    _require_rl()
    from sb3_contrib import MaskablePPO

    # The rollout buffer is allocated here: sized from the options before numpy is asked for it.
    check_memory(dataclasses.replace(config, envs=venv.num_envs), behaviour_cloning=False)
    algorithm = getattr(venv, "ppo_class", MaskablePPO)  # Ray's rollouts bring their own collection
    split = bool(config.hold_coverage)  # prices that move: train.critic's two heads
    if split:
        from train.critic import PricedRolloutBuffer
    return algorithm(
        _policy_class(),
        venv,
        n_steps=config.n_steps,
        batch_size=config.batch_size,
        learning_rate=config.learning_rate,
        ent_coef=config.ent_coef,
        seed=config.seed,
        device=device,
        tensorboard_log=tensorboard,
        policy_kwargs={"network": config.network, "stop_lr_scale": config.stop_lr_scale, "split_critic": split},
        rollout_buffer_class=PricedRolloutBuffer if split else None,
        verbose=0,
    )


def load_model(checkpoint: str | Path, env=None, device: str = "cpu"):
    """A MaskablePPO with a run's whole policy (value head included) and optimiser state.

    Parameters
    ----------
    checkpoint : str or Path
        A run folder or one of its ``checkpoint_N`` folders (the latest state in it is read).
    env : gymnasium.Env or VecEnv, optional
        What the model will step; None: one env of the run's own configuration.
    device : str
        torch's device.

    Raises
    ------
    ModelFileError
        No state, a modified tensors file, or a network other than the run's.
    """
    _require_rl()
    folder, document = latest_state(checkpoint)
    config = resume_config(checkpoint)  # the settings checked as a resume checks them
    if env is None:
        from stable_baselines3.common.vec_env import DummyVecEnv

        env = DummyVecEnv([_env_factory(config)])
    model = build_model(config, env, device=device)
    _load_state(model, folder, document)
    return model


def train(
    config: TrainConfig,
    out: str | Path,
    progress: bool = True,
    resume: bool = False,
    backend: str = "local",
    address: str | None = None,
):
    """Train, write checkpoints and the final policy into ``out``.

    Parameters
    ----------
    config : TrainConfig
    out : str or Path
        The run folder: checkpoints, the learning curve, the final policy and its resumable state.
    progress : bool
        A progress bar.
    resume : bool
        Continue the run in ``out`` from its latest state (:func:`latest_state`), with its
        optimiser, up to ``config.timesteps`` in all; behaviour cloning is not repeated.
    backend : {"local", "ray"}
        Where rollouts are collected: ``"local"``, ``config.envs`` worker processes stepped in
        lockstep (stable-baselines3's ``SubprocVecEnv``); ``"ray"``, ``config.envs`` Ray actors that
        each collect their share of a rollout on their own (:mod:`train.ray_rollouts`).
    address : str, optional
        The Ray cluster to join (``"auto"`` or ``host:port``); None starts a local instance.

    Returns
    -------
    (Path or None, MaskablePPO)
        The final checkpoint's ``policy.json`` and the trained model; ``model.interrupted`` is the
        signal that stopped the run early (None when it ran to the end). The path is None when a
        signal stopped the run during behaviour cloning, before there was a state to save.

    Raises
    ------
    ModelFileError
        ``config.init`` or the state to resume from cannot be read.
    FileExistsError
        A new run's ``out`` holds a run, a checkpoint or a file a run writes
        (:func:`run_folder_problem`).
    OSError
        The disk holding ``out`` has no room for one saved state (:func:`check_disk`, before the
        work), or a file of the run could not be written; either names the path.
    train.outputs.OutputBusyError
        Another process is training in ``out`` (or writing a comparison or a report there).
    """
    from train.outputs import Output, claimed

    out = Path(out)
    made = not os.path.lexists(out)
    # Held for the run: a second run (or resume) of the same folder meanwhile is refused before it
    # looks at the folder (two runs into one --out left one run and both runs' TensorBoard logs).
    with claimed([Output("--resume" if resume else "--out", out)]):
        before = set() if resume or made or not out.is_dir() else {p.name for p in out.iterdir()}
        try:
            with _tensorboard_failures(out / "tb"):
                final, model = _train(config, out, progress, resume, backend, address)
        except BaseException:
            if not resume:
                _discard_unstarted(out, before, made)
            raise
        if final is None and not resume:  # stopped while cloning: no state a resume could use
            _discard_unstarted(out, before, made)
        return final, model


#: The start of the names of TensorBoard's event files.
EVENTS = "events.out.tfevents."


@contextlib.contextmanager
def _tensorboard_failures(folder: Path):
    """A failed write of TensorBoard's event file (a full disk) reported once, naming the file.

    TensorBoard writes from a thread of its own: its error was printed there as a traceback, then
    raised again at the next flush in the training's thread, as an OSError naming no file. Here the
    thread's copy is not printed, the training's names the event file, and an event file the run
    made and left empty is removed (each failed try left one).
    """
    hook = threading.excepthook

    def quiet(args) -> None:
        if type(args.thread).__name__ != "_AsyncWriterThread":  # tensorboard's writer thread
            hook(args)

    before = set(folder.rglob(f"{EVENTS}*")) if folder.is_dir() else set()
    threading.excepthook = quiet
    try:
        yield
    except BaseException as exc:
        made = sorted(set(folder.rglob(f"{EVENTS}*")) - before) if folder.is_dir() else []
        for path in made:
            with contextlib.suppress(OSError):
                if path.stat().st_size == 0:
                    path.unlink()
        if isinstance(exc, OSError) and not exc.filename and _raised_in_tensorboard(exc):
            named = made[-1] if made else folder
            raise OSError(exc.errno, exc.strerror or str(exc), str(named)) from exc
        raise
    finally:
        threading.excepthook = hook


def _raised_in_tensorboard(exc: BaseException) -> bool:
    frame = exc.__traceback__
    while frame is not None:
        if f"{os.sep}tensorboard{os.sep}" in frame.tb_frame.f_code.co_filename:
            return True
        frame = frame.tb_next
    return False


def _discard_unstarted(out: Path, before: set[str], made: bool) -> None:
    """Remove what a new run wrote into ``out`` when it ended before it had a state to resume from
    (a failure or a signal before its first save): its empty curve and logs made the folder one
    that a rerun of the same command refused, and that ``--resume`` could not continue."""
    if any(out.glob(f"**/{STATE_JSON}")):
        return
    with contextlib.suppress(OSError):
        for entry in out.iterdir():
            if entry.name not in before:
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    entry.unlink()
        if made:
            out.rmdir()  # only when nothing is left in it


def _train(
    config: TrainConfig, out: Path, progress: bool, resume: bool, backend: str, address: str | None
) -> tuple[Path | None, Any]:
    """:func:`train`'s work, in a run folder that :func:`train` cleans up if it leaves no state."""
    _require_rl()
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    from policies import GreedyPolicy
    from train.stopping import StopRequest

    if backend not in ("local", "ray"):
        raise ConfigError(f"backend must be 'local' or 'ray', got {backend!r}")
    network = config.network
    out = Path(out)
    if resume and (problem := checkpoint_problem(out) or resume_folder_problem(out)) is not None:
        raise ModelFileError(problem)  # the second found at the run's end, after all its steps
    if not resume and (problem := run_folder_problem(out)) is not None:
        raise FileExistsError(problem)
    state = latest_state(out) if resume else None
    # Read before any worker starts: what behaviour cloning measured, which a resumed run goes on with.
    cloned = _clone_record(out, config) if state is not None else None
    # Checked before anything is built or written: what the options claim, and where Ray would run.
    check_memory(config, backend, behaviour_cloning=bool(config.bc_steps) and state is None)
    check_workers(config, backend, address)
    check_disk(config, out)
    if backend == "ray":
        _check_ray(address)
    # Checked before any worker starts: a bad checkpoint fails at once, not after the envs are up.
    initial = _load_init(config.init, network) if config.init and state is None else None
    out.mkdir(parents=True, exist_ok=True)
    done_before = 0 if state is None else int(state[1]["timesteps"])
    if backend == "ray":
        venv = ray_rollouts(config, address=address, seed=config.seed + done_before)
    else:
        venv = make_training_envs(config, seed=config.seed + done_before)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    model = build_model(config, venv, device, str(out / "tb") if _has_tensorboard() else None)
    if state is not None:
        _load_state(model, *state)
    elif initial is not None:  # the encoder and scorer from the checkpoint; the value head starts afresh
        model.policy.features_extractor.encoder.load_state_dict(initial[0].state_dict())
        model.policy.action_net.load_state_dict(initial[1].state_dict())
        _check_scores(model, venv, config.init)
    if backend == "ray":
        venv.attach(model)
    held_out = [VALIDATION_BASE + k for k in range(config.eval_storeys)]
    # Every checkpoint records the run and the full configuration its envs ran with: what a user of
    # it reproduces, and the room rules the policy then requires (policies.learned.trained_rules).
    recorded = {**config.to_dict(), "config": config.env_config().to_dict()}
    log = out / CURVE
    # A resumed run's curve is read whole before any step: a damaged one was found by the plot at the
    # end of the session, after the training it records had been done.
    earlier = _curve(log) if state is not None else []
    # Which run the folder's records are of: a state copied in from another run's folder resumed that
    # run here, beside this one's curve and logs.
    run_id = secrets.token_hex(8) if state is None or state[1].get("run_id") is None else state[1]["run_id"]
    others = sorted({r["run"] for r in earlier if r.get("run", run_id) != run_id})
    if others:
        raise ModelFileError(
            f"{log}: its records are of another run ({others[0]}) than the training state beside it ({run_id}): "
            "the state files were copied from another run's folder; resume that run in its own folder"
        )
    if earlier and earlier[-1]["timesteps"] > done_before:
        # Evaluations after the last saved state (a run killed before its next save): the steps they
        # measured are taken again, and so are they.
        earlier = [r for r in earlier if r["timesteps"] <= done_before]
        write_text(log, "".join(json.dumps(r) + "\n" for r in earlier))
    if state is None:
        write_text(log, "")
    greedy = GreedyPolicy()
    baseline = taught = None
    if config.eval_every:
        # A resumed run's greedy and teacher are the ones its curve already holds: the same storeys,
        # the same robot.
        baseline = earlier[-1]["greedy"] if earlier and earlier[-1].get("greedy") else None
        taught = earlier[-1].get("teacher") if earlier else None
        if baseline is None:
            baseline = evaluate(greedy.act, held_out, config.max_episode_steps, config.evaluation_config())
        if taught is None and config.bc_steps:
            # The teacher on the same storeys: what a policy that learned beyond its clone must beat at
            # equal coverage (its stop is where it declares rooms done, as in behaviour cloning).
            tutor = _teacher(config.bc_teacher)
            taught = evaluate(
                tutor.act, held_out, config.max_episode_steps, config.evaluation_config(), room_rule=tutor.stop
            )

    dual: CostWeight | None = None
    split = bool(config.hold_coverage)  # build_model gave the critic two heads
    if split:
        from train import critic

    def weight() -> float:
        return 1.0 if dual is None else dual.weight

    def checkpoint(n: int) -> None:
        folder = out / f"checkpoint_{n}"
        made = not os.path.lexists(folder)
        try:
            save_checkpoint(folder, network, _state_dict(model), _layout(model), recorded)
            save_training_state(model, folder, config, weight(), run_id)
        except BaseException:
            if made:  # a checkpoint is whole or absent: a full disk left an empty or policy-only folder
                shutil.rmtree(folder, ignore_errors=True)
            raise

    class Progress(BaseCallback):
        def _on_training_start(self) -> None:
            # SB3 collects whole rollouts, so it stops at the next multiple of n_steps × envs.
            rollout = config.n_steps * config.envs
            total = done_before + -(-(config.timesteps - done_before) // rollout) * rollout
            self.bar = tqdm(total=total, initial=done_before, unit="step", disable=not progress, dynamic_ncols=True)
            self.last_eval = done_before
            self.last_checkpoint = done_before
            self.episodes: list[float] = []
            if config.eval_every and warm is not None and done_before == 0:
                self._evaluate(0)  # the behaviour-cloned start

        def _on_rollout_start(self) -> None:
            # Until the rollout's update, the weights and Adam's state are the last update's: a
            # state saved now with this count of steps is one the run could have saved then.
            self.rollout_start: int | None = self.model.num_timesteps

        def _on_rollout_end(self) -> None:
            self.rollout_start = None
            if split:
                buffer, policy = self.model.rollout_buffer, self.model.policy
                explained = critic.finish_rollout(
                    buffer, policy, self.model._last_obs, self.model._last_episode_starts, self.model.gamma,
                    self.model.gae_lambda,
                )  # fmt: skip
                for name, value in explained.items():
                    if value is not None:
                        self.logger.record(f"train/{name}", value)
            if dual is not None:
                dual.update()
                if split:  # the next rollout's values at the new weight
                    self.model.policy.value_net.price_weight.fill_(dual.weight)
                self.logger.record("train/cost_weight", dual.weight)
                if dual.last_mean is not None:
                    self.logger.record("train/mapped", dual.last_mean)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            if dual is not None:  # before the rollout buffer holds the rewards
                dual.reweigh(self.locals["rewards"], self.locals["infos"], self.locals["dones"])
            if split:
                critic.record_step(
                    self.model.rollout_buffer, self.model.policy, self.locals["infos"], self.locals["dones"],
                    self.model.gamma,
                )  # fmt: skip
            for info in self.locals.get("infos", []):
                if "episode" in info:
                    self.episodes.append(float(info["episode"]["r"]))
            n = self.num_timesteps
            if stop.signal is not None:
                return False
            if config.checkpoint_every and n - self.last_checkpoint >= config.checkpoint_every:
                self.last_checkpoint = n
                checkpoint(n)
            if config.eval_every and n - self.last_eval >= config.eval_every:
                self.last_eval = n
                self._evaluate(n)
            return True

        def _evaluate(self, n: int) -> None:
            def act(obs, info):
                action, _ = self.model.predict(
                    {k: v[None] for k, v in obs.items()}, deterministic=True, action_masks=info["action_mask"][None]
                )
                return int(action[0])

            learned = evaluate(act, held_out, config.max_episode_steps, config.evaluation_config())
            record = {"timesteps": n, "run": run_id, "learned": learned, "greedy": baseline}
            if taught is not None:
                record["teacher"] = taught
            record["train_return"] = float(np.mean(self.episodes[-20:])) if self.episodes else None
            if dual is not None:
                record["cost_weight"], record["mapped"] = dual.weight, dual.last_mean
            record["seconds"] = time.time() - started
            # The whole curve again rather than an appended line: a full disk leaves the previous one.
            write_text(log, (log.read_text() if log.is_file() else "") + json.dumps(record) + "\n")

        def _on_training_end(self) -> None:
            self.bar.close()

    started = time.time()
    warm = None
    progress_callback = None
    stop: StopRequest | None = None
    try:
        # A step on a large storey can take minutes: a stop not reached in STOP_WAIT_S is escalated,
        # and the run keeps its last update's state (the rollout under way is dropped).
        with StopRequest(escalate_after=STOP_WAIT_S) as stop:
            if config.bc_steps and state is None:
                teacher = _teacher(config.bc_teacher)
                warm = behaviour_clone(model, config.bc_steps, progress=progress, teacher=teacher, stop=stop)
                if warm is None:  # stopped while cloning: nothing learned yet that a resume could use
                    venv.close()
                    model.interrupted = stop.signal
                    return None, model
            if warm is not None:
                write_text(out / CLONE_RECORD, json.dumps(warm, indent=1))
                if config.checkpoint_every:  # the behaviour-cloned start, a policy of its own to compare
                    checkpoint(0)
            elif state is not None:
                warm = cloned
            if config.hold_coverage:
                target = warm.get("mapped") if isinstance(warm, dict) else None
                if target is None:
                    raise ConfigError(
                        f"hold_coverage: no finished episode of the teacher to hold ({out / CLONE_RECORD}"
                        f" has none); raise --bc-steps so that the teacher finishes storeys"
                    )
                dual = CostWeight(
                    config.hold_coverage, target, 1.0 if state is None else state[1].get("cost_weight", 1.0)
                )
                model.policy.value_net.price_weight.fill_(dual.weight)
            progress_callback = Progress()
            progress_callback.rollout_start = None
            model.learn(
                total_timesteps=max(0, config.timesteps - done_before),
                callback=progress_callback,
                reset_num_timesteps=state is None,
            )
    except KeyboardInterrupt as exc:  # a second signal, or the first escalated: no wait for the rollout's end
        received = None if stop is None else stop.signal
        exc.signal = received or signal.SIGINT  # what _run exits with: 143 for a SIGTERM escalated
        with StopRequest() as again, again.hold():
            again.signal = exc.signal  # as if received: a third one is held too while the state is written
            start = None if progress_callback is None else progress_callback.rollout_start
            if start is not None and start > done_before:
                model.num_timesteps = start  # the rollout under way is dropped: it would be collected again
                save_training_state(model, out, config, weight(), run_id)
            with contextlib.suppress(Exception):
                venv.close()
        raise
    except BaseException:  # a file that could not be written, a failed worker: end the workers too
        with contextlib.suppress(Exception):
            venv.close()
        raise
    venv.close()
    start = progress_callback.rollout_start if progress_callback is not None else None
    if stop.signal is not None and start is not None:
        # Stopped mid-rollout: stable-baselines3 drops the rollout under way (no update learns from
        # it) but counted its steps; the state is the last update's, and --resume collects it again.
        model.num_timesteps = start
    seconds = time.time() - started + (0.0 if state is None else float(_previous_seconds(out)))
    training = {
        **recorded,
        "seconds": seconds,
        "timesteps_done": int(model.num_timesteps),
        "device": device,
        "algo": "maskable_ppo",
        "backend": backend,
        "behaviour_cloning": warm,
    }
    final = save_checkpoint(out, network, _state_dict(model), _layout(model), training=training)
    save_training_state(model, out, config, weight(), run_id)
    plot_learning_curve(log, out / "learning_curve.png")
    # TensorBoard's last events written now, where a failure is reported (it flushed in a thread, at exit).
    model.logger.close()
    model.interrupted = stop.signal
    return final, model


#: The figures of each policy in a learning-curve record, as :func:`evaluate` gives them.
CURVE_FIGURES = ("structure_sensed_pct", "scans", "path_length_m")
#: The most each figure can be: a percentage, a count of scans, metres of path (10 km).
CURVE_BOUNDS = {"structure_sensed_pct": 100.0, "scans": float(MAX_SCANS), "path_length_m": 1e4}
#: The record's other figures: the mean training return, the prices' weight, the mapped structure
#: of the last training episodes and the run's seconds.
CURVE_NUMBERS = ("train_return", "cost_weight", "mapped", "seconds")


def _curve(log: Path) -> list[dict]:
    """The records of ``learning_curve.jsonl`` (none where there is no file), each checked to be one
    that :func:`plot_learning_curve` and a resumed run can use.

    Raises
    ------
    ModelFileError
        Naming the line that is no JSON object or lacks a figure.
    """
    if not log.exists():
        return []
    try:
        if not log.is_file():
            raise ValueError("not a regular file")
        if log.stat().st_size > MAX_JSON_BYTES:
            raise ValueError(f"more than the {MAX_JSON_BYTES:,} bytes a curve of nbs-env may hold")
        text = log.read_text(encoding="utf-8-sig")  # a byte-order mark, as RFC 8259 allows
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ModelFileError(f"{log}: cannot be read as a learning curve ({exc})") from None
    records = []
    for k, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            record = read_json(line)
        except json.JSONDecodeError as exc:
            raise ModelFileError(f"{log}: line {k} is not JSON ({exc}); remove it to continue") from None
        problem = _curve_record_problem(record)
        if problem is None and records and record["timesteps"] < records[-1]["timesteps"]:
            problem = f"has timesteps {record['timesteps']}, before the line above's {records[-1]['timesteps']}"
        if problem:
            raise ModelFileError(f"{log}: line {k} {problem}; remove it to continue")
        records.append(record)
    return records


def _curve_record_problem(record: Any) -> str | None:
    """What makes one learning-curve record unusable, or None."""
    if not isinstance(record, dict):
        return "is not a record (a JSON object)"
    if not isinstance(record.get("run", ""), str):
        return f"has run {json_text(record['run'], 40)}, not a run's id"
    steps = record.get("timesteps")
    if type(steps) is not int or not 0 <= steps <= MAX_STATE_TIMESTEPS:
        return f"has timesteps {json_text(steps, 40)}, not a count of steps (0..{MAX_STATE_TIMESTEPS:,})"
    for policy in ("learned", "greedy", "teacher"):
        figures = record.get(policy)
        if figures is None and policy != "learned":
            continue
        if not isinstance(figures, dict):
            return f"has no {policy} figures (a JSON object of {', '.join(CURVE_FIGURES)})"
        for key in CURVE_FIGURES:
            value = figures.get(key)
            if type(value) not in (int, float) or not math.isfinite(value):
                return f"has {policy}.{key} {json_text(value, 40)}, not a finite number"
            high = CURVE_BOUNDS[key]
            if not 0 <= value <= high:  # read back as the run's baseline: a figure out of its meaning steered it
                return f"has {policy}.{key} {json_text(value, 40)}, outside [0, {high:g}]"
    for key in CURVE_NUMBERS:  # what the record adds when it has it (a number, or null where unknown)
        value = record.get(key)
        if value is not None and (type(value) not in (int, float) or not math.isfinite(value)):
            return f"has {key} {json_text(value, 40)}, not a finite number or null"
    return None


def _previous_seconds(out: Path) -> float:
    """The seconds the run's earlier sessions took, as its last policy.json recorded them (0 where
    it records no count of seconds: a string "nan" once went into the next policy.json as NaN, and a
    401-digit number was an OverflowError after the resumed session's work)."""
    try:
        seconds = read_json_file(out / "policy.json")["training"]["seconds"]
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0
    if type(seconds) not in (int, float) or not 0 <= seconds < 1e12:  # NaN fails too
        return 0.0
    return float(seconds)


def _check_scores(model, venv, path: str) -> None:
    """Refuse a start whose network scores an observation NaN or inf (weights that overflow float32):
    the first rollout raised a traceback from torch's distribution. The observation is a sample of
    the space, not an env's: the run's storeys stay those its seed gives."""
    import torch

    sample = venv.observation_space.sample()
    batch = {key: np.asarray(value)[None] for key, value in sample.items()}
    with torch.no_grad():
        tensor, _ = model.policy.obs_to_tensor(batch)
        logits = model.policy.action_net(
            model.policy.mlp_extractor.forward_actor(model.policy.extract_features(tensor))
        )
    if not bool(torch.isfinite(logits).all()):
        raise ModelFileError(
            f"{path}: the network's scores are not finite for an observation (its weights overflow float32): "
            "it cannot start a run"
        )


def _load_init(path: str, network: NetworkConfig):
    """The encoder and scorer of the checkpoint a run starts from.

    Raises
    ------
    ModelFileError
        The checkpoint cannot be read, or its network is not ``network``.
    """
    from policies.learned import load_checkpoint, resolve_checkpoint

    theirs, encoder, scorer, _, _ = load_checkpoint(resolve_checkpoint(path))
    if theirs != network:
        mine, other = network.to_dict(), theirs.to_dict()
        apart = ", ".join(f"{k} {other.get(k)!r} against {mine.get(k)!r}" for k in mine if other.get(k) != mine.get(k))
        hint = ""
        if (theirs.actions > theirs.candidates) != (network.actions > network.candidates):
            hint = f": it was trained with --completion {'policy' if theirs.actions > theirs.candidates else 'gain'}"
        raise ModelFileError(f"{path}: its network is not this run's ({apart}){hint}")
    return encoder, scorer


def _teacher(name: str):
    """The :class:`policies.GreedyPolicy` named ``name``, or ConfigError."""
    from policies import GreedyPolicy, UnknownPolicyError, make_policy

    if str(name).partition(":")[0] != "greedy":
        # Refused by name, before make_policy would load a checkpoint (ppo:PATH) only to refuse it.
        raise ConfigError(f"bc_teacher must name a greedy (greedy or greedy:OPTIONS), got {name!r}")
    try:
        teacher = make_policy(name)
    except UnknownPolicyError as exc:
        raise ConfigError(f"bc_teacher: {exc}") from None
    if not isinstance(teacher, GreedyPolicy):  # "greedy" registered to something else
        raise ConfigError(f"bc_teacher must name a greedy, got {name!r}")
    return teacher


def behaviour_clone(
    model, steps: int, epochs: int = 30, batch_size: int = 64, progress: bool = False, teacher=None, stop=None
) -> dict | None:
    """Warm-start the policy on a greedy's decisions: play the greedy in the training envs for
    ``steps`` vector steps, then fit the masked logits to its choices by cross-entropy. With a
    "room done" action (completion="policy") the greedy declares the room done where the robot's
    gain rule would end it at the teacher's completion fraction (``NBSEnv.gain_rule_done``, the
    robot's own plan; the robot's fraction when the teacher sets none).

    ``teacher``: a :class:`policies.GreedyPolicy` (None: the paper's greedy). ``stop``: an object
    whose ``signal`` turns non-None when the run is asked to stop; the clone then ends at once and
    returns None.

    Returns ``{"samples", "loss_first", "loss_last", "agreement", "teacher", "rooms_declared",
    "episodes", "mapped"}``: agreement is the share of the samples where the policy's masked argmax
    equals the greedy's choice after fitting; rooms_declared how many of the teacher's choices were
    "room done"; mapped the mean structure the robot mapped (``info["mapped_pct"]`` at the end) in
    the teacher's ``episodes`` finished episodes (None when none finished).
    """
    import torch
    from sb3_contrib.common.maskable.utils import get_action_masks

    from policies import GreedyPolicy

    venv = model.env
    greedy = GreedyPolicy() if teacher is None else teacher
    obs = venv.reset()
    samples: list[tuple[dict, np.ndarray, np.ndarray]] = []
    # The structure the teacher's finished episodes mapped: what hold_coverage holds.
    mapped: list[float] = []
    rewards: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    for _ in range(steps):
        if stop is not None and stop.signal is not None:
            return None
        masks = get_action_masks(venv)
        # The greedy's own rule, one env at a time, from what its info would hold.
        gains = venv.env_method("candidate_gains")
        room_action = masks.shape[1] > len(gains[0])
        done = venv.env_method("gain_rule_done", greedy.stop) if room_action else [False] * len(masks)
        actions = np.array(
            [
                greedy.act(
                    {key: value[i] for key, value in obs.items()},
                    {"candidate_gains": gains[i], "action_mask": masks[i], "gain_rule_done": done[i]},
                )
                for i in range(len(masks))
            ]
        )
        samples.append(({k: v.copy() for k, v in obs.items()}, masks.copy(), actions))
        obs, reward, dones, infos = venv.step(actions)
        if getattr(model.policy, "split_critic", False):  # each head fitted to its own term
            rewards.append(np.array([[i["reward_terms"]["gain"], i["reward_terms"]["cost"]] for i in infos]))
        else:
            rewards.append(np.asarray(reward, dtype=float))
        ends.append(np.asarray(dones, dtype=bool))
        mapped.extend(float(info["mapped_pct"]) for info, done in zip(infos, dones, strict=True) if done)
    policy = model.policy
    keys = samples[0][0].keys()
    all_obs = {k: np.concatenate([s[0][k] for s in samples]) for k in keys}
    all_masks = np.concatenate([s[1] for s in samples])
    all_actions = np.concatenate([s[2] for s in samples])
    n = len(all_actions)
    optimiser = torch.optim.Adam(policy.parameters(), lr=3e-3)
    rng = np.random.default_rng(0)
    losses = []
    policy.set_training_mode(True)
    for _ in range(epochs):
        order = rng.permutation(n)
        for start in range(0, n, batch_size):
            idx = order[start : start + batch_size]
            tensors, _ = policy.obs_to_tensor({k: v[idx] for k, v in all_obs.items()})
            dist = policy.get_distribution(tensors, action_masks=all_masks[idx])
            loss = -dist.log_prob(torch.as_tensor(all_actions[idx], device=policy.device)).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(loss.item())
    policy.set_training_mode(False)
    chosen = []
    with torch.no_grad():  # in minibatches: the encoder's activations for every sample at once grow with bc_steps
        for start in range(0, n, batch_size):
            part = slice(start, start + batch_size)
            tensors, _ = policy.obs_to_tensor({k: v[part] for k, v in all_obs.items()})
            dist = policy.get_distribution(tensors, action_masks=all_masks[part])
            chosen.append(dist.get_actions(deterministic=True).cpu().numpy())
    agreement = float((np.concatenate(chosen) == all_actions).mean())
    value_fit = fit_value(model, all_obs, np.stack(rewards), np.stack(ends), epochs=epochs, batch_size=batch_size)
    return {
        "samples": n,
        "loss_first": losses[0],
        "loss_last": losses[-1],
        "agreement": agreement,
        "teacher": greedy.name,
        "rooms_declared": int((all_actions == all_masks.shape[1] - 1).sum()) if room_action else 0,
        "episodes": len(mapped),
        "mapped": float(np.mean(mapped)) if mapped else None,
        **value_fit,
    }


def discounted_returns(rewards: np.ndarray, ends: np.ndarray, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """Each step's discounted return to its episode's end, from a vector env's rollout.

    Parameters
    ----------
    rewards, ends : (T, E) float, (T, E) bool
        The reward of each step of each env, and whether the episode ended with that step.
    gamma : float

    Returns
    -------
    returns : (T * E,) float
        G_t = r_t + gamma (1 - end_t) G_{t+1}, in the rollout's order (step-major, as its samples).
    complete : (T * E,) bool
        Whether the step's episode ended within the rollout: the others' returns are cut short.
    """
    returns = np.zeros_like(rewards, dtype=float)
    complete = np.zeros_like(ends, dtype=bool)
    running = np.zeros(rewards.shape[1])
    ended = np.zeros(rewards.shape[1], dtype=bool)
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + gamma * np.where(ends[t], 0.0, running)
        ended |= ends[t]
        returns[t], complete[t] = running, ended
    return returns.reshape(-1), complete.reshape(-1)


#: The fewest minibatch updates :func:`fit_value` makes.
VALUE_UPDATES = 1500


def fit_value(
    model, obs: dict[str, np.ndarray], rewards: np.ndarray, ends: np.ndarray, epochs: int = 30, batch_size: int = 64
) -> dict:
    """Fit the critic to the teacher's discounted returns, the encoder left as cloning made it.

    A critic that starts from nothing explains none of the return for thousands of PPO steps (run
    hold1: explained variance 0.000 over 41 updates), and its advantages are then noise; after
    cloning, the teacher's own episodes are returns of the policy PPO starts from. Only the value
    branch learns (the features are shared with the policy: fitting them would undo the clone).
    One sample in five is held out to measure the fit.

    ``rewards`` (T, E) for a critic of one head, (T, E, 2) for a split one (:mod:`train.critic`):
    the gain and the price of each step, each head fitted to its own return.

    Returns ``{"value_samples", "value_explained_variance"}``: the complete-episode samples and the
    explained variance of the held-out returns (None when too few episodes ended); for a split
    critic, of the returns of the env's own reward (gain - price, the weight 1 a run starts at).
    """
    import torch

    policy = model.policy
    split = rewards.ndim == 3
    if split:
        (gains, complete), (prices, _) = (discounted_returns(rewards[..., k], ends, model.gamma) for k in range(2))
        returns = np.stack([gains, prices], axis=1)
    else:
        returns, complete = discounted_returns(rewards, ends, model.gamma)
    index = np.flatnonzero(complete)
    if len(index) < 10:
        return {"value_samples": len(index), "value_explained_variance": None}
    with torch.no_grad():  # the encoder once for every sample, in minibatches
        parts = []
        for start in range(0, len(index), batch_size):
            tensors, _ = policy.obs_to_tensor({k: v[index[start : start + batch_size]] for k, v in obs.items()})
            parts.append(policy.extract_features(tensors))
        features = torch.cat(parts)
    target = torch.as_tensor(returns[index], dtype=torch.float32, device=policy.device)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(index))
    held, fit = order[: len(order) // 5], order[len(order) // 5 :]
    branch = [*policy.mlp_extractor.value_net.parameters(), *policy.value_net.parameters()]
    optimiser = torch.optim.Adam(branch, lr=1e-3)

    def values(rows: np.ndarray) -> torch.Tensor:
        latent = policy.mlp_extractor.forward_critic(features[rows])
        return policy.value_net.heads(latent) if split else policy.value_net(latent).flatten()

    policy.set_training_mode(True)
    # A small network on fixed features: cheap, and slower to fit than the clone; at least
    # VALUE_UPDATES minibatches however few the samples.
    rounds = max(epochs * 3, -(-VALUE_UPDATES // -(-len(fit) // batch_size)))
    for _ in range(rounds):
        rng.shuffle(fit)
        for start in range(0, len(fit), batch_size):
            rows = fit[start : start + batch_size]
            loss = torch.nn.functional.mse_loss(values(rows), target[rows])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    policy.set_training_mode(False)
    with torch.no_grad():
        predicted, actual = values(held), target[held]
        if split:  # the env's own return: gain - price
            predicted, actual = predicted[:, 0] - predicted[:, 1], actual[:, 0] - actual[:, 1]
        error = (predicted - actual).cpu().numpy()
    spread = float(actual.var(unbiased=False))
    explained = 1.0 - float(error.var()) / spread if spread > 0 else None
    return {"value_samples": len(index), "value_explained_variance": explained}


def plot_learning_curve(log: str | Path, out: str | Path) -> Path | None:
    """``learning_curve.png`` from ``learning_curve.jsonl``: the learned policy's SE %, scans and path
    on the validation storeys against timesteps, with the greedy's as lines. None when nothing was
    evaluated."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    records = _curve(Path(log))
    if not records:
        return None
    steps = [r["timesteps"] for r in records]
    fig = Figure(figsize=(12, 3.6), dpi=110)
    FigureCanvasAgg(fig)
    panels = (("structure_sensed_pct", "SE sensed (%)"), ("scans", "scans"), ("path_length_m", "path (m)"))
    for k, (key, label) in enumerate(panels):
        ax = fig.add_subplot(1, 3, k + 1)
        ax.plot(steps, [r["learned"][key] for r in records], "o-", label="learned (validation storeys)")
        if records[0].get("greedy"):
            ax.axhline(records[0]["greedy"][key], color="k", ls="--", label="greedy")
        if records[-1].get("teacher"):
            ax.axhline(records[-1]["teacher"][key], color="tab:orange", ls=":", label="teacher")
        ax.set_xlabel("PPO timesteps (0: after behaviour cloning)" if steps[0] == 0 else "PPO timesteps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(out)
    with replacing(path) as temporary:
        fig.savefig(temporary)
    return path


def _has_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def build_parser() -> argparse.ArgumentParser:
    from train.outputs import output_path
    from train.ray_connect import ADDRESS_HELP

    p = argparse.ArgumentParser(prog="nbs train", description="Train a masked PPO agent on generated storeys.")
    p.add_argument("--algo", choices=("maskable_ppo",), default="maskable_ppo")
    p.add_argument("--timesteps", type=whole, default=None, help="PPO timesteps in all (default 2048)")
    p.add_argument("--envs", type=whole, default=2)
    p.add_argument("--seed", type=whole, default=0)
    p.add_argument("--rooms", default="1-5", help="room range of the training storeys, e.g. 1-5")
    p.add_argument("--eval-every", type=whole, default=0, help="timesteps between evaluations (0: none)")
    p.add_argument("--checkpoint-every", type=whole, default=0, help="timesteps between checkpoints (0: none)")
    p.add_argument("--bc-steps", type=whole, default=0, help="vector steps of greedy play to warm-start from (0: none)")
    p.add_argument(
        "--bc-teacher",
        default="greedy",
        help="the greedy behaviour cloning copies, e.g. greedy:stop=0.05 or greedy:0.8+stop=0.05 (default greedy)",
    )
    p.add_argument("--eval-storeys", type=whole, default=4, help="validation storeys per evaluation")
    p.add_argument("--learning-rate", type=number, default=3e-4)
    p.add_argument("--n-steps", type=whole, default=64, help="steps per worker between PPO updates")
    p.add_argument("--metre-cost", type=number, default=0.05, help="reward per metre driven, subtracted")
    p.add_argument("--scan-cost", type=number, default=0.5, help="reward per scan, subtracted")
    p.add_argument("--ent-coef", type=number, default=0.0, help="PPO's entropy bonus")
    p.add_argument(
        "--hold-coverage",
        type=number,
        default=0.0,
        metavar="RATE",
        help="scale the prices between rollouts by exp(RATE x (mapped - teacher's)) so that the policy keeps its "
        "behaviour-cloning teacher's coverage (0, the default: fixed prices; needs --bc-steps)",
    )
    p.add_argument(
        "--stop-lr-scale",
        type=number,
        default=1.0,
        metavar="X",
        help="the 'room done' head's learning rate as X times --learning-rate (default 1, within 0.001-100; needs "
        "--completion policy)",
    )
    p.add_argument(
        "--completion",
        choices=("policy", "gain"),
        default="gain",
        help="who ends a room: the agent's 'room done' action (policy) or the robot's gain rule (gain, the default)",
    )
    p.add_argument("--max-episode-steps", type=whole, default=40, help="decisions per episode at the most")
    p.add_argument("--cell-size", default="2.0-3.6", help="range of the generator's cell edge in metres, e.g. 2.0-6.0")
    p.add_argument("--init", default="", help="checkpoint to start the network from (default: random weights)")
    p.add_argument("--out", type=output_path, help="the run folder (required unless --resume)")
    p.add_argument(
        "--resume",
        type=Path,
        metavar="RUN",
        help="continue the run in folder RUN from its latest state, optimiser included, with its own "
        "settings (--timesteps sets a new total; --backend, --address and --quiet apply)",
    )
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="where rollouts are collected: local worker processes (default) or Ray actors",
    )
    p.add_argument("--address", default=None, help=f"with --backend ray: {ADDRESS_HELP}")
    p.add_argument("--quiet", action="store_true")
    add_robot_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.address is not None and args.backend != "ray":
        print(
            f"nbs train: error: --address applies to --backend ray only (this run is --backend {args.backend})",
            file=sys.stderr,
        )
        return 2
    if args.resume is not None:
        return _resume(args, _given(argv))
    if args.out is None:
        print("nbs train: error: --out is required (or --resume RUN)", file=sys.stderr)
        return 2
    try:
        rooms = parse_range(args.rooms)
    except ValueError as exc:
        print(f"nbs train: error: --rooms: {exc}", file=sys.stderr)
        return 2
    try:
        # A or A-B: the range's "-" follows a digit or a point (not an exponent's "e"), and B is
        # not left out ("2.0-" is a slip, as parse_range refuses "2-").
        parts = re.fullmatch(r"\s*([^\s]*?[0-9.])(?:\s*-\s*(\S+))?\s*", args.cell_size)
        if parts is None:
            raise ValueError(args.cell_size)
        lo, hi = parts.group(1), parts.group(2)
        cell_size = (parse_float(lo), parse_float(hi if hi is not None else lo))
    except ValueError:
        print(f"nbs train: error: --cell-size: expected A-B in metres, got {args.cell_size!r}", file=sys.stderr)
        return 2
    problem = scene_option_error("generated", args.storey, args.y_up, args.ifc_doors, args.units)
    if problem is not None:
        print(f"nbs train: error: {problem} (nbs train scans generated storeys)", file=sys.stderr)
        return 2
    try:
        preset, overrides = config_from_arguments(args, "train", measured=False)
        config = TrainConfig(
            timesteps=2048 if args.timesteps is None else args.timesteps,
            envs=args.envs,
            seed=args.seed,
            rooms=rooms,
            eval_every=args.eval_every,
            checkpoint_every=args.checkpoint_every,
            bc_steps=args.bc_steps,
            bc_teacher=args.bc_teacher,
            eval_storeys=args.eval_storeys,
            learning_rate=args.learning_rate,
            n_steps=args.n_steps,
            metre_cost=args.metre_cost,
            scan_cost=args.scan_cost,
            ent_coef=args.ent_coef,
            preset=preset,
            overrides=overrides,
            completion=args.completion,
            max_episode_steps=args.max_episode_steps,
            cell_size=cell_size,
            init=args.init,
            hold_coverage=args.hold_coverage,
            stop_lr_scale=args.stop_lr_scale,
        )
    except ConfigError as exc:
        print(f"nbs train: error: {exc}", file=sys.stderr)
        return 2
    problem = _output_problem("--out", args.out)  # first: a name the system refuses fails every test
    if problem is not None:
        print(f"nbs train: error: {problem}", file=sys.stderr)
        return 2
    problem = run_folder_problem(args.out)
    if problem is not None:
        print(f"nbs train: error: --out {problem}", file=sys.stderr)
        return 2
    return _run(config, args.out, args, resume=False)


#: What a run writes in its folder, besides its ``checkpoint_N/`` folders.
RUN_FILES = (
    "policy.json",
    "policy.pt",
    STATE_JSON,
    STATE_FILE,
    CURVE,
    "learning_curve.png",
    CLONE_RECORD,
    "tb",
)


def run_folder_problem(out: str | Path) -> str | None:
    """Why a new run cannot be written into ``out`` (None when it can): it holds a run, a checkpoint
    (a ``--init`` folder), or any file a run writes, which the run would write over."""
    out = Path(out)
    if not out.is_dir():
        return None
    state = next(iter(sorted(out.glob(f"**/{STATE_JSON}"))), None)
    if state is not None:
        # The run is the state's folder, or the run a checkpoint_N folder belongs to.
        run = state.parent
        if run != out and re.fullmatch(r"checkpoint_\d+", run.name) and not (run / CURVE).exists():
            run = run.parent
        where = "a run already" if run == out else f"the run {run}"
        return f"{out} holds {where}; continue it with --resume {run}, or name another folder"
    held = sorted(name for name in RUN_FILES if os.path.lexists(out / name))
    held += sorted(p.name for p in out.glob("checkpoint_*") if re.fullmatch(r"checkpoint_\d+", p.name))
    if held:
        shown = ", ".join(held[:4]) + (", ..." if len(held) > 4 else "")
        return (
            f"{out} holds {shown} (a checkpoint's or a run's files), which this run would write over; "
            "name a new or empty folder"
        )
    return None


def resume_folder_problem(run: Path) -> str | None:
    """Why a resumed run could not write its files into its folder (None when it can): a file it
    writes there that is a folder, or a ``checkpoint_N`` that is a file. Found before the work: the
    run wrote them at its end, after all its steps."""
    for name in RUN_FILES:
        path = run / name
        if name != "tb" and path.is_dir():
            return f"{path} is a folder where the run writes its file: remove it or restore the file"
        if name == "tb" and os.path.lexists(path) and not path.is_dir():
            return f"{path} is a file where the run keeps its TensorBoard folder: remove it or restore the folder"
    for path in sorted(run.glob("checkpoint_*")):
        if re.fullmatch(r"checkpoint_\d+", path.name) and not path.is_dir():
            return f"{path} is a file where the run keeps a checkpoint folder: remove it or restore the folder"
    return None


def _output_problem(flag: str, folder: Path) -> str | None:
    """Why the run folder cannot be written (:mod:`train.outputs`), found before the run starts: a run
    of hours that finds it at its first checkpoint would lose them. None when it can."""
    from train.outputs import Output, OutputError, check_outputs

    try:
        check_outputs([Output(flag, folder, "folder")])
    except OutputError as exc:
        return str(exc)
    return None


#: What ``nbs train --resume`` takes besides the run: the rest are the run's own settings.
RESUME_OPTIONS = ("resume", "out", "timesteps", "envs", "backend", "address", "quiet")


def _given(argv: list[str] | None) -> set[str]:
    """The destinations of the options typed (not those left at their defaults)."""
    parser = build_parser()
    for action in parser._actions:
        action.default = argparse.SUPPRESS
    return set(vars(parser.parse_args(argv)))


def _resume(args, given: set[str]) -> int:
    if args.out is not None and Path(args.out) != Path(args.resume):
        print("nbs train: error: --resume continues in its own folder; leave out --out", file=sys.stderr)
        return 2
    ignored = sorted(f"--{name.replace('_', '-')}" for name in given - set(RESUME_OPTIONS))
    if ignored:
        # Dropped without a word, they would seem to have been applied (a resumed run's settings are its own).
        print(
            f"nbs train: error: --resume continues the run with its own settings; {', '.join(ignored)} "
            "apply to a new run (leave them out, or start one with --init RUN)",
            file=sys.stderr,
        )
        return 2
    problem = checkpoint_problem(args.resume)
    if problem is not None:  # refused before any work: its checkpoints would be written inside it
        print(f"nbs train: error: --resume {problem}", file=sys.stderr)
        return 2
    try:
        folder, document = latest_state(args.resume)
    except ModelFileError as exc:
        print(f"nbs train: error: --resume: {exc}", file=sys.stderr)
        return 2
    done = int(document["timesteps"])
    if args.timesteps is not None and args.timesteps > MAX_STATE_TIMESTEPS:  # the option's fault, not the file's
        print(
            f"nbs train: error: --timesteps {str(args.timesteps)[:40]}: must be at most {MAX_STATE_TIMESTEPS:,}",
            file=sys.stderr,
        )
        return 2
    # A total below the steps done would rewrite the policy and leave a state that says both; one
    # equal to them has nothing left to do, unless the run's own final state was never written (a full
    # disk at its end: its newest state is a checkpoint's, and resuming writes the final policy).
    if args.timesteps is not None and (
        args.timesteps < done or (args.timesteps == done and folder == Path(args.resume))
    ):
        more = done + max(done, 1)
        print(
            f"nbs train: error: --timesteps {args.timesteps}: the run has done {done} steps already; "
            f"ask for more (e.g. --timesteps {more})",
            file=sys.stderr,
        )
        return 2
    try:
        config = resume_config(args.resume, args.timesteps)
    except ModelFileError as exc:
        print(f"nbs train: error: --resume: {exc}", file=sys.stderr)
        return 2
    if args.timesteps is None and config.timesteps <= done and folder == Path(args.resume):
        # A finished run, resumed to its own total: no step to take, yet its records were rewritten
        # (with --envs 2 they said 2 envs for a run trained with 1).
        print(
            f"nbs train: error: --resume {args.resume}: the run has done its {done} steps; ask for more "
            f"(e.g. --timesteps {done + max(done, 1)})",
            file=sys.stderr,
        )
        return 2
    problem = _output_problem("--resume", args.resume)
    if problem is not None:  # a run folder that has become read-only since
        print(f"nbs train: error: {problem}", file=sys.stderr)
        return 2
    from train.outputs import odd_entry

    odd = odd_entry(Path(args.resume))
    if odd is not None:  # a fifo as its curve blocked the run's end for ever, deaf to signals
        print(
            f"nbs train: error: --resume {args.resume}: {odd[0]} is {odd[1]}; a run's files are its own: "
            "replace it by the file or remove it",
            file=sys.stderr,
        )
        return 2
    if "envs" in given:
        try:
            config = dataclasses.replace(config, envs=args.envs)
        except ConfigError as exc:  # the run's n_steps and batch size stay: only --envs can change
            print(f"nbs train: error: --resume {args.resume} --envs {args.envs}: {exc}", file=sys.stderr)
            return 2
    else:
        try:
            check_workers(config, args.backend, args.address)
        except ConfigError:  # the file's number, not an option the user typed
            most = 2 * (os.cpu_count() or 1)
            print(
                f"nbs train: error: --resume: {folder / STATE_JSON}: its run.envs is {config.envs}, more env "
                f"workers than this machine takes (at most {most}); continue with --envs {most} or fewer, or on a "
                "cluster with --backend ray --address",
                file=sys.stderr,
            )
            return 2
    return _run(config, args.resume, args, resume=True)


def _kept(out: Path, first: str) -> str:
    """What a run that ended early leaves to continue from, and what to do (``first``, then continue)."""
    try:
        _, saved = latest_state(out)
    except ModelFileError:
        return f"nothing was saved to continue from: {first}run the command again"
    return (
        f"the run keeps its last saved state ({saved['timesteps']} timesteps): {first}continue it with "
        f"nbs train --resume {out}"
    )


def _rounding(config: TrainConfig, out: Path, resume: bool) -> str:
    """The note a run that PPO's whole rollouts take past ``--timesteps`` ends with ("" for none):
    ``--timesteps 10`` with rollouts of 32 steps trained 32 without a word (``policy.json``'s
    ``timesteps_done`` records it). Worked out before the run, from the steps a resumed one had done."""
    done = 0
    if resume:
        with contextlib.suppress(ModelFileError):
            done = int(latest_state(out)[1]["timesteps"])
    rollout = config.n_steps * config.envs
    if config.timesteps > done and (config.timesteps - done) % rollout:
        end = done + -(-(config.timesteps - done) // rollout) * rollout
        return (
            f"nbs train: note: PPO trains whole rollouts of n_steps {config.n_steps} x {config.envs} env(s) = "
            f"{rollout} steps: --timesteps {config.timesteps} ran to {end}"
        )
    return ""


def _run(config: TrainConfig, out: Path, args, resume: bool) -> int:
    from train.outputs import OutputBusyError
    from train.stopping import exit_code

    rounding = _rounding(config, out, resume)
    try:
        path, model = train(
            config, out, progress=not args.quiet, resume=resume, backend=args.backend, address=args.address
        )
    except ModelFileError as exc:
        print(f"nbs train: error: {'--resume' if resume else '--init'}: {exc}", file=sys.stderr)
        return 2
    except OutputBusyError as exc:
        print(f"nbs train: error: {exc}", file=sys.stderr)
        return 2
    except ConfigError as exc:
        print(f"nbs train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # before the run's steps began, a second signal, or the first escalated
        kept = _kept(out, "")
        received = getattr(exc, "signal", None) or signal.SIGINT
        print(f"nbs train: stopped by {signal.Signals(received).name}; {kept}", file=sys.stderr)
        return exit_code(received)
    except (EOFError, BrokenPipeError, ConnectionResetError) as exc:  # a rollout worker that ended
        print(
            f"nbs train: error: a rollout worker process ended ({type(exc).__name__}); {_kept(out, '')}",
            file=sys.stderr,
        )
        return 1
    except OSError as exc:  # a file of the run that could not be written (a full disk): the last whole state stays
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"nbs train: error: {where}{exc.strerror or exc}; {_kept(out, 'make room and ')}", file=sys.stderr)
        return 1
    if model.interrupted is not None and path is None:
        print(
            f"nbs train: stopped by {signal.Signals(model.interrupted).name} during behaviour cloning; "
            f"{_kept(out, '')}",
            file=sys.stderr,
        )
        return exit_code(model.interrupted)
    if model.interrupted is not None:
        print(
            f"nbs train: stopped by {signal.Signals(model.interrupted).name} at {model.num_timesteps} timesteps; "
            f"the run is saved: continue it with nbs train --resume {out}",
            file=sys.stderr,
        )
        # 130 for Ctrl-C, 143 for SIGTERM, as nbs scan and nbs compare exit and shells report.
        return exit_code(model.interrupted)
    if rounding:
        print(rounding, file=sys.stderr)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
