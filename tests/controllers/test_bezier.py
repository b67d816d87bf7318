"""Bezier polynomials and Bezier virtual constraints."""

import numpy as np
import pytest

from controllers.bezier import (
    BezierConstraint,
    bernstein_basis,
    bezier,
    bezier_derivative_coeffs,
    chord_coefficients,
)


def test_basis_partition_of_unity_and_endpoints():
    s = np.linspace(0.0, 1.0, 11)
    for m in (1, 4, 6):
        b = bernstein_basis(m, s)
        assert b.shape == (11, m + 1)
        np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-14)
        assert np.all(b >= 0)
        a = np.arange(m + 1.0) ** 2
        assert bezier(a, 0.0) == pytest.approx(a[0], abs=1e-14)
        assert bezier(a, 1.0) == pytest.approx(a[-1], abs=1e-14)


@pytest.mark.parametrize("order", [3, 4, 6])
def test_derivatives_match_finite_differences(order):
    rng = np.random.default_rng(order)
    a = rng.normal(size=order + 1)
    s = np.linspace(-0.1, 1.1, 13)  # including a little extrapolation
    h = 1e-5
    for d in (0, 1):
        fd = (bezier(a, s + h, d) - bezier(a, s - h, d)) / (2 * h)
        np.testing.assert_allclose(bezier(a, s, d + 1), fd, rtol=1e-7, atol=1e-7)
    # end slopes: M (a1 - a0) and M (aM - aM-1); derivative coefficients agree
    assert bezier(a, 0.0, 1) == pytest.approx(order * (a[1] - a[0]))
    assert bezier(a, 1.0, 1) == pytest.approx(order * (a[-1] - a[-2]))
    np.testing.assert_allclose(bezier(bezier_derivative_coeffs(a), s), bezier(a, s, 1))
    assert np.all(bezier(a, s, order + 1) == 0.0)


def test_batch_evaluation_matches_single():
    a = np.array([[0.0, 1.0, -1.0, 2.0, 0.5], [1.0, 0.0, 0.0, 0.0, -1.0]])
    s = np.linspace(0, 1, 7)
    out = bezier(a, s, 1)
    assert out.shape == (2, 7)
    for k in range(2):
        np.testing.assert_allclose(out[k], bezier(a[k], s, 1))


def test_constraint_chain_rule_and_boundary_coefficients():
    c = BezierConstraint(np.array([-0.5, -0.4, 0.2, 0.6, 0.5]), -0.25, 0.3)
    th = np.linspace(-0.25, 0.3, 9)
    h = 1e-6
    np.testing.assert_allclose(c.dphi(th), (c.phi(th + h) - c.phi(th - h)) / (2 * h), rtol=1e-7)
    np.testing.assert_allclose(c.ddphi(th), (c.dphi(th + h) - c.dphi(th - h)) / (2 * h), rtol=1e-6)
    ph, dph, ddph = c.derivatives(th)
    np.testing.assert_allclose(ph, c.phi(th))
    np.testing.assert_allclose(dph, c.dphi(th))
    np.testing.assert_allclose(ddph, c.ddphi(th))
    assert c.phi(c.theta_plus) == pytest.approx(-0.5)
    assert c.phi(c.theta_minus) == pytest.approx(0.5)
    # a_1 and a_{M-1} from prescribed end slopes
    a1 = BezierConstraint.second_coeff(-0.5, 0.7, -0.25, 0.3, 4)
    a3 = BezierConstraint.penultimate_coeff(0.5, 1.3, -0.25, 0.3, 4)
    c2 = BezierConstraint(np.array([-0.5, a1, 0.0, a3, 0.5]), -0.25, 0.3)
    assert c2.dphi(-0.25) == pytest.approx(0.7)
    assert c2.dphi(0.3) == pytest.approx(1.3)


