"""A compiled SQP for the step problems: one numba call runs a whole solve.

SLSQP driven from Python (:mod:`.slsqp`) pays, at every iteration, a QP routine whose cost grows
with the number of constraints (about 0.1 ms for a pair's 118), a typed dispatch into the
compiled step kernel (about 25 us a call) and the Python between them. This module runs the
same kind of method inside one compiled loop that calls the kernel directly:

- the iteration of Kraft's SLSQP (SciPy's ``slsqp.c``): a quasi-Newton model of the
  Lagrangian kept as ``L D L'`` factors (BFGS with Powell's damping, Fletcher and Powell's
  updates), a QP on the linearised constraints, a line search on the L1 merit function with
  Powell's penalties that takes its eleventh point whatever it brings, SLSQP's convergence
  tests and its fresh models where no descent is left (five at most);
- the QP solved as SLSQP does, as a least-distance problem by Lawson and Hanson's
  non-negative least squares (stopped by their certificate alone: these problems amplify an
  early stop); where the linearised constraints are inconsistent, SLSQP's augmented QP (one
  more variable relaxing the violated constraints in proportion);
- forward-difference Jacobians, as :class:`.problem.BatchProblem` takes them, evaluated only
  at the points the line search accepts;
- in the coordinates of the cost's Gauss-Newton model (:meth:`BatchProblem.scaling`), where
  the identity is a good first Hessian.

Every row of the kernel evaluated is counted, and the solve stops where the count reaches its
budget. The early end of runs that stall (``_STALL_*`` of :mod:`.problem`) is the same rule.
Beyond SLSQP, a model whose factors fail SLSQP's test is started afresh once more. On 1,602
step problems met on validation courses at difficulty 2 and 3, SLSQP ends feasible on 10
that this solve does not, this solve on 4 that SLSQP does not, the other 1,588 end alike; it
spends about half the kernel rows and half the time.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import kernel

__all__ = ["FD_STEP", "SQP_STATUS", "fd_points", "fd_quotients", "sqp_solve"]

_jit = njit(cache=True, error_model="numpy")

#: what :func:`sqp_solve`'s status means
SQP_STATUS = {
    0: "converged",
    1: "iteration limit",
    2: "evaluation budget spent",
    3: "the line search's point broke the model (a cost not finite)",
    4: "QP failed",
    5: "stalled",
    6: "no descent direction",
}

_AUGMENT = 100.0  # SLSQP's first weight of the augmented variable (x 10 per retry, 5 retries)
_EPS = float(np.finfo(np.float64).eps)
#: forward-difference step of the Jacobians (the solves' and :class:`.problem.BatchProblem`'s)
FD_STEP = math.sqrt(_EPS)
_ARMIJO = 0.1  # sufficient decrease of the merit function, fraction of its slope
_LINE_TRIALS = 10  # a line search accepts its point after this many shortened ones
_ALPHA_MIN = 0.1  # least shortening of a line search's step
_RESETS = 5  # quasi-Newton models a solve may start (the first included)
NO_START = np.empty(0)  # sqp_solve's start rows not given
NO_START_G = np.empty((0, 0))


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
    (``E``: ``(p, q)``); returns ``(u, ok)`` (``ok`` False: the iteration limit). Stops where
    no dual component is positive (their KKT certificate, no tolerance: the least-distance
    problems built on it amplify an early stop); a column dependent on the chosen ones, or
    whose coefficient would not come out positive, is passed over, as in their algorithm."""
    p, q = E.shape
    u = np.zeros(q)
    passive = np.zeros(q, dtype=np.bool_)
    order = np.empty(q, dtype=np.int64)  # the chosen columns, in the order chosen
    k = 0
    it = 0
    while k < min(p, q):
        w = E.T @ (f - E @ u)
        while True:
            t, wmax = -1, 0.0
            for j in range(q):
                if not passive[j] and w[j] > wmax:
                    t, wmax = j, w[j]
            if t < 0:
                return u, True
            order[k] = t
            z = _least_squares(E, order[: k + 1], f)
            if z[k] > 0.0:
                break
            w[t] = 0.0  # dependent on the chosen columns, or round-off: not this one
        passive[t] = True
        k += 1
        while True:
            it += 1
            if it > max_iter:
                return u, False
            if np.all(z[:k] > 0.0):
                for i in range(k):
                    u[order[i]] = z[i]
                break
            alpha = 1.0
            for i in range(k):
                if z[i] <= 0.0:
                    j = order[i]
                    a = u[j] / (u[j] - z[i])
                    if a < alpha:
                        alpha = a
            kept = 0
            for i in range(k):
                j = order[i]
                u[j] += alpha * (z[i] - u[j])
                if u[j] <= 0.0:
                    u[j] = 0.0
                    passive[j] = False
                else:
                    order[kept] = j
                    kept += 1
            k = kept
            if k == 0:
                break
            z = _least_squares(E, order[:k], f)
    return u, True


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
def _ldl_update(L, D, z, sigma):
    """``L D L' + sigma z z'`` in place, for a unit lower triangular ``L`` and a positive
    ``D``: Fletcher and Powell's composite t-method (Math. Comp. 28, 1974), as SLSQP keeps its
    quasi-Newton model; a downdate that would lose positive definiteness is cut short to keep
    it (SLSQP's rule)."""
    n = D.size
    if sigma == 0.0:
        return
    w = z.copy()
    ts = np.empty(n)
    t = 1.0 / sigma
    if sigma < 0.0:  # the t's of a downdate, from L p = z, backwards
        p = z.copy()
        for i in range(n):
            for j in range(i):
                p[i] -= L[i, j] * p[j]
            t += p[i] * p[i] / D[i]
        if t >= 0.0:
            t = _EPS / sigma
        for i in range(n - 1, -1, -1):
            ts[i] = t
            t -= p[i] * p[i] / D[i]
    for i in range(n):
        v = w[i]
        delta = v / D[i]
        tp = ts[i] if sigma < 0.0 else t + delta * v
        alpha = tp / t
        D[i] *= alpha
        if i == n - 1:
            return
        beta = delta / tp
        if alpha <= 4.0:
            for j in range(i + 1, n):
                w[j] -= v * L[j, i]
                L[j, i] += beta * w[j]
        else:
            gamma = t / tp
            for j in range(i + 1, n):
                u = L[j, i]
                L[j, i] = gamma * u + beta * w[j]
                w[j] -= v * u
        t = tp


