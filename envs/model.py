"""Equations of motion of the compass-gait biped: ``M, C, G, B``, friction, impact, kinematics.

This module is the single source of the model equations (Manchester et al. 2011, Appendix B, in
the conventions of the control notes). Every function is compiled with numba and takes the flat
parameter vector ``P = RobotParams.vector()`` first. The functions are written entry by entry,
so the same code serves scalars inside the simulator's compiled loops and numpy arrays (a grid of
``theta`` values, say) in the planner and the controller.

Coordinates: ``q1`` is the inter-leg (hip) angle, ``q2`` the stance-leg angle from the vertical
(positive when the hip is ahead of the stance foot). The swing-leg angle from the vertical is
``q2 - q1``. Hip torque is ``P[PB] * u`` on the ``q1`` row.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .params import (
    P1,
    P2,
    P3,
    P4,
    P5,
    P6,
    P7,
    P8,
    PB,
    PFC,
    PFV,
    PG,
    PIC,
    PL,
    PLC,
    PM,
    PMH,
    PMHG,
)

_jit = njit(cache=True, fastmath=False, error_model="numpy")


# ---------------------------------------------------------------------------- dynamics terms
@_jit
def mass_matrix(P, q1):
    """Entries ``(M11, M12, M22)`` of the symmetric inertia matrix [kg m^2]."""
    c = np.cos(q1)
    m12 = -P[P1] + c * P[P2]
    m22 = P[P3] + 2.0 * P[P1] - 2.0 * c * P[P2]
    return P[P1] + 0.0 * c, m12, m22


@_jit
def coriolis(P, q1, q1d, q2d):
    """``C(q, qd) qd`` as ``(c1, c2)`` [N m]."""
    s = np.sin(q1) * P[P2]
    return -s * q2d * q2d, s * (2.0 * q1d * q2d - q1d * q1d)


@_jit
def coriolis_matrix(P, q1, q1d, q2d):
    """The matrix ``C(q, qd)`` of Appendix B as ``(C11, C12, C21, C22)``."""
    s = np.sin(q1) * P[P2]
    return 0.0 * s, -q2d * s, -(q1d - q2d) * s, q1d * s


@_jit
def gravity(P, q1, q2):
    """Gradient of the potential energy ``(G1, G2)`` [N m]."""
    a = np.sin(q1 - q2) * P[P4]
    return a, -a - np.sin(q2) * (P[P5] + P[P4])


@_jit
def friction(P, q1d):
    """Hip friction torque ``Fc sign(q1d) + Fv q1d`` [N m] (acts on the ``q1`` row)."""
    return P[PFC] * np.sign(q1d) + P[PFV] * q1d


@_jit
def input_gain(P):
    """``B = [b, 0]``: hip torque per unit input ``b = kI ktau`` [N m]."""
    return P[PB]


@_jit
def accelerations(P, q1, q2, q1d, q2d, u):
    """Joint accelerations ``(q1dd, q2dd)`` of the swing phase under input ``u``.

    Solves ``M qdd = B u - C qd - G - [tau_F, 0]``.
    """
    m11, m12, m22 = mass_matrix(P, q1)
    c1, c2 = coriolis(P, q1, q1d, q2d)
    g1, g2 = gravity(P, q1, q2)
    r1 = P[PB] * u - c1 - g1 - friction(P, q1d)
    r2 = -c2 - g2
    det = m11 * m22 - m12 * m12
    return (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det


@_jit
def potential_energy(P, q1, q2, ys):
    """Potential energy [J] with the stance foot at height ``ys`` (gravitational masses)."""
    mg_total = P[PG] * (2.0 * P[PM] + P[PMHG])
    return (P[P4] + P[P5]) * np.cos(q2) - P[P4] * np.cos(q2 - q1) + mg_total * ys


@_jit
def kinetic_energy(P, q1, q1d, q2d):
    """Kinetic energy ``qd' M qd / 2`` [J]."""
    m11, m12, m22 = mass_matrix(P, q1)
    return 0.5 * (m11 * q1d * q1d + 2.0 * m12 * q1d * q2d + m22 * q2d * q2d)


@_jit
def energy(P, q1, q2, q1d, q2d, ys):
    """Total mechanical energy [J]."""
    return kinetic_energy(P, q1, q1d, q2d) + potential_energy(P, q1, q2, ys)


# ---------------------------------------------------------------------------- impact
@_jit
def impact_matrices(P, q1):
    """Closed-form ``H+`` and ``H-`` of Appendix B as two tuples ``(h11, h12, h21, h22)``."""
    p1, p2, p3 = P[P1], P[P2], P[P3]
    p6, p7, p8 = P[P6], P[P7], P[P8]
    l = P[PL]  # noqa: E741
    c = np.cos(q1)
    hp11 = p1 - 2.0 * p6 * l + l * l * p7
    hp12 = (l * l * p7 + (-p8 - 2.0 * p6) * l + p2) * c - l * l * p7 + 2.0 * p6 * l - p1
    hp22 = (
        (-2.0 * l * l * p7 + (2.0 * p8 + 4.0 * p6) * l - 2.0 * p2) * c
        + 2.0 * l * l * p7
        + (-4.0 * p6 - 2.0 * p8) * l
        + p3
        + 2.0 * p1
    )
    hm11 = p1 - p6 * l + 0.0 * c
    hm12 = ((-p6 - p8) * l + p2) * c - p1 + p6 * l
    hm21 = (p2 - p6 * l) * c - p1 + p6 * l
    hm22 = ((2.0 * p6 + p8) * l - 2.0 * p2) * c + (-p8 - 2.0 * p6) * l + p3 + 2.0 * p1
    return (hp11, hp12, hp12, hp22), (hm11, hm12, hm21, hm22)


