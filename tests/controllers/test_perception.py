"""Perception: stance-foot localisation from the terrain scan, and maps built from the scans."""

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from controllers import make_reference_policy
from controllers.estimator import SensorStateEstimator
from controllers.localisation import ESTIMATES, NOMINAL_DRIFT, ScanLocaliser
from controllers.mapping import ScanMap
from envs.physics.terrain import Terrain
from envs.sensors import SensorConfig

OFFSETS = SensorConfig().scan_offsets  # 0.05 ... 0.50 m ahead of the stance foot
NOISE = 0.002  # m, the envs' scan noise
BLOCKS = Terrain.random_blocks(7, start=0.3, length=6.0, width_range=(0.1, 0.3),
                               height_range=(-0.0075, 0.0075))  # fmt: skip


def scan(terrain, x, rng, readings):
    """The mean of ``readings`` noisy, quantised scans from a foot at ``x`` [m]."""
    exact = terrain.height(x + OFFSETS) - terrain.height(x)
    noisy = exact + NOISE * rng.standard_normal((readings, OFFSETS.size))
    return np.round(noisy / 1e-3).mean(axis=0) * 1e-3


def walk(terrain, scale, localise, seed=0, steps=40, length=0.14, estimate="mean"):
    """Estimated minus true stance-foot x [m] at each touchdown of a walk whose true steps are
    ``scale`` times the dead-reckoned ones (a leg ``scale - 1`` off), with or without the
    scan's corrections: the mean scan of each stance (50 readings), then the new one."""
    rng = np.random.default_rng(seed)
    loc = ScanLocaliser(OFFSETS, np.hypot(NOISE, 1e-3 / 12**0.5), 0.3, estimate=estimate)
    true = est = 0.0
    errors = []
    for _ in range(steps):
        if localise:
            est += loc.update(est, scan(terrain, true, rng, 50), terrain.height, readings=50).shift
        true += scale * length
        est += length
        if localise:
            est += loc.predict(length)
            est += loc.update(est, scan(terrain, true, rng, 1), terrain.height).shift
        errors.append(est - true)
    return np.array(errors)


@pytest.mark.parametrize("estimate", ESTIMATES)
def test_drift_stays_bounded_under_a_leg_length_error(estimate):
    dead = walk(BLOCKS, 0.95, localise=False)
    loc = walk(BLOCKS, 0.95, localise=True, estimate=estimate)
    assert abs(dead[-1]) > 0.25  # m: 7 mm a step, 40 steps
    assert np.abs(loc).max() < 0.025 and np.abs(loc[-10:]).max() < 0.012


@pytest.mark.parametrize("estimate", ESTIMATES)
def test_localisation_does_not_worsen_the_nominal_case(estimate):
    errors = walk(BLOCKS, 1.0, localise=True, estimate=estimate)
    assert np.abs(errors).max() < 0.006  # m


def test_the_selected_estimate_keeps_a_right_model_short_of_a_stair_edge():
    """A nominal robot's first step ends with a scan point 0.6 mm short of a stair edge, which
    bounds the error on one side only: the belief's mean moves the foot back by millimetres
    (the wrong model's wide drifts, cut on one side), the mean given the likelier, right model
    by less, and by a fraction of a millimetre with the odometry's calibrated noise. Where the
    scans rule the right model out (legs 5 % off, on blocks) the two estimates are the same."""
    stairs = Terrain.stairs(edges=[0.40, 0.62], rises=[-0.03, -0.03])
    step = 0.40 - 0.25 - 0.0006  # the scan point 0.25 m ahead lands 0.6 mm short of the edge

    def error(estimate, odometry_error=0.02):
        loc = ScanLocaliser(
            OFFSETS, 0.001, 0.3, odometry_error, initial_sigma=0.0, estimate=estimate
        )
        s = stairs.height(step + OFFSETS) - stairs.height(step)  # exact readings
        est = step + loc.predict(step)
        return est + loc.update(est, s, stairs.height).shift - step

    assert error("mean") < -0.003 and -0.0025 < error("selected") < 0  # m
    assert error("mean", 0.005) < -0.002 and abs(error("selected", 0.005)) < 0.001
    for scale in (0.95, 1.05):
        mean, selected = (walk(BLOCKS, scale, True, estimate=e) for e in ESTIMATES)
        assert np.abs(mean[10:] - selected[10:]).max() < 1e-6


