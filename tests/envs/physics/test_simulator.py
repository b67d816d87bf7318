"""Hybrid simulator: invariants, convergence to the classic passive cycle, events, failures,
batching, the public state views."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from envs.physics import (
    FAILURES,
    RobotParams,
    SimConfig,
    Simulator,
    Terrain,
    model,
    simulate,
)
from envs.physics.passive import CLASSIC_CYCLE

CLASSIC = RobotParams.from_preset("classic")
PAPER = RobotParams.from_preset("paper")
# post-impact state of the classic walker's passive cycle (control notes, section 1)
SLOPE, Q2P, SWING, Q2DP, SWINGD = CLASSIC_CYCLE
Q0, QD0 = CLASSIC_CYCLE.q, CLASSIC_CYCLE.qd
# the stance foot on a narrow pillar over a deep pit: the swing foot never meets the ground
PILLAR = Terrain.from_points([-1, -0.05, -0.05, 0.05, 0.05, 1], [-5, -5, 0, 0, -5, -5])
FREE = {"check_reaction": False}
NEVER_ARMED = {"arm_distance": 2.0}  # robot parameters of a swing foot that is never armed


def _energy_error(params, config, q0, qd0, duration=1.0):
    P = params.vector()
    sim = Simulator(params, PILLAR, 1, config=config)
    sim.reset(q0, qd0)
    e0 = model.energy(P, *sim.state(0), 0.0)
    worst = 0.0
    for _ in range(round(duration / sim.dt)):
        ev = sim.step(0.0)
        assert ev.n_impacts[0] == 0 and sim.failure() is None
        worst = max(worst, abs(model.energy(P, *sim.state(0), 0.0) - e0) / abs(e0))
    return worst


@pytest.mark.parametrize(
    "params", [CLASSIC, PAPER.replace(Fc=0.0, Fv=0.0)], ids=["classic", "paper"]
)
def test_energy_conserved_in_unforced_frictionless_swing(params):
    start = ((0.6, 0.02), (-1.0, 0.05))
    params = params.replace(**NEVER_ARMED)
    assert _energy_error(params, SimConfig.accurate(**FREE), *start) < 1e-9
    # the default (2.5 ms) setting drifts about 1e-11 here
    assert _energy_error(params, SimConfig(**FREE), *start) < 1e-9


def test_motor_work_balances_the_energy_change_and_is_split_into_parts():
    P = CLASSIC.vector()
    sim = Simulator(CLASSIC.replace(**NEVER_ARMED), PILLAR, 1, config=SimConfig.accurate(**FREE))
    sim.reset((0.6, 0.02), (-1.0, 0.05))
    total = 0.0
    e0 = model.energy(P, *sim.state(0), 0.0)
    for k in range(50):
        tau = 2.0 * math.sin(0.3 * k)
        q1_before = sim.q[0, 0]
        ev = sim.step(tau)
        net, pos, ab = ev.work[0]
        # same quadrature as the state update: net work is exactly tau * delta q1
        assert math.isclose(net, tau * (sim.q[0, 0] - q1_before), rel_tol=1e-9, abs_tol=1e-14)
        assert pos >= max(net, 0.0) - 1e-15 and ab >= abs(net) - 1e-15 and ab >= pos
        total += net
    e1 = model.energy(P, *sim.state(0), 0.0)
    assert abs((e1 - e0) - total) < 1e-9 * abs(e0)


def _post_impact_samples(res):
    """Indices of the post-impact samples (the second of two samples at the same time)."""
    return np.nonzero(np.diff(res.t) == 0)[0] + 1


def test_perturbed_start_converges_to_the_limit_cycle():
    q0 = (Q0[0] + 0.03, Q0[1] + 0.015)  # swing foot lifted a little off the slope
    qd0 = (QD0[0] - 0.1, QD0[1] + 0.05)
    res = simulate(CLASSIC, Terrain.slope(SLOPE), q0, qd0, 20.0)
    assert res.failure is None and len(res.impact_times) >= 25
    k = _post_impact_samples(res)
    first = np.abs(np.r_[res.q[k[0], 1] - Q2P, res.qd[k[0]] - QD0]).max()
    last = np.abs(np.r_[res.q[k[-1], 1] - Q2P, res.qd[k[-1]] - QD0]).max()
    assert first > 1e-2 and last < 1e-5
    assert abs(np.diff(res.impact_times)[-1] - 0.734461) < 1e-5
    assert abs(res.step_lengths[-1] - 0.535919) < 1e-5
    legs = res.stance_leg[k]
    assert np.all(legs[1:] != legs[:-1])


@pytest.mark.parametrize("config", [SimConfig(), SimConfig.accurate()], ids=["default", "accurate"])
def test_touchdown_time_matches_a_tight_reference_integration(config):
    P = CLASSIC.vector()

    def rhs(t, y):
        a1, a2 = model.accelerations(P, y[0], y[1], y[2], y[3], 0.0)
        return [y[2], y[3], a1, a2]

    def touchdown(t, y):  # full-length clearance once the foot is well ahead
        fx, fy = model.swing_foot_position(P, y[0], y[1], 0.0, 0.0)
        return fy - math.tan(SLOPE) * fx if fx > 0.1 else 1.0

    touchdown.terminal, touchdown.direction = True, -1
    ref = solve_ivp(
        rhs, (0, 2), [*Q0, *QD0], method="DOP853", rtol=1e-12, atol=1e-12, events=touchdown
    )
    res = simulate(CLASSIC, Terrain.slope(SLOPE), Q0, QD0, 2.0, config=config, stop_at_impacts=1)
    assert abs(res.impact_times[0] - ref.t_events[0][0]) < 1e-9
    k = _post_impact_samples(res)[0]
    assert np.max(np.abs(res.q[k - 1] - ref.y_events[0][0][:2])) < 1e-9
    # no penetration: the foothold is on the ground, the pre-impact foot at it
    fx, fy = model.swing_foot_position(P, *res.q[k - 1], *res.stance_foot[k - 1])
    assert np.allclose((fx, fy), res.footholds[0], atol=1e-12)
    assert res.stance_foot[k].tolist() == res.footholds[0].tolist()


def test_impacts_in_the_simulator_conserve_momentum_and_swap_legs():
    sim = Simulator(CLASSIC, Terrain.slope(SLOPE), 1)
    sim.reset(Q0, QD0)
    P = CLASSIC.vector()
    leg = sim.stance_leg[0]
    while True:
        ev = sim.step(0.0)
        if ev.n_impacts[0]:
            break
    pre, post = ev.pre_impact[0, 0], ev.post_impact[0, 0]
    assert np.allclose(post, model.impact_momentum(P, *pre), rtol=0, atol=1e-12)
    assert sim.stance_leg[0] == 1 - leg
    assert np.array_equal(sim.stance_foot[0], ev.foothold[0, 0])


def _failure(params, terrain, q0, qd0, torque=None, **cfg):
    res = simulate(params, terrain, q0, qd0, 2.0, torque, config=SimConfig(**cfg))
    return res.failure, res


def test_fall_by_hip_height_and_by_stance_angle():
    still = CLASSIC.replace(arm_distance=2.0, retract=0.5)  # a swing foot that never lands
    reason, res = _failure(still, "flat", (0.0, 0.5), (0.0, 0.0), fall_height=0.8)
    assert reason == "fall" and res.failure_time > 0
    assert CLASSIC.l * math.cos(res.q[-1, 1]) < 0.8 * CLASSIC.l
    reason, res = _failure(still, "flat", (0.0, 0.5), (0.0, 0.0), q2_limit=0.6)
    assert reason == "fall" and res.q[-1, 1] > 0.6


def test_retracted_foot_running_into_a_riser_trips():
    # a 20 cm riser just ahead of the stance foot: the retracted swing foot hits its face
    reason, res = _failure(CLASSIC, Terrain.stairs([0.05], [0.2]), Q0, QD0)
    assert reason == "trip" and len(res.impact_times) == 0
    P = CLASSIC.vector()
    fx, fy = model.swing_foot_position(P, *res.q[-1], 0.0, 0.0, 0.05 * CLASSIC.l)
    assert abs(fx - 0.05) < 1e-9 and fy < 0.2


def test_armed_foot_hitting_a_vertical_face_trips_and_a_low_step_is_climbed():
    reason, res = _failure(CLASSIC, Terrain.stairs([0.45], [0.1]), Q0, QD0)
    assert reason == "trip"
    P = CLASSIC.vector()
    fx, fy = model.swing_foot_position(P, *res.q[-1], 0.0, 0.0)
    assert abs(fx - 0.45) < 1e-9 and 0.0 < fy < 0.1
    reason, res = _failure(CLASSIC, Terrain.stairs([0.45], [0.05]), Q0, QD0)
    assert res.footholds[0, 1] == 0.05 and res.footholds[0, 0] > 0.45


def test_liftoff_when_the_stance_leg_spins_too_fast():
    reason, res = _failure(CLASSIC, "flat", (-0.4, -0.2), (0.0, 4.0))  # l q2d^2 > g
    assert reason == "liftoff"


def test_slip_with_a_low_friction_coefficient_but_not_with_the_default():
    assert _failure(CLASSIC, Terrain.slope(SLOPE), Q0, QD0, mu=0.05)[0] == "slip"
    assert _failure(CLASSIC, Terrain.slope(SLOPE), Q0, QD0)[0] is None


def test_stuck_when_the_trailing_foot_cannot_leave_the_ground():
    # swing leg thrown backwards onto the ground just ahead: after the impact the old stance
    # foot would have to move into the ground
    reason, res = _failure(CLASSIC, "flat", (0.21, 0.1), (-4.0, 0.0))
    assert reason == "stuck" and len(res.impact_times) == 0
    P = CLASSIC.vector()
    post = model.impact(P, *res.q[-1], *res.qd[-1])
    assert model.swing_foot_velocity(P, *post)[1] <= 0.0


def test_invalid_when_the_state_overflows():
    assert _failure(CLASSIC, "flat", Q0, QD0, torque=1e300)[0] == "invalid"


def test_failed_walkers_stay_frozen_until_reset():
    sim = Simulator(CLASSIC, "flat", 2)
    sim.reset(np.array([Q0, (-0.4, -0.2)]), np.array([QD0, (0.0, 4.0)]))
    ev = sim.step(0.0)
    assert sim.failure(1) == "liftoff" and ev.new_failure.tolist() == [False, True]
    frozen = sim.states[1].copy()
    ev = sim.step(0.0)
    assert np.array_equal(sim.states[1], frozen) and not ev.new_failure.any()
    assert sim.status[1] == FAILURES.index("liftoff")
    sim.reset(Q0, QD0, index=1)
    assert sim.failure(1) is None and sim.t[1] == 0.0


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"q0": (math.nan, 0.0)}, "q0"),
        ({"qd0": (0.0, math.inf)}, "qd0"),
        ({"q0": (0.1, 1.4)}, "q2"),
        ({"torque": math.nan}, "torque"),
        ({"torque": lambda t, q, qd: math.inf}, "torque"),
        ({"duration": -1.0}, "duration"),
        ({"dt": 0.0}, "dt"),
        ({"foot": (0.0, 0.3)}, "not on the ground"),
        ({"q0": (0.0, 0.0, 0.0)}, "shape"),
    ],
)
def test_bad_inputs_raise_value_errors(kwargs, match):
    args = {"q0": Q0, "qd0": QD0, "duration": 0.1, **kwargs}
    with pytest.raises(ValueError, match=match):
        simulate(CLASSIC, "flat", **args)


def test_step_rejects_non_finite_torque_without_advancing():
    sim = Simulator(CLASSIC, "flat", 3)
    sim.reset(Q0, QD0)
    before = sim.states.copy()
    with pytest.raises(ValueError, match=r"torque\[1\]"):
        sim.step(np.array([0.0, math.nan, 0.0]))
    assert np.array_equal(sim.states, before)
    with pytest.raises(ValueError, match="SimConfig.mu"):
        SimConfig(mu=-1.0)
    with pytest.raises(ValueError, match="reset"):
        Simulator(CLASSIC, "flat", 2).step(0.0)


def test_batch_equals_single_walkers_bit_for_bit():
    rng = np.random.default_rng(5)
    n = 6
    terrains = [
        Terrain.slope(SLOPE + 0.002 * i) if i % 2 else Terrain.stairs([0.5, 1.0], [-0.02, -0.02])
        for i in range(n)
    ]
    params = [CLASSIC if i % 3 else CLASSIC.replace(mH=11.0) for i in range(n)]
    q0 = np.array([Q0] * n) + rng.uniform(-0.01, 0.01, (n, 2))
    qd0 = np.array([QD0] * n)
    steps = 110
    torques = rng.uniform(-0.3, 0.3, (steps, n))
    batch = Simulator(params, terrains, n, parallel=True)
    batch.reset(q0, qd0)
    singles = [Simulator(params[i], terrains[i], 1) for i in range(n)]
    for i, s in enumerate(singles):
        s.reset(q0[i], qd0[i])
    impacts = np.zeros(n, dtype=int)
    for k in range(steps):
        ev = batch.step(torques[k])
        impacts += ev.n_impacts
        for i, s in enumerate(singles):
            e1 = s.step(torques[k, i])
            assert np.array_equal(s.states[0], batch.states[i])
            assert np.array_equal(s.flags[0], batch.flags[i])
            assert np.array_equal(e1.work[0], ev.work[i])
            m = e1.n_impacts[0]
            assert np.array_equal(e1.foothold[0, :m], ev.foothold[i, :m])
    assert np.all(impacts >= 1) and not batch.status.any()


def test_state_and_flag_views_are_read_only_and_follow_the_walkers():
    sim = Simulator(CLASSIC, Terrain.slope(SLOPE), 2)
    sim.reset(Q0, QD0)
    states, flags = sim.states, sim.flags
    assert states.shape == (2, 7) and flags.shape == (2, 4)
    with pytest.raises(ValueError):
        states[0, 0] = 1.0
    with pytest.raises(ValueError):
        flags[0, 2] = 1
    impacts = 0
    for _ in range(80):
        ev = sim.step(0.0)
        impacts += int(ev.n_impacts.sum())
        assert sim.states is states and sim.flags is flags
        assert np.array_equal(states[:, 0:2], sim.q) and np.array_equal(states[:, 2:4], sim.qd)
        assert np.array_equal(states[:, 4:6], sim.stance_foot)
        assert np.array_equal(states[:, 6], sim.t)
        assert np.array_equal(flags[:, 0], sim.stance_leg)
        assert np.array_equal(flags[:, 1], sim.armed)
        assert np.array_equal(flags[:, 2], sim.status)
        assert np.array_equal(flags[:, 3], ev.n_impacts)
    assert impacts >= 2 and not sim.status.any()


def test_callable_torque_is_held_over_each_period():
    seen = []

    def torque(t, q, qd):
        seen.append(t)
        return 0.5

    res = simulate(CLASSIC, Terrain.slope(SLOPE), Q0, QD0, 0.1, torque, dt=0.02)
    assert np.allclose(seen, np.arange(5) * 0.02)
    assert np.all(res.torque[1:] == 0.5) and res.t[-1] == pytest.approx(0.1)


def test_per_walker_terrain_and_masked_reset():
    sim = Simulator(CLASSIC, "flat", 3)
    sim.reset(Q0, QD0)
    long_course = Terrain.random_blocks(seed=2, length=10.0)
    sim.set_terrain(long_course, index=2)  # more vertices: the padded arrays grow
    tx, ty, tn = sim.terrain_arrays
    assert tn[2] == long_course.xs.size and tn[0] == 2 and tx.shape[1] >= tn[2]
    assert sim.terrains[2] is long_course
    sim.step(0.1)
    sim.reset(Q0, QD0, index=np.array([False, True, False]), stance_leg=1, t=5.0)
    assert sim.t.tolist() == [0.01, 5.0, 0.01] and sim.stance_leg.tolist() == [0, 1, 0]
    with pytest.raises(ValueError, match="below the ground"):
        sim.reset((0.3, 0.5), (0.0, 0.0), index=0)  # retracted swing foot in the ground
    with pytest.raises(ValueError, match="hip"):
        Simulator(CLASSIC, "flat", 1, config=SimConfig(fall_height=0.9)).reset((0.0, 0.6), (0, 0))


def test_foot_geometry_comes_from_each_walkers_robot():
    # swing foot 0.395 m ahead of the stance foot and 0.04 m above the ground (l = 1 m)
    q, qd = (0.4, 0.1), (0.0, 0.0)
    sim = Simulator([CLASSIC, CLASSIC.replace(arm_distance=0.5)], "flat", 2)
    sim.reset(q, qd)
    assert sim.armed.tolist() == [1, 0]
    # full-length swing foot 0.04 m below the ground: retracted by 5 % of l it clears it
    Simulator(CLASSIC, "flat").reset((0.4, 0.3), qd)
    with pytest.raises(ValueError, match="retracted swing foot"):
        Simulator(CLASSIC.replace(retract=0.0), "flat").reset((0.4, 0.3), qd)
    # the former SimConfig fields name their replacement
    for key in ("retract", "arm_distance"):
        with pytest.raises(ValueError, match=rf"SimConfig\.{key} moved.*RobotParams\.{key}"):
            SimConfig(**{key: 0.1})
        with pytest.raises(ValueError, match=rf"RobotParams\.{key}"):
            SimConfig.accurate(**{key: 0.1})
