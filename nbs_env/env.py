"""NBSEnv: the scanning loop of the paper as a Gymnasium environment.

The env is a thin layer over a :class:`~nbs_env.storey.Storey` (the method over a storey: the
robot, the room-and-door loop, the coverage meter and the episode log). It adds what Gymnasium
asks for: spaces, ``reset`` and ``step``, the reward, the observation (from the robot's belief
only, :func:`nbs_env.observation.observe`), ``info``, rendering and pickling. One step reads
top-down: env → storey → robot → sensing and belief → planner.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from nbs_env.config import PRESETS, EnvConfig, RewardConfig, make_config
from nbs_env.errors import ConfigError, InvalidActionError
from nbs_env.observation import (
    CANDIDATE_FEATURES,
    ROOM_FEATURES,
    STOREY_FEATURES,
    BeliefView,
    candidate_table_of,
    observe,
)
from nbs_env.storey import STAGES, StageTimes, StepOutcome, Storey, resolve_scene
from scenes import Scene
from scenes.limits import MAX_SEED_DIGITS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

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
    says which. With `rooms.completion="policy"` the space is `Discrete(K + 1)` and action K, always
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
    - `storey`: (4,) float32, what the robot knows beyond the room (`nbs_env.observation.StoreyColumn`):
      scans taken in the episode, the doors it detected and has not crossed or given up, and the
      straight-line metres to the nearest of them and to all of them.

    Everything in the observation comes from the robot's own measurements and pose estimate. The
    shapes are those stable-baselines3 takes without a warning: `voxels` is image-like (its default
    `MultiInputPolicy` sees a 64×64 picture with 16 height channels), `candidates` is flat.

    ## Rewards

    `RewardConfig`. By default the increase of the true structural surface sensed, in percentage
    points of the storey's structural surface, minus `scan_cost` (0.5) per scan and `metre_cost`
    (0.05) per metre driven. `kind="mapped"` replaces the first term with the surface the robot
    itself labelled Structure, on the same scale (the training fidelity's reward: no meter runs);
    `kind="conversions"` with the robot's own realised Occluded-structure→Structure conversions
    (% of the room's structural voxels).

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
    name (`"default"`, `"fast"`); `overrides` replace its fields as `make_config` does (e.g.
    `scene="five_rooms"`, `max_scans=30`, `completion="policy"`, `**{"rooms.wall_search.scans": 3}`).
    `render_mode="rgb_array"` draws a top-down picture.

    Parameters
    ----------
    config : EnvConfig or str, optional
        The configuration, or the name of a preset of `PRESETS`; None (the default): `"default"`.
    render_mode : str, optional
        `"rgb_array"`: `render()` returns a top-down picture; None (the default): no rendering.
    **overrides
        Fields of `config` to replace, by the names `make_config` takes (a leaf's name where it is
        unique, or its dotted path).

    Raises
    ------
    ConfigError
        `config` is neither an `EnvConfig` nor a preset name, `render_mode` is not one of
        `metadata["render_modes"]`, or `make_config` refuses an override (an unknown preset or
        field, a value out of range).

    ## Registered Configurations

    | id | preset | scene | max_episode_steps |
    |---|---|---|---|
    | `nbs_env/NBS-v0` | default: 0.5° scanner, 5 cm voxels, odometry drift + ICP | generated 1-8 rooms | 80 |
    | `nbs_env/NBS-Fast-v0` | fast: 1° scanner, 10 cm voxels, perfect localisation | generated 1-3 rooms | 40 |
    | `nbs_env/NBS-Train-v0` | train: fast without the coverage meter, reward `mapped` | generated 1-3 rooms | 40 |
    | `nbs_env/NBS-FiveRooms-v0` | default | `five_rooms` | 60 |
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, config: EnvConfig | str | None = None, render_mode: str | None = None, **overrides: Any) -> None:
        if config is None or isinstance(config, str) or (isinstance(config, EnvConfig) and overrides):
            config = make_config(config, **overrides)
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
        self.stop_action: int | None = k if config.rooms.completion == "policy" else None
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
                "storey": spaces.Box(-1e4, 1e4, shape=(len(STOREY_FEATURES),), dtype=np.float32),
            }
        )
        self._scene_cache: dict[str, Scene] = {}
        self._episode: dict[str, Any] | None = None  # what reset was given, for pickling
        self._actions: list[int] = []
        self._last = StepOutcome()
        self._ended = False  # a step has returned terminated or truncated
        self.storey: Storey | None = None

    @property
    def scene(self) -> Scene | None:
        """The true building of the episode (None before ``reset``)."""
        return None if self.storey is None else self.storey.scene

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode: pick the storey, put the robot at its start and take the first scan.

        Parameters
        ----------
        seed : int, optional
            Seeds the env's random generator ``np_random``, which all randomness of an episode comes
            from (a generated storey, the robot's noise); None: the generator runs on (seeded from
            entropy at the first reset).
        options : dict of str to Any, optional
            ``"scene"``: the storey, anything ``scenes.load_scene`` takes, a ``Scene``, a ``FloorPlan`` or
            ``"generated"`` (a fresh storey from ``np_random``); default ``config.scene``. ``"start"``: (2,)
            or (3,) float, the robot's start position in the scene (m); default the scene's own.

        Returns
        -------
        obs : dict of str to numpy.ndarray
            The observation (Observation Space above): ``"voxels"`` ``observation.shape`` ((64, 64, 16)
            by default) uint8, ``"candidates"`` (K·5,) float32, ``"pose"`` (4,) float32, ``"room"`` (5,)
            float32.
        info : dict of str to Any
            As :meth:`step` returns it.

        Raises
        ------
        ConfigError
            A seed other than None or an integer >= 0, an option other than ``"scene"`` and
            ``"start"``, or a scene of no known kind.
        nbs_env.errors.InvalidPoseError
            The start is not free floor of the storey.
        """
        if seed is not None and (
            not isinstance(seed, (int, np.integer)) or isinstance(seed, (bool, np.bool_)) or seed < 0
        ):
            # gymnasium's own Error otherwise, which no caller of nbs-env expects.
            raise ConfigError(f"seed must be None or an integer >= 0, got {seed!r}")
        if seed is not None and seed >= 10**MAX_SEED_DIGITS:
            raise ConfigError(f"seed must have at most {MAX_SEED_DIGITS} digits, got one of more")
        # A numpy integer (what vector envs pass) as the Python int gymnasium requires.
        super().reset(seed=None if seed is None else int(seed))
        if options is not None and not isinstance(options, Mapping):
            raise ConfigError(f"reset options must be a dict (or None), got {type(options).__name__}")
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
        self._ended = False
        self.storey = Storey(scene, config, self.np_random, count_conversions=config.reward.kind == "conversions")

    def step(self, action: Any):
        """Scan at the chosen candidate (or, with ``rooms.completion="policy"``, end the room).

        The robot drives to the candidate, scans, registers the scan and updates its belief; when
        the room is then complete it also crosses to the next room and takes its first scan. A masked
        action, or any action while there is no candidate, takes no scan and costs
        ``reward.invalid_action_penalty``. An episode that ended at :meth:`reset` (its first scan
        finished the storey, or ``max_scans=1``) ends at the first step, with reward 0 and no scan; a
        step after a step that ended the episode, or after :meth:`close`, is refused.

        Parameters
        ----------
        action : int or numpy.integer or numpy.ndarray
            An index in ``[0, n_actions)``: a Python or numpy integer, or a 0-d integer array (not a
            bool, not a float).

        Returns
        -------
        obs : dict of str to numpy.ndarray
            The observation, as :meth:`reset` returns it.
        reward : float
            The step's reward (Rewards above); ``-reward.invalid_action_penalty`` for a masked action.
        terminated : bool
            The storey is complete.
        truncated : bool
            The ``max_scans`` scan budget is spent and the storey is not complete.
        info : dict of str to Any
            ``scans``, ``room``, ``rooms_done`` (int); ``structure_sensed_pct`` (float, % of the storey's
            true structural surface: evaluation only; None with ``coverage_meter=False``);
            ``path_length_m`` (float); ``mapped_pct`` (float, the surface the robot labelled
            Structure, % of the storey's structural surface: :attr:`Storey.mapped_pct`); ``times``
            (:class:`~nbs_env.storey.StageTimes`, this step's seconds per stage);
            ``registration_error_m``, ``registration_error_deg`` (float, the last scan's pose error);
            ``registration_refused`` (str, why ICP's pose was refused; "" when accepted);
            ``door_events`` (list of dict); ``action_mask`` ((n_actions,) bool, :meth:`action_masks`);
            ``candidate_gains`` ((K,) int64, :meth:`candidate_gains`); ``gain_rule_done`` (bool,
            :meth:`gain_rule_done`); ``invalid_action`` (bool); ``conversions`` (int, the realised
            Occluded-structure→Structure conversions of the last decision, counted only with
            ``reward.kind="conversions"``); ``complete`` (bool); ``reward_terms`` (dict: ``gain``, the
            reward's first term, and ``cost``, what the prices or the penalty took: reward = gain - cost);
            and with ``expose_belief=True``, ``belief``
            (:class:`~nbs_env.observation.BeliefView`).

        Raises
        ------
        gymnasium.error.ResetNeeded
            Called before :meth:`reset`, after a step returned terminated or truncated, or after
            :meth:`close`.
        InvalidActionError
            ``action`` is not an integer in ``[0, n_actions)``.
        """
        storey = self._storey()
        a = self._check_action(action)
        if not storey.open:
            if self._ended:
                # What gymnasium leaves undefined is refused: a loop that missed terminated/truncated
                # would otherwise run on, collecting rewards of 0 from an episode that has ended.
                raise gym.error.ResetNeeded("the episode has ended (terminated or truncated); call reset()")
            # An episode that ended at reset (its first scan finished the storey, or max_scans=1):
            # reset cannot say so, the first step does, at no cost.
            self._ended = True
            storey.begin_step()
            info = {**self._info(), "reward_terms": {"gain": 0.0, "cost": 0.0}}
            return self._observation(), 0.0, storey.complete, not storey.complete, info
        storey.begin_step()
        stop = a == self.stop_action
        if not self.action_masks()[a] or (not stop and storey.plan.count == 0):
            penalty = self.config.reward.invalid_action_penalty
            info = {**self._info(invalid_action=True), "reward_terms": {"gain": 0.0, "cost": penalty}}
            return self._observation(), -penalty, False, False, info
        self._actions.append(a)
        self._last = storey.room_done() if stop else storey.scan_at(a)
        terminated = storey.complete
        truncated = not terminated and not storey.open
        self._ended = terminated or truncated
        gain, cost = self._reward_terms(self._last)
        info = {**self._info(), "reward_terms": {"gain": gain, "cost": cost}}
        return self._observation(), gain - cost, terminated, truncated, info

    def _reward_terms(self, outcome: StepOutcome) -> tuple[float, float]:
        # The reward's two terms apart, so that a learner may weigh them (train.ppo's hold_coverage).
        cfg = self.config.reward
        if cfg.kind == "coverage":
            gain = outcome.coverage_gain
        elif cfg.kind == "mapped":
            gain = outcome.mapped_gain
        else:
            gain = 100.0 * outcome.conversions / max(1, outcome.structural_voxels)
        return float(gain), float(cfg.scan_cost * outcome.scans + cfg.metre_cost * outcome.metres)

    def _storey(self) -> Storey:
        if self.storey is None:
            raise gym.error.ResetNeeded("call reset() first")
        return self.storey

    def close(self) -> None:
        """Let go of the episode and the storeys loaded (their ray-casting scenes and maps): the env
        is then as before its first :meth:`reset`; :meth:`step` and :meth:`render` raise ResetNeeded."""
        self.storey = None
        self._episode = None
        self._actions = []
        self._scene_cache.clear()
        super().close()

    def _check_action(self, action: Any) -> int:
        # What Discrete.contains takes: a Python or numpy integer, or a 0-d integer array (not a
        # bool, not a float that happens to be whole, not a one-element list or array).
        # A masked array is an ndarray whose masked value has no integer (numpy's MaskError).
        integer = (isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_))) or (
            isinstance(action, np.ndarray)
            and action.shape == ()
            and np.issubdtype(action.dtype, np.integer)
            and not np.ma.is_masked(action)
        )
        if not integer or not (0 <= int(action) < self.n_actions):
            raise InvalidActionError(
                f"action must be an integer in [0, {self.n_actions}) (int, numpy integer or 0-d integer array), "
                f"got {action!r} of type {type(action).__name__}"
            )
        return int(action)

    def action_masks(self) -> np.ndarray:
        """Which actions are real candidates (sb3-contrib's MaskablePPO reads this).

        Returns
        -------
        (n_actions,) bool
            True for the real candidates; with ``rooms.completion="policy"`` the last action, "room
            done", is always allowed. All False before :meth:`reset`; once the episode is over only
            action 0, so that a masked sampler given the last observation always has a choice (stepping
            it raises ResetNeeded).
        """
        mask = np.zeros(self.n_actions, dtype=bool)
        if self.storey is None:
            return mask
        if self.storey.open:
            mask[: self.max_candidates] = self.storey.plan.candidates.mask
            if self.stop_action is not None:
                mask[self.stop_action] = True
        if not mask.any():
            # A finished episode keeps one action so that a masked sampler always has a choice.
            mask[0] = True
        return mask

    def gain_rule_done(self, fraction: float | None = None) -> bool:
        """Whether the robot's gain rule would end the room now (:meth:`Storey.gain_rule_done`): what
        the greedy declares by with ``rooms.completion="policy"``; also ``info["gain_rule_done"]``.

        Parameters
        ----------
        fraction : float, optional
            Reads the rule at this completion fraction, in [0, 1); None (the default): the robot's
            ``rooms.completion_fraction``.

        Returns
        -------
        bool
            True when no candidate predicts ``fraction`` of the room's structural voxels; False before
            :meth:`reset`, once the episode is over and when the robot predicts no gains
            (``robot.predict_gains=False``). Reads the robot's plan only, never ground truth.

        Raises
        ------
        ValueError
            ``fraction`` is not in [0, 1) (checked once an episode has started).
        """
        return self.storey is not None and self.storey.gain_rule_done(fraction)

    def candidate_gains(self) -> np.ndarray:
        """The greedy's predicted gain of each candidate (the paper's criterion); also
        ``info["candidate_gains"]``.

        Returns
        -------
        (K,) int64
            Predicted Occluded-structure→Structure conversions of each candidate, voxels, from the
            robot's own grid; 0 for padding, and all zeros before :meth:`reset`, once the storey is
            complete and when the robot predicts no gains.
        """
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
            # None without the meter (the training fidelity): no figure, rather than a NaN.
            "structure_sensed_pct": storey.coverage_pct() if self.config.coverage_meter else None,
            "path_length_m": storey.path_length,
            # The robot's own account (its Structure voxels), on the coverage's scale: no meter needed.
            "mapped_pct": storey.mapped_pct,
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
        """The robot's belief now: its grid, RoI, candidates and scans, never ground truth.

        Returns
        -------
        BeliefView
            References into the live belief (:class:`~nbs_env.observation.BeliefView`): read, never
            write.

        Raises
        ------
        gymnasium.error.ResetNeeded
            Called before :meth:`reset`.
        """
        return self._storey().view()

    def render(self):
        """A top-down picture of the robot's belief: the current room's voxel labels, RoI and
        candidates, the rooms finished before, its stops by kind and the paths it drove, with a
        legend (:meth:`render_figure`).

        Returns
        -------
        (h, w, 3) uint8 or None
            The picture with ``render_mode="rgb_array"``; None (and a warning) without a render mode.

        Raises
        ------
        gymnasium.error.ResetNeeded
            Called before :meth:`reset` with a render mode.
        """
        if self.render_mode is None:
            gym.logger.warn("render() was called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self.storey is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        from nbs_env.render import draw

        return draw(self.render_figure())

    def render_figure(self) -> Figure:
        """The picture :meth:`render` draws, as a matplotlib Figure (whatever the render mode).

        Everything in it is the robot's own, in its map frame: the current room's V(t), RoI and
        candidates, the finished rooms' models, each scan position marked by kind (the start, a
        scan at an NVP, a door-frame scan, a search scan; the last one as the robot) and each path
        it drove as it planned it (:attr:`nbs_env.storey.Storey.paths`). Its legend
        (``figure.axes[0].get_legend()``) names every kind drawn (:func:`nbs_env.render.topdown_figure`).

        Returns
        -------
        matplotlib.figure.Figure

        Raises
        ------
        gymnasium.error.ResetNeeded
            Called before :meth:`reset`.
        """
        if self.storey is None:
            raise gym.error.ResetNeeded("call reset() before render_figure()")
        from nbs_env.render import topdown_figure

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
        searched = {search["scan"] for search in storey.wall_searches}
        kinds = [
            "start" if k == 0 else "door" if s.door else "search" if k in searched else "nvp"
            for k, s in enumerate(storey.scans)
        ]
        return topdown_figure(
            grid=view.grid,
            roi=view.roi,
            se=view.se,
            candidates_xy=cands_xy,
            gains=gains,
            paths=storey.paths,
            stops=np.array([s.estimated_position[:2] for s in storey.scans]),
            stop_kinds=kinds,
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
