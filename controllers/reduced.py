"""Reduced (zero) dynamics along a virtual constraint, impact along constraints, and PFL terms.

For one step with the constraint ``q1 = phi(theta)``, ``theta = q2``, the unactuated row of the
equations of motion restricted to the constraint reads (control notes, section 2)

    alpha(theta) theta_ddot + beta(theta) theta_dot^2 + gamma(theta) = 0,

with ``alpha = M21 phi' + M22``, ``beta theta_dot^2 = M21 phi'' theta_dot^2 + [C(q, qd) qd]_2`` at
``qd = [phi', 1] theta_dot`` (the Christoffel terms, from :func:`envs.physics.model.coriolis`, which
is quadratic in ``qd``) and ``gamma = G2``. Its integral is

    theta_dot^2 = psi(theta, theta0) theta_dot0^2 + Gam(theta, theta0).

Integrals are computed on a Chebyshev-Lobatto grid over the step (spectrally accurate for the
smooth integrands of a Bezier constraint): :func:`phase_grid` makes the grid, and every function
here is vectorised over it. All model quantities come from :mod:`envs.physics.model`; ``P`` is
``RobotParams.vector()``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit
from numpy.polynomial import chebyshev as cheb

from envs.physics import model

# entry-wise functions are compiled like the model's: the same code serves numpy arrays (a grid of
# phases) and scalars inside compiled loops (controllers.planner.kernel)
_jit = njit(cache=True, error_model="numpy")

__all__ = [
    "ChebyshevSeries",
    "cheb_nodes",
    "chebyshev_point",
    "cumulative_integral",
    "cumulative_integral_matrix",
    "grid_cumulative_integral",
    "grid_reduced_integral",
    "grid_step_time",
    "impact_along_constraint",
    "matvec",
    "nominal_accelerations",
    "nominal_input",
    "output_acceleration",
    "pfl_terms",
    "phase_at",
    "phase_grid",
    "reduced_coefficients",
    "reduced_integral",
    "series_at",
    "step_fractions",
    "step_time",
]


# ---------------------------------------------------------------------------- Chebyshev grid
@lru_cache(maxsize=16)
def _cheb_matrices(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes ``x`` (increasing, on [-1, 1]), values->coefficients matrix, cumulative integral."""
    k = np.arange(n + 1)
    x = -np.cos(np.pi * k / n)
    vinv = np.linalg.inv(cheb.chebvander(x, n))
    integ = cheb.chebint(np.eye(n + 1), lbnd=-1.0, axis=0)  # (n + 2, n + 1) coefficient map
    q = cheb.chebvander(x, n + 1) @ integ @ vinv
    for arr in (x, vinv, q):
        arr.flags.writeable = False
    return x, vinv, q


def cheb_nodes(n: int) -> np.ndarray:
    """``n + 1`` Chebyshev-Lobatto nodes on ``[-1, 1]`` in increasing order (``n >= 4``)."""
    if int(n) != n or n < 4:
        raise ValueError(f"grid size n = {n!r}; allowed: integer >= 4")
    return _cheb_matrices(int(n))[0]


def step_fractions(n: int) -> np.ndarray:
    """The ``n + 1`` nodes of :func:`cheb_nodes` mapped onto ``[0, 1]``, increasing: fractions
    of a step's phase range (``s`` of :class:`controllers.bezier.BezierConstraint`)."""
    return 0.5 * (cheb_nodes(n) + 1.0)


@_jit
def phase_at(theta_a: float, span: float, s: np.ndarray | float) -> np.ndarray | float:
    """Phase ``theta_a + span s`` [rad] at the fraction ``s`` of the range ``span`` [rad] that
    starts at ``theta_a`` [rad] (entry by entry)."""
    return theta_a + span * s


def phase_grid(theta_a: float, theta_b: float, n: int) -> np.ndarray:
    """Chebyshev-Lobatto grid of ``n + 1`` phases on ``[theta_a, theta_b]`` [rad], increasing:
    :func:`phase_at` of the :func:`step_fractions`."""
    return phase_at(float(theta_a), float(theta_b) - float(theta_a), step_fractions(n))


