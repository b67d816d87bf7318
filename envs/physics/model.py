"""Equations of motion of the compass-gait biped: ``M, C, G, B``, friction, impact, kinematics,
energy, momenta, the hip push and the contact conditions (ground reaction, impulse, friction
cone).

This module is the single source of the model equations (Manchester et al. 2011, Appendix B, in
the conventions of the control notes). Every function is compiled with numba and takes the flat
parameter vector ``P = RobotParams.vector()`` first (layout: the ``P*`` constants of
:mod:`envs.physics.params`). The functions are written entry by entry, so the same code serves
scalars inside the simulator's compiled loops and numpy arrays (a grid of ``theta`` values, say)
in the planner and the controller; the few marked "scalars only" branch on their values.

Coordinates and units: ``q1`` [rad] is the inter-leg (hip) angle, ``q2`` [rad] the stance-leg
angle from the vertical (positive when the hip is ahead of the stance foot); ``q1d, q2d`` are
their rates [rad/s] and ``q1dd, q2dd`` their accelerations [rad/s^2]. The swing-leg angle from
the vertical is ``q2 - q1``. ``(xs, ys)`` is the stance-foot position [m]. The input ``u`` is in
input units; the hip torque is ``P[PB] * u`` [N m] on the ``q1`` row (:func:`torque_from_input`;
:func:`input_from_torque` inverts it).
"""

from __future__ import annotations

import math

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
    """Entries ``(M11, M12, M22)`` [kg m^2] of the symmetric inertia matrix at ``q1`` [rad]."""
    c = np.cos(q1)
    m12 = -P[P1] + c * P[P2]
    m22 = P[P3] + 2.0 * P[P1] - 2.0 * c * P[P2]
    return P[P1] + 0.0 * c, m12, m22


@_jit
def coriolis(P, q1, q1d, q2d):
    """Coriolis and centrifugal terms ``C(q, qd) qd`` as ``(c1, c2)`` [N m], from ``q1`` [rad]
    and the rates ``q1d, q2d`` [rad/s]."""
    s = np.sin(q1) * P[P2]
    return -s * q2d * q2d, s * (2.0 * q1d * q2d - q1d * q1d)


@_jit
def gravity(P, q1, q2):
    """Gradient of the potential energy ``(G1, G2)`` [N m] at ``(q1, q2)`` [rad]."""
    a = np.sin(q1 - q2) * P[P4]
    return a, -a - np.sin(q2) * (P[P5] + P[P4])


@_jit
def friction(P, q1d):
    """Hip friction torque ``Fc sign(q1d) + Fv q1d`` [N m] at the hip rate ``q1d`` [rad/s]
    (acts on the ``q1`` row)."""
    return P[PFC] * np.sign(q1d) + P[PFV] * q1d


@_jit
def input_gain(P):
    """``B = [b, 0]``: hip torque per unit input ``b = kI ktau`` [N m per input unit]."""
    return P[PB]


@_jit
def torque_from_input(P, u):
    """Hip torque ``input_gain * u`` [N m] of the input ``u`` [input units]."""
    return P[PB] * u


@_jit
def input_from_torque(P, tau):
    """Input ``tau / input_gain`` [input units] that makes the hip torque ``tau`` [N m]."""
    return tau / P[PB]