@_jit
def impact_velocity_matrix(P, q1):
    """``Delta_qdot(q-) = Delta_q H+^-1 H-`` as ``(d11, d12, d21, d22)``."""
    hp, hm = impact_matrices(P, q1)
    det = hp[0] * hp[3] - hp[1] * hp[2]
    # X = H+^-1 H-
    x11 = (hp[3] * hm[0] - hp[1] * hm[2]) / det
    x12 = (hp[3] * hm[1] - hp[1] * hm[3]) / det
    x21 = (-hp[2] * hm[0] + hp[0] * hm[2]) / det
    x22 = (-hp[2] * hm[1] + hp[0] * hm[3]) / det
    # Delta_q = [[-1, 0], [-1, 1]]
    return -x11, -x12, x21 - x11, x22 - x12


@_jit
def impact(P, q1, q2, q1d, q2d):
    """Impact map (paper closed form): pre-impact state -> post-impact state, legs swapped.

    Returns ``(q1+, q2+, q1d+, q2d+)`` with ``q+ = Delta_q q-`` and
    ``qd+ = Delta_q H+(q-)^-1 H-(q-) qd-``.
    """
    d11, d12, d21, d22 = impact_velocity_matrix(P, q1)
    return -q1, q2 - q1, d11 * q1d + d12 * q2d, d21 * q1d + d22 * q2d


# ---------------------------------------------------------------------------- kinematics
@_jit
def hip_position(P, q1, q2, xs, ys):
    """Hip position ``(x, y)`` [m] for the stance foot at ``(xs, ys)``."""
    l = P[PL]  # noqa: E741
    return xs + l * np.sin(q2), ys + l * np.cos(q2)


@_jit
def swing_foot_position(P, q1, q2, xs, ys, retract=0.0):
    """Swing-foot position [m]; ``retract`` shortens the swing leg by that length [m]."""
    l = P[PL]  # noqa: E741
    hx, hy = hip_position(P, q1, q2, xs, ys)
    s = q2 - q1
    return hx - (l - retract) * np.sin(s), hy - (l - retract) * np.cos(s)


@_jit
def swing_foot_velocity(P, q1, q2, q1d, q2d):
    """Swing-foot velocity ``(vx, vy)`` [m/s] (stance foot fixed)."""
    l = P[PL]  # noqa: E741
    s = q2 - q1
    sd = q2d - q1d
    return l * np.cos(q2) * q2d - l * np.cos(s) * sd, -l * np.sin(q2) * q2d + l * np.sin(s) * sd


@_jit
def hip_velocity(P, q2, q2d):
    """Hip velocity ``(vx, vy)`` [m/s] (stance foot fixed)."""
    l = P[PL]  # noqa: E741
    return l * np.cos(q2) * q2d, -l * np.sin(q2) * q2d


@_jit
def centre_of_mass(P, q1, q2, xs, ys):
    """Centre of mass of the whole robot ``(x, y)`` [m], inertial masses."""
    l, lc, m, mh = P[PL], P[PLC], P[PM], P[PMH]  # noqa: E741
    s2, c2 = np.sin(q2), np.cos(q2)
    ss, cs = np.sin(q2 - q1), np.cos(q2 - q1)
    mt = 2.0 * m + mh
    x = (m * lc * s2 + mh * l * s2 + m * (l * s2 - (l - lc) * ss)) / mt
    y = (m * lc * c2 + mh * l * c2 + m * (l * c2 - (l - lc) * cs)) / mt
    return xs + x, ys + y


@_jit
def ground_reaction(P, q1, q2, q1d, q2d, q1dd, q2dd):
    """Force of the ground on the stance foot ``(Fx, Fy)`` [N] during the swing phase.

    Newton's law on the whole robot: inertial masses times accelerations of the bodies minus
    the gravitational force (gravitational hip mass ``mHg``).
    """
    l, lc, m, mh, mhg, g = P[PL], P[PLC], P[PM], P[PMH], P[PMHG], P[PG]  # noqa: E741
    s2, c2 = np.sin(q2), np.cos(q2)
    s = q2 - q1
    sd = q2d - q1d
    sdd = q2dd - q1dd
    ss, cs = np.sin(s), np.cos(s)
    # d2/dt2 of (sin a, cos a) = (cos a add - sin a ad^2, -sin a add - cos a ad^2)
    ax2 = c2 * q2dd - s2 * q2d * q2d
    ay2 = -s2 * q2dd - c2 * q2d * q2d
    axs = cs * sdd - ss * sd * sd
    ays = -ss * sdd - cs * sd * sd
    # stance leg com (lc along q2), hip (l along q2), swing com (hip - (l - lc) along s)
    max_ = m * lc * ax2 + mh * l * ax2 + m * (l * ax2 - (l - lc) * axs)
    may_ = m * lc * ay2 + mh * l * ay2 + m * (l * ay2 - (l - lc) * ays)
    return max_, may_ + g * (2.0 * m + mhg)


