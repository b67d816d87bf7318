"""The compiled SQP: its QP pieces against SciPy's and numpy's, and its solves of step problems
against SLSQP's."""

import numpy as np
import pytest
from scipy.optimize import minimize, nnls

from controllers.planner import GaitPlanner
from controllers.planner.problem import BatchProblem, BudgetExhausted, SearchBudget
from controllers.planner.sqp import (
    FD_STEP,
    _augmented_qp,
    _ldl_update,
    _least_squares,
    _nnls,
    _qp,
    sqp_solve,
)

from .cases import CASES, gait_step
from .test_plan import rollout
from .test_problem import _pair


def test_the_small_least_squares_is_numpys():
    """The Householder least squares of NNLS's passive columns solves what numpy's does, and a
    column dependent on the earlier ones gets 0."""
    rng = np.random.default_rng(0)
    for p, q in [(7, 1), (7, 4), (8, 8), (9, 5)]:
        E = rng.standard_normal((p, q + 3))
        idx = np.sort(rng.choice(q + 3, q, replace=False))
        f = rng.standard_normal(p)
        want = np.linalg.lstsq(E[:, idx], f, rcond=None)[0]
        np.testing.assert_allclose(_least_squares(E, idx, f), want, rtol=1e-10, atol=1e-12)
    E = rng.standard_normal((6, 3))
    E[:, 2] = 2.0 * E[:, 0]
    z = _least_squares(E, np.arange(3), rng.standard_normal(6))
    assert z[2] == 0.0


def test_nnls_is_scipys():
    """Lawson and Hanson's NNLS gives SciPy's solution on the least-distance problems' shape
    (a few rows, many columns)."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        E = rng.standard_normal((7, 60))
        f = rng.standard_normal(7)
        u, ok = _nnls(E, f, 500)
        want = nnls(E, f)[0]
        assert ok and np.all(u >= 0)
        np.testing.assert_allclose(u, want, atol=1e-9)


def _slsqp_qp(B, g, A, c):
    """SciPy's SLSQP on the QP ``d' B d / 2 + g' d`` subject to ``A d + c >= 0``."""
    return minimize(
        lambda x: 0.5 * x @ B @ x + g @ x,
        np.zeros(g.size),
        jac=lambda x: B @ x + g,
        constraints=[{"type": "ineq", "fun": lambda x: A @ x + c, "jac": lambda x: A}],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 500},
    ).x


def test_the_qp_is_a_constrained_minimum():
    """The QP step minimises ``d' B d / 2 + g' d`` over ``A d + c >= 0`` (SciPy's SLSQP on the
    same QP); the multipliers are non-negative, zero on inactive constraints, and make the
    Lagrangian stationary. Inconsistent constraints are reported, and the elastic QP then
    meets them as far as it can."""
    rng = np.random.default_rng(2)
    for _ in range(10):
        n, m = 6, 40
        M = rng.standard_normal((n, n))
        B = M @ M.T + 0.5 * np.eye(n)
        g = rng.standard_normal(n)
        A = rng.standard_normal((m, n))
        c = -A @ rng.standard_normal(n) + rng.uniform(0.0, 1.0, m)  # consistent
        d, lam, ok = _qp(np.linalg.cholesky(B), g, A, c)
        assert ok
        np.testing.assert_allclose(d, _slsqp_qp(B, g, A, c), atol=1e-6)
        assert np.all(A @ d + c >= -1e-9) and np.all(lam >= 0)
        np.testing.assert_allclose(B @ d + g, A.T @ lam, atol=1e-8)
        assert np.all(lam[A @ d + c > 1e-6] < 1e-9)
    A = np.array([[1.0, 0.0], [-1.0, 0.0]])
    c = np.array([-1.0, -1.0])  # x >= 1 and x <= -1
    assert not _qp(np.eye(2), np.zeros(2), A, c)[2]
    d, _, delta, ok = _augmented_qp(np.eye(2), np.zeros(2), A, c, 100.0)
    assert ok and abs(d[0]) < 1e-6 and delta == pytest.approx(1.0)  # both relaxed in full
    # a constraint met stays met: x >= 1 violated, x <= 3 met
    A = np.array([[1.0], [-1.0]])
    c = np.array([-1.0, 3.0])
    d, _, delta, ok = _augmented_qp(np.eye(1), np.array([-10.0]), A, c, 100.0)
    assert ok and d[0] <= 3.0 + 1e-9