@_jit
def accelerations(P, q1, q2, q1d, q2d, u):
    """Joint accelerations ``(q1dd, q2dd)`` [rad/s^2] of the swing phase at the state
    ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] under the input ``u`` [input units].

    Solves ``M qdd = B u - C qd - G - [tau_F, 0]``.
    """
    m11, m12, m22 = mass_matrix(P, q1)
    c1, c2 = coriolis(P, q1, q1d, q2d)
    g1, g2 = gravity(P, q1, q2)
    r1 = torque_from_input(P, u) - c1 - g1 - friction(P, q1d)
    r2 = -c2 - g2
    det = m11 * m22 - m12 * m12
    return (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det


@_jit
def rk4_sum(x, h6, k1, k2, k3, k4):
    """The classical RK4 update of ``x`` from its four slopes ``k1 .. k4``, ``h6`` being a
    sixth of the step: ``x + h6 (k1 + 2 k2 + 2 k3 + k4)``. Scalars only."""
    return x + h6 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@_jit
def swing_rk4_stages(P, q1, q2, q1d, q2d, u, h, q1dd, q2dd):
    """The stages of one classical RK4 step of the swing phase (:func:`swing_rk4`): for each
    of stages 2, 3 and 4 the state ``(q1, q2, q1d, q2d)`` [rad, rad/s] at which its slope is
    taken and the accelerations there [rad/s^2], from the state whose accelerations
    ``(q1dd, q2dd)`` are known. Scalars only."""
    hh = 0.5 * h
    s2 = (q1 + hh * q1d, q2 + hh * q2d, q1d + hh * q1dd, q2d + hh * q2dd)
    a2, b2 = accelerations(P, s2[0], s2[1], s2[2], s2[3], u)
    s3 = (q1 + hh * s2[2], q2 + hh * s2[3], q1d + hh * a2, q2d + hh * b2)
    a3, b3 = accelerations(P, s3[0], s3[1], s3[2], s3[3], u)
    s4 = (q1 + h * s3[2], q2 + h * s3[3], q1d + h * a3, q2d + h * b3)
    a4, b4 = accelerations(P, s4[0], s4[1], s4[2], s4[3], u)
    return s2, a2, b2, s3, a3, b3, s4, a4, b4


@_jit
def swing_rk4(P, q1, q2, q1d, q2d, u, h, q1dd, q2dd):
    """One classical RK4 step of the swing phase, of length ``h`` [s] under the held input
    ``u`` [input units], from the state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] whose
    accelerations ``(q1dd, q2dd)`` [rad/s^2] (:func:`accelerations`) are known. Scalars only.

    Returns the state after the step ``(q1, q2, q1d, q2d)`` [rad, rad/s] and the motor work
    over it by the same quadrature [J]: net ``int tau q1d dt``, positive
    ``int max(tau q1d, 0) dt`` and absolute ``int |tau q1d| dt``, ``tau = P[PB] u`` [N m].
    """
    s2, a2, b2, s3, a3, b3, s4, a4, b4 = swing_rk4_stages(P, q1, q2, q1d, q2d, u, h, q1dd, q2dd)
    w1_2, w2_2, w1_3, w2_3, w1_4, w2_4 = s2[2], s2[3], s3[2], s3[3], s4[2], s4[3]
    h6 = h / 6.0
    nq1 = rk4_sum(q1, h6, q1d, w1_2, w1_3, w1_4)
    nq2 = rk4_sum(q2, h6, q2d, w2_2, w2_3, w2_4)
    nw1 = rk4_sum(q1d, h6, q1dd, a2, a3, a4)
    nw2 = rk4_sum(q2d, h6, q2dd, b2, b3, b4)
    tau = torque_from_input(P, u)
    p1, p2, p3, p4 = tau * q1d, tau * w1_2, tau * w1_3, tau * w1_4
    wnet = h6 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
    wpos = h6 * (max(p1, 0.0) + 2.0 * max(p2, 0.0) + 2.0 * max(p3, 0.0) + max(p4, 0.0))
    wabs = h6 * (abs(p1) + 2.0 * abs(p2) + 2.0 * abs(p3) + abs(p4))
    return nq1, nq2, nw1, nw2, wnet, wpos, wabs


@_jit
def weight(P):
    """Weight of the whole robot ``g (2 m + mHg)`` [N] (gravitational masses)."""
    return P[PG] * (2.0 * P[PM] + P[PMHG])


@_jit
def potential_energy(P, q1, q2, ys):
    """Potential energy [J] at ``(q1, q2)`` [rad] with the stance foot at height ``ys`` [m]
    (gravitational masses)."""
    return (P[P4] + P[P5]) * np.cos(q2) - P[P4] * np.cos(q2 - q1) + weight(P) * ys


@_jit
def kinetic_energy(P, q1, q1d, q2d):
    """Kinetic energy ``qd' M qd / 2`` [J] at ``q1`` [rad] and the rates ``q1d, q2d``
    [rad/s]."""
    m11, m12, m22 = mass_matrix(P, q1)
    return 0.5 * (m11 * q1d * q1d + 2.0 * m12 * q1d * q2d + m22 * q2d * q2d)


@_jit
def energy(P, q1, q2, q1d, q2d, ys):
    """Total mechanical energy [J] of the state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] with
    the stance foot at height ``ys`` [m]."""
    return kinetic_energy(P, q1, q1d, q2d) + potential_energy(P, q1, q2, ys)


# ---------------------------------------------------------------------------- impact
@_jit
def impact_matrices(P, q1):
    """Closed-form ``H+`` and ``H-`` [kg m^2] of Appendix B at the pre-impact ``q1`` [rad], as
    two tuples ``(h11, h12, h21, h22)``."""
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
    """Velocity jump ``Delta_qdot(q-) = Delta_q H+^-1 H-`` (dimensionless) at the pre-impact
    ``q1`` [rad], as ``(d11, d12, d21, d22)``."""
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

    Takes the pre-impact ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s]; returns
    ``(q1+, q2+, q1d+, q2d+)`` [rad, rad/s] with ``q+ = Delta_q q-`` and
    ``qd+ = Delta_q H+(q-)^-1 H-(q-) qd-``.
    """
    d11, d12, d21, d22 = impact_velocity_matrix(P, q1)
    return -q1, q2 - q1, d11 * q1d + d12 * q2d, d21 * q1d + d22 * q2d


# ---------------------------------------------------------------------------- kinematics
@_jit
def hip_position(P, q1, q2, xs, ys):
    """Hip position ``(x, y)`` [m] at ``(q1, q2)`` [rad] for the stance foot at ``(xs, ys)``
    [m]."""
    l = P[PL]  # noqa: E741
    return xs + l * np.sin(q2), ys + l * np.cos(q2)


@_jit
def swing_foot_position(P, q1, q2, xs, ys, retract=0.0):
    """Swing-foot position ``(x, y)`` [m] at ``(q1, q2)`` [rad] for the stance foot at
    ``(xs, ys)`` [m]; ``retract`` shortens the swing leg by that length [m]."""
    l = P[PL]  # noqa: E741
    hx, hy = hip_position(P, q1, q2, xs, ys)
    s = q2 - q1
    return hx - (l - retract) * np.sin(s), hy - (l - retract) * np.cos(s)


@_jit
def touchdown_configuration(dx, dh, l):
    """Pre-impact ``(q1, q2)`` [rad] that puts the swing foot at ``(dx, dh)`` [m] from the
    stance foot with both legs at full length ``l`` [m] (the inverse of
    :func:`swing_foot_position`): ``l (sin q2 - sin(q2 - q1)) = dx``,
    ``l (cos q2 - cos(q2 - q1)) = dh``; ``q1`` is ``NaN`` where the foothold is out of reach.
    Scalars only."""
    chord = math.hypot(dx, dh) / (2.0 * l)
    q1 = 2.0 * math.asin(chord) if chord <= 1.0 else math.nan
    return q1, math.atan2(-dh, dx) + 0.5 * q1


@_jit
def swing_foot_velocity(P, q1, q2, q1d, q2d):
    """Swing-foot velocity ``(vx, vy)`` [m/s] at ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s]
    (stance foot fixed)."""
    l = P[PL]  # noqa: E741
    s = q2 - q1
    sd = q2d - q1d
    return l * np.cos(q2) * q2d - l * np.cos(s) * sd, -l * np.sin(q2) * q2d + l * np.sin(s) * sd


@_jit
def hip_push(P, q1, q2, dvx):
    """Horizontal impulse at the hip that changes the hip's horizontal velocity by ``dvx``
    [m/s] with the stance foot pinned, at ``(q1, q2)`` [rad].

    The impulse ``p`` [N s] acts through the hip's horizontal Jacobian ``J = (0, l cos q2)``
    (of :func:`hip_position`): ``M dqd = J' p`` with ``p = dvx / (J M^-1 J')``, so that
    ``J dqd = dvx``; the ground takes the reaction at the stance foot. The hip's vertical
    velocity changes by ``-tan(q2) dvx`` (it moves on a circle about the foot).

    Returns ``(dq1d, dq2d, p)``: the jump of the joint rates [rad/s] and the impulse [N s]
    (positive forwards, towards +x). Scalars only (``|q2| < pi / 2``).
    """
    m11, m12, m22 = mass_matrix(P, q1)
    det = m11 * m22 - m12 * m12
    j2 = P[PL] * np.cos(q2)
    # M^-1 J' = j2 (-m12, m11) / det
    a1, a2 = -m12 * j2 / det, m11 * j2 / det
    p = dvx / (j2 * a2)
    return a1 * p, a2 * p, p


@_jit
def centre_of_mass(P, q1, q2, xs, ys):
    """Centre of mass of the whole robot ``(x, y)`` [m] at ``(q1, q2)`` [rad] for the stance
    foot at ``(xs, ys)`` [m], inertial masses."""
    l, lc, m, mh = P[PL], P[PLC], P[PM], P[PMH]  # noqa: E741
    s2, c2 = np.sin(q2), np.cos(q2)
    ss, cs = np.sin(q2 - q1), np.cos(q2 - q1)
    mt = 2.0 * m + mh
    x = (m * lc * s2 + mh * l * s2 + m * (l * s2 - (l - lc) * ss)) / mt
    y = (m * lc * c2 + mh * l * c2 + m * (l * c2 - (l - lc) * cs)) / mt
    return xs + x, ys + y


@_jit
def ground_reaction(P, q1, q2, q1d, q2d, q1dd, q2dd):
    """Force of the ground on the stance foot ``(Fx, Fy)`` [N] during the swing phase, at the
    state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] with accelerations ``(q1dd, q2dd)``
    [rad/s^2].

    Newton's law on the whole robot: inertial masses times accelerations of the bodies minus
    the gravitational force (gravitational hip mass ``mHg``).
    """
    l, lc, m, mh = P[PL], P[PLC], P[PM], P[PMH]  # noqa: E741
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
    return max_, may_ + weight(P)


# ---------------------------------------------------------------------------- momenta
@_jit
def centre_of_mass_velocity(P, q1, q2, q1d, q2d):
    """Velocity ``(vx, vy)`` [m/s] of the centre of mass at ``(q1, q2)`` [rad],
    ``(q1d, q2d)`` [rad/s] (stance foot fixed), inertial masses."""
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
    """Angular momentum [kg m^2/s] (counter-clockwise positive) about ``(ox, oy)`` [m] of a
    rigid body of mass ``m`` [kg] and inertia ``ic`` [kg m^2] with its centre of mass at
    ``(cx, cy)`` [m] moving at ``(vx, vy)`` [m/s] and turning at ``w`` [rad/s]."""
    return m * ((cx - ox) * vy - (cy - oy) * vx) + ic * w


@_jit
def leg_momenta(P, q1, q2, q1d, q2d, ox, oy):
    """Angular momenta [kg m^2/s] about the point ``(ox, oy)`` [m] (relative to the stance
    foot) of ``(stance leg, hip mass, swing leg)`` at ``(q1, q2)`` [rad], ``(q1d, q2d)``
    [rad/s], built from the kinematics (counter-clockwise positive; within a step the walker
    rotates clockwise)."""
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
    """Angular momentum of the whole robot [kg m^2/s] about ``(ox, oy)`` [m] relative to the
    stance foot, at ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] (counter-clockwise positive)."""
    a, b, c = leg_momenta(P, q1, q2, q1d, q2d, ox, oy)
    return a + b + c


@_jit
def impact_momentum(P, q1, q2, q1d, q2d):
    """Impact map by conservation of angular momentum (independent of the closed form).

    A plastic impact without slip at the swing foot: the angular momentum of the whole robot
    about the new stance foot, and that of the trailing leg (the old stance leg, whose foot
    leaves the ground without impulse) about the hip, are conserved. Both are built from the
    kinematics of :func:`leg_momenta` and solved for the post-impact velocities.

    Takes and returns states like :func:`impact`: ``(q1+, q2+, q1d+, q2d+)`` [rad, rad/s].
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


