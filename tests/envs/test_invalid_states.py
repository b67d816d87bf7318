"""Absurd inputs at the env level: rejected with clear errors, or a finite "invalid" ending."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs import CompassGaitEnv
from envs.vector_env import CompassGaitVectorEnv

#: a start state of the classic walker whose first substep under full torque passes its rate
#: bound (100 rad/s): the integration blows up and the episode must end as "invalid"
DIVERGING = ((0.3, -0.15), (99.9, -99.9))


@pytest.mark.parametrize("rate", [1e6, 1e20, 1e50])
def test_absurd_start_rates_are_rejected_naming_the_option(rate):
    env = CompassGaitEnv("flat")
    with pytest.raises(ValueError, match=r"reset option 'state': qd0 = .* rad/s"):
        env.reset(seed=0, options={"state": ((0.3, -0.15), (rate, rate))})


def test_an_absurd_torque_limit_is_rejected_naming_it():
    with pytest.raises(ValueError, match=r"torque_limit = 1e\+100 out of range; allowed: \(0, "):
        gym.make("roughwalk/CompassGaitFlat-v0", torque_limit=1e100)
    with pytest.raises(ValueError, match=r"RobotParams\.u_max = .* out of range"):
        gym.make("roughwalk/CompassGaitFlat-v0", u_max=1e300)


@pytest.mark.parametrize("observation", ["sensors", "state"])
def test_a_diverging_episode_ends_invalid_with_finite_outputs(observation):
    env = gym.make(
        "roughwalk/CompassGait-v0", robot="classic", observation=observation,
        render_mode="rgb_array",
    )  # fmt: skip
    obs, _ = env.reset(seed=0, options={"state": DIVERGING})
    obs, reward, terminated, truncated, info = env.step(np.array([1.0], dtype=np.float32))
    assert terminated and not truncated and info["failure"] == "invalid"
    assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs)
    # the walker is left at its last valid state (here the start): no progress, no work, so
    # the reward is the failure penalty
    assert reward == -env.unwrapped.settings.reward.failure
    assert np.array_equal(info["state"], [0.3, -0.15, 99.9, -99.9])
    frame = env.render()
    assert frame.shape[2] == 3 and frame.dtype == np.uint8
    env.close()


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_the_vector_env_ends_a_diverging_walker_invalid_and_autoresets_it(mode):
    venv = CompassGaitVectorEnv(
        2, "flat", robot="classic", autoreset_mode=mode, render_mode="rgb_array"
    )
    venv.reset(seed=0)
    venv.reset(options={"state": DIVERGING, "reset_mask": np.array([True, False])})
    actions = np.array([[1.0], [0.0]], dtype=np.float32)
    obs, rew, term, trunc, info = venv.step(actions)
    assert term.tolist() == [True, False] and np.all(np.isfinite(rew))
    assert venv.observation_space.contains(obs)
    if mode == "next_step":
        assert info["failure"][0] == "invalid"
        assert all(f.shape[2] == 3 for f in venv.render())
        obs, rew, term, trunc, info = venv.step(actions)  # sub-env 0 resets
        assert rew[0] == 0.0 and not term[0] and info["failure"][0] is None
    else:
        assert info["final_info"]["failure"][0] == "invalid"
        final = info["final_obs"][0]
        assert np.all(np.isfinite(final)) and venv.single_observation_space.contains(final)
        assert info["failure"][0] is None  # already reset
    assert venv.observation_space.contains(obs)
    venv.close()
