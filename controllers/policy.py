"""Reference policy for the Gymnasium environments: observer + planner + transverse controller.

The policy sees what the paper's controller sees: the sensor observation (two encoders, two
contact switches; the terrain scan is not needed) plus what the environment tells a controller
about the world and the robot (``env.unwrapped``: ``robot``, ``terrain``, ``dt``, ``u_max``,
``sensor_layout``). It never reads the true state.

Every tick it decodes the encoders into ``q`` with the stance leg from the contact switches,
advances the high-gain observer (:mod:`controllers.observer`), and applies the controller's
input to the estimate. When the contact switches report a new stance leg, the touchdown inside
the last control period is located on the terrain map by integrating the observer's model from
the previous estimate (:func:`controllers.observer.predict_touchdown`); the impact map is applied
to the estimate there, the stance-foot position is updated (dead reckoning on the map) and the
controller replans. Shortly after the start, once the observer has converged (``settle_time``),
the current step is replanned from the estimate.

Safe behaviour: if planning fails, the controller shortens its look-ahead (down to a single
planned step held with PD on ``y``), keeps the previous plan, or, with nothing left, applies
zero input (:mod:`controllers.controller`); if anything else fails inside a tick (a non-finite
estimate, say), the policy applies zero input for the rest of the episode. Both are recorded in
:attr:`ReferencePolicy.diagnostics` (``"fallbacks"``: ``(kind, time, reason)``). A call never
raises because of the robot's state.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.terrain import Terrain

from .controller import ControllerConfig, PDController, TransverseController
from .observer import HighGainObserver, observer_impact, observer_update, predict_touchdown
from .planner import GaitPlanner, PlannerConfig

__all__ = ["PDPolicy", "ReferencePolicy", "make_reference_policy"]


class ReferencePolicy:
    """Sensor-based walking policy: ``action = policy(observation)``.

    Args:
        env: the environment (as ``gym.make`` returns it; wrappers are looked through).
        config: :class:`ControllerConfig` or dict (default: replan at every footstep, h = 3).
        planner: :class:`GaitPlanner`, :class:`PlannerConfig`, dict or None (robot default).
        eps: observer time constant [s] (paper: 0.02).
        settle_time: time after the start at which the current step is replanned from the
            observer's estimate [s].
        initial_velocity: velocity guess ``(q1d, q2d)`` [rad/s] for the observer at the start;
            default: the environment's nominal start velocity (its configuration, not the
            episode's true state), else zero.
        record_history: keep per-tick ``t, q_meas, x_hat, u, stance_leg, nominal`` in
            :attr:`history` (nominal: ``q1, q1d, q2d`` of the current step at the estimated
            phase).
        controller_kwargs: passed to the controller class (``kp``, ``kd`` for :class:`PDPolicy`).
    """

    controller_class = TransverseController

    def __init__(
        self,
        env: gym.Env,
        config: ControllerConfig | dict | None = None,
        planner: GaitPlanner | PlannerConfig | dict | None = None,
        eps: float = 0.02,
        settle_time: float = 0.1,
        initial_velocity: tuple[float, float] | None = None,
        record_history: bool = False,
        **controller_kwargs: Any,
    ):
        u = env.unwrapped
        for name in ("robot", "dt", "u_max", "sensor_layout"):
            if not hasattr(u, name):
                raise ValueError(f"the environment does not expose '{name}' (env.unwrapped.{name})")
        if getattr(u, "observation_mode", "sensors") != "sensors":
            raise ValueError(
                "the reference policy reads the sensor observation: make the env "
                "with observation='sensors'"
            )
        self.env = u
        self.robot = u.robot
        self.P = self.robot.vector()
        self.dt = float(u.dt)
        self.u_max = float(u.u_max)
        self.layout = u.sensor_layout
        if config is None:
            config = ControllerConfig()
        self.controller = self.controller_class(
            self.robot, "flat", config, planner, **controller_kwargs
        )
        self.observer = HighGainObserver(self.robot, self.dt, eps)
        self.settle_time = float(settle_time)
        if initial_velocity is None:
            init = getattr(getattr(u, "settings", None), "initial_state", None)
            initial_velocity = tuple(init.qd) if init is not None else (0.0, 0.0)
        self.initial_velocity = np.asarray(initial_velocity, dtype=np.float64)
        self._nsub_td = 16
        self.record_history = bool(record_history)
        self.reset()

    # ------------------------------------------------------------------ episode
    def reset(self) -> None:
        """Forget the episode (call after ``env.reset``); the next call starts a new one."""
        self._started = False
        self._stance_leg = 0
        self._u = 0.0
        self._t = 0.0
        self._settled = False
        self._dead = False
        self.stance_foot = (0.0, 0.0)
        self.diagnostics: dict[str, Any] = {
            "footsteps": 0,
            "fallbacks": [],
            "touchdowns_located": 0,
            "touchdowns_guessed": 0,
            "error": None,
        }
        self.history: dict[str, list] = {
            "t": [],
            "q_meas": [],
            "x_hat": [],
            "u": [],
            "stance_leg": [],
            "nominal": [],
        }

    @property
    def records(self) -> list:
        """The controller's per-footstep :class:`StepRecord` list."""
        return self.controller.records

    def _decode(self, obs: np.ndarray) -> tuple[np.ndarray, int]:
        o = np.asarray(obs, dtype=np.float64)
        if o.shape != (self.layout.size,) or not np.all(np.isfinite(o)):
            raise ValueError(f"observation must be {self.layout.size} finite numbers")
        ca, cb = o[2] > 0.5, o[3] > 0.5
        leg = 0 if (ca and not cb) else 1 if (cb and not ca) else self._stance_leg
        hip, leg_a = o[0], o[1]
        if leg == 1:
            return np.array([-hip, leg_a - hip]), 1
        return np.array([hip, leg_a]), 0

    def _start(self, q: np.ndarray, leg: int) -> None:
        terrain = getattr(self.env, "terrain", None)
        self.terrain = terrain if isinstance(terrain, Terrain) else Terrain.flat()
        self.controller.terrain = self.terrain
        self._tx, self._ty = self.terrain.arrays()
        self.stance_foot = (0.0, float(self.terrain.height(0.0)))
        self._stance_leg = leg
        self.observer.reset(q, self.initial_velocity)
        self.controller.reset(q, self.initial_velocity.copy(), self.stance_foot, t=0.0)
        self._started = True

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Action (float32, shape (1,)) for one sensor observation."""
        q, leg = self._decode(obs)
        if self._dead:
            return np.zeros(1, dtype=np.float32)
        try:
            u = self._tick(q, leg)
        except Exception as exc:  # never crash a rollout: record and go limp
            self._dead = True
            self.diagnostics["error"] = f"{type(exc).__name__}: {exc}"
            self.diagnostics["fallbacks"].append(("zero input", self._t, str(exc)))
            u = 0.0
        self._u = u
        return np.array([max(-1.0, min(1.0, u / self.u_max))], dtype=np.float32)

    def _tick(self, q: np.ndarray, leg: int) -> float:
        if not self._started:
            self._start(q, leg)
        else:
            self._t += self.dt
            obs_x = self.observer.x
            if leg != self._stance_leg:
                self._touchdown(q)
                self._stance_leg = leg
            else:
                self.observer.update(q, self._u)
            if not np.all(np.isfinite(obs_x)):
                raise FloatingPointError("non-finite observer estimate")
            if not self._settled and self._t >= self.settle_time - 1e-12:
                self._settled = True
                self.controller.replan(obs_x[:2].copy(), obs_x[2:].copy())
                self._note_fallback()
        x = self.observer.x
        u = self.controller.control(x[:2], x[2:])
        if self.record_history:
            h = self.history
            h["t"].append(self._t)
            h["q_meas"].append(q.copy())
            h["x_hat"].append(x.copy())
            h["u"].append(u)
            h["stance_leg"].append(self._stance_leg)
            h["nominal"].append(self.controller.nominal(x[1]))
        return u

    def _touchdown(self, q_meas: np.ndarray) -> None:
        """Impact inside the last period: locate it, map the estimate, replan."""
        x = self.observer.x
        xs, ys = self.stance_foot
        found, tau, xpre, fx = predict_touchdown(
            self.P,
            x.copy(),
            self._u,
            2.0 * self.dt,  # the estimate may lag the touchdown a little: search a bit beyond
            self._tx,
            self._ty,
            self._tx.size,
            xs,
            ys,
            2 * self._nsub_td,
            0.1 * self.robot.l,
        )
        if not found:  # take the state at the end of the period as the pre-impact state
            _, tau, xpre, fx = predict_touchdown(
                self.P,
                x.copy(),
                self._u,
                self.dt,
                self._tx,
                self._ty,
                self._tx.size,
                xs,
                ys,
                self._nsub_td,
                math.inf,
            )
        self.diagnostics["touchdowns_located" if found else "touchdowns_guessed"] += 1
        x[:] = xpre
        observer_impact(self.P, x)
        rest = self.dt - min(tau, self.dt)
        if rest > 1e-9:
            # the measurement goes from the mapped estimate to the new sample
            nsub = max(1, math.ceil(rest / (0.25 * self.observer.eps)))
            observer_update(
                self.P,
                x,
                x[0],
                x[1],
                q_meas[0],
                q_meas[1],
                self._u,
                rest,
                self.observer.eps,
                nsub,
            )
        self.observer.q_last = q_meas.copy()
        self.stance_foot = (float(fx), float(self.terrain.height(float(fx))))
        self.diagnostics["footsteps"] += 1
        self.controller.on_impact(x[:2].copy(), x[2:].copy(), self.stance_foot, t=self._t)
        self._note_fallback()

    def _note_fallback(self) -> None:
        rec = self.controller.records[-1] if self.controller.records else None
        if rec is not None and rec.fallback is not None:
            self.diagnostics["fallbacks"].append((rec.fallback, self._t, rec.reason))


class PDPolicy(ReferencePolicy):
    """The reference policy with the transverse feedback replaced by plain PD on ``y``
    (:class:`controllers.controller.PDController`; keyword arguments ``kp``, ``kd``)."""

    controller_class = PDController


def make_reference_policy(env: gym.Env, **kwargs: Any) -> ReferencePolicy:
    """The reference policy for ``env`` (see :class:`ReferencePolicy` for the options)."""
    return ReferencePolicy(env, **kwargs)
