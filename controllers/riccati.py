"""Finite-horizon jump-Riccati equation of the receding-horizon controller (paper Section 4).

The linear impulsive system is a chain of smooth segments ``j = 0 .. S-1`` joined by jumps::

    dz/ds = A(s) z + B(s) v            inside segment j, s in [s_j, s_j + L_j]
    z(s_{j+1}+) = F_j z(s_j + L_j -)   between segment j and segment j+1

with cost ``int w(s) (z'Qz + v'Rv) ds + sum_j z(jump_j -)' Q_j z(jump_j -)`` and the terminal
constraint ``z(end) = 0``. The independent variable ``s`` is time in the paper; the transverse
controller uses the phase variable ``theta`` instead (then ``A, B`` are divided by the nominal
``theta_dot`` and ``w = 1/theta_dot``), which is why the weight ``w`` exists.

The equation is solved in inverse form, for ``Z`` the inverse of the usual Riccati matrix
(control notes, section 5), backwards::

    -dZ/ds = -Z A' - A Z + B (w R)^-1 B' - w Z Q Z,     Z(end) = 0,
    Z(jump_j -) = Q_j^-1 - Q_j^-1 F_j' (Z(jump_j +) + F_j Q_j^-1 F_j')^-1 F_j Q_j^-1,

the Woodbury form of ``(F_j' Z+^-1 F_j + Q_j)^-1``, valid where ``Z+`` is singular. Integrated
backwards the quadratic term only damps ``Z``, so there is no finite escape; the scheme is
classical RK4 on a fixed grid per segment, with ``A, B, w`` sampled at the grid nodes and the
midpoints (``2 n_j + 1`` samples per segment). The optimal feedback is
``v = K z`` with ``K = -(w R)^-1 B' Z^-1``; see :func:`solve_jump_riccati`.

The equation is stiff where the weights ask for a fast closed loop (a large ``Q`` against
``R``): its Jacobian at ``Z`` is ``dZ -> -(A + Z wQ) dZ - dZ (A + Z wQ)'``, whose rate is at
most ``2 |A| + 2 |Z wQ|``, and near its equilibrium ``Z* wQ Z* = G`` (``G = B (wR)^-1 B'``;
``Z`` settles onto it from 0 at the horizon's end) ``Z* wQ`` is a square root of ``G wQ``. So
``L = 2 |A| + 2 max(sqrt(|G wQ|), |Z wQ|)`` (Frobenius norms of the products: with ``Q`` large
on one coordinate and ``G`` along another the products are far below the products of the
norms), and RK4 is stable only for ``h L`` below about 2.8. A
grid interval with ``h L > STIFF_TRIGGER`` is cut into ``ceil(h L / STIFF_STEP)`` RK4 steps,
with ``A, G, wQ`` interpolated quadratically through the interval's three samples; the others
take one step, so solves that are not stiff are unchanged (the paper's weights reach ``h L``
of about 0.6 on a walk and 2.2 on a stalling one; ``Q = diag(1, 40000, 400)`` 4 and more on
every interval).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

_jit = njit(cache=True, error_model="numpy")

#: a grid interval with ``h L`` above this is substepped (``L`` the bound on the equation's rate,
#: module docstring; RK4 is stable below about 2.8) ...
STIFF_TRIGGER = 2.5
#: ... into RK4 steps of ``h L`` at most this
STIFF_STEP = 1.0


@_jit
def _rhs(Z, A, G, Qw, s, T, out, n):
    """``out = -Z A' - A Z + G - Z Qw Z`` (``G = B (wR)^-1 B'``, ``Qw = w Q``, all ``n x n``)
    with the samples ``s`` of ``A, G, Qw`` (indexed in place: views of them would add
    reference counting to every step); ``T`` scratch."""
    for i in range(n):  # T = Z Qw
        for k in range(n):
            acc = 0.0
            for m in range(n):
                acc += Z[i, m] * Qw[s, m, k]
            T[i, k] = acc
    for i in range(n):
        for k in range(i, n):
            az_ik = 0.0
            az_ki = 0.0
            zqz = 0.0
            for m in range(n):
                az_ik += A[s, i, m] * Z[m, k]
                az_ki += A[s, k, m] * Z[m, i]
                zqz += T[i, m] * Z[m, k]
            v = -az_ki - az_ik + G[s, i, k] - zqz
            out[i, k] = v
            out[k, i] = v


@_jit
def _spd_inverse(Z):
    """Inverse of a symmetric positive-definite matrix by Cholesky (raises if not SPD)."""
    n = Z.shape[0]
    L = np.linalg.cholesky(Z)
    Li = np.linalg.solve(L, np.eye(n))
    return Li.T @ Li


@_jit
def _frobenius(M):
    acc = 0.0
    for a in range(M.shape[0]):
        for b in range(M.shape[1]):
            acc += M[a, b] * M[a, b]
    return math.sqrt(acc)


@_jit
def _frobenius_product(X, Y, n):
    """``|X Y|`` (Frobenius) of two ``n x n`` matrices without forming the product."""
    acc = 0.0
    for a in range(n):
        for b in range(n):
            v = 0.0
            for m in range(n):
                v += X[a, m] * Y[m, b]
            acc += v * v
    return math.sqrt(acc)


@_jit
def _rate_terms(A, G, Qw, n):
    """Per sample, the parts of the rate bound that do not depend on ``Z`` (module
    docstring): ``2 |A|`` and ``sqrt(|G wQ|)``."""
    N = A.shape[0]
    out = np.empty((N, 2))
    for i in range(N):
        out[i, 0] = 2.0 * _frobenius(A[i])
        out[i, 1] = math.sqrt(_frobenius_product(G[i], Qw[i], n))
    return out


@_jit
def _rate_bound(Z, Qw, terms, i0, im, i1, n):
    """Bound ``L`` on the rate of the equation over one grid interval (module docstring)."""
    out = 0.0
    for i in (i0, im, i1):
        r = terms[i, 0] + 2.0 * max(terms[i, 1], _frobenius_product(Z, Qw[i], n))
        if r > out:
            out = r
    return out


@_jit
def _quadratic(X, i0, im, i1, tau, out, p, n):
    """``out[p]``: ``X`` (``n x n`` samples) at ``tau`` in [0, 1] of the interval, through its
    samples at 0, 1/2 and 1."""
    l0 = 2.0 * (tau - 0.5) * (tau - 1.0)
    lm = -4.0 * tau * (tau - 1.0)
    l1 = 2.0 * tau * (tau - 0.5)
    for a in range(n):
        for b in range(n):
            out[p, a, b] = l0 * X[i0, a, b] + lm * X[im, a, b] + l1 * X[i1, a, b]


@_jit
def _rk4_step(Z, A, G, Qw, s1, sm, s0, h, T, k1, k2, k3, k4, Zt, n):
    """One backward RK4 step of length ``h`` (``Z`` in place) with the equation's samples
    ``s1`` at the step's start (its larger ``s``), ``sm`` in the middle and ``s0`` at the end;
    the rest is scratch."""
    _rhs(Z, A, G, Qw, s1, T, k1, n)
    for a in range(n):
        for b in range(n):
            Zt[a, b] = Z[a, b] + 0.5 * h * k1[a, b]
    _rhs(Zt, A, G, Qw, sm, T, k2, n)
    for a in range(n):
        for b in range(n):
            Zt[a, b] = Z[a, b] + 0.5 * h * k2[a, b]
    _rhs(Zt, A, G, Qw, sm, T, k3, n)
    for a in range(n):
        for b in range(n):
            Zt[a, b] = Z[a, b] + h * k3[a, b]
    _rhs(Zt, A, G, Qw, s0, T, k4, n)
    for a in range(n):
        for b in range(n):
            Z[a, b] += (h / 6.0) * (k1[a, b] + 2.0 * k2[a, b] + 2.0 * k3[a, b] + k4[a, b])


@_jit
def _substeps(Z, A, G, Qw, i0, im, i1, h, m, T, k1, k2, k3, k4, Zt, As, Gs, Qs, n):
    """``m`` backward RK4 steps over one grid interval of length ``h`` (``Z`` in place), the
    equation interpolated quadratically through the interval's samples ``i0, im, i1`` into
    the scratch ``As, Gs, Qs`` (``(3, n, n)`` each)."""
    dt = 1.0 / m
    for r in range(m):
        tau = 1.0 - r * dt
        for p, t in enumerate((tau, tau - 0.5 * dt, tau - dt)):
            _quadratic(A, i0, im, i1, t, As, p, n)
            _quadratic(G, i0, im, i1, t, Gs, p, n)
            _quadratic(Qw, i0, im, i1, t, Qs, p, n)
        _rk4_step(Z, As, Gs, Qs, 0, 1, 2, h / m, T, k1, k2, k3, k4, Zt, n)


@_jit
def _solve_segments(A, G, Qw, ds, nsteps, offs, F, Qj_inv, Znodes, node_offs, n):
    """Backward RK4 over all segments of an ``n``-dimensional system; ``Znodes`` receives ``Z``
    at every grid node."""
    S = nsteps.shape[0]
    Z = np.zeros((n, n))
    k1 = np.empty((n, n))
    k2 = np.empty((n, n))
    k3 = np.empty((n, n))
    k4 = np.empty((n, n))
    Zt = np.empty((n, n))
    T = np.empty((n, n))
    As = np.empty((3, n, n))  # the substeps' interpolated samples
    Gs = np.empty((3, n, n))
    Qs = np.empty((3, n, n))
    terms = _rate_terms(A, G, Qw, n)
    for j in range(S - 1, -1, -1):
        if j < S - 1:
            # jump from the start of segment j+1 back to the end of segment j (Woodbury)
            Fj = F[j]
            Qi = Qj_inv[j]
            QiFt = Qi @ Fj.T
            Mj = Z + Fj @ QiFt
            # (Z+ + F Qi F')^-1 F Qi; a C-ordered right-hand side, like the other solve's, so
            # that one compiled solve serves both (the values are the same)
            X = np.linalg.solve(Mj, np.ascontiguousarray(QiFt.T))
            Z = Qi - QiFt @ X
            Z = 0.5 * (Z + Z.T)
            Z = np.ascontiguousarray(Z)
        nj = nsteps[j]
        h = ds[j]
        o = offs[j]
        no = node_offs[j]
        Znodes[no + nj] = Z
        for k in range(nj - 1, -1, -1):
            i1 = o + 2 * k + 2
            im = o + 2 * k + 1
            i0 = o + 2 * k
            rate = _rate_bound(Z, Qw, terms, i0, im, i1, n)
            if h * rate > STIFF_TRIGGER:
                m = int(math.ceil(h * rate / STIFF_STEP))
                _substeps(Z, A, G, Qw, i0, im, i1, h, m, T, k1, k2, k3, k4, Zt, As, Gs, Qs, n)
            else:
                _rk4_step(Z, A, G, Qw, i1, im, i0, h, T, k1, k2, k3, k4, Zt, n)
            Znodes[no + k] = Z
    return Z


@_jit
def _solve(A, G, Qw, ds, nsteps, offs, F, Qj_inv, Znodes, node_offs):
    """:func:`_solve_segments` of the system's dimension ``A.shape[1]``. The transverse
    coordinates' ``n = 3`` is passed as a constant, so that its matrix products are compiled
    unrolled (the same operations in the same order, about twice as fast)."""
    n = A.shape[1]
    if n == 3:
        _solve_segments(A, G, Qw, ds, nsteps, offs, F, Qj_inv, Znodes, node_offs, 3)
    else:
        _solve_segments(A, G, Qw, ds, nsteps, offs, F, Qj_inv, Znodes, node_offs, n)


@_jit
def _prepare(B, w, R_inv, Q):
    """Per sample ``G = B R^-1 B' / w`` and ``Qw = w Q``."""
    N = B.shape[0]
    n = B.shape[1]
    m = B.shape[2]
    G = np.empty((N, n, n))
    Qw = np.empty((N, n, n))
    BR = np.empty((n, m))
    for i in range(N):
        for a in range(n):
            for c in range(m):
                acc = 0.0
                for d in range(m):
                    acc += B[i, a, d] * R_inv[d, c]
                BR[a, c] = acc
        for a in range(n):
            for b in range(n):
                acc = 0.0
                for c in range(m):
                    acc += BR[a, c] * B[i, b, c]
                G[i, a, b] = acc / w[i]
                Qw[i, a, b] = w[i] * Q[a, b]
    return G, Qw


