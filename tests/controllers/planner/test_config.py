"""Planner settings: validation and the robot presets."""

import pytest

from controllers.planner import PlannerConfig


def test_bad_config_raises():
    with pytest.raises(ValueError, match="unknown planner setting"):
        PlannerConfig.from_dict({"speed": 1.0})
    with pytest.raises(ValueError, match="target_speed"):
        PlannerConfig(target_speed=-1.0)
    with pytest.raises(ValueError, match="order"):
        PlannerConfig(order=3)
    with pytest.raises(ValueError, match="step_min"):
        PlannerConfig(step_min=0.3, step_length=0.2)
