"""Model equations: impact map (closed form vs. momentum derivation), momenta, energy, the
swing-phase RK4 step and the contact conditions."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from envs.physics import model
from envs.physics.params import RobotParams


def _states(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return (
        rng.uniform(-0.7, 0.7, n),
        rng.uniform(-0.5, 0.5, n),
        rng.uniform(-3.0, 3.0, n),
        rng.uniform(-3.0, 3.0, n),
    )


@pytest.mark.parametrize("preset", ["classic", "paper"])
def test_impact_closed_form_equals_momentum_derivation(preset):
    P = RobotParams.from_preset(preset).vector()
    for q1, q2, w1, w2 in zip(*_states()):
        a = np.array(model.impact(P, q1, q2, w1, w2))
        b = np.array(model.impact_momentum(P, q1, q2, w1, w2))
        assert np.max(np.abs(a - b)) < 1e-12


@pytest.mark.parametrize("preset", ["classic", "paper"])
def test_closed_form_impact_conserves_both_angular_momenta(preset):
    P = RobotParams.from_preset(preset).vector()
    l = P[11]
    for q1, q2, w1, w2 in zip(*_states(seed=1)):
        n1, n2, v1, v2 = model.impact(P, q1, q2, w1, w2)
        assert (n1, n2) == (-q1, q2 - q1)
        # new stance foot = old swing foot, relative to the old stance foot
        fx, fy = model.swing_foot_position(P, q1, q2, 0.0, 0.0)
        before = model.angular_momentum(P, q1, q2, w1, w2, fx, fy)
        after = model.angular_momentum(P, n1, n2, v1, v2, 0.0, 0.0)
        assert abs(before - after) < 1e-12 * max(1.0, abs(before))
        # trailing leg (old stance leg, new swing leg) about the hip
        hx, hy = model.hip_position(P, q1, q2, 0.0, 0.0)
        trail_before = model.leg_momenta(P, q1, q2, w1, w2, hx, hy)[0]
        hx2, hy2 = model.hip_position(P, n1, n2, 0.0, 0.0)
        trail_after = model.leg_momenta(P, n1, n2, v1, v2, hx2, hy2)[2]
        assert abs(trail_before - trail_after) < 1e-12 * max(1.0, abs(trail_before))
        assert np.isclose(hx2 - hx, -fx, atol=1e-15 * l) and np.isclose(hy2 - hy, -fy, atol=1e-15)


@pytest.mark.parametrize("preset", ["classic", "paper"])
def test_kinematic_momenta_match_the_inertia_matrix(preset):
    """The body-by-body kinematics behind the momentum derivation reproduce ``M(q)``: the
    angular momentum about the stance foot is ``-(row 2 of M) qd`` (generalised momentum of
    ``q2``, which rotates the whole robot clockwise)."""
    P = RobotParams.from_preset(preset).vector()
    for q1, q2, w1, w2 in zip(*_states(seed=2)):
        m11, m12, m22 = model.mass_matrix(P, q1)
        L = model.angular_momentum(P, q1, q2, w1, w2, 0.0, 0.0)
        assert np.isclose(L, -(m12 * w1 + m22 * w2), rtol=1e-12, atol=1e-12)
        # swing leg about the hip: generalised momentum of q1 (with q2 fixed) up to sign
        hx, hy = model.hip_position(P, q1, q2, 0.0, 0.0)
        sw_only = model.leg_momenta(P, q1, q2, w1, 0.0, hx, hy)[2]
        assert np.isclose(sw_only, m11 * w1, rtol=1e-12, atol=1e-12)


def test_impact_keeps_kinetic_energy_from_growing_and_lifts_the_trailing_foot():
    P = RobotParams.from_preset("classic").vector()
    # a flat-ground heel-strike configuration q1 = 2 q2 with a forward-walking velocity
    for q2 in (0.15, 0.2, 0.3):
        q1, w1, w2 = 2 * q2, 0.4, 1.2
        n1, n2, v1, v2 = model.impact(P, q1, q2, w1, w2)
        assert model.kinetic_energy(P, n1, v1, v2) < model.kinetic_energy(P, q1, w1, w2)
        assert model.swing_foot_velocity(P, n1, n2, v1, v2)[1] > 0


def test_centre_of_mass_velocity_is_the_derivative_of_its_position():
    P = RobotParams.from_preset("paper").vector()
    q1, q2, w1, w2, h = 0.3, -0.1, 0.7, 1.1, 1e-6
    p = np.array(model.centre_of_mass(P, q1 + h * w1, q2 + h * w2, 0.0, 0.0))
    m = np.array(model.centre_of_mass(P, q1 - h * w1, q2 - h * w2, 0.0, 0.0))
    v = np.array(model.centre_of_mass_velocity(P, q1, q2, w1, w2))
    assert np.allclose((p - m) / (2 * h), v, atol=1e-8)


def test_model_functions_work_entrywise_on_arrays():
    P = RobotParams.from_preset("classic").vector()
    q1, q2, w1, w2 = _states(5)
    a = np.array(model.impact_momentum(P, q1, q2, w1, w2))
    for k in range(5):
        assert np.allclose(a[:, k], model.impact_momentum(P, q1[k], q2[k], w1[k], w2[k]))


def test_swing_rk4_step_is_fourth_order_and_its_work_matches_the_hip_rotation():
    P = RobotParams.from_preset("paper").vector()
    x0, u = (0.4, -0.1, -0.8, 1.1), 3.0

    def rhs(t, y):
        a1, a2 = model.accelerations(P, y[0], y[1], y[2], y[3], u)
        return [y[2], y[3], a1, a2]

    errors = []
    for h in (0.02, 0.01):
        a1, a2 = model.accelerations(P, *x0, u)
        q1, q2, w1, w2, net, pos, ab = model.swing_rk4(P, *x0, u, h, a1, a2)
        ref = solve_ivp(rhs, (0, h), x0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
        errors.append(np.max(np.abs(np.array([q1, q2, w1, w2]) - ref)))
        tau = model.input_gain(P) * u
        assert math.isclose(net, tau * (q1 - x0[0]), rel_tol=1e-12)
        assert pos >= max(net, 0.0) - 1e-15 and ab >= abs(net) - 1e-15 and ab >= pos
    # local error O(h^5): halving the step divides it by about 32
    assert errors[0] < 1e-6 and 16.0 < errors[0] / errors[1] < 64.0


@pytest.mark.parametrize("slope", [0.0, -0.0525, 0.3])
def test_ground_normal_is_the_upward_unit_normal(slope):
    nx, ny = model.ground_normal(slope)
    assert math.isclose(math.hypot(nx, ny), 1.0, rel_tol=1e-15)
    assert ny > 0.0 and abs(nx + slope * ny) < 1e-15  # orthogonal to the tangent (1, slope)
    # a force along the normal has no tangential part; the tangent points forwards
    assert model.normal_tangential(2.0 * nx, 2.0 * ny, nx, ny) == pytest.approx((2.0, 0.0))
    assert model.normal_tangential(ny, -nx, nx, ny) == pytest.approx((0.0, 1.0))
    assert model.outside_friction_cone(1.0, 0.6, 0.5)
    assert not model.outside_friction_cone(1.0, -0.4, 0.5)


def test_stance_reaction_resolves_the_ground_reaction_along_the_ground():
    P = RobotParams.from_preset("paper").vector()
    x = (0.3, -0.1, 0.7, 1.1)
    a1, a2 = model.accelerations(P, *x, 0.5)
    fx, fy = model.ground_reaction(P, *x, a1, a2)
    assert model.stance_reaction(P, *x, a1, a2, 0.0, 1.0) == (fy, fx)
    nx, ny = model.ground_normal(0.1)
    fn, ft = model.stance_reaction(P, *x, a1, a2, nx, ny)
    assert np.allclose([fn * nx + ft * ny, fn * ny - ft * nx], [fx, fy], rtol=0, atol=1e-12)


def test_heel_strike_on_flat_ground_is_admissible_and_a_backward_throw_is_not():
    P = RobotParams.from_preset("classic").vector()
    mass = 2 * 5.0 + 10.0  # 2 m + mH of the classic walker [kg]
    q1, q2, w1, w2 = 0.4, 0.2, 0.4, 1.2  # flat-ground heel strike, walking forwards
    post = model.impact(P, q1, q2, w1, w2)
    ix, iy = model.impact_impulse(P, q1, q2, w1, w2, *post)
    vm = np.array(model.centre_of_mass_velocity(P, q1, q2, w1, w2))
    vp = np.array(model.centre_of_mass_velocity(P, *post))
    assert np.allclose((ix, iy), mass * (vp - vm), rtol=1e-14, atol=0)
    assert iy > 0.0  # the ground pushes up
    assert model.trailing_foot_normal_velocity(P, *post, 0.0, 1.0) > 0.0
    assert model.impact_admissible(P, q1, q2, w1, w2, *post, 0.0, 1.0, 0.0, 1.0, 1.0)
    # the same impact outside a nearly frictionless cone
    assert abs(ix) > 1e-3 * iy
    assert not model.impact_admissible(P, q1, q2, w1, w2, *post, 0.0, 1.0, 0.0, 1.0, 1e-3 * 0.5)
    # swing leg thrown backwards onto the ground: the trailing foot would go into the ground
    pre = (0.21, 0.1, -4.0, 0.0)
    post = model.impact(P, *pre)
    assert model.trailing_foot_normal_velocity(P, *post, 0.0, 1.0) <= 0.0
    assert not model.impact_admissible(P, *pre, *post, 0.0, 1.0, 0.0, 1.0, 1.0)


@pytest.mark.parametrize("preset", ["classic", "paper"])
def test_touchdown_configuration_puts_the_full_length_swing_foot_on_the_foothold(preset):
    params = RobotParams.from_preset(preset)
    P, l = params.vector(), params.l  # noqa: E741
    rng = np.random.default_rng(3)
    for dx, dh in zip(rng.uniform(0.2, 1.2, 20) * l, rng.uniform(-0.3, 0.3, 20) * l):
        q1, q2 = model.touchdown_configuration(dx, dh, l)
        fx, fy = model.swing_foot_position(P, q1, q2, 0.0, 0.0)
        assert abs(fx - dx) < 1e-13 * l and abs(fy - dh) < 1e-13 * l
        # both legs at full length: the hip is symmetric over the chord
        assert model.hip_position(P, q1, q2, 0.0, 0.0)[1] > max(0.0, dh)
    assert math.isnan(model.touchdown_configuration(2.1 * l, 0.0, l)[0])


def test_weight_is_the_gravitational_mass_times_g():
    params = RobotParams.from_preset("paper")
    P = params.vector()
    assert model.weight(P) == (2 * params.m + params.mHg) * params.g
    # the swing-phase ground reaction carries the weight at rest
    assert model.ground_reaction(P, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)[1] == model.weight(P)
