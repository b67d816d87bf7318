"""A compiled SQP for the step problems: one numba call runs a whole solve.

SLSQP driven from Python (:mod:`.slsqp`) pays, at every iteration, a QP routine whose cost grows
with the number of constraints (about 0.1 ms for a pair's 118), a typed dispatch into the
compiled step kernel (about 25 us a call) and the Python between them. This module runs the
same kind of method inside one compiled loop that calls the kernel directly:

- the structure of Kraft's SLSQP: a quasi-Newton (BFGS, Powell's damping) model of the
  Lagrangian, a QP subproblem on the linearised constraints, a line search on the L1 merit
  function with Powell's penalty update, and the same convergence test (cost change or step
  below ``ftol`` with the constraints met to ``ftol``);
- the QP solved as SLSQP does, as a least-distance problem by Lawson and Hanson's
  non-negative least squares; where the linearised constraints are inconsistent, an elastic
  QP (one more variable relaxing every constraint, at a high quadratic price);
- forward-difference Jacobians, as :class:`.problem.BatchProblem` takes them, evaluated only
  at the points the line search accepts;
- in the coordinates of the cost's Gauss-Newton model (:meth:`BatchProblem.scaling`), where
  the identity is a good first Hessian.

Every row of the kernel evaluated is counted, and the solve stops where the count reaches its
budget. The early end of runs that stall (``_STALL_*`` of :mod:`.problem`) is the same rule.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import kernel

__all__ = ["SQP_STATUS", "sqp_solve"]

_jit = njit(cache=True, error_model="numpy")

#: what :func:`sqp_solve`'s status means
SQP_STATUS = {
    0: "converged",
    1: "iteration limit",
    2: "evaluation budget spent",
    3: "line search failed",
    4: "QP failed",
    5: "stalled",
    6: "no descent direction",
}

_ELASTIC = 1e6  # price of the elastic variable (relative to the scaled cost's unit Hessian)
_FD_STEP = math.sqrt(np.finfo(np.float64).eps)
_ARMIJO = 0.1  # sufficient decrease of the merit function, fraction of its derivative
_LINE_TRIALS = 10  # line-search points per iteration
_RESETS = 5  # fresh quasi-Newton models a solve may start where the line search fails


# ---------------------------------------------------------------------------- QP
@_jit
def _least_squares(E, idx, f):
    """``z`` minimising ``|E[:, idx] z - f|`` by Householder QR (a few columns of a few rows;
    a column dependent on the earlier ones gets 0)."""
    p, q = E.shape[0], idx.size
    M = np.empty((p, q))
    for i in range(p):
        for j in range(q):
            M[i, j] = E[i, idx[j]]
    b = f.copy()
    scale = 0.0
    for i in range(p):
        for j in range(q):
            scale = max(scale, abs(M[i, j]))
    tol = 1e-13 * max(scale, 1e-300)
    rank = np.ones(q, dtype=np.bool_)
    for j in range(min(q, p)):
        norm = 0.0
        for i in range(j, p):
            norm += M[i, j] * M[i, j]
        norm = math.sqrt(norm)
        if norm <= tol:
            rank[j] = False
            continue
        alpha = -norm if M[j, j] >= 0.0 else norm
        v0 = M[j, j] - alpha
        # v = (v0, M[j+1:, j]); H = I - 2 v v' / v'v
        vv = v0 * v0
        for i in range(j + 1, p):
            vv += M[i, j] * M[i, j]
        if vv == 0.0:
            M[j, j] = alpha
            continue
        for k in range(j + 1, q):
            t = v0 * M[j, k]
            for i in range(j + 1, p):
                t += M[i, j] * M[i, k]
            t = 2.0 * t / vv
            M[j, k] -= t * v0
            for i in range(j + 1, p):
                M[i, k] -= t * M[i, j]
        t = v0 * b[j]
        for i in range(j + 1, p):
            t += M[i, j] * b[i]
        t = 2.0 * t / vv
        b[j] -= t * v0
        for i in range(j + 1, p):
            b[i] -= t * M[i, j]
        M[j, j] = alpha
    z = np.zeros(q)
    for j in range(min(q, p) - 1, -1, -1):
        if not rank[j] or abs(M[j, j]) <= tol:
            continue
        t = b[j]
        for k in range(j + 1, min(q, p)):
            t -= M[j, k] * z[k]
        z[j] = t / M[j, j]
    return z


@_jit
def _nnls(E, f, max_iter):
    """Lawson and Hanson's non-negative least squares: ``u >= 0`` minimising ``|E u - f|``
    (``E``: ``(p, q)``); returns ``(u, ok)`` (``ok`` False: the iteration limit)."""
    p, q = E.shape
    u = np.zeros(q)
    passive = np.zeros(q, dtype=np.bool_)
    r = f.copy()
    w = E.T @ r
    tol = 1e-12 * max(1.0, np.max(np.abs(E)))
    it = 0
    while True:
        t, wmax = -1, tol
        for j in range(q):
            if not passive[j] and w[j] > wmax:
                t, wmax = j, w[j]
        if t < 0:
            return u, True
        passive[t] = True
        while True:
            it += 1
            if it > max_iter:
                return u, False
            idx = np.nonzero(passive)[0]
            z_p = _least_squares(E, idx, f)
            if np.all(z_p > 0.0):
                u[:] = 0.0
                u[idx] = z_p
                break
            alpha = 1.0
            for i in range(idx.size):
                j = idx[i]
                if z_p[i] <= 0.0:
                    a = u[j] / (u[j] - z_p[i])
                    if a < alpha:
                        alpha = a
            for i in range(idx.size):
                j = idx[i]
                u[j] += alpha * (z_p[i] - u[j])
                if u[j] <= 1e-15:
                    u[j] = 0.0
                    passive[j] = False
            if not np.any(passive):
                break
        r = f - E @ u
        w = E.T @ r


@_jit
def _ldp(G, h):
    """The least-distance problem: ``x`` minimising ``|x|`` subject to ``G x >= h`` (``G``:
    ``(m, n)``), with the constraints' multipliers (for ``|x|^2 / 2``); ``ok`` False where the
    constraints are inconsistent or the solver failed."""
    m, n = G.shape
    E = np.empty((n + 1, m))
    E[:n, :] = G.T
    E[n, :] = h
    f = np.zeros(n + 1)
    f[n] = 1.0
    u, ok = _nnls(E, f, 3 * (m + n + 1))
    r = E @ u - f
    den = -r[n]
    x = np.zeros(n)
    lam = np.zeros(m)
    if not ok or not den > 1e-12 or not np.all(np.isfinite(r)):
        return x, lam, False
    for i in range(n):
        x[i] = r[i] / den
    for i in range(m):
        lam[i] = u[i] / den
    return x, lam, True


@_jit
def _cholesky(B):
    """The lower Cholesky factor of ``B`` and whether ``B`` is (numerically) positive
    definite."""
    n = B.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = B[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 1e-14 * max(1.0, abs(B[j, j])):
            return L, False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            t = B[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    return L, True


@_jit
def _qp(B, g, A, c):
    """The step ``d`` minimising ``d' B d / 2 + g' d`` subject to ``A d + c >= 0`` and its
    multipliers, as a least-distance problem on the Cholesky factor of ``B``; ``ok`` False if
    the linearised constraints are inconsistent."""
    n = g.size
    L, ok = _cholesky(B)
    if not ok:
        return np.zeros(n), np.zeros(c.size), False
    Linv = np.linalg.inv(L)  # n <= 8
    Binv_g = Linv.T @ (Linv @ g)
    G = A @ Linv.T  # (m, n): A L^-T
    h = A @ Binv_g - c
    e, lam, ok = _ldp(G, h)
    d = Linv.T @ e - Binv_g
    if not ok:
        return np.zeros(n), lam, False
    return d, lam, True


@_jit
def _elastic_qp(B, g, A, c):
    """:func:`_qp` with one more variable ``t >= 0`` relaxing every constraint (``A d + c + t
    >= 0``) at the cost ``_ELASTIC t^2 / 2``: always consistent; the step, the multipliers of
    the original constraints and ``t``."""
    m, n = A.shape
    B2 = np.zeros((n + 1, n + 1))
    B2[:n, :n] = B
    B2[n, n] = _ELASTIC
    g2 = np.zeros(n + 1)
    g2[:n] = g
    A2 = np.zeros((m + 1, n + 1))
    A2[:m, :n] = A
    A2[:m, n] = 1.0
    A2[m, n] = 1.0
    c2 = np.zeros(m + 1)
    c2[:m] = c
    d2, lam2, ok = _qp(B2, g2, A2, c2)
    return d2[:n], lam2[:m], ok


# ---------------------------------------------------------------------------- evaluations
@_jit
def _values(P, X, k1, common, first, second, pair):
    """Costs and packed constraints of the rows ``X`` (a step, or with ``pair`` a step and the
    next one)."""
    if pair:
        return kernel.pair_values(P, X, k1, common, first, second)
    return kernel.step_values(P, X, common, first)


@_jit
def _violation(c):
    """Sum of the negative constraints' magnitudes (``inf`` past overflow)."""
    s = 0.0
    for v in c:
        if v < 0.0:
            s -= v
    return s


