"""State estimation from the sensors: decoding, observer, touchdowns located on the map."""

import gymnasium as gym
import numpy as np
import pytest

import controllers.estimator
import envs  # registers the ids
from controllers import make_reference_policy
from controllers.estimator import SensorStateEstimator
from envs.physics.encoders import encoders_to_q, q_to_encoders, stance_from_contacts


@pytest.mark.parametrize(("localise", "foot_error"), [(False, 5e-3), (True, 1e-2)])
def test_estimate_follows_the_true_state_through_impacts(localise, foot_error):
    """The stance foot dead-reckoned on the map (``localise=False``) or located by the scan
    (the policy's default; on the nominal robot the scan's noise costs a few millimetres)."""
    env = gym.make("roughwalk/CompassGaitStairs-v0")
    # drives the robot; its estimator is under test
    policy = make_reference_policy(env, localise=localise)
    assert policy.estimator.localise == localise
    est = policy.estimator
    obs, info = env.reset(seed=4)
    policy.reset()
    errors, feet = [], []
    for k in range(700):
        action = policy(obs)  # the estimate now reflects `obs`, which came with `info`
        if k >= 20:
            errors.append(np.abs(est.x - info["state"]))
        assert est.stance_leg == info["stance_leg"]
        feet.append(np.abs(np.subtract(est.stance_foot, info["stance_foot"])).max())
        obs, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
    err = np.array(errors)
    assert info["footsteps"] >= 4
    assert est.touchdowns_located == info["footsteps"] and est.touchdowns_guessed == 0
    # rad, rad/s: quantisation and noise; after a touchdown a short transient while the
    # observer converges from the located impact
    assert err[:, :2].max() < 0.02 and err[:, 2:].max() < 0.3
    assert np.median(err[:, :2]) < 1e-3 and np.median(err[:, 2:]) < 0.03
    assert max(feet) < foot_error  # m


def test_decode_and_bad_input():
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    est = SensorStateEstimator(env)
    obs, info = env.reset(seed=0)
    q, leg = est.decode(obs)
    assert leg == info["stance_leg"] == 0
    np.testing.assert_allclose(q, info["state"][:2], atol=5e-3)
    with pytest.raises(ValueError, match="finite numbers"):
        est.decode(np.full_like(obs, np.nan))
    with pytest.raises(ValueError, match="finite numbers"):
        est.decode(obs[:3])
    one_inf = np.array(obs, dtype=np.float64)
    one_inf[-1] = -np.inf
    for bad in (one_inf, np.stack([obs, obs]), list(obs[:-1]) + [float("nan")]):
        with pytest.raises(ValueError, match="finite numbers"):
            est.decode(bad)
    # the scan is the estimator's own copy, not a view of the caller's observation
    mine = np.array(obs, dtype=np.float64)
    est.decode(mine)
    mine[:] = 0.0
    assert np.array_equal(est.scan, np.asarray(obs, dtype=np.float64)[est.layout.scan])
    with pytest.raises(ValueError, match="observation='sensors'"):
        SensorStateEstimator(gym.make("roughwalk/CompassGaitFlat-v0", observation="state"))
    assert est.update(q, leg, 0.0) == "start"
    np.testing.assert_allclose(est.x[2:], env.unwrapped.settings.initial_state.qd)


def test_touchdowns_count_from_the_robots_arming_distance(monkeypatch):
    robot = envs.RobotParams.from_preset("paper").replace(arm_distance=0.3)
    env = gym.make("roughwalk/CompassGaitFlat-v0", robot=robot)
    est = SensorStateEstimator(env)
    obs, _ = env.reset(seed=0)
    q, leg = est.decode(obs)
    assert est.update(q, leg, 0.0) == "start"
    seen, locate = [], controllers.estimator.predict_touchdown

    def spy(*args):
        seen.append(args[-1])  # the arming distance [m]
        return locate(*args)

    monkeypatch.setattr(controllers.estimator, "predict_touchdown", spy)
    assert est.update(q, 1 - leg, 0.0) == "impact"
    assert seen[0] == 0.3 * robot.l


def test_decode_is_the_encoder_model():
    """The estimator decodes with the robot's encoder model: either stance leg, and the stance
    leg kept when the contact switches do not name one."""
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    est = SensorStateEstimator(env)
    obs, _ = env.reset(seed=0)
    lay = est.layout
    o = np.array(obs, dtype=np.float64)
    for leg in (0, 1):
        hip, leg_a = q_to_encoders(0.3, -0.1, leg)
        o[lay.hip], o[lay.leg_a] = hip, leg_a
        o[lay.contact_a], o[lay.contact_b] = float(leg == 0), float(leg == 1)
        q, got = est.decode(o)
        assert got == leg and q.tolist() == list(encoders_to_q(hip, leg_a, leg))
        np.testing.assert_allclose(q, [0.3, -0.1], atol=1e-15)
    for both in (0.0, 1.0):
        o[lay.contact_a] = o[lay.contact_b] = both
        for prev in (0, 1):
            est.stance_leg = prev
            q, got = est.decode(o)
            assert got == stance_from_contacts(both, both, prev) == prev
            assert q.tolist() == list(encoders_to_q(o[lay.hip], o[lay.leg_a], prev))