@_jit
def _factor(L, D):
    """The lower Cholesky factor ``L diag(sqrt(D))`` of ``L D L'``, and whether every pivot
    passes SLSQP's test (``sqrt(D_i) >= eps``)."""
    n = D.size
    C = np.zeros((n, n))
    for j in range(n):
        if not D[j] >= _EPS * _EPS:
            return C, False
        r = math.sqrt(D[j])
        for i in range(j, n):
            C[i, j] = L[i, j] * r
    return C, True


@_jit
def _qp(C, g, A, c):
    """The step ``d`` minimising ``d' B d / 2 + g' d`` subject to ``A d + c >= 0`` (``B = C
    C'``, ``C`` lower triangular) and its multipliers, as a least-distance problem; ``ok``
    False if the linearised constraints are inconsistent (or the solver failed)."""
    n = g.size
    Cinv = np.linalg.inv(C)  # n <= 8
    Binv_g = Cinv.T @ (Cinv @ g)
    G = A @ Cinv.T  # (m, n): A C^-T
    h = A @ Binv_g - c
    e, lam, ok = _ldp(G, h)
    if not ok:
        return np.zeros(n), lam, False
    return Cinv.T @ e - Binv_g, lam, True


@_jit
def _augmented_qp(C, g, A, c, rho):
    """SLSQP's QP for an inconsistent linearisation (Kraft, section 2.2.3): one more variable
    ``delta`` in [0, 1] relaxes each violated constraint in proportion to its violation (``A_i
    d + c_i + delta max(-c_i, 0) >= 0``; the constraints met stay as they are), at the cost
    ``(rho delta)^2 / 2`` (``C``: the Cholesky factor of the model). Returns the step, the
    original constraints' multipliers, ``delta`` and whether it was solved."""
    m, n = A.shape
    C2 = np.zeros((n + 1, n + 1))
    C2[:n, :n] = C
    C2[n, n] = rho
    g2 = np.zeros(n + 1)
    g2[:n] = g
    A2 = np.zeros((m + 2, n + 1))
    A2[:m, :n] = A
    c2 = np.zeros(m + 2)
    c2[:m] = c
    for i in range(m):
        A2[i, n] = max(-c[i], 0.0)
    A2[m, n] = 1.0  # delta >= 0
    A2[m + 1, n] = -1.0  # delta <= 1
    c2[m + 1] = 1.0
    d2, lam2, ok = _qp(C2, g2, A2, c2)
    return d2[:n], lam2[:m], d2[n], ok


