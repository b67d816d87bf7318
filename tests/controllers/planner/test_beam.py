"""The beam search over the horizon (footholds and step speeds chosen jointly)."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlannerConfig, PlanningError
from controllers.planner.footholds import TerrainMap
from controllers.planner.problem import FixedStep, StepEvaluator
from envs.physics.terrain import Terrain

from .test_budget import WALL
from .test_plan import rollout

HORIZON, BUDGET = 4, 2000  # the reference controller's look-ahead and replanning budget
FULL = {"beam_width": 32, "beam_coarse": 0}  # the full beam alone (no coarse pass first)


def plan_blocks(course, **settings):
    return GaitPlanner("paper", settings).plan(
        course.terrain(), course.state, course.stance, horizon=HORIZON, max_evaluations=BUDGET
    )


class BlocksBeforeARise:
    """Random blocks at difficulty 2 (a validation course of the reference policy): from a
    stance foot on a block 2 mm up, drops of 7, 8 and 8 mm, then an 11 mm rise at 1.09 m; and
    the post-impact ``state`` of the footstep where the replanning search found no plan over
    the horizon and the beam search did."""

    edges = [0.3, 0.46156, 0.56499, 0.80515, 0.93349, 1.08618, 1.30339, 1.58768, 1.77266]
    heights = [
        0.0, -0.00993, 0.00216, -0.00476, -0.01282, -0.02035, -0.00905, -0.00961, -0.01177,
        -0.00656,
    ]  # fmt: skip
    state = (
        (-0.47306500527909323, -0.31441765073675415),
        (0.26451146550408317, 0.9036367215039772),
    )
    stance = (0.509051388270713, 0.00216)

    def terrain(self) -> Terrain:
        return Terrain.stairs(self.edges, np.diff(self.heights).tolist())


def assert_feasible_chain(pl, plan, course):
    """The plan is a chain of steps from the course's actual state, each feasible under every
    constraint of the step problem."""
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


def assert_followed(pl, plan, course):
    """The nonlinear model follows the plan under PFL (touchdown time, phase and foothold)."""
    for j, r in enumerate(rollout(pl, plan, course.terrain(), nsteps=len(plan))):
        assert r["y"] < 1e-6 and r["thd_err"] < 1e-5, (j, r)
        assert r["time_err"] < 1e-5 and r["foot_err"] < 1e-5, (j, r)


def test_the_beam_plans_the_horizon_where_the_depth_first_search_stops_short(rise_after_drops):
    course = rise_after_drops
    with pytest.raises(PlanningError) as info:
        plan_blocks(course, beam_width=0)
    partial = info.value.partial
    assert info.value.step == HORIZON - 1 and len(partial) == HORIZON - 1
    plan = plan_blocks(course, **FULL)
    assert plan.beam and len(plan) == HORIZON
    assert BUDGET < plan.evaluations <= BUDGET + PlannerConfig().beam_evaluations + 100
    # the beam's evaluations are counted apart (its own budget): the rest is the depth-first
    # search's, within the call's budget
    assert 0 < plan.beam_evaluations <= PlannerConfig().beam_evaluations + 65
    assert plan.evaluations - plan.beam_evaluations <= BUDGET + 100
    pl = GaitPlanner("paper", FULL)
    assert_feasible_chain(pl, plan, course)
    # the steps shed the speed gained down the drops: the last block before the rise is
    # reached slower than by the depth-first search's steps, whose next step found no shape
    # within the hip's torque reserve
    assert plan[-1].foothold == partial[-1].foothold
    assert plan[-1].thetadot_minus < partial[-1].thetadot_minus - 0.05
    # sampled, not optimised: the steps keep inside the torque reserve (0.8 u_max)
    reserve = pl.config.torque_fraction * pl.params.u_max
    assert max(float(np.max(np.abs(s.input_grid))) for s in plan) <= reserve + 1e-9
    assert_followed(pl, plan, course)


def test_the_beam_is_deterministic_and_bounded_by_its_budget(rise_after_drops):
    course = rise_after_drops
    a, b = plan_blocks(course, **FULL), plan_blocks(course, **FULL)
    for s, t in zip(a, b):
        assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold
    # a budget too small to reach the horizon: the search fails, keeping its deepest steps
    with pytest.raises(PlanningError) as info:
        plan_blocks(course, **FULL, beam_evaluations=300)
    exc = info.value
    assert not exc.partial or len(exc.partial) < HORIZON
    assert exc.evaluations <= BUDGET + 100 + 300 + 100
    assert 0 < exc.beam_evaluations <= 300 + 65
    assert exc.evaluations - exc.beam_evaluations <= BUDGET + 100


def test_a_coarse_beam_pass_plans_the_horizon_for_a_fraction_of_the_evaluations():
    """With ``beam_coarse`` (the paper robot's default: 8) the beam first tries 8 of each set of
    shapes: where that spans the horizon it is the plan (feasible, followed under PFL), on the
    same footholds as the full beam's here, for under a quarter of its evaluations."""
    course = BlocksBeforeARise()
    full = plan_blocks(course, **FULL)
    coarse = plan_blocks(course)
    assert GaitPlanner("paper").config.beam_coarse == 8
    assert full.beam and coarse.beam and len(full) == len(coarse) == HORIZON
    assert [s.foothold for s in coarse] == [s.foothold for s in full]
    assert 0 < 4 * coarse.beam_evaluations < full.beam_evaluations
    pl = GaitPlanner("paper", {"beam_width": 32, "beam_coarse": 8})
    assert_feasible_chain(pl, coarse, course)
    assert_followed(pl, coarse, course)


def test_where_the_coarse_pass_spans_no_horizon_the_full_beam_plans(rise_after_drops):
    """No coarse pass spans the horizon before the 13 mm rise: the full beam then runs with the
    evaluations left and plans what the full beam alone plans; the call spends both passes'
    evaluations, within the beam's budget."""
    full = plan_blocks(rise_after_drops, **FULL)
    budget = PlannerConfig().beam_evaluations
    for shapes in (1, 8):
        plan = plan_blocks(rise_after_drops, beam_width=32, beam_coarse=shapes)
        assert plan.beam and len(plan) == HORIZON
        for s, t in zip(plan, full):
            assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold
        assert full.beam_evaluations < plan.beam_evaluations <= budget + 2 * 65


def test_with_beam_full_0_the_coarse_pass_is_the_whole_beam(rise_after_drops):
    """``beam_full: 0``: where the coarse pass spans no horizon the call fails with that pass's
    evaluations only (the full beam is not tried); where it spans, the plan is the same as
    with the full pass allowed (it never ran)."""
    two = plan_blocks(rise_after_drops, beam_width=32, beam_coarse=8)
    with pytest.raises(PlanningError) as one:
        plan_blocks(rise_after_drops, beam_width=32, beam_coarse=8, beam_full=0)
    coarse_only = one.value.beam_evaluations
    assert 0 < coarse_only < two.beam_evaluations
    assert coarse_only <= PlannerConfig().beam_evaluations + 65
    course = BlocksBeforeARise()
    spans = plan_blocks(course, beam_full=0)
    same = plan_blocks(course)
    assert spans.beam and len(spans) == HORIZON
    assert spans.beam_evaluations == same.beam_evaluations
    for s, t in zip(spans, same):
        assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold


def test_with_beam_far_0_a_beam_step_tries_the_gaits_shape_and_those_near_it():
    """``beam_far: 0`` (the paper robot's default; the dataclass's and the classic walker's is
    1): each foothold a beam step tries costs the gait's shape and the near set (1 + 8 rows in
    the coarse pass, against 1 + 2 x 8 with the far set), and on a course whose plan the coarse
    pass finds from near shapes the plan is the same."""
    assert GaitPlanner("paper").config.beam_far == 0
    assert PlannerConfig().beam_far == 1 and GaitPlanner("classic").config.beam_far == 1
    course = BlocksBeforeARise()
    near = plan_blocks(course, beam_full=0)
    both = plan_blocks(course, beam_full=0, beam_far=1)
    assert near.beam and both.beam and len(near) == len(both) == HORIZON
    assert near.beam_evaluations % 9 == 0 and both.beam_evaluations % 17 == 0
    assert near.beam_evaluations < both.beam_evaluations
    for s, t in zip(near, both):
        assert np.array_equal(s.coeffs, t.coeffs) and s.foothold == t.foothold


def test_terrain_no_sequence_crosses_still_raises_naming_the_step(planners):
    gait = planners["paper"].periodic_gait()
    pl = GaitPlanner("paper", {"beam_width": 8, "beam_evaluations": 5000})
    with pytest.raises(PlanningError, match="planning failed at step") as info:
        pl.plan(WALL, (gait.q, gait.qd), (0.0, 0.0), horizon=4, max_evaluations=500)
    assert 1 <= len(info.value.partial) < 4 or info.value.partial == []


@pytest.mark.parametrize(
    "bad",
    [
        {"beam_width": -1},
        {"beam_footholds": 0},
        {"beam_speeds": -1},
        {"beam_evaluations": 0},
        {"beam_coarse": -1},
        {"beam_coarse": 33},
        {"beam_full": -1},
        {"beam_full": 2},
        {"beam_far": -1},
        {"beam_far": 2},
    ],
)
def test_beam_settings_are_validated(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        PlannerConfig(**bad)


def test_a_call_may_give_the_beam_less_than_its_budget(rise_after_drops):
    """``max_beam_evaluations`` caps the call's beam search below ``beam_evaluations`` (the
    same plan as that budget set in the config), 0 runs none (the depth-first search's
    failure is raised), and a value out of range is refused."""
    course = rise_after_drops
    pl = GaitPlanner("paper", FULL)

    def plan(**kwargs):
        return pl.plan(
            course.terrain(), course.state, course.stance, horizon=HORIZON,
            max_evaluations=BUDGET, **kwargs,
        )  # fmt: skip

    with pytest.raises(PlanningError) as capped:
        plan(max_beam_evaluations=300)
    with pytest.raises(PlanningError) as configured:
        plan_blocks(course, **FULL, beam_evaluations=300)
    assert 0 < capped.value.beam_evaluations <= 300 + 65
    assert capped.value.beam_evaluations == configured.value.beam_evaluations
    assert [s.foothold for s in capped.value.partial] == [
        s.foothold for s in configured.value.partial
    ]
    with pytest.raises(PlanningError) as none:
        plan(max_beam_evaluations=0)
    assert none.value.beam_evaluations == 0 and none.value.evaluations <= BUDGET + 100
    assert plan(max_beam_evaluations=10**9).beam  # at most the config's: the whole beam
    with pytest.raises(ValueError, match="max_beam_evaluations"):
        plan(max_beam_evaluations=-1)
