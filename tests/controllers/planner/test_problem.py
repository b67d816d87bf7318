"""The step problem: batched evaluation, the constraint-group table and its layout."""

import warnings

import numpy as np
import pytest

from controllers.planner import TerrainMap
from controllers.planner.kernel import allocate_outputs, packed_size
from controllers.planner.problem import (
    CONSTRAINT_GROUPS,
    BatchProblem,
    ConstraintGroups,
    FixedStep,
    SearchBudget,
    StepEvaluator,
    constraint_layout,
    gait_reference,
    violation,
    worst_violation,
)

from .cases import CASES, RecordedBudget, gait_step


def test_batched_step_evaluation_matches_single_points(planners):
    """The vectorised evaluation of many candidate shapes (used for the SLSQP Jacobians and the
    global search) gives, row by row, the constraints and cost of evaluating each alone."""
    sm, fx, st = gait_step(planners["paper"], CASES["paper"]["blocks_high"])
    assert sm.ref.delta == st.delta
    x = st.coeffs[2:-1] + 0.05 * np.random.default_rng(0).standard_normal((6, st.coeffs.size - 3))
    batch = sm.evaluate_batch(fx, x)
    for i in range(len(x)):
        one = sm.evaluate(fx, x[i])
        np.testing.assert_allclose(batch["g"][i], one["g"], rtol=1e-12, atol=1e-14)
        assert batch["cost"][i] == pytest.approx(one["cost"], rel=1e-12)
        assert batch["T"][i] == pytest.approx(one["T"], rel=1e-12)
    # the fixed coefficients come from the step's start and end
    np.testing.assert_allclose(sm.evaluate(fx, st.coeffs[2:-1])["a"], st.coeffs, atol=1e-12)


def _pair(planners):
    """A step of the gait on high blocks and the step after it (its start left open)."""
    sm, fx, st = gait_step(planners["paper"], CASES["paper"]["blocks_high"])
    x1 = fx.foothold[0] + st.step_length
    fx2 = FixedStep(
        st.theta_plus,
        st.coeffs[0],
        float("nan"),
        float("nan"),
        fx.foothold,
        (x1, float(sm.tmap.height(x1))),
        st.theta_minus,
        st.coeffs[-1],
    )
    rng = np.random.default_rng(2)
    x = np.tile(st.coeffs[2:-1], 2) + 0.03 * rng.standard_normal((7, 2 * (st.coeffs.size - 3)))
    return sm, fx, fx2, x


def _pair_batch(sm, fx, fx2, X):
    """The pair's cost and constraints from two full evaluations (the search's payload path)."""
    n = (X.shape[1]) // 2
    e1 = sm.evaluate_batch(fx, X[:, :n])
    thd2 = e1["delta"] * e1["thetadot_minus"]
    e2 = sm.evaluate_batch(fx2, X[:, n:], slope=e1["slope_plus"], thetadot_plus=thd2)
    e1["next_residuals"] = e2["residuals"]
    return e1["cost"] + e2["cost"], np.concatenate([e1["g"], e2["g"]], axis=1), e1


def test_the_compiled_values_are_the_full_evaluations_numbers(planners):
    """What SLSQP gets from the lean compiled calls (a step; a step and the next one, which
    starts where the first ends, row by row) is, bit for bit, the cost and constraints of the
    full evaluations the search keeps for the steps it plans."""
    sm, fx, fx2, x = _pair(planners)
    n = x.shape[1] // 2
    cost, g = sm.step_values(fx, x[:, :n])
    ev = sm.evaluate_batch(fx, x[:, :n])
    assert np.array_equal(cost, ev["cost"]) and np.array_equal(g, ev["g"], equal_nan=True)
    # random rows, and a forward-difference batch: rows 0 and n + 1 .. 2 n share the first step
    # (evaluated once)
    for X in (x, np.vstack([x[0], x[0] + 1e-8 * np.eye(2 * n), x[1]])):
        cost, g = sm.pair_values(fx, fx2, X)
        cost2, g2, _ = _pair_batch(sm, fx, fx2, X)
        assert np.array_equal(cost, cost2) and np.array_equal(g, g2, equal_nan=True)
    assert g.shape[1] > ev["g"].shape[1]  # both steps' constraints
    with pytest.raises(ValueError, match="free coefficients of shape"):
        sm.step_values(fx, x)  # a pair's coefficients for one step


