"""A terrain curriculum in the manner of legged_gym (Rudin et al. 2022, "Learning to Walk in
Minutes Using Massively Parallel Deep Reinforcement Learning"): each training env has a
difficulty level, promoted after an episode in which the walker went far and demoted after one
in which it fell early, so that every env trains near the edge of what the agent can walk.

:class:`TerrainCurriculum` is an env wrapper: at every reset it hands the env the course of
its current level through the reset option ``"terrain"`` (a random course of the env's own
terrain generator, drawn from the env's ``np_random``), the level's difficulty scaled by
:class:`envs.task.TerrainSource` exactly as the env's ``difficulty`` argument scales it. It is
``training_only``: ``AgentConfig.wrap`` applies it to the training envs, not to the periodic
evaluation nor to evaluations of the trained agent, which walk the config's own difficulty.
``agents.callbacks.CurriculumLog`` logs the levels to TensorBoard.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.settings import resolve_env_settings
from envs.task import TerrainSource

#: mixed with the reset seed to draw the initial level (a stream apart from the env's own)
LEVEL_STREAM = 0x5C11


class TerrainCurriculum(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Promotes or demotes the env's terrain difficulty by how far each episode got.

    Level ``k`` of ``levels`` has difficulty ``min_difficulty + k * (max_difficulty -
    min_difficulty) / (levels - 1)``. An episode's progress is the fraction of the time limit
    it walked before failing (1 when it reached the time limit). After an episode with progress
    >= ``promote`` the level goes up one, after one with progress < ``demote`` down one, within
    ``[0, levels - 1]``. The first level is drawn uniformly from ``[0, max_initial_level]`` at
    every reset given a seed (from that seed: the same seed gives the same levels), else at the
    first reset from the env's ``np_random``. An episode whose reset options name a terrain
    walks that terrain and leaves the level as it is.

    ``info`` of a reset carries ``curriculum_level`` and ``curriculum_difficulty``; the last
    step of a counted episode carries ``curriculum``: ``level``, ``difficulty``, ``progress``,
    ``next_level``, ``next_difficulty``. The attributes ``curriculum_level`` and
    ``curriculum_difficulty`` are the level of the next (or current) episode.

    Args:
        env: a roughwalk env with a time limit (``gym.make`` of a registered id) whose terrain
            is a random kind (``blocks``, ``piecewise``), or with ``terrain`` given.
        min_difficulty: difficulty of level 0, finite >= 0.
        max_difficulty: difficulty of the top level, finite >= ``min_difficulty``.
        levels: number of levels, >= 1 (1 only with equal min and max).
        promote: progress at or above which the level goes up, in (0, 1].
        demote: progress below which the level goes down, in [0, ``promote``).
        max_initial_level: highest first level, in [0, levels - 1]; None: ``levels - 1``.
        terrain: the random terrain to scale (a name in ``configs/terrains`` or a spec dict);
            None: the env's own (its config and ``terrain`` argument).
    """

    training_only = True

    def __init__(
        self,
        env: gym.Env,
        min_difficulty: float = 0.5,
        max_difficulty: float = 3.0,
        levels: int = 6,
        promote: float = 0.8,
        demote: float = 0.4,
        max_initial_level: int | None = None,
        terrain: str | dict[str, Any] | None = None,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            min_difficulty=min_difficulty,
            max_difficulty=max_difficulty,
            levels=levels,
            promote=promote,
            demote=demote,
            max_initial_level=max_initial_level,
            terrain=terrain,
        )
        gym.Wrapper.__init__(self, env)
        self.check_arguments(
            min_difficulty, max_difficulty, levels, promote, demote, max_initial_level
        )
        horizon = env.spec.max_episode_steps if env.spec is not None else None
        if not horizon:
            raise ValueError(
                "TerrainCurriculum measures progress against the time limit: the env needs "
                "max_episode_steps (make it with gym.make)"
            )
        self.horizon = int(horizon)
        self.difficulties = np.linspace(min_difficulty, max_difficulty, levels)
        self.sources = [_level_source(env, terrain, float(d)) for d in self.difficulties]
        self.promote = float(promote)
        self.demote = float(demote)
        self.max_initial_level = levels - 1 if max_initial_level is None else max_initial_level
        self.curriculum_level: int | None = None
        self._steps = 0
        self._counted = False

    @staticmethod
    def check_arguments(
        min_difficulty: float = 0.5,
        max_difficulty: float = 3.0,
        levels: int = 6,
        promote: float = 0.8,
        demote: float = 0.4,
        max_initial_level: int | None = None,
        terrain: str | dict[str, Any] | None = None,
    ) -> None:
        """Check the arguments that need no env (see the class docstring for their ranges).

        Args:
            min_difficulty: difficulty of level 0.
            max_difficulty: difficulty of the top level.
            levels: number of levels.
            promote: progress threshold of a promotion.
            demote: progress threshold of a demotion.
            max_initial_level: highest first level, or None.
            terrain: the random terrain to scale, or None (built here when given).

        Raises:
            ValueError: a value out of range, naming the argument and what it allows.
        """
        for name, value in (("min_difficulty", min_difficulty), ("max_difficulty", max_difficulty)):
            if not _number(value) or not value >= 0:
                raise ValueError(f"{name} = {value!r}; allowed: a finite number >= 0")
        if max_difficulty < min_difficulty:
            raise ValueError(
                f"max_difficulty = {max_difficulty!r}; allowed: >= min_difficulty "
                f"({min_difficulty!r})"
            )
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 1:
            raise ValueError(f"levels = {levels!r}; allowed: an integer >= 1")
        if levels == 1 and max_difficulty != min_difficulty:
            raise ValueError("levels = 1 needs min_difficulty == max_difficulty")
        if not _number(promote) or not 0 < promote <= 1:
            raise ValueError(f"promote = {promote!r}; allowed: a number in (0, 1]")
        if not _number(demote) or not 0 <= demote < promote:
            raise ValueError(f"demote = {demote!r}; allowed: a number in [0, promote = {promote})")
        if max_initial_level is not None and (
            isinstance(max_initial_level, bool)
            or not isinstance(max_initial_level, int)
            or not 0 <= max_initial_level < levels
        ):
            raise ValueError(
                f"max_initial_level = {max_initial_level!r}; allowed: null or an integer in "
                f"[0, {levels - 1}]"
            )
        if terrain is not None:
            for d in (min_difficulty, max_difficulty):
                _random_source(terrain, float(d))

    @property
    def curriculum_difficulty(self) -> float | None:
        """Difficulty of the current level (None before the first reset)."""
        if self.curriculum_level is None:
            return None
        return float(self.difficulties[self.curriculum_level])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset the env on a course of the current level (unless ``options`` name one).

        Args:
            seed: episode seed; a new seed also draws the first level again.
            options: the env's reset options (a ``"terrain"`` there is used as it is).
        """
        if seed is not None:
            rng = np.random.default_rng([int(seed), LEVEL_STREAM])
            self.curriculum_level = int(rng.integers(0, self.max_initial_level + 1))
        elif self.curriculum_level is None:
            rng = self.env.unwrapped.np_random
            self.curriculum_level = int(rng.integers(0, self.max_initial_level + 1))
        options = dict(options or {})
        self._counted = options.get("terrain") is None
        if self._counted:
            options["terrain"] = dict(self.sources[self.curriculum_level].template)
        self._steps = 0
        obs, info = self.env.reset(seed=seed, options=options)
        info = dict(info)
        info["curriculum_level"] = self.curriculum_level
        info["curriculum_difficulty"] = self.curriculum_difficulty
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Step the env; at the end of a counted episode, move the level.

        Args:
            action: the action for the wrapped env.
        """
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        if (terminated or truncated) and self._counted:
            self._counted = False
            info = dict(info)
            info["curriculum"] = self.update(1.0 if not terminated else self._steps / self.horizon)
        return obs, reward, terminated, truncated, info

    def update(self, progress: float) -> dict[str, Any]:
        """Move the level after an episode of ``progress`` (fraction of the time limit walked,
        in [0, 1]); returns the ``info["curriculum"]`` record of it."""
        level = self.curriculum_level
        if level is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        step = 1 if progress >= self.promote else -1 if progress < self.demote else 0
        self.curriculum_level = min(max(level + step, 0), len(self.difficulties) - 1)
        return {
            "level": level,
            "difficulty": float(self.difficulties[level]),
            "progress": float(progress),
            "next_level": self.curriculum_level,
            "next_difficulty": self.curriculum_difficulty,
        }


