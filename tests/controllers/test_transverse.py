"""Transverse linearization: A(t), B(t) and F_j against the nonlinear model."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from controllers.bezier import BezierConstraint
from controllers.reduced import pfl_terms
from controllers.transverse import StepModel, impact_jacobian, impact_jacobian_fd, surface_state
from envs.physics import model
from envs.physics.params import RobotParams

K0 = np.array([0.5, -30.0, -9.0])  # some fixed feedback v = K0 x_perp for the closed loop


def _nonlinear(P, step, theta_a, theta_b, x0):
    """Closed loop y_ddot = K0 x_perp through the full model, theta as independent variable."""

    def f(th, x):
        q1, q2, q1d, q2d = x
        z = step.coords(x)
        n, r = pfl_terms(P, q1, q2, q1d, q2d, step.constraint.dphi(q2), step.constraint.ddphi(q2))
        u = (K0 @ z - r) / n
        a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, u)
        return np.array([q1d, q2d, a1, a2]) / q2d

    r = solve_ivp(f, (theta_a, theta_b), x0, method="DOP853", rtol=1e-12, atol=1e-13)
    return r.y[:, -1]


def _linear(step, theta_a, theta_b, z0):
    def f(th, z):
        A, B, _ = step.phase_matrices(np.array([th]))
        return (A[0] + B[0] @ K0[None, :]) @ z

    r = solve_ivp(f, (theta_a, theta_b), z0, method="DOP853", rtol=1e-12, atol=1e-15)
    return r.y[:, -1]


@pytest.mark.parametrize("direction", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.3, -0.5, 2.0)])
def test_continuous_linearization_error_is_quadratic(chain, state_from_z, direction):
    P, steps = chain
    st = steps[0]
    ta, tb = st.theta_plus, st.theta_minus
    d = np.array(direction) / np.linalg.norm(direction)
    errs = []
    for eps in (4e-3, 2e-3, 1e-3):
        x0 = state_from_z(st, ta, eps * d)
        np.testing.assert_allclose(st.coords(x0), eps * d, atol=1e-12)
        z_nl = st.coords(_nonlinear(P, st, ta, tb, x0))
        z_lin = _linear(st, ta, tb, eps * d)
        assert np.linalg.norm(z_lin) > 0.1 * eps  # the prediction is not trivially small
        errs.append(np.linalg.norm(z_nl - z_lin))
    # mismatch O(eps^2): halving eps divides it by about 4
    assert 3.0 < errs[0] / errs[1] < 5.0 and 3.0 < errs[1] / errs[2] < 5.0
    assert errs[-1] < 0.05 * 1e-3


def test_time_and_phase_forms_agree(chain):
    _, steps = chain
    st = steps[1]
    th = np.linspace(st.theta_plus, st.theta_minus, 7)
    A, B = st.matrices(th)
    Ap, Bp, w = st.phase_matrices(th)
    np.testing.assert_allclose(Ap, A * w[:, None, None])
    np.testing.assert_allclose(Bp, B * w[:, None, None])
    assert np.all(A[:, 1:, :2] == 0) and np.all(A[:, 1, 2] == 1) and np.all(B[:, 2, 0] == 1)


def test_impact_jacobian_closed_form_matches_finite_differences(chain):
    _, steps = chain
    for j in range(2):
        F = impact_jacobian(steps[j], steps[j + 1])
        Ffd = impact_jacobian_fd(steps[j], steps[j + 1], h=1e-6)
        assert np.abs(F - Ffd).max() < 1e-6 * max(1.0, np.abs(F).max())
        # the nominal pre-impact point maps onto the next step's nominal start (z = 0)
        x = surface_state(steps[j], np.zeros(3))
        z1 = steps[j + 1].coords(np.array(model.impact(steps[j].P, *x)))
        assert np.abs(z1).max() < 1e-10


def test_impact_jacobian_matches_flow_impact_flow(chain, state_from_z):
    """F_j inside the full nonlinear flow -> impact -> flow map between two phase sections."""
    P, steps = chain
    s0, s1 = steps[0], steps[1]
    ta = s0.theta_minus - 0.03
    tb = s1.theta_plus + 0.03

    def flow_map(z):
        x = state_from_z(s0, ta, z)

        def f(th, x):
            q1, q2, q1d, q2d = x
            n, r = pfl_terms(P, q1, q2, q1d, q2d, s0.constraint.dphi(q2), s0.constraint.ddphi(q2))
            a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, -r / n)
            return np.array([q1d, q2d, a1, a2]) / q2d

        def hit(th, x):
            return s0.surface(x[0], x[1])

        hit.terminal, hit.direction = True, -1
        r = solve_ivp(f, (ta, ta + 0.1), x, events=hit, method="DOP853", rtol=1e-13, atol=1e-14)
        xm = r.y_events[0][0]
        xp = np.array(model.impact(P, *xm))

        def g(th, x):
            q1, q2, q1d, q2d = x
            n, r = pfl_terms(P, q1, q2, q1d, q2d, s1.constraint.dphi(q2), s1.constraint.ddphi(q2))
            a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, -r / n)
            return np.array([q1d, q2d, a1, a2]) / q2d

        r = solve_ivp(g, (xp[1], tb), xp, method="DOP853", rtol=1e-13, atol=1e-14)
        return s1.coords(r.y[:, -1])

    def transition(step, a, b):
        def f(th, Phi):
            A, _, _ = step.phase_matrices(np.array([th]))
            return (A[0] @ Phi.reshape(3, 3)).ravel()

        return (
            solve_ivp(f, (a, b), np.eye(3).ravel(), rtol=1e-12, atol=1e-14).y[:, -1].reshape(3, 3)
        )

    pred = (
        transition(s1, s1.theta_plus, tb)
        @ impact_jacobian(s0, s1)
        @ transition(s0, ta, s0.theta_minus)
    )
    h = 1e-6
    J = np.zeros((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        J[:, i] = (flow_map(e) - flow_map(-e)) / (2 * h)
    assert np.abs(flow_map(np.zeros(3))).max() < 1e-9
    assert np.abs(J - pred).max() < 1e-5 * np.abs(pred).max()


def test_margin_shrinks_where_the_continued_constraint_is_singular():
    """A step onto a 1 cm rise replanned in closed loop (classic walker): its order-6
    constraint continued 15 % past theta- makes alpha change sign; the extension shrinks
    instead of the step being rejected, and the profile on the step is unchanged."""
    P = RobotParams.from_preset("classic").vector()
    a = [-0.29102594500881324, -0.2640678151438681, 0.0928026563809734, 1.3565597272147574]
    a += [0.13804921681533533, 0.30097754751602745, 0.273031028035243]
    c = BezierConstraint(np.array(a), -0.14551297250440662, 0.09976735897462588)
    m = StepModel(P, c, 0.7753035964756947, margin=0.15)
    assert 0.0 < m.margin < 0.15
    th = np.linspace(c.theta_plus - m.margin * c.span, c.theta_minus + m.margin * c.span, 501)
    assert np.all(m.thetadot_sq(th) > 0)
    ref = StepModel(P, c, 0.7753035964756947, margin=0.0)
    on = np.linspace(c.theta_plus, c.theta_minus, 201)
    np.testing.assert_allclose(m.thetadot_sq(on), ref.thetadot_sq(on), atol=1e-6)


def test_theta_dot_squared_stays_positive_between_the_chebyshev_nodes():
    """A slow step with a sharply bent constraint (planned from a basin start 3-4 units of
    ``sqrt(V)`` off the gait): with its 15 % margins ``theta_dot^2`` is positive at the Chebyshev
    nodes but dips below zero between them, and ``theta_dot = sqrt(F)`` on the gain grid was
    NaN (silent: the feedback then applied zero input). The margins now shrink until it is
    positive everywhere on the range."""
    P = RobotParams.from_preset("paper").vector()
    a = [
        -0.4027158415806616,
        -0.3937959122157784,
        7.389249615112188,
        -1.5133353531748073,
        0.25435639694546675,
        0.4410665218416667,
    ]
    c = BezierConstraint(np.array(a), -0.2013579207903308, 0.22053326092083336)
    m = StepModel(P, c, 0.39185373744840823, margin=0.15)
    assert 0.0 < m.margin < 0.15
    lo, hi = c.theta_plus - m.margin * c.span, c.theta_minus + m.margin * c.span
    assert np.all(m.thetadot_sq(np.linspace(lo, hi, 4001)) > 0)
    on = np.linspace(c.theta_plus, c.theta_minus, 81)
    assert all(np.all(np.isfinite(x)) for x in m.phase_matrices(on))
    ref = StepModel(P, c, 0.39185373744840823, margin=0.0)
    # the constraint bends sharply: 48 Chebyshev nodes resolve the profile to 0.01 rad^2/s^2
    np.testing.assert_allclose(m.thetadot_sq(on), ref.thetadot_sq(on), atol=0.01)


def test_power_form_is_numpys_polyfit_and_polyval_bit_for_bit():
    """The constraint's power form is what ``numpy.polynomial.polynomial.polyfit`` gives
    through its values at the Chebyshev points, and ``(phi, phi', phi'')`` what ``polyval``
    gives, to the last bit, at a scalar and at arrays of any shape."""
    from numpy.polynomial import polynomial as npoly

    P = RobotParams.from_preset("paper").vector()
    rng = np.random.default_rng(5)
    for order in (4, 5, 6):
        a = -0.2 + 0.05 * rng.standard_normal(order + 1)
        c = BezierConstraint(a, -0.25, 0.2)
        step = StepModel(P, c, 1.1)
        sn = 0.5 * (1 - np.cos(np.pi * np.arange(order + 1) / order))
        pc = npoly.polyfit(sn, c.phi(c.theta_plus + sn * c.span), order)
        assert step.power_coefficients.tobytes() == pc.tobytes()
        ders = (pc, npoly.polyder(pc) / c.span, npoly.polyder(pc, 2) / c.span**2)
        for theta in (0.01, rng.uniform(-0.3, 0.25, 9), rng.uniform(-0.25, 0.2, (2, 3))):
            s = c.s(theta)
            for got, coef in zip(step.derivatives(theta), ders):
                want = npoly.polyval(s, coef)
                assert np.shape(got) == np.shape(want)
                assert np.asarray(got).tobytes() == np.asarray(want).tobytes()
