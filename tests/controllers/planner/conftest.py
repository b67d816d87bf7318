"""Fixtures of the planner tests: one planner per robot and plans made on first use, per module."""

import pytest

from controllers.planner import GaitPlanner

from .cases import CASES, HORIZON


class _Planners(dict):
    def __missing__(self, robot):
        self[robot] = GaitPlanner(robot)
        return self[robot]


@pytest.fixture(scope="module")
def planners():
    return _Planners()


class _Plans(dict):
    def __init__(self, planners):
        super().__init__()
        self.planners = planners

    def __missing__(self, key):
        r, t = key
        pl = self.planners[r]
        g = pl.periodic_gait()
        self[key] = pl.plan(CASES[r][t], (g.q, g.qd), (0.0, 0.0), horizon=HORIZON[r])
        return self[key]


@pytest.fixture(scope="module")
def plans(planners):
    """Plans from the periodic gait's post-impact state, made on first use."""
    return _Plans(planners)
