"""Residual RL: the agent learns a correction on top of a base (reference) policy.

The residual lives in the environment, not in the agent: ``ResidualWrapper`` turns the agent's
action ``a`` in [-1, 1] into the command ``clip(b + scale * a, -1, 1)`` sent to the wrapped
env. ``b = clip(base(obs), -1, 1)`` is the command of a base policy, i.e. what it would apply on
its own (so the residual can also pull a saturated command back); the base policy has
``reset()`` and ``__call__(obs) -> action``
(by default the reference controller, ``controllers.make_reference_policy``). Any RL algorithm
then trains on the residual unchanged: PPO's rollouts and SAC's replay buffer see the agent's
own action, the env applies the sum. (Overriding an SB3 policy's ``predict`` instead would be
silently wrong, because rollout collection and off-policy sampling bypass ``predict``.)

With ``observe_base=True`` the base command is appended to the observation as its last entry,
so the agent knows what it is correcting; with ``observe_state=True`` the base policy's state
estimate (``q1, q2, q1d, q2d`` and the stance leg, from its
:class:`controllers.estimator.SensorStateEstimator`) comes before it, since the encoders alone
carry no velocity. When the applied command differs from the base policy's own, a base
policy with an ``applied(action)`` method (the reference controllers) is told it, so its
observer integrates the model with the true input. ``info`` carries ``base_action``,
``residual_action`` (the scaled residual) and ``total_action`` for every step. A zero residual
reproduces the base policy exactly (for base policies that return the action space's float32,
as the roughwalk controllers do). The wrapper is a plain ``gymnasium.Wrapper``, so it works
with SB3's ``make_vec_env`` (``wrapper_class``), ``VecNormalize``, rl-zoo3's ``env_wrapper``
and the vector-env adapter.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agents.policies import Policy, make_baseline_policy
from agents.wrappers import ESTIMATE_HIGH, ESTIMATE_LOW, estimate_features

BaseSpec = str | Policy | Callable[[gym.Env], Policy]
#: largest residual authority [action units]: the command range [-1, 1] spans 2
MAX_SCALE = 2.0


class ResidualWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Adds the agent's scaled action to a base policy's command.

    Args:
        env: an env with a ``Box`` action space in [-1, 1] (the roughwalk envs' normalised
            hip command) and, with ``observe_base``, a ``Box`` observation space.
        base: the base policy: a name accepted by ``agents.policies.make_baseline_policy``
            (``"reference"``, ``"pd"``, ``"passive"``), a policy object, or a factory
            ``env -> policy`` (called once with the wrapped env).
        scale: residual authority, in action units: the agent can move the command by at most
            ``scale`` either way; in (0, 2] (2 spans the whole command range). Training can
            ramp it up from 0 (:meth:`set_scale`, ``agents.callbacks.ResidualScaleRamp``).
        observe_base: append the base command to the observation.
        observe_state: append the base policy's state estimate ``q1, q2, q1d, q2d, stance leg``
            [rad, rad/s, 0/1] (``agents.wrappers.estimate_features``) before the base command; the
            base policy must have an ``estimator`` (the reference controllers do).
        base_kwargs: options of a named base policy (e.g. ``planner`` settings of the
            reference controller; see ``agents.policies.make_baseline_policy``).

    Out-of-range agent actions are clipped to [-1, 1]; NaN or inf raise ``ValueError``.
    """

    def __init__(
        self,
        env: gym.Env,
        base: BaseSpec = "reference",
        scale: float = 0.3,
        observe_base: bool = True,
        base_kwargs: dict[str, Any] | None = None,
        observe_state: bool = False,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            base=base,
            scale=scale,
            observe_base=observe_base,
            base_kwargs=base_kwargs,
            observe_state=observe_state,
        )
        gym.Wrapper.__init__(self, env)
        act = env.action_space
        if not isinstance(act, spaces.Box):
            raise ValueError(f"ResidualWrapper needs a Box action space, got {act}")
        if not (np.isfinite(scale) and 0 < scale <= MAX_SCALE):
            raise ValueError(
                f"scale = {scale!r} is out of range; allowed: in (0, {MAX_SCALE:g}] (action units)"
            )
        self.scale = float(scale)
        self.max_scale = float(scale)
        self.observe_base = bool(observe_base)
        self.observe_state = bool(observe_state)
        self._low = act.low.astype(np.float64)
        self._high = act.high.astype(np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=act.shape, dtype=np.float32)
        if self.observe_base or self.observe_state:
            obs_space = env.observation_space
            if not isinstance(obs_space, spaces.Box) or len(obs_space.shape) != 1:
                raise ValueError(
                    f"observe_base/observe_state need a flat Box observation space, got {obs_space}"
                )
            lo, hi = [obs_space.low], [obs_space.high]
            if self.observe_state:
                lo.append(ESTIMATE_LOW)
                hi.append(ESTIMATE_HIGH)
            if self.observe_base:
                lo.append(act.low.ravel())
                hi.append(act.high.ravel())
            self.observation_space = spaces.Box(
                low=np.concatenate(lo).astype(obs_space.dtype),
                high=np.concatenate(hi).astype(obs_space.dtype),
                dtype=obs_space.dtype,
            )
        self.base_name = base if isinstance(base, str) else type(base).__name__
        if isinstance(base, str):
            self.base_policy: Policy = make_baseline_policy(base, env, **(base_kwargs or {}))
        elif isinstance(base, type) or (callable(base) and not hasattr(base, "reset")):
            self.base_policy = base(env)  # a factory (e.g. a policy class)
        elif callable(base):
            self.base_policy = base  # type: ignore[assignment]
        else:
            raise ValueError(f"base must be a policy name, a policy or a factory, got {base!r}")
        if base_kwargs and not isinstance(base, str):
            raise ValueError("base_kwargs apply to a named base policy only")
        if self.observe_state and not hasattr(self.base_policy, "estimator"):
            raise ValueError(
                f"observe_state=True needs a base policy with a state estimator "
                f"(e.g. 'reference' or 'pd'), got {self.base_name!r}"
            )
        self._base = np.zeros(act.shape, dtype=np.float64)

    def set_scale(self, scale: float) -> None:
        """Set the residual authority for the next steps (a schedule during training).

        Args:
            scale: in [0, the constructed ``scale``] [action units].
        """
        if not (np.isfinite(scale) and 0 <= scale <= self.max_scale):
            raise ValueError(
                f"scale = {scale!r} is out of range; allowed: in [0, {self.max_scale}]"
            )
        self.scale = float(scale)

    def _base_command(self, obs: Any) -> np.ndarray:
        """The base policy's command for ``obs``, clipped to the action limits."""
        cmd = np.asarray(self.base_policy(obs), dtype=np.float64).reshape(self._low.shape)
        if not np.all(np.isfinite(cmd)):
            raise ValueError(f"base policy {self.base_name!r} returned a non-finite action {cmd}")
        return np.clip(cmd, self._low, self._high)

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        if not (self.observe_base or self.observe_state):
            return obs
        parts = [np.asarray(obs, dtype=np.float64)]
        if self.observe_state:
            parts.append(estimate_features(self.base_policy.estimator))  # type: ignore[attr-defined]
        if self.observe_base:
            parts.append(self._base.ravel())
        return np.concatenate(parts).astype(self.observation_space.dtype, copy=False)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset the env with ``seed`` and ``options``, then the base policy (which may read
        the new course from the env)."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.base_policy.reset()
        self._base = self._base_command(obs)
        info = dict(info)
        info["base_action"] = self._base.astype(np.float32)
        return self._observe(obs), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Apply ``clip(base + scale * clip(action, -1, 1))``; log base, residual and total."""
        a = np.asarray(action, dtype=np.float64).reshape(self._low.shape)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"residual action must be finite, got {action!r}")
        residual = self.scale * np.clip(a, -1.0, 1.0)
        base = self._base
        total = np.clip(base + residual, self._low, self._high).astype(np.float32)
        obs, reward, terminated, truncated, info = self.env.step(total)
        applied = getattr(self.base_policy, "applied", None)
        if applied is not None and not np.array_equal(total, base.astype(np.float32)):
            applied(total)
        info = dict(info)
        info["base_action"] = base.astype(np.float32)
        info["residual_action"] = residual.astype(np.float32)
        info["total_action"] = total
        self._base = self._base_command(obs)
        return self._observe(obs), reward, terminated, truncated, info


def init_policy(model: Any, zero_output: bool = True, log_std: float | None = None) -> None:
    """Start a new stable-baselines3 model at a zero action (Silver et al. 2018, "Residual
    Policy Learning": a zero-initialised last actor layer), so that a residual agent's first
    deterministic actions are exactly its base policy's.

    Args:
        model: a PPO or A2C (the ``action_net`` of its ``ActorCriticPolicy``), SAC (the mean
            layer ``actor.mu``) or TD3 model (the last linear layer of ``actor.mu``; its
            target actor is set equal).
        zero_output: zero the weights and bias of that layer: the deterministic action is then
            0 for every observation (SAC and TD3 squash it with tanh(0) = 0).
        log_std: initial log standard deviation of the exploration [log action units], or None
            to keep the model's: PPO and A2C fill their ``log_std``; SAC zeroes its log-std
            layer's weights and sets its bias (a state-independent start), or fills its
            ``log_std`` parameter with gSDE. TD3 has none (its exploration is action noise).

    Raises:
        ValueError: a model of another kind, or ``log_std`` for TD3 or outside [-20, 2].
    """
    import torch
    from torch import nn

    policy = model.policy
    if hasattr(policy, "action_net"):  # on-policy ActorCriticPolicy
        mean, std = policy.action_net, getattr(policy, "log_std", None)
    elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):
        mean, std = policy.actor.mu, getattr(policy.actor, "log_std", None)
    else:
        raise ValueError(f"init_policy: unsupported policy {type(policy).__name__}")
    if isinstance(mean, nn.Sequential):  # TD3 (Linear, Tanh); SAC with gSDE (Linear, Hardtanh)
        mean = [m for m in mean if isinstance(m, nn.Linear)][-1]
    if log_std is not None:
        if std is None:
            raise ValueError(
                f"init_policy: log_std: {type(model).__name__} has no log standard deviation"
            )
        if not (np.isfinite(log_std) and -20 <= log_std <= 2):
            raise ValueError(f"init_policy: log_std = {log_std!r}; allowed: in [-20, 2]")
    with torch.no_grad():
        if zero_output:
            mean.weight.zero_()
            mean.bias.zero_()
        if log_std is not None:
            if isinstance(std, nn.Linear):
                std.weight.zero_()
                std.bias.fill_(log_std)
            else:
                std.fill_(log_std)
    target = getattr(policy, "actor_target", None)
    if target is not None:
        target.load_state_dict(policy.actor.state_dict())
