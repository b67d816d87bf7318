"""The hip command's unit chain: input, action and torque conversions and their inverses."""

import math

import numpy as np
import pytest

from envs.physics import model
from envs.physics.actuator import (
    action_from_input,
    action_from_torque,
    actions_to_torques,
    input_from_action,
    torque_from_action,
)
from envs.physics.params import RobotParams

PAPER = RobotParams.from_preset("paper")
ACTIONS = np.linspace(-1.0, 1.0, 41)


def test_action_and_input_invert_each_other_within_rounding():
    for a in ACTIONS:
        u = input_from_action(a, PAPER.u_max)
        assert -PAPER.u_max <= u <= PAPER.u_max
        assert action_from_input(u, PAPER.u_max) == pytest.approx(a, rel=0, abs=1e-15)
    assert action_from_input(3 * PAPER.u_max, PAPER.u_max) == 1.0
    assert action_from_input(-math.inf, PAPER.u_max) == -1.0
    assert input_from_action(-7.0, PAPER.u_max) == -PAPER.u_max
    assert math.isnan(action_from_input(math.nan, PAPER.u_max))
    assert math.isnan(input_from_action(math.nan, PAPER.u_max))


@pytest.mark.parametrize("preset", ["paper", "classic"])
def test_input_and_torque_invert_each_other_within_rounding(preset):
    robot = RobotParams.from_preset(preset)
    P = robot.vector()
    for a in ACTIONS:
        tau = torque_from_action(a, robot.tau_max)
        u = model.input_from_torque(P, tau)
        assert u == pytest.approx(input_from_action(a, robot.u_max), rel=1e-15, abs=1e-15)
        assert model.torque_from_input(P, u) == pytest.approx(tau, rel=1e-15, abs=1e-15)
        assert action_from_torque(tau, robot.tau_max) == pytest.approx(a, rel=0, abs=1e-15)
    assert model.torque_from_input(P, 1.0) == robot.input_gain
    # the compiled conversions work entrywise on arrays as well
    u = np.linspace(-robot.u_max, robot.u_max, 7)
    assert np.allclose(model.input_from_torque(P, model.torque_from_input(P, u)), u, rtol=1e-15)


def test_batched_actions_give_the_scalar_torques():
    out = np.zeros(ACTIONS.size + 2)
    actions = np.r_[ACTIONS, -3.0, 2.0].astype(np.float32)
    actions_to_torques(actions.reshape(-1, 1), PAPER.tau_max, out)
    expected = [torque_from_action(float(a), PAPER.tau_max) for a in actions]
    assert out.tolist() == expected
    assert out[-2:].tolist() == [-PAPER.tau_max, PAPER.tau_max]
    one = np.zeros(1)
    actions_to_torques(np.array([0.25], dtype=np.float32), PAPER.tau_max, one)
    assert one[0] == 0.25 * PAPER.tau_max
    actions_to_torques([[1]], PAPER.tau_max, one)  # lists and integers are converted
    assert one[0] == PAPER.tau_max


@pytest.mark.parametrize(
    "actions,match",
    [
        (np.array([np.nan]), "finite"),
        (np.array([0.0, np.inf, 0.0]), r"action\[1\]"),
        (np.zeros(2), "shape"),
        (np.zeros((3, 1, 1)), "shape"),
    ],
)
def test_bad_actions_write_nothing(actions, match):
    out = np.full(actions.size if actions.size in (1, 3) else 3, 7.0)
    with pytest.raises(ValueError, match=match):
        actions_to_torques(actions, PAPER.tau_max, out)
    assert np.all(out == 7.0)