def test_a_solves_prepared_functions_give_the_same_numbers(planners):
    """The functions a solve gets with its problem's data looked up once
    (:meth:`StepEvaluator.solve_functions`) return, bit for bit, what the evaluator's own
    calls return: a step, and a step with the next one."""
    sm, fx, fx2, x = _pair(planners)
    n = x.shape[1] // 2
    values, residual_values = sm.solve_functions(fx)
    X = np.ascontiguousarray(x[:, :n])
    for a, b in zip(
        values(X) + residual_values(X), sm.step_values(fx, X) + sm.step_residuals(fx, X)
    ):
        assert np.array_equal(a, b, equal_nan=True)
    values, residual_values = sm.solve_functions(fx, fx2)
    for a, b in zip(
        values(x) + residual_values(x), sm.pair_values(fx, fx2, x) + sm.pair_residuals(fx, fx2, x)
    ):
        assert np.array_equal(a, b, equal_nan=True)


def test_the_forward_difference_quotients_are_numpys_bit_for_bit():
    """The compiled forward-difference quotients are those of the plain array expression, to
    the last bit, with a model breakdown's NaN set to 0 and infinite or huge slopes clipped to
    +-1e12."""
    from controllers.planner.problem import _fd_points
    from controllers.planner.sqp import fd_quotients as _fd_quotients

    rng = np.random.default_rng(4)
    x = rng.standard_normal(6)
    X = _fd_points(x)
    cost = rng.standard_normal(7)
    g = rng.standard_normal((7, 40))
    g[3, 5], g[2, 7], g[4, 9], g[0, 11] = np.nan, 1e6, -1e6, np.inf
    h = np.diag(X[1:]) - x
    with np.errstate(all="ignore"):
        want_c = (cost[1:] - cost[0]) / h
        want_g = ((g[1:] - g[0]) / h[:, None]).T
    for d in (want_c, want_g):
        d[np.isnan(d)] = 0.0
        np.clip(d, -1e12, 1e12, out=d)
    dc, dgt = _fd_quotients(X, cost, g)
    assert dc.tobytes() == want_c.tobytes()
    assert np.ascontiguousarray(dgt.T).tobytes() == np.ascontiguousarray(want_g).tobytes()
    assert dgt[2, 5] == 0.0 and dgt[1, 7] == 1e12 and dgt[3, 9] == -1e12
    assert np.all(dgt[:, 11] == -1e12)


def test_the_screen_skips_only_infeasible_rows_and_keeps_the_feasible_ones_bit_for_bit(planners):
    """With ``screen`` (the beam search's), a row whose dynamics break a constraint below it is
    left early: it is infeasible in the full evaluation too, and its scalar outputs are NaN;
    every row feasible at that threshold is the same, to the last bit, in every output."""
    from controllers.planner.beam import beam_shapes

    sm, fx, st = gait_step(planners["paper"], CASES["paper"]["blocks_high"])
    near, far = beam_shapes(sm.cfg.order)
    chord = fx.a_last - fx.a0
    base = st.coeffs[2:-1]  # the gait's shape
    X = np.vstack([base, base + chord * near, base + chord * far])
    screen = -1e-7
    full = sm.evaluate_batch(fx, X)
    cut = sm.evaluate_batch(fx, X, screen=screen)
    feasible = np.min(full["g"], axis=1) >= screen
    skipped = np.isnan(cut["cost"])
    assert 0 < feasible.sum() < X.shape[0] and skipped.sum() > X.shape[0] // 2
    assert not np.any(feasible & skipped)
    assert np.array_equal(np.min(cut["g"], axis=1) >= screen, feasible)
    for key, v in full.items():
        if key == "groups":
            for a, b in zip(v, cut[key]):
                assert np.array_equal(a[feasible], b[feasible], equal_nan=True)
        else:
            a, b = np.asarray(v)[feasible], np.asarray(cut[key])[feasible]
            assert np.array_equal(a, b, equal_nan=True), key
    # rows not skipped are evaluated whole, feasible or not
    kept = ~skipped
    assert np.array_equal(full["g"][kept], cut["g"][kept], equal_nan=True)
    assert np.isnan(cut["thetadot_minus"][skipped]).all()


