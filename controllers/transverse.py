"""Transverse linearization of a planned walking motion (paper Section 3; control notes 3 and 4).

For one step with the virtual constraint ``q1 = phi(theta)``, ``theta = q2``, and the nominal
speed profile ``theta_dot*(theta)^2 = F*(theta)`` of the reduced dynamics, the transverse
coordinates of a state ``x = (q1, q2, q1d, q2d)`` are::

    x_perp = [I, y, y_dot],   I = theta_dot^2 - F*(theta),   y = q1 - phi(theta),
    y_dot = q1d - phi'(theta) theta_dot.

With ``y_ddot = v`` (partial feedback linearisation, :func:`controllers.reduced.pfl_terms`) their
linearization along the nominal motion is ``z' = A(t) z + B(t) v`` (:meth:`StepModel.matrices`),
and across an impact ``z+ = F_j z-`` (:func:`impact_jacobian`; :func:`impact_jacobian_fd` is the
finite-difference counterpart used to check it).

Derivatives of model terms with respect to ``q1`` and ``q1d`` are taken by the complex step
through :mod:`envs.physics.model` (exact to rounding), so the model equations are written only once.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.polynomial import polynomial as npoly
from scipy.optimize import brentq

from envs.physics import model

from .bezier import BezierConstraint, phase_fraction
from .reduced import (
    ChebyshevSeries,
    cumulative_integral_matrix,
    grid_reduced_integral,
    nominal_accelerations,
    phase_at,
    reduced_coefficients,
    series_at,
    step_fractions,
)

__all__ = [
    "StepModel",
    "impact_jacobian",
    "impact_jacobian_fd",
    "surface_state",
]

_H = 1e-30  # complex-step size

_jit = njit(cache=True, error_model="numpy")


@functools.cache
def _power_fit(order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The fit of a polynomial of ``order`` through its values at ``order + 1`` Chebyshev
    points ``sn`` of [0, 1], as :func:`numpy.polynomial.polynomial.polyfit` sets it up:
    ``(sn, design matrix with unit columns, the columns' norms, rcond)``; read-only."""
    sn = 0.5 * (1 - np.cos(np.pi * np.arange(order + 1) / order))
    lhs = npoly.polyvander(sn, order).T
    scale = np.sqrt(np.square(lhs).sum(1))
    scale[scale == 0] = 1
    design = lhs.T / scale
    for a in (sn, design, scale):
        a.flags.writeable = False
    return sn, design, scale, len(sn) * np.finfo(np.float64).eps


@_jit
def _power_derivative(c, m):
    """``numpy.polynomial.polynomial.polyder(c, m)`` of 1-d coefficients ``c``: the same
    products ``j c_j``, without its per-call set-up."""
    if m >= c.size:
        return c[:1] * 0.0
    for _ in range(m):
        d = np.empty(c.size - 1)
        for j in range(1, c.size):
            d[j - 1] = j * c[j]
        c = d
    return c


@_jit
def _phi_power_forms(pc, span, span_sq):
    """The power forms of ``phi'`` and ``phi''`` in ``s`` from that of ``phi``, ``pc``, on a
    step of span ``span`` (``span_sq``: its square as the caller takes it)."""
    return _power_derivative(pc, 1) / span, _power_derivative(pc, 2) / span_sq


@_jit
def _power_series3(s, c0, c1, c2):
    """``numpy.polynomial.polynomial.polyval(s, c)`` of the three coefficient vectors at the
    points ``s`` (1-d), by its Horner recurrence in its order: the same numbers."""
    out = np.empty((3, s.size))
    for r, c in enumerate((c0, c1, c2)):
        n = c.size
        for j in range(s.size):
            v = c[n - 1] + s[j] * 0.0
            for i in range(2, n + 1):
                v = c[n - i] + v * s[j]
            out[r, j] = v
    return out


# The compiled kernels below take a step model's arrays as StepModel._args lists them:
# ``P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef`` (robot parameters; phi, phi', phi'' in
# power form in s; the step's start and span; the speed profile's Chebyshev series on [fa, fb]).
# They evaluate each formula entry by entry in the order numpy evaluates it on arrays: the
# same numbers, without numpy's per-call cost on these short arrays.


@_jit
def _constraint_rows(pc0, pc1, pc2, theta_plus, span, theta):
    """``(phi, phi', phi'')`` as the rows of a ``(3, N)`` array at the phases ``theta`` (1-d)."""
    return _power_series3(phase_fraction(theta, theta_plus, span), pc0, pc1, pc2)


