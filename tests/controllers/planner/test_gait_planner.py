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