def test_the_compiled_residuals_are_the_full_evaluations_terms(planners):
    """The cost terms of the Gauss-Newton scaling from the compiled calls (a step; a pair, the
    first step's terms then the second's) are, bit for bit, the full evaluations', and so are
    the cost and constraints that come with them; the scaling made from them is the same, and
    so are the evaluations it accounts."""
    sm, fx, fx2, x = _pair(planners)
    n = x.shape[1] // 2
    cost, g, res = sm.step_residuals(fx, x[:, :n])
    ev = sm.evaluate_batch(fx, x[:, :n])
    assert np.array_equal(res, ev["residuals"]) and np.array_equal(cost, ev["cost"])
    assert np.array_equal(g, ev["g"], equal_nan=True)
    for X in (x, np.vstack([x[0], x[0] + 1e-8 * np.eye(2 * n), x[1]])):
        cost, g, res = sm.pair_residuals(fx, fx2, X)
        cost2, g2, e1 = _pair_batch(sm, fx, fx2, X)
        full = np.concatenate([e1["residuals"], e1["next_residuals"]], axis=1)
        assert np.array_equal(res, full) and np.array_equal(cost, cost2)
        assert np.array_equal(g, g2, equal_nan=True)
    scalings = []
    for compiled in (False, True):
        budget = SearchBudget(10**6)
        prob = BatchProblem(
            lambda X: _pair_batch(sm, fx, fx2, X),
            budget,
            lambda e: np.concatenate([e["residuals"], e["next_residuals"]], axis=1),
            lambda X: sm.pair_values(fx, fx2, X),
            (lambda X: sm.pair_residuals(fx, fx2, X)) if compiled else None,
        )
        T = prob.scaling(x[0])
        assert (prob.get(x[0])[2] is None) == compiled  # no payload where it was not needed
        scalings.append((T, budget.used, prob.get(x[0] + 1e-3)[:2]))
    (T1, u1, (c1, g1)), (T2, u2, (c2, g2)) = scalings
    assert np.array_equal(T1, T2) and u1 == u2 > 0 and c1 == c2
    assert np.array_equal(g1, g2, equal_nan=True)


