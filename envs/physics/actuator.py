"""The hip command's unit chain, one named conversion per step.

A hip command exists in three units: the controller's **input** ``u`` [input units] (the
paper's motor input; ``|u| <= u_max``), the environment's normalised **action** ``a`` [-] in
[-1, 1] (``a = u / u_max``), and the hip **torque** ``tau`` [N m]. The robot's
:attr:`~envs.physics.RobotParams.input_gain` ``kI * ktau`` [N m per input unit] links input and
torque; ``tau_max = input_gain * u_max`` [N m] is the torque at ``|a| = 1``
(:attr:`~envs.physics.RobotParams.tau_max`, the env's ``torque_limit``).

One command on its way from a controller to the equations of motion:

1. the reference policy turns its controller's input into an action,
   :func:`action_from_input` (``clip(u / u_max, -1, 1)``, returned as float32);
2. a residual policy adds its correction in action units
   (``agents.residual.ResidualWrapper``: ``clip(b + scale * r, -1, 1)``, float32);
3. the env and the vector env hand the action to their walker batch, which turns it into a hip
   torque, :func:`actions_to_torques` (one action: :func:`torque_from_action`,
   ``clip(a, -1, 1) * tau_max``), into its own buffer, and steps the simulator with it (the
   simulator copies the torques into its own buffer);
4. the simulator kernel takes the torque in input units for the dynamics,
   :func:`envs.physics.model.input_from_torque` (``tau / input_gain``), and the equations of
   motion and the motor work turn it back into N m, :func:`envs.physics.model.torque_from_input`
   (``input_gain * u``);
5. the policy's state estimator integrates the observer with the input of the applied action,
   :func:`input_from_action` (``clip(a, -1, 1) * u_max``).

The chain keeps its round trips (input -> action -> torque -> input -> torque): each step
rounds, and removing one would change the simulated numbers in the last bits. The estimator's
input in step 5 is computed from the unrounded float64 action the policy returned, while the env
applies the float32 action; they agree to float32 precision.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit


def action_from_input(u: float, u_max: float) -> float:
    """Normalised action ``clip(u / u_max, -1, 1)`` [-] of an input ``u`` [input units] under
    the actuator limit ``u_max`` [input units]; NaN stays NaN."""
    a = u / u_max
    if a > 1.0:
        return 1.0
    if a < -1.0:
        return -1.0
    return a


def input_from_action(a: float, u_max: float) -> float:
    """Input ``clip(a, -1, 1) * u_max`` [input units] of an action ``a`` [-] under the actuator
    limit ``u_max`` [input units]."""
    if a > 1.0:
        a = 1.0
    elif a < -1.0:
        a = -1.0
    return a * u_max


def action_from_torque(tau: float, tau_max: float) -> float:
    """Normalised action ``clip(tau / tau_max, -1, 1)`` [-] of a hip torque ``tau`` [N m] under
    the torque limit ``tau_max`` [N m]; NaN stays NaN."""
    return action_from_input(tau, tau_max)


@njit(cache=True)
def torque_from_action(a, tau_max):
    """Hip torque ``clip(a, -1, 1) * tau_max`` [N m] of an action ``a`` [-] (float64) under the
    torque limit ``tau_max`` [N m] (``RobotParams.tau_max``)."""
    x = np.float64(a)
    if x > 1.0:
        x = 1.0
    elif x < -1.0:
        x = -1.0
    return x * tau_max


@njit(cache=True)
def _torques_from_actions(a, tau_max, out):
    """``out[i] = torque_from_action(a[i], tau_max)`` [N m]; returns -1, or the index of the first
    non-finite action (then nothing is written)."""
    for i in range(a.size):
        if not math.isfinite(a[i]):
            return i
    for i in range(a.size):
        out[i] = torque_from_action(a[i], tau_max)
    return -1


def actions_to_torques(actions: Any, tau_max: float, out: np.ndarray) -> None:
    """Hip torques ``out = clip(actions, -1, 1) * tau_max`` [N m] of a batch of actions [-] under
    the torque limit ``tau_max`` [N m].

    Args:
        actions: ``(n,)`` or ``(n, 1)`` real actions (float32 or float64; integers, lists and
            other float types are converted; with ``n == 1`` also one number).
        tau_max: hip torque at ``|action| = 1`` [N m].
        out: ``(n,)`` float64 buffer the torques are written to.

    Raises:
        TypeError: actions that are not real numbers (strings, complex numbers, None, a dict,
            booleans, ...); nothing written.
        ValueError: a NaN or infinite action (nothing written) or another shape.
    """
    n = out.size
    if (
        n == 1
        and type(actions) is np.ndarray
        and actions.shape == (1,)
        and actions.dtype.kind == "f"
    ):
        # one env's action: a scalar, without the batch's array checks
        a = float(actions[0])
        if not math.isfinite(a):
            raise ValueError(f"action = {a!r} must be finite (allowed: [-1, 1])")
        out[0] = torque_from_action(a, tau_max)
        return
    a = actions if type(actions) is np.ndarray else _action_array(actions, n)
    if a.dtype.kind not in _REAL_KINDS:
        raise TypeError(_action_rule(n, _described(actions, a)))
    if a.dtype != np.float32 and a.dtype != np.float64:
        a = a.astype(np.float64)
    if a.shape != (n,) and a.shape != (n, 1) and not (n == 1 and a.shape == ()):
        raise ValueError(_action_rule(n, f"shape {a.shape}"))
    bad = _torques_from_actions(a.reshape(n), float(tau_max), out)
    if bad >= 0:
        raise ValueError(f"action[{bad}] = {a.reshape(n)[bad]!r} must be finite (allowed: [-1, 1])")


#: numpy dtype kinds accepted as actions: floats, signed and unsigned integers
_REAL_KINDS = "fiu"


def _action_array(actions: Any, n: int) -> np.ndarray:
    """``actions`` as an array (a ragged nesting is a shape error)."""
    try:
        return np.asarray(actions)
    except (TypeError, ValueError):
        raise ValueError(_action_rule(n, f"a {type(actions).__name__} of no array shape")) from None


def _described(actions: Any, a: np.ndarray) -> str:
    """What was given, for the messages: the type of a Python object, an array's dtype."""
    if type(actions) is np.ndarray or a.dtype.kind not in "OUS":
        return f"dtype {a.dtype}"
    return f"a {type(actions).__name__} ({actions!r:.40})"


def _action_rule(n: int, got: str) -> str:
    """The message of a rejected action: the expected shape and dtype, and what was given."""
    shapes = f"({n},) or ({n}, 1)" + (" or one number" if n == 1 else "")
    return f"actions must be real numbers (float32 or float64) of shape {shapes}; got {got}"