def test_flat_ground_gives_no_correction():
    loc = ScanLocaliser(OFFSETS, 0.002, 0.3)
    flat = Terrain.flat()
    rng = np.random.default_rng(1)
    for k in range(10):
        assert abs(loc.predict(0.14)) < 1e-12
        res = loc.update(0.14 * (k + 1), scan(flat, 0.0, rng, 1), flat.height)
        assert abs(res.shift) < 1e-12 and res.sigma == pytest.approx(res.sigma_prior, rel=1e-9)
    assert loc.sigma > 0.002  # the uncertainty grows, the estimate stays


def test_localiser_bad_arguments():
    with pytest.raises(ValueError, match="odometry_error"):
        ScanLocaliser(OFFSETS, 0.002, 0.3, odometry_error=-1.0)
    with pytest.raises(ValueError, match="estimate = 'mode'; allowed: mean, selected"):
        ScanLocaliser(OFFSETS, 0.002, 0.3, estimate="mode")
    loc = ScanLocaliser(OFFSETS, 0.002, 0.3)
    with pytest.raises(ValueError, match="10 heights"):
        loc.update(0.0, np.zeros(3), Terrain.flat().height)
    with pytest.raises(ValueError, match="readings"):
        loc.update(0.0, np.zeros(10), Terrain.flat().height, readings=0)


def test_map_from_scans_finds_the_block_edges():
    rng = np.random.default_rng(2)
    m = ScanMap()
    x = 0.0
    while x < 3.0:  # the mean scan of each stance, as the estimator fuses them
        m.add_scan((x, float(BLOCKS.height(x))), OFFSETS, scan(BLOCKS, x, rng, 50), 50)
        x += 0.137
    terrain = m.terrain()
    every = [f[0] for f in BLOCKS.vertical_faces() if abs(f[2] - f[1]) > 1e-3]
    true = [f for f in BLOCKS.vertical_faces() if abs(f[2] - f[1]) > 0.005 and f[0] < 3.2]
    faces = terrain.vertical_faces()
    assert len(true) >= 5
    for xf, _, _ in faces:  # the scanner's noise makes no faces
        assert min(abs(np.subtract(every, xf))) < 0.015
    for xf, a, b in true:  # within half the gap between scanned points on either side
        assert min(abs(f[0] - xf) for f in faces) < 0.015
        assert abs(terrain.height(xf - 0.03) - a) < 0.002
        assert abs(terrain.height(xf + 0.03) - b) < 0.002


def test_map_bad_arguments():
    with pytest.raises(ValueError, match="cell"):
        ScanMap(cell=0.0)
    with pytest.raises(ValueError, match="no readings"):
        ScanMap().terrain()


def test_mapping_mode_walks_the_stairs_without_the_course():
    env = gym.make("roughwalk/CompassGaitStairs-v0", max_episode_steps=1000)
    policy = make_reference_policy(env, mapping=True)
    obs, info = env.reset(seed=1_000_000)
    env.unwrapped.terrain = None  # the policy must not need the true course
    policy.reset()
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
    assert info["failure"] is None and info["distance"] > 0.8  # past both stairs
    faces = [f for f in policy.terrain.vertical_faces() if f[2] - f[1] < -0.02]
    assert [round(f[0], 1) for f in faces] == [0.4, 0.6]
    assert [f[2] - f[1] for f in faces] == pytest.approx([-0.03, -0.03], abs=0.003)


def test_estimator_perception_options():
    env = gym.make("roughwalk/CompassGaitFlat-v0", sensors={"scan_count": 0})
    with pytest.raises(ValueError, match="scan_count"):
        SensorStateEstimator(env, localise=True)
    with pytest.raises(ValueError, match="odometry_error"):
        SensorStateEstimator(gym.make("roughwalk/CompassGaitFlat-v0"), odometry_error=-0.1)
    with pytest.raises(ValueError, match="cannot be combined"):
        SensorStateEstimator(gym.make("roughwalk/CompassGaitFlat-v0"), localise=True, mapping=True)
    flat = gym.make("roughwalk/CompassGaitFlat-v0")
    with pytest.raises(ValueError, match="foot_estimate = 'mode'; allowed: mean, selected"):
        SensorStateEstimator(flat, localise=True, foot_estimate="mode")
    with pytest.raises(ValueError, match="needs localise"):
        SensorStateEstimator(flat, localise=False, foot_estimate="selected")
    est = SensorStateEstimator(flat, localise=True, foot_estimate="selected")
    assert est.localiser.estimate == "selected"