@_jit
def _subproblem(L, D, g, A, c):
    """SLSQP's search direction for the model ``L D L'``: the QP, or where its linearised
    constraints are inconsistent the augmented QP with weights 100, 1,000, ... (six tries).
    Returns the step, the multipliers, the augmented variable, whether the QP was
    inconsistent, and whether a step was found."""
    C, ok = _factor(L, D)
    if not ok:
        return np.zeros(g.size), np.zeros(c.size), 0.0, False, False
    d, lam, ok = _qp(C, g, A, c)
    if ok:
        return d, lam, 0.0, False, True
    rho = _AUGMENT
    delta = 1.0
    for _ in range(6):
        d, lam, delta, ok = _augmented_qp(C, g, A, c, rho)
        if ok:
            break
        rho *= 10.0
    return d, lam, delta, True, ok


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
def fd_quotients(X, cost, g):
    """The forward-difference quotients of the costs ``(k + 1,)`` and constraints ``(k + 1,
    m)`` at the points ``X`` (a point, then its ``k`` neighbours one coordinate each, the steps
    as actually taken): the cost's gradient ``(k,)`` and the constraints' Jacobian transposed,
    ``(k, m)``. A point where the step model breaks down (NaN mapped to +-1e3) gives huge
    slopes: NaN becomes 0 and every slope is clipped to +-1e12."""
    k, m = X.shape[1], g.shape[1]
    dc = np.empty(k)
    dgt = np.empty((k, m))
    for i in range(k):
        h = X[1 + i, i] - X[0, i]
        dc[i] = _clipped((cost[1 + i] - cost[0]) / h)
        for j in range(m):
            dgt[i, j] = _clipped((g[1 + i, j] - g[0, j]) / h)
    return dc, dgt


@_jit
def _clipped(v):
    if v != v:
        return 0.0
    return min(max(v, -1e12), 1e12)


# ---------------------------------------------------------------------------- solve
@_jit
def _jacobian(P, x0, T, z, f, c, k1, common, first, second, pair, X, cost, g, grad, A):
    """The gradient and constraint Jacobian at ``z`` (cost ``f``, constraints ``c``) in ``z``:
    forward differences in the free coefficients ``x = x0 + T z`` (``n`` kernel rows;
    :func:`fd_quotients`, as :class:`.problem.BatchProblem` takes them), mapped through
    ``T``. ``X``, ``cost``, ``g``: work arrays of ``n + 1`` rows."""
    fd_points(x0 + T @ z, X)
    cf, gf = _values(P, X[1:], k1, common, first, second, pair)
    cost[0] = f
    cost[1:] = cf
    g[0] = c
    g[1:] = gf
    _mapped_quotients(X, cost, g, T, grad, A)


@_jit
def _mapped_quotients(X, cost, g, T, grad, A):
    """:func:`fd_quotients` of the rows ``X`` (a point in ``x`` and its forward-difference
    neighbours), mapped into ``z`` (``x = x0 + T z``): the gradient into ``grad``, the
    constraints' Jacobian into ``A``."""
    gx, Axt = fd_quotients(X, cost, g)
    grad[:] = T.T @ gx
    A[:, :] = np.ascontiguousarray(Axt.T) @ T


@_jit
def fd_points(x, X):
    """``x`` and its forward-difference neighbours, one coordinate each, into the rows of
    ``X`` (``(k + 1, k)``)."""
    for i in range(X.shape[0]):
        X[i] = x
    for i in range(x.size):
        X[1 + i, i] += FD_STEP


@_jit
def _merit_penalty(c, mu):
    """``sum mu_j max(-c_j, 0)``: the L1 merit function's penalty."""
    s = 0.0
    for j in range(c.size):
        if c[j] < 0.0:
            s -= mu[j] * c[j]
    return s


