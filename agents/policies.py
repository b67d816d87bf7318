"""Baseline policies, and the interface every policy offers.

Every policy has ``reset()`` (called after each ``env.reset``) and ``__call__(obs) -> action``
with the action in the env's normalised [-1, 1] scale. The baselines:

- ``passive``: zero hip torque.
- ``pd``: the planned virtual constraints enforced by plain PD (``controllers.PDPolicy``).
- ``reference``: the transverse-linearization controller (``controllers.make_reference_policy``).

Trained models are policies too (:class:`agents.trained.TrainedPolicy`).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

import controllers

BASELINES = ("passive", "pd", "reference")


@runtime_checkable
class Policy(Protocol):
    """What ``evaluate`` and ``ResidualWrapper`` need from a policy."""

    def reset(self) -> None:
        """Start a new episode (called after each ``env.reset``)."""
        ...

    def __call__(self, obs: Any) -> np.ndarray: ...


class ZeroPolicy:
    """The passive walker: a zero command whatever the observation.

    Args:
        action_space: the env's action space (the command's shape and dtype).
    """

    def __init__(self, action_space: gym.spaces.Box) -> None:
        self._action = np.zeros(action_space.shape, dtype=action_space.dtype)

    def reset(self) -> None:
        """Nothing to reset."""

    def __call__(self, obs: Any) -> np.ndarray:
        return self._action.copy()


def make_baseline_policy(name: str, env: gym.Env, **kwargs: Any) -> Policy:
    """Baseline policy ``name`` (one of ``BASELINES``) for ``env`` (as ``gym.make`` returns it).

    ``kwargs`` go to ``controllers.PDPolicy`` / ``controllers.make_reference_policy`` (e.g.
    ``planner``, ``config``, ``eps``); ``passive`` takes none.
    """
    if name == "passive":
        if kwargs:
            raise ValueError(f"the passive policy takes no options, got {sorted(kwargs)}")
        return ZeroPolicy(env.action_space)
    if name == "pd":
        return controllers.PDPolicy(env, **kwargs)
    if name == "reference":
        return controllers.make_reference_policy(env, **kwargs)
    raise ValueError(f"unknown baseline policy {name!r}; allowed: {', '.join(BASELINES)}")


def base_settings(env: gym.Env) -> list[dict[str, Any]]:
    """The resolved settings (``controllers.ReferencePolicy.settings``) of the base policies
    of ``env``'s wrappers (a residual's, a per-footstep agent's), outermost first, each with
    its wrapper's class name; [] when no wrapper has one."""
    out = []
    while isinstance(env, gym.Wrapper):
        base = getattr(env, "base_policy", None)
        if base is not None and callable(getattr(base, "settings", None)):
            out.append({"wrapper": type(env).__name__, **base.settings()})
        env = env.env
    return out


def settings_changes(recorded: Any, current: Any, path: str = "") -> list[str]:
    """Where ``current`` differs from ``recorded`` (nested mappings and lists in JSON types,
    as :func:`base_settings` gives them), one ``"path: recorded, now current"`` per setting."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        out = []
        for key in dict.fromkeys([*recorded, *current]):
            where = f"{path}.{key}" if path else str(key)
            if key not in recorded:
                out.append(f"{where}: absent, now {current[key]!r}")
            elif key not in current:
                out.append(f"{where}: {recorded[key]!r}, now absent")
            else:
                out += settings_changes(recorded[key], current[key], where)
        return out
    if isinstance(recorded, list) and isinstance(current, list) and len(recorded) == len(current):
        if all(isinstance(r, dict) for r in recorded):  # one entry per base policy
            return [
                c
                for i, r in enumerate(recorded)
                for c in settings_changes(r, current[i], f"{path}[{i}]")
            ]
    return [] if recorded == current else [f"{path}: {recorded!r}, now {current!r}"]