def test_localised_policy_walks_a_block_course_with_a_shorter_leg():
    """The policy is built for the nominal robot and walks one whose legs are 5 % shorter; a
    second estimator, fed the same readings, dead-reckons without the scan."""
    nominal = envs.RobotParams.from_preset("paper")
    short = nominal.replace(l=0.95 * nominal.l, lc=0.95 * nominal.lc)
    kwargs = {"max_episode_steps": 1600}  # 8 s
    model_env = gym.make("roughwalk/CompassGaitRough-v0", **kwargs)
    env = gym.make("roughwalk/CompassGaitRough-v0", robot=short, **kwargs)
    policy = make_reference_policy(model_env, localise=True)
    dead = SensorStateEstimator(model_env)
    model_env.reset(seed=1_000_000)  # the same course: the policy's map
    obs, info = env.reset(seed=1_000_000)
    policy.reset()
    u, errors, leg, done = 0.0, [], info["stance_leg"], False
    while not done:
        action = policy(obs)
        dead.update(*dead.decode(obs), u)
        u = float(action[0]) * policy.u_max
        if leg != info["stance_leg"] or not errors:
            leg = info["stance_leg"]
            errors.append((policy.stance_foot[0], dead.stance_foot[0], info["stance_foot"][0]))
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    assert info["failure"] is None and info["footsteps"] >= 8
    est, dr, true = np.array(errors).T
    assert abs(dr[-1] - true[-1]) > 0.04  # m: about 7 mm a footstep
    # the prior's even odds on a right model slow the drift's learning over the first steps
    assert np.abs(est - true).max() < 0.025 and abs(est[-1] - true[-1]) < 0.01


def test_localisation_keeps_the_nominal_estimate():
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    policy = make_reference_policy(env, localise=True)
    obs, info = env.reset(seed=4)
    policy.reset()
    feet = []
    for _ in range(700):
        action = policy(obs)
        feet.append(abs(policy.stance_foot[0] - info["stance_foot"][0]))
        obs, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
    assert info["footsteps"] >= 4 and len(policy.estimator.corrections) == info["footsteps"]
    # m: dead reckoning alone stays within 5 mm here; a scan that fits over an interval of
    # shifts may move the foot by a few millimetres within it
    assert max(feet) < 8e-3


def test_localiser_belief_is_the_exact_posterior_on_a_staircase():
    """Without odometry noise the true foot error is ``e0 + r * walked`` for an initial error
    ``e0`` and a drift ``r``: the posterior over that plane, by brute force on a fine grid,
    is what the filter's corrections and drift must equal. The stair risers, scanned 5 cm
    apart, bound the error on one side only, which a Gaussian belief gets wrong."""
    stairs = Terrain.stairs(edges=[0.40, 0.62], rises=[0.0125, 0.0125])
    sigma = np.hypot(NOISE, 1e-3 / 12**0.5)
    loc = ScanLocaliser(OFFSETS, sigma, 0.3, odometry_error=0.0, initial_sigma=0.004)
    rng = np.random.default_rng(3)
    e0 = np.linspace(-0.02, 0.02, 801)[None, :]
    r = np.linspace(-0.15, 0.15, 601)[:, None]
    wide, nominal = (
        np.exp(-0.5 * (r / 0.05) ** 2) / 0.05,
        np.exp(-0.5 * (r / NOMINAL_DRIFT) ** 2) / NOMINAL_DRIFT,
    )
    logp = -0.5 * (e0 / 0.004) ** 2 + np.log(0.5 * wide + 0.5 * nominal)
    true = est = walked = 0.0
    for _ in range(5):
        length = rng.uniform(0.13, 0.17)
        true += 1.03 * length  # the drift: 3 %
        est += length
        walked += length
        est += loc.predict(length)
        s = scan(stairs, true, rng, 1)
        est += loc.update(est, s, stairs.height).shift
        cost, _, _ = loc._match(walked, (e0 + r * walked).ravel(), s, sigma, stairs.height, None)
        logp = logp - cost.reshape(logp.shape)
        w = np.exp(logp - logp.max())
        w /= w.sum()
        assert est - walked == pytest.approx(float((w * (e0 + r * walked)).sum()), abs=5e-4)
        assert loc.drift == pytest.approx(float((w * r).sum()), abs=3e-3)