@_jit
def leg_inertia(P):
    """Leg inertia about its centre of mass [kg m^2]."""
    return P[PIC]


# ---------------------------------------------------------------------------- momenta
@_jit
def centre_of_mass_velocity(P, q1, q2, q1d, q2d):
    """Velocity ``(vx, vy)`` [m/s] of the centre of mass (stance foot fixed), inertial masses."""
    l, lc, m, mh = P[PL], P[PLC], P[PM], P[PMH]  # noqa: E741
    s = q2 - q1
    sd = q2d - q1d
    a = m * lc + mh * l + m * l
    mt = 2.0 * m + mh
    vx = (a * np.cos(q2) * q2d - m * (l - lc) * np.cos(s) * sd) / mt
    vy = (-a * np.sin(q2) * q2d + m * (l - lc) * np.sin(s) * sd) / mt
    return vx, vy


@_jit
def _body_momentum(m, ic, cx, cy, vx, vy, w, ox, oy):
    """Angular momentum (counter-clockwise positive) of a rigid body about ``(ox, oy)``."""
    return m * ((cx - ox) * vy - (cy - oy) * vx) + ic * w


@_jit
def leg_momenta(P, q1, q2, q1d, q2d, ox, oy):
    """Angular momenta [kg m^2/s] about the point ``(ox, oy)`` (relative to the stance foot)
    of ``(stance leg, hip mass, swing leg)``, built from the kinematics (counter-clockwise
    positive; within a step the walker rotates clockwise)."""
    l, lc, m, mh, ic = P[PL], P[PLC], P[PM], P[PMH], P[PIC]  # noqa: E741
    s2, c2 = np.sin(q2), np.cos(q2)
    s = q2 - q1
    sd = q2d - q1d
    ss, cs = np.sin(s), np.cos(s)
    hx, hy = l * s2, l * c2
    hvx, hvy = l * c2 * q2d, -l * s2 * q2d
    stance = _body_momentum(m, ic, lc * s2, lc * c2, lc * c2 * q2d, -lc * s2 * q2d, -q2d, ox, oy)
    hip = _body_momentum(mh, 0.0, hx, hy, hvx, hvy, 0.0, ox, oy)
    d = l - lc
    swing = _body_momentum(
        m, ic, hx - d * ss, hy - d * cs, hvx - d * cs * sd, hvy + d * ss * sd, -sd, ox, oy
    )
    return stance, hip, swing


@_jit
def angular_momentum(P, q1, q2, q1d, q2d, ox, oy):
    """Angular momentum of the whole robot [kg m^2/s] about ``(ox, oy)`` relative to the
    stance foot (counter-clockwise positive)."""
    a, b, c = leg_momenta(P, q1, q2, q1d, q2d, ox, oy)
    return a + b + c


@_jit
def impact_momentum(P, q1, q2, q1d, q2d):
    """Impact map by conservation of angular momentum (independent of the closed form).

    A plastic impact without slip at the swing foot: the angular momentum of the whole robot
    about the new stance foot, and that of the trailing leg (the old stance leg, whose foot
    leaves the ground without impulse) about the hip, are conserved. Both are built from the
    kinematics of :func:`leg_momenta` and solved for the post-impact velocities.

    Returns ``(q1+, q2+, q1d+, q2d+)`` like :func:`impact`.
    """
    l = P[PL]  # noqa: E741
    s = q2 - q1
    fx, fy = l * np.sin(q2) - l * np.sin(s), l * np.cos(q2) - l * np.cos(s)
    st, hp, sw = leg_momenta(P, q1, q2, q1d, q2d, fx, fy)
    b1 = st + hp + sw
    hx, hy = l * np.sin(q2), l * np.cos(q2)
    b2 = leg_momenta(P, q1, q2, q1d, q2d, hx, hy)[0]
    # after the impact: new stance foot at the origin, new coordinates, unit velocities
    p1, p2 = -q1, q2 - q1
    z = 0.0 * q1
    a11 = angular_momentum(P, p1, p2, z + 1.0, z, z, z)
    a12 = angular_momentum(P, p1, p2, z, z + 1.0, z, z)
    hx2, hy2 = l * np.sin(p2), l * np.cos(p2)
    a21 = leg_momenta(P, p1, p2, z + 1.0, z, hx2, hy2)[2]
    a22 = leg_momenta(P, p1, p2, z, z + 1.0, hx2, hy2)[2]
    det = a11 * a22 - a12 * a21
    return p1, p2, (a22 * b1 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det
