"""The stable-baselines3 adapter of the native vector env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import VecMonitor, VecNormalize  # noqa: E402

from agents.sb3_vec_env import SB3VecEnv, make_sb3_vec_env  # noqa: E402

ID = "roughwalk/CompassGaitFlat-v0"


def test_terminal_observation_and_time_limit_flags() -> None:
    n, seed, limit = 3, 4, 40
    venv = make_sb3_vec_env(ID, n_envs=n, seed=seed, max_episode_steps=limit)
    singles = [gym.make(ID, max_episode_steps=limit) for _ in range(n)]
    obs = venv.reset()
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=seed + i)[0])
    rng = np.random.default_rng(0)
    truncations = 0
    for _ in range(2 * limit + 5):
        actions = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        obs, rewards, dones, infos = venv.step(actions)
        assert obs.shape == (n, 14) and rewards.dtype == np.float32 and dones.dtype == bool
        assert len(infos) == n
        for i, env in enumerate(singles):
            o, r, term, trunc, info = env.step(actions[i])
            assert rewards[i] == np.float32(r) and dones[i] == (term or trunc)
            if term or trunc:
                np.testing.assert_array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["TimeLimit.truncated"] == (trunc and not term)
                assert infos[i]["distance"] == info["distance"]
                truncations += infos[i]["TimeLimit.truncated"]
                o, _ = env.reset()
            else:
                assert "terminal_observation" not in infos[i]
            np.testing.assert_array_equal(obs[i], o)
    assert truncations >= n  # every sub-env hit the time limit at least once
    assert venv.get_attr("dt") == [0.005] * n and venv.env_is_wrapped(gym.Wrapper) == [False] * n
    venv.close()


def test_info_every_step_and_reset_infos() -> None:
    venv = make_sb3_vec_env(ID, n_envs=2, seed=0, info_every_step=True)
    venv.reset()
    assert venv.reset_infos[1]["footsteps"] == 0
    _, _, _, infos = venv.step(np.zeros((2, 1), np.float32))
    assert infos[0]["impacts"] == 0 and infos[1]["state"].shape == (4,)


def test_rejects_next_step_autoreset() -> None:
    venv = gym.make_vec(ID, 2, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(venv)


def test_ppo_trains_under_vecnormalize() -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    venv = VecNormalize(VecMonitor(make_sb3_vec_env(ID, n_envs=4, seed=0, max_episode_steps=50)))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.set_logger(Logger(None, []))  # SB3's default makes a folder in the temp folder
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    assert np.all(np.isfinite(venv.obs_rms.mean))
