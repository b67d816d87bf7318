"""The robot's instrumentation model: what its two encoders and two contact switches read in
the paper's coordinates, and the decoding of those readings back into ``q`` and the stance leg.

The paper's robot (Manchester et al. 2011, Section 5) carries two optical encoders: one measures
the angle between the legs, the other the absolute angle of one physical leg (the *inner* leg,
called leg ``A``; the other leg is ``B``). Which leg is the stance leg is not measured by the
encoders: it follows from the two foot contact switches.

Physical angles. The absolute angle ``alpha_X`` of leg ``X`` is the angle of the foot-to-hip
direction from the vertical, positive when the hip is ahead (+x) of that leg's foot. In the paper's
coordinates (``q1`` inter-leg angle, ``q2`` stance-leg angle) the stance leg has ``alpha = q2`` and
the swing leg ``alpha = q2 - q1``. The encoders read

* hip encoder: ``alpha_A - alpha_B`` (the angle of leg A measured from leg B; its sign is fixed to
  the hardware and does *not* flip at an impact),
* leg-A encoder: ``alpha_A``.

So with leg A in stance, ``q1 = hip``, ``q2 = leg_A``; with leg B in stance, ``q1 = -hip`` and
``q2 = leg_A - hip``. Stance legs are numbered 0 (leg A) and 1 (leg B).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["encoders_to_q", "q_to_encoders", "stance_from_contacts"]


def stance_from_contacts(
    contact_a: float | np.ndarray, contact_b: float | np.ndarray, previous: int | None = None
) -> int | np.ndarray:
    """Stance leg (0 = A, 1 = B) from the contact switches.

    A closed switch (> 0.5) on one foot only names the stance leg. If both or neither are closed
    (not produced by the simulator, whose double support is instantaneous, but possible on real
    hardware) the ``previous`` stance leg is kept, or leg A when there is none.
    """
    fallback = 0 if previous is None else int(previous)
    if isinstance(contact_a, float) and isinstance(contact_b, float):  # one reading (a tick)
        a, b = contact_a > 0.5, contact_b > 0.5
        return 0 if a and not b else 1 if b and not a else fallback
    a = np.asarray(contact_a) > 0.5
    b = np.asarray(contact_b) > 0.5
    out = np.where(a & ~b, 0, np.where(b & ~a, 1, fallback))
    return int(out) if out.ndim == 0 else out


def encoders_to_q(
    hip: float | np.ndarray, leg_a: float | np.ndarray, stance_leg: int | np.ndarray
) -> tuple[Any, Any]:
    """Paper coordinates ``(q1, q2)`` [rad] from the encoder angles ``hip`` and ``leg_a`` [rad]
    and the ``stance_leg`` (0 = A, 1 = B; scalars or arrays of one shape).

    Leg A in stance (0): ``q1 = hip``, ``q2 = leg_a``; leg B in stance (1): ``q1 = -hip``,
    ``q2 = leg_a - hip``.
    """
    if isinstance(hip, float) and isinstance(leg_a, float) and isinstance(stance_leg, int):
        # one reading (a tick): the same arithmetic without arrays
        if stance_leg == 1:
            return -float(hip), float(leg_a) - float(hip)
        return float(hip), float(leg_a)
    b = np.asarray(stance_leg) == 1
    q1 = np.where(b, -np.asarray(hip), hip)
    q2 = np.where(b, np.asarray(leg_a) - np.asarray(hip), leg_a)
    if q1.ndim == 0:
        return float(q1), float(q2)
    return q1, q2


def q_to_encoders(
    q1: float | np.ndarray, q2: float | np.ndarray, stance_leg: int | np.ndarray
) -> tuple[Any, Any]:
    """Ideal encoder readings ``(hip, leg_a)`` [rad] for the paper coordinates ``q1``, ``q2``
    [rad] and the ``stance_leg`` (0 = A, 1 = B; scalars or arrays of one shape)."""
    b = np.asarray(stance_leg) == 1
    hip = np.where(b, -np.asarray(q1), q1)
    leg_a = np.where(b, np.asarray(q2) - np.asarray(q1), q2)
    if hip.ndim == 0:
        return float(hip), float(leg_a)
    return hip, leg_a