def test_an_optimisation_on_the_compiled_values_is_the_one_on_full_evaluations(planners):
    """SLSQP on a pair reaches the same point with the same evaluations spent whether its
    points are evaluated by the lean compiled call or in full; the payload of a point evaluated
    lean comes on request (:meth:`BatchProblem.details`) without being accounted again."""
    sm, fx, fx2, x = _pair(planners)
    runs = []
    for lean in (False, True):
        budget = SearchBudget(10**6)
        values = (lambda X: sm.pair_values(fx, fx2, X)) if lean else None
        prob = BatchProblem(lambda X: _pair_batch(sm, fx, fx2, X), budget, values=values)
        xs = prob.minimize(x[0], 30, 1e-7)
        used = budget.used
        assert (prob.get(xs)[2] is None) == lean
        cost, g, ev, r = prob.details(xs)
        assert ev is not None and budget.used == used
        assert np.array_equal(ev["a"][r, 2:-1], xs[: x.shape[1] // 2])  # the first step's
        runs.append((xs, used, cost, g))
    (x1, u1, c1, g1), (x2, u2, c2, g2) = runs
    assert np.array_equal(x1, x2) and u1 == u2 > 0 and c1 == c2
    assert np.array_equal(g1, g2, equal_nan=True)


class _EagerProblem(BatchProblem):
    """:class:`BatchProblem` evaluating every iterate's forward differences with it."""

    def _with_jacobian_points(self, x, eager=True):
        return super()._with_jacobian_points(x, eager=True)


@pytest.mark.parametrize("scaled", [False, True])
def test_put_off_forward_differences_change_the_cost_not_the_solve(planners, scaled):
    """SLSQP on a pair: putting off the forward differences of the points it may reject gives
    the same final points and the same budget spent, call by call, and evaluates no more rows
    (fewer where a line search shortens a step: ``test_slsqp.py``)."""
    sm, fx, fx2, x = _pair(planners)
    runs = []
    for cls in (_EagerProblem, BatchProblem):
        budget, rows = RecordedBudget(10**6), [0]

        def values(X, rows=rows):
            rows[0] += X.shape[0]
            return sm.pair_values(fx, fx2, X)

        def residual_values(X):
            return sm.pair_residuals(fx, fx2, X)

        finals = []
        for x0 in x:
            prob = cls(
                lambda X: _pair_batch(sm, fx, fx2, X),
                budget,
                lambda ev: np.concatenate([ev["residuals"], ev["next_residuals"]], axis=1),
                values,
                residual_values,
            )
            finals.append(prob.minimize(x0, 30, 1e-7, scaled=scaled))
        runs.append((np.array(finals), budget.spent, rows[0]))
    (x1, s1, r1), (x2, s2, r2) = runs
    assert x1.tobytes() == x2.tobytes() and s1 == s2 and len(s1) > 0
    assert r2 <= r1


@pytest.mark.parametrize("periodic", [False, True])
def test_the_cost_is_the_sum_of_the_squared_residuals(planners, periodic):
    """The kernel's residuals (the Gauss-Newton model's terms) square and sum to its cost, for
    the periodic gait's effort cost and for a step's pull towards the gait."""
    pl = planners["paper"]
    st = pl.periodic_gait().step
    sm, fx, st = gait_step(
        pl, CASES["paper"]["blocks_high"], length=0.9 * st.step_length, ref=not periodic
    )
    x = st.coeffs[2:-1] + 0.03 * np.random.default_rng(1).standard_normal((5, st.coeffs.size - 3))
    ev = sm.evaluate_batch(fx, x, periodic=periodic)
    assert np.all(ev["cost"] > 0)
    np.testing.assert_allclose(np.sum(ev["residuals"] ** 2, axis=1), ev["cost"], rtol=1e-12)
    used = np.any(ev["residuals"] != 0, axis=0)
    # the speed term, then 33 effort terms or end speed, slope and the order - 2 shape terms
    assert used.sum() == (1 + sm.grids.nodes.size if periodic else 3 + pl.config.order - 2)


def test_constraint_layout_follows_the_table():
    """Each group of the table gets a block of columns of its size, in the table's order (the
    periodic-gait group last and only for the periodic gait); the kernel's columns by name are
    the blocks' first columns."""
    assert [g.periodic_only for g in CONSTRAINT_GROUPS] == [False] * 12 + [True]
    assert len({g.name for g in CONSTRAINT_GROUPS}) == len(CONSTRAINT_GROUPS)
    n, k, f = 33, 97, 2
    for periodic in (False, True):
        lay = constraint_layout(n, k, f, periodic)
        groups = [g for g in CONSTRAINT_GROUPS if periodic or not g.periodic_only]
        assert lay.offsets[0] == 0 and lay.offsets.dtype == np.int64
        assert np.diff(lay.offsets).tolist() == [g.size(n, k, f) for g in groups]
        # _fields is the named tuple's public list of field names, not a private attribute
        assert lay.columns._fields == tuple(g.name for g in CONSTRAINT_GROUPS)
        for g, first in zip(groups, lay.offsets):
            assert getattr(lay.columns, g.name) == first
        if not periodic:
            assert lay.columns.periodic == lay.offsets[-1]
        assert lay.packed == packed_size(np.diff(lay.offsets).tolist(), 8)
    # the sizes the kernel documents: N + K + 1, N, N, K, 2 N, 2, 1 + F, 1, 2, 2, 1, 1, (2)
    sizes = np.diff(constraint_layout(n, k, f, True).offsets).tolist()
    assert sizes == [n + k, n, n, k - 1, 2 * n, 2, 1 + f, 1, 2, 2, 1, 1, 2]


@pytest.mark.parametrize("periodic", [False, True])
def test_the_kernel_writes_every_constraint_column(planners, periodic):
    """No column of the constraint matrix is left as allocated (NaN, ``allocate_outputs``),
    with or without the periodic group, with vertical faces between the stance foot and the
    foothold."""
    out = allocate_outputs(2, 5, 3, 4)
    assert np.all(np.isnan(out.constraints)) and np.all(out.residuals == 0)
    pl = planners["paper"]
    g = pl.periodic_gait()
    st = g.step
    tmap = TerrainMap(CASES["paper"]["stairs_up"])
    sm = StepEvaluator(pl.params, pl.config, tmap)
    x0 = 0.4 - 0.5 * st.step_length  # the first riser lies between stance foot and foothold
    fx = FixedStep(
        st.theta_plus,
        st.coeffs[0],
        st.slope_plus,
        st.thetadot_plus,
        (x0, 0.0),
        (x0 + st.step_length, 0.01),
        st.theta_minus,
        st.coeffs[-1],
    )
    if not periodic:
        sm.ref = gait_reference(g)
    assert len(tmap.faces_between(x0, x0 + st.step_length)) == 1
    ev = sm.evaluate_batch(fx, np.stack([st.coeffs[2:-1]] * 3), periodic=periodic)
    G = ev["groups"].G
    assert not np.any(np.isnan(G))
    groups = [c for c in CONSTRAINT_GROUPS if periodic or not c.periodic_only]
    assert len(ev["groups"]) == len(groups)
    for grp, block in zip(groups, ev["groups"]):
        assert block.shape == (3, grp.size(sm.grids.nodes.size, sm.grids.check.size, 1))


def test_worst_violation_names_the_group_of_the_table():
    n, k, f = 5, 9, 0
    lay = constraint_layout(n, k, f, True)
    for i, grp in enumerate(CONSTRAINT_GROUPS):
        G = np.ones((1, lay.offsets[-1]))
        G[0, lay.offsets[i]] = -0.5
        rows = [block[0] for block in ConstraintGroups(G, lay.offsets)]
        assert worst_violation(rows) == (-0.5, grp.violation)
    assert worst_violation([np.ones(3)]) == (0.0, "")


def test_the_swing_foot_geometry_is_the_robots(planners):
    pl = planners["paper"]
    robot = pl.params.replace(retract=0.08, arm_distance=0.3)
    sm = StepEvaluator(robot, pl.config, TerrainMap(CASES["paper"]["stairs_up"]))
    assert sm.settings.retract == 0.08 * robot.l and sm.settings.arm == 0.3 * robot.l
    default = StepEvaluator(pl.params, pl.config, TerrainMap("flat")).settings
    assert (default.retract, default.arm) == (0.05 * robot.l, 0.1 * robot.l)


def test_the_total_violation_is_infinite_without_a_warning_where_its_sum_overflows():
    g = np.array([[0.5, -0.25, -1.0], [1.0, 2.0, 0.0], [-1e308, -1e308, 1.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # SLSQP's stall test met such points: one warning each
        assert violation(g[0]) == 1.25 and violation(g[1]) == 0.0
        assert violation(g[2]) == np.inf
        np.testing.assert_array_equal(violation(g, axis=1), [1.25, 0.0, np.inf])