def test_bad_input_raises():
    with pytest.raises(ValueError, match="theta_minus"):
        BezierConstraint(np.zeros(5), 0.3, 0.2)
    with pytest.raises(ValueError, match="finite"):
        BezierConstraint(np.array([0.0, np.nan, 0.0]), 0.0, 1.0)
    with pytest.raises(ValueError, match="order"):
        bernstein_basis(-1, 0.5)
    with pytest.raises(ValueError, match="coeffs"):
        bezier(np.zeros((2, 2, 2)), 0.5)


def test_chord_coefficients_run_straight_from_the_first_to_the_last():
    k = np.arange(5)
    line = chord_coefficients(-0.4, 0.5, k, 4)
    assert line[0] == -0.4 and line[-1] == 0.5
    np.testing.assert_allclose(np.diff(line), 0.9 / 4, rtol=1e-14)
    # the scalar form (the planner kernel's) gives the same coefficients
    assert [chord_coefficients(-0.4, 0.5, int(i), 4) for i in k] == line.tolist()
    # a Bezier polynomial on its chord is a straight line in s
    s = np.linspace(0.0, 1.0, 7)
    np.testing.assert_allclose(bezier(line, s), -0.4 + 0.9 * s, atol=1e-15)


def test_derivatives_in_one_pass_are_phi_and_its_derivatives_bit_for_bit():
    """``derivatives`` takes the powers of ``s`` and ``1 - s`` once for the three bases: the
    same numbers as ``phi``, ``dphi`` and ``ddphi`` evaluated one by one, at a scalar and at
    arrays, for every order."""
    rng = np.random.default_rng(7)
    for order in range(1, 8):
        c = BezierConstraint(rng.normal(size=order + 1), -0.2, 0.25)
        for theta in (0.03, rng.uniform(-0.3, 0.35, 17), rng.uniform(-0.2, 0.25, (2, 5))):
            for got, want in zip(
                c.derivatives(theta), (c.phi(theta), c.dphi(theta), c.ddphi(theta))
            ):
                assert np.shape(got) == np.shape(want)
                assert np.asarray(got).tobytes() == np.asarray(want).tobytes()


def test_normalised_phase_is_the_compiled_fraction_of_the_span():
    """``s`` is ``(theta - theta_plus) / span`` to the last bit (compiled, entry by entry): a
    numpy float at a scalar, an array of the same shape otherwise, strided arrays included."""
    rng = np.random.default_rng(8)
    c = BezierConstraint(rng.normal(size=5), -0.2113, 0.2471)
    for theta in (0.031, 3, rng.uniform(-0.3, 0.35, 17), rng.uniform(-0.3, 0.3, (4, 6))[:, ::2]):
        want = (np.asarray(theta, dtype=np.float64) - c.theta_plus) / c.span
        got = c.s(theta)
        assert type(got) is type(want) and np.shape(got) == np.shape(want)
        assert np.asarray(got).tobytes() == np.asarray(want).tobytes()


def test_compiled_basis_is_its_numpy_formula_bit_for_bit():
    """The basis (compiled from numpy's powers of ``s`` and ``1 - s``) is what the formula gives
    on numpy arrays, to the last bit: every order and derivative, at a scalar and at arrays."""
    from scipy.special import comb

    rng = np.random.default_rng(9)
    for order in range(9):
        for s in (0.37, rng.uniform(-0.2, 1.2, 7), rng.uniform(-0.2, 1.2, (3, 5)), np.zeros(0)):
            sb = np.asarray(s)[..., None]
            k = np.arange(order + 1)
            up, down = sb**k, (1.0 - sb) ** k
            for deriv in range(4):
                want = np.zeros(np.shape(s) + (order + 1,))
                if deriv <= order:
                    m = order - deriv
                    low = comb(m, np.arange(m + 1), exact=False) * up[..., : m + 1]
                    low = low * down[..., m::-1]
                    scale = float(np.prod(np.arange(order, m, -1.0)))
                    for i in range(deriv + 1):
                        w = scale * (-1.0) ** (deriv - i) * comb(deriv, i, exact=False)
                        want[..., i : i + m + 1] += w * low
                got = bernstein_basis(order, s, deriv)
                assert got.shape == want.shape and got.tobytes() == want.tobytes()
