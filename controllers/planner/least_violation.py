"""The least-violating steps: what the planner offers when no feasible step exists.

When even the relaxed step problems have no feasible solution, the robot still needs a motion
to track (zero input would let it fall). For each step along a short horizon this picks, among
the candidate footholds, the step whose constraints are violated least: the free Bezier
coefficients minimise the weighted sum of squared violations (``scipy.optimize.least_squares``
from the best point of the coarse global search), the step's cost breaking ties. The weights
rank what matters for a step that is still to be tracked: the swing foot's geometry first (a
trip ends the walk), then the motion along the constraint (``theta_dot^2``, the reduced
inertia, the stance foot and the impact), then the hip input (the feedback saturates), then the
duration.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from ..bezier import BezierConstraint, chord_coefficients
from .footholds import touchdown_configuration
from .plan import StepPlan
from .problem import (
    CONSTRAINT_GROUPS,
    MIN_PHASE_SPAN,
    BatchProblem,
    BudgetExhausted,
    FixedStep,
    batch_row,
    shape_guess,
    worst_violation,
)
from .search import StepSearch, _global_samples

__all__ = ["VIOLATION_WEIGHTS", "least_violation_steps"]

#: weight of each constraint group's violations (groups not named: 1)
VIOLATION_WEIGHTS = {
    "clearance": 30.0,
    "armed": 30.0,
    "faces": 30.0,
    "touchdown": 30.0,
    "trailing_foot": 30.0,
    "thetadot_sq": 10.0,
    "alpha": 10.0,
    "stance_reaction": 10.0,
    "impact": 10.0,
    "post_impact_speed": 10.0,
    "torque": 1.0,
    "duration": 0.1,
}
_LSQ_EVALUATIONS = 40  # residual evaluations of each least-squares refinement


def least_violation_steps(
    search: StepSearch, start: tuple[float, float, float, float], stance: tuple[float, float]
) -> tuple[list[StepPlan], list[tuple[float, str]]]:
    """Up to ``search.horizon`` least-violating steps from ``start = (theta_plus, a_0,
    phi'(theta_plus), theta_dot_plus)`` [rad, rad, -, rad/s] with the stance foot at ``stance``
    [m], and each step's ``(worst violation, constraint)``. The sequence stops early at a step
    along which ``theta_dot`` would not stay positive (no motion to track), or when the search
    budget is spent; it may be empty."""
    steps: list[StepPlan] = []
    worst: list[tuple[float, str]] = []
    for j in range(search.horizon):
        try:
            best = _least_violating_step(search, j, start, stance)
        except BudgetExhausted:
            break
        if best is None:
            break
        step, viol = best
        steps.append(step)
        worst.append(viol)
        start = (
            step.theta_minus - step.coeffs[-1],
            -step.coeffs[-1],
            step.slope_plus,
            step.delta * step.thetadot_minus,
        )
        stance = step.foothold
        if not (math.isfinite(start[3]) and start[3] > 0):
            break
    return steps, worst


def _least_violating_step(
    search: StepSearch, j: int, start: tuple, stance: tuple[float, float]
) -> tuple[StepPlan, tuple[float, str]] | None:
    cfg, sm, l = search.config, search.model, search.params.l  # noqa: E741
    th_p, a0, slope, thd = start
    cx, cy, order, why = search._candidates(
        stance, th_p, search.horizon - 1 - j, None, cfg.candidates
    )
    best: tuple[tuple[float, float], StepPlan, tuple[float, str]] | None = None
    sm.wscale = 1.0
    for i in order:
        fh = (float(cx[i]), float(cy[i]))
        q1m, q2m = touchdown_configuration(fh[0] - stance[0], fh[1] - stance[1], l)
        if not q2m > th_p + MIN_PHASE_SPAN:
            continue
        fx = search.fixed_step(j, start, stance, fh, q1m, q2m)
        ev, score = _minimise_violation(search, fx)
        if not np.all(np.isfinite(ev["f"])) or np.min(ev["f"]) <= 0:
            continue  # theta_dot reaches zero: no motion along this step to track
        if best is None or score < best[0]:
            c = BezierConstraint(ev["a"], th_p, q2m)
            step = StepPlan(j, search.P, c, thd, stance, fh, cfg.grid, ev["arm_theta"])
            step.note = why  # the riser margins relaxed (else empty)
            best = (score, step, worst_violation(ev["groups"]))
    return None if best is None else (best[1], best[2])


def _minimise_violation(search: StepSearch, fx: FixedStep) -> tuple[dict, tuple[float, float]]:
    """The free coefficients of step ``fx`` with the least weighted violation; returns the
    step's evaluation there and its score ``(weighted squared violation, cost)``."""
    sm, order = search.model, search.config.order
    weights: np.ndarray | None = None

    def batch(X):
        nonlocal weights
        ev = sm.evaluate_batch(fx, X)
        G = ev["groups"].G
        if weights is None:
            weights = np.concatenate(
                [
                    np.full(n, VIOLATION_WEIGHTS.get(grp.name, 1.0))
                    for grp, n in zip(CONSTRAINT_GROUPS, np.diff(ev["groups"].offsets))
                ]
            )
        return ev["cost"], np.nan_to_num(G * weights, nan=-1e3), ev

    prob = BatchProblem(batch, search.evaluations)

    def residual(x):
        return np.minimum(prob.get(x)[1], 0.0)

    def jacobian(x):
        g = prob.get(x)[1]
        return prob._jacobians(x)[1] * (g < 0)[:, None]

    def score(x):
        c, g, _, _ = prob.get(x)
        with np.errstate(over="ignore"):  # far outside the constraints: inf
            return (float(np.sum(np.minimum(g, 0.0) ** 2)), c)

    chord = fx.a_last - fx.a0
    base = chord_coefficients(fx.a0, fx.a_last, np.arange(2, order), order)
    x0 = shape_guess(sm.ref.shape, fx.a0, fx.a_last, order)
    starts = np.vstack([x0, base + chord * _global_samples(order)])
    prob.evaluate_many(starts)
    xs = min(starts, key=score)
    if score(xs)[0] > 0:
        res = least_squares(
            residual, xs, jac=jacobian, method="trf", max_nfev=_LSQ_EVALUATIONS, x_scale=1.0
        )
        if score(res.x) < score(xs):
            xs = res.x
    _, _, ev, r = prob.get(xs)
    return batch_row(ev, r), score(xs)
