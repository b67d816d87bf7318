"""The planner's entry point: plans from scanned heights, infeasible terrain and malformed input."""

import numpy as np
import pytest

from controllers.planner import PlanningError, TerrainMap
from envs.physics.terrain import Terrain

from .cases import PAPER_STAIRS


def test_plan_from_scanned_heights_matches_the_true_terrain(planners):
    pl = planners["paper"]
    g = pl.periodic_gait()
    xs = np.arange(-0.2, 1.6, 0.01)
    scan = TerrainMap.from_scan(xs, PAPER_STAIRS.height(xs))
    a = pl.plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=5)
    b = pl.plan(scan, (g.q, g.qd), (0.0, 0.0), horizon=5)
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
