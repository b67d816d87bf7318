"""The single Gymnasium environment: API checkers, determinism, actions, rewards, options."""

from __future__ import annotations

import math
import os
import warnings

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import envs  # noqa: E402, F401  (registers the ids)
from envs import Terrain  # noqa: E402
from envs.env import CompassGaitEnv  # noqa: E402
from envs.registration import ENV_IDS, NAMESPACE  # noqa: E402
from envs.settings import load_env_config  # noqa: E402

IDS = [f"{NAMESPACE}/{name}" for name in ENV_IDS]
ZERO = np.zeros(1, dtype=np.float32)


@pytest.mark.parametrize("observation", ["sensors", "state"])
@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_and_sb3_checkers(env_id: str, observation: str) -> None:
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, observation=observation)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # e.g. SB3's "normalise your obs" advice
        check_env(env.unwrapped)
        sb3_check_env(gym.make(env_id, observation=observation), warn=True)
    env.close()


def test_registered_ids_and_metadata() -> None:
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps is not None and spec.vector_entry_point is not None
    env = gym.make("roughwalk/CompassGaitSlope-v0")
    base = env.unwrapped
    assert base.metadata["render_fps"] == pytest.approx(1 / base.dt) == pytest.approx(100)
    assert gym.make("roughwalk/CompassGaitFlat-v0").unwrapped.dt == pytest.approx(0.005)
    assert base.robot.name == "classic" and base.params is base.robot
    assert base.torque_limit == base.robot.input_gain * base.u_max == base.robot.tau_max
    paper = gym.make("roughwalk/CompassGaitStairs-v0").unwrapped
    assert paper.robot.name == "paper" and paper.terrain.spec["edges"] == [0.40, 0.62]
    assert paper.action_from_input(paper.u_max / 2)[0] == pytest.approx(0.5)
    assert paper.action_from_input(np.array([-3.0 * paper.u_max])).tolist() == [-1.0]
    assert paper.action_from_torque(paper.torque_limit / 4).tolist() == [0.25]
    assert np.isnan(paper.action_from_input(np.nan)[0])
    with pytest.raises(ValueError, match="one number"):
        paper.action_from_input([1.0, 2.0])


def _rollout(env: gym.Env, seed: int, steps: int) -> list:
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        out.append((obs, r, term, trunc, info))
        if term or trunc:
            obs, info = env.reset()
            out.append((obs, info))
    return out


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def test_determinism_and_seeds_change_terrain() -> None:
    make = lambda: gym.make("roughwalk/CompassGaitRough-v0", max_episode_steps=150)  # noqa: E731
    a, b = _rollout(make(), 7, 400), _rollout(make(), 7, 400)
    assert _same(a, b)
    env = make()
    t1 = env.reset(seed=1)[1]["terrain"]
    t2 = env.reset(seed=2)[1]["terrain"]
    assert t1["seed"] != t2["seed"] and t1["ys"] != t2["ys"]
    # the spec in info rebuilds the course exactly (replay)
    assert Terrain.from_dict(t2) == env.unwrapped.terrain


def test_actions_clipped_and_non_finite_rejected() -> None:
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    outs = []
    for action in (np.array([1.0], np.float32), np.array([7.5], np.float32), [3.0]):
        env.reset(seed=0)
        outs.append(env.step(action))
    assert _same(outs[0], outs[1]) and _same(outs[0], outs[2])
    env.reset(seed=0)
    for bad in (np.array([np.nan], np.float32), np.array([np.inf]), [-np.inf]):
        with pytest.raises(ValueError, match="finite"):
            env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(2))


def test_reward_is_progress_minus_work_minus_failure() -> None:
    env = gym.make("roughwalk/CompassGaitFlat-v0", reward={"energy": 0.5, "failure": 2.0})
    _, info = env.reset(seed=0)
    prev = info["distance"]
    for _ in range(2000):
        _, r, term, _, info = env.step(np.array([0.2], np.float32))
        expected = (info["distance"] - prev) - 0.5 * info["motor_work"] - 2.0 * term
        assert r == pytest.approx(expected, abs=1e-12)
        prev = info["distance"]
        if term:
            break
    assert term and info["failure"] in envs.FAILURES  # a constant torque falls


