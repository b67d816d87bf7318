"""Passive limit cycle down a slope: the classic walker's cycle of the control notes, the paper
robot's stable passive gait."""

import numpy as np

from envs.physics import RobotParams, SimConfig, Terrain, simulate
from envs.physics.passive import (
    CLASSIC_CYCLE,
    passive_limit_cycle,
    slope_section_state,
    slope_step_map,
)

CLASSIC = RobotParams.from_preset("classic")
PAPER = RobotParams.from_preset("paper")
# post-impact state of the classic walker's passive cycle (control notes, section 1)
SLOPE, Q2P, SWING, Q2DP, SWINGD = CLASSIC_CYCLE
QD0 = CLASSIC_CYCLE.qd


def test_classic_passive_limit_cycle_matches_the_reference():
    cyc = passive_limit_cycle(CLASSIC, SLOPE, CLASSIC_CYCLE.section)
    z = cyc.state[[1, 2, 3]]
    assert np.max(np.abs(slope_step_map(CLASSIC, SLOPE, z, SimConfig.accurate())[0] - z)) < 1e-10
    q1, q2, q1d, q2d = cyc.state
    assert round(q2, 6) == Q2P
    assert round(q2 - q1, 6) == SWING
    assert round(q2d, 6) == Q2DP
    assert round(q2d - q1d, 6) == SWINGD
    # the start state the README's simulate() example quotes
    assert round(q1, 5) == -0.54255 and round(q1d, 6) == 0.716732
    assert round(cyc.period, 6) == 0.734461
    assert round(cyc.step_length, 6) == 0.535919
    moduli = np.sort(np.abs(cyc.eigenvalues))[::-1]
    assert np.array_equal(np.round(moduli, 3), [0.580, 0.580, 0.131])


def test_the_classic_cycle_start_is_one_state_in_three_forms():
    assert CLASSIC_CYCLE.q == (Q2P - SWING, Q2P) and CLASSIC_CYCLE.qd == (Q2DP - SWINGD, Q2DP)
    assert CLASSIC_CYCLE.section == (Q2P, Q2DP - SWINGD, Q2DP)
    # both feet on the slope to the six digits of the constants
    q, qd = slope_section_state(CLASSIC_CYCLE.section, SLOPE)
    assert np.allclose(q, CLASSIC_CYCLE.q, rtol=0, atol=1e-6) and qd.tolist() == list(QD0)


def test_section_state_puts_both_feet_on_the_slope():
    q, qd = slope_section_state(CLASSIC_CYCLE.section, SLOPE)
    assert q.tolist() == [2.0 * (Q2P + SLOPE), Q2P] and qd.tolist() == list(QD0)


def test_paper_robot_walks_passively_with_friction_and_retractable_feet():
    cyc = passive_limit_cycle(PAPER, SLOPE, CLASSIC_CYCLE.section)
    assert np.max(np.abs(cyc.eigenvalues)) < 1.0 and 0.1 < cyc.step_length < 0.3
    q, qd = cyc.state[:2] + (0.0, 0.0), cyc.state[2:] * 1.02
    res = simulate(PAPER, Terrain.slope(SLOPE), q, qd, 6.0)
    assert res.failure is None and len(res.impact_times) >= 9
    assert abs(np.diff(res.impact_times)[-1] - cyc.period) < 1e-3
