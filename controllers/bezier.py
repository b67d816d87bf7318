"""Bezier polynomials (Bernstein form) and Bezier virtual constraints ``q1 = phi(theta)``.

A Bezier polynomial of order ``M`` with coefficients ``a_0 .. a_M`` is
``b(s) = sum_k a_k C(M, k) s^k (1 - s)^(M - k)`` for ``s`` in ``[0, 1]``. A virtual constraint
of one step maps the phase ``theta`` (the stance-leg angle ``q2``) to ``s`` with
``s = (theta - theta_plus) / (theta_minus - theta_plus)``, so that ``phi(theta_plus) = a_0`` and
``phi(theta_minus) = a_M``. Everything is vectorised over ``s`` (and ``theta``); the polynomial is
evaluated as it stands outside ``[0, 1]`` (smooth extrapolation).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.special import comb

__all__ = [
    "BezierConstraint",
    "bernstein_basis",
    "bezier",
    "bezier_derivative_coeffs",
    "bezier_on_basis",
    "chord_coefficients",
    "phase_fraction",
    "second_coeff",
]


@lru_cache(maxsize=32)
def _binomials(order: int) -> np.ndarray:
    return comb(order, np.arange(order + 1), exact=False)


@lru_cache(maxsize=64)
def _derivative_weights(order: int, deriv: int) -> np.ndarray:
    """The weights of the order-``(order - deriv)`` basis in the ``deriv``-th derivative's:
    ``M!/(M-r)! (-1)^(r-i) C(r, i)``, ``i = 0 .. r``; read-only."""
    scale = 1.0
    for i in range(deriv):
        scale *= order - i
    out = np.array(
        [scale * (-1.0) ** (deriv - i) * comb(deriv, i, exact=False) for i in range(deriv + 1)]
    )
    out.flags.writeable = False
    return out


def bernstein_basis(order: int, s: np.ndarray | float, deriv: int = 0) -> np.ndarray:
    """Bernstein basis (or its ``deriv``-th derivative in ``s``) as a matrix.

    Args:
        order: polynomial order ``M`` >= 0.
        s: evaluation points (any shape).
        deriv: derivative order (0, 1, 2, ...).

    Returns:
        Array of shape ``s.shape + (M + 1,)``: ``b(s) = basis @ coeffs``.
    """
    if int(order) != order or order < 0:
        raise ValueError(f"Bezier order = {order!r}; allowed: integer >= 0")
    if int(deriv) != deriv or deriv < 0:
        raise ValueError(f"Bezier derivative order = {deriv!r}; allowed: integer >= 0")
    return _bases(int(order), s, (int(deriv),))[0]


def _bases(order: int, s: np.ndarray | float, derivs: tuple[int, ...]) -> list[np.ndarray]:
    """:func:`bernstein_basis` for each of ``derivs``, the powers of ``s`` and ``1 - s``
    taken once for all of them."""
    s = np.asarray(s, dtype=np.float64)
    sb = s[..., None]
    k = np.arange(order + 1)
    up, down = sb**k, (1.0 - sb) ** k
    rows = (-1, order + 1)
    bases = []
    for deriv in derivs:
        out = np.zeros(s.shape + (order + 1,))
        if deriv <= order:
            _basis_from_powers(
                up.reshape(rows),
                down.reshape(rows),
                _binomials(order - deriv),
                _derivative_weights(order, deriv),
                out.reshape(rows),
            )
        bases.append(out)
    return bases


@njit(cache=True, error_model="numpy")
def _basis_from_powers(
    up: np.ndarray, down: np.ndarray, binom: np.ndarray, weights: np.ndarray, out: np.ndarray
) -> None:
    """Adds to the basis rows ``out`` ``(K, M + 1)`` of a derivative of order ``r`` its terms
    from the powers ``up = s^k`` and ``down = (1 - s)^k`` ``(K, M + 1)``, with ``binom`` the
    binomial coefficients of order ``m = M - r`` and ``weights`` :func:`_derivative_weights`."""
    m = binom.size - 1
    low = np.empty(m + 1)
    for row in range(up.shape[0]):
        # basis of order m: C(m, k) s^k (1 - s)^(m - k)
        for j in range(m + 1):
            low[j] = binom[j] * up[row, j] * down[row, m - j]
        # d^r/ds^r b(s) = M!/(M-r)! sum_k (Delta^r a)_k B_{k,M-r}(s); Delta^r a_k =
        # sum_i (-1)^(r-i) C(r, i) a_{k+i}, so the basis of b^(r) w.r.t. a_j collects the
        # terms with k + i = j, added in the order of i
        for i in range(weights.size):
            for j in range(m + 1):
                out[row, i + j] += weights[i] * low[j]


@njit(cache=True, error_model="numpy")
def bezier_on_basis(coeffs: np.ndarray, basis: np.ndarray, out: np.ndarray) -> None:
    """A Bezier polynomial (or a derivative) at the points of a :func:`bernstein_basis` matrix,
    compiled: ``out[k] = sum_i coeffs[i] basis[k, i]`` for the ``(K, M + 1)`` ``basis`` and the
    ``M + 1`` coefficients ``coeffs`` [rad]."""
    for k in range(basis.shape[0]):
        s = 0.0
        for i in range(coeffs.size):
            s += coeffs[i] * basis[k, i]
        out[k] = s


@njit(cache=True, error_model="numpy")
def chord_coefficients(
    a0: float, a_last: float, k: np.ndarray | int, order: int
) -> np.ndarray | float:
    """Coefficients ``a_0 + (a_M - a_0) k / M`` [rad] of the chord, the straight line from the
    first to the last coefficient of an order-``M`` polynomial, at the indices ``k`` (entry by
    entry); a shape is measured relative to it."""
    return a0 + (a_last - a0) * k / order


@njit(cache=True, error_model="numpy")
def second_coeff(
    a0: float, slope: np.ndarray | float, theta_plus: float, theta_minus: float, order: int
) -> np.ndarray | float:
    """``a_1`` that gives ``phi'(theta_plus) = slope`` (impact invariance); compiled, entry by
    entry for an array ``slope``.

    Args:
        a0: first coefficient ``a_0`` [rad].
        slope: wanted ``d phi / d theta`` at ``theta_plus`` [-].
        theta_plus: phase at the start of the step [rad].
        theta_minus: phase at the planned impact [rad].
        order: polynomial order ``M``.

    Returns:
        The coefficient ``a_1`` [rad].
    """
    return a0 + slope * (theta_minus - theta_plus) / order


@njit(cache=True, error_model="numpy")
def phase_fraction(theta: np.ndarray | float, theta_plus: float, span: float) -> np.ndarray | float:
    """Normalised phase ``s = (theta - theta_plus) / span`` of the phase ``theta`` [rad] on a
    step that starts at ``theta_plus`` [rad] and spans ``span`` [rad] (entry by entry)."""
    return (theta - theta_plus) / span


def bezier(coeffs: np.ndarray, s: np.ndarray | float, deriv: int = 0) -> np.ndarray | float:
    """Evaluate a Bezier polynomial (or a derivative in ``s``) at ``s``.

    Args:
        coeffs: coefficients, shape ``(M + 1,)`` or a batch ``(K, M + 1)``.
        s: evaluation points (any shape).
        deriv: derivative order in ``s``.

    Returns:
        Shape ``s.shape`` for one polynomial, ``(K,) + s.shape`` for a batch; a float for a
        scalar ``s`` and a single polynomial.
    """
    a = np.asarray(coeffs, dtype=np.float64)
    if a.ndim not in (1, 2) or a.shape[-1] < 1:
        raise ValueError(f"Bezier coeffs must have shape (M+1,) or (K, M+1), got {a.shape}")
    basis = bernstein_basis(a.shape[-1] - 1, s, deriv)
    out = _on_basis(a, basis)
    return float(out) if np.ndim(out) == 0 else out


def _on_basis(coeffs: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """:func:`bezier_on_basis` for one polynomial or a batch ``(K, M + 1)`` of them and a basis
    of any leading shape: the result has shape ``(K,) + basis.shape[:-1]`` (no ``K`` for one)."""
    a = np.ascontiguousarray(coeffs, dtype=np.float64)
    flat = np.ascontiguousarray(basis.reshape(-1, basis.shape[-1]))
    rows = a.reshape(-1, a.shape[-1])
    out = np.empty((rows.shape[0], flat.shape[0]))
    for k in range(rows.shape[0]):
        bezier_on_basis(rows[k], flat, out[k])
    shape = basis.shape[:-1]
    return out.reshape(shape) if a.ndim == 1 else out.reshape((rows.shape[0],) + shape)


def bezier_derivative_coeffs(coeffs: np.ndarray) -> np.ndarray:
    """Coefficients (order ``M - 1``) of ``d b / d s``: ``M (a_{k+1} - a_k)``."""
    a = np.asarray(coeffs, dtype=np.float64)
    return (a.shape[-1] - 1) * np.diff(a, axis=-1)


@dataclass(frozen=True)
class BezierConstraint:
    """One step's virtual constraint ``q1 = phi(theta)``, a Bezier polynomial in ``theta``.

    Attributes:
        coeffs: Bezier coefficients ``a_0 .. a_M`` [rad], shape ``(M + 1,)``.
        theta_plus: phase at the start of the step (post-impact ``q2``) [rad].
        theta_minus: phase at the planned impact (pre-impact ``q2``) [rad], ``> theta_plus``.
    """

    coeffs: np.ndarray
    theta_plus: float
    theta_minus: float

    def __post_init__(self) -> None:
        a = np.array(self.coeffs, dtype=np.float64)
        if a.ndim != 1 or a.size < 2 or not np.all(np.isfinite(a)):
            raise ValueError(f"BezierConstraint.coeffs must be finite, shape (M+1,) M>=1: {a!r}")
        tp, tm = float(self.theta_plus), float(self.theta_minus)
        if not (np.isfinite(tp) and np.isfinite(tm) and tm > tp):
            raise ValueError(
                f"BezierConstraint: theta_minus = {tm!r} must be finite and > theta_plus = {tp!r}"
            )
        a.flags.writeable = False
        object.__setattr__(self, "coeffs", a)
        object.__setattr__(self, "theta_plus", tp)
        object.__setattr__(self, "theta_minus", tm)

    @property
    def order(self) -> int:
        """Polynomial order ``M``."""
        return self.coeffs.size - 1

    @property
    def span(self) -> float:
        """``theta_minus - theta_plus`` [rad]."""
        return self.theta_minus - self.theta_plus

    def s(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Normalised phase ``(theta - theta_plus) / (theta_minus - theta_plus)``
        (:func:`phase_fraction`)."""
        th = np.asarray(theta, dtype=np.float64)
        if th.ndim == 0:
            return np.float64(phase_fraction(float(th), self.theta_plus, self.span))
        return phase_fraction(th, self.theta_plus, self.span)

    def phi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi(theta)`` [rad]."""
        return bezier(self.coeffs, self.s(theta))

    def dphi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``d phi / d theta`` [-]."""
        return bezier(self.coeffs, self.s(theta), 1) / self.span

    def ddphi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``d^2 phi / d theta^2`` [1/rad]."""
        return bezier(self.coeffs, self.s(theta), 2) / self.span**2

    def derivatives(self, theta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(phi, phi', phi'')`` at ``theta`` in one pass."""
        s = self.s(theta)
        b = [_on_basis(self.coeffs, basis) for basis in _bases(self.order, s, (0, 1, 2))]
        return b[0], b[1] / self.span, b[2] / self.span**2

    second_coeff = staticmethod(second_coeff)

    @staticmethod
    def penultimate_coeff(
        a_last: float, slope: float, theta_plus: float, theta_minus: float, order: int
    ):
        """``a_{M-1}`` that gives ``phi'(theta_minus) = slope``.

        Args:
            a_last: last coefficient ``a_M`` [rad].
            slope: wanted ``d phi / d theta`` at ``theta_minus`` [-].
            theta_plus: phase at the start of the step [rad].
            theta_minus: phase at the planned impact [rad].
            order: polynomial order ``M``.

        Returns:
            The coefficient ``a_{M-1}`` [rad].
        """
        return a_last - slope * (theta_minus - theta_plus) / order
