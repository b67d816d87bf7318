"""The per-footstep wrapper: one agent step per footstep, the action sets planner settings."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from agents.footstep import ADJUSTABLE, DEFAULT_ADJUST, FootstepWrapper
from agents.policies import make_baseline_policy

FLAT = "roughwalk/CompassGaitFlat-v0"
STAIRS = "roughwalk/CompassGaitStairs-v0"


def test_a_zero_action_is_the_reference_controller_exactly():
    """Footstep by footstep with zero actions, the wrapped env sees the same commands as the
    reference policy alone: the same ticks, return and final state."""
    env = FootstepWrapper(gym.make(STAIRS))
    obs, _ = env.reset(seed=1000003)
    total, ticks, steps, work, impacts, done = 0.0, 0, 0, 0.0, 0, False
    while not done:
        obs, r, term, trunc, info = env.step(np.zeros(env.action_space.shape))
        total += r
        ticks += info["ticks"]
        work += info["motor_work"]
        impacts += info["impacts"]
        steps += 1
        done = term or trunc
    assert info["planner_settings"] == {
        k: float(getattr(env.configured, k)) for k in DEFAULT_ADJUST
    }
    plain = gym.make(STAIRS)
    ref = make_baseline_policy("reference", plain)
    o, _ = plain.reset(seed=1000003)
    ref.reset()
    ref_total, ref_ticks, ref_work, done = 0.0, 0, 0.0, False
    while not done:
        o, r, term2, trunc2, info2 = plain.step(ref(o))
        ref_total += r
        ref_work += info2["motor_work"]
        ref_ticks += 1
        done = term2 or trunc2
    assert (term, trunc, ticks) == (term2, trunc2, ref_ticks)
    assert total == pytest.approx(ref_total, rel=1e-12)
    # the per-step info entries cover the whole footstep
    assert work == pytest.approx(ref_work, rel=1e-12) and impacts == info2["footsteps"]
    np.testing.assert_array_equal(info["state"], info2["state"])
    assert steps == info2["footsteps"] + 1  # one decision per stance, the last one cut short


def walk(env, seed, action):
    """Observations and rewards of one episode from ``reset(seed=seed)``, ``action`` at every
    footstep."""
    obs, _ = env.reset(seed=seed)
    seen, done = [obs], False
    while not done:
        obs, r, term, trunc, _ = env.step(action)
        seen += [obs, np.float64(r)]
        done = term or trunc
    return seen


def test_an_episode_does_not_depend_on_the_episode_before():
    """The first observation after a reset holds no estimate of the last episode (the
    estimator starts at the first tick, as a new wrapper's does), so an episode is the same
    after another one as on a new wrapper: evaluations split over workers give the same
    records."""
    action = np.full(len(DEFAULT_ADJUST), 0.5)
    fresh = walk(FootstepWrapper(gym.make(FLAT)), 1000001, action)
    env = FootstepWrapper(gym.make(FLAT))
    walk(env, 1000000, action)
    after = walk(env, 1000001, action)
    assert len(after) == len(fresh)
    for a, b in zip(after, fresh, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.any(fresh[0][-5:])  # the estimate's entries before the first tick


def test_the_action_moves_the_next_footholds_and_the_speed_aimed_at():
    """On level ground ``foothold_shift`` at +1 plans the next footholds 3 cm further out
    each, at -1 3 cm nearer; ``target_speed`` is the configured one plus its half-range."""
    footholds = {}
    for a in (-1.0, 0.0, 1.0):
        env = FootstepWrapper(gym.make(FLAT), adjust={"foothold_shift": 0.03})
        env.reset(seed=1000000)
        env.step([0.0])  # the first stance, planned from the start state
        _, _, _, _, info = env.step([a])  # planned at the first touchdown
        assert info["planner_settings"] == {"foothold_shift": pytest.approx(0.03 * a)}
        plan = env.controller.plan
        footholds[a] = np.array([s.foothold[0] - s.stance_foot[0] for s in plan.steps[:3]])
    np.testing.assert_allclose(footholds[1.0] - footholds[0.0], 0.03, atol=0.004)
    np.testing.assert_allclose(footholds[0.0] - footholds[-1.0], 0.03, atol=0.004)
    env = FootstepWrapper(gym.make(FLAT), adjust={"target_speed": 0.05, "torque_fraction": 0.1})
    assert env.settings([1.0, -1.0]) == {
        "target_speed": pytest.approx(env.configured.target_speed + 0.05),
        "torque_fraction": pytest.approx(env.configured.torque_fraction - 0.1),
    }
    assert env.settings([0.0, 0.0]) == {}  # the configured planner
    assert env.settings([5.0, 0.0])["target_speed"] == pytest.approx(
        env.configured.target_speed + 0.05
    )  # actions are clipped to [-1, 1]
    big = FootstepWrapper(gym.make(FLAT), adjust={"torque_fraction": 0.5})
    assert big.settings([1.0])["torque_fraction"] == ADJUSTABLE["torque_fraction"][1]


def test_passes_the_env_checkers():
    env = FootstepWrapper(gym.make(FLAT))
    check_env(env, skip_render_check=True)
    sb3_check_env(FootstepWrapper(gym.make(FLAT), observe_state=False))
    assert env.observation_space.shape[0] == gym.make(FLAT).observation_space.shape[0] + 5


@pytest.mark.parametrize(
    "adjust,match",
    [
        ({"no_such": 0.1}, "cannot be adjusted per footstep; allowed: foothold_shift"),
        ({"order": 1.0}, "cannot be adjusted per footstep"),
        ({"target_speed": 0.0}, r"adjust.target_speed = 0.0; allowed: a finite half-range > 0"),
        ({"target_speed": float("nan")}, "adjust.target_speed"),
        ({}, "at least one"),
    ],
)
def test_bad_adjustments_are_named(adjust, match):
    with pytest.raises(ValueError, match=match):
        FootstepWrapper(gym.make(FLAT), adjust=adjust)


def test_bad_actions_are_named():
    env = FootstepWrapper(gym.make(FLAT))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="footstep action must be 3 finite numbers"):
        env.step([0.0, 0.0])
    with pytest.raises(ValueError, match="footstep action must be 3 finite numbers"):
        env.step([0.0, np.nan, 0.0])


def test_evaluation_counts_a_footsteps_control_periods():
    """``agents.evaluate.run_episode`` on the wrapper (zero actions) reports the reference's
    duration, speed and motor work, not per-agent-step ones."""
    from agents.evaluate import run_episode

    class Zero:
        def reset(self):
            pass

        def __call__(self, obs):
            return np.zeros(3, dtype=np.float32)

    wrapped = run_episode(FootstepWrapper(gym.make(FLAT)), Zero(), seed=1000001)
    plain = gym.make(FLAT)
    ref = run_episode(plain, make_baseline_policy("reference", plain), seed=1000001)
    assert (wrapped.steps, wrapped.duration) == (ref.steps, ref.duration)
    assert wrapped.speed == pytest.approx(ref.speed, rel=1e-12)
    assert wrapped.motor_work == pytest.approx(ref.motor_work, rel=1e-12)
    assert wrapped.footsteps == ref.footsteps and wrapped.success == ref.success