@_jit
def sqp_solve(
    P, x0, T, k1, common, first, second, pair, maxiter, ftol, stall, budget, stall_rule,
    start_cost=NO_START, start_g=NO_START_G,
):  # fmt: skip
    """Minimise a step problem's cost subject to its packed constraints ``>= 0`` from ``x0``,
    with the iteration of Kraft's SLSQP (SciPy's ``slsqp.c``): its QP, its augmented QP where
    the linearisation is inconsistent, its L1 line search (which takes its eleventh point
    whatever it brings), its convergence tests and its resets of the quasi-Newton model.

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
        start_cost, start_g: the costs ``(k + 1,)`` and packed constraints ``(k + 1, m)`` at
            ``x0`` and its forward-difference points (:func:`fd_quotients`'s rows, the steps
            in ``x``), already evaluated (by the Gauss-Newton scaling): the solve's first
            Jacobian without evaluating them again. Empty (the default): evaluated here.

    Returns:
        ``(x, rows, status, iterations)``: the final point, the rows evaluated,
        :data:`SQP_STATUS`'s code and the iterations run.
    """
    n = x0.size
    s_iter, s_window, s_gain, s_viol = stall_rule
    given = start_cost.size == n + 1
    if budget < 1 + n and not given:
        return x0.copy(), 0, 2, 0
    if given:
        cost, g, rows = start_cost, start_g, 0
    else:
        cost, g = _values(P, x0.reshape(1, n), k1, common, first, second, pair)
        rows = 1
    f = cost[0]
    c = g[0].copy()
    m = c.size
    z = np.zeros(n)
    grad = np.zeros(n)
    A = np.zeros((m, n))
    X = np.empty((n + 1, n))
    cost_fd = np.empty(n + 1)
    g_fd = np.empty((n + 1, m))
    if given:  # the start's forward differences are among the rows given
        fd_points(x0, X)
        _mapped_quotients(X, start_cost, start_g, T, grad, A)
    else:
        _jacobian(P, x0, T, z, f, c, k1, common, first, second, pair, X, cost_fd, g_fd, grad, A)
        rows += n
    L = np.eye(n)
    D = np.ones(n)
    mu = np.zeros(m)
    hist = np.empty(maxiter + 1)
    xt = np.empty((1, n))
    status, it, resets = 1, 0, 1
    while True:
        if it >= maxiter:
            status = 1
            break
        it += 1
        viol = _violation(c)
        hist[it - 1] = viol
        if stall and it >= s_iter and viol > s_viol:
            w = int(s_window)
            if np.min(hist[it - w : it]) > s_gain * np.min(hist[: it - w]):
                status = 5
                break
        d, lam, delta, badlin, ok = _subproblem(L, D, grad, A, c)
        if not ok and resets < _RESETS:  # a degenerate model: afresh (beyond SLSQP)
            resets += 1
            L, D = np.eye(n), np.ones(n)
            d, lam, delta, badlin, ok = _subproblem(L, D, grad, A, c)
        if not ok:
            status = 4
            break
        h4 = 1.0 - delta if badlin else 1.0
        # SLSQP's KKT test, and Powell's penalties
        gs = np.dot(grad, d)
        h1 = abs(gs)
        for j in range(m):
            lj = abs(lam[j])
            mu[j] = max(lj, 0.5 * (mu[j] + lj))
            h1 += lj * abs(c[j])
        if h1 < ftol and viol < ftol and not badlin and f == f:
            status = 0
            break
        pen = _merit_penalty(c, mu)
        t0 = f + pen
        slope = gs - pen * h4
        if slope >= 0.0 or slope != slope:  # no descent: a fresh model
            resets += 1
            if resets > _RESETS:  # SLSQP's relaxed test
                status = 0 if viol < 10.0 * ftol and not badlin else 6
                break
            L, D = np.eye(n), np.ones(n)
            continue
        # line search on the L1 merit function
        step = d.copy()
        h3 = slope
        alpha = 1.0
        line = 0
        ft = f
        ct = c
        spent = False
        while True:
            line += 1
            h3 = alpha * h3
            step *= alpha
            if rows + 1 > budget:
                spent = True
                break
            xt[0] = x0 + T @ (z + step)
            cf, gf = _values(P, xt, k1, common, first, second, pair)
            rows += 1
            ft = cf[0]
            ct = gf[0]
            dm = ft + _merit_penalty(ct, mu) - t0
            if dm <= _ARMIJO * h3 or line > _LINE_TRIALS:
                break
            alpha = _ALPHA_MIN
            if h3 - dm != 0.0:
                q = h3 / (2.0 * (h3 - dm))
                if q == q and q > _ALPHA_MIN:
                    alpha = q
        if spent:
            status = 2
            break
        if not np.isfinite(ft):  # the model broke down at the point taken: stop before it
            status = 3
            break
        f_old = f
        z = z + step
        f = ft
        c = ct.copy()
        snorm = math.sqrt(np.sum(step * step))
        if (abs(f - f_old) < ftol or snorm < ftol) and _violation(c) < ftol and not badlin:
            status = 0
            break
        # BFGS on the Lagrangian's gradient with Powell's damping (the multipliers of the QP)
        gl_old = grad - A.T @ lam
        if rows + n > budget:
            status = 2
            break
        _jacobian(P, x0, T, z, f, c, k1, common, first, second, pair, X, cost_fd, g_fd, grad, A)
        rows += n
        y = grad - A.T @ lam - gl_old
        Bs = L @ (D * (L.T @ step))
        sy = np.dot(step, y)
        sBs = np.dot(step, Bs)
        if sy < 0.2 * sBs:
            theta = 0.8 * sBs / (sBs - sy)
            y = theta * y + (1.0 - theta) * Bs
            sy = 0.2 * sBs
        if sy == 0.0 or sBs == 0.0:
            resets += 1
            if resets > _RESETS:
                status = 6
                break
            L, D = np.eye(n), np.ones(n)
            continue
        _ldl_update(L, D, y, 1.0 / sy)
        _ldl_update(L, D, Bs, -1.0 / sBs)
    return x0 + T @ z, rows, status, it