def test_localiser_drift_is_re_referred_to_a_new_leg_length():
    loc = ScanLocaliser(OFFSETS, 0.002, 0.3)
    rng = np.random.default_rng(4)
    true = est = 0.0
    for _ in range(10):  # on the blocks with steps 4 % longer than dead-reckoned
        true += 0.15 * 1.04
        est += 0.15
        est += loc.predict(0.15)
        est += loc.update(est, scan(BLOCKS, true, rng, 1), BLOCKS.height).shift
    drift = loc.drift
    assert drift == pytest.approx(0.04, abs=0.01)
    loc.rescale(1.04)  # the dead reckoning's legs now 4 % longer: no drift left
    assert loc.drift == pytest.approx((1 + drift) / 1.04 - 1, abs=1e-3)
    with pytest.raises(ValueError, match="ratio"):
        loc.rescale(0.0)


def _moved_rows(p, a):
    """Each row of ``p`` moved by ``a[j]`` grid points by linear interpolation, zero beyond the
    grid (numpy)."""
    n = p.shape[1]
    grid = np.arange(-1, n + 1)
    return np.stack(
        [np.interp(np.arange(n) - aj, grid, np.r_[0.0, row, 0.0]) for row, aj in zip(p, a)]
    )


@pytest.mark.parametrize("sigma", [None, 0.3, 1.0, 6.0, 12.5])
def test_the_belief_moves_and_blurs_as_interpolation_and_scipy_filter_do(sigma):
    """The predict step's compiled kernel: rows moved by their drift (linear interpolation, mass
    off the grid lost) and blurred by the odometry's Gaussian, as numpy's interpolation and
    SciPy's ``gaussian_filter1d`` (``mode="constant"``) give them."""
    from scipy.ndimage import gaussian_filter1d

    from controllers.localisation import _BLUR_TRUNCATE, _NO_BLUR, _gaussian_weights
    from controllers.localisation import _shift_and_blur as shift_and_blur

    rng = np.random.default_rng(3)
    p = rng.random((9, 61)) * (rng.random((9, 61)) < 0.7)
    a = np.r_[rng.normal(0.0, 4.0, 8), 70.0]  # the last row moved off the grid entirely
    moved = _moved_rows(p, a)
    w = _NO_BLUR if sigma is None else _gaussian_weights(sigma, _BLUR_TRUNCATE)
    got = shift_and_blur(p, a, w)
    want = moved
    if sigma is not None:
        want = gaussian_filter1d(moved, sigma, axis=1, mode="constant", truncate=_BLUR_TRUNCATE)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert np.all(got[-1] == 0.0)
    # the compiled loops give the sums of the same code run by Python, bit for bit
    np.testing.assert_array_equal(got, shift_and_blur.py_func(p, a, w))


def test_row_medians_are_numpys_medians_bit_for_bit():
    """The scan match's compiled medians: numpy's ``median(axis=1)`` value and sign (a zero
    median is +0 as numpy's mean makes it), even and odd counts, ties, zeros of both signs,
    infinities and NaN."""
    from controllers.localisation import _row_medians

    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 8, 11, 12):
        for _ in range(20):
            R = rng.normal(size=(40, n))
            R[0] = 0.0
            R[1, : n // 2 + 1] = -0.0
            R[2] = rng.choice([-0.0, 0.0, 1.0, -1.0], n)
            R[3] = rng.integers(-2, 3, n) * 0.5
            R[4, rng.integers(n)] = np.nan
            R[5] = np.inf * rng.choice([-1.0, 1.0], n)
            R[6, 0] = -np.inf
            with np.errstate(invalid="ignore"):
                want = np.median(R, axis=1)
            got = _row_medians(R)
            np.testing.assert_array_equal(got, want)
            np.testing.assert_array_equal(np.signbit(got), np.signbit(want))
