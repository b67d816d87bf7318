"""Online identification of the swing dynamics: the kernel against an independent integrator,
the fit against known coefficients, the robot rebuilt from them, and the reference policy with
it in closed loop under model error."""

import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

import envs  # noqa: F401  (registers the ids)
from controllers import make_reference_policy
from controllers.identification import (
    _INDEX,
    CHI2_99,
    COEFFICIENTS,
    DEFAULT_LONG_SEGMENT,
    EXPLAINED_RMS,
    ROBUST_SCALE,
    SwingIdentifier,
    _acceleration_partials,
    _coefficients,
    _fit_huber,
    _huber,
    _jacobian,
    robot_from_coefficients,
    simulate_swing,
)
from envs.physics import model
from envs.physics.params import RobotParams

DT = 0.005
# every physical parameter off (the input gain too): what robot_error draws
ERRORS = {"m": 0.1, "mH": -0.1, "mHg": 0.1, "Ic": -0.1, "l": 0.08, "lc": -0.05, "ktau": -0.1}


def nominal() -> RobotParams:
    return RobotParams.from_preset("paper")


def coefficients_in_nominal_scale(true: RobotParams, nom: RobotParams) -> np.ndarray:
    """What identification can see: the true coefficients in the nominal input's scale."""
    c, s = true.coefficients(), nom.input_gain / true.input_gain
    return np.array([s * c[f"p{i}"] for i in range(1, 6)] + [s * true.Fc, s * true.Fv])


def stance_inputs(n: int, phase: float) -> np.ndarray:
    t = np.arange(n) * DT
    return 3.0 * np.sin(9.0 * t + phase) + 1.5


def test_simulated_swing_matches_an_independent_integrator():
    P = nominal().vector()
    x0 = np.array([-0.45, -0.22, 1.8, 1.1])
    u = stance_inputs(40, 0.3)

    def rhs(t, x):
        k = min(int(t / DT + 1e-9), u.size - 2)
        a1, a2 = model.accelerations(P, x[0], x[1], x[2], x[3], u[k])
        return [x[2], x[3], a1, a2]

    q = simulate_swing(P, x0, u, DT, 4)
    y = x0.copy()
    for k in range(u.size - 1):  # piecewise-constant input: one solve per interval
        sol = solve_ivp(rhs, (k * DT, (k + 1) * DT), y, rtol=1e-11, atol=1e-12)
        y = sol.y[:, -1]
        assert np.allclose(q[k + 1], y[:2], atol=1e-8)


def test_acceleration_partials_are_the_models_derivatives():
    """By the state and by each coefficient, against the complex step through
    ``model.accelerations`` (by the state on a robot without Coulomb friction, whose sign the
    complex step would differentiate)."""
    rng = np.random.default_rng(1)
    h = 1e-30
    for Fc in (0.0, 0.02):
        P = nominal().replace(Fc=Fc).vector()
        for _ in range(50):
            x = rng.uniform([-0.6, -0.4, -3.0, -2.0], [0.6, 0.4, 3.0, 2.0])
            u = rng.uniform(-3.0, 3.0)
            D = np.empty((2, 11))
            _acceleration_partials(P, *x, *model.accelerations(P, *x, u), D)
            ref = np.empty((2, 11))
            for j in range(4):
                xc = x.astype(complex)
                xc[j] += 1j * h
                ref[:, j] = np.imag(model.accelerations(P.astype(complex), *xc, u)) / h
            for j, k in enumerate(_INDEX):
                Pc = P.astype(complex)
                Pc[k] += 1j * h
                ref[:, 4 + j] = np.imag(model.accelerations(Pc, *x, u)) / h
            cols = slice(0 if Fc == 0.0 else 4, 11)
            err = np.abs(D - ref)[:, cols] / np.abs(ref[:, cols]).max(axis=1, keepdims=True)
            assert np.all(err < 1e-12), err


def noisy_stances(seed: int, knock: bool = False) -> tuple[SwingIdentifier, np.random.Generator]:
    """An identifier of the nominal robot (1 mrad encoders) given three 90-sample stances of the
    robot ``ERRORS`` off, with 1 mrad noise drawn from ``default_rng(seed)`` (with ``knock``,
    0.02 rad added mid-way through the second stance's ``q2``: no initial state explains it);
    and that generator."""
    P = nominal().perturbed(ERRORS).vector()
    rng = np.random.default_rng(seed)
    ident = SwingIdentifier(nominal(), DT, angle_sigma=1e-3)
    starts = [[-0.5, -0.25, 2.0, 1.2], [-0.42, -0.2, 1.6, 0.9], [-0.48, -0.23, 2.4, 1.0]]
    for i, x0 in enumerate(starts):
        u = stance_inputs(90, i)
        q = simulate_swing(P, np.array(x0), u, DT, 4) + rng.normal(0.0, 1e-3, (90, 2))
        if knock and i == 1:
            q[45:60, 1] += 0.02
        ident.add_stance(q, u)
    return ident, rng


