"""Jump-Riccati solver against an independent high-accuracy solve (scipy, DOP853)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from controllers import riccati
from controllers.riccati import solve_jump_riccati

LENGTHS = [0.5, 0.4, 0.6, 0.45]


def _A(s, j):
    return np.array(
        [[-0.5 + 0.3 * np.sin(2 * s + j), 1.0 + 0.2 * np.cos(s), 0.3], [0, 0, 1.0], [0, 0, 0]]
    )


def _B(s, j):
    return np.array([[0.4 + 0.1 * np.cos(3 * s + j)], [0.0], [1.0]])


def _w(s, j):
    return 1.0 / (1.5 + 0.5 * np.sin(s + j))


def _samples(nsteps):
    A, B, W, s = [], [], [], 0.0
    for j, L in enumerate(LENGTHS):
        ss = s + np.linspace(0, L, 2 * nsteps + 1)
        A.append(np.array([_A(x, j) for x in ss]))
        B.append(np.array([_B(x, j) for x in ss]))
        W.append(np.array([_w(x, j) for x in ss]))
        s += L
    return A, B, W


def _reference(F, Q, R, Qj, method="DOP853"):
    """Reference in Z alone: Z-equation by DOP853 (Radau where stiff) at tight tolerance, jumps
    in the plain form."""
    ends = np.cumsum(LENGTHS)
    starts = ends - np.array(LENGTHS)
    Z = np.zeros((3, 3))
    out = {}
    for j in range(len(LENGTHS) - 1, -1, -1):
        if j < len(LENGTHS) - 1:
            Z = np.linalg.inv(F[j].T @ np.linalg.solve(Z, F[j]) + Qj)
        out[("end", j)] = Z

        def f(s, zf, j=j):
            Zm = zf.reshape(3, 3)
            A, B, w = _A(s, j), _B(s, j), _w(s, j)
            return (Zm @ A.T + A @ Zm - B @ np.linalg.solve(w * R, B.T) + w * Zm @ Q @ Zm).ravel()

        r = solve_ivp(f, (ends[j], starts[j]), Z.ravel(), method=method, rtol=1e-12, atol=1e-16)
        Z = r.y[:, -1].reshape(3, 3)
        out[("start", j)] = Z
    return out


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(0)
    F = [np.eye(3) + 0.3 * rng.standard_normal((3, 3)) for _ in range(3)]
    Q, R, Qj = np.eye(3), np.eye(1) * 0.7, np.diag([1.0, 2.0, 0.5])
    return F, Q, R, Qj, _reference(F, Q, R, Qj)


def test_matches_high_accuracy_solve_and_converges_at_fourth_order(problem):
    F, Q, R, Qj, ref = problem
    errs = []
    for n in (10, 20, 40):
        A, B, W = _samples(n)
        sol = solve_jump_riccati(A, B, LENGTHS, F, Q, R, Qj, w=W)
        err = max(np.abs(sol.Z[j][0] - ref[("start", j)]).max() for j in range(len(LENGTHS)))
        err = max(err, *(np.abs(sol.Z[j][-1] - ref[("end", j)]).max() for j in range(3)))
        errs.append(err)
        assert np.abs(sol.Z[-1][-1]).max() == 0.0  # terminal condition Z(t_f) = 0
    assert errs[-1] < 5e-8
    # RK4: halving the step divides the error by about 16
    assert errs[0] / errs[1] > 10 and errs[1] / errs[2] > 10


def test_gain_and_lyapunov_matrix(problem):
    F, Q, R, Qj, _ = problem
    A, B, W = _samples(20)
    sol = solve_jump_riccati(A, B, LENGTHS, F, Q, R, Qj, w=W, gain_segments=2)
    for j in range(2):
        for k in range(0, 21, 5):
            Z, Zinv = sol.Z[j][k], sol.Zinv[j][k]
            np.testing.assert_allclose(Zinv @ Z, np.eye(3), atol=1e-9)
            Bk, wk = B[j][2 * k], W[j][2 * k]
            np.testing.assert_allclose(sol.K[j][k], -np.linalg.solve(wk * R, Bk.T) @ Zinv)
            assert np.all(np.linalg.eigvalsh(Z) > 0)


def test_stiff_weights_are_substepped_and_match_a_stiff_solver():
    # a closed loop of about 400 rad/s on the second coordinate: one RK4 step per grid interval
    # (h = 0.025) would diverge to NaN; the substepped intervals follow Radau's solution
    rng = np.random.default_rng(0)
    F = [np.eye(3) + 0.3 * rng.standard_normal((3, 3)) for _ in range(3)]
    Q, R, Qj = np.diag([1.0, 160000.0, 800.0]), np.eye(1), np.eye(3)
    ref = _reference(F, Q, R, Qj, method="Radau")
    A, B, W = _samples(20)
    sol = solve_jump_riccati(A, B, LENGTHS, F, Q, R, Qj, w=W, gain_segments=1)
    for j in range(len(LENGTHS)):
        assert np.all(np.isfinite(sol.Z[j]))
        Zr = ref[("start", j)]
        assert np.abs(sol.Z[j][0] - Zr).max() < 1e-4 * np.abs(Zr).max()
    assert np.all(np.isfinite(sol.K[0]))


def test_stiff_gain_reaches_the_algebraic_riccati_gain():
    # y'' = v with Q = diag(160000, 800), R = 1 over a long horizon: the gain at the start is
    # the infinite-horizon LQR gain, PD with kp = 400, kd = 40 (scipy's CARE gives the same)
    from scipy.linalg import solve_continuous_are

    n = 40
    A = [np.tile(np.array([[0.0, 1.0], [0.0, 0.0]]), (2 * n + 1, 1, 1))] * 2
    B = [np.tile(np.array([[0.0], [1.0]]), (2 * n + 1, 1, 1))] * 2
    Q = np.diag([160000.0, 800.0])
    sol = solve_jump_riccati(A, B, [1.0, 1.0], [np.eye(2)], Q, np.eye(1), np.eye(2))
    P = solve_continuous_are(A[0][0], B[0][0], Q, np.eye(1))
    np.testing.assert_allclose(sol.K[0][0], -(B[0][0].T @ P), rtol=1e-6)
    np.testing.assert_allclose(sol.K[0][0], [[-400.0, -40.0]], rtol=1e-6)


def test_jump_at_singular_Z_uses_woodbury_form():
    # a last segment so short that Z+ at the jump is nearly singular: the plain form
    # (F' Z+^-1 F + Qj)^-1 loses accuracy, the Woodbury form stays finite and symmetric
    A = [np.zeros((41, 3, 3)), np.zeros((3, 3, 3))]
    for a in A:
        a[:, 1, 2] = a[:, 0, 1] = 1.0
    b = np.array([[0.3], [0.0], [1.0]])
    B = [np.tile(b, (41, 1, 1)), np.tile(b, (3, 1, 1))]
    F = [np.array([[1.0, 0.2, 0.0], [0.0, -2.0, 0.0], [0.1, 5.0, 0.5]])]
    sol = solve_jump_riccati(A, B, [0.5, 1e-9], F, np.eye(3), np.eye(1), np.eye(3), gain_segments=0)
    Z = sol.Z[0][-1]
    assert np.all(np.isfinite(sol.Z[0])) and np.all(np.isfinite(sol.Z[1]))
    np.testing.assert_array_equal(Z, Z.T)
    assert np.linalg.eigvalsh(Z).min() > -1e-15
    assert np.linalg.eigvalsh(sol.Z[0][0]).min() > 1e-5  # the first segment restores rank
    # with a regular Z+ the Woodbury jump equals the plain form
    A2, B2 = [A[0], A[0]], [B[0], B[0]]
    sol = solve_jump_riccati(A2, B2, [0.5, 0.4], F, np.eye(3), np.eye(1), np.eye(3))
    Zp = sol.Z[1][0]
    np.testing.assert_allclose(
        sol.Z[0][-1], np.linalg.inv(F[0].T @ np.linalg.solve(Zp, F[0]) + np.eye(3)), atol=1e-12
    )


def test_three_coordinates_are_solved_as_the_generic_solve_does_bit_for_bit(problem, monkeypatch):
    """With n = 3 the solve runs compiled for that size (its products unrolled): the same
    numbers, to the last bit, as the solve compiled for any n, on plain and on substepped
    (stiff) intervals, across the jumps and in the gains; one jump weight or one per jump."""
    F, Q, R, Qj, _ = problem
    A, B, W = _samples(20)

    def generic(A, *args):  # called from Python, n is a plain integer
        riccati._solve_segments(A, *args, A.shape[1])

    for Qs, Qjs in ((Q, Qj), (np.diag([1.0, 160000.0, 800.0]), [Qj, 2.0 * Qj, np.eye(3)])):
        fast = solve_jump_riccati(A, B, LENGTHS, F, Qs, R, Qjs, w=W, gain_segments=2)
        with monkeypatch.context() as m:
            m.setattr(riccati, "_solve", generic)
            ref = solve_jump_riccati(A, B, LENGTHS, F, Qs, R, Qjs, w=W, gain_segments=2)
        for j in range(len(LENGTHS)):
            assert fast.Z[j].tobytes() == ref.Z[j].tobytes()
        for j in range(2):
            assert fast.K[j].tobytes() == ref.K[j].tobytes()
            assert fast.Zinv[j].tobytes() == ref.Zinv[j].tobytes()


def test_bad_inputs_raise():
    A, B, W = _samples(4)
    with pytest.raises(ValueError, match="jump matrices"):
        solve_jump_riccati(A, B, LENGTHS, [np.eye(3)], np.eye(3), np.eye(1), np.eye(3))
    with pytest.raises(ValueError, match="lengths"):
        solve_jump_riccati(A, B, [0.5, -1, 0.2, 0.1], [np.eye(3)] * 3, np.eye(3), 1.0, np.eye(3))
    bad = [a.copy() for a in A]
    bad[1][3, 0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        solve_jump_riccati(bad, B, LENGTHS, [np.eye(3)] * 3, np.eye(3), 1.0, np.eye(3))
