"""The planner's entry point: plans from scanned heights, infeasible terrain and malformed input."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlanningError, TerrainMap
from envs.physics.terrain import Terrain

from .cases import PAPER_STAIRS


def test_plan_from_scanned_heights_matches_the_true_terrain(planners):
    """A map from heights scanned every 1 cm puts every foothold at the true ground's height.
    Without the speed reserve before drops the plan is the true terrain's to the scan's
    spacing; with it (the preset) the map's edges, 5 mm off at most, tip the choice between
    two foothold chains near the first stair (two steps on the top or three), both feasible."""
    xs = np.arange(-0.2, 1.6, 0.01)
    scan = TerrainMap.from_scan(xs, PAPER_STAIRS.height(xs))
    for pl in (GaitPlanner("paper", {"end_thetadot_floor": 0.0}), planners["paper"]):
        g = pl.periodic_gait()
        a = pl.plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=5)
        b = pl.plan(scan, (g.q, g.qd), (0.0, 0.0), horizon=5)
        np.testing.assert_allclose(b.footholds[:, 1], PAPER_STAIRS.height(b.footholds[:, 0]))
        np.testing.assert_allclose(b.footholds[0], a.footholds[0])
        if pl.config.end_thetadot_floor == 0.0:
            np.testing.assert_allclose(b.footholds[:, 1], a.footholds[:, 1])
            np.testing.assert_allclose(b.footholds[:, 0], a.footholds[:, 0], atol=0.011)


@pytest.mark.parametrize(
    "terrain,step",
    [
        (Terrain.stairs([0.4], [0.3]), 2),  # a wall
        (Terrain.stairs([0.4], [-1.0]), 2),  # a drop far beyond the leg length
    ],
)
def test_infeasible_terrain_raises_planning_error(planners, terrain, step):
    pl = planners["paper"]
    g = pl.periodic_gait()
    with pytest.raises(PlanningError) as err:
        pl.plan(terrain, (g.q, g.qd), (0.0, 0.0), horizon=5)
    assert err.value.step >= step  # the footholds before the obstacle are planned
    assert err.value.constraint == "foothold"
    assert "no admissible foothold" in str(err.value)


def test_bad_state_raises(planners):
    pl = planners["paper"]
    with pytest.raises(PlanningError, match="theta_dot"):
        pl.plan("flat", (np.array([-0.4, -0.2]), np.array([0.1, -0.5])), (0.0, 0.0))
    with pytest.raises(ValueError, match="state"):
        pl.plan("flat", (np.array([np.nan, 0.0]), np.array([0.1, 0.5])), (0.0, 0.0))


# a slowed robot mid-step before the paper's first stair (a replan within a step): past
# vertical at 0.385 rad/s, the foot 2 cm before the edge; relaxed as the replans within a step
# are (TUBE_FALLBACKS)
SLOWED = (np.array([-0.344, 0.048]), np.array([0.468, 0.385]))
TUBE_RELAXED = {"duration_min": 0.05, "torque_fraction": 1.0}


@pytest.mark.parametrize("scaling", [0, 1])
def test_the_speed_reserve_keeps_a_replan_from_slowing_the_robot_further(scaling):
    """Without the reserve the plan from the slowed state lets theta_dot fall below the 0.385
    rad/s it starts with (to about 0.35) before the long step down; with a reserve above the
    start speed no such plan is admissible and the planner says which constraint fails; a
    reserve below what the plan keeps anyway changes nothing: bit for bit with unscaled
    solves, to the last digits with scaled ones (the preset's), which carry the inactive
    bound's row through their subproblems."""
    q, qd = SLOWED
    relaxed = {**TUBE_RELAXED, "gauss_newton_scaling": scaling}
    plain = GaitPlanner("paper", relaxed).plan(PAPER_STAIRS, SLOWED, (0.379, 0.0), horizon=3)
    least = float(np.sqrt(plain.steps[0].thetadot_sq_grid.min()))
    assert 0.3 < least < qd[1] - 0.02
    with pytest.raises(PlanningError) as err:
        GaitPlanner("paper", {**relaxed, "speed_reserve": 0.4}).plan(
            PAPER_STAIRS, SLOWED, (0.379, 0.0), horizon=3
        )
    assert err.value.step == 0
    assert err.value.constraint == "theta_dot^2 bounded away from zero"
    low = GaitPlanner("paper", {**relaxed, "speed_reserve": 0.3})
    same = low.plan(PAPER_STAIRS, SLOWED, (0.379, 0.0), horizon=3)
    if scaling:
        np.testing.assert_allclose(same.steps[0].coeffs, plain.steps[0].coeffs, rtol=1e-6)
    else:
        np.testing.assert_array_equal(same.steps[0].coeffs, plain.steps[0].coeffs)


def test_the_speed_reserve_bounds_the_first_step_only(planners):
    """From the periodic gait's post-impact state (about 0.9 rad/s) a reserve of 0.6 rad/s
    holds over the first step, which without it passes mid-stance at the gait's 0.55 rad/s;
    the steps after it plan the stairs' drops as without it, down to well below 0.6 rad/s."""
    g = planners["paper"].periodic_gait()

    def least(config: dict) -> list[float]:
        plan = GaitPlanner("paper", config).plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=5)
        return [float(np.sqrt(s.thetadot_sq_grid.min())) for s in plan.steps]

    plain, reserved = least({}), least({"speed_reserve": 0.6})
    assert g.qd[1] > 0.6
    assert plain[0] < 0.58
    assert reserved[0] >= 0.6 - 1e-6
    assert min(reserved[1:]) < 0.5


