"""Absurd parameters and start states are rejected; a blown-up integration ends as "invalid"."""

from __future__ import annotations

import numpy as np
import pytest

from envs.physics import RobotParams, SimConfig, Simulator, simulate
from envs.physics.kernel import ANGLE_LIMIT
from envs.physics.passive import CLASSIC_CYCLE

PAPER = RobotParams.from_preset("paper")
CLASSIC = RobotParams.from_preset("classic")
Q0, QD0 = CLASSIC_CYCLE.q, CLASSIC_CYCLE.qd  # a valid start state of the classic walker


def test_stiff_viscous_friction_is_rejected_naming_fv_and_its_range():
    with pytest.raises(
        ValueError, match=r"RobotParams\.Fv = 100\.0 .*allowed: \[0, 17\.4\d*\] N m s/rad"
    ):
        PAPER.replace(Fv=100.0)
    limit = PAPER.viscous_friction_limit(2.5e-3)
    # the bound is RK4's decay limit at the fastest hip-rate decay Fv (M^-1)_11 over q1
    assert 17.0 < limit < 18.0 and PAPER.replace(Fv=limit).Fv == limit


def test_a_longer_substep_lowers_the_friction_the_simulator_accepts():
    robot = PAPER.replace(Fv=10.0)
    Simulator(robot, "flat")  # stable at the default 2.5 ms substep
    with pytest.raises(ValueError, match=r"RobotParams\.Fv = 10\.0 .*SimConfig\.substep = 0\.01"):
        Simulator(robot, "flat", config=SimConfig(substep=0.01))


def test_friction_at_the_bound_integrates_stably():
    robot = PAPER.replace(Fv=PAPER.viscous_friction_limit(2.5e-3))
    res = simulate(robot, "flat", (0.3, -0.15), (2.0, 1.0), 0.5)
    assert res.failure != "invalid"
    assert np.all(np.abs(res.qd) < robot.max_rate)


@pytest.mark.parametrize(
    "field,value",
    [
        ("m", 1e300),
        ("mH", 1e4),
        ("mHg", 1e300),
        ("l", 1e3),
        ("Ic", 1e9),
        ("g", 1e3),
        ("kI", 1e9),
        ("ktau", 1e9),
        ("Fc", 1e9),
        ("u_max", 1e100),
    ],
)
def test_absurd_parameters_are_rejected_naming_the_field_and_range(field, value):
    with pytest.raises(ValueError, match=rf"RobotParams\.{field} = .* out of range; allowed: "):
        CLASSIC.replace(**{field: value})


def test_start_rates_beyond_the_robots_bound_are_rejected():
    assert CLASSIC.max_rate == 100.0 and PAPER.max_rate == pytest.approx(312.5)
    sim = Simulator(CLASSIC, "flat")
    for qd in [(1e6, 0.0), (0.0, -1e20), (1e50, 1e50)]:
        with pytest.raises(ValueError, match=r"qd0 = .* allowed: \|q1d\|, \|q2d\| <= 100 rad/s"):
            sim.reset(Q0, qd)
    with pytest.raises(ValueError, match=r"q0\[0\] = .* allowed: \|q1\| <= pi"):
        sim.reset((7.0, 0.1), (0.0, 0.0))


def test_a_diverging_walker_ends_invalid_at_its_last_valid_state():
    sim = Simulator(CLASSIC, "flat", 2)
    qd = np.array([(99.9, -99.9), QD0])  # walker 0 passes the rate bound within a substep
    sim.reset(np.array([(0.3, -0.15), Q0]), qd)
    ev = sim.step(np.array([150.0, 0.0]))
    assert sim.failure(0) == "invalid" and sim.failure(1) is None
    assert ev.new_failure.tolist() == [True, False]
    # put back to the start of the substep that diverged: the reset state here
    assert np.array_equal(sim.states[0, :4], [0.3, -0.15, 99.9, -99.9])
    assert sim.t[0] == 0.0 and ev.n_impacts[0] == 0 and np.all(ev.work[0] == 0.0)
    assert np.all(np.isfinite(sim.states))


@pytest.mark.parametrize("torque", [1e6, 1e300])
def test_absurd_torques_end_invalid_with_a_finite_state(torque):
    res = simulate(CLASSIC, "flat", Q0, QD0, 1.0, torque)
    assert res.failure == "invalid"
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.qd))
    assert np.all(np.abs(res.q) <= ANGLE_LIMIT) and np.all(np.abs(res.qd) <= CLASSIC.max_rate)
    assert np.all(np.isfinite(res.work))