def test_the_ldl_updates_are_the_rank_one_changes():
    """The composite-t updates of ``L D L'`` give ``B + sigma z z'`` for an update and a
    downdate that keeps ``B`` positive definite, and keep it positive definite where the
    downdate would not (cut short, as SLSQP does)."""
    rng = np.random.default_rng(3)
    n = 6
    M = rng.standard_normal((n, n))
    B = M @ M.T + np.eye(n)
    C = np.linalg.cholesky(B)
    d0 = np.diag(C) ** 2
    L0 = C / np.diag(C)
    for sigma, z in [(0.7, rng.standard_normal(n)), (-0.1, 0.5 * rng.standard_normal(n))]:
        L, D = L0.copy(), d0.copy()
        _ldl_update(L, D, z.copy(), sigma)
        np.testing.assert_allclose(L @ np.diag(D) @ L.T, B + sigma * np.outer(z, z), rtol=1e-10)
        assert np.allclose(np.diag(L), 1.0) and np.all(D > 0)
    L, D = L0.copy(), d0.copy()
    z = 10.0 * rng.standard_normal(n)
    _ldl_update(L, D, z, -1.0)  # B - z z' is indefinite
    assert np.all(D > 0)


def _solve(sm, fx, fx2, x0, compiled, budget=10**6):
    b = SearchBudget(budget)
    prob = BatchProblem(
        lambda X: None,
        b,
        lambda ev: None,
        *sm.solve_functions(fx, fx2),
        sm.kernel_args(fx, fx2) if compiled else None,
    )
    x = prob.minimize(x0, 60, 1e-7, scaled=True)
    cost, g = sm.pair_values(fx, fx2, x[None]) if fx2 is not None else sm.step_values(fx, x[None])
    return x, float(cost[0]), float(np.min(g)), b


@pytest.mark.parametrize("spread", [1.0, 3.0])
def test_compiled_solves_of_pairs_reach_slsqps_optima(planners, spread):
    """From perturbed starts on a pair of steps over high blocks, the compiled SQP ends
    feasible where SLSQP does, at the same cost to 1e-4, with a bounded number of kernel
    rows."""
    sm, fx, fx2, X = _pair(planners)
    X = X[0] + spread * (X - X[0])
    n = X.shape[1] // 2
    both = 0
    for x0 in X:
        _, c1, g1, _ = _solve(sm, fx, fx2, x0, False)
        _, c2, g2, b2 = _solve(sm, fx, fx2, x0, True)
        if g1 >= -1e-7:
            assert g2 >= -1e-7
            assert c2 == pytest.approx(c1, rel=1e-4, abs=1e-7)
            both += 1
        assert 0 < b2.used < 60 * (2 * n + 12)
    assert both >= 4


def test_a_compiled_solve_of_one_step_reaches_slsqps_optimum(planners):
    """A step alone: the same optimum as SLSQP from the gait's shape moved off."""
    sm, fx, st = gait_step(planners["paper"], CASES["paper"]["blocks_high"], rise=0.005)
    x0 = st.coeffs[2:-1] + 0.02
    _, c1, g1, _ = _solve(sm, fx, None, x0, False)
    _, c2, g2, _ = _solve(sm, fx, None, x0, True)
    assert g1 >= -1e-7 and g2 >= -1e-7 and c2 == pytest.approx(c1, rel=1e-4, abs=1e-7)


def test_a_compiled_solve_stops_at_its_budget(planners):
    """A solve whose budget runs out raises :class:`BudgetExhausted` with the budget spent
    no further than one Jacobian beyond it, and marks the budget exhausted."""
    sm, fx, fx2, X = _pair(planners)
    # (the whole solve takes 14 rows: the scaling's 7, which are its first Jacobian's too)
    with pytest.raises(BudgetExhausted):
        _solve(sm, fx, fx2, X[0], True, budget=10)
    b = SearchBudget(10)
    prob = BatchProblem(
        lambda X: None, b, lambda ev: None, *sm.solve_functions(fx, fx2), sm.kernel_args(fx, fx2)
    )
    with pytest.raises(BudgetExhausted):
        prob.minimize(X[0], 60, 1e-7, scaled=True)
    assert b.exhausted and b.used <= 10