def test_jacobian_is_the_derivative_of_the_simulated_residuals():
    """The residuals are the simulated minus measured angles (bit for bit as
    :func:`simulate_swing` integrates them) and the sensitivities' Jacobian is their derivative:
    against central differences (Richardson-extrapolated) to 1e-8 of each column's largest
    entry, at a point away from the fit's start."""
    ident, rng = noisy_stances(0)
    p0, scale, args = ident._problem(ident._short, [0, 1, 2, 4, 6, 7], ident._z, ident.prior)
    Pm, index, nom_c, free_index, ratio, prior, Q, U, bounds, dt, nsub, sig = args
    nf = free_index.size
    p = p0 + 0.3 * scale * rng.normal(size=p0.size)
    r, Jt, Jd = _jacobian(p, *args)

    Pm = Pm.copy()
    Pm[index] = nom_c * (1.0 + _coefficients(p[:nf], free_index, ratio))
    np.testing.assert_array_equal(r[:nf], p[:nf] / prior)
    for s, (a, b) in enumerate(zip(bounds, bounds[1:])):
        d = p[nf + 4 * s : nf + 4 * s + 4]
        sim = simulate_swing(
            Pm, np.array([Q[a, 0] + d[0], Q[a, 1] + d[1], d[2], d[3]]), U[a:b], dt, nsub
        )
        np.testing.assert_array_equal(r[nf + 2 * a : nf + 2 * b], ((sim - Q[a:b]) / sig).ravel())

    def central(cols, h):
        e = p.copy()
        e[cols] += h
        up = _jacobian(e, *args)[0]
        e[cols] -= 2 * h
        return (up - _jacobian(e, *args)[0]) / (2 * h)

    # the k-th initial-state component of every segment at once, as Jd holds them
    cols = [[j] for j in range(nf)] + [list(range(nf + k, p.size, 4)) for k in range(4)]
    ref = np.column_stack([(4 * central(c, 1e-4) - central(c, 2e-4)) / 3 for c in cols])
    ref[:nf, nf:] = 0.0
    J = np.hstack([Jt, Jd])
    assert np.all(np.abs(J - ref) < 1e-8 * np.abs(J).max(axis=0))


def test_fit_recovers_the_coefficients_of_a_perturbed_robot_from_its_stances():
    nom = nominal()
    true = nom.perturbed({**ERRORS, "Fv": 0.3})
    theta_true = coefficients_in_nominal_scale(true, nom)
    P = true.vector()
    starts = [[-0.5, -0.25, 2.0, 1.2], [-0.42, -0.2, 1.6, 0.9], [-0.48, -0.23, 2.4, 1.0]]
    # short segments alone (the default), and with long ones: noise-free stances explain the
    # long segments (0.3 s and the 0.15 s tail of each stance), whose fit is then returned
    for long_segment, segments in ((0.0, 9), (0.3, 6)):
        ident = SwingIdentifier(nom, DT, angle_sigma=1e-5, long_segment=long_segment)
        ident.leg_length = true.l  # what the localisation measures
        for i, x0 in enumerate(starts):
            u = stance_inputs(90, i)
            # the same input on the true robot, whose input gain differs (what the env does)
            q = simulate_swing(P, np.array(x0), u, DT, 4)
            assert ident.add_stance(q, u) == 3  # 0.45 s in segments of 0.15 s
        fit = ident.fit()
        assert fit.long == (long_segment > 0)
        assert fit.segments == segments and fit.rms < 1e-5  # the fit integrates with 2 substeps
        assert fit.significant
        err = fit.theta / theta_true - 1
        assert np.all(np.abs(err[:5]) < 2e-3), dict(zip(COEFFICIENTS, err))
        assert abs(err[6]) < 0.05  # viscous friction: a small term, still seen
    # and the nominal robot's own stance (integrated as the fit does) gives back the nominal
    # coefficients, which the data then do not reject
    ident = SwingIdentifier(nom, DT, angle_sigma=1e-5)
    ident.add_stance(simulate_swing(nom.vector(), np.array(starts[0]), u, DT, 2), u)
    fit = ident.fit()
    assert np.all(np.abs(fit.relative) < 1e-4) and not fit.significant