# ---------------------------------------------------------------------------- contact
@_jit
def ground_normal(slope):
    """Upward unit normal ``(nx, ny)`` of ground of slope ``slope`` (``dh/dx``, dimensionless).
    Scalars only."""
    r = 1.0 / math.sqrt(1.0 + slope * slope)
    return -slope * r, r


@_jit
def normal_tangential(fx, fy, nx, ny):
    """Components of a force [N] or impulse [N s] ``(fx, fy)`` on a foot along the unit ground
    normal ``(nx, ny)`` and along the tangent ``(ny, -nx)`` (forwards along the ground), as
    ``(normal, tangential)``."""
    return fx * nx + fy * ny, fx * ny - fy * nx


@_jit
def friction_cone_margin(fn, ft, mu):
    """Margin ``mu fn - |ft|`` [N or N s] of a contact force [N] or impulse [N s] with normal
    component ``fn`` and tangential component ``ft`` inside the friction cone of coefficient
    ``mu`` (dimensionless): negative outside the cone."""
    return mu * fn - abs(ft)


@_jit
def outside_friction_cone(fn, ft, mu):
    """Whether a contact force [N] or impulse [N s] with normal component ``fn`` and tangential
    component ``ft`` lies outside the friction cone ``|ft| <= mu fn`` (``mu`` dimensionless):
    :func:`friction_cone_margin` negative."""
    return friction_cone_margin(fn, ft, mu) < 0.0


