"""The beam search over the horizon (footholds and step speeds chosen jointly)."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlannerConfig, PlanningError
from controllers.planner.footholds import TerrainMap
from controllers.planner.problem import FixedStep, StepEvaluator

from .test_budget import WALL
from .test_plan import rollout

HORIZON, BUDGET = 4, 2000  # the reference controller's look-ahead and replanning budget


def plan_blocks(course, **settings):
    return GaitPlanner("paper", settings).plan(
        course.terrain(), course.state, course.stance, horizon=HORIZON, max_evaluations=BUDGET
    )


def test_the_beam_plans_the_horizon_where_the_depth_first_search_stops_short(rise_after_drops):
    course = rise_after_drops
    with pytest.raises(PlanningError) as info:
        plan_blocks(course, beam_width=0)
    partial = info.value.partial
    assert info.value.step == HORIZON - 1 and len(partial) == HORIZON - 1
    plan = plan_blocks(course, beam_width=32)
    assert plan.beam and len(plan) == HORIZON
    assert BUDGET < plan.evaluations <= BUDGET + PlannerConfig().beam_evaluations + 100
    # the beam's evaluations are counted apart (its own budget): the rest is the depth-first
    # search's, within the call's budget
    assert 0 < plan.beam_evaluations <= PlannerConfig().beam_evaluations + 65
    assert plan.evaluations - plan.beam_evaluations <= BUDGET + 100
    # a chain of steps from the actual state, each feasible under every constraint
    pl = GaitPlanner("paper", {"beam_width": 32})
    ev = StepEvaluator(pl.params, pl.config, TerrainMap(course.terrain()))
    stance, thd = course.stance, course.state[1][1]
    for j, s in enumerate(plan):
        assert s.index == j and s.stance_foot == stance
        assert s.thetadot_plus == pytest.approx(thd, rel=1e-12)
        fx = FixedStep(
            s.theta_plus,
            s.coeffs[0],
            s.constraint.dphi(s.theta_plus),
            s.thetadot_plus,
            s.stance_foot,
            s.foothold,
            s.theta_minus,
            s.coeffs[-1],
        )
        g = ev.evaluate(fx, s.coeffs[2:-1])["g"]
        assert np.min(g) >= -1e-7, (j, float(np.min(g)))
        stance, thd = s.foothold, s.delta * s.thetadot_minus
    # the steps shed the speed gained down the drops: the last block before the rise is
    # reached slower than by the depth-first search's steps, whose next step found no shape
    # within the hip's torque reserve
    assert plan[-1].foothold == partial[-1].foothold
    assert plan[-1].thetadot_minus < partial[-1].thetadot_minus - 0.05
    # sampled, not optimised: the steps keep inside the torque reserve (0.8 u_max)
    reserve = pl.config.torque_fraction * pl.params.u_max
    assert max(float(np.max(np.abs(s.input_grid))) for s in plan) <= reserve + 1e-9
    # and the nonlinear model follows them under PFL (touchdown time, phase and foothold)
    for j, r in enumerate(rollout(pl, plan, course.terrain(), nsteps=HORIZON)):
        assert r["y"] < 1e-6 and r["thd_err"] < 1e-5, (j, r)
        assert r["time_err"] < 1e-5 and r["foot_err"] < 1e-5, (j, r)


def test_the_beam_is_deterministic_and_bounded_by_its_budget(rise_after_drops):
    course = rise_after_drops
    a, b = plan_blocks(course, beam_width=32), plan_blocks(course, beam_width=32)
    for s, t in zip(a, b):
        assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold
    # a budget too small to reach the horizon: the search fails, keeping its deepest steps
    with pytest.raises(PlanningError) as info:
        plan_blocks(course, beam_width=32, beam_evaluations=300)
    exc = info.value
    assert not exc.partial or len(exc.partial) < HORIZON
    assert exc.evaluations <= BUDGET + 100 + 300 + 100
    assert 0 < exc.beam_evaluations <= 300 + 65
    assert exc.evaluations - exc.beam_evaluations <= BUDGET + 100


def test_terrain_no_sequence_crosses_still_raises_naming_the_step(planners):
    gait = planners["paper"].periodic_gait()
    pl = GaitPlanner("paper", {"beam_width": 8, "beam_evaluations": 5000})
    with pytest.raises(PlanningError, match="planning failed at step") as info:
        pl.plan(WALL, (gait.q, gait.qd), (0.0, 0.0), horizon=4, max_evaluations=500)
    assert 1 <= len(info.value.partial) < 4 or info.value.partial == []


@pytest.mark.parametrize(
    "bad", [{"beam_width": -1}, {"beam_footholds": 0}, {"beam_speeds": -1}, {"beam_evaluations": 0}]
)
def test_beam_settings_are_validated(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        PlannerConfig(**bad)