def walking_stances(P, pushes=(), seed=0):
    """Four noisy stances of 0.5 s of the robot ``P`` from states about those of the paper
    robot's gait (encoder noise 1.5e-3 rad, about the env's), each pushed at the samples in
    ``pushes`` (a hip push: ``q2d`` up by 0.3 rad/s, ``q1d`` down by as much)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(4):
        x = np.array([-0.42 - 0.02 * i, -0.21, 0.3 + 0.1 * i, 0.95 + 0.05 * i])
        u = 0.5 * stance_inputs(100, i)
        q = np.empty((100, 2))
        for k in range(100):
            q[k] = x[:2]
            if k in pushes:
                x[2:] += (-0.3, 0.3)
            for _ in range(4):
                a1, a2 = model.accelerations(P, *x, u[k])
                x = np.array(model.swing_rk4(P, *x, u[k], DT / 4, a1, a2)[:4])
        out.append((q + rng.normal(0.0, 1.5e-3, q.shape), u))
    return out


def test_long_segments_see_the_level_of_p3_and_p5_that_short_ones_miss():
    """A robot at a corner of +-10 % on every parameter (p5 53 % below the nominal, p3 21 %):
    from four noisy stances the fit on segments of 0.3 s gets p3 and p5 to within 0.1 (within
    its posterior spread, 0.1 and 0.18), where the short segments' fit alone (``long_segment=0``)
    stays near the nominal, 0.3 and 0.45 off."""
    nom = nominal()
    true = nom.perturbed(
        {"m": -0.1, "mH": -0.1, "mHg": 0.1, "Ic": 0.1, "l": -0.1, "lc": -0.1, "ktau": -0.1}
    )
    z_true = coefficients_in_nominal_scale(true, nom) / coefficients_in_nominal_scale(nom, nom)
    z_true -= 1.0
    assert z_true[4] < -0.5 and z_true[2] < -0.2
    fits = {}
    for long_segment in (0.3, 0.0):
        ident = SwingIdentifier(nom, DT, angle_sigma=1.5e-3, long_segment=long_segment)
        ident.leg_length = true.l
        for q, u in walking_stances(true.vector()):
            ident.add_stance(q, u)
        fits[long_segment] = ident.fit()
    assert fits[0.3].long and not fits[0.0].long
    err_long = np.abs(fits[0.3].relative - z_true)[[2, 4]]
    err_short = np.abs(fits[0.0].relative - z_true)[[2, 4]]
    assert np.all(err_long < 0.1), err_long
    assert np.all(err_short > 0.3), err_short


def test_a_push_within_a_long_segment_falls_back_to_the_short_segments_fit():
    """On the nominal robot, a hip push 0.15 s into every stance, within the first long segment:
    the long segments are left unexplained (rms above EXPLAINED_RMS), and the fit returned is
    the short segments', the same as without long segments, which keeps the nominal model."""
    nom = nominal()
    fits = []
    for long_segment in (0.3, 0.0):
        ident = SwingIdentifier(nom, DT, angle_sigma=1.5e-3, long_segment=long_segment)
        for q, u in walking_stances(nom.vector(), pushes=(30,)):
            ident.add_stance(q, u)
        fits.append(ident.fit())
    long = ident_long_fit(nom, walking_stances(nom.vector(), pushes=(30,)))
    assert np.min(long) > EXPLAINED_RMS
    assert not fits[0].long and not fits[0].significant
    np.testing.assert_array_equal(fits[0].relative, fits[1].relative)


def test_the_long_segments_refine_only_a_model_the_short_ones_reject():
    """On the nominal robot, unpushed, the long segments are explained, but the short
    segments' fit does not reject the nominal model: it is the fit returned, as without long
    segments (a long fit is free to take a small push for another robot)."""
    nom = nominal()
    stances = walking_stances(nom.vector())
    assert np.max(ident_long_fit(nom, stances)) <= EXPLAINED_RMS
    fits = []
    for long_segment in (0.3, 0.0):
        ident = SwingIdentifier(nom, DT, angle_sigma=1.5e-3, long_segment=long_segment)
        for q, u in stances:
            ident.add_stance(q, u)
        fits.append(ident.fit())
    assert not fits[0].significant and not fits[0].long
    np.testing.assert_array_equal(fits[0].relative, fits[1].relative)