@_jit
def stance_reaction(P, q1, q2, q1d, q2d, q1dd, q2dd, nx, ny):
    """Ground reaction on the stance foot [N] during the swing phase (:func:`ground_reaction`
    at the state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] with accelerations
    ``(q1dd, q2dd)`` [rad/s^2]) resolved along the unit ground normal ``(nx, ny)`` under the
    foot: ``(normal, tangential)`` as in :func:`normal_tangential`. A negative normal component
    lifts the foot off; :func:`outside_friction_cone` tells a slip."""
    fx, fy = ground_reaction(P, q1, q2, q1d, q2d, q1dd, q2dd)
    return normal_tangential(fx, fy, nx, ny)


@_jit
def impact_impulse(P, q1, q2, q1d, q2d, q1p, q2p, q1dp, q2dp):
    """Impulse ``(ix, iy)`` [N s] of the ground on the new stance foot at an impact: the
    inertial mass ``2 m + mH`` times the jump of the centre-of-mass velocity, from the
    pre-impact state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] and the post-impact state
    ``(q1p, q2p, q1dp, q2dp)`` (legs swapped, as :func:`impact` returns it)."""
    mt = 2.0 * P[PM] + P[PMH]
    vxm, vym = centre_of_mass_velocity(P, q1, q2, q1d, q2d)
    vxp, vyp = centre_of_mass_velocity(P, q1p, q2p, q1dp, q2dp)
    return mt * (vxp - vxm), mt * (vyp - vym)


