"""Observation wrappers for learning agents.

``EstimatedStateObservation`` gives an agent what the reference controller works from: the
state estimated from the sensors (encoders and contact switches through the high-gain observer
and the touchdown locator of :class:`controllers.estimator.SensorStateEstimator`) instead of
the raw encoder readings, which carry no velocity. Learned and classical controllers then see
the same information, and neither reads the true state.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from controllers.estimator import SensorStateEstimator
from envs.physics.actuator import input_from_action

VELOCITY_LIMIT = 50.0  # [rad/s]: estimated velocities are clipped to this in the observation


def estimate_features(estimator: SensorStateEstimator) -> np.ndarray:
    """``[q1, q2, q1d, q2d, stance_leg]`` of an estimator (velocities clipped to
    ``+-VELOCITY_LIMIT``), as agents observe it."""
    x = estimator.x
    v = np.clip(x[2:], -VELOCITY_LIMIT, VELOCITY_LIMIT)
    return np.r_[x[:2], v, float(estimator.stance_leg)]


ESTIMATE_LOW = np.array([-np.pi, -np.pi, -VELOCITY_LIMIT, -VELOCITY_LIMIT, 0.0])
ESTIMATE_HIGH = np.array([np.pi, np.pi, VELOCITY_LIMIT, VELOCITY_LIMIT, 1.0])


class EstimatedStateObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the encoder and contact-switch readings by the estimated state.

    The observation becomes ``[q1, q2, q1d, q2d, stance_leg, heights...]`` (float32):
    the estimate of :class:`SensorStateEstimator` (angles [rad], velocities [rad/s] clipped to
    ``+-VELOCITY_LIMIT``), the stance leg from the contact switches (0 = A, 1 = B) and the
    terrain scanner's heights unchanged. The estimator is fed the action applied at each step.
    If the estimate stops being finite (after a fall, say) it restarts from the measured
    angles at zero velocity.

    Args:
        env: a roughwalk env observing ``"sensors"``.
        eps: observer time constant [s]; None: from the encoders' noise
            (:func:`controllers.observer.eps_for_noise`).
    """

    def __init__(self, env: gym.Env, eps: float | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, eps=eps)
        gym.Wrapper.__init__(self, env)
        self.estimator = SensorStateEstimator(env, eps)
        layout = self.estimator.layout
        obs_space = env.observation_space
        if not isinstance(obs_space, spaces.Box) or obs_space.shape != (layout.size,):
            raise ValueError(
                f"EstimatedStateObservation needs the sensor observation, got {obs_space}"
            )
        n_scan = layout.size - 4
        low = np.r_[ESTIMATE_LOW, obs_space.low[4:]]
        high = np.r_[ESTIMATE_HIGH, obs_space.high[4:]]
        self.observation_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), (5 + n_scan,), np.float32
        )

    def _observe(self, obs: np.ndarray, u: float) -> np.ndarray:
        est = self.estimator
        q, leg = est.decode(obs)
        try:
            est.update(q, leg, u)
        except FloatingPointError:
            est.observer.reset(q, np.zeros(2))
        out = np.empty(self.observation_space.shape, dtype=np.float32)
        out[:5] = estimate_features(est)
        out[5:] = obs[4:]
        return out

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env with ``seed`` and ``options``, and the estimator."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.estimator.reset()
        return self._observe(obs, 0.0), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Step the env with ``action``; the estimator is fed the command applied."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        obs, reward, terminated, truncated, info = self.env.step(action)
        # the env has checked the action (finite); it applies it clipped to [-1, 1]
        u = input_from_action(float(a[0]), self.estimator.u_max)
        return self._observe(obs, u), reward, terminated, truncated, info
