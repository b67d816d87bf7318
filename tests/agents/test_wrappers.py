"""Observation wrappers: the estimated state the agents see, through impacts, no true state."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env

import envs  # noqa: F401  (registers the ids)
from agents.residual import ResidualWrapper
from agents.wrappers import VELOCITY_LIMIT, EstimatedStateObservation, estimate_features

SETTLED = 20  # control periods (0.1 s = 5 observer time constants)


def test_estimated_state_observation_is_a_valid_env_and_tracks_the_true_state():
    env = EstimatedStateObservation(gym.make("roughwalk/CompassGaitFlat-v0"))
    check_env(env)
    obs, info = env.reset(seed=0)
    assert obs.shape == (15,) and env.observation_space.contains(obs)
    errors = []
    for _ in range(80):  # the passive swing until just before the first touchdown
        obs, _, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
        assert not terminated
        errors.append(np.abs(obs[:4] - info["state"]))
    err = np.array(errors[SETTLED:])
    assert err[:, :2].max() < 3e-3  # rad: encoder quantisation and noise
    assert err[:, 2:].max() < 0.1  # rad/s
    # the scanner's heights pass through unchanged
    raw = env.env.unwrapped.sensor_layout.size
    assert obs.size == 5 + raw - 4


def test_residual_wrapper_observes_the_reference_estimate_through_impacts():
    env = ResidualWrapper(gym.make("roughwalk/CompassGaitStairs-v0"), observe_state=True)
    assert env.observation_space.shape == (14 + 5 + 1,)
    obs, info = env.reset(seed=1)
    impacts, errors = 0, []
    for k in range(600):
        obs, _, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
        assert not (terminated or truncated)
        impacts += info["impacts"]
        est = obs[-6:-1]
        assert est[4] == info["stance_leg"]
        if k >= SETTLED:
            errors.append(np.abs(est[:4] - info["state"]))
    assert impacts >= 2
    err = np.array(errors)
    assert err[:, :2].max() < 5e-3 and err[:, 2:].max() < 0.2
    assert np.median(err[:, 2:]) < 0.03


def test_residual_estimate_uses_the_applied_command():
    """With a residual the env applies base + residual: the base controller's observer is fed
    that input (``applied``), so its estimate stays as good as without a residual; fed its
    own command instead, the velocity error is about four times larger."""

    def max_velocity_error(tell_applied: bool) -> float:
        env = ResidualWrapper(gym.make("roughwalk/CompassGaitFlat-v0"), observe_state=True)
        env.reset(seed=2)
        policy = env.base_policy
        if not tell_applied:
            policy.applied = lambda action: None
        errors = []
        for k in range(60):
            _, _, terminated, _, info = env.step(np.array([0.5 if k % 10 < 5 else -0.5]))
            assert not terminated
            if k >= SETTLED:
                errors.append(np.abs(policy.estimator.x[2:] - info["state"][2:]))
        return float(np.max(errors))

    told, not_told = max_velocity_error(True), max_velocity_error(False)
    assert told < 0.05 and not_told > 2 * told


def test_estimate_observation_needs_an_estimator_and_sensors():
    with pytest.raises(ValueError, match="observe_state=True needs a base policy"):
        ResidualWrapper(
            gym.make("roughwalk/CompassGaitFlat-v0"), base="passive", observe_state=True
        )
    with pytest.raises(ValueError, match="sensor observation"):
        EstimatedStateObservation(gym.make("roughwalk/CompassGaitFlat-v0", observation="state"))


def test_estimated_velocities_are_clipped_to_the_observation_bounds():
    class Estimate:  # an estimator's state after a blow-up: velocities far out of range
        x = np.array([0.3, -0.2, 1e3, -2e3])
        stance_leg = 1

    features = estimate_features(Estimate())
    np.testing.assert_array_equal(features, [0.3, -0.2, VELOCITY_LIMIT, -VELOCITY_LIMIT, 1.0])
    space = EstimatedStateObservation(gym.make("roughwalk/CompassGaitFlat-v0")).observation_space
    np.testing.assert_array_equal(space.high[2:4], [VELOCITY_LIMIT, VELOCITY_LIMIT])
    np.testing.assert_array_equal(space.low[2:4], [-VELOCITY_LIMIT, -VELOCITY_LIMIT])
    assert space.contains(np.r_[features, np.zeros(space.shape[0] - 5)].astype(np.float32))
