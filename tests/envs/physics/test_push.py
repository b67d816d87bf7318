"""The hip push: the model's impulse (momentum-consistent, checked against the momenta built
from the kinematics) and the simulator's ``push_hip``; parameter perturbation."""

import math

import numpy as np
import pytest

from envs.physics import Simulator, model
from envs.physics.params import PHYSICAL_PARAMS, RobotParams


def _hip_vx(P, q1, q2, q1d, q2d, eps=1e-6):
    """Horizontal hip velocity [m/s] by central differences of the hip position along qd."""
    a = model.hip_position(P, q1 + eps * q1d, q2 + eps * q2d, 0.0, 0.0)[0]
    b = model.hip_position(P, q1 - eps * q1d, q2 - eps * q2d, 0.0, 0.0)[0]
    return (a - b) / (2 * eps)


@pytest.mark.parametrize("preset", ["classic", "paper"])
def test_push_changes_the_hip_speed_by_dv_and_the_momenta_by_the_impulse(preset):
    P = RobotParams.from_preset(preset).vector()
    l = RobotParams.from_preset(preset).l  # noqa: E741
    rng = np.random.default_rng(3)
    for _ in range(30):
        q1, q2 = rng.uniform(-0.7, 0.7), rng.uniform(-0.5, 0.5)
        w1, w2 = rng.uniform(-3, 3, 2)
        dv = rng.uniform(-0.3, 0.3)
        d1, d2, p = model.hip_push(P, q1, q2, dv)
        v1, v2 = w1 + d1, w2 + d2
        # the hip's horizontal velocity jumps by dv (its velocity is linear in the rates)
        assert _hip_vx(P, q1, q2, v1, v2) - _hip_vx(P, q1, q2, w1, w2) == pytest.approx(
            dv, rel=1e-7, abs=1e-10
        )
        # about the pinned stance foot: the impulse (p, 0) at the hip has the moment -y_hip p
        hy = l * math.cos(q2)
        dl = model.angular_momentum(P, q1, q2, v1, v2, 0.0, 0.0) - model.angular_momentum(
            P, q1, q2, w1, w2, 0.0, 0.0
        )
        assert dl == pytest.approx(-hy * p, rel=1e-10, abs=1e-12)
        # the swing leg hangs from the hip: its momentum about the hip is unchanged
        hx = l * math.sin(q2)
        before = model.leg_momenta(P, q1, q2, w1, w2, hx, hy)[2]
        after = model.leg_momenta(P, q1, q2, v1, v2, hx, hy)[2]
        assert after == pytest.approx(before, rel=1e-10, abs=1e-12)
        assert np.sign(p) == np.sign(dv)


def test_simulator_push_keeps_positions_and_the_stance_foot():
    robot = RobotParams.from_preset("paper")
    sim = Simulator(robot, "flat", 2, dt=0.005)
    sim.reset((-0.5, -0.25), (2.7, 1.2))
    for _ in range(40):
        sim.step(0.0)
    before = sim.states.copy()
    impulse = sim.push_hip(1, -0.1)
    after = sim.states
    np.testing.assert_array_equal(after[0], before[0])  # the other walker untouched
    keep = [0, 1, 4, 5, 6]  # q1, q2, stance foot, time
    np.testing.assert_array_equal(after[1, keep], before[1, keep])
    d1, d2, p = model.hip_push(robot.vector(), before[1, 0], before[1, 1], -0.1)
    assert impulse == p < 0
    assert (after[1, 2], after[1, 3]) == (before[1, 2] + d1, before[1, 3] + d2)
    with pytest.raises(ValueError, match="dv = nan"):
        sim.push_hip(0, math.nan)
    sim2 = Simulator(robot, "flat", 1, dt=0.005)
    with pytest.raises(ValueError, match="not running"):
        sim2.push_hip(0, 0.1)


def test_perturbed_moves_the_centre_of_mass_with_the_leg():
    robot = RobotParams.from_preset("paper")
    assert robot.perturbed({}) == robot
    r = robot.perturbed({"l": 0.1, "m": -0.05})
    assert r.l == pytest.approx(0.352) and r.m == pytest.approx(1.235)
    assert r.lc / r.l == pytest.approx(robot.lc / robot.l)  # the centre of mass moves along
    r = robot.perturbed({"l": 0.1, "lc": 0.1})
    assert r.lc / r.l == pytest.approx(1.1 * robot.lc / robot.l)
    assert r.retract == robot.retract  # a fraction of l: it scales with l
    for name in PHYSICAL_PARAMS:
        assert getattr(robot.perturbed({name: 0.2}), name) == pytest.approx(
            1.2 * getattr(robot, name)
        )
    with pytest.raises(ValueError, match=r"RobotParams\.lc = .* out of range; allowed: \[0, l\]"):
        robot.perturbed({"lc": 0.3})  # lc / l = 0.81 * 1.3 > 1
    with pytest.raises(ValueError, match=r"unknown physical parameter\(s\) \['g'\]"):
        robot.perturbed({"g": 0.1})
    with pytest.raises(ValueError, match="relative error of m = -1.0; allowed: finite > -1"):
        robot.perturbed({"m": -1.0})