@_jit
def _gains(Znodes, Bn, wn, R_inv):
    """``K = -R^-1 B' Z^-1 / w`` and ``Z^-1`` at the nodes (``B`` and ``w`` at the nodes)."""
    N = Znodes.shape[0]
    n = Znodes.shape[1]
    m = Bn.shape[2]
    K = np.empty((N, m, n))
    Zinv = np.empty((N, n, n))
    for i in range(N):
        Zi = _spd_inverse(Znodes[i])
        Zinv[i] = Zi
        K[i] = -(R_inv @ Bn[i].T @ Zi) / wn[i]
    return K, Zinv


@dataclass
class RiccatiSolution:
    """Solution of the jump-Riccati equation on the grid nodes.

    Attributes:
        s: per segment, the node positions ``s_j + k L_j / n_j``, ``k = 0 .. n_j``.
        Z: per segment, ``Z`` at the nodes, shape ``(n_j + 1, n, n)``.
        K: gains ``v = K z`` at the nodes of the first ``gain_segments`` segments,
            shape ``(n_j + 1, m, n)`` each.
        Zinv: ``Z^-1`` (the Lyapunov matrix of ``V = z' Z^-1 z``) where ``K`` is given.
    """

    s: list[np.ndarray]
    Z: list[np.ndarray]
    K: list[np.ndarray]
    Zinv: list[np.ndarray]


