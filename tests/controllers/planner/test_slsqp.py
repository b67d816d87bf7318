"""SLSQP driven directly: the iterates of ``scipy.optimize.minimize(method="SLSQP")`` bit for
bit, at a fraction of its overhead."""

import numpy as np
import pytest
from scipy.optimize import minimize

from controllers.planner import slsqp
from controllers.planner.problem import BatchProblem
from controllers.planner.slsqp import minimize_slsqp

from .cases import CASES, RecordedBudget, gait_step


class _Recorder:
    """Rosenbrock's function under a disc and a half-plane constraint, recording every point
    at which the cost, the constraints or their derivatives are asked for."""

    def __init__(self):
        self.points: list[tuple[str, tuple[float, ...]]] = []

    def cost(self, x):
        self.points.append(("f", tuple(x)))
        return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))

    def cons(self, x):
        self.points.append(("c", tuple(x)))
        return np.array([1.5 - x @ x, x[0] - 0.1 * x[-1]])

    def dcost(self, x):
        self.points.append(("df", tuple(x)))
        d = np.zeros_like(x)
        d[:-1] += -400.0 * x[:-1] * (x[1:] - x[:-1] ** 2) - 2.0 * (1.0 - x[:-1])
        d[1:] += 200.0 * (x[1:] - x[:-1] ** 2)
        return d

    def dcons(self, x):
        self.points.append(("dc", tuple(x)))
        e = np.zeros_like(x)
        e[0], e[-1] = 1.0, -0.1
        return np.stack([-2.0 * x, e])


def _scipy(rec, x0, maxiter, stop_after=None):
    it = []

    def cb(intermediate_result):
        it.append(np.copy(intermediate_result.x))
        if stop_after is not None and len(it) >= stop_after:
            raise StopIteration

    res = minimize(
        rec.cost,
        x0,
        jac=rec.dcost,
        method="SLSQP",
        callback=cb,
        constraints=[{"type": "ineq", "fun": rec.cons, "jac": rec.dcons}],
        options={"maxiter": maxiter, "ftol": 1e-10},
    )
    return res.x, it


def _direct(rec, x0, maxiter, stop_after=None):
    it = []

    def cb(x):
        it.append(x)
        return stop_after is not None and len(it) >= stop_after

    x = minimize_slsqp(
        lambda x: (rec.cost(x), rec.cons(x)),
        lambda x: (rec.dcost(x), rec.dcons(x)),
        x0,
        maxiter,
        1e-10,
        cb,
    )
    return x, it


@pytest.mark.parametrize("direct", [True, False])
@pytest.mark.parametrize("stop_after", [None, 3])
@pytest.mark.parametrize("maxiter", [100, 4])
def test_the_direct_driver_reproduces_scipys_iterates_bit_for_bit(
    maxiter, stop_after, direct, monkeypatch
):
    """Same final point, same iterates, to the last bit: converged, cut by the iteration limit
    and stopped by the callback; also through ``minimize`` itself, as on a SciPy without the
    compiled routine."""
    if direct and not slsqp.DIRECT:
        pytest.skip("this SciPy does not expose the compiled SLSQP routine")
    if not direct:
        monkeypatch.setattr(slsqp, "_slsqp", None)
    x0 = np.array([-1.2, 1.0, 0.3, -0.5])
    a, b = _Recorder(), _Recorder()
    xs, its = _scipy(a, x0, maxiter, stop_after)
    xd, itd = _direct(b, x0, maxiter, stop_after)
    assert xs.tobytes() == xd.tobytes()
    assert len(its) == len(itd) and all(p.tobytes() == q.tobytes() for p, q in zip(its, itd))
    # directly, the cost and its gradient are asked for at the same points in the same order
    # (through minimize, each of fun's halves is asked for separately)
    for kind in ("f", "df") if direct else ():
        assert [p for k, p in a.points if k == kind] == [p for k, p in b.points if k == kind]
    if maxiter == 100 and stop_after is None:
        assert xs @ xs == pytest.approx(1.5, abs=1e-8)  # on the disc


def test_a_step_problem_solves_as_scipy_solves_it(planners):
    """The planner's batched adaptor: the direct driver lands on scipy's point exactly and
    evaluates the same points (the search budget's count is unchanged)."""
    pl = planners["paper"]
    length = 0.8 * pl.periodic_gait().step.step_length
    sm, fx, st = gait_step(pl, CASES["paper"]["blocks_high"], length=length)

    def fn(X):
        ev = sm.evaluate_batch(fx, X)
        return ev["cost"], ev["g"], ev

    x0 = st.coeffs[2:-1] + 0.02
    direct = BatchProblem(fn)
    xd = direct.minimize(x0, 100, 1e-8)
    ref = BatchProblem(fn)
    res = minimize(
        lambda x: ref._with_jacobian_points(x)[0],
        x0,
        jac=lambda x: ref._jacobians(x)[0],
        method="SLSQP",
        constraints=[
            {
                "type": "ineq",
                "fun": lambda x: ref._with_jacobian_points(x)[1],
                "jac": lambda x: ref._jacobians(x)[1],
            }
        ],
        options={"maxiter": 100, "ftol": 1e-8},
    )
    assert xd.tobytes() == res.x.tobytes()
    assert list(direct.cache) == list(ref.cache)  # the same points, in the same order
    assert np.min(direct.get(xd)[1]) >= -1e-7  # feasible
    assert not np.allclose(xd, x0)  # it did move


def test_points_a_line_search_rejects_cost_one_row_and_the_same_budget():
    """:meth:`BatchProblem.minimize` evaluates the forward differences of a line search's
    shorter steps only if SLSQP accepts the point: on Rosenbrock's function, whose line
    searches shorten steps, fewer rows than with every iterate's batch evaluated whole, the
    same final point, and the budget spent in the same amounts at the same moments."""

    def rosenbrock(X):
        c = np.sum(100.0 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (1.0 - X[:, :-1]) ** 2, axis=1)
        g = np.stack([1.5 - np.sum(X * X, axis=1), X[:, 0] - 0.1 * X[:, -1]], axis=1)
        return c, g, None

    class Eager(BatchProblem):
        def _with_jacobian_points(self, x, eager=True):
            return super()._with_jacobian_points(x, eager=True)

    runs = []
    for cls in (Eager, BatchProblem):
        budget, rows = RecordedBudget(10**6), [0]

        def fn(X, rows=rows):
            rows[0] += X.shape[0]
            return rosenbrock(X)

        x = cls(fn, budget).minimize(np.array([-1.2, 1.0, 0.3]), 100, 1e-10)
        runs.append((x, budget.spent, rows[0]))
    (x1, s1, r1), (x2, s2, r2) = runs
    assert x1.tobytes() == x2.tobytes() and s1 == s2
    assert r2 < r1 and budget.used == r1  # the eager run evaluates every row it accounts
