"""The planner's search budget (anytime searches) and its least-violating steps."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlanningError
from envs.physics.terrain import Terrain

from .test_plan import rollout

# a 2 cm rise the paper robot cannot climb from its gait: every search fails
WALL = Terrain.stairs([0.33], [0.02])
LARGEST_BATCH = 82  # the coarse global search: 81 samples and the start


def failing_search(planner, gait, **kwargs):
    with pytest.raises(PlanningError) as info:
        planner.plan(WALL, (gait.q, gait.qd), (0.0, 0.0), horizon=4, **kwargs)
    return info.value


def test_the_evaluation_budget_bounds_a_failing_search(planners):
    gait = planners["paper"].periodic_gait()
    # replanning (a previous plan to fall back on): the planner's budget applies (to the
    # depth-first search; the beam search after it has its own, test_beam.py)
    pl = GaitPlanner("paper", {"max_evaluations": 1000, "beam_width": 0})
    previous = pl.plan(Terrain.flat(), (gait.q, gait.qd), (0.0, 0.0), horizon=4)
    cut = failing_search(pl, gait, previous_plan=previous)
    assert cut.budget_exhausted and "search budget exhausted" in str(cut)
    assert 1000 <= cut.evaluations < 1000 + LARGEST_BATCH
    # the same cut from the same inputs (a fresh planner: pl now holds reusable step solutions)
    again = failing_search(
        GaitPlanner("paper", {"max_evaluations": 1000, "beam_width": 0}),
        gait,
        previous_plan=previous,
    )
    assert (again.evaluations, again.step, str(again)) == (cut.evaluations, cut.step, str(cut))
    # a call may set its own budget (also for a plan from scratch)
    small = failing_search(pl, gait, max_evaluations=300)
    assert small.budget_exhausted and 300 <= small.evaluations < 300 + LARGEST_BATCH


def test_a_failed_search_keeps_the_feasible_steps_before_the_failure(planners):
    gait = planners["paper"].periodic_gait()
    exc = failing_search(planners["paper"], gait)  # from scratch: the whole search
    assert not exc.budget_exhausted and exc.evaluations > 3000  # what the budgets above cut
    assert exc.step >= 1 and len(exc.partial) == exc.step
    stance = (0.0, 0.0)
    for j, s in enumerate(exc.partial):  # a chain of steps from the start
        assert s.index == j and s.stance_foot == stance
        stance = s.foothold


def test_budget_settings_are_validated():
    for bad in ({"max_evaluations": 0}, {"time_budget": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            GaitPlanner("paper", bad)
    with pytest.raises(ValueError, match="max_evaluations"):
        GaitPlanner("paper").plan(Terrain.flat(), ((0.5, -0.2), (1, 1)), (0, 0), 2, None, 0)


def test_relaxed_and_least_violating_plans_follow_open_loop_pfl(planners):
    """The relaxed planner's plan and the least-violating steps are consistent plans: PFL
    (v = 0) in the nonlinear model follows them (touchdown time, phase and foothold)."""
    base = planners["paper"]
    gait = base.periodic_gait()
    relaxed = base.relaxed(torque_fraction=1.0)
    assert relaxed.periodic_gait() is gait
    terrain = Terrain.stairs([0.33], [0.01])
    plan = relaxed.plan(terrain, (gait.q, gait.qd), (0.0, 0.0), horizon=3)
    lv = relaxed.plan_least_violation(WALL, (gait.q, gait.qd), (0.0, 0.0), horizon=2)
    assert len(lv) >= 1 and lv.evaluations > 0
    assert all(w <= 0 and isinstance(name, str) for w, name in lv.violations)
    for p, t in ((plan, terrain), (lv, WALL)):
        for j, r in enumerate(rollout(relaxed, p, t, nsteps=len(p))):
            assert r["y"] < 1e-6 and r["thd_err"] < 1e-5, (j, r)
            assert r["time_err"] < 1e-5 and r["foot_err"] < 1e-5, (j, r)
    with pytest.raises(ValueError, match="no_such_field"):
        base.relaxed(no_such_field=1.0)
    assert np.all(np.isfinite([s.duration for s in lv]))


def test_a_process_time_bound_stops_the_search(planners):
    """The optional time bound (off by default; it bounds replanning calls like the evaluation
    budget): a bound already spent when the search starts stops it before its first
    evaluation."""
    gait = planners["paper"].periodic_gait()
    pl = GaitPlanner("paper", {"time_budget": 1e-12})
    previous = planners["paper"].plan(Terrain.flat(), (gait.q, gait.qd), (0.0, 0.0), horizon=2)
    with pytest.raises(PlanningError) as info:
        pl.plan(Terrain.flat(), (gait.q, gait.qd), (0.0, 0.0), horizon=2, previous_plan=previous)
    assert info.value.budget_exhausted and info.value.evaluations == 0