@_jit
def _speed_profile_nodes(P, pc0, pc1, pc2, theta_plus, span, mid, a, b, fractions, q):
    """``psi`` and ``Gam`` of the reduced dynamics (:func:`controllers.reduced.reduced_integral`)
    on the Chebyshev grid of ``[a, b]`` (``fractions``, ``q``: its :func:`step_fractions` and
    :func:`cumulative_integral_matrix`), and whether ``alpha`` keeps its sign at the phase
    ``mid`` all over the grid (above 1e-12 times it); ``psi, Gam`` are not filled if not."""
    dm = _constraint_rows(pc0, pc1, pc2, theta_plus, span, np.array([mid]))
    sign = np.sign(reduced_coefficients(P, dm[0, 0], mid, dm[1, 0], dm[2, 0])[0])
    th = phase_at(a, b - a, fractions)
    d = _constraint_rows(pc0, pc1, pc2, theta_plus, span, th)
    al, be, ga = reduced_coefficients(P, d[0], th, d[1], d[2])
    psi, gam = np.empty(th.size), np.empty(th.size)
    if not np.all(sign * al > 1e-12):
        return psi, gam, False
    grid_reduced_integral(al, be, ga, q, 0.5 * (th[-1] - th[0]), -math.inf, psi, gam)
    return psi, gam, True


@_jit
def _speed_slope(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, theta):
    """:meth:`StepModel.dthetadot_sq` at the phases ``theta`` (1-d)."""
    d = _constraint_rows(pc0, pc1, pc2, theta_plus, span, theta)
    al, be, ga = reduced_coefficients(P, d[0], theta, d[1], d[2])
    return 2.0 * nominal_accelerations(al, be, ga, d[1], d[2], series_at(theta, fa, fb, fcoef))[1]


@_jit
def _nominal_states(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, theta):
    """:meth:`StepModel.nominal_state` at the phases ``theta`` (1-d), shape ``(N, 4)``."""
    d = _constraint_rows(pc0, pc1, pc2, theta_plus, span, theta)
    td = np.sqrt(series_at(theta, fa, fb, fcoef))
    out = np.empty((theta.size, 4))
    out[:, 0] = d[0]
    out[:, 1] = theta + 0.0 * d[0]
    out[:, 2] = d[1] * td
    out[:, 3] = td + 0.0 * d[0]
    return out


@_jit
def _coords_jacobian(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, x):
    """:meth:`StepModel.coords_jacobian` at the state ``x`` (4,)."""
    th = np.array([x[1]])
    thd = x[3]
    d = _constraint_rows(pc0, pc1, pc2, theta_plus, span, th)
    dF = _speed_slope(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, th)[0]
    J = np.zeros((3, 4))
    J[0, 1], J[0, 3] = -dF, 2.0 * thd
    J[1, 0], J[1, 1] = 1.0, -d[1, 0]
    J[2, 1], J[2, 2], J[2, 3] = -d[2, 0] * thd, 1.0, -d[1, 0]
    return J


@_jit
def _surface_gradient(P, slope, q1, q2):
    """:meth:`StepModel.surface_gradient` of the ground line of slope ``slope``."""
    g = np.zeros(4)
    for i in range(2):
        if i == 0:
            a, b = q1 + 1j * _H, q2 + 0j
        else:
            a, b = q1 + 0j, q2 + 1j * _H
        fx, fy = model.swing_foot_position(P, a, b, 0.0, 0.0)
        g[i] = (fy - slope * fx).imag / _H
    return g


@_jit
def _linearization(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, theta):
    """:meth:`StepModel.coefficients` at the phases ``theta`` (1-d)."""
    d = _constraint_rows(pc0, pc1, pc2, theta_plus, span, theta)
    phi, dphi, ddphi = d[0], d[1], d[2]
    al, be, ga = reduced_coefficients(P, phi, theta, dphi, ddphi)
    F = series_at(theta, fa, fb, fcoef)
    td = np.sqrt(F)
    q1dd, thdd = nominal_accelerations(al, be, ga, dphi, ddphi, F)
    # complex step in q1 (and q1d) of the unactuated row
    #   Phi(q1, q1d) = M21(q1) (phi' thdd + phi'' td^2) + M22(q1) thdd + [C qd]_2 + G2
    q1c = phi + 1j * _H
    _, m12, m22 = model.mass_matrix(P, q1c)
    _, c2 = model.coriolis(P, q1c, dphi * td + 0j, td + 0j)
    _, g2 = model.gravity(P, q1c, theta + 0j)
    dPhi_dq1 = np.imag(m12 * q1dd + m22 * thdd + c2 + g2) / _H
    _, c2d = model.coriolis(P, phi + 0j, dphi * td + 1j * _H, td + 0j)
    dPhi_dq1d = np.imag(c2d) / _H
    m12r = model.mass_matrix(P, phi)[1]
    g_y, g_yd, g_v = -dPhi_dq1, -dPhi_dq1d, -m12r
    k = 2.0 * td / al
    return -k * be, k * g_y, k * g_yd, k * g_v, td


