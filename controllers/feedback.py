"""The control tick: transverse feedback through partial feedback linearisation (paper Section 4).

Every control tick evaluates, at the measured (or estimated) state ``x = (q1, q2, q1d, q2d)``
with the phase ``theta = q2``,

* the virtual constraint of the current step, ``phi(theta)`` and its derivatives, from its
  power-basis coefficients (continued past the planned touchdown, see
  ``ControllerConfig.late_blend``);
* the transverse coordinates ``x_perp = [I, y, y_dot]`` with the nominal ``theta_dot^2``
  interpolated (cubic Hermite) on a uniform phase grid;
* the feedback ``v = K(theta) x_perp`` with the gains interpolated linearly on their grid;
* the input ``u = (v - R) / N`` that gives ``y_ddot = v`` (``y_ddot = N u + R`` with the hip
  friction in ``R``, so it is compensated), clipped to the actuator limit and, where asked
  (``ControllerConfig.friction_limit``), to the inputs that keep the stance foot's ground
  reaction inside its friction cone (the reaction is affine in ``u``).

The tick is one compiled function, :func:`feedback_law`; the step it reads comes from a
:class:`controllers.gains.GainTable` as ``feedback_law(P, x, *table.kernel_args())``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from envs.physics import model

from .reduced import output_acceleration

__all__ = [
    "constraint_at",
    "control_tick",
    "feedback_law",
    "friction_clip",
    "lyapunov_at",
    "pack_scalars",
    "thetadot_sq_at",
]

_jit = njit(cache=True, error_model="numpy")

# layout of the scalar vector of the compiled tick (GainTable.scalars), written by pack_scalars
T_TP, T_SPAN, T_F0, T_FD, T_K0, T_KD, T_UMAX, T_LATE, T_MU, T_NX, T_NY = range(11)
N_T = 11


def pack_scalars(
    theta_plus: float,
    span: float,
    speed_theta0: float,
    speed_step: float,
    gain_theta0: float,
    gain_step: float,
    u_max: float,
    late_blend: float,
    friction_limit: float = 0.0,
    stance_slope: float = 0.0,
) -> np.ndarray:
    """The scalar vector of the compiled tick (fields as in :class:`controllers.gains.GainTable`:
    phases and spacings [rad], ``u_max`` [input units], ``late_blend`` [rad], the friction
    coefficient of the input's friction-cone clip (0: off) and the ground slope ``dh/dx`` under
    the stance foot)."""
    tab = np.zeros(N_T)
    tab[T_TP], tab[T_SPAN] = theta_plus, span
    tab[T_F0], tab[T_FD] = speed_theta0, speed_step
    tab[T_K0], tab[T_KD] = gain_theta0, gain_step
    tab[T_UMAX] = u_max
    tab[T_LATE] = late_blend
    tab[T_MU] = friction_limit
    tab[T_NX], tab[T_NY] = model.ground_normal(float(stance_slope))
    return tab


@_jit
def _hermite(tab0, h, vals, ders, th):
    """Cubic Hermite interpolation on a uniform grid (clamped to the grid)."""
    n = vals.size - 1
    r = (th - tab0) / h
    if r <= 0.0:
        return vals[0]
    if r >= n:
        return vals[n]
    k = int(r)
    if k >= n:
        k = n - 1
    t = r - k
    t2 = t * t
    t3 = t2 * t
    return (
        (2 * t3 - 3 * t2 + 1) * vals[k]
        + (t3 - 2 * t2 + t) * h * ders[k]
        + (-2 * t3 + 3 * t2) * vals[k + 1]
        + (t3 - t2) * h * ders[k + 1]
    )


@_jit
def thetadot_sq_at(tab, thetadot_sq, dthetadot_sq, theta):
    """Nominal ``theta_dot^2`` [rad^2/s^2] of the loaded step at phase ``theta`` [rad] (cubic
    Hermite interpolation of the speed grid, clamped to it)."""
    return _hermite(tab[T_F0], tab[T_FD], thetadot_sq, dthetadot_sq, theta)


@_jit
def constraint_at(tab, pc, q2):
    """``(phi, phi', phi'')`` of the loaded step at phase ``q2``, including the continuation
    past the planned touchdown (see ``ControllerConfig.late_blend``)."""
    span = tab[T_SPAN]
    s = (q2 - tab[T_TP]) / span
    late = q2 - (tab[T_TP] + span)  # phase past the planned touchdown [rad]
    if late > 0.0 and tab[T_LATE] > 0.0:
        s = 1.0
    m = pc.size - 1
    ph = pc[m]
    dph = 0.0
    ddph = 0.0
    for k in range(m - 1, -1, -1):
        ddph = ddph * s + 2.0 * dph
        dph = dph * s + ph
        ph = ph * s + pc[k]
    dph /= span
    ddph /= span * span
    if late > 0.0 and tab[T_LATE] > 0.0:
        # touchdown is late: stop opening the legs (phi' -> 0 over late_blend rad), so the hip
        # falls forward and the swing foot moves down onto the ground
        d0 = tab[T_LATE]
        if late < d0:
            ph = ph + dph * late - 0.5 * dph / d0 * late * late
            ddph = -dph / d0
            dph = dph * (1.0 - late / d0)
        else:
            ph = ph + 0.5 * dph * d0
            dph = 0.0
            ddph = 0.0
    return ph, dph, ddph


@_jit
def feedback_law(P, x, tab, pc, thetadot_sq, dthetadot_sq, K):
    """One control tick: input ``u`` [input units] for the state ``x = (q1, q2, q1d, q2d)``.

    Args:
        P: robot parameter vector (``RobotParams.vector()``).
        x: state (estimate) ``(q1, q2, q1d, q2d)`` [rad, rad/s].
        tab: scalars of the step (:func:`pack_scalars`).
        pc: power-basis coefficients of ``phi`` in ``s = (theta - theta+) / span`` (ascending).
        thetadot_sq, dthetadot_sq: nominal ``theta_dot^2`` and its ``theta`` derivative on the
            speed grid.
        K: gains ``(n + 1, 3)`` on the gain grid (linear interpolation, clamped).

    Returns:
        ``(u, I, y, y_dot, v)``.
    """
    u, I, y, yd, v, _ = _law(P, x, tab, pc, thetadot_sq, dthetadot_sq, K)
    return u, I, y, yd, v


@_jit
def control_tick(P, x, tab, pc, thetadot_sq, dthetadot_sq, K, Zinv, z):
    """The controller's tick in one call: :func:`feedback_law`'s input, the nominal
    ``theta_dot^2`` at the state's phase (the plan's tube reads it) and the Lyapunov value.

    Args:
        P, x, tab, pc, thetadot_sq, dthetadot_sq, K: as for :func:`feedback_law`.
        Zinv: the Lyapunov matrices ``Z^-1`` at the gain grid's nodes, ``(n + 1, 3, 3)``
            (:func:`lyapunov_at`, on the grid of ``tab``'s gain phase and spacing).
        z: ``(3,)`` array that receives ``x_perp = (I, y, y_dot)``.

    Returns:
        ``(u, I, y, y_dot, thetadot_sq_ref, V)``: :func:`feedback_law`'s ``u, I, y, y_dot``,
        :func:`thetadot_sq_at` at ``x[1]`` [rad^2/s^2] and ``V = z' Z^-1(x[1]) z``.
    """
    u, I, y, yd, _, ref = _law(P, x, tab, pc, thetadot_sq, dthetadot_sq, K)
    z[0] = I
    z[1] = y
    z[2] = yd
    V = lyapunov_at(Zinv, tab[T_K0], tab[T_KD], I, y, yd, x[1])
    return u, I, y, yd, ref, V


@_jit
def _law(P, x, tab, pc, thetadot_sq, dthetadot_sq, K):
    """The feedback law (:func:`feedback_law`): ``(u, I, y, y_dot, v, thetadot_sq_ref)``, the
    last the nominal ``theta_dot^2`` at the phase ``x[1]``."""
    q1, q2, q1d, q2d = x[0], x[1], x[2], x[3]
    ph, dph, ddph = constraint_at(tab, pc, q2)
    y = q1 - ph
    yd = q1d - dph * q2d
    ref = thetadot_sq_at(tab, thetadot_sq, dthetadot_sq, q2)
    I = q2d * q2d - ref
    nk = K.shape[0] - 1
    r = (q2 - tab[T_K0]) / tab[T_KD]
    if r <= 0.0:
        k0, w = 0, 0.0
    elif r >= nk:
        k0, w = nk - 1, 1.0
    else:
        k0 = int(r)
        if k0 >= nk:
            k0 = nk - 1
        w = r - k0
    v = 0.0
    comp = (I, y, yd)
    for i in range(3):
        v += ((1.0 - w) * K[k0, i] + w * K[k0 + 1, i]) * comp[i]
    # y_ddot = N u + R: R at zero input, N the response to a unit input (friction in R)
    r0 = output_acceleration(P, q1, q2, q1d, q2d, 0.0, dph, ddph)
    nn = output_acceleration(P, q1, q2, q1d, q2d, 1.0, dph, ddph) - r0
    u = (v - r0) / nn
    umax = tab[T_UMAX]
    if tab[T_MU] > 0.0:
        u = friction_clip(P, q1, q2, q1d, q2d, u, tab[T_MU], tab[T_NX], tab[T_NY], umax)
    if u > umax:
        u = umax
    elif u < -umax:
        u = -umax
    if not (u == u):
        u = 0.0
    return u, I, y, yd, v, ref


@_jit
def friction_clip(P, q1, q2, q1d, q2d, u, mu, nx, ny, umax):
    """``u`` [input units] clipped to the inputs in ``[-umax, umax]`` under which the stance
    foot's ground reaction at the state ``(q1, q2, q1d, q2d)`` [rad, rad/s] stays inside the
    friction cone ``|f_t| <= mu f_n`` of the ground with unit normal ``(nx, ny)``; ``u``
    unchanged where no input does (the state slips or lifts off whatever the motor does).

    The accelerations are affine in ``u``, and so is the reaction (Newton's law on the robot),
    so each side of the cone bounds ``u`` on one side."""
    a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, 0.0)
    b1, b2 = model.accelerations(P, q1, q2, q1d, q2d, 1.0)
    fn0, ft0 = model.stance_reaction(P, q1, q2, q1d, q2d, a1, a2, nx, ny)
    fn1, ft1 = model.stance_reaction(P, q1, q2, q1d, q2d, b1, b2, nx, ny)
    lo, hi = -umax, umax
    for sgn in (1.0, -1.0):
        # mu f_n(u) - sgn f_t(u) >= 0, affine: c0 + c1 u >= 0
        c0 = mu * fn0 - sgn * ft0
        c1 = mu * (fn1 - fn0) - sgn * (ft1 - ft0)
        if c1 > 0.0:
            lo = max(lo, -c0 / c1)
        elif c1 < 0.0:
            hi = min(hi, -c0 / c1)
        elif c0 < 0.0:
            return u
    if lo > hi:
        return u
    return min(max(u, lo), hi)


@_jit
def lyapunov_at(Zinv, theta0, step, z0, z1, z2, theta):
    """``V = z' Z^-1(theta) z`` for ``z = (z0, z1, z2)``, with ``Z^-1`` given at the uniform
    phase nodes ``theta0 + k step`` [rad] (``Zinv``, shape ``(n + 1, 3, 3)``) and interpolated
    linearly between them (held at the ends)."""
    r = min(max((theta - theta0) / step, 0.0), Zinv.shape[0] - 1 - 1e-12)
    k = int(r)
    w = r - k
    z = (z0, z1, z2)
    V = 0.0
    for i in range(3):
        for j in range(3):
            V += z[i] * ((1 - w) * Zinv[k, i, j] + w * Zinv[k + 1, i, j]) * z[j]
    return V
