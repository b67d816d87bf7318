"""Planner settings: validation and the robot presets; the planner's failure."""

import copy
import pickle

import pytest

from controllers.planner import GaitPlanner, PlannerConfig, PlanningError
from envs.physics import RobotParams


def test_bad_config_raises():
    with pytest.raises(ValueError, match="unknown planner setting"):
        PlannerConfig.from_dict({"speed": 1.0})
    with pytest.raises(ValueError, match="target_speed"):
        PlannerConfig(target_speed=-1.0)
    with pytest.raises(ValueError, match="order"):
        PlannerConfig(order=3)
    with pytest.raises(ValueError, match="step_min"):
        PlannerConfig(step_min=0.3, step_length=0.2)
    with pytest.raises(ValueError, match=r"pairs_first = 2; allowed: 0 or 1"):
        PlannerConfig(pairs_first=2)
    with pytest.raises(ValueError, match=r"gauss_newton_scaling = 2; allowed: 0 or 1"):
        PlannerConfig(gauss_newton_scaling=2)
    with pytest.raises(ValueError, match=r"gauss_newton_scaling = 0.5; allowed: integer >= 0"):
        PlannerConfig(gauss_newton_scaling=0.5)
    with pytest.raises(ValueError, match=r"speed_reserve = -0.1; allowed: >= 0"):
        PlannerConfig(speed_reserve=-0.1)
    with pytest.raises(ValueError, match=r"drop_edge_margin = -0.01; allowed: >= 0"):
        PlannerConfig(drop_edge_margin=-0.01)
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match=rf"dip_floor = {bad}; allowed: \[0, 1\)"):
            PlannerConfig(dip_floor=bad)
    with pytest.raises(ValueError, match=r"dip_floor must be finite"):
        PlannerConfig(dip_floor=float("nan"))


@pytest.mark.parametrize("key", ["retract", "arm_distance"])
def test_foot_geometry_settings_moved_to_the_robot(key):
    assert key not in PlannerConfig().to_dict()
    with pytest.raises(ValueError, match=rf"PlannerConfig\.{key} moved.*RobotParams\.{key}"):
        PlannerConfig(**{key: 0.1})
    with pytest.raises(ValueError, match=rf"RobotParams\.{key}"):
        PlannerConfig.for_robot("paper", **{key: 0.1})
    with pytest.raises(ValueError, match=rf"RobotParams\.{key}"):
        PlannerConfig.from_dict({key: 0.1})


def test_the_planner_rejects_a_half_leg_retraction():
    with pytest.raises(ValueError, match=r"RobotParams\.retract = 0.5.*\[0, 0.5\)"):
        GaitPlanner(RobotParams.from_preset("paper").replace(retract=0.5))


def test_a_planning_failure_pickles_and_copies_whole():
    """A failure crosses process boundaries (vectorised envs, Ray workers) and deep copies with
    its message and what the search found."""
    exc = PlanningError(2, "torque", "foothold x = 0.412 m")
    exc.partial, exc.evaluations, exc.beam_evaluations = ["step 0", "step 1"], 1234, 567
    exc.budget_exhausted = True
    for back in (pickle.loads(pickle.dumps(exc)), copy.deepcopy(exc)):
        assert type(back) is PlanningError and str(back) == str(exc)
        assert (back.step, back.constraint, back.detail) == (2, "torque", exc.detail)
        assert back.partial == exc.partial and back.evaluations == 1234
        assert back.beam_evaluations == 567 and back.budget_exhausted
