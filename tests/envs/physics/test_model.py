"""Model equations: impact map (closed form vs. momentum derivation), momenta, energy."""

import numpy as np
import pytest

from envs import model
from envs.params import RobotParams


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