@_jit
def _clipped(v):
    if v != v:
        return 0.0
    return min(max(v, -1e12), 1e12)


# ---------------------------------------------------------------------------- solve
@_jit
def sqp_solve(P, x0, T, k1, common, first, second, pair, maxiter, ftol, stall, budget, stall_rule):
    """Minimise a step problem's cost subject to its packed constraints ``>= 0`` from ``x0``.

    Args:
        P: robot parameter vector.
        x0: starting free coefficients ``(k,)`` [rad].
        T: ``x = x0 + T z``: the coordinates the solve works in (``(k, k)``; the identity for
            none).
        k1, common, first, second: the kernel's arguments (:func:`kernel.pair_values`; for a
            step alone, ``second`` is ``first`` and ``pair`` False).
        pair: a step and the next one (``True``) or one step.
        maxiter: iteration limit (QP subproblems).
        ftol: accuracy: the cost's change or the step's length, and the constraint violation.
        stall: end a run that stops making progress towards feasibility
            (``stall_rule = (iterations, window, gain, violation)``: see :mod:`.problem`).
        budget: kernel rows the solve may evaluate.

    Returns:
        ``(x, rows, status, iterations)``: the final point (the last accepted), the rows
        evaluated, :data:`SQP_STATUS`'s code and the iterations run.
    """
    n = x0.size
    s_iter, s_window, s_gain, s_viol = stall_rule
    rows = 0
    # the point and its forward-difference neighbours, in z = 0 .. e_i h_i
    Z = np.zeros((n + 1, n))
    X = np.empty((n + 1, n))
    for r in range(n + 1):
        X[r] = x0 + T @ Z[r]
    z = np.zeros(n)
    if rows + 1 > budget:
        return x0.copy(), rows, 2, 0
    cost, g = _values(P, X[:1], k1, common, first, second, pair)
    rows += 1
    f = cost[0]
    c = g[0].copy()
    m = c.size
    B = np.eye(n)
    pen = np.zeros(m)
    hist = np.empty(maxiter + 1)
    grad = np.zeros(n)
    A = np.zeros((m, n))
    lam = np.zeros(m)
    status, it, resets = 1, 0, 0
    need_jac = True
    gl_old = np.zeros(n)
    s_step = np.zeros(n)
    while it < maxiter:
        if need_jac:
            if rows + n > budget:
                status = 2
                break
            for i in range(n):
                Z[i + 1] = z
                Z[i + 1, i] += _FD_STEP
            for r in range(1, n + 1):
                X[r] = x0 + T @ Z[r]
            cf, gf = _values(P, X[1:], k1, common, first, second, pair)
            rows += n
            for i in range(n):
                h = Z[i + 1, i] - z[i]
                grad[i] = _clipped((cf[i] - f) / h)
                for j in range(m):
                    A[j, i] = _clipped((gf[i, j] - c[j]) / h)
            need_jac = False
        it += 1
        d, lam, ok = _qp(B, grad, A, c)
        if not ok:
            d, lam, ok = _elastic_qp(B, grad, A, c)
        if not ok and not np.all(B == np.eye(n)):  # a degenerate model: start it afresh
            B = np.eye(n)
            d, lam, ok = _qp(B, grad, A, c)
            if not ok:
                d, lam, ok = _elastic_qp(B, grad, A, c)
        if not ok:
            status = 4
            break
        viol = _violation(c)
        dn = math.sqrt(np.sum(d * d))
        if dn < ftol and viol < ftol:
            status = 0
            break
        # Powell's penalties and the merit function's slope along d
        for j in range(m):
            lj = abs(lam[j])
            pen[j] = max(lj, 0.5 * (pen[j] + lj))
        merit = f
        for j in range(m):
            if c[j] < 0.0:
                merit -= pen[j] * c[j]
        slope = np.dot(grad, d)
        for j in range(m):
            if c[j] < 0.0:
                slope += pen[j] * c[j]
        if not slope < 0.0:
            if viol < ftol:
                status = 0
                break
            if resets < _RESETS:  # SLSQP's remedy: the quasi-Newton model afresh
                resets += 1
                B = np.eye(n)
                continue
            status = 6
            break
        alpha = 1.0
        accepted = False
        for _ in range(_LINE_TRIALS):
            if rows + 1 > budget:
                break
            zt = z + alpha * d
            X[0] = x0 + T @ zt
            ct, gt = _values(P, X[:1], k1, common, first, second, pair)
            rows += 1
            ft = ct[0]
            mt = ft
            for j in range(m):
                if gt[0, j] < 0.0:
                    mt -= pen[j] * gt[0, j]
            if np.isfinite(mt) and mt - merit <= _ARMIJO * alpha * slope:
                accepted = True
                break
            dm = mt - merit - slope * alpha
            a_new = 0.1 * alpha
            if np.isfinite(dm) and dm > 0.0:
                a_new = max(0.1 * alpha, min(0.5 * alpha, -slope * alpha * alpha / (2.0 * dm)))
            alpha = a_new
        if not accepted:
            if rows + 1 > budget:
                status = 2
                break
            if resets < _RESETS:
                resets += 1
                B = np.eye(n)
                continue
            status = 3
            break
        # BFGS on the Lagrangian's gradient, Powell's damping (the new Jacobian first)
        for i in range(n):
            s_step[i] = alpha * d[i]
        gl_old[:] = grad - A.T @ lam
        f_old = f
        z = zt
        f = ft
        c[:] = gt[0]
        Z[0] = z
        viol = _violation(c)
        hist[it - 1] = viol
        if (abs(f - f_old) < ftol or math.sqrt(np.sum(s_step * s_step)) < ftol) and viol < ftol:
            status = 0
            break
        if rows + n > budget:
            status = 2
            break
        need_jac = True
        for i in range(n):
            Z[i + 1] = z
            Z[i + 1, i] += _FD_STEP
        for r in range(1, n + 1):
            X[r] = x0 + T @ Z[r]
        cf, gf = _values(P, X[1:], k1, common, first, second, pair)
        rows += n
        for i in range(n):
            h = Z[i + 1, i] - z[i]
            grad[i] = _clipped((cf[i] - f) / h)
            for j in range(m):
                A[j, i] = _clipped((gf[i, j] - c[j]) / h)
        need_jac = False
        y = grad - A.T @ lam - gl_old
        Bs = B @ s_step
        sBs = np.dot(s_step, Bs)
        sy = np.dot(s_step, y)
        if sBs > 0.0:
            if sy < 0.2 * sBs:
                theta = 0.8 * sBs / (sBs - sy)
                y = theta * y + (1.0 - theta) * Bs
                sy = np.dot(s_step, y)
            if sy > 0.0:
                B += np.outer(y, y) / sy - np.outer(Bs, Bs) / sBs
        if stall and it >= s_iter and viol > s_viol:
            w = int(s_window)
            recent = np.min(hist[it - w : it])
            earlier = np.min(hist[: it - w])
            if recent > s_gain * earlier:
                status = 5
                break
    return x0 + T @ z, rows, status, it
