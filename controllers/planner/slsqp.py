"""SLSQP driven directly: the iteration of :func:`scipy.optimize.minimize` (``method="SLSQP"``)
for one vector of inequality constraints, without its per-call set-up and per-evaluation
wrappers.

The step problems are small (2 to 8 free coefficients) and solved thousands of times per walk;
``minimize`` spends more time preparing and wrapping than SciPy's compiled SLSQP iteration
does. :func:`minimize_slsqp` calls the same compiled routine with the same arguments and
requests, so it returns the same iterates bit for bit (``tests/controllers/planner/
test_slsqp.py`` checks this against ``minimize``). Where SciPy does not expose the routine
(releases before 1.16 wrapped Fortran), it calls ``minimize`` itself.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize

try:  # SciPy >= 1.16: the C translation of SLSQP, a reverse-communication routine
    from scipy.optimize._slsqplib import slsqp as _slsqp
except ImportError:  # pragma: no cover - older SciPy: the public front end
    _slsqp = None

__all__ = ["DIRECT", "minimize_slsqp"]

#: whether :func:`minimize_slsqp` drives the compiled routine itself
DIRECT = _slsqp is not None


def minimize_slsqp(
    fun: Callable[[np.ndarray], tuple[float, np.ndarray]],
    jac: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0: np.ndarray,
    maxiter: int,
    ftol: float,
    callback: Callable[[np.ndarray], bool] | None = None,
) -> np.ndarray:
    """Minimise ``cost(x)`` subject to ``c(x) >= 0`` with SLSQP from ``x0``; the final point.

    Args:
        fun: ``x -> (cost, c)``, the cost and the constraint vector ``(m,)`` (``m >= 1``).
        jac: ``x -> (dcost, dc)``, the cost's gradient ``(n,)`` and the constraints' Jacobian
            ``(m, n)``.
        x0: starting point ``(n,)``.
        maxiter: iteration limit (>= 1).
        ftol: SLSQP's accuracy ``acc`` (> 0).
        callback: called with a copy of the iterate after each major iteration; returning
            True stops the run there (as ``StopIteration`` in a ``minimize`` callback).

    Raises whatever ``fun`` or ``jac`` raise.
    """
    x = np.array(x0, dtype=np.float64).reshape(-1)
    if _slsqp is None:
        return _minimize_scipy(fun, jac, x, maxiter, ftol, callback)
    n = x.size
    fx, c = fun(x)
    m = int(np.size(c))
    # the set-up of scipy.optimize._slsqp_py._minimize_slsqp, inequality constraints only
    state = {
        "acc": ftol,
        "alpha": 0.0,
        "f0": 0.0,
        "gs": 0.0,
        "h1": 0.0,
        "h2": 0.0,
        "h3": 0.0,
        "h4": 0.0,
        "t": 0.0,
        "t0": 0.0,
        "tol": 10.0 * ftol,
        "exact": 0,
        "inconsistent": 0,
        "reset": 0,
        "iter": 0,
        "itermax": int(maxiter),
        "line": 0,
        "m": m,
        "meq": 0,
        "mode": 0,
        "n": n,
    }
    indices = np.zeros(max(m + 2 * n + 2, 1), dtype=np.int32)
    size = n * (n + 1) // 2 + 3 * m * n + 9 * m + 8 * n * n + 35 * n + 28  # SciPy's, meq = 0
    buffer = np.zeros(max(size, 1), dtype=np.float64)
    xl = np.full(n, np.nan)  # no bounds
    xu = np.full(n, np.nan)
    mult = np.zeros(max(1, m + 2 * n + 2), dtype=np.float64)
    C = np.zeros((max(1, m), n), dtype=np.float64, order="F")
    d = np.zeros(max(1, m), dtype=np.float64)
    g, C[:] = jac(x)
    d[:] = c
    fx = float(fx)
    it_prev = 0
    while True:
        _slsqp(state, fx, g, C, d, x, mult, xl, xu, buffer, indices)
        mode = state["mode"]
        if mode == 1:  # cost and constraints wanted at x
            fx, c = fun(x)
            fx = float(fx)
            d[:] = c
        elif mode == -1:  # their derivatives wanted at x
            g, C[:] = jac(x)
        if state["iter"] > it_prev and callback is not None and callback(x.copy()):
            break
        if abs(state["mode"]) != 1:
            break
        it_prev = state["iter"]
    return x


def _minimize_scipy(fun, jac, x, maxiter, ftol, callback):
    def stop(intermediate_result):
        if callback is not None and callback(np.copy(intermediate_result.x)):
            raise StopIteration

    res = minimize(
        lambda y: fun(y)[0],
        x,
        jac=lambda y: jac(y)[0],
        method="SLSQP",
        callback=stop,
        constraints=[{"type": "ineq", "fun": lambda y: fun(y)[1], "jac": lambda y: jac(y)[1]}],
        options={"maxiter": maxiter, "ftol": ftol},
    )
    return np.asarray(res.x)
