"""Online identification of the robot's swing dynamics from the encoders and the applied input.

The paper's controller walked a robot whose model was identified beforehand; ours is built on
the nominal model, and a robot a few per cent off (``robot_error``) makes its plans wrong: with
every parameter at +-10 % the reference policy built on the nominal robot walks 8 of 30
validation stairs courses, and all 30 when it is built on the true parameters. Only some of
those parameters shape the motion between touchdowns, and they are identifiable from what the
controller sees.

The swing phase (:func:`envs.physics.model.accelerations`) depends on the parameters only
through the coefficients ``p1 .. p5`` of the paper's Appendix B, the input gain ``b`` and the
hip friction ``Fc, Fv``, linearly, and is unchanged when all of them are scaled by the same
factor: only their ratios are identifiable, so ``b`` stays the nominal one and ``theta = (p1,
p2, p3, p4, p5, Fc, Fv)`` is identified in the nominal input's scale. Every robot has ``p2 / p4
= l / g``; the fit ties ``p2`` to ``p4`` and the leg length, which the localisation measures
better than the dynamics (a free ``p2`` absorbs a push instead).

:class:`SwingIdentifier` fits ``theta`` by **output error with multiple shooting**: each stance is
cut into segments of about 0.15 s; each segment is simulated from its own initial state (fitted too)
under the inputs that were applied, and the simulated angles are compared with the measured ones (a
Huber loss; a segment that the fitted model still cannot explain, a push say, is then left out and
the fit repeated). Short segments see the ratio of ``p3`` and ``p5`` (the stance leg's inertia and
gravity) but barely their level, which decides how much speed a step loses before its apex: a +-10 %
robot moves ``p5`` by up to 98 %, and fits on segments of 0.15 s alone missed it by 40 % (rms, on
validation stairs courses). So every stance is also cut into segments of 0.3 s (``long_segment``),
and the fit on those is used where each of them is explained to :data:`EXPLAINED_RMS` standard
deviations; a push within a long segment leaves it unexplained, and the fit on the short segments
(which a push costs one segment) is used instead. A small push (0.05 m/s at the hip) leaves a long
segment explained, and the long fit can take the push for a robot with other ``p3`` and ``p5``; so
the long fit only refines a model the short segments' fit already rejects (model error makes it
significant, a push on a nominal robot seldom does). The default (:data:`DEFAULT_LONG_SEGMENT`); 0
turns it off. The solver is an iteratively reweighted Levenberg-Marquardt on the Huber cost: a
segment's residuals depend on the coefficients and its own initial state only, so each iteration
eliminates the segments' 4 x 4 blocks (a Schur complement) and costs in proportion to the number of
segments, where a dense solver's cost grows with its cube; the coefficients' covariance is the
inverse of the same Schur complement at the solution. The Jacobian is exact for the discretised
model: each segment is simulated once with the sensitivities of its state to its initial state and
the coefficients carried through every RK4 step (forward differences took a simulation per
unknown, and a perturbation that flipped the sign of the hip rate at an RK4 stage put the Coulomb
friction's jump into a column). Equation-error fits (regressing on differentiated encoder
readings) are biased here: the unactuated row of the dynamics is homogeneous in ``theta``, and
noise in the differentiated angles pulls ``p3`` and ``p4 + p5`` to zero together. Output error
puts the noise where it is, on the measured angles. A Gaussian prior centred on the nominal
coefficients (:data:`PRIOR`) keeps the directions the data barely see (the absolute level of
``p3`` and ``p5`` when only their ratio is excited) near the nominal robot.

:func:`robot_from_coefficients` turns the identified coefficients into the nearest robot
(smallest relative change of ``m, mH, mHg, Ic, lc``) with a given leg length: the leg length is
a matter of geometry, measured better by the localisation's drift
(:class:`controllers.localisation.ScanLocaliser`) than by the ratio ``g p2 / p4`` of the
dynamics.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import least_squares  # robot_from_coefficients

from envs.physics import model
from envs.physics.params import P1, P2, P3, P4, P5, PFC, PFV, RobotParams

from .numerics import one_blas_thread

__all__ = [
    "COEFFICIENTS",
    "LONG_PRIOR",
    "PRIOR",
    "IdentifiedModel",
    "SwingIdentifier",
    "robot_from_coefficients",
    "simulate_swing",
]

#: the identified coefficients, in the order of :attr:`IdentifiedModel.theta`
COEFFICIENTS = ("p1", "p2", "p3", "p4", "p5", "Fc", "Fv")
_INDEX = np.array([P1, P2, P3, P4, P5, PFC, PFV])
#: the coefficients fitted: p2 follows p4 and the leg length (``p2 / p4 = l / g``)
_FREE = np.array([0, 2, 3, 4, 5, 6])
#: prior standard deviation of each coefficient, relative to its nominal value: products of
#: two or three parameters each +-10 % for p1..p5, a poorly known friction for Fc, Fv
PRIOR = (0.15, 0.15, 0.15, 0.15, 0.15, 0.5, 0.5)
#: the prior of the fit on long segments: wider for p3 and p5, whose level long segments see
#: and which a +-10 % robot moves furthest (p5 is the legs' gravity term less the hip's
#: counterweight: at the corners of +-10 % on every parameter it moves by up to 98 %, p3 by up
#: to 55 %). The short segments' fit keeps :data:`PRIOR`: with this one a push at every
#: mid-stance pulled its p3 and p5 by half on a nominal robot
LONG_PRIOR = (0.15, 0.15, 0.3, 0.15, 0.6, 0.5, 0.5)
_MIN_SAMPLES = 12  # a shorter segment is dropped
#: length of a long shooting segment by default [s]
DEFAULT_LONG_SEGMENT = 0.3
#: residuals beyond this many standard deviations count linearly (Huber loss)
ROBUST_SCALE = 3.0
#: a segment whose rms residual under the fit exceeds this many standard deviations is left out
OUTLIER_RMS = 3.0
#: the fit on long segments is used only where each of them is explained to this rms residual
#: [standard deviations]: a push within one leaves it unexplained (measured: 1.2-4.1 for pushed
#: segments of 0.3 s, 0.5-1.1 for the others, on rough ground and on the stairs)
EXPLAINED_RMS = 1.2
#: relative standard deviation added to every fitted coefficient's: the swing model's own error
#: (the observer's, the discretisation's), which no amount of data removes; without it a segment
#: whose sensitivities are large makes the linearised covariance overconfident (a nominal robot
#: fitted 0.6 % off in p4 at 0.07 % standard deviation)
SD_FLOOR = 0.01
#: 99th percentile of chi-square with 6 degrees of freedom (scipy.stats.chi2.ppf(0.99, 6))
CHI2_99 = 16.812
_INIT_SCALE = (1e-3, 1e-3, 0.1, 0.1)  # typical size of the initial-state corrections
#: a segment's state sensitivities: by its initial state, then by the coefficients
_SENSITIVITIES = 4 + len(COEFFICIENTS)
_EPS = float(np.finfo(np.float64).eps)


@njit(cache=True)
def simulate_swing(P, x0, u, dt, nsub):  # pragma: no cover - compiled
    """Angles ``(n, 2)`` [rad] of the swing phase sampled every ``dt`` [s] from the state
    ``x0 = [q1, q2, q1d, q2d]`` [rad, rad/s], input ``u[k]`` [input units] held over sample
    interval ``k`` (``u[n - 1]`` unused), ``nsub`` RK4 substeps per interval; no touchdown."""
    n = u.size
    out = np.empty((n, 2))
    q1, q2, w1, w2 = x0[0], x0[1], x0[2], x0[3]
    h = dt / nsub
    for k in range(n):
        out[k, 0] = q1
        out[k, 1] = q2
        if k == n - 1:
            break
        for _ in range(nsub):
            a1, a2 = model.accelerations(P, q1, q2, w1, w2, u[k])
            q1, q2, w1, w2, _w, _p, _a = model.swing_rk4(P, q1, q2, w1, w2, u[k], h, a1, a2)
    return out


@njit(cache=True)
def _coefficients(free, free_index, ratio):  # pragma: no cover - compiled
    """All seven relative coefficients from the fitted ones: ``p2`` follows ``p4`` and the leg
    length ratio ``ratio`` (``p2 / p4 = l / g`` for every robot)."""
    z = np.empty(len(COEFFICIENTS))
    z[free_index] = free
    z[1] = (1.0 + z[3]) * ratio - 1.0
    return z


# inlined where numba compiles the caller, so that the sines and cosines are shared with the
# caller's model.accelerations at the same state (a quarter of the Jacobian's time otherwise)
@njit(cache=True, inline="always")
def _acceleration_partials(P, q1, q2, q1d, q2d, q1dd, q2dd, out):  # pragma: no cover - compiled
    """Partial derivatives of the swing accelerations ``(q1dd, q2dd)`` (those of
    :func:`envs.physics.model.accelerations` at the state) into ``out`` (2, 11): by the state
    ``(q1, q2, q1d, q2d)`` and by the coefficients ``(p1, p2, p3, p4, p5, Fc, Fv)``. From the
    dynamics ``R = M qdd + C qd + G + tau_F - B u = 0``: ``d qdd = -M^-1 dR`` (the Coulomb
    term's sign counts as constant)."""
    p2, p4, p5 = P[P2], P[P4], P[P5]
    m11, m12, m22 = model.mass_matrix(P, q1)
    c, s = math.cos(q1), math.sin(q1)
    sd, cd = math.sin(q1 - q2), math.cos(q1 - q2)
    s2, c2 = math.sin(q2), math.cos(q2)
    v1 = 2.0 * q1d * q2d - q1d * q1d  # the Coriolis row 2's rate factor
    # dR / d(state, coefficients), rows 1 and 2
    r1 = out[0]
    r2 = out[1]
    r1[0] = -s * p2 * q2dd - c * p2 * q2d * q2d + cd * p4
    r2[0] = s * p2 * (2.0 * q2dd - q1dd) + c * p2 * v1 - cd * p4
    r1[1] = -cd * p4
    r2[1] = cd * p4 - c2 * (p5 + p4)
    r1[2] = P[PFV]
    r2[2] = 2.0 * s * p2 * (q2d - q1d)
    r1[3] = -2.0 * s * p2 * q2d
    r2[3] = 2.0 * s * p2 * q1d
    r1[4] = q1dd - q2dd
    r2[4] = 2.0 * q2dd - q1dd
    r1[5] = c * q2dd - s * q2d * q2d
    r2[5] = c * (q1dd - 2.0 * q2dd) + s * v1
    r1[6] = 0.0
    r2[6] = q2dd
    r1[7] = sd
    r2[7] = -sd - s2
    r1[8] = 0.0
    r2[8] = -s2
    r1[9] = np.sign(q1d)
    r2[9] = 0.0
    r1[10] = q1d
    r2[10] = 0.0
    det = m11 * m22 - m12 * m12
    for j in range(_SENSITIVITIES):
        a, b = r1[j], r2[j]
        r1[j] = (m12 * b - m22 * a) / det
        r2[j] = (m12 * a - m11 * b) / det


@njit(cache=True)
def _slope(D, j, x0, x1, x2, x3):  # pragma: no cover - compiled
    """The slope of a state's sensitivity ``(x0, x1, x2, x3)`` by unknown ``j`` at an RK4
    stage whose :func:`_acceleration_partials` are ``D`` (2, 11): unknowns 0-3 are the
    initial state's (the homogeneous equation), 4-10 the coefficients (forced by ``D``'s
    column)."""
    f0 = D[0, j] if j >= 4 else 0.0
    f1 = D[1, j] if j >= 4 else 0.0
    return (
        x2,
        x3,
        D[0, 0] * x0 + D[0, 1] * x1 + D[0, 2] * x2 + D[0, 3] * x3 + f0,
        D[1, 0] * x0 + D[1, 1] * x1 + D[1, 2] * x2 + D[1, 3] * x3 + f1,
    )


@njit(cache=True)
def _rk4_tangent(P, x, S, u, h, D):  # pragma: no cover - compiled
    """One RK4 step of :func:`envs.physics.model.swing_rk4` (its stages and update: the same
    state) from ``x`` (4,) under the input ``u``, and the step's exact derivative applied to
    the state's sensitivities ``S`` (11, 4), row ``j`` by unknown ``j`` of :func:`_slope`;
    both in place. ``D`` (4, 2, 11): work space."""
    hh = 0.5 * h
    h6 = h / 6.0
    q1, q2, q1d, q2d = x[0], x[1], x[2], x[3]
    q1dd, q2dd = model.accelerations(P, q1, q2, q1d, q2d, u)
    s2, a2, b2, s3, a3, b3, s4, a4, b4 = model.swing_rk4_stages(
        P, q1, q2, q1d, q2d, u, h, q1dd, q2dd
    )
    _acceleration_partials(P, q1, q2, q1d, q2d, q1dd, q2dd, D[0])
    _acceleration_partials(P, s2[0], s2[1], s2[2], s2[3], a2, b2, D[1])
    _acceleration_partials(P, s3[0], s3[1], s3[2], s3[3], a3, b3, D[2])
    _acceleration_partials(P, s4[0], s4[1], s4[2], s4[3], a4, b4, D[3])
    x[0] = model.rk4_sum(q1, h6, q1d, s2[2], s3[2], s4[2])
    x[1] = model.rk4_sum(q2, h6, q2d, s2[3], s3[3], s4[3])
    x[2] = model.rk4_sum(q1d, h6, q1dd, a2, a3, a4)
    x[3] = model.rk4_sum(q2d, h6, q2dd, b2, b3, b4)
    for j in range(S.shape[0]):
        v0, v1, v2, v3 = S[j, 0], S[j, 1], S[j, 2], S[j, 3]
        k0, k1, k2, k3 = _slope(D[0], j, v0, v1, v2, v3)
        l0, l1, l2, l3 = _slope(D[1], j, v0 + hh * k0, v1 + hh * k1, v2 + hh * k2, v3 + hh * k3)
        m0, m1, m2, m3 = _slope(D[2], j, v0 + hh * l0, v1 + hh * l1, v2 + hh * l2, v3 + hh * l3)
        n0, n1, n2, n3 = _slope(D[3], j, v0 + h * m0, v1 + h * m1, v2 + h * m2, v3 + h * m3)
        S[j, 0] = model.rk4_sum(v0, h6, k0, l0, m0, n0)
        S[j, 1] = model.rk4_sum(v1, h6, k1, l1, m1, n1)
        S[j, 2] = model.rk4_sum(v2, h6, k2, l2, m2, n2)
        S[j, 3] = model.rk4_sum(v3, h6, k3, l3, m3, n3)


@njit(cache=True)
def _jacobian(
    p, P, index, nominal, free_index, ratio, prior, Q, U, bounds, dt, nsub, sig
):  # pragma: no cover - compiled
    """The fit's residuals ``r`` at ``p`` (fitted coefficients, then each segment's
    initial-state correction): the prior's, then each segment's simulated minus measured angles
    [standard deviations], the segments being the rows ``bounds[s]:bounds[s + 1]`` of ``Q`` and
    ``U``; and their Jacobian in two blocks: ``Jt`` by the fitted coefficients ``(m, nf)`` and
    ``Jd`` by the initial-state corrections ``(m, 4)``, row ``i`` of ``Jd`` by those of the
    segment row ``i`` belongs to (zero on the prior's rows). The Jacobian is exact for the
    discretised model: every segment's simulation carries the sensitivities of its state
    through each RK4 step (:func:`_rk4_tangent`)."""
    nf = free_index.size
    # the model's coefficients by the fitted ones (_coefficients is affine)
    G = np.empty((index.size, nf))
    z0 = _coefficients(np.zeros(nf), free_index, ratio)
    for j in range(nf):
        e = np.zeros(nf)
        e[j] = 1.0
        G[:, j] = nominal * (_coefficients(e, free_index, ratio) - z0)
    P = P.copy()
    P[index] = nominal * (1.0 + _coefficients(p[:nf], free_index, ratio))
    r = np.empty(nf + 2 * Q.shape[0])
    Jt = np.zeros((r.size, nf))
    Jd = np.zeros((r.size, 4))
    r[:nf] = p[:nf] / prior
    for j in range(nf):
        Jt[j, j] = 1.0 / prior[j]
    x, S, D = np.empty(4), np.empty((_SENSITIVITIES, 4)), np.empty((4, 2, _SENSITIVITIES))
    h = dt / nsub
    for s in range(bounds.size - 1):
        a, b = bounds[s], bounds[s + 1]
        d = p[nf + 4 * s : nf + 4 * s + 4]
        x[0] = Q[a, 0] + d[0]
        x[1] = Q[a, 1] + d[1]
        x[2] = d[2]
        x[3] = d[3]
        S[:] = 0.0
        for i in range(4):
            S[i, i] = 1.0
        for k in range(b - a):
            row = nf + 2 * (a + k)
            r[row] = (x[0] - Q[a + k, 0]) / sig
            r[row + 1] = (x[1] - Q[a + k, 1]) / sig
            for i in range(2):
                for j in range(4):
                    Jd[row + i, j] = S[j, i] / sig
                for j in range(nf):
                    v = 0.0
                    for c in range(index.size):
                        v += S[4 + c, i] * G[c, j]
                    Jt[row + i, j] = v / sig
            if k == b - a - 1:
                break
            for _ in range(nsub):
                _rk4_tangent(P, x, S, U[a + k], h, D)
    return r, Jt, Jd


@njit(cache=True)
def _huber(r, c):  # pragma: no cover - compiled
    """The Huber cost ``0.5 sum c^2 rho((r / c)^2)`` (``rho(z) = z`` up to 1, ``2 sqrt(z) - 1``
    beyond), the weights of the gradient ``rho'`` and of the Gauss-Newton Hessian
    (``rho' + 2 rho'' z``: 0 beyond the threshold, floored at machine epsilon)."""
    n = r.size
    w_grad = np.ones(n)
    w_hess = np.ones(n)
    cost = 0.0
    for i in range(n):
        z = (r[i] / c) ** 2
        if z <= 1.0:
            cost += z
        else:
            cost += 2.0 * math.sqrt(z) - 1.0
            w_grad[i] = 1.0 / math.sqrt(z)
            w_hess[i] = _EPS
    return 0.5 * c * c * cost, w_grad, w_hess


@njit(cache=True)
def _normal_equations(r, Jt, Jd, w_grad, w_hess, bounds):  # pragma: no cover - compiled
    """The weighted Gauss-Newton system in blocks: ``A = Jt' W Jt`` ``(nf, nf)``, per segment
    ``B_s = Jt_s' W Jd_s`` ``(nf, 4)`` and ``C_s = Jd_s' W Jd_s`` ``(4, 4)``, and the gradient
    ``gt = Jt' rho' r``, ``gd_s = Jd_s' rho' r_s``."""
    nf, S = Jt.shape[1], bounds.size - 1
    WJt = Jt * w_hess[:, None]
    A = Jt.T @ WJt
    gt = Jt.T @ (w_grad * r)
    B = np.empty((S, nf, 4))
    C = np.empty((S, 4, 4))
    gd = np.empty((S, 4))
    for s in range(S):
        a, b = nf + 2 * bounds[s], nf + 2 * bounds[s + 1]
        Js = np.ascontiguousarray(Jd[a:b])
        B[s] = np.ascontiguousarray(WJt[a:b]).T @ Js
        C[s] = Js.T @ (Js * w_hess[a:b][:, None])
        gd[s] = Js.T @ (w_grad[a:b] * r[a:b])
    return A, B, C, gt, gd


def _fit_huber(
    p0: np.ndarray, scale: np.ndarray, args: tuple, max_iter: int = 100, tol: float = 1e-8
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on the Huber cost of the residuals of :func:`_jacobian` (scale
    ``ROBUST_SCALE``) from ``p0``, ``scale`` the typical sizes of the unknowns (the convergence
    tests', and the floor of the damping, which is Marquardt's: the Hessian's diagonal). Stops
    when the cost falls by less than ``tol`` relatively, the step is below ``tol`` relative to
    the point, or the scaled gradient below ``tol``. Each trial point is linearised with its
    residuals (nearly every one is taken). Returns the point, its residuals and the undamped
    blocks ``A, B, C`` of its Gauss-Newton Hessian (:func:`_normal_equations`)."""
    nf = args[3].size
    bounds = args[8]
    x = p0.copy()

    def linearise(lin: tuple, huber: tuple) -> tuple:
        # iteratively reweighted: the Hessian's weights are the gradient's (a residual beyond
        # the Huber threshold keeps its curvature, scaled down), which keeps the steps sane
        # where the start explains a segment badly
        cost, wg, wh = huber
        return (cost, *_normal_equations(*lin, wg, wg, bounds), lin, wg, wh)

    lin = _jacobian(x, *args)
    cost, A, B, C, gt, gd, lin, wg, wh = linearise(lin, _huber(lin[0], ROBUST_SCALE))
    mu = 1e-3
    nu = 2.0
    for _ in range(max_iter):
        g = np.concatenate([gt, gd.ravel()])
        if np.max(np.abs(g * scale)) < tol:
            break
        # Marquardt's damping: mu times the Hessian's diagonal (floored by the scales')
        d_t = np.maximum(np.diag(A), 1e-6 * scale[:nf] ** -2.0)
        d_d = np.maximum(np.einsum("sii->si", C), 1e-6 * np.asarray(_INIT_SCALE) ** -2.0)
        d = np.concatenate([d_t, d_d.ravel()])
        step_t, step_d = _schur_step(A, B, C, gt, gd, mu, d_t, d_d)
        step = np.concatenate([step_t, step_d.ravel()])
        if np.linalg.norm(step / scale) <= tol * (tol + np.linalg.norm(x / scale)):
            break
        trial = x + step
        lin_new = _jacobian(trial, *args)
        huber = _huber(lin_new[0], ROBUST_SCALE)
        cost_new = huber[0]
        predicted = 0.5 * float(step @ (mu * d * step - g))
        gain = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if math.isfinite(cost_new) and gain > 0:
            x, fell = trial, cost - cost_new
            cost, A, B, C, gt, gd, lin, wg, wh = linearise(lin_new, huber)
            mu *= 0.1 if gain > 0.75 else (1.0 if gain > 0.25 else 2.0)
            nu = 2.0
            if fell < tol * cost:
                break
        else:
            mu *= nu
            nu *= 2.0
    # the covariance's blocks: the Gauss-Newton Hessian of the Huber cost (no curvature beyond
    # the threshold)
    A, B, C = _normal_equations(*lin, wg, wh, bounds)[:3]
    return x, lin[0], A, B, C


@njit(cache=True)
def _schur_step(A, B, C, gt, gd, mu, dt_, dd_):  # pragma: no cover - compiled
    """The Levenberg-Marquardt step of the block system (``H + mu diag(D)``, ``D = dt_`` on the
    coefficients and ``dd_[s]`` on segment ``s``'s initial state), the segments eliminated by
    their Schur complement; returns the steps of the coefficients ``(nf,)`` and of the
    segments ``(S, 4)``."""
    S = B.shape[0]
    M = A + mu * np.diag(dt_)
    rhs = -gt.copy()
    Cinv = np.empty((S, 4, 4))
    for s in range(S):
        Cinv[s] = np.linalg.inv(C[s] + mu * np.diag(dd_[s]))
        BC = B[s] @ Cinv[s]
        M -= BC @ B[s].T
        rhs += BC @ gd[s]
    step_t = np.linalg.solve(M, rhs)
    step_d = np.empty((S, 4))
    for s in range(S):
        step_d[s] = Cinv[s] @ (-gd[s] - B[s].T @ step_t)
    return step_t, step_d


@dataclass(frozen=True)
class IdentifiedModel:
    """One fit of :class:`SwingIdentifier`.

    Attributes:
        theta: ``(p1, p2, p3, p4, p5, Fc, Fv)`` in the nominal input's scale (SI units).
        relative: ``theta / nominal - 1`` per coefficient.
        sigma: posterior standard deviation of ``relative`` per coefficient (with
            :data:`SD_FLOOR` added in quadrature).
        segments: segments fitted.
        rms: root-mean-square angle residual [rad].
        distance2: squared Mahalanobis distance of the fitted coefficients (all but ``p2``)
            from the nominal ones under their posterior covariance plus :data:`SD_FLOOR`
            squared (about chi-square with 6 degrees of freedom when the robot is the nominal
            one).
        long: fitted on the long segments (``SwingIdentifier.long_segment``), else on the
            short ones.
    """

    theta: np.ndarray
    relative: np.ndarray
    sigma: np.ndarray
    segments: int
    rms: float
    distance2: float
    long: bool = False

    @property
    def significant(self) -> bool:
        """Whether the data reject the nominal coefficients at the 1 % level
        (``distance2`` above the 99th percentile of chi-square with 6 degrees of freedom)."""
        return self.distance2 > CHI2_99


@dataclass
class _Shooting:
    """The stances cut into shooting segments of ``samples`` samples: each segment's angles
    and inputs, and its last fitted initial-state correction (None before its first fit)."""

    samples: int
    segments: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    x0: list[np.ndarray | None] = field(default_factory=list)

    def add(self, q: np.ndarray, u: np.ndarray) -> int:
        """Cut one stance (validated ``q`` (n, 2), ``u`` (n,)) into segments; returns how
        many were added (a segment shorter than the minimum is dropped, a short tail joins the
        last one)."""
        n, w = q.shape[0], self.samples
        added = 0
        for a in range(0, n, w):
            b = min(a + w, n)
            if n - b < w // 2:
                b = n
            if b - a >= _MIN_SAMPLES:
                self.segments.append((q[a:b].copy(), u[a:b].copy()))
                self.x0.append(None)
                added += 1
            if b == n:
                break
        return added


class SwingIdentifier:
    """Identifies the swing-phase coefficients from stances of measured angles and inputs.

    Every stance is cut into short segments (``segment``), which a push costs one segment of
    data, and into long ones (``long_segment``), which see the level of ``p3`` and
    ``p5`` (the stance leg's inertia and gravity) that short ones barely do. The fit on the
    long segments is then the one returned where the short segments' fit rejects the nominal
    model and each long segment is explained to :data:`EXPLAINED_RMS` (no push seen);
    otherwise the fit on the short ones.

    Args:
        robot: the nominal robot (the prior's centre, and the input gain kept).
        dt: sample period [s], > 0.
        angle_sigma: standard deviation of a measured angle [rad] (encoder noise and
            quantisation), > 0.
        segment: length of a short shooting segment [s], > 0.
        long_segment: length of a long shooting segment [s], >= 0 (default
            :data:`DEFAULT_LONG_SEGMENT`; 0: short segments only).
        prior: prior standard deviations relative to the nominal coefficients (7 numbers > 0;
            :data:`PRIOR`), of the fit on the short segments.
        long_prior: the same for the fit on the long segments (:data:`LONG_PRIOR`).
        substeps: RK4 substeps per sample interval, >= 1.

    Attributes:
        leg_length: the leg length [m] the fit assumes (``p2`` follows ``p4`` with it; the
            nominal one unless set, e.g. from the localisation).
    """

    def __init__(
        self,
        robot: RobotParams,
        dt: float,
        angle_sigma: float,
        segment: float = 0.15,
        long_segment: float = DEFAULT_LONG_SEGMENT,
        prior: tuple[float, ...] = PRIOR,
        long_prior: tuple[float, ...] = LONG_PRIOR,
        substeps: int = 2,
    ) -> None:
        for name, v in (("dt", dt), ("angle_sigma", angle_sigma), ("segment", segment)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"identification {name} = {v!r}; allowed: > 0")
        if not (math.isfinite(long_segment) and long_segment >= 0):
            raise ValueError(
                f"identification long_segment = {long_segment!r}; allowed: >= 0 (0: off)"
            )
        priors = []
        for name, v in (("prior", prior), ("long_prior", long_prior)):
            p = np.asarray(v, dtype=np.float64)
            if p.shape != (len(COEFFICIENTS),) or not np.all(np.isfinite(p) & (p > 0)):
                raise ValueError(f"identification {name} = {v!r}; allowed: 7 numbers > 0")
            priors.append(p)
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"identification substeps = {substeps!r}; allowed: integer >= 1")
        self.robot = robot
        self.P = robot.vector()
        self.nominal = self.P[_INDEX].copy()
        self.dt = float(dt)
        self.angle_sigma = float(angle_sigma)
        self.samples = max(_MIN_SAMPLES, round(segment / dt))
        self.long_samples = max(_MIN_SAMPLES, round(long_segment / dt)) if long_segment else 0
        self.prior, self.long_prior = priors
        self.substeps = int(substeps)
        self.leg_length = robot.l
        self.reset()

    def reset(self) -> None:
        """Forget the data (a new episode)."""
        self._short = _Shooting(self.samples)
        self._long = _Shooting(self.long_samples) if self.long_samples else None
        self._z = np.zeros(len(COEFFICIENTS))

    @property
    def segments(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The short segments so far: ``(angles (n, 2), inputs (n,))`` each."""
        return self._short.segments

    def add_stance(self, q: np.ndarray, u: np.ndarray) -> int:
        """Add one stance: measured angles ``q`` (n, 2) [rad] at consecutive samples and the
        inputs ``u`` (n,) [input units], ``u[k]`` held from sample ``k`` to ``k + 1`` (the
        last one unused). Returns the short segments added."""
        q = np.asarray(q, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64).reshape(-1)
        if q.ndim != 2 or q.shape[1] != 2 or u.shape != (q.shape[0],):
            raise ValueError(f"stance: q must be (n, 2) and u (n,), got {q.shape} and {u.shape}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(u))):
            raise ValueError("stance: angles and inputs must be finite")
        if self._long is not None:
            self._long.add(q, u)
        return self._short.add(q, u)

    def _initial_states(self, split: _Shooting, which: list[int]) -> np.ndarray:
        """Starting guesses of the segments' initial corrections: the last fit's, else rates
        from a line through a new segment's first samples."""
        x0 = np.zeros((len(which), 4))
        for i, j in enumerate(which):
            if split.x0[j] is not None:
                x0[i] = split.x0[j]
                continue
            q = split.segments[j][0]
            k = min(6, q.shape[0])
            x0[i, 2:] = np.polyfit(np.arange(k) * self.dt, q[:k], 1)[0]
        return x0

    @one_blas_thread
    def fit(self) -> IdentifiedModel | None:
        """The coefficients that best explain the segments so far (None without data).

        On the short segments, those the fitted model still cannot explain (root-mean-square
        residual above :data:`OUTLIER_RMS` standard deviations: a push, a scuff) are left out
        and the fit is repeated without them; :attr:`IdentifiedModel.segments` counts those
        kept. The fit on the long segments (from the nominal coefficients) replaces it where
        that fit is significant (the data reject the nominal model) and every long segment is
        explained to :data:`EXPLAINED_RMS`."""
        if not self._short.segments:
            return None
        first = self._fit(self._short, list(range(len(self._short.segments))), self._z, self.prior)
        if first is None:
            return None
        fit, rms = first
        keep = [i for i, r in enumerate(rms) if r <= OUTLIER_RMS]
        if keep and len(keep) < len(rms):
            again = self._fit(self._short, keep, self._z, self.prior)
            if again is not None:
                fit = again[0]
        self._z = fit.relative.copy()  # the next short fit starts here, never at a long fit
        if self._long is not None and self._long.segments and fit.significant:
            every = list(range(len(self._long.segments)))
            long = self._fit(self._long, every, np.zeros(len(COEFFICIENTS)), self.long_prior)
            if long is not None and np.all(long[1] <= EXPLAINED_RMS):
                fit = dataclasses.replace(long[0], long=True)
        return fit

    def _problem(
        self, split: _Shooting, which: list[int], z0: np.ndarray, prior: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, tuple]:
        """The fit to the segments ``which`` of ``split`` from the relative coefficients ``z0``
        under ``prior`` (7 relative standard deviations) as ``(p0, scale, args)``: the starting
        point (coefficients, then each segment's initial-state correction), the unknowns' typical
        sizes and the arguments of :func:`_jacobian` after the point."""
        segments = [split.segments[i] for i in which]
        Q = np.ascontiguousarray(np.concatenate([q for q, _ in segments]))
        U = np.ascontiguousarray(np.concatenate([u for _, u in segments]))
        bounds = np.cumsum([0] + [q.shape[0] for q, _ in segments])
        prior = prior[_FREE]
        ratio = self.leg_length / self.robot.l
        args = (self.P.copy(), _INDEX, self.nominal, _FREE, ratio, prior, Q, U, bounds)
        args += (self.dt, self.substeps, self.angle_sigma)
        p0 = np.concatenate([z0[_FREE], self._initial_states(split, which).ravel()])
        scale = np.concatenate([prior, np.tile(_INIT_SCALE, len(segments))])
        return p0, scale, args

    def _fit(
        self, split: _Shooting, which: list[int], z0: np.ndarray, prior: np.ndarray
    ) -> tuple[IdentifiedModel, np.ndarray] | None:
        """The fit to the segments ``which`` of ``split`` from ``z0`` under ``prior``, and
        each one's rms residual [standard deviations]."""
        p0, scale, args = self._problem(split, which, z0, prior)
        nf, S, bounds = _FREE.size, len(which), args[8]
        nominal, prior, sig, ratio = self.nominal, args[5], self.angle_sigma, args[4]
        x, r, A, B, C = _fit_huber(p0, scale, args)
        free = x[:nf]
        try:
            # the coefficients' block of the inverse Gauss-Newton Hessian: the inverse of the
            # Schur complement of the segments' blocks
            M = A - sum(Bs @ np.linalg.solve(Cs, Bs.T) for Bs, Cs in zip(B, C))
            cov = np.linalg.inv(M) + np.diag(np.full(nf, SD_FLOOR**2))
            distance2 = float(free @ np.linalg.solve(cov, free))
            sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        except np.linalg.LinAlgError:
            sd, distance2 = prior.copy(), 0.0
        if not (np.all(np.isfinite(free)) and math.isfinite(distance2)):
            return None
        for i, j in enumerate(which):
            split.x0[j] = x[nf + 4 * i : nf + 4 * i + 4].copy()
        z = _coefficients(free, _FREE, ratio)
        sigma = np.empty(len(COEFFICIENTS))
        sigma[_FREE] = sd
        sigma[1] = sigma[3] * ratio
        r = r[nf:]
        rms = np.array(
            [np.sqrt(np.mean(r[2 * a : 2 * b] ** 2)) for a, b in zip(bounds, bounds[1:])]
        )
        fit = IdentifiedModel(
            theta=nominal * (1.0 + z),
            relative=z,
            sigma=sigma,
            segments=S,
            rms=float(np.sqrt(np.mean(r * r))) * sig if r.size else 0.0,
            distance2=distance2,
        )
        return fit, rms


@one_blas_thread
def robot_from_coefficients(
    nominal: RobotParams,
    theta: np.ndarray,
    l: float | None = None,  # noqa: E741
) -> RobotParams:
    """The robot nearest to ``nominal`` (smallest relative change of ``m, mH, mHg, Ic, lc``)
    whose swing coefficients (:meth:`RobotParams.coefficients`) are ``theta[:5]``, with hip
    friction ``theta[5:7]`` and leg length ``l`` [m] (default: the nominal one); the input
    gain stays the nominal one (``theta`` is in its scale).

    Where ``theta`` is inconsistent with ``l`` (``p2 / p4 = l / g`` for every robot) the
    coefficients are matched in the least-squares sense.

    Raises:
        ValueError: no valid robot is near (the message says which parameter).
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.shape != (len(COEFFICIENTS),) or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta must be {len(COEFFICIENTS)} finite numbers")
    l = nominal.l if l is None else float(l)  # noqa: E741
    names = ("m", "mH", "mHg", "Ic", "lc")
    x_nom = np.array([getattr(nominal, k) for k in names])
    x_scale = np.abs(x_nom) + 1e-9
    base = nominal.replace(l=l, lc=min(nominal.lc * l / nominal.l, l))
    target = theta[:5]
    t_scale = np.abs(target) + 1e-12
    keys = ("p1", "p2", "p3", "p4", "p5")

    def robot(x: np.ndarray) -> RobotParams:
        return base.replace(**dict(zip(names, x)))

    def residuals(x: np.ndarray) -> np.ndarray:
        try:
            c = robot(x).coefficients()
        except ValueError:
            return np.full(10, 1e3)
        coef = np.array([c[k] for k in keys])
        return np.concatenate([1e3 * (coef - target) / t_scale, (x - x_nom) / x_scale])

    x0 = np.array([getattr(base, k) for k in names])
    res = least_squares(residuals, x0, x_scale=x_scale)
    return robot(res.x).replace(Fc=max(float(theta[5]), 0.0), Fv=max(float(theta[6]), 0.0))