def test_zero_torque_from_the_nominal_start_completes_a_step() -> None:
    """The paper-robot start: a passive step (about 0.14 m) before any failure."""
    env = gym.make("roughwalk/CompassGaitFlat-v0")
    _, info = env.reset(seed=0)
    while info["footsteps"] == 0:
        _, _, term, _, info = env.step(ZERO)
        assert not term
    assert info["stance_foot"][0] == pytest.approx(0.14, abs=0.03)
    assert info["failure"] is None


def test_slope_walks_passively() -> None:
    env = gym.make("roughwalk/CompassGaitSlope-v0")
    _, info = env.reset(seed=0)
    total = 0.0
    for _ in range(1000):  # 10 s
        _, r, term, trunc, info = env.step(ZERO)
        total += r
        assert not (term or trunc)
    # period 0.734461 s, step length 0.535919 m: about 13.6 steps and 7.3 m
    assert 12 <= info["footsteps"] <= 15
    assert info["distance"] == pytest.approx(total)  # no motor work, no failure
    assert 6.0 < info["distance"] < 8.5


def test_info_contents() -> None:
    env = gym.make("roughwalk/CompassGaitStairs-v0", observation="state")
    obs, info = env.reset(seed=0)
    keys = {"state", "stance_foot", "stance_leg", "time", "footsteps", "distance", "impacts",
            "motor_work", "failure", "terrain"}  # fmt: skip
    assert keys <= info.keys()
    np.testing.assert_allclose(obs[:4], info["state"], rtol=1e-6)
    assert info["stance_foot"].tolist() == [0.0, 0.0] and info["terrain"]["kind"] == "stairs"
    assert info["impacts"] == 0 and info["footsteps"] == 0 and info["failure"] is None


def test_reset_options_pin_state_terrain_and_leg() -> None:
    env = gym.make("roughwalk/CompassGaitRough-v0")
    q, qd = (-0.48, -0.24), (2.6, 1.1)
    _, info = env.reset(seed=0, options={"state": (q, qd), "terrain": "flat", "stance_leg": "B"})
    np.testing.assert_array_equal(info["state"], [*q, *qd])
    assert info["terrain"]["kind"] == "flat" and info["stance_leg"] == 1
    # the next plain reset draws from the generator again
    assert env.reset()[1]["terrain"]["kind"] == "blocks"
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"start": 1})
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": ([np.nan, 0.0], [0.0, 0.0])})


def test_difficulty_scales_random_blocks() -> None:
    t = gym.make("roughwalk/CompassGaitRough-v0", difficulty=3.0).reset(seed=0)[1]["terrain"]
    assert t["height_range"] == pytest.approx([-0.0225, 0.0225])
    steps = np.abs(np.diff(np.asarray(t["ys"])))
    assert steps.max() <= 0.0225 + 1e-12 and steps.max() > 0.011
    with pytest.raises(ValueError, match="difficulty"):
        gym.make("roughwalk/CompassGaitFlat-v0", difficulty=2.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"observation": "pixels"}, "observation"),
        ({"dt": 0.0}, "dt"),
        ({"colour": "red"}, "colour"),
        ({"sensors": {"latency": -2}}, "latency"),
        ({"reward": {"energy": -1.0}}, "energy"),
        ({"terrain": {"kind": "moon"}}, "kind"),
        ({"terrain": "no_such_course"}, "terrain"),
        ({"robot": "no_such_robot"}, "preset"),
        ({"initial_state": {"stance_leg": "C"}}, "stance_leg"),
    ],
)
def test_bad_arguments_raise_clear_errors(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CompassGaitEnv("flat", **kwargs)


def test_torque_limit_override_and_state_observation_bounds() -> None:
    env = CompassGaitEnv("flat", u_max=5.0, observation="state")
    assert env.u_max == 5.0 and env.torque_limit == pytest.approx(5.0 * 1.1 * 0.0671)
    low, high = env.observation_space.low, env.observation_space.high
    assert np.all(np.isfinite(low)) and np.all(np.isfinite(high))
    assert env.observation_space.shape == (5 + env.sensor_config.scan_count,)
    assert math.isclose(high[0], math.pi, rel_tol=1e-6)
    env = CompassGaitEnv("flat", torque_limit=0.5)
    assert env.torque_limit == pytest.approx(0.5) and env.u_max == pytest.approx(
        0.5 / 0.0738 * 1.0, rel=1e-3
    )
    with pytest.raises(ValueError, match="torque_limit"):
        CompassGaitEnv({**load_env_config("flat"), "torque_limit": 1.0, "u_max": 3.0})