def ident_long_fit(nom, stances):
    """Each long segment's rms residual [standard deviations] under the fit on them."""
    ident = SwingIdentifier(nom, DT, angle_sigma=1.5e-3, long_segment=0.3)
    for q, u in stances:
        ident.add_stance(q, u)
    which = list(range(len(ident._long.segments)))
    return ident._fit(ident._long, which, np.zeros(7), ident.long_prior)[1]


def test_robot_from_coefficients_has_them_and_changes_the_nominal_robot_least():
    nom = nominal()
    true = nom.perturbed(ERRORS)
    theta = coefficients_in_nominal_scale(true, nom)
    robot = robot_from_coefficients(nom, theta, true.l)
    assert robot.l == pytest.approx(true.l) and robot.input_gain == nom.input_gain
    c = robot.coefficients()
    assert np.allclose([c[f"p{i}"] for i in range(1, 6)], theta[:5], rtol=1e-5)
    assert (robot.Fc, robot.Fv) == pytest.approx(tuple(theta[5:]))
    nom_theta = coefficients_in_nominal_scale(nom, nom)
    same = robot_from_coefficients(nom, nom_theta)
    for k in ("m", "mH", "mHg", "Ic", "lc", "l"):
        assert getattr(same, k) == pytest.approx(getattr(nom, k), rel=1e-7)
    with pytest.raises(ValueError, match="7 finite numbers"):
        robot_from_coefficients(nom, np.r_[theta[:6], np.nan])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"angle_sigma": 0.0}, "angle_sigma = 0.0; allowed: > 0"),
        ({"angle_sigma": 1e-3, "segment": -1.0}, "segment = -1.0; allowed: > 0"),
        ({"angle_sigma": 1e-3, "prior": (0.1,) * 6}, "prior = .*7 numbers > 0"),
        ({"angle_sigma": 1e-3, "long_prior": (0.1,) * 6 + (0.0,)}, "long_prior = .*7 numbers"),
        ({"angle_sigma": 1e-3, "long_segment": -0.3}, "long_segment = -0.3; allowed: >= 0"),
        ({"angle_sigma": 1e-3, "substeps": 0}, "substeps = 0"),
    ],
)
def test_bad_identification_settings_are_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SwingIdentifier(nominal(), DT, **kwargs)
    with pytest.raises(ValueError, match="stance: q must be"):
        SwingIdentifier(nominal(), DT, 1e-3).add_stance(np.zeros((10, 3)), np.zeros(10))


@pytest.mark.parametrize("identify", [-1, 1.5, True])
def test_bad_identify_values_are_errors(identify):
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    with pytest.raises(ValueError, match="identify = .*an integer >= 0"):
        make_reference_policy(env, identify=identify)


def test_long_segments_are_the_policys_default_and_can_be_turned_off():
    """On by default (segments of 0.3 s); ``long_segment=0`` leaves the short segments' fits
    alone; the value reaches the identifier and the policy's recorded settings."""
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    default, off = make_reference_policy(env), make_reference_policy(env, long_segment=0.0)
    assert default.settings()["long_segment"] == DEFAULT_LONG_SEGMENT == 0.3
    assert default.identifier.long_samples == round(0.3 / default.identifier.dt)
    assert off.identifier._long is None and off.settings()["long_segment"] == 0.0


@pytest.mark.parametrize("long_segment", [-0.1, 1.5, float("nan"), "0.3", True])
def test_bad_long_segment_values_are_errors(long_segment):
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    with pytest.raises(ValueError, match=r"long_segment = .*allowed: a number in \[0, 1\]"):
        make_reference_policy(env, long_segment=long_segment)


def walk(env, policy, seed):
    obs, info = env.reset(seed=seed)
    policy.reset()
    while True:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            return info, info["robot"] if "robot" in info else None


