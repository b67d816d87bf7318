"""Native Gymnasium vector env of the compass-gait biped on the batched simulator.

``gym.make_vec("roughwalk/CompassGaitRough-v0", num_envs=1024,
vectorization_mode="vector_entry_point")`` builds a :class:`CompassGaitVectorEnv`: all
sub-environments are walkers of one :class:`envs.physics.Simulator`, stepped by one compiled
call, with rewards and observations computed by one more. Sub-environment ``i`` gives exactly the
observations, rewards and infos of ``gym.make(id)`` reset with ``seed + i`` and fed the same
actions (the single env is a batch of one of the same code).

Autoreset follows Gymnasium 1.x: the default is ``AutoresetMode.NEXT_STEP`` (Gymnasium's default;
the step after an episode ends returns the reset observation with reward 0, ``terminated`` and
``truncated`` False, and the action for that sub-env is ignored). ``autoreset_mode="same_step"``
resets within the ending step instead and puts the final observation and info in
``info["final_obs"]`` and ``info["final_info"]`` (what the stable-baselines3 adapter uses);
``"disabled"`` leaves resets to the caller (``reset(options={"reset_mask": mask})``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .batch import WalkerBatch
from .physics.simulator import Simulator
from .physics.terrain import Terrain
from .rendering import WalkerRenderer
from .settings import check_max_episode_steps, resolve_env_settings

_MODES = {
    "next_step": AutoresetMode.NEXT_STEP,
    "same_step": AutoresetMode.SAME_STEP,
    "disabled": AutoresetMode.DISABLED,
}


class CompassGaitVectorEnv(VectorEnv):
    """``num_envs`` compass-gait environments stepped together (see :class:`CompassGaitEnv`).

    Args:
        num_envs: number of sub-environments, >= 1.
        config: env variant (a name in ``configs/envs``, a YAML path or a dict).
        max_episode_steps: time limit in steps (truncation); None for none.
        render_mode: None or ``"rgb_array"`` (``render()`` returns one frame per sub-env).
        autoreset_mode: ``"next_step"`` (default), ``"same_step"`` or ``"disabled"`` (or an
            :class:`AutoresetMode`).
        parallel: spread walkers over threads (default: ``num_envs >= 256``).
        **kwargs: overrides of the config, as for :class:`CompassGaitEnv`.

    Seeding: ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (or ``seed[i]`` for a list).
    Each sub-env draws its terrain, start state and sensor noise from its own generator
    (``env.np_randoms[i]``). Actions: ``(num_envs, 1)`` float32 in [-1, 1], clipped; NaN or inf
    raise ``ValueError``.
    """

    metadata = {
        "render_modes": ["rgb_array"],
        "render_fps": 200,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        config: str | Path | dict[str, Any] = "flat",
        *,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        parallel: bool | None = None,
        **kwargs: Any,
    ):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs = {num_envs} out of range; allowed: >= 1")
        if isinstance(autoreset_mode, str):
            if autoreset_mode.lower() not in _MODES:
                allowed = sorted(_MODES)
                raise ValueError(f"autoreset_mode = {autoreset_mode!r}; allowed: {allowed}")
            autoreset_mode = _MODES[autoreset_mode.lower()]
        if not isinstance(autoreset_mode, AutoresetMode):
            raise ValueError(f"autoreset_mode must be a string or AutoresetMode: {autoreset_mode}")
        settings = resolve_env_settings(config, **kwargs)
        if max_episode_steps is None:
            max_episode_steps = settings.max_episode_steps
        self.num_envs = n = int(num_envs)
        self.settings = settings
        self.max_episode_steps = check_max_episode_steps(max_episode_steps)
        self.autoreset_mode = autoreset_mode
        self._batch = b = WalkerBatch(settings, n, parallel=parallel)
        self.robot = self.params = settings.robot
        self.dt = settings.dt
        self.u_max = settings.robot.u_max
        self.torque_limit = settings.robot.tau_max
        self.sensor_config = settings.sensors
        self.sensor_layout = b.layout
        self.observation_mode = settings.observation
        self.metadata = {
            **type(self).metadata,
            "render_fps": 1.0 / settings.dt,
            "autoreset_mode": autoreset_mode,
        }
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode = {render_mode!r}; allowed: ['rgb_array'] or None")
        self.render_mode = render_mode
        b.track_footholds = render_mode is not None
        self.single_action_space = spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, n)
        self.single_observation_space = spaces.Box(b.obs_low, b.obs_high, dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, n)
        self.np_randoms: list[np.random.Generator] = []
        self._steps = np.zeros(n, dtype=np.int64)
        self._prev_done = np.zeros(n, dtype=bool)
        self._truncated = np.zeros(n, dtype=bool)
        self._was_reset = False
        self._renderers: list[Any] = []

    @property
    def terrains(self) -> list[Terrain | None]:
        """The current episode's :class:`envs.Terrain` of every sub-env."""
        return list(self._batch.terrains)

    @property
    def simulator(self) -> Simulator:
        """The batched simulator of all sub-envs, for diagnostics and benchmarks; stepping or
        resetting it directly desynchronises the env."""
        return self._batch.sim

    # ------------------------------------------------------------------ reset
    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset all sub-envs, or those of ``options["reset_mask"]`` (a bool array).

        Args:
            seed: None (keep each sub-env's generator), an int (sub-env ``i`` gets ``seed + i``)
                or one seed (or None) per sub-env.
            options: the single env's reset options, plus ``"reset_mask"``.

        Returns:
            The observations (one row per sub-env) and the batched info dict.
        """
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(n)]
            super().reset(seed=int(seed))
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed list has {len(seeds)} entries for {n} envs")
        mask = None if options is None else options.get("reset_mask")
        if mask is None:
            idx = range(n)
        else:
            mask = np.asarray(mask)
            if mask.dtype != bool or mask.shape != (n,):
                raise ValueError(f"reset_mask must be a bool array of shape ({n},)")
            idx = np.nonzero(mask)[0]
        if not self.np_randoms:
            self.np_randoms = [seeding.np_random(None)[0] for _ in range(n)]
        for i in idx:
            if seeds[i] is not None:
                self.np_randoms[i] = seeding.np_random(seeds[i])[0]
            self._reset_one(int(i), options)
        self._was_reset = True
        return self._batch.observations(), self._batch.infos()

    def _reset_one(self, i: int, options: dict[str, Any] | None) -> None:
        self._batch.reset_walker(i, self.np_randoms[i], options)
        self._steps[i] = 0
        self._prev_done[i] = False

    # ------------------------------------------------------------------ step
    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Apply ``actions`` (``(num_envs, 1)`` in [-1, 1]) for one control period; finished
        sub-envs reset as ``autoreset_mode`` says."""
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        b = self._batch
        b.step(actions)
        self._steps += 1
        terminated = b.terminated.copy()
        if self.max_episode_steps is not None:
            truncated = self._steps >= self.max_episode_steps
        else:
            truncated = np.zeros(self.num_envs, dtype=bool)
        rewards = b.reward.copy()
        mode = self.autoreset_mode
        if mode == AutoresetMode.NEXT_STEP:
            if self._prev_done.any():
                reset_idx = np.nonzero(self._prev_done)[0]
                for i in reset_idx:
                    self._reset_one(int(i), None)
                rewards[reset_idx] = 0.0
                terminated[reset_idx] = False
                truncated[reset_idx] = False
            self._prev_done = terminated | truncated
            return b.observations(), rewards, terminated, truncated, b.infos()
        if mode == AutoresetMode.SAME_STEP:
            done = np.nonzero(terminated | truncated)[0]
            if done.size == 0:
                return b.observations(), rewards, terminated, truncated, b.infos()
            final_obs_all = b.observations()
            final_info = b.infos()
            for key in [k for k in final_info if k.startswith("_")]:
                final_info[key] = final_info[key] & (terminated | truncated)
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in done:
                final_obs[i] = final_obs_all[i]
                self._reset_one(int(i), None)
            infos = b.infos()
            infos["final_obs"] = final_obs
            infos["_final_obs"] = terminated | truncated
            infos["final_info"] = final_info
            infos["_final_info"] = terminated | truncated
            return b.observations(), rewards, terminated, truncated, infos
        # DISABLED: the caller resets finished sub-envs with options={"reset_mask": ...}
        return b.observations(), rewards, terminated, truncated, b.infos()

    # ------------------------------------------------------------------ render / close
    def render(self) -> tuple[np.ndarray, ...] | None:
        """One RGB frame per sub-env (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'")
            return None
        while len(self._renderers) < self.num_envs:
            self._renderers.append(
                WalkerRenderer(self.robot.l, "rgb_array", fps=min(self.metadata["render_fps"], 60))
            )
        return tuple(r.render(**self._batch.render_args(i)) for i, r in enumerate(self._renderers))

    def close_extras(self, **kwargs: Any) -> None:
        """Close the renderers."""
        for r in self._renderers:
            r.close()
        self._renderers = []