@_jit
def _phase_linearization(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, theta):
    """:meth:`StepModel.phase_matrices` at the phases ``theta`` (1-d)."""
    a11, a12, a13, b1, td = _linearization(P, pc0, pc1, pc2, theta_plus, span, fa, fb, fcoef, theta)
    n = a11.size
    A = np.zeros((n, 3, 3))
    B = np.zeros((n, 3, 1))
    for i in range(n):
        A[i, 0, 0], A[i, 0, 1], A[i, 0, 2] = a11[i] / td[i], a12[i] / td[i], a13[i] / td[i]
        A[i, 1, 2] = 1.0 / td[i]
        B[i, 0, 0], B[i, 2, 0] = b1[i] / td[i], 1.0 / td[i]
    return A, B, 1.0 / td


@dataclass
class StepModel:
    """Nominal motion of one step and its transverse coordinates.

    Args:
        P: robot parameter vector (``RobotParams.vector()``).
        constraint: the step's virtual constraint.
        thetadot_plus: nominal ``theta_dot`` at ``theta_plus`` [rad/s], > 0.
        ground_slope: slope ``dh/dx`` of the ground at the planned foothold (0 on stairs and
            blocks); defines the switching surface used by the impact linearization.
        margin: fraction of the step's span by which the nominal speed profile is extended on
            both sides (states slightly before ``theta_plus`` or after ``theta_minus``); halved
            (down to 0) while the constraint continued that far would stall the walker.
        n_cheb: Chebyshev grid size of the speed profile.

    Raises:
        ValueError: the nominal ``theta_dot^2`` is not positive over the extended step.
    """

    P: np.ndarray
    constraint: BezierConstraint
    thetadot_plus: float
    ground_slope: float = 0.0
    margin: float = 0.15
    n_cheb: int = 48
    _F: ChebyshevSeries = field(init=False, repr=False)
    _pc: tuple = field(init=False, repr=False)
    _args: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        c = self.constraint
        if not (math.isfinite(self.thetadot_plus) and self.thetadot_plus > 0):
            raise ValueError(f"StepModel.thetadot_plus = {self.thetadot_plus!r}; allowed > 0")
        # power-basis coefficients of phi in s (exact: phi is a polynomial of this order)
        sn, design, scale, rcond = _power_fit(c.order)
        # numpy.polynomial.polynomial.polyfit(sn, phi, order), its design matrix made once
        pc = np.linalg.lstsq(design, c.phi(c.theta_plus + sn * c.span), rcond)[0] / scale
        self._pc = (pc, *_phi_power_forms(pc, c.span, c.span**2))
        # the constraint continued past the step's ends may be singular or stall the walker
        # there (a steep polynomial): the margin then halves until neither happens
        margins = [self.margin * 0.5**k for k in range(4)] + [0.0]
        mid = 0.5 * (c.theta_plus + c.theta_minus)
        grid = (step_fractions(self.n_cheb), cumulative_integral_matrix(self.n_cheb))
        for margin in dict.fromkeys(margins):
            a = c.theta_plus - margin * c.span
            b = c.theta_minus + margin * c.span
            psi, gam, alpha_ok = _speed_profile_nodes(
                self.P, *self._pc, c.theta_plus, c.span, mid, a, b, *grid
            )
            if not alpha_ok:
                continue
            # F(theta) = psi(theta, a) Fa + Gam(theta, a), with Fa fixed by F(theta_plus)
            psi_s, gam_s = ChebyshevSeries(psi, a, b), ChebyshevSeries(gam, a, b)
            fa = (self.thetadot_plus**2 - gam_s(c.theta_plus)) / psi_s(c.theta_plus)
            F_nodes = psi * fa + gam
            # positive at the nodes and between them (the interpolant can dip below zero
            # between nodes on a step that nearly stalls, and theta_dot = sqrt(F) is taken
            # on other grids)
            F = ChebyshevSeries(F_nodes, a, b)
            F_min = min(F_nodes.min(), F(np.linspace(a, b, 257)).min())
            if F_min > 0:
                break
        if not alpha_ok:
            raise ValueError("StepModel: alpha(theta) vanishes on the step (singular constraint)")
        if not F_min > 0:
            raise ValueError(
                "StepModel: the nominal theta_dot^2 is not positive over the step "
                f"(min {F_min:.3g} rad^2/s^2): the walker would stall"
            )
        self.margin = margin
        self._F = F
        self._args = (self.P, *self._pc, c.theta_plus, c.span, F.theta_a, F.theta_b, F.coef)

    # ------------------------------------------------------------------ nominal motion
    def derivatives(self, theta: np.ndarray | float) -> tuple[np.ndarray, ...]:
        """``(phi, phi', phi'')`` at ``theta`` (the constraint in power form, fast)."""
        th = np.asarray(theta, dtype=np.float64)
        c = self.constraint
        out = _constraint_rows(*self._pc, c.theta_plus, c.span, th.reshape(-1))
        if th.ndim == 0:
            return out[0, 0], out[1, 0], out[2, 0]
        return out[0].reshape(th.shape), out[1].reshape(th.shape), out[2].reshape(th.shape)

    @property
    def power_coefficients(self) -> np.ndarray:
        """Coefficients of ``phi`` as a polynomial in ``s = (theta - theta+) / span``
        (ascending powers)."""
        return self._pc[0]

    @property
    def theta_plus(self) -> float:
        """Phase at the start of the step [rad]."""
        return self.constraint.theta_plus

    @property
    def theta_minus(self) -> float:
        """Phase at the planned impact [rad]."""
        return self.constraint.theta_minus

    def thetadot_sq(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot^2`` [rad^2/s^2] at ``theta``."""
        return self._F(theta)

    def dthetadot_sq(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``d F* / d theta = -2 (beta F* + gamma) / alpha`` [rad/s^2]."""
        th = np.asarray(theta, dtype=np.float64)
        out = _speed_slope(*self._args, th.reshape(-1))
        return float(out[0]) if th.ndim == 0 else out.reshape(th.shape)

    def nominal_state(self, theta: np.ndarray | float) -> np.ndarray:
        """Nominal ``(q1, q2, q1d, q2d)`` at ``theta`` (last axis)."""
        th = np.asarray(theta, dtype=np.float64)
        return _nominal_states(*self._args, th.reshape(-1)).reshape(th.shape + (4,))

    # ------------------------------------------------------------------ coordinates
    def coords(self, x: np.ndarray) -> np.ndarray:
        """Transverse coordinates ``[I, y, y_dot]`` of states ``x = (q1, q2, q1d, q2d)``."""
        x = np.asarray(x, dtype=np.float64)
        q1, th, q1d, thd = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
        phi, dphi, _ = self.derivatives(th)
        return np.stack([thd * thd - self._F(th), q1 - phi, q1d - dphi * thd], axis=-1)

    def coords_jacobian(self, x: np.ndarray) -> np.ndarray:
        """``d x_perp / d x`` (3 x 4) at one state ``x``."""
        q1, th, q1d, thd = (float(v) for v in x)
        return _coords_jacobian(*self._args, np.array([q1, th, q1d, thd]))

    # ------------------------------------------------------------------ linearization
    def coefficients(self, theta: np.ndarray | float) -> tuple[np.ndarray, ...]:
        """``(a11, a12, a13, b1, thetadot)`` along the nominal motion at ``theta`` (time units).

        ``a11 = -2 td beta / alpha``, ``a12 = 2 td g_y / alpha``, ``a13 = 2 td g_yd / alpha``,
        ``b1 = 2 td g_v / alpha`` (control notes, section 3) with ``td`` the nominal
        ``theta_dot``.
        """
        th = np.atleast_1d(np.asarray(theta, dtype=np.float64))
        return tuple(v.reshape(th.shape) for v in _linearization(*self._args, th.reshape(-1)))

    def matrices(self, theta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """``A(theta)`` (..., 3, 3) and ``B(theta)`` (..., 3, 1) of ``z' = A z + B v`` in time
        units, evaluated at the nominal point of phase ``theta``."""
        a11, a12, a13, b1, _ = self.coefficients(theta)
        n = a11.size
        A = np.zeros((n, 3, 3))
        A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = a11, a12, a13
        A[:, 1, 2] = 1.0
        B = np.zeros((n, 3, 1))
        B[:, 0, 0], B[:, 2, 0] = b1, 1.0
        return A, B

    def phase_matrices(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``A / theta_dot``, ``B / theta_dot`` and ``w = 1 / theta_dot`` at ``theta``: the
        linearization with the phase as independent variable (``dz/dtheta``)."""
        th = np.asarray(theta, dtype=np.float64).reshape(-1)
        return _phase_linearization(*self._args, th)

    # ------------------------------------------------------------------ switching surface
    def surface(self, q1: float, q2: float) -> float:
        """Switching function ``S(q)``: zero when the swing foot is on the ground line through
        the planned foothold (slope :attr:`ground_slope`); positive above it."""
        x0, y0 = self._foothold()
        fx, fy = model.swing_foot_position(self.P, q1, q2, 0.0, 0.0)
        return (fy - y0) - self.ground_slope * (fx - x0)

    def surface_gradient(self, q1: float, q2: float) -> np.ndarray:
        """``dS/dx`` (4,) at configuration ``(q1, q2)``."""
        return _surface_gradient(self.P, float(self.ground_slope), float(q1), float(q2))

    def _foothold(self) -> tuple[float, float]:
        c = self.constraint
        fx, fy = model.swing_foot_position(
            self.P, float(c.phi(c.theta_minus)), c.theta_minus, 0.0, 0.0
        )
        return float(fx), float(fy)


def surface_state(step: StepModel, z: np.ndarray) -> np.ndarray:
    """The state on the step's switching surface near the nominal pre-impact point whose
    transverse coordinates are ``z = [I, y, y_dot]``."""
    I, y, yd = (float(v) for v in z)
    c = step.constraint

    def s_of(th: float) -> float:
        return step.surface(float(c.phi(th)) + y, th)

    w = 0.05 * c.span
    th = brentq(s_of, c.theta_minus - w, c.theta_minus + w, xtol=1e-15, rtol=1e-15)
    F = float(step.thetadot_sq(th)) + I
    td = math.sqrt(F)
    return np.array([float(c.phi(th)) + y, th, float(c.dphi(th)) * td + yd, td])


def _impact_map(P: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.array(model.impact(P, x[0], x[1], x[2], x[3]))


@_jit
def _impact_terms(step, theta_minus, slope, nxt):
    """The factors of :func:`impact_jacobian` from the arrays of its two models: ``[dT-; dS]``
    at the nominal pre-impact state (4 x 4), ``dDelta`` there (4 x 4) and ``dT+`` after the
    impact (3 x 4)."""
    xm = _nominal_states(*step, np.array([theta_minus]))[0]
    D = np.empty((4, 4))
    D[:3] = _coords_jacobian(*step, xm)
    D[3] = _surface_gradient(step[0], slope, xm[0], xm[1])
    xc = np.empty((4, 4), dtype=np.complex128)
    for r in range(4):
        for k in range(4):
            xc[r, k] = complex(xm[r], 0.0) + 1j * _H * (1.0 if r == k else 0.0)
    q1, q2, q1d, q2d = model.impact(step[0], xc[0], xc[1], xc[2], xc[3])
    dDelta = np.empty((4, 4))
    dDelta[0], dDelta[1] = np.imag(q1) / _H, np.imag(q2) / _H
    dDelta[2], dDelta[3] = np.imag(q1d) / _H, np.imag(q2d) / _H
    xp = np.array(model.impact(step[0], xm[0], xm[1], xm[2], xm[3]))
    return D, dDelta, _coords_jacobian(*nxt, xp)


_SURFACE_RHS = np.vstack([np.eye(3), np.zeros((1, 3))])
_SURFACE_RHS.flags.writeable = False


def impact_jacobian(step: StepModel, nxt: StepModel) -> np.ndarray:
    """Closed-form ``F_j`` (3 x 3): transverse coordinates of ``step`` on its switching surface
    to those of ``nxt`` after the impact, ``F = dT+ dDelta [dT-; dS]^-1 [I_3; 0]``."""
    D, dDelta, dT = _impact_terms(step._args, step.theta_minus, float(step.ground_slope), nxt._args)
    return dT @ dDelta @ np.linalg.solve(D, _SURFACE_RHS)


def impact_jacobian_fd(step: StepModel, nxt: StepModel, h: float = 1e-6) -> np.ndarray:
    """``F_j`` by central differences of ``z -> x_perp^{j+1}(Delta(X_S(z)))``."""
    P = step.P
    F = np.zeros((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        zp = nxt.coords(_impact_map(P, surface_state(step, e)))
        zm = nxt.coords(_impact_map(P, surface_state(step, -e)))
        F[:, i] = (zp - zm) / (2 * h)
    return F
