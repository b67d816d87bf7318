"""Reduced dynamics along a virtual constraint, impact along constraints, PFL terms."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from controllers import reduced as rd
from controllers.bezier import BezierConstraint
from envs.physics import model
from envs.physics.params import RobotParams

ROBOTS = ["paper", "classic"]
C = BezierConstraint(np.array([-0.5, -0.3, 0.0, 0.3, 0.5]), -0.25, 0.25)


def _abg(P, c, th):
    ph, dph, ddph = c.derivatives(th)
    return rd.reduced_coefficients(P, ph, np.asarray(th, float), dph, ddph)


@pytest.mark.parametrize("robot", ROBOTS)
def test_integral_matches_ode_solution(robot):
    """psi theta_dot0^2 + Gam solves dF/dtheta = -2 (beta F + gamma) / alpha."""
    P = RobotParams.from_preset(robot).vector()
    th = rd.phase_grid(C.theta_plus, C.theta_minus, 32)
    al, be, ga = _abg(P, C, th)
    psi, gam = rd.reduced_integral(th, al, be, ga)
    td0 = 1.5

    def rhs(t, f):
        a, b, g = _abg(P, C, t)
        return -2.0 * (b * f + g) / a

    sol = solve_ivp(rhs, th[[0, -1]], [td0**2], t_eval=th, rtol=1e-12, atol=1e-12, method="DOP853")
    np.testing.assert_allclose(psi * td0**2 + gam, sol.y[0], atol=1e-9)
    assert psi[0] == 1.0 and abs(gam[0]) < 1e-15
    # time along the step: dt/dtheta = 1/theta_dot
    f = psi * td0**2 + gam
    t = rd.step_time(th, f)
    sol_t = solve_ivp(
        lambda x, y: 1.0 / np.sqrt(rd.ChebyshevSeries(f, th[0], th[-1])(x)),
        th[[0, -1]],
        [0.0],
        rtol=1e-12,
        atol=1e-13,
    )
    assert t[-1] == pytest.approx(sol_t.y[0, -1], rel=1e-9)


@pytest.mark.parametrize("robot", ROBOTS)
def test_beta_matches_christoffel_symbols_of_the_mass_matrix(robot):
    """Independent check: Christoffel symbols by finite differences of M(q1)."""
    P = RobotParams.from_preset(robot).vector()
    th = np.linspace(-0.25, 0.25, 7)
    ph, dph, ddph = C.derivatives(th)
    h = 1e-6
    dm = [
        (np.array(model.mass_matrix(P, ph + h)) - np.array(model.mass_matrix(P, ph - h))) / (2 * h)
    ]
    dm11, dm12, dm22 = dm[0]  # M depends on q1 only
    g211 = dm12 - 0.5 * dm11 * 0  # 1/2 (2 dM21/dq1 - dM11/dq2), dM11/dq2 = 0
    g212 = 0.5 * dm22  # 1/2 (dM21/dq2 + dM22/dq1 - dM12/dq2)
    g222 = 0.0
    _, m12, _ = model.mass_matrix(P, ph)
    beta_ref = m12 * ddph + g211 * dph**2 + 2 * g212 * dph + g222
    _, beta, _ = rd.reduced_coefficients(P, ph, th, dph, ddph)
    np.testing.assert_allclose(beta, beta_ref, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("robot", ROBOTS)
def test_pfl_keeps_the_constraint_and_gives_the_reduced_dynamics(robot):
    P = RobotParams.from_preset(robot).vector()
    rng = np.random.default_rng(0)
    for _ in range(5):
        th = rng.uniform(-0.25, 0.25)
        ph, dph, ddph = C.derivatives(th)
        q1, q2 = ph + rng.normal(scale=0.05), th
        q1d, q2d = rng.normal(), rng.uniform(0.5, 2.0)
        n, r = rd.pfl_terms(P, q1, q2, q1d, q2d, dph, ddph)
        for v in (0.0, 3.0):
            u = (v - r) / n
            a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, u)
            assert a1 - dph * a2 - ddph * q2d**2 == pytest.approx(v, abs=1e-9)
        # on the constraint with y_ddot = 0 the unactuated row is the reduced dynamics
        q1, q1d = ph, dph * q2d
        n, r = rd.pfl_terms(P, q1, q2, q1d, q2d, dph, ddph)
        a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, -r / n)
        al, be, ga = rd.reduced_coefficients(P, ph, th, dph, ddph)
        assert al * a2 + be * q2d**2 + ga == pytest.approx(0.0, abs=1e-9)
        assert rd.nominal_input(P, ph, th, dph, ddph, q2d) == pytest.approx(-r / n)


@pytest.mark.parametrize("robot", ROBOTS)
def test_impact_along_constraint_matches_the_impact_map(robot):
    P = RobotParams.from_preset(robot).vector()
    q1m, dphm, thdm = 0.45, 1.3, 1.1
    delta, slope = rd.impact_along_constraint(P, q1m, dphm)
    _, _, w1, w2 = model.impact(P, q1m, 0.5 * q1m, dphm * thdm, thdm)
    assert w2 == pytest.approx(delta * thdm, rel=1e-12)
    assert w1 / w2 == pytest.approx(slope, rel=1e-12)


def test_chebyshev_series_interpolates_smooth_functions():
    th = rd.phase_grid(-0.3, 0.4, 24)
    f = rd.ChebyshevSeries(np.exp(np.sin(3 * th)), -0.3, 0.4)
    x = np.linspace(-0.3, 0.4, 101)
    np.testing.assert_allclose(f(x), np.exp(np.sin(3 * x)), atol=1e-10)
    np.testing.assert_allclose(
        f.derivative(x), 3 * np.cos(3 * x) * np.exp(np.sin(3 * x)), atol=1e-7
    )
    ci = rd.cumulative_integral(np.cos(th), -0.3, 0.4)
    np.testing.assert_allclose(ci, np.sin(th) - np.sin(-0.3), atol=1e-14)


def test_the_series_is_numpys_chebval_bit_for_bit():
    """The compiled recurrence evaluates a series as ``numpy``'s ``chebval`` does, to the last
    bit, at a scalar (a float) and at arrays of any shape, and so does its derivative."""
    from numpy.polynomial import chebyshev as cheb

    rng = np.random.default_rng(4)
    for n in (4, 16, 48):
        s = rd.ChebyshevSeries(rng.standard_normal(n + 1), -0.3, 0.4)
        dc = cheb.chebder(s.coef) * 2.0 / (s.theta_b - s.theta_a)
        for theta in (0.1, rng.uniform(-0.32, 0.42, 7), rng.uniform(-0.3, 0.4, (3, 5))):
            x = s._x(theta)
            for got, want in (
                (s(theta), cheb.chebval(x, s.coef)),
                (s.derivative(theta), cheb.chebval(x, dc)),
            ):
                if np.ndim(theta) == 0:
                    assert isinstance(got, float) and got == float(want)
                else:
                    assert got.shape == want.shape and got.tobytes() == want.tobytes()


def test_the_compiled_series_is_numpys_chebval_bit_for_bit_four_points_at_a_time():
    """The compiled call (:func:`series_at`, four recurrences side by side) gives ``chebval``
    of the series' points to the last bit, on grids of every length modulo four, and so does
    one point at a time."""
    from numpy.polynomial import chebyshev as cheb

    rng = np.random.default_rng(6)
    for ncoef in (2, 3, 5, 49):
        coef = rng.standard_normal(ncoef) * 10.0 ** rng.integers(-3, 3, ncoef)
        for size in (*range(10), 81, 257):
            theta = rng.uniform(-0.35, 0.45, size)
            x = (2.0 * theta - -0.3 - 0.4) / (0.4 - -0.3)
            assert rd.chebyshev_point(theta, -0.3, 0.4).tobytes() == x.tobytes()
            got = rd.series_at(theta, -0.3, 0.4, coef)
            assert got.shape == (size,) and got.tobytes() == cheb.chebval(x, coef).tobytes()
            assert all(rd._clenshaw_at(v, coef) == cheb.chebval(v, coef) for v in x)


def test_bad_grid_and_nonpositive_speed_raise():
    with pytest.raises(ValueError, match="grid size"):
        rd.cheb_nodes(2)
    th = rd.phase_grid(0.0, 1.0, 8)
    with pytest.raises(ValueError, match="theta_dot"):
        rd.step_time(th, np.linspace(1.0, -0.1, 9))


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_compiled_grid_integrals_are_the_reduced_integral_and_step_time(robot):
    """The planner kernel's integrals on one grid: without a floor they are
    :func:`reduced_integral` and :func:`step_time`; the floors bound ``alpha`` and
    ``theta_dot^2`` from below in the integrands."""
    P = RobotParams.from_preset(robot).vector()
    n = 24
    th = rd.phase_grid(C.theta_plus, C.theta_minus, n)
    al, be, ga = _abg(P, C, th)
    q = rd.cumulative_integral_matrix(n)
    half = 0.5 * (th[-1] - th[0])
    psi, gam = np.empty(n + 1), np.empty(n + 1)
    rd.grid_reduced_integral(al, be, ga, q, half, -np.inf, psi, gam)
    ref_psi, ref_gam = rd.reduced_integral(th, al, be, ga)
    np.testing.assert_allclose(psi, ref_psi, rtol=1e-13)
    np.testing.assert_allclose(gam, ref_gam, rtol=1e-12, atol=1e-13)
    floor = 0.5 * (al.min() + al.max())
    rd.grid_reduced_integral(al, be, ga, q, half, floor, psi, gam)
    ref_psi, ref_gam = rd.reduced_integral(th, np.maximum(al, floor), be, ga)
    np.testing.assert_allclose(psi, ref_psi, rtol=1e-13)
    np.testing.assert_allclose(gam, ref_gam, rtol=1e-12, atol=1e-13)
    f = ref_psi * 1.5**2 + ref_gam
    thd, t = np.empty(n + 1), np.empty(n + 1)
    rd.grid_step_time(f, q, half, 0.0, thd, t)
    np.testing.assert_allclose(t, rd.step_time(th, f), rtol=1e-13, atol=1e-15)
    assert np.array_equal(thd, np.sqrt(f))
    lo = f.mean()
    rd.grid_step_time(f, q, half, lo, thd, t)
    np.testing.assert_allclose(t, rd.step_time(th, np.maximum(f, lo)), rtol=1e-13, atol=1e-15)
    # the compiled cumulative integral is the vectorised one
    out = np.empty(n + 1)
    rd.grid_cumulative_integral(np.cos(th), q, half, out)
    np.testing.assert_allclose(out, rd.cumulative_integral(np.cos(th), th[0], th[-1]), atol=1e-15)


@pytest.mark.parametrize("rows", [1, 4, 7, 33, 97])
def test_the_compiled_matrix_vector_product_sums_each_row_in_order(rows):
    """``matvec`` (four rows at a time) gives each entry bit for bit as one running sum over the
    row in order does, and ``a @ x`` to rounding."""
    rng = np.random.default_rng(rows)
    a, x = rng.standard_normal((rows, 33)), rng.standard_normal(33)
    out = np.empty(rows)
    rd.matvec(a, x, out)
    for k in range(rows):
        s = 0.0
        for j in range(x.size):
            s += a[k, j] * x[j]
        assert out[k] == s
    np.testing.assert_allclose(out, a @ x, rtol=1e-12, atol=1e-12)
