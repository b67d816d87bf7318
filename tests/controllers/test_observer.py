"""High-gain observer: convergence at the designed rate, impacts, quantised and noisy
measurements, the time constant chosen from the encoders' noise."""

import math

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from controllers.estimator import SensorStateEstimator
from controllers.observer import (
    DEFAULT_EPS,
    NOMINAL_ENCODER_NOISE,
    NOMINAL_ENCODER_RESOLUTION,
    HighGainObserver,
    angle_sigma,
    eps_for_noise,
    observer_update,
    predict_touchdown,
)
from envs.physics.params import RobotParams
from envs.physics.passive import CLASSIC_CYCLE
from envs.physics.simulator import Simulator
from envs.physics.terrain import Terrain

# classic walker's passive limit cycle down a 0.0525 rad slope (control notes, section 1)
Q0 = np.array(CLASSIC_CYCLE.q)
QD0 = np.array(CLASSIC_CYCLE.qd)
DT = 0.005


def _run(robot, observer, T, quantum=0.0, locate=True, noise=0.0, seed=0):
    """Passive walk; the observer sees (optionally quantised, optionally noisy: Gaussian of
    standard deviation ``noise`` [rad]) angles only. Returns the time, true states, estimates,
    and touchdown errors (time [s], foothold [m])."""
    rng = np.random.default_rng(seed)
    terrain = Terrain.slope(CLASSIC_CYCLE.slope)
    sim = Simulator(robot, terrain, 1, dt=DT)
    sim.reset(Q0, QD0)
    tx, ty = terrain.arrays()
    P = robot.vector()
    out_t, out_x, out_h, td_err = [], [], [], []
    for _ in range(int(T / DT)):
        x_before = observer.x.copy()
        foot = sim.stance_foot[0].copy()
        t0 = float(sim.t[0])
        ev = sim.step(0.0)
        assert ev.status[0] == 0
        q = sim.q[0].copy()
        if quantum:
            q = quantum * np.round(q / quantum)
        if noise:
            q = q + rng.normal(0.0, noise, 2)
        if ev.n_impacts[0]:
            found, tau, xpre, fx = predict_touchdown(
                P, x_before, 0.0, DT, tx, ty, tx.size, foot[0], foot[1], 16, 0.1 * robot.l
            )
            assert found
            td_err.append(
                (t0 + tau - float(ev.impact_time[0, 0]), float(fx) - ev.foothold[0, 0, 0])
            )
            observer.x[:] = xpre if locate else x_before
            observer.impact()
            x = observer.x
            observer_update(P, x, x[0], x[1], q[0], q[1], 0.0, DT - tau, observer.eps, 4)
            observer.q_last = q
        else:
            observer.update(q, 0.0)
        out_t.append(float(sim.t[0]))
        out_x.append(sim.state(0))
        out_h.append(observer.x.copy())
    return np.array(out_t), np.array(out_x), np.array(out_h), np.array(td_err)


@pytest.fixture(scope="module")
def classic():
    return RobotParams.from_preset("classic")


def test_converges_at_the_designed_rate_and_through_impacts(classic):
    eps = 0.02
    obs = HighGainObserver(classic, DT, eps)
    obs.reset(Q0, np.zeros(2))  # velocities unknown at the start
    t, x, xh, td = _run(classic, obs, 2.5)
    err = np.abs(xh[:, 2:] - x[:, 2:]).max(axis=1)
    e0 = np.abs(QD0).max()
    # double pole at -1/eps: the velocity error decays like (1 - t/eps) exp(-t/eps)
    k = np.searchsorted(t, 10 * eps)
    assert err[k] < 2e-3 * e0
    assert err[np.searchsorted(t, 3 * eps)] > 1e-3 * e0  # not faster than designed either
    # through the impacts (at least two steps) the estimate stays locked on
    assert len(td) >= 2
    assert err[k:].max() < 1e-3
    # touchdowns located from the estimate: time within 0.1 ms, foothold within 0.1 mm
    assert np.abs(td[:, 0]).max() < 1e-4 and np.abs(td[:, 1]).max() < 1e-4


def test_quantised_encoders_bounded_velocity_error(classic):
    obs = HighGainObserver(classic, DT, 0.02)
    obs.reset(Q0, QD0)
    quantum = 2 * math.pi / 4096
    t, x, xh, _ = _run(classic, obs, 2.0, quantum=quantum)
    err = xh[:, 2:] - x[:, 2:]
    rms = np.sqrt(np.mean(err[t > 0.2] ** 2))
    # noise gain of the velocity estimate is of order quantum / eps (about 0.08 rad/s)
    assert rms < 0.05
    assert np.abs(xh[:, :2] - x[:, :2]).max() < 2 * quantum


def test_bad_settings_raise(classic):
    for dt, eps in ((0.0, 0.02), (0.005, 0.0), (math.nan, 0.02), (0.005, -1.0)):
        with pytest.raises(ValueError):
            HighGainObserver(classic, dt, eps)


def test_the_time_constant_from_the_encoders_noise_keeps_the_velocity_noise(classic):
    nominal = angle_sigma(NOMINAL_ENCODER_NOISE, NOMINAL_ENCODER_RESOLUTION)
    assert eps_for_noise(nominal) == pytest.approx(DEFAULT_EPS)
    assert eps_for_noise(0.0) == DEFAULT_EPS  # quieter encoders keep the default
    noisy = angle_sigma(5 * NOMINAL_ENCODER_NOISE, NOMINAL_ENCODER_RESOLUTION)
    assert eps_for_noise(noisy) == pytest.approx(0.1105, abs=5e-4)

    def velocity_rms(sigma, eps):
        obs = HighGainObserver(classic, DT, eps)
        obs.reset(Q0, QD0)
        t, x, xh, _ = _run(classic, obs, 2.0, noise=sigma, seed=3)
        return float(np.sqrt(np.mean((xh[t > 0.3, 2:] - x[t > 0.3, 2:]) ** 2)))

    base = velocity_rms(nominal, DEFAULT_EPS)
    # five times the noise through the default observer: velocity noise about 4.6 times
    assert velocity_rms(noisy, DEFAULT_EPS) > 3.0 * base
    # through the longer time constant: back to the nominal level (the eps^-3/2 law)
    assert velocity_rms(noisy, eps_for_noise(noisy)) == pytest.approx(base, rel=0.3)
    for bad in (-1e-3, math.nan):
        with pytest.raises(ValueError, match="angle sigma"):
            eps_for_noise(bad)


def test_the_nominal_encoders_are_the_envs_defaults():
    """eps_for_noise's reference point is the envs' sensor configuration (configs/envs/base.yaml):
    the reference policy on a default env runs the observer at DEFAULT_EPS exactly."""
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    sensors = env.unwrapped.settings.sensors
    assert sensors.encoder_noise == NOMINAL_ENCODER_NOISE
    assert sensors.encoder_resolution == NOMINAL_ENCODER_RESOLUTION
    assert SensorStateEstimator(env).observer.eps == DEFAULT_EPS
