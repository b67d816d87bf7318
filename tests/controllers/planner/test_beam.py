"""The beam search over the horizon (footholds and step speeds chosen jointly)."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlannerConfig, PlanningError
from controllers.planner.footholds import TerrainMap
from controllers.planner.problem import FixedStep, StepEvaluator
from envs.physics.terrain import Terrain

from .test_budget import WALL
from .test_plan import rollout

# random blocks at difficulty 2 (a validation course of the reference policy): three drops of
# 6, 11 and 14 mm, then a 13 mm rise on a block 0.22 m wide
EDGES = [0.3, 0.4752, 0.7189, 0.8735, 1.0909, 1.3786, 1.598, 1.8576]
HEIGHTS = [0.0, -0.00598, -0.01735, -0.03164, -0.01885, -0.02697, -0.0339, -0.02885, -0.02642]
BLOCKS = Terrain.stairs(EDGES, np.diff(HEIGHTS).tolist())
# the post-impact state and stance foot of the footstep where the replanning search first found
# only three of its four steps (the robot descending, 0.89 rad/s)
STATE = ((-0.39099489784414365, -0.1923186271042424), (-0.028842415109954597, 0.889456164095743))
STANCE = (0.27751934145834933, 0.0)
HORIZON, BUDGET = 4, 2000  # the reference controller's look-ahead and replanning budget


def plan_blocks(**settings):
    return GaitPlanner("paper", settings).plan(
        BLOCKS, STATE, STANCE, horizon=HORIZON, max_evaluations=BUDGET
    )


def test_the_beam_plans_the_horizon_where_the_depth_first_search_stops_short():
    with pytest.raises(PlanningError) as info:
        plan_blocks(beam_width=0)
    partial = info.value.partial
    assert info.value.step == HORIZON - 1 and len(partial) == HORIZON - 1
    plan = plan_blocks(beam_width=32)
    assert plan.beam and len(plan) == HORIZON
    assert BUDGET < plan.evaluations <= BUDGET + PlannerConfig().beam_evaluations + 100
    # a chain of steps from the actual state, each feasible under every constraint
    pl = GaitPlanner("paper", {"beam_width": 32})
    ev = StepEvaluator(pl.params, pl.config, TerrainMap(BLOCKS))
    stance, thd = STANCE, STATE[1][1]
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
    # and the nonlinear model follows them under PFL (touchdown time, phase and foothold)
    for j, r in enumerate(rollout(pl, plan, BLOCKS, nsteps=HORIZON)):
        assert r["y"] < 1e-6 and r["thd_err"] < 1e-5, (j, r)
        assert r["time_err"] < 1e-5 and r["foot_err"] < 1e-5, (j, r)


def test_the_beam_is_deterministic_and_bounded_by_its_budget():
    a, b = plan_blocks(beam_width=32), plan_blocks(beam_width=32)
    for s, t in zip(a, b):
        assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold
    # a budget too small to reach the horizon: the search fails, keeping its deepest steps
    with pytest.raises(PlanningError) as info:
        plan_blocks(beam_width=32, beam_evaluations=300)
    exc = info.value
    assert not exc.partial or len(exc.partial) < HORIZON
    assert exc.evaluations <= BUDGET + 100 + 300 + 100


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