def test_identification_walks_stairs_courses_the_nominal_model_fails_on():
    """Every parameter 10 % off (random sign), 8 validation courses (seeds from 1,000,000):
    after each of the first six footsteps (the default) the policy fits the swing dynamics and
    switches model where the data reject the one in use. It walks every course the nominal
    model walks and at least 2 more (the nominal model walks 6 with the paper robot's defaults,
    5 with the beam's far shapes on 40,000 a replanning, the defaults before them), on each it
    walks the fits switched model, and the identified leg length (from the localisation's
    drift) has at most half the nominal one's error in the median; a reset goes back to the
    nominal robot."""
    env = gym.make("roughwalk/CompassGaitStairs-v0", robot_error={"all": 0.1, "draw": "sign"})
    plain = make_reference_policy(env, identify=0)
    policy = make_reference_policy(env)
    walked = {"plain": 0, "identified": 0}
    leg_errors = []
    for seed in range(1_000_000, 1_000_008):
        info, _ = walk(env, plain, seed)
        plain_walked = info["failure"] is None
        walked["plain"] += plain_walked
        true_l = env.reset(seed=seed)[1]["robot"]["l"]
        info, _ = walk(env, policy, seed)
        if info["failure"] is not None:
            assert not plain_walked, (seed, info["failure"])
            continue
        walked["identified"] += 1
        fits = policy.diagnostics["identified"]
        assert [r.footstep for r in fits] == [1, 2, 3, 4, 5, 6]
        assert any(r.switched for r in fits) and policy.robot is not policy.nominal_robot
        assert fits[-1].leg_length == policy.robot.l
        nominal_l = policy.nominal_robot.l
        leg_errors.append(abs(policy.robot.l - true_l) / abs(nominal_l - true_l))
        policy.reset()
        assert policy.robot is policy.nominal_robot
        assert policy.estimator.robot is policy.controller.robot is policy.nominal_robot
    assert walked["identified"] >= walked["plain"] + 2, walked
    assert np.median(leg_errors) < 0.5, leg_errors


def test_identification_keeps_the_nominal_model_for_the_nominal_robot():
    """On the nominal robot the fits stay near the nominal coefficients and the data do not
    reject the nominal model: the policy keeps it (and walks)."""
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    policy = make_reference_policy(env)
    for seed in (1_000_000, 1_000_001):
        info, _ = walk(env, policy, seed)
        assert info["failure"] is None
        fits = policy.diagnostics["identified"]
        assert len(fits) == 6 and not any(r.switched for r in fits)
        assert all(r.distance2 < CHI2_99 for r in fits)
        # the last fit again, with its posterior spread: p3 and p5 (the gravity terms) are
        # the least informed (sd 6-8 % and 10-13 % on these courses, p1, p2, p4 1-1.5 %)
        last = policy.identifier.fit()
        np.testing.assert_allclose(last.relative, fits[-1].relative, atol=1e-4)
        assert np.all(np.abs(last.relative[:5]) < 3.0 * last.sigma[:5]), (last.relative, last.sigma)
        assert policy.robot is policy.nominal_robot


def test_block_solver_reaches_scipys_huber_minimum_and_covariance():
    """The Schur-complement solver against scipy's dense trust-region solver on the same Huber
    cost, with encoder noise and one stance pushed mid-way (samples beyond the threshold); its
    coefficient covariance against the dense inverse of scipy's robust Gauss-Newton Hessian."""
    ident, _ = noisy_stances(4, knock=True)
    which = list(range(len(ident.segments)))
    p0, scale, args = ident._problem(ident._short, which, ident._z, ident.prior)
    x, _, A, B, C = _fit_huber(p0, scale, args)

    def residuals(p):
        return _jacobian(p, *args)[0]

    ref = least_squares(
        residuals, p0, x_scale=scale, loss="huber", f_scale=ROBUST_SCALE, xtol=1e-12, ftol=1e-12
    )
    cost = _huber(residuals(x), ROBUST_SCALE)[0]
    assert np.sum(np.abs(residuals(x)) > ROBUST_SCALE) > 10  # the knock is beyond the threshold
    assert cost <= ref.cost * (1 + 1e-8)  # the solver stops at a relative decrease of 1e-8
    nf = len(COEFFICIENTS) - 1
    # the dense Jacobian at the solution, scaled as scipy scales it for the Huber loss
    r, Jt, Jd = _jacobian(x, *args)
    bounds = args[8]
    J = np.zeros((r.size, x.size))
    J[:, :nf] = Jt
    for s in range(bounds.size - 1):
        rows = slice(nf + 2 * bounds[s], nf + 2 * bounds[s + 1])
        J[rows, nf + 4 * s : nf + 4 * s + 4] = Jd[rows]
    w = _huber(r, ROBUST_SCALE)[2]
    Jw = J * np.sqrt(w)[:, None]
    dense = np.linalg.inv(Jw.T @ Jw)[:nf, :nf]
    schur = np.linalg.inv(A - sum(b @ np.linalg.solve(c, b.T) for b, c in zip(B, C)))
    assert np.allclose(schur, dense, rtol=1e-6, atol=0)
    # the same coefficients, to a hundredth of their posterior standard deviation
    assert np.all(np.abs(x[:nf] - ref.x[:nf]) < 0.01 * np.sqrt(np.diag(schur)))
