"""Per-footstep residual RL: the agent adjusts the reference planner once per footstep.

:class:`FootstepWrapper` turns a roughwalk env into a semi-Markov decision process whose steps
are footsteps: the agent's action in [-1, 1]^k sets ``k`` planner settings of the reference
controller for the next footstep (each the configured value plus ``half_range * action``, e.g.
the preferred foothold moved by up to 3 cm, the walking speed aimed at, the torque reserve),
and the wrapper then runs the reference controller tick by tick until the next touchdown (or
the episode's end). The reward is the sum of the ticks' rewards; ``info["ticks"]`` says how
many control periods the footstep took (for a discount per tick, ``gamma ** ticks``; SB3's
algorithms discount per agent step); the env's per-step entries of ``info`` cover the whole
footstep (``motor_work`` and ``impacts`` summed, ``push`` the last push in it), the others are
the last tick's. A zero action is the reference controller exactly.

This is the option-style residual of the residual-RL literature applied to the planner's
choices (where the per-tick torque residual of :class:`agents.residual.ResidualWrapper` acts
on the command): the agent decides where and how fast to step; the transverse feedback tracks
what the planner makes of it. The observation at each decision is the env's (encoders,
contacts and terrain scan at the touchdown) with, optionally, the controller's state estimate
(:func:`agents.wrappers.estimate_features`) appended.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agents.policies import make_baseline_policy
from agents.wrappers import ESTIMATE_HIGH, ESTIMATE_LOW, estimate_features

#: the planner settings a footstep action may set, with the range it is clipped to [units]
ADJUSTABLE: dict[str, tuple[float, float]] = {
    "foothold_shift": (-0.1, 0.1),  # preferred foothold moved [m]
    "target_speed": (0.02, 1.0),  # walking speed the plan regulates towards [m/s]
    "torque_fraction": (0.05, 1.0),  # nominal input's share of the actuator limit
    "end_thetadot_floor": (0.0, 3.0),  # speed reserve at the end of a step before a drop [rad/s]
}
#: default adjustments: planner setting -> half-range of the action [its units]
DEFAULT_ADJUST: dict[str, float] = {
    "foothold_shift": 0.03,  # preferred foothold moved by up to 3 cm [m]
    "target_speed": 0.05,  # walking speed aimed at [m/s]
    "torque_fraction": 0.1,  # nominal input's share of the actuator limit
}
#: the most control periods one footstep may take before the wrapper returns anyway
MAX_TICKS = 2000


class FootstepWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """One agent step per footstep: the action adjusts the reference planner's settings.

    Args:
        env: a roughwalk env observing sensors (``gym.make(id)``, its default).
        adjust: the planner settings the action sets, ``{setting of ADJUSTABLE: half-range}``
            (positive, in the setting's units); action ``a_i`` gives ``configured + half_range *
            a_i``, clipped to the setting's range in :data:`ADJUSTABLE`. Default
            :data:`DEFAULT_ADJUST`.
        observe_state: append the controller's state estimate (``q1, q2, q1d, q2d``, stance
            leg) to the observation.
        base_kwargs: options of the reference policy (``agents.policies.make_baseline_policy``,
            e.g. ``planner`` settings).

    Raises:
        ValueError: a setting not in :data:`ADJUSTABLE`, a half-range that is not finite and
            positive, or an env whose action or observation space is not a ``Box``.
    """

    def __init__(
        self,
        env: gym.Env,
        adjust: Mapping[str, float] | None = None,
        observe_state: bool = True,
        base_kwargs: dict[str, Any] | None = None,
    ) -> None:
        adjust = dict(DEFAULT_ADJUST if adjust is None else adjust)
        gym.utils.RecordConstructorArgs.__init__(
            self, adjust=adjust, observe_state=observe_state, base_kwargs=base_kwargs
        )
        gym.Wrapper.__init__(self, env)
        if not isinstance(env.action_space, spaces.Box):
            raise ValueError(f"FootstepWrapper needs a Box action space, got {env.action_space}")
        obs_space = env.observation_space
        if not isinstance(obs_space, spaces.Box) or len(obs_space.shape) != 1:
            raise ValueError(f"FootstepWrapper needs a flat Box observation, got {obs_space}")
        if not adjust:
            raise ValueError("adjust: give at least one planner setting to adjust")
        for name, half in adjust.items():
            if name not in ADJUSTABLE:
                raise ValueError(
                    f"adjust: {name!r} cannot be adjusted per footstep; allowed: "
                    f"{', '.join(ADJUSTABLE)}"
                )
            if isinstance(half, bool) or not (
                isinstance(half, (int, float)) and math.isfinite(half) and half > 0
            ):
                raise ValueError(f"adjust.{name} = {half!r}; allowed: a finite half-range > 0")
        self.adjust = {k: float(v) for k, v in adjust.items()}
        self.observe_state = bool(observe_state)
        self.base_policy = make_baseline_policy("reference", env, **(base_kwargs or {}))
        self.controller = self.base_policy.controller
        self.configured = self.controller.planner.config
        self._base = np.array([getattr(self.configured, k) for k in self.adjust])
        self._lo = np.array([ADJUSTABLE[k][0] for k in self.adjust])
        self._hi = np.array([ADJUSTABLE[k][1] for k in self.adjust])
        self.action_space = spaces.Box(-1.0, 1.0, shape=(len(self.adjust),), dtype=np.float32)
        lo, hi = [obs_space.low], [obs_space.high]
        if self.observe_state:
            lo.append(ESTIMATE_LOW)
            hi.append(ESTIMATE_HIGH)
        self.observation_space = spaces.Box(
            low=np.concatenate(lo).astype(obs_space.dtype),
            high=np.concatenate(hi).astype(obs_space.dtype),
            dtype=obs_space.dtype,
        )
        self._obs: Any = None
        self._footsteps = 0

    def settings(self, action: Any) -> dict[str, float]:
        """The planner settings action ``action`` gives (only those it changes)."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (len(self.adjust),) or not np.all(np.isfinite(a)):
            raise ValueError(
                f"footstep action must be {len(self.adjust)} finite numbers, got {action!r}"
            )
        half = np.fromiter(self.adjust.values(), dtype=np.float64)
        values = np.clip(self._base + half * np.clip(a, -1.0, 1.0), self._lo, self._hi)
        return {
            k: float(v) for k, v, b in zip(self.adjust, values, self._base, strict=True) if v != b
        }

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        if not self.observe_state:
            return obs
        parts = [np.asarray(obs, dtype=np.float64), estimate_features(self.base_policy.estimator)]
        return np.concatenate(parts).astype(self.observation_space.dtype, copy=False)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset the env and the reference controller (it plans its first step at the first
        tick, with the planner the first action sets)."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.base_policy.reset()
        self.controller.adjust_planner()
        self._obs = obs
        self._footsteps = int(info.get("footsteps", 0))
        return self._observe(obs), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Set the planner for the next footstep from ``action``, then walk to the next
        touchdown (at most :data:`MAX_TICKS` control periods) with the reference controller."""
        self.controller.adjust_planner(**self.settings(action))
        obs, total, ticks, work, impacts, push = self._obs, 0.0, 0, 0.0, 0, None
        terminated = truncated = False
        info: dict[str, Any] = {}
        while ticks < MAX_TICKS:
            obs, reward, terminated, truncated, info = self.env.step(self.base_policy(obs))
            total += float(reward)
            ticks += 1
            work += float(info.get("motor_work", 0.0))
            impacts += int(info.get("impacts", 0))
            push = info.get("push", push)
            footsteps = int(info.get("footsteps", self._footsteps))
            if terminated or truncated or footsteps > self._footsteps:
                self._footsteps = footsteps
                break
        self._obs = obs
        info = dict(info)
        # the env's per-step entries, over the footstep's control periods
        info.update(ticks=ticks, motor_work=work, impacts=impacts)
        if push is not None:
            info["push"] = push
        config = self.controller.planner.config
        info["planner_settings"] = {k: float(getattr(config, k)) for k in self.adjust}
        return self._observe(obs), total, terminated, truncated, info