@pytest.mark.parametrize("scaling", [0, 1])
def test_the_dip_floor_bounds_every_step_by_its_own_start_speed(planners, scaling):
    """From the periodic gait's state the paper's second step down passes its apex at about
    42 % of the theta_dot it starts with. A dip floor of 0.5 holds every step of the plan at or
    above half its own start speed (that step's bound active, a look-ahead step's start being
    the plan's own); the steps that kept it anyway are planned as before (to 1e-6 with unscaled
    solves; with scaled ones, the preset's, within the solver's tolerance: 1e-7 on the cost,
    whose flattest directions the scaling stretches, so their speeds agree far closer than
    their shapes); a floor of 0.7 leaves the first step no plan within the actuator, a
    PlanningError at step 0; 0 changes nothing, bit for bit."""
    g = planners["paper"].periodic_gait()

    def plan(config: dict):
        config = {**config, "gauss_newton_scaling": scaling}
        return GaitPlanner("paper", config).plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=5)

    def ratios(p) -> np.ndarray:
        return np.array([np.sqrt(s.thetadot_sq_grid.min()) / s.thetadot_plus for s in p.steps])

    plain, floored = plan({}), plan({"dip_floor": 0.5})
    r0, r1 = ratios(plain), ratios(floored)
    assert r0.min() < 0.45
    assert r1.min() >= 0.5 - 1e-6
    assert abs(r1[np.argmin(r0)] - 0.5) < 1e-3  # the bound is what shapes that step
    keep = r0 >= 0.5
    assert keep.sum() >= 3
    for a, b in zip(np.array(plain.steps)[keep], np.array(floored.steps)[keep]):
        np.testing.assert_allclose(b.coeffs, a.coeffs, atol=1e-3 if scaling else 1e-6)
        assert b.thetadot_minus == pytest.approx(a.thetadot_minus, rel=1e-4)
    np.testing.assert_array_equal(plan({"dip_floor": 0.0}).steps[-1].coeffs, plain.steps[-1].coeffs)
    with pytest.raises(PlanningError) as err:
        plan({"dip_floor": 0.7})
    assert err.value.step == 0


def test_a_planner_keeps_the_map_of_a_terrain_it_plans_on_again(planners):
    """Planning again on a terrain equal to the last one (a controller's map at every footstep)
    reuses its map, and the plan is the one a fresh planner makes; another terrain gets its
    own map."""
    planner = GaitPlanner("paper")
    g = planner.periodic_gait()
    stairs = Terrain.stairs([0.4, 0.62], [-0.01, -0.01])
    first = planner.plan(stairs, (g.q, g.qd), (0.0, 0.0), horizon=3)
    again = Terrain.from_dict(stairs.to_dict())
    assert again is not stairs
    assert planner._terrain_map(again) is planner._terrain_map(stairs)
    assert planner._terrain_map(Terrain.flat()) is not planner._terrain_map(stairs)
    second = planner.plan(again, (g.q, g.qd), (0.0, 0.0), horizon=3)
    fresh = GaitPlanner("paper").plan(again, (g.q, g.qd), (0.0, 0.0), horizon=3)
    for a, b, c in zip(first.steps, second.steps, fresh.steps, strict=True):
        assert np.array_equal(a.coeffs, b.coeffs) and np.array_equal(b.coeffs, c.coeffs)