def _number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)


def _random_source(terrain: str | dict[str, Any], difficulty: float) -> TerrainSource:
    """``terrain`` scaled to ``difficulty``; it must be a random course generator."""
    if not TerrainSource(terrain).is_random:
        raise ValueError(
            f"terrain {terrain!r} is fixed: a curriculum needs a random terrain kind "
            "(blocks, piecewise) without a seed"
        )
    return TerrainSource(terrain, difficulty)


def _level_source(env: gym.Env, terrain: str | dict[str, Any] | None, d: float) -> TerrainSource:
    """The course generator of one level: ``terrain``, or the env's own, at difficulty ``d``."""
    if terrain is not None:
        return _random_source(terrain, d)
    spec = env.unwrapped.spec
    kwargs = spec.kwargs if spec is not None else {}
    if "config" not in kwargs:
        raise ValueError("TerrainCurriculum: the env has no registered config; give terrain")
    config, terrain = kwargs["config"], kwargs.get("terrain")
    if not resolve_env_settings(config, terrain=terrain, difficulty=1.0).terrain.is_random:
        raise ValueError(
            f"TerrainCurriculum: the env's terrain is fixed (config {config!r}); a curriculum "
            "needs a random terrain kind (blocks, piecewise) or the terrain argument"
        )
    return resolve_env_settings(config, terrain=terrain, difficulty=d).terrain
