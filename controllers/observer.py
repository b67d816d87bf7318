"""High-gain observer of the joint velocities (paper Section 5; control notes section 6).

A copy of the nonlinear swing-phase dynamics plus a linear correction from the measured angles::

    q_hat'  = qd_hat + (2/eps) (q_meas - q_hat)
    qd_hat' = M^-1(q_hat) (B u - C(q_hat, qd_hat) qd_hat - G(q_hat) - tau_F)
              + (1/eps^2) (q_meas - q_hat)

which puts both eigenvalues of each joint's linearised error at ``-1/eps``. At every impact the
impact map is applied to the estimate. Between control ticks the measurement and the input are
interpolated linearly between consecutive samples (the input is held) and the observer is
integrated with classical RK4 on sub-steps of at most ``eps / 4``. The update is compiled with
numba; the state lives in a 4-vector ``[q1, q2, q1d, q2d]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from envs.physics import model
from envs.physics.params import RobotParams
from envs.physics.terrain import terrain_height

_jit = njit(cache=True, error_model="numpy")


@_jit
def _observer_rhs(P, x, qm1, qm2, u, l1, l2, out):
    d1 = qm1 - x[0]
    d2 = qm2 - x[1]
    a1, a2 = model.accelerations(P, x[0], x[1], x[2], x[3], u)
    out[0] = x[2] + l1 * d1
    out[1] = x[3] + l1 * d2
    out[2] = a1 + l2 * d1
    out[3] = a2 + l2 * d2


@_jit
def observer_update(P, x, qa1, qa2, qb1, qb2, u, dt, eps, nsub):
    """Advance the estimate ``x = [q1, q2, q1d, q2d]`` in place over ``dt`` [s].

    The measured angles [rad] go linearly from ``(qa1, qa2)`` at the start of the interval to
    ``(qb1, qb2)`` at its end (first-order hold between two samples; pass equal values for a
    held measurement); ``u`` is the input held over the interval; ``nsub`` RK4 sub-steps.
    """
    l1 = 2.0 / eps
    l2 = 1.0 / (eps * eps)
    h = dt / nsub
    k1 = np.empty(4)
    k2 = np.empty(4)
    k3 = np.empty(4)
    k4 = np.empty(4)
    xt = np.empty(4)
    s1 = (qb1 - qa1) / dt
    s2 = (qb2 - qa2) / dt
    for j in range(nsub):
        t0 = j * h
        m1, m2 = qa1 + s1 * t0, qa2 + s2 * t0
        n1, n2 = m1 + 0.5 * h * s1, m2 + 0.5 * h * s2
        e1, e2 = m1 + h * s1, m2 + h * s2
        _observer_rhs(P, x, m1, m2, u, l1, l2, k1)
        for i in range(4):
            xt[i] = x[i] + 0.5 * h * k1[i]
        _observer_rhs(P, xt, n1, n2, u, l1, l2, k2)
        for i in range(4):
            xt[i] = x[i] + 0.5 * h * k2[i]
        _observer_rhs(P, xt, n1, n2, u, l1, l2, k3)
        for i in range(4):
            xt[i] = x[i] + h * k3[i]
        _observer_rhs(P, xt, e1, e2, u, l1, l2, k4)
        for i in range(4):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@_jit
def observer_impact(P, x):
    """Apply the impact map to the estimate ``x`` in place (legs swap)."""
    a, b, c, d = model.impact(P, x[0], x[1], x[2], x[3])
    x[0] = a
    x[1] = b
    x[2] = c
    x[3] = d


@_jit
def predict_touchdown(P, x, u, dt, tx, ty, n, xs, ys, nsub, ahead):
    """Locate a touchdown inside one control period from the estimate ``x`` (model only).

    Integrates the swing-phase model from ``x`` under the held input ``u`` over ``dt`` [s] in
    ``nsub`` RK4 sub-steps and finds the first downward crossing of the ground
    (``tx, ty, n``) by the full-length swing foot once it is ``ahead`` [m] in front of the
    stance foot ``(xs, ys)``; the crossing time inside the sub-step is found by bisection.

    Returns:
        ``(found, tau, x_pre, foot_x)``: whether a crossing was found, its time after the start
        [s] (``dt`` if not found), the state there (pre-impact) and the foot's x [m].
    """
    h = dt / nsub
    xt = x.copy()
    t = 0.0
    fx, fy = model.swing_foot_position(P, xt[0], xt[1], xs, ys)
    c0 = fy - terrain_height(tx, ty, n, fx)
    if c0 <= 0.0 and fx - xs >= ahead:  # the estimate is already through the ground
        return True, 0.0, xt, fx
    for _ in range(nsub):
        x1 = _model_rk4(P, xt, u, h)
        fx, fy = model.swing_foot_position(P, x1[0], x1[1], xs, ys)
        c1 = fy - terrain_height(tx, ty, n, fx)
        if c1 <= 0.0 and c0 > 0.0 and fx - xs >= ahead:
            a, b = 0.0, h
            for _ in range(40):
                m = 0.5 * (a + b)
                xm = _model_rk4(P, xt, u, m)
                gx, gy = model.swing_foot_position(P, xm[0], xm[1], xs, ys)
                if gy - terrain_height(tx, ty, n, gx) > 0.0:
                    a = m
                else:
                    b = m
            xb = _model_rk4(P, xt, u, b)
            gx, _ = model.swing_foot_position(P, xb[0], xb[1], xs, ys)
            return True, t + b, xb, gx
        xt = x1
        c0 = c1
        t += h
    return False, dt, xt, fx


@_jit
def _model_rk4(P, x, u, h):
    """The state ``x`` after one swing-phase RK4 step of length ``h`` [s] of the model under
    the held input ``u`` (:func:`envs.physics.model.swing_rk4`), as a new 4-vector."""
    a1, a2 = model.accelerations(P, x[0], x[1], x[2], x[3], u)
    r = model.swing_rk4(P, x[0], x[1], x[2], x[3], u, h, a1, a2)
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = r[0], r[1], r[2], r[3]
    return out


#: the paper's observer time constant [s]
PAPER_EPS = 0.02

#: the default time constant [s]: twice the paper's. With the encoders' noise at five times
#: its nominal 0.001 rad, the paper's 0.02 s lets about 0.1 rad/s of noise into the velocity
#: estimate a plan starts from; doubling it divides that by about 2.8 (velocity noise goes as
#: eps^-3/2), and the observer, integrating the model with the applied input, lags little.
DEFAULT_EPS = 0.04

#: the encoders :data:`DEFAULT_EPS` was chosen for, the envs' nominal sensors
#: (``configs/envs/base.yaml``): Gaussian noise and quantisation step of each encoder [rad]
NOMINAL_ENCODER_NOISE = 0.001
NOMINAL_ENCODER_RESOLUTION = 2.0 * math.pi / 4096.0


def angle_sigma(encoder_noise: float, encoder_resolution: float) -> float:
    """Standard deviation [rad] of a decoded angle, from each encoder's Gaussian noise and
    quantisation step [rad] (its uniform error): ``q2`` reads two encoders."""
    return math.sqrt(2.0) * math.hypot(encoder_noise, encoder_resolution / math.sqrt(12.0))


def eps_for_noise(sigma: float) -> float:
    """The observer time constant [s] for decoded angles of standard deviation ``sigma``
    [rad]: :data:`DEFAULT_EPS` on the nominal encoders or quieter ones, longer on noisier
    ones, ``DEFAULT_EPS (sigma / sigma_nominal)^(2/3)``, which keeps the velocity estimate's
    noise (``sigma eps^-3/2``) at its level on the nominal encoders."""
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"angle sigma = {sigma!r}; allowed: a number >= 0 [rad]")
    nominal = angle_sigma(NOMINAL_ENCODER_NOISE, NOMINAL_ENCODER_RESOLUTION)
    return DEFAULT_EPS * max(1.0, sigma / nominal) ** (2.0 / 3.0)


def substeps_for(dt: float, eps: float) -> int:
    """Number of RK4 sub-steps that keeps each one at most ``eps / 4`` long."""
    return max(1, math.ceil(dt / (0.25 * eps)))


class HighGainObserver:
    """Velocity observer from measured joint angles.

    Args:
        robot: robot parameters (the model copy inside the observer).
        dt: control period [s], > 0: the interval of each :meth:`update`.
        eps: observer time constant [s], > 0 (default :data:`DEFAULT_EPS`; the paper's:
            :data:`PAPER_EPS`); error eigenvalues at ``-1/eps``.

    Attributes:
        x: the estimate ``[q1, q2, q1d, q2d]`` [rad, rad/s], updated in place.
        q_last: the last measured angles [rad], where the next update's interpolation starts.
    """

    def __init__(self, robot: RobotParams, dt: float, eps: float = DEFAULT_EPS):
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"observer dt = {dt!r}; allowed: > 0 s")
        if not (math.isfinite(eps) and eps > 0):
            raise ValueError(f"observer eps = {eps!r}; allowed: > 0 s")
        self.robot = robot
        self.P = robot.vector()
        self.dt = float(dt)
        self.eps = float(eps)
        self.nsub = substeps_for(self.dt, self.eps)
        self.x = np.zeros(4)
        self.q_last = np.zeros(2)

    def reset(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """Start from the measured angles ``q`` [rad] and a velocity guess ``qd`` (default 0)."""
        self.x[:2] = q
        self.x[2:] = 0.0 if qd is None else qd
        self.q_last = np.array(q, dtype=np.float64)

    def update(self, q_meas: np.ndarray, u: float) -> np.ndarray:
        """One control period ending with the measurement ``q_meas`` [rad], input ``u`` held;
        the measurement is interpolated linearly from the previous one. Returns the estimate."""
        qa = self.q_last
        observer_update(
            self.P,
            self.x,
            qa[0],
            qa[1],
            float(q_meas[0]),
            float(q_meas[1]),
            float(u),
            self.dt,
            self.eps,
            self.nsub,
        )
        self.q_last = np.array(q_meas, dtype=np.float64)
        return self.x

    def impact(self) -> np.ndarray:
        """Apply the impact map to the estimate (and to the last measurement)."""
        observer_impact(self.P, self.x)
        q1, q2 = self.q_last
        self.q_last = np.array([-q1, q2 - q1])
        return self.x
