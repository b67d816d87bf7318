"""Transverse linearization: A(t), B(t) and F_j against the nonlinear model."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from controllers.bezier import BezierConstraint
from controllers.reduced import (
    ChebyshevSeries,
    nominal_accelerations,
    pfl_terms,
    reduced_coefficients,
)
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


# ---------------------------------------------------------------------------- compiled = numpy
def _models(rng, count):
    """Random steps around the hand-made chain's (both robots, orders 4 to 6, sloped switching
    surfaces), and the two steps whose speed profile needs a shorter margin."""
    out = []
    for k in range(count):
        P = RobotParams.from_preset(("paper", "classic")[k % 2]).vector()
        order = 4 + k % 3
        th0 = rng.uniform(0.15, 0.25)
        a = np.linspace(-2 * th0, 2 * th0, order + 1) + 0.05 * rng.standard_normal(order + 1)
        c = BezierConstraint(a, -th0 + 0.02 * rng.standard_normal(), th0)
        try:
            slope = rng.uniform(-0.2, 0.2)  # a float or a numpy float, as a terrain gives it
            slope = np.float64(slope) if k % 4 < 2 else slope
            out.append(StepModel(P, c, rng.uniform(0.9, 1.6), slope))
        except ValueError:
            pass
    out.append(StepModel(P, BezierConstraint(np.array(MARGIN_A), *MARGIN_TH), 0.7753035964756947))
    return out


MARGIN_A = [-0.29102594500881324, -0.2640678151438681, 0.0928026563809734, 1.3565597272147574]
MARGIN_A += [0.13804921681533533, 0.30097754751602745, 0.273031028035243]
MARGIN_TH = (-0.14551297250440662, 0.09976735897462588)


def _ref_derivatives(m, th):
    """``(phi, phi', phi'')`` by numpy's polyval of the model's power form."""
    from numpy.polynomial import polynomial as npoly

    c, pc = m.constraint, m.power_coefficients
    s = (np.asarray(th, dtype=np.float64) - c.theta_plus) / c.span
    ders = (pc, npoly.polyder(pc) / c.span, npoly.polyder(pc, 2) / c.span**2)
    return tuple(npoly.polyval(s, d) for d in ders)


def _ref_speed(m, th):
    """The speed profile ``F*`` by numpy's chebval of the model's series."""
    from numpy.polynomial import chebyshev as cheb

    F = m._F
    x = (2.0 * np.asarray(th, dtype=np.float64) - F.theta_a - F.theta_b) / (F.theta_b - F.theta_a)
    return cheb.chebval(x, F.coef)


def _ref_profile(m):
    """``(margin, F* at the Chebyshev nodes)`` as the speed profile was built with numpy arrays
    (the model's power form given)."""
    from controllers.reduced import phase_grid, reduced_integral

    c = m.constraint
    mid = 0.5 * (c.theta_plus + c.theta_minus)
    phi, dphi, ddphi = (float(v) for v in _ref_derivatives(m, mid))
    sign = np.sign(reduced_coefficients(m.P, phi, mid, dphi, ddphi)[0])
    for margin in dict.fromkeys([0.15 * 0.5**k for k in range(4)] + [0.0]):
        a, b = c.theta_plus - margin * c.span, c.theta_minus + margin * c.span
        th = phase_grid(a, b, 48)
        phi, dphi, ddphi = _ref_derivatives(m, th)
        al, be, ga = reduced_coefficients(m.P, phi, th, dphi, ddphi)
        if not np.all(sign * al > 1e-12):
            continue
        psi, gam = reduced_integral(th, al, be, ga)
        psi_s, gam_s = ChebyshevSeries(psi, a, b), ChebyshevSeries(gam, a, b)
        fa = (m.thetadot_plus**2 - gam_s(c.theta_plus)) / psi_s(c.theta_plus)
        F_nodes = psi * fa + gam
        if min(F_nodes.min(), ChebyshevSeries(F_nodes, a, b)(np.linspace(a, b, 257)).min()) > 0:
            return margin, F_nodes


def _ref_coefficients(m, th):
    """``(a11, a12, a13, b1, thetadot)``: the complex steps through the model on numpy arrays."""
    P, H = m.P, 1e-30
    phi, dphi, ddphi = _ref_derivatives(m, th)
    al, be, ga = reduced_coefficients(P, phi, th, dphi, ddphi)
    F = _ref_speed(m, th)
    td = np.sqrt(F)
    q1dd, thdd = nominal_accelerations(al, be, ga, dphi, ddphi, F)
    q1c = phi + 1j * H
    _, m12, m22 = model.mass_matrix(P, q1c)
    _, c2 = model.coriolis(P, q1c, dphi * td + 0j, td + 0j)
    _, g2 = model.gravity(P, q1c, th + 0j)
    dPhi_dq1 = np.imag(m12 * q1dd + m22 * thdd + c2 + g2) / H
    _, c2d = model.coriolis(P, phi + 0j, dphi * td + 1j * H, td + 0j)
    k = 2.0 * td / al
    return -k * be, k * -dPhi_dq1, k * -(np.imag(c2d) / H), k * -model.mass_matrix(P, phi)[1], td


def _ref_dthetadot_sq(m, th):
    phi, dphi, ddphi = _ref_derivatives(m, th)
    al, be, ga = reduced_coefficients(m.P, phi, th, dphi, ddphi)
    return 2.0 * nominal_accelerations(al, be, ga, dphi, ddphi, _ref_speed(m, th))[1]


def _ref_coords_jacobian(m, x):
    _, th, _, thd = (float(v) for v in x)
    _, dphi, ddphi = (float(v) for v in _ref_derivatives(m, th))
    dF = float(_ref_dthetadot_sq(m, np.float64(th)))
    return np.array(
        [[0.0, -dF, 0.0, 2.0 * thd], [1.0, -dphi, 0.0, 0.0], [0.0, -ddphi * thd, 1.0, -dphi]]
    )


def _ref_impact_jacobian(m, nxt):
    P, H = m.P, 1e-30
    th = np.float64(m.theta_minus)
    phi, dphi, _ = _ref_derivatives(m, th)
    td = np.sqrt(_ref_speed(m, th))
    xm = np.stack([phi, th + 0.0 * phi, dphi * td, td + 0.0 * phi], axis=-1)
    grad = np.zeros(4)
    for i, (a, b) in enumerate(((xm[0] + 1j * H, xm[1] + 0j), (xm[0] + 0j, xm[1] + 1j * H))):
        fx, fy = model.swing_foot_position(P, a, b, 0.0, 0.0)
        grad[i] = np.imag(fy - m.ground_slope * fx) / H
    D = np.vstack([_ref_coords_jacobian(m, xm), grad])
    dXs = np.linalg.solve(D, np.vstack([np.eye(3), np.zeros((1, 3))]))
    xc = np.tile(xm.astype(complex)[:, None], (1, 4)) + 1j * H * np.eye(4)
    dDelta = np.imag(np.array(model.impact(P, xc[0], xc[1], xc[2], xc[3]))) / H
    xp = np.array(model.impact(P, *xm))
    return _ref_coords_jacobian(nxt, xp) @ dDelta @ dXs, xm, grad


def _same(got, want):
    got, want = np.asarray(got), np.asarray(want)
    return got.shape == want.shape and got.tobytes() == want.tobytes()


def test_compiled_step_model_is_its_numpy_formulas_bit_for_bit():
    """The step model's compiled kernels (speed profile, linearization, nominal state,
    Jacobians, impact Jacobian) give what their formulas give on numpy arrays, to the last bit,
    on random steps of both robots, on the gain grid and at points past the step's ends."""
    rng = np.random.default_rng(11)
    models = _models(rng, 24)
    assert len(models) > 15 and models[-1].margin < 0.15
    for m, nxt in zip(models, models[1:] + models[:1]):
        margin, F_nodes = _ref_profile(m)
        assert m.margin == margin
        a, b = m._F.theta_a, m._F.theta_b
        assert _same(m._F.coef, ChebyshevSeries(F_nodes, a, b).coef)
        grid = np.linspace(m.theta_plus, m.theta_minus, 81)
        for th in (grid, rng.uniform(a, b, 13), np.float64(rng.uniform(a, b))):
            want = _ref_coefficients(m, np.atleast_1d(th))
            assert all(_same(g, w) for g, w in zip(m.coefficients(th), want))
            assert _same(m.dthetadot_sq(th), _ref_dthetadot_sq(m, th))
            phi, dphi, _ = _ref_derivatives(m, th)
            td = np.sqrt(_ref_speed(m, th))
            state = np.stack([phi, th + 0.0 * phi, dphi * td, td + 0.0 * phi], axis=-1)
            assert _same(m.nominal_state(th), state)
        A, B, w = m.phase_matrices(grid)
        a11, a12, a13, b1, td = _ref_coefficients(m, grid)
        assert _same(w, 1.0 / td) and _same(A[:, 1, 2], 1.0 / td) and _same(B[:, 2, 0], 1.0 / td)
        assert _same(A[:, 0], np.stack([a11 / td, a12 / td, a13 / td], axis=-1))
        assert _same(B[:, 0, 0], b1 / td)
        assert np.count_nonzero(A) == 4 * grid.size and np.count_nonzero(B) == 2 * grid.size
        F, xm, grad = _ref_impact_jacobian(m, nxt)
        assert _same(impact_jacobian(m, nxt), F)
        assert _same(m.coords_jacobian(xm), _ref_coords_jacobian(m, xm))
        assert _same(m.surface_gradient(xm[0], xm[1]), grad)
