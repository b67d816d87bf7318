"""ResidualWrapper: command arithmetic, observation, info, resets, VecNormalize, zero residual."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import controllers
import envs  # noqa: F401
from agents.residual import ResidualWrapper
from agents.sb3_vec_env import SB3VecEnv

FLAT = "roughwalk/CompassGaitFlat-v0"


class HipPD:
    """Stand-in base policy: PD on the hip encoder towards a fixed angle, counting resets."""

    def __init__(self, target: float = 0.4, kp: float = 3.0) -> None:
        self.target, self.kp = target, kp
        self.resets = 0
        self.prev = None

    def reset(self) -> None:
        self.resets += 1
        self.prev = None

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        # obs[0] is the hip encoder; a finite difference gives the damping term
        d = 0.0 if self.prev is None else obs[0] - self.prev
        self.prev = float(obs[0])
        return np.array([self.kp * (self.target - obs[0]) - 20.0 * d], dtype=np.float32)


def rollout(env, policy, seed: int, steps: int, actions=None):
    obs, info = env.reset(seed=seed)
    policy.reset()
    out = [(obs, 0.0, False, False, info)]
    for k in range(steps):
        a = policy(obs) if actions is None else actions[k]
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, trunc, info))
        if term or trunc:
            break
    return out


def test_zero_residual_reproduces_the_base_policy_exactly():
    base_direct, base_wrapped = HipPD(), HipPD()
    direct = rollout(gym.make(FLAT), base_direct, seed=7, steps=400)
    wrapped_env = ResidualWrapper(gym.make(FLAT), base=base_wrapped, scale=0.5, observe_base=False)
    zeros = [np.zeros(1, np.float32)] * 400
    wrapped = rollout(wrapped_env, base_wrapped, seed=7, steps=400, actions=zeros)
    assert len(direct) == len(wrapped) > 50
    for (o1, r1, t1, u1, i1), (o2, r2, t2, u2, i2) in zip(direct, wrapped):
        np.testing.assert_array_equal(o1, o2)
        assert (r1, t1, u1) == (r2, t2, u2)
        np.testing.assert_array_equal(i1["state"], i2["state"])
        assert i1["footsteps"] == i2["footsteps"] and i1["failure"] == i2["failure"]
    # and the log says the whole command came from the base policy
    assert all(np.all(i["residual_action"] == 0) for *_, i in wrapped[1:])
    assert all(np.array_equal(i["total_action"], i["base_action"]) for *_, i in wrapped[1:])


def test_command_is_clipped_sum_and_logged():
    env = ResidualWrapper(gym.make(FLAT), base=HipPD(kp=30.0), scale=0.25)
    obs, _ = env.reset(seed=1)
    saturated = 0
    for a in (0.5, -1.0, 3.0, -7.0, 0.0, 0.2) * 10:
        base_cmd = float(obs[-1])  # the appended entry is the base command of this step
        obs, _, term, trunc, info = env.step(np.array([a], np.float32))
        residual = 0.25 * np.clip(a, -1, 1)
        assert -1 <= base_cmd <= 1
        assert info["base_action"][0] == pytest.approx(base_cmd)
        assert info["residual_action"][0] == pytest.approx(residual)
        total = np.clip(base_cmd + residual, -1, 1)
        assert info["total_action"][0] == pytest.approx(total, abs=1e-6)
        saturated += abs(base_cmd) == 1.0
        if term or trunc:
            break
    assert saturated > 0  # the stiff stand-in saturates: the clipping path was exercised


def test_observation_appends_base_command_and_space_is_consistent():
    inner = gym.make(FLAT)
    env = ResidualWrapper(gym.make(FLAT), base=HipPD(), scale=0.3, observe_base=True)
    assert env.observation_space.shape == (inner.observation_space.shape[0] + 1,)
    assert env.observation_space.low[-1] == -1 and env.observation_space.high[-1] == 1
    obs, _ = env.reset(seed=3)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    for _ in range(20):
        obs, *_, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
    # the appended entry is the base command for the next step
    nxt = env.step(np.zeros(1, np.float32))[-1]
    assert nxt["base_action"][0] == pytest.approx(obs[-1])
    check_env(ResidualWrapper(gym.make(FLAT), base=HipPD(), scale=0.3), skip_render_check=True)


def test_base_policy_reset_with_env_and_bad_input_raises():
    base = HipPD()
    env = ResidualWrapper(gym.make(FLAT), base=base, scale=0.3)
    for seed in range(3):
        env.reset(seed=seed)
    assert base.resets == 3
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan], np.float32))
    with pytest.raises(ValueError, match="scale"):
        ResidualWrapper(gym.make(FLAT), base=HipPD(), scale=0.0)
    with pytest.raises(ValueError, match="unknown baseline"):
        ResidualWrapper(gym.make(FLAT), base="nonsense")
    with pytest.raises(ValueError, match="passive policy takes no options"):
        ResidualWrapper(gym.make(FLAT), base="passive", base_kwargs={"gain": 1})
    with pytest.raises(ValueError, match="named base policy only"):
        ResidualWrapper(gym.make(FLAT), base=HipPD(), base_kwargs={"gain": 1})


def test_works_in_sb3_vec_env_under_vecnormalize():
    bases: list[HipPD] = []

    def wrap(e):
        bases.append(HipPD())
        return ResidualWrapper(e, base=bases[-1], scale=0.3)

    venv = VecNormalize(
        make_vec_env(FLAT, n_envs=2, seed=5, wrapper_class=wrap), norm_obs=True, norm_reward=True
    )
    obs = venv.reset()
    assert obs.shape == (2, gym.make(FLAT).observation_space.shape[0] + 1)
    done_seen = False
    for _ in range(400):  # the stand-in falls within a few hundred steps: autoreset happens
        obs, rew, dones, infos = venv.step(np.zeros((2, 1), np.float32))
        assert np.all(np.isfinite(obs))
        for d, info in zip(dones, infos):
            assert {"base_action", "residual_action", "total_action"} <= set(info)
            if d:
                done_seen = True
                assert info["terminal_observation"].shape == obs.shape[1:]
    assert done_seen
    assert all(b.resets >= 2 for b in bases)  # initial reset + at least one autoreset each


def test_zero_residual_reproduces_the_reference_controller_exactly():
    env_id = "roughwalk/CompassGaitRough-v0"
    direct_env = gym.make(env_id)
    reference = controllers.make_reference_policy(direct_env)
    direct = rollout(direct_env, reference, seed=11, steps=600)
    wrapped_env = ResidualWrapper(gym.make(env_id), base="reference", scale=0.3)
    obs, info = wrapped_env.reset(seed=11)
    np.testing.assert_array_equal(obs[:-1], direct[0][0])
    for o1, r1, t1, u1, i1 in direct[1:]:
        obs, r2, t2, u2, i2 = wrapped_env.step(np.zeros(1, np.float32))
        np.testing.assert_array_equal(obs[:-1], o1)
        assert (r1, t1, u1) == (r2, t2, u2)
        np.testing.assert_array_equal(i1["state"], i2["state"])
    assert i2["footsteps"] >= 3  # the reference walked several steps in these 3 s


def test_works_with_the_vector_env_adapter_under_vecnormalize():
    bases: list[HipPD] = []

    def make():
        bases.append(HipPD())
        return ResidualWrapper(gym.make(FLAT), base=bases[-1], scale=0.3)

    vec = gym.vector.SyncVectorEnv([make, make], autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    venv = VecNormalize(SB3VecEnv(vec, info_every_step=True))
    venv.seed(5)
    obs = venv.reset()
    dim = gym.make(FLAT).observation_space.shape[0] + 1
    assert obs.shape == (2, dim)
    ends = 0
    for _ in range(400):
        obs, _, dones, infos = venv.step(np.zeros((2, 1), np.float32))
        for d, info in zip(dones, infos):
            assert np.array_equal(info["total_action"], info["base_action"])
            if d:
                ends += 1
                assert info["terminal_observation"].shape == (dim,)
    assert ends >= 2 and all(b.resets >= 2 for b in bases)
