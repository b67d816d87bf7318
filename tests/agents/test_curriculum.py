"""Terrain curriculum: promotion and demotion on constructed episodes, bounds, seeding, the
courses handed to the env, training-only wrapping, and its log."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec
from stable_baselines3.common.logger import KVWriter, Logger

from agents.callbacks import CurriculumLog
from agents.config import config_from_dict
from agents.curriculum import TerrainCurriculum
from agents.train import build, make_callbacks, make_vec_env
from envs.task import TerrainSource

ROUGH = "roughwalk/CompassGaitRough-v0"
HORIZON = 10


class ScriptedEpisodes(gym.Env):
    """A stand-in env whose episodes fail after the scripted number of steps (None: never,
    the time limit ends them); it records the reset options it was given."""

    def __init__(self, fail_after: list[int | None]) -> None:
        self.fail_after = list(fail_after)
        self.observation_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.spec = EnvSpec("Scripted-v0", max_episode_steps=HORIZON)
        self.options: list[dict[str, Any] | None] = []
        self._t = 0
        self._fail: int | None = None

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.options.append(options)
        self._t, self._fail = 0, self.fail_after.pop(0)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        self._t += 1
        failed = self._fail is not None and self._t >= self._fail
        return np.zeros(1, np.float32), 0.0, failed, not failed and self._t >= HORIZON, {}


def _episodes(env: TerrainCurriculum, count: int, seed: int = 0) -> list[dict]:
    events = []
    for k in range(count):
        env.reset(seed=seed if k == 0 else None)
        while True:
            _, _, term, trunc, info = env.step(np.zeros(1, np.float32))
            if term or trunc:
                events.append(info["curriculum"])
                break
    return events


def test_promotes_after_far_episodes_and_demotes_after_early_falls():
    # progress: 1 (time limit), 0.8 (fails at step 8), 0.7, 0.3, 0.39, 0.4, 1
    script = [None, 8, 7, 3, 4, 4, None]
    env = TerrainCurriculum(
        ScriptedEpisodes(script), levels=6, max_initial_level=2, terrain="rough_blocks"
    )
    events = _episodes(env, len(script))
    progress = [e["progress"] for e in events]
    assert progress == [1.0, 0.8, 0.7, 0.3, 0.4, 0.4, 1.0]
    first = events[0]["level"]
    assert 0 <= first <= 2
    steps = [e["next_level"] - e["level"] for e in events]
    assert steps == [1, 1, 0, -1, 0, 0, 1]  # >= 0.8 up, < 0.4 down, else stay
    for e in events:
        assert e["difficulty"] == pytest.approx(0.5 + 0.5 * e["level"])  # 0.5 ... 3.0
    assert [e["level"] for e in events[1:]] == [e["next_level"] for e in events[:-1]]


def test_levels_stay_within_their_bounds():
    top = TerrainCurriculum(ScriptedEpisodes([None] * 8), levels=3, terrain="rough_blocks")
    assert [e["next_level"] for e in _episodes(top, 8)][-3:] == [2, 2, 2]
    bottom = TerrainCurriculum(ScriptedEpisodes([1] * 8), levels=3, terrain="rough_blocks")
    assert [e["next_level"] for e in _episodes(bottom, 8)][-3:] == [0, 0, 0]


def test_courses_are_the_terrain_scaled_by_the_level_difficulty():
    inner = ScriptedEpisodes([None] * 3)
    env = TerrainCurriculum(inner, 1.0, 2.0, levels=3, terrain="rough_blocks")
    env.reset(seed=4)
    level = env.curriculum_level
    expected = TerrainSource("rough_blocks", [1.0, 1.5, 2.0][level]).template
    assert inner.options[-1] == {"terrain": expected}
    env.reset(options={"terrain": "flat"})  # a course named by the caller is walked as given
    assert inner.options[-1] == {"terrain": "flat"}
    env.step(np.zeros(1, np.float32))
    assert env.curriculum_level == level


def test_the_env_walks_the_level_difficulty_from_its_own_terrain():
    env = TerrainCurriculum(
        gym.make(ROUGH, max_episode_steps=5), min_difficulty=2.0, max_difficulty=2.0, levels=1
    )
    _, info = env.reset(seed=0)
    assert info["curriculum_difficulty"] == 2.0
    assert info["terrain"]["height_range"] == [-0.015, 0.015]  # 2 x configs' +-7.5 mm


def test_initial_level_comes_from_the_seed():
    def first_levels(seed: int) -> list[int]:
        env = TerrainCurriculum(ScriptedEpisodes([None] * 20), terrain="rough_blocks")
        out = []
        for s in range(seed, seed + 20):
            env.reset(seed=s)
            out.append(env.curriculum_level)
        return out

    assert first_levels(0) == first_levels(0)
    assert len(set(first_levels(0))) > 2  # spread over the levels
    assert first_levels(0) != first_levels(1)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"min_difficulty": -1.0}, r"min_difficulty = -1.0; allowed: a finite number >= 0"),
        ({"min_difficulty": 2.0, "max_difficulty": 1.0}, "max_difficulty = 1.0; allowed: >="),
        ({"levels": 0}, "levels = 0; allowed: an integer >= 1"),
        ({"promote": 1.5}, r"promote = 1.5; allowed: a number in \(0, 1\]"),
        ({"demote": 0.9}, r"demote = 0.9; allowed: a number in \[0, promote = 0.8\)"),
        ({"max_initial_level": 6}, r"max_initial_level = 6; allowed: null or an integer in"),
        ({"terrain": "flat"}, "a curriculum needs a random terrain kind"),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TerrainCurriculum.check_arguments(**kwargs)


def test_needs_a_random_terrain_and_a_time_limit():
    with pytest.raises(ValueError, match="random terrain kind"):
        TerrainCurriculum(gym.make("roughwalk/CompassGaitStairs-v0"))
    no_limit = ScriptedEpisodes([None])
    no_limit.spec = None
    with pytest.raises(ValueError, match="needs max_episode_steps"):
        TerrainCurriculum(no_limit, terrain="rough_blocks")


def _curriculum_config(**curriculum: Any):
    wrapper = {"agents.curriculum.TerrainCurriculum": {"levels": 3, **curriculum}}
    hyper = {
        "n_timesteps": 96,
        "n_steps": 48,
        "n_envs": 2,
        "batch_size": 32,
        "n_epochs": 1,
        "env_kwargs": {"max_episode_steps": 12},
        "env_wrapper": [wrapper],
    }
    run = {"algo": "ppo", "env": ROUGH, "eval_freq": 0, "checkpoint_freq": 0}
    return config_from_dict({"run": run, ROUGH: hyper})


class _Recorder(KVWriter):
    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def write(self, key_values, key_excluded, step=0) -> None:
        self.rows.append(dict(key_values))


def test_training_envs_only_and_the_levels_are_logged(tmp_path):
    cfg = _curriculum_config()
    assert isinstance(cfg.wrap(gym.make(ROUGH), training=True), TerrainCurriculum)
    assert not isinstance(cfg.wrap(gym.make(ROUGH)), TerrainCurriculum)  # evaluation
    eval_env = make_vec_env(cfg, 1, 0, None, training=False)
    assert not eval_env.env_is_wrapped(TerrainCurriculum)[0]
    eval_env.close()
    model, venv, _ = build(cfg, tmp_path, tensorboard=False)
    assert all(venv.env_is_wrapped(TerrainCurriculum))
    callbacks = make_callbacks(cfg, tmp_path, None)
    log = next(c for c in callbacks if isinstance(c, CurriculumLog))
    recorder = _Recorder()
    model.set_logger(Logger(None, [recorder]))
    model.learn(cfg.n_timesteps, callback=callbacks)  # one rollout, logged at its end
    venv.close()
    (row,) = [r for r in recorder.rows if "curriculum/promoted" in r]
    assert log.promoted + log.demoted >= 1  # episodes of 12 steps: several ended
    assert row["curriculum/promoted"] == log.promoted
    assert row["curriculum/demoted"] == log.demoted
    assert row["curriculum/difficulty_mean"] == pytest.approx(np.mean(log.difficulty))
    assert 0.5 <= row["curriculum/difficulty_min"] <= row["curriculum/difficulty_max"] <= 3.0
    assert list(row["curriculum/difficulty"].numpy()) == list(log.difficulty)  # histogram
    levels = np.asarray(venv.get_attr("curriculum_level"))
    np.testing.assert_array_equal(log.level, levels)