@pytest.mark.parametrize("terrain", ["paper_stairs", "blocks_high"])
def test_the_planners_plans_with_the_compiled_sqp_follow_open_loop_pfl(terrain):
    """The planner with ``compiled_sqp`` plans the paper's stairs and high blocks over its
    horizon, and its plans pass the open-loop PFL validation of SLSQP's plans (touchdown time,
    phase and foothold as planned)."""
    planner = GaitPlanner("paper", {"compiled_sqp": 1})
    g = planner.periodic_gait()
    plan = planner.plan(CASES["paper"][terrain], (g.q, g.qd), (0.0, 0.0), horizon=5)
    assert len(plan) == 5 and plan.evaluations > 0
    for j, r in enumerate(rollout(planner, plan, CASES["paper"][terrain], nsteps=5)):
        assert r["y"] < 1e-6 and r["thd_err"] < 1e-5, (j, r)
        assert r["time_err"] < 1e-5 and r["foot_err"] < 1e-5, (j, r)


def test_sqp_solve_runs_directly(planners):
    """The compiled call itself: rows counted, a converged status from the gait's own step."""
    sm, fx, st = gait_step(planners["paper"], CASES["paper"]["flat"])
    P, k, common, first, second, pair = sm.kernel_args(fx)
    x0 = np.ascontiguousarray(st.coeffs[2:-1])
    rule = (25.0, 5.0, 0.95, 1e-4)
    x, rows, status, it = sqp_solve(
        P, x0, np.eye(k), k, common, first, second, pair, 60, 1e-7, False, 10**6, rule
    )
    assert status == 0 and 0 < rows < 200 and it >= 1
    assert np.min(sm.step_values(fx, x[None])[1]) >= -1e-7


def test_a_solve_given_its_start_rows_is_the_same_solve_without_evaluating_them(planners):
    """The compiled solve given the costs and constraints at its start and its
    forward-difference points (the scaling's rows) ends where it ends evaluating them itself,
    to the last bit, with exactly those ``k + 1`` rows fewer."""
    sm, fx, fx2, X = _pair(planners)
    P, k, common, first, second, pair = sm.kernel_args(fx, fx2)
    rule = (25.0, 5.0, 0.95, 1e-4)
    for x0 in X[:3]:
        x0 = np.ascontiguousarray(x0)
        T = BatchProblem(
            lambda X: None, None, lambda ev: None, *sm.solve_functions(fx, fx2)
        ).scaling(x0)
        args = (P, x0, T, k, common, first, second, pair, 60, 1e-7, False, 10**6, rule)
        x, rows, status, it = sqp_solve(*args)
        pts = x0 + np.vstack([np.zeros(x0.size), FD_STEP * np.eye(x0.size)])
        cost, g = sm.pair_values(fx, fx2, pts)
        x2, rows2, status2, it2 = sqp_solve(*args, cost, np.ascontiguousarray(g))
        assert np.array_equal(x, x2) and (status, it) == (status2, it2)
        assert rows2 == rows - (x0.size + 1)


def test_a_minimize_spends_the_scalings_rows_once(planners):
    """A scaled solve through :class:`BatchProblem` accounts the scaling's rows once: its
    budget's count is the rows the compiled solve evaluated plus the scaling's ``k + 1``."""
    sm, fx, fx2, X = _pair(planners)
    b = SearchBudget(10**6)
    prob = BatchProblem(
        lambda X: None, b, lambda ev: None, *sm.solve_functions(fx, fx2), sm.kernel_args(fx, fx2)
    )
    x0 = np.ascontiguousarray(X[0])
    T = prob.scaling(x0)
    P, k, common, first, second, pair = sm.kernel_args(fx, fx2)
    rule = (25.0, 5.0, 0.95, 1e-4)
    _, rows, _, _ = sqp_solve(
        P, x0, T, k, common, first, second, pair, 60, 1e-7, False, 10**6, rule
    )
    b.used = 0
    prob = BatchProblem(
        lambda X: None, b, lambda ev: None, *sm.solve_functions(fx, fx2), sm.kernel_args(fx, fx2)
    )
    prob.minimize(x0, 60, 1e-7, scaled=True)
    assert b.used == rows  # the scaling's k + 1 rows and the solve's rows - (k + 1)