def solve_jump_riccati(
    A: Sequence[np.ndarray],
    B: Sequence[np.ndarray],
    lengths: Sequence[float],
    F: Sequence[np.ndarray],
    Q: np.ndarray,
    R: np.ndarray,
    Qj: np.ndarray | Sequence[np.ndarray],
    w: Sequence[np.ndarray] | None = None,
    s0: float = 0.0,
    gain_segments: int = 1,
) -> RiccatiSolution:
    """Solve the jump-Riccati equation backwards from ``Z(end) = 0``.

    Args:
        A: per segment ``j``, ``A`` sampled at ``2 n_j + 1`` equally spaced points (the RK4
            nodes and midpoints) covering the segment, shape ``(2 n_j + 1, n, n)``.
        B: per segment, ``B`` at the same points, shape ``(2 n_j + 1, n, m)``.
        lengths: length ``L_j > 0`` of each segment in the independent variable.
        F: the ``S - 1`` jump matrices, ``z+ = F_j z-`` between segments ``j`` and ``j+1``.
        Q, R: running weights (``n x n`` positive semi-definite, ``m x m`` positive definite).
        Qj: jump weight(s), positive definite ``n x n`` (one, or one per jump).
        w: optional per-segment positive weight samples (default 1): the running cost is
            ``w (z'Qz + v'Rv)``.
        s0: position of the start of the first segment.
        gain_segments: number of leading segments for which gains are returned (0 .. S).

    Returns:
        :class:`RiccatiSolution`. The feedback ``v = K z`` minimises the cost to go; with the
        time-scaled form (``A = A_t / theta_dot``, ``B = B_t / theta_dot``, ``w = 1/theta_dot``)
        ``K`` equals the time-domain gain ``-R^-1 B_t' Z^-1``.
    """
    S = len(A)
    if S < 1 or len(B) != S or len(lengths) != S:
        raise ValueError("solve_jump_riccati: A, B and lengths need one entry per segment (>= 1)")
    if len(F) != S - 1:
        raise ValueError(f"solve_jump_riccati: need {S - 1} jump matrices F, got {len(F)}")
    if not 0 <= gain_segments <= S:
        raise ValueError(f"solve_jump_riccati: gain_segments = {gain_segments}; allowed 0..{S}")
    n = np.asarray(A[0]).shape[1]
    nsteps = np.empty(S, dtype=np.int64)
    for j in range(S):
        ns = np.asarray(A[j]).shape[0]
        if ns < 3 or ns % 2 == 0 or np.asarray(B[j]).shape[0] != ns:
            raise ValueError(
                f"solve_jump_riccati: segment {j} needs an odd number >= 3 of samples of A and B"
            )
        if not lengths[j] > 0:
            raise ValueError(f"solve_jump_riccati: lengths[{j}] = {lengths[j]}; allowed > 0")
        nsteps[j] = (ns - 1) // 2
    Aall = np.ascontiguousarray(np.concatenate(A, axis=0), dtype=np.float64)
    Ball = np.ascontiguousarray(np.concatenate(B, axis=0), dtype=np.float64)
    if w is None:
        wall = np.ones(Aall.shape[0])
    else:
        wall = np.ascontiguousarray(np.concatenate(w), dtype=np.float64)
    Q = np.ascontiguousarray(Q, dtype=np.float64)
    R = np.atleast_2d(np.asarray(R, dtype=np.float64))
    if not (np.all(np.isfinite(Aall)) and np.all(np.isfinite(Ball)) and np.all(wall > 0)):
        raise ValueError("solve_jump_riccati: A, B must be finite and w positive")
    R_inv = np.linalg.inv(R)
    Qj_inv = np.zeros((max(S - 1, 1), n, n))
    if np.ndim(Qj) == 2:  # one weight for every jump: inverted once
        if S > 1:
            Qj_inv[:] = np.linalg.inv(np.asarray(Qj, dtype=np.float64))
    else:
        for j in range(S - 1):
            Qj_inv[j] = np.linalg.inv(np.asarray(Qj[j], dtype=np.float64))
    Fall = np.zeros((max(S - 1, 1), n, n))
    for j in range(S - 1):
        Fall[j] = F[j]
    if not np.all(np.isfinite(Fall)):
        raise ValueError("solve_jump_riccati: jump matrices F must be finite")
    offs = np.zeros(S, dtype=np.int64)
    offs[1:] = np.cumsum(2 * nsteps + 1)[:-1]
    node_offs = np.zeros(S, dtype=np.int64)
    node_offs[1:] = np.cumsum(nsteps + 1)[:-1]
    ds = np.asarray(lengths, dtype=np.float64) / nsteps
    G, Qw = _prepare(Ball, wall, R_inv, Q)
    Znodes = np.empty((int(np.sum(nsteps + 1)), n, n))
    _solve(Aall, G, Qw, ds, nsteps, offs, Fall, Qj_inv, Znodes, node_offs)
    s_list, Z_list, K_list, Zinv_list = [], [], [], []
    start = float(s0)
    for j in range(S):
        nj = int(nsteps[j])
        s_list.append(start + np.arange(nj + 1) * ds[j])
        start += float(lengths[j])
        Z_list.append(Znodes[node_offs[j] : node_offs[j] + nj + 1])
        if j < gain_segments:
            Bn = Ball[offs[j] : offs[j] + 2 * nj + 1 : 2]
            wn = wall[offs[j] : offs[j] + 2 * nj + 1 : 2]
            try:
                K, Zinv = _gains(
                    np.ascontiguousarray(Z_list[j]), np.ascontiguousarray(Bn), wn, R_inv
                )
            except np.linalg.LinAlgError:
                raise ValueError(
                    f"solve_jump_riccati: Z is not positive definite on segment {j}; the system "
                    "is not controllable over the remaining horizon (lengthen the horizon)"
                ) from None
            K_list.append(K)
            Zinv_list.append(Zinv)
    return RiccatiSolution(s_list, Z_list, K_list, Zinv_list)
