"""State estimation from the environment's sensors: encoders, contact switches, observer.

:class:`SensorStateEstimator` turns the sensor observation of the roughwalk envs into an
estimate of the full state ``(q1, q2, q1d, q2d)``, the stance leg and the stance-foot position,
as the paper's controller does. Every tick it decodes the two encoders into ``q`` with the
stance leg from the contact switches and advances the high-gain observer
(:mod:`controllers.observer`) with the input applied over the last period. When the contact
switches report a new stance leg, the touchdown inside the last period is located on the
terrain map by integrating the observer's model from the previous estimate
(:func:`controllers.observer.predict_touchdown`); the impact map is applied to the estimate
there and the stance foot moves to the located foothold (dead reckoning on the map).

The reference policy (:mod:`controllers.reference`) and the RL observation wrapper
(``agents.wrappers.EstimatedStateObservation``) share it, so learned and classical controllers
see the same estimate.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.physics.encoders import encoders_to_q, stance_from_contacts
from envs.physics.terrain import Terrain

from .observer import (
    HighGainObserver,
    observer_impact,
    observer_update,
    predict_touchdown,
    substeps_for,
)

__all__ = ["IMPACT", "START", "TICK", "SensorStateEstimator"]

#: what :meth:`SensorStateEstimator.update` reports about a tick
START, TICK, IMPACT = "start", "tick", "impact"


class SensorStateEstimator:
    """Estimated state of a roughwalk env's walker from its sensor observations.

    Args:
        env: the environment (as ``gym.make`` returns it; wrappers are looked through); it must
            expose ``robot``, ``dt``, ``u_max`` and ``sensor_layout`` and observe sensors.
        eps: observer time constant [s] (paper: 0.02), > 0.
        initial_velocity: velocity guess ``(q1d, q2d)`` [rad/s] at the start of an episode;
            default: the environment's nominal start velocity (its configuration, not the
            episode's true state), else zero.

    Attributes:
        x: the estimate ``[q1, q2, q1d, q2d]`` [rad, rad/s] (a view, updated in place).
        stance_leg: physical stance leg (0 = A, 1 = B) from the contact switches.
        stance_foot: estimated stance-foot position ``(x, y)`` [m].
        terrain: the terrain map the touchdowns are located on (the env's course).
        t: time since the start of the episode [s].
        touchdowns_located, touchdowns_guessed: touchdowns located inside their period, and
            those taken at the end of the period (none found by the model).
    """

    def __init__(
        self,
        env: gym.Env,
        eps: float = 0.02,
        initial_velocity: tuple[float, float] | None = None,
    ) -> None:
        u = env.unwrapped
        for name in ("robot", "dt", "u_max", "sensor_layout"):
            if not hasattr(u, name):
                raise ValueError(f"the environment does not expose '{name}' (env.unwrapped.{name})")
        if getattr(u, "observation_mode", "sensors") != "sensors":
            raise ValueError(
                "state estimation reads the sensor observation: make the env "
                "with observation='sensors'"
            )
        self.env = u
        self.robot = u.robot
        self.P = self.robot.vector()
        self.dt = float(u.dt)
        self.u_max = float(u.u_max)
        self.layout = u.sensor_layout
        self.observer = HighGainObserver(self.robot, self.dt, eps)
        if initial_velocity is None:
            init = getattr(getattr(u, "settings", None), "initial_state", None)
            initial_velocity = tuple(init.qd) if init is not None else (0.0, 0.0)
        self.initial_velocity = np.asarray(initial_velocity, dtype=np.float64)
        self._nsub_td = 16
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call after ``env.reset``); the next update starts a new one."""
        self.started = False
        self.stance_leg = 0
        self.stance_foot = (0.0, 0.0)
        self.t = 0.0
        self.terrain = Terrain.flat()
        self._tx, self._ty = self.terrain.arrays()
        self.touchdowns_located = 0
        self.touchdowns_guessed = 0

    @property
    def x(self) -> np.ndarray:
        """The estimate ``[q1, q2, q1d, q2d]`` [rad, rad/s] (the observer's, updated in place)."""
        return self.observer.x

    def decode(self, obs: Any) -> tuple[np.ndarray, int]:
        """Measured ``q`` [rad] and the stance leg from one sensor observation.

        Raises:
            ValueError: the observation has the wrong size or is not finite.
        """
        o = np.asarray(obs, dtype=np.float64)
        if o.shape != (self.layout.size,) or not np.all(np.isfinite(o)):
            raise ValueError(f"observation must be {self.layout.size} finite numbers")
        lay = self.layout
        leg = stance_from_contacts(o[lay.contact_a], o[lay.contact_b], self.stance_leg)
        return np.array(encoders_to_q(o[lay.hip], o[lay.leg_a], leg)), leg

    def update(self, q: np.ndarray, leg: int, u: float) -> str:
        """Take the decoded measurement of a new tick; ``u`` [input units] is the input applied
        over the period that ended with it. Returns ``"start"`` (first tick of an episode:
        the estimate starts at ``q`` and the initial velocity guess), ``"impact"`` (a touchdown
        happened in the period: estimate mapped, stance foot moved) or ``"tick"``.

        Raises:
            FloatingPointError: the estimate is no longer finite.
        """
        if not self.started:
            terrain = getattr(self.env, "terrain", None)
            self.terrain = terrain if isinstance(terrain, Terrain) else Terrain.flat()
            self._tx, self._ty = self.terrain.arrays()
            self.stance_foot = (0.0, float(self.terrain.height(0.0)))
            self.stance_leg = leg
            self.observer.reset(q, self.initial_velocity)
            self.started = True
            return START
        self.t += self.dt
        event = TICK
        if leg != self.stance_leg:
            self._touchdown(q, u)
            self.stance_leg = leg
            event = IMPACT
        else:
            self.observer.update(q, u)
        if not np.all(np.isfinite(self.observer.x)):
            raise FloatingPointError("non-finite observer estimate")
        return event

    def _touchdown(self, q_meas: np.ndarray, u: float) -> None:
        """Impact inside the last period: locate it, map the estimate, move the stance foot."""
        x = self.observer.x
        xs, ys = self.stance_foot
        found, tau, xpre, fx = predict_touchdown(
            self.P,
            x.copy(),
            u,
            2.0 * self.dt,  # the estimate may lag the touchdown a little: search a bit beyond
            self._tx,
            self._ty,
            self._tx.size,
            xs,
            ys,
            2 * self._nsub_td,
            # a crossing counts once the full-length swing foot is the robot's arming distance
            # ahead of the stance foot (the simulator's and the planner's rule)
            self.robot.arm_distance * self.robot.l,
        )
        if not found:  # take the state at the end of the period as the pre-impact state
            _, tau, xpre, fx = predict_touchdown(
                self.P,
                x.copy(),
                u,
                self.dt,
                self._tx,
                self._ty,
                self._tx.size,
                xs,
                ys,
                self._nsub_td,
                math.inf,
            )
        if found:
            self.touchdowns_located += 1
        else:
            self.touchdowns_guessed += 1
        x[:] = xpre
        observer_impact(self.P, x)
        rest = self.dt - min(tau, self.dt)
        if rest > 1e-9:
            # the measurement goes from the mapped estimate to the new sample
            nsub = substeps_for(rest, self.observer.eps)
            observer_update(
                self.P, x, x[0], x[1], q_meas[0], q_meas[1], u, rest, self.observer.eps, nsub
            )
        self.observer.q_last = q_meas.copy()
        self.stance_foot = (float(fx), float(self.terrain.height(float(fx))))