@_jit
def trailing_foot_normal_velocity(P, q1p, q2p, q1dp, q2dp, nx, ny):
    """Velocity [m/s] of the trailing foot (the old stance foot, the swing foot after the
    impact) along the unit ground normal ``(nx, ny)`` under it, from the post-impact state
    ``(q1p, q2p)`` [rad], ``(q1dp, q2dp)`` [rad/s]; it takes off when this is positive."""
    vfx, vfy = swing_foot_velocity(P, q1p, q2p, q1dp, q2dp)
    return vfx * nx + vfy * ny


@_jit
def impact_admissible(P, q1, q2, q1d, q2d, q1p, q2p, q1dp, q2dp, nx, ny, tnx, tny, mu):
    """Whether an impact is consistent with the contact model. Scalars only.

    The impulse on the new stance foot (:func:`impact_impulse`, from the pre-impact state
    ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s] and the post-impact state
    ``(q1p, q2p, q1dp, q2dp)``) must push (non-negative component along the unit ground normal
    ``(nx, ny)`` under the foothold) and lie in the friction cone of coefficient ``mu``
    (dimensionless), and the trailing foot must take off (positive velocity along the unit
    ground normal ``(tnx, tny)`` under it, :func:`trailing_foot_normal_velocity`).
    """
    ix, iy = impact_impulse(P, q1, q2, q1d, q2d, q1p, q2p, q1dp, q2dp)
    inn, itt = normal_tangential(ix, iy, nx, ny)
    lift = trailing_foot_normal_velocity(P, q1p, q2p, q1dp, q2dp, tnx, tny)
    return not (inn < 0.0 or outside_friction_cone(inn, itt, mu) or lift <= 0.0)
