"""Actions and time limits that are not what the envs take are rejected, naming what is."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs.physics.actuator import actions_to_torques
from envs.settings import resolve_env_settings
from envs.vector_env import CompassGaitVectorEnv

BAD_SINGLE = [
    ("0.5", TypeError, "a str"),
    (np.array(["0.5"]), TypeError, "dtype <U3"),
    (0.5 + 1j, TypeError, "complex"),
    (np.array([0.5 + 0j]), TypeError, "complex"),
    (None, TypeError, "a NoneType"),
    ({"a": 1}, TypeError, "a dict"),
    (True, TypeError, "dtype bool"),
    (np.zeros(2), ValueError, r"shape \(2,\)"),
    (np.zeros((1, 1, 1)), ValueError, r"shape \(1, 1, 1\)"),
    ([0.5, [1.0]], ValueError, "no array shape"),
]


@pytest.mark.parametrize("action,error,match", BAD_SINGLE)
def test_the_single_env_rejects_actions_that_are_not_one_real_number(action, error, match):
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    env.reset(seed=0)
    with pytest.raises(error, match=rf"shape \(1,\) or \(1, 1\) or one number; got .*{match}"):
        env.step(action)
    assert env.unwrapped.simulator.t[0] == 0.0  # nothing was stepped


@pytest.mark.parametrize(
    "action",
    [0.5, 1, [0.5], [[0.5]], np.float32(0.5), np.array([0.5], np.float32), np.array([0.5])],
)
def test_the_single_env_takes_floats_lists_and_arrays(action):
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    env.reset(seed=0)
    obs, *_ = env.step(action)
    expected = np.zeros(1)
    actions_to_torques(np.array([float(np.ravel(action)[0])]), env.unwrapped.torque_limit, expected)
    assert env.unwrapped._batch._torques[0] == expected[0]


@pytest.mark.parametrize(
    "actions,error",
    [
        (np.array([["0.5"], ["0.1"]]), TypeError),
        (np.zeros((2, 1), complex), TypeError),
        ([None, None], TypeError),
        (np.zeros((1, 2)), ValueError),
        (np.zeros((2, 2)), ValueError),
        (0.5, ValueError),
    ],
)
def test_the_vector_env_rejects_bad_batches_naming_the_shape(actions, error):
    venv = CompassGaitVectorEnv(2, "flat")
    venv.reset(seed=0)
    with pytest.raises(error, match=r"float32 or float64\) of shape \(2,\) or \(2, 1\)"):
        venv.step(actions)
    obs, *_ = venv.step(np.zeros(2))  # (n,) is taken as well as (n, 1)
    assert obs.shape[0] == 2


@pytest.mark.parametrize("steps", [2.5, 0, "3", True, float("nan")])
def test_max_episode_steps_must_be_an_integer(steps):
    with pytest.raises(ValueError, match=r"max_episode_steps = .*; allowed: integer >= 1"):
        CompassGaitVectorEnv(2, "flat", max_episode_steps=steps)
    with pytest.raises(ValueError, match=r"max_episode_steps = .*; allowed: integer >= 1"):
        resolve_env_settings("flat", max_episode_steps=steps)
    assert CompassGaitVectorEnv(1, "flat", max_episode_steps=3.0).max_episode_steps == 3
