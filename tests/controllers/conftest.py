"""Shared helpers of the controller tests."""

import numpy as np
import pytest

from controllers.bezier import BezierConstraint
from controllers.reduced import impact_along_constraint
from controllers.transverse import StepModel
from envs.physics.params import RobotParams


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
