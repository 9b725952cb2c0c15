"""NBSEnv: the scanning loop of the paper as a Gymnasium environment.

The env is a thin layer over a :class:`~nbs_env.storey.Storey` (the method over a storey: the
robot, the room-and-door loop, the coverage meter and the episode log). It adds what Gymnasium
asks for: spaces, ``reset`` and ``step``, the reward, the observation (from the robot's belief
only, :func:`nbs_env.observation.observe`), ``info``, rendering and pickling. One step reads
top-down: env → storey → robot → sensing and belief → planner.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from nbs_env.errors import ConfigError, InvalidActionError
from nbs_env.observation import CANDIDATE_FEATURES, ROOM_FEATURES, BeliefView, candidate_table_of, observe
from nbs_env.settings import PRESETS, EnvConfig, RewardConfig, make_config
from nbs_env.storey import STAGES, StageTimes, StepOutcome, Storey, resolve_scene
from scenes import Scene

__all__ = [
    "PRESETS",
    "STAGES",
    "BeliefView",
    "EnvConfig",
    "NBSEnv",
    "RewardConfig",
    "StageTimes",
    "candidate_table_of",
    "make_config",
]


class NBSEnv(gym.Env):
    """
    ## Description

    Autonomous next-best-scan planning of a building storey (Kim et al., "Autonomous Scanning of
    Structural Elements in Buildings"). A mobile robot with a 360°×100° terrestrial laser scanner
    stands in a storey of cluttered rooms joined by doors. At every stop it has scanned, registered
    the scan (ICP), found the room's region of interest (RoI), classified its wall faces as
    structural elements (SE) with an SVM, and labelled its voxel space V(t). The agent chooses the
    next scan among the next valid positions (NVPs). When the robot judges the room complete
    (no NVP predicts enough Occluded-structure→Structure conversions), it detects the room's doors,
    drives to the nearest unvisited one and takes the first scan of the next room, all inside the
    same step.

    ## Action Space

    `Discrete(K)` with K = `robot.navigation.max_candidates` (64): an index into the candidate
    list. Only the first `count` entries are real; `action_masks()` (and `info["action_mask"]`)
    says which. With `completion="policy"` the space is `Discrete(K + 1)` and action K, always
    allowed, declares the room complete (the robot then looks for the next door). A masked action
    takes no scan, costs `reward.invalid_action_penalty` and sets
    `info["invalid_action"] = True`. An action outside `Discrete(K)` raises `InvalidActionError`.

    ## Observation Space

    A flat `Dict`:

    - `voxels`: `observation.shape` (64, 64, 16) uint8, space 0..255, values 0..5. The
      `VoxelLabel`s of the current room's V(t) in a window of 0.2 m cells centred on the robot's
      estimated position, axis-aligned, from 0.2 m below its floor. Labels are pooled by priority
      Structure > Occluded-structure > Clutter > Occluded-clutter > Empty > Unknown; cells outside
      the grid are Unknown.
    - `candidates`: (K·5,) float32, row-major (K, 5); `nbs_env.observation.candidate_table_of(obs)`
      reshapes it and `nbs_env.observation.CandidateColumn` names the columns. Per NVP: dx, dy (m,
      world axes, from the robot), geodesic path length (m), predicted conversions as a share of
      the room's structural voxels, valid (1/0); zeros for padding.
    - `pose`: (4,) float32, the robot's pose estimate: x, y, z (m) and yaw (rad).
    - `room`: (5,) float32, the room being scanned (`nbs_env.observation.RoomColumn`): scans taken
      in it, the share of its structural voxels sensed (Structure over Structure +
      Occluded-structure), its structural surface as mapped (m²), the length of its frontier faces
      (m) and the rooms completed before it.

    Everything in the observation comes from the robot's own measurements and pose estimate. The
    shapes are those stable-baselines3 takes without a warning: `voxels` is image-like (its default
    `MultiInputPolicy` sees a 64×64 picture with 16 height channels), `candidates` is flat.

    ## Rewards

    `RewardConfig`. By default the increase of the true structural surface sensed, in percentage
    points of the storey's structural surface, minus `scan_cost` (0.5) per scan and `metre_cost`
    (0.05) per metre driven. `kind="conversions"` replaces the first term with the robot's own
    realised Occluded-structure→Structure conversions (% of the room's structural voxels): no
    ground truth.

    ## Starting State

    The robot stands at the scene's start position (its own map's origin) and has taken its first
    scan. `reset(seed=..., options={"scene": ..., "start": (x, y)})` picks the storey: anything
    `scenes.load_scene` takes, a `Scene` or `FloorPlan`, or `"generated"` (a fresh storey per
    reset from the env's random generator).

    ## Episode End

    `terminated` when the storey is complete: the current room is complete and no detected door is
    left that the robot can reach. `truncated` when `max_scans` scans have been taken, and through
    `max_episode_steps` of the registered ids.

    ## Arguments

    `NBSEnv(config=None, render_mode=None, **overrides)`: `config` is an `EnvConfig` or a preset
    name (`"default"`, `"fast"`); `overrides` replace top-level `EnvConfig` fields (e.g.
    `scene="five_rooms"`, `max_scans=30`). `render_mode="rgb_array"` draws a top-down picture.

    ## Registered Configurations

    | id | preset | scene | max_episode_steps |
    |---|---|---|---|
    | `nbs_env/NBS-v0` | default: 0.5° scanner, 5 cm voxels, odometry drift + ICP | generated 1-8 rooms | 80 |
    | `nbs_env/NBS-Fast-v0` | fast: 1° scanner, 10 cm voxels, perfect localisation | generated 1-3 rooms | 40 |
    | `nbs_env/NBS-FiveRooms-v0` | default | `five_rooms` | 60 |
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, config: EnvConfig | str | None = None, render_mode: str | None = None, **overrides: Any) -> None:
        if config is None or isinstance(config, str):
            config = make_config(config or "default", **overrides)
        elif overrides:
            config = replace(config, **overrides)
        if not isinstance(config, EnvConfig):
            raise ConfigError(f"config must be an EnvConfig or a preset name, got {type(config).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        self.config = config
        self.render_mode = render_mode
        k = config.robot.navigation.max_candidates
        self.max_candidates = k
        #: The "room done" action of completion="policy" (None otherwise).
        self.stop_action: int | None = k if config.completion == "policy" else None
        self.n_actions = k + (self.stop_action is not None)
        self.action_space = spaces.Discrete(self.n_actions)
        self.observation_space = spaces.Dict(
            {
                # uint8 in 0..255 is what stable-baselines3 expects of image-like arrays; only 0..5 occur.
                "voxels": spaces.Box(0, 255, shape=config.observation.shape, dtype=np.uint8),
                # Flat, because stable-baselines3 accepts 1-D and image-like arrays only.
                "candidates": spaces.Box(-1e4, 1e4, shape=(k * len(CANDIDATE_FEATURES),), dtype=np.float32),
                "pose": spaces.Box(-1e4, 1e4, shape=(4,), dtype=np.float32),
                "room": spaces.Box(-1e4, 1e4, shape=(len(ROOM_FEATURES),), dtype=np.float32),
            }
        )
        self._scene_cache: dict[str, Scene] = {}
        self._episode: dict[str, Any] | None = None  # what reset was given, for pickling
        self._actions: list[int] = []
        self._last = StepOutcome()
        self.storey: Storey | None = None

    @property
    def scene(self) -> Scene | None:
        """The true building of the episode (None before ``reset``)."""
        return None if self.storey is None else self.storey.scene

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"scene", "start"})
        if unknown:
            raise ConfigError(f"reset options {unknown} are not known; use 'scene' and 'start'")
        self._episode = {"rng_state": self.np_random.bit_generator.state, "options": options}
        self._actions = []
        self._start(options)
        return self._observation(), self._info()

    def _start(self, options: dict[str, Any]) -> None:
        config = self.config
        scene = resolve_scene(
            options.get("scene", config.scene), options.get("start"), config, self.np_random, self._scene_cache
        )
        self._last = StepOutcome()
        self.storey = Storey(scene, config, self.np_random, count_conversions=config.reward.kind == "conversions")

    def step(self, action: Any):
        storey = self._storey()
        a = self._check_action(action)
        storey.begin_step()
        if not storey.open:
            # Stepping past the end of an episode: nothing to do, nothing changes.
            return self._observation(), 0.0, storey.complete, not storey.complete, self._info()
        stop = a == self.stop_action
        if not self.action_masks()[a] or (not stop and storey.plan.count == 0):
            info = self._info(invalid_action=True)
            return self._observation(), -self.config.reward.invalid_action_penalty, False, False, info
        self._actions.append(a)
        self._last = storey.room_done() if stop else storey.scan_at(a)
        terminated = storey.complete
        truncated = not terminated and not storey.open
        return self._observation(), self._reward(self._last), terminated, truncated, self._info()

    def _reward(self, outcome: StepOutcome) -> float:
        cfg = self.config.reward
        if cfg.kind == "coverage":
            gain = outcome.coverage_gain
        else:
            gain = 100.0 * outcome.conversions / max(1, outcome.structural_voxels)
        return float(gain - cfg.scan_cost * outcome.scans - cfg.metre_cost * outcome.metres)

    def _storey(self) -> Storey:
        if self.storey is None:
            raise gym.error.ResetNeeded("call reset() first")
        return self.storey

    def _check_action(self, action: Any) -> int:
        # What Discrete.contains takes: a Python or numpy integer, or a 0-d integer array (not a
        # bool, not a float that happens to be whole, not a one-element list or array).
        integer = (isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_))) or (
            isinstance(action, np.ndarray) and action.shape == () and np.issubdtype(action.dtype, np.integer)
        )
        if not integer or not (0 <= int(action) < self.n_actions):
            raise InvalidActionError(
                f"action must be an integer in [0, {self.n_actions}) (int, numpy integer or 0-d integer array), "
                f"got {action!r} of type {type(action).__name__}"
            )
        return int(action)

    def action_masks(self) -> np.ndarray:
        """(n_actions,) bool: which actions are real candidates (sb3-contrib's MaskablePPO reads
        this); with completion="policy" the last, "room done", is always allowed."""
        mask = np.zeros(self.n_actions, dtype=bool)
        if self.storey is None:
            return mask
        if self.storey.open:
            mask[: self.max_candidates] = self.storey.plan.candidates.mask
            if self.stop_action is not None:
                mask[self.stop_action] = True
        if not mask.any():
            # A finished episode keeps one action so that a masked sampler always has a choice;
            # stepping it changes nothing.
            mask[0] = True
        return mask

    def gain_rule_done(self, fraction: float | None = None) -> bool:
        """Whether the robot's gain rule would end the room now (:meth:`Storey.gain_rule_done`; False
        before ``reset``): what the greedy declares by with ``completion="policy"``; also
        ``info["gain_rule_done"]``. ``fraction`` reads the rule at another completion fraction
        (None: the robot's)."""
        return self.storey is not None and self.storey.gain_rule_done(fraction)

    def candidate_gains(self) -> np.ndarray:
        """(K,) int64: predicted Occluded-structure→Structure conversions of each candidate, from the
        robot's own grid (the paper's greedy criterion); 0 for padding."""
        if self.storey is None or self.storey.complete:
            return np.zeros(self.max_candidates, dtype=np.int64)
        return self.storey.plan.gains.copy()

    # ------------------------------------------------------------------ observation and info
    def _observation(self) -> dict[str, np.ndarray]:
        return observe(self._storey().view(), self.config.observation)

    def _info(self, invalid_action: bool = False) -> dict[str, Any]:
        storey = self._storey()
        last = storey.scans[-1]
        m, deg = last.registration_error
        return {
            "scans": len(storey.scans),
            "room": storey.room,
            "rooms_done": storey.rooms_done,
            "structure_sensed_pct": storey.coverage_pct(),
            "path_length_m": storey.path_length,
            "times": StageTimes(dict(last.times)),
            "registration_error_m": m,
            "registration_error_deg": deg,
            # Why ICP's pose was refused and the odometry's kept (METHOD §2); empty when accepted.
            "registration_refused": last.registration_refused,
            "door_events": list(storey.door_events),
            "action_mask": self.action_masks(),
            "candidate_gains": self.candidate_gains(),
            "gain_rule_done": self.gain_rule_done(),
            "invalid_action": invalid_action,
            "conversions": self._last.conversions,
            "complete": storey.complete,
            **({"belief": storey.view()} if self.config.expose_belief else {}),
        }

    def belief_view(self) -> BeliefView:
        """The robot's belief now (see :class:`~nbs_env.observation.BeliefView`)."""
        return self._storey().view()

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() was called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self.storey is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        from nbs_env.render import render_topdown

        storey = self.storey
        view = storey.view()
        count = view.count
        cands_xy = gains = None
        if storey.open:
            cands_xy, gains = view.candidates_xy[:count], view.gains[:count]
        last = storey.scans[-1]
        title = (
            f"{storey.scene.name}: scan {len(storey.scans)}, room {storey.room + 1}, "
            f"SE sensed {last.structure_sensed_pct:.1f}%, path {storey.path_length:.1f} m"
            + (" (complete)" if storey.complete else "")
        )
        return render_topdown(
            grid=view.grid,
            roi=view.roi,
            se=view.se,
            candidates_xy=cands_xy,
            gains=gains,
            paths=storey.paths,
            stops=np.array([s.estimated_position[:2] for s in storey.scans]),
            rooms=storey.room_models(current=False),
            title=title,
        )

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        # The episode holds Embree scenes and open3d clouds, which do not pickle; it is rebuilt on
        # unpickling by replaying the same reset and actions (a seed gives the same trajectory).
        return {
            "config": self.config,
            "render_mode": self.render_mode,
            "episode": self._episode,
            "actions": list(self._actions),
            "np_random_state": None if self._np_random is None else self.np_random.bit_generator.state,
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["config"], render_mode=state["render_mode"])
        episode = state["episode"]
        if episode is not None:
            self._np_random = np.random.Generator(np.random.PCG64())
            self._np_random.bit_generator.state = episode["rng_state"]
            self._episode = episode
            self._start(episode["options"])
            for a in state["actions"]:
                self.step(a)
        if state["np_random_state"] is not None:
            if self._np_random is None:
                self._np_random = np.random.Generator(np.random.PCG64())
            self._np_random.bit_generator.state = state["np_random_state"]