def cumulative_integral_matrix(n: int) -> np.ndarray:
    """Matrix ``Q`` with ``int_{-1}^{x_k} f = (Q f)_k`` on the ``n + 1`` nodes of
    :func:`cheb_nodes` (scale by half the interval for a :func:`phase_grid`); read-only."""
    cheb_nodes(n)
    return _cheb_matrices(int(n))[2]


def cumulative_integral(values: np.ndarray, theta_a: float, theta_b: float) -> np.ndarray:
    """``int_{theta_a}^{theta_k} f`` at every node ``theta_k`` of :func:`phase_grid`
    (:func:`grid_cumulative_integral` on each grid).

    Args:
        values: ``f`` at the ``n + 1`` grid nodes along the last axis (batches allowed).
        theta_a, theta_b: the grid's interval (scalars, or arrays broadcasting against
            ``values[..., :1]`` for a batch of grids).
    """
    rows, halves, shape = _grids(values, theta_a, theta_b)
    q = _cheb_matrices(rows.shape[1] - 1)[2]
    out = np.empty_like(rows)
    for r in range(rows.shape[0]):
        grid_cumulative_integral(rows[r], q, halves[r], out[r])
    return out.reshape(shape)


def _grids(
    values: np.ndarray, theta_a: np.ndarray | float, theta_b: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Grids along the last axis of ``values`` as rows, each grid's half interval, the shape."""
    v = np.asarray(values, dtype=np.float64)
    cheb_nodes(v.shape[-1] - 1)
    half = 0.5 * (np.asarray(theta_b, dtype=np.float64) - np.asarray(theta_a, dtype=np.float64))
    halves = np.broadcast_to(half, v.shape[:-1] + (1,)).reshape(-1)
    return np.ascontiguousarray(v.reshape(-1, v.shape[-1])), halves, v.shape


@_jit
def grid_cumulative_integral(
    values: np.ndarray, q: np.ndarray, half: float, out: np.ndarray
) -> None:
    """Compiled :func:`cumulative_integral` of one grid: ``out[k] = half (q values)_k``, with
    ``q`` the :func:`cumulative_integral_matrix` and ``half`` half the grid's interval [rad]."""
    matvec(q, values, out)
    for k in range(out.size):
        out[k] = half * out[k]


@_jit
def matvec(a: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """``out = a @ x`` for a ``(K, N)`` matrix, each entry summed in the order of ``j`` (as a
    plain loop does: the same bits), four rows at a time so that their sums run side by side
    rather than one after the other."""
    nk, n = a.shape
    k = 0
    while k + 4 <= nk:
        s0 = s1 = s2 = s3 = 0.0
        for j in range(n):
            v = x[j]
            s0 += a[k, j] * v
            s1 += a[k + 1, j] * v
            s2 += a[k + 2, j] * v
            s3 += a[k + 3, j] * v
        out[k], out[k + 1], out[k + 2], out[k + 3] = s0, s1, s2, s3
        k += 4
    while k < nk:
        s = 0.0
        for j in range(n):
            s += a[k, j] * x[j]
        out[k] = s
        k += 1


class ChebyshevSeries:
    """Interpolant of values given on a :func:`phase_grid`; callable at any ``theta``.

    Inside ``[theta_a, theta_b]`` it is spectrally accurate; slightly outside, it extrapolates
    the polynomial smoothly (use only a few percent of the interval outside).
    """

    def __init__(self, values: np.ndarray, theta_a: float, theta_b: float):
        v = np.asarray(values, dtype=np.float64)
        n = v.shape[-1] - 1
        cheb_nodes(n)
        self.theta_a, self.theta_b = float(theta_a), float(theta_b)
        self.coef = v @ _cheb_matrices(n)[1].T

    def _x(self, theta: np.ndarray | float) -> np.ndarray | float:
        t = np.asarray(theta, dtype=np.float64)
        if t.ndim == 0:
            return chebyshev_point(float(t), self.theta_a, self.theta_b)
        return chebyshev_point(t, self.theta_a, self.theta_b)

    def __call__(self, theta: np.ndarray | float) -> np.ndarray | float:
        return _series_at(self._x(theta), self.coef)

    def derivative(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``d/dtheta`` of the interpolant."""
        dc = cheb.chebder(self.coef) * 2.0 / (self.theta_b - self.theta_a)
        return _series_at(self._x(theta), dc)


@_jit
def chebyshev_point(
    theta: np.ndarray | float, theta_a: float, theta_b: float
) -> np.ndarray | float:
    """The point ``x`` of [-1, 1] of the phase ``theta`` [rad] on the interval
    ``[theta_a, theta_b]`` [rad] of a :class:`ChebyshevSeries` (entry by entry)."""
    return (2.0 * theta - theta_a - theta_b) / (theta_b - theta_a)


@_jit
def series_at(theta: np.ndarray, theta_a: float, theta_b: float, coef: np.ndarray) -> np.ndarray:
    """Compiled :class:`ChebyshevSeries` call: the series ``coef`` (at least two coefficients)
    on ``[theta_a, theta_b]`` [rad] at the phases ``theta`` (1-d) [rad]."""
    return _clenshaw(chebyshev_point(theta, theta_a, theta_b), coef)


def _series_at(x: np.ndarray, coef: np.ndarray) -> np.ndarray | float:
    """The Chebyshev series ``coef`` at ``x`` (a float where ``x`` is a scalar)."""
    c = np.ascontiguousarray(coef, dtype=np.float64)
    if isinstance(x, float) and c.ndim == 1:
        return _clenshaw_at(x, c)
    out = _clenshaw(np.ravel(x), c)
    return float(out[0]) if np.ndim(x) == 0 else out.reshape(np.shape(x))


@_jit
def _clenshaw4(x0, x1, x2, x3, c):
    """The Chebyshev series ``c`` (at least two coefficients) at four points, each by
    ``chebval``'s recurrence in its order. The four recurrences run side by side: each step of
    one waits on its previous step, so that one alone leaves the processor mostly idle."""
    n = c.size
    t0, t1, t2, t3 = 2.0 * x0, 2.0 * x1, 2.0 * x2, 2.0 * x3
    a0 = b0 = d0 = e0 = c[n - 2]
    a1 = b1 = d1 = e1 = c[n - 1]
    for i in range(3, n + 1):
        ci = c[n - i]
        a0, a1 = ci - a1, a0 + a1 * t0
        b0, b1 = ci - b1, b0 + b1 * t1
        d0, d1 = ci - d1, d0 + d1 * t2
        e0, e1 = ci - e1, e0 + e1 * t3
    return a0 + a1 * x0, b0 + b1 * x1, d0 + d1 * x2, e0 + e1 * x3


@_jit
def _clenshaw_at(x, c):
    """The Chebyshev series ``c`` (at least two coefficients) at one point ``x`` (one of the
    recurrences of :func:`_clenshaw4`, whose others take no longer alongside it)."""
    return _clenshaw4(x, x, x, x, c)[0]


@_jit
def _clenshaw(x, c):
    """``numpy.polynomial.chebyshev.chebval(x, c)`` for 1-d ``x`` and ``c`` (at least two
    coefficients), by its recurrence in its order (:func:`_clenshaw4`, four points at a time):
    the same numbers, without its per-term array operations."""
    out = np.empty(x.size)
    last = x.size - 1
    for j in range(0, x.size, 4):
        v = _clenshaw4(x[j], x[min(j + 1, last)], x[min(j + 2, last)], x[min(j + 3, last)], c)
        for k in range(min(4, x.size - j)):
            out[j + k] = v[k]
    return out


# ---------------------------------------------------------------------------- reduced dynamics
@_jit
def reduced_coefficients(
    P: np.ndarray, phi: np.ndarray, theta: np.ndarray, dphi: np.ndarray, ddphi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``alpha, beta, gamma`` of the reduced dynamics at ``q = (phi(theta), theta)``.

    Args:
        P: robot parameter vector.
        phi, dphi, ddphi: ``phi(theta)`` [rad], ``phi'`` [-], ``phi''`` [1/rad].
        theta: phase ``q2`` [rad].

    Returns:
        ``alpha`` [kg m^2], ``beta`` [kg m^2], ``gamma`` [N m], broadcast over the inputs.
    """
    _, m12, m22 = model.mass_matrix(P, phi)
    alpha = m12 * dphi + m22
    # [C(q, qd) qd]_2 is quadratic in qd, so its value at qd = [phi', 1] is the Christoffel sum
    _, c2 = model.coriolis(P, phi, dphi, 1.0 + 0.0 * dphi)
    beta = m12 * ddphi + c2
    _, gamma = model.gravity(P, phi, theta)
    return alpha, beta, gamma


def reduced_integral(
    theta: np.ndarray, alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``psi(theta_k, theta_0)`` and ``Gam(theta_k, theta_0)`` on a :func:`phase_grid`
    (:func:`grid_reduced_integral` on each grid, no floor on ``alpha``).

    ``theta_dot^2(theta_k) = psi_k theta_dot(theta_0)^2 + Gam_k`` for every solution of the
    reduced dynamics. Arrays along the last axis (batches allowed); ``alpha`` must not vanish.
    """
    th = np.asarray(theta, dtype=np.float64)
    a, b, g = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (alpha, beta, gamma)))
    al, halves, shape = _grids(a, th[..., :1], th[..., -1:])
    be, ga = (np.ascontiguousarray(x.reshape(al.shape)) for x in (b, g))
    q = _cheb_matrices(al.shape[1] - 1)[2]
    psi, gam = np.empty_like(al), np.empty_like(al)
    for r in range(al.shape[0]):
        grid_reduced_integral(al[r], be[r], ga[r], q, halves[r], -math.inf, psi[r], gam[r])
    return psi.reshape(shape), gam.reshape(shape)


@_jit
def grid_reduced_integral(
    alpha: np.ndarray,
    beta: np.ndarray,
    gamma: np.ndarray,
    q: np.ndarray,
    half: float,
    alpha_floor: float,
    psi: np.ndarray,
    gam: np.ndarray,
) -> None:
    """Compiled :func:`reduced_integral` of one grid: writes ``psi`` and ``Gam`` from
    ``alpha, beta, gamma`` on the grid's nodes (``q``, ``half``: as for
    :func:`grid_cumulative_integral`). In the integrands ``alpha`` is floored at
    ``alpha_floor`` [kg m^2] (``-inf``: no floor)."""
    n = alpha.size
    w = np.empty(n)
    for k in range(n):
        w[k] = 2.0 * beta[k] / max(alpha[k], alpha_floor)
    kint = np.empty(n)
    grid_cumulative_integral(w, q, half, kint)
    for k in range(n):
        w[k] = -2.0 * gamma[k] / max(alpha[k], alpha_floor) * math.exp(kint[k])
    grid_cumulative_integral(w, q, half, gam)
    for k in range(n):
        psi[k] = math.exp(-kint[k])
        gam[k] = psi[k] * gam[k]


@_jit
def grid_step_time(
    thetadot_sq: np.ndarray,
    q: np.ndarray,
    half: float,
    floor: float,
    thetadot: np.ndarray,
    time: np.ndarray,
) -> None:
    """Compiled :func:`step_time` of one grid: writes ``thetadot = sqrt(max(thetadot_sq,
    floor))`` [rad/s] and the time [s] to reach each node from the first (``q``, ``half``: as
    for :func:`grid_cumulative_integral`; ``floor`` [rad^2/s^2])."""
    n = thetadot_sq.size
    w = np.empty(n)
    for k in range(n):
        thetadot[k] = math.sqrt(max(thetadot_sq[k], floor))
        w[k] = 1.0 / thetadot[k]
    grid_cumulative_integral(w, q, half, time)


def step_time(theta: np.ndarray, thetadot_sq: np.ndarray) -> np.ndarray:
    """Time [s] to reach each grid phase from ``theta[0]``: ``int dtheta / theta_dot``
    (:func:`grid_step_time` of one grid).

    ``thetadot_sq`` must be positive on the grid (raises ``ValueError`` otherwise).
    """
    f = np.ascontiguousarray(thetadot_sq, dtype=np.float64)
    if f.ndim != 1 or np.any(~(f > 0)):
        raise ValueError("step_time: theta_dot^2 must be > 0 on the whole grid (one grid)")
    cheb_nodes(f.size - 1)
    thetadot, time = np.empty_like(f), np.empty_like(f)
    half = 0.5 * (float(theta[-1]) - float(theta[0]))
    grid_step_time(f, _cheb_matrices(f.size - 1)[2], half, 0.0, thetadot, time)
    return time


@_jit
def nominal_accelerations(
    alpha: np.ndarray,
    beta: np.ndarray,
    gamma: np.ndarray,
    dphi: np.ndarray,
    ddphi: np.ndarray,
    thetadot_sq: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(q1dd, q2dd)`` [rad/s^2] along the constraint from the reduced dynamics."""
    thdd = -(beta * thetadot_sq + gamma) / alpha
    return dphi * thdd + ddphi * thetadot_sq, thdd


# ---------------------------------------------------------------------------- impact, PFL
@_jit
def impact_along_constraint(
    P: np.ndarray, q1_minus: np.ndarray | float, dphi_minus: np.ndarray | float
) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Impact on the constraint direction ``qd- = [phi'(theta-), 1] theta_dot-``.

    Returns:
        ``(delta, slope_plus)``: ``theta_dot+ = delta theta_dot-`` for the next step's phase,
        and the post-impact velocity direction ``q1d+/q2d+``, which the next step's constraint
        must have as ``phi'(theta+)`` for impact invariance.
    """
    d11, d12, d21, d22 = model.impact_velocity_matrix(P, q1_minus)
    delta = d21 * dphi_minus + d22
    return delta, (d11 * dphi_minus + d12) / delta


@_jit
def output_acceleration(
    P: np.ndarray,
    q1: np.ndarray | float,
    q2: np.ndarray | float,
    q1d: np.ndarray | float,
    q2d: np.ndarray | float,
    u: float,
    dphi: np.ndarray | float,
    ddphi: np.ndarray | float,
) -> np.ndarray | float:
    """``y_ddot`` [rad/s^2] of the output ``y = q1 - phi(q2)`` under the input ``u`` [input
    units]: ``q1dd - phi' q2dd - phi'' q2d^2`` (hip friction included); ``dphi, ddphi`` are
    ``phi', phi''`` evaluated at ``theta = q2``."""
    q1dd, q2dd = model.accelerations(P, q1, q2, q1d, q2d, u)
    return q1dd - dphi * q2dd - ddphi * q2d * q2d


@_jit
def pfl_terms(
    P: np.ndarray,
    q1: np.ndarray | float,
    q2: np.ndarray | float,
    q1d: np.ndarray | float,
    q2d: np.ndarray | float,
    dphi: np.ndarray | float,
    ddphi: np.ndarray | float,
) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Partial feedback linearisation terms: ``y_ddot = N u + R`` for ``y = q1 - phi(q2)``.

    ``u`` is in input units (hip torque ``kI ktau u``); ``R`` includes the hip friction at the
    given ``q1d``. ``dphi, ddphi`` are ``phi', phi''`` evaluated at ``theta = q2``. The input that
    gives ``y_ddot = v`` is ``u = (v - R) / N``. ``N`` is written in closed form here; the
    control tick (:func:`controllers.feedback.feedback_law`) takes it as the response of
    :func:`output_acceleration` to a unit input, equal up to rounding.
    """
    r = output_acceleration(P, q1, q2, q1d, q2d, 0.0, dphi, ddphi)
    m11, m12, m22 = model.mass_matrix(P, q1)
    det = m11 * m22 - m12 * m12
    # response of qdd to a unit input: M^-1 [b, 0]
    b = model.input_gain(P)
    n = b * (m22 + dphi * m12) / det
    return n, r


@_jit
def nominal_input(
    P: np.ndarray,
    phi: np.ndarray,
    theta: np.ndarray,
    dphi: np.ndarray,
    ddphi: np.ndarray,
    thetadot: np.ndarray,
) -> np.ndarray:
    """Input ``u`` [input units] that keeps the robot on the constraint (``y_ddot = 0``) at the
    nominal state ``q = (phi, theta)``, ``qd = (phi' theta_dot, theta_dot)``; friction included."""
    n, r = pfl_terms(P, phi, theta, dphi * thetadot, thetadot, dphi, ddphi)
    return -r / n
