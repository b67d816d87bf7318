"""Planner and controller arguments: non-integer counts and non-finite numbers are rejected."""

from __future__ import annotations

import math

import pytest

from controllers import ControllerConfig, GaitPlanner
from envs.physics import Terrain


@pytest.fixture(scope="module")
def planner_and_gait():
    planner = GaitPlanner("paper")
    return planner, planner.periodic_gait()


@pytest.mark.parametrize(
    "stance,horizon,match",
    [
        ((math.nan, 0.0), 2, r"stance_foot must be two finite numbers \[m\], got \(nan, 0\.0\)"),
        ((0.0, math.inf), 2, "stance_foot must be two finite numbers"),
        ((0.0,), 2, "stance_foot must be two finite numbers"),
        (None, 2, "stance_foot must be two finite numbers"),
        ((0.0, 0.0), 2.7, r"horizon = 2\.7; allowed: integer >= 1"),
        ((0.0, 0.0), "2", "horizon = '2'; allowed: integer >= 1"),
        ((0.0, 0.0), 0, "horizon = 0; allowed: integer >= 1"),
    ],
)
def test_plan_rejects_bad_arguments_with_value_errors(planner_and_gait, stance, horizon, match):
    planner, gait = planner_and_gait
    with pytest.raises(ValueError, match=match):
        planner.plan(Terrain.flat(), (gait.q, gait.qd), stance, horizon=horizon)


@pytest.mark.parametrize(
    "changes,match",
    [
        ({"horizon": 2.7}, r"ControllerConfig\.horizon = 2\.7; allowed: integer >= 1"),
        ({"grid": None}, r"ControllerConfig\.grid = None"),
        ({"plan_steps": math.inf}, r"ControllerConfig\.plan_steps = inf"),
        ({"R": "a"}, r"ControllerConfig\.R = 'a'; allowed: a finite number > 0"),
        ({"R": math.nan}, r"ControllerConfig\.R = nan"),
        ({"Q": 5}, r"ControllerConfig\.Q = 5; allowed: three numbers > 0"),
        ({"Qj": (1.0, math.nan, 1.0)}, r"ControllerConfig\.Qj"),
        ({"margin": None}, r"ControllerConfig\.margin = None"),
        ({"late_blend": math.inf}, r"ControllerConfig\.late_blend = inf"),
    ],
)
def test_controller_config_rejects_non_integer_counts_and_non_finite_numbers(changes, match):
    with pytest.raises(ValueError, match=match):
        ControllerConfig(**changes)
    assert ControllerConfig(horizon=3.0, grid=40).horizon == 3  # integral floats are integers
