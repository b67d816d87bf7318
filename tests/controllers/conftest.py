"""Shared helpers of the controller tests."""

import numpy as np
import pytest

from controllers.bezier import BezierConstraint
from controllers.reduced import impact_along_constraint
from controllers.transverse import StepModel
from envs.physics.params import RobotParams
from envs.physics.terrain import Terrain


def flat_chain(robot="paper", th0=0.2, nsteps=3, td_plus=1.3, slope_minus=1.6, order=4):
    """A hand-made chain of impact-invariant Bezier steps on flat ground (test data only; the
    production constraints come from the planner)."""
    P = RobotParams.from_preset(robot).vector()
    steps, slope_plus, tdp = [], 1.2, td_plus
    for _ in range(nsteps):
        a = np.zeros(order + 1)
        a[0], a[order] = -2 * th0, 2 * th0
        a[1] = BezierConstraint.second_coeff(a[0], slope_plus, -th0, th0, order)
        a[order - 1] = BezierConstraint.penultimate_coeff(a[order], slope_minus, -th0, th0, order)
        st = StepModel(P, BezierConstraint(a, -th0, th0), tdp)
        steps.append(st)
        delta, slope_plus = impact_along_constraint(P, a[order], slope_minus)
        tdp = float(delta) * float(np.sqrt(st.thetadot_sq(th0)))
    return P, steps


@pytest.fixture(scope="session")
def chain():
    return flat_chain()


@pytest.fixture(scope="session")
def state_from_z():
    """``f(step, theta, z)``: the state at phase ``theta`` whose transverse coordinates relative
    to ``step`` are ``z = [I, y, y_dot]``."""

    def f(step, theta, z):
        c = step.constraint
        td = np.sqrt(step.thetadot_sq(theta) + z[0])
        return np.array([c.phi(theta) + z[1], theta, c.dphi(theta) * td + z[2], td])

    return f


class RiseAfterDrops:
    """Random blocks at difficulty 2 (a validation course of the reference policy): three drops
    of 6, 11 and 14 mm, then a 13 mm rise on a block 0.22 m wide; and the post-impact ``state``
    with its ``stance`` foot [m] of the footstep where the replanning search first found only
    three of its four steps (the robot descending at 0.89 rad/s)."""

    edges = [0.3, 0.4752, 0.7189, 0.8735, 1.0909, 1.3786, 1.598, 1.8576]
    heights = [0.0, -0.00598, -0.01735, -0.03164, -0.01885, -0.02697, -0.0339, -0.02885, -0.02642]
    state = (
        (-0.39099489784414365, -0.1923186271042424),
        (-0.028842415109954597, 0.889456164095743),
    )
    stance = (0.27751934145834933, 0.0)

    def terrain(self, shift: float = 0.0) -> Terrain:
        """The course, moved by ``-shift`` [m] (``shift = stance[0]`` puts the stance foot at
        x = 0)."""
        return Terrain.stairs([e - shift for e in self.edges], np.diff(self.heights).tolist())


@pytest.fixture(scope="session")
def rise_after_drops():
    return RiseAfterDrops()
