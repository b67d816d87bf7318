"""Native vector env: same numbers as the single env, autoreset semantics, seeding, errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import envs  # noqa: F401  (registers the ids)
from envs.vector_env import CompassGaitVectorEnv

ID = "roughwalk/CompassGaitRough-v0"
KEYS = ("state", "stance_foot", "stance_leg", "time", "footsteps", "distance", "impacts",
        "motor_work", "failure", "terrain")  # fmt: skip


def _check_info(vinfo: dict, i: int, info: dict) -> None:
    if "push" in info:  # a push in this step: Gymnasium's nested form, masked per sub-env
        assert vinfo["_push"][i]
        for key, value in info["push"].items():
            assert vinfo["push"]["_" + key][i] and vinfo["push"][key][i] == value
    else:
        assert "push" not in vinfo or not vinfo["_push"][i]
    for key in (*KEYS, "robot"):
        if key not in info:  # single envs give the terrain at reset and termination only
            continue
        assert vinfo["_" + key][i]
        got, want = vinfo[key][i], info[key]
        if isinstance(want, np.ndarray):
            np.testing.assert_array_equal(got, want)
        else:
            assert got == want, key


@pytest.mark.parametrize(
    ("parallel", "kwargs"),
    [
        (False, {}),
        (True, {}),
        (True, {"sensors": {"latency": 2}}),
        (False, {"observation": "state"}),
        (False, {"robot_error": 0.05, "push": {"dv": [0.05, 0.2], "every": [0.05, 0.15]}}),
        (True, {"robot_error": {"l": 0.1, "m": 0.1}, "push": {"dv": 0.1, "at": "mid_stance"}}),
    ],
)
def test_vector_equals_single_envs_step_by_step(parallel: bool, kwargs: dict) -> None:
    """Next-step autoreset, truncation and failures included; noisy sensors."""
    n, seed, limit = 3, 11, 90
    venv = gym.make_vec(
        ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        max_episode_steps=limit,
        parallel=parallel,
        **kwargs,
    )
    assert isinstance(venv.unwrapped, CompassGaitVectorEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    singles = [gym.make(ID, max_episode_steps=limit, **kwargs) for _ in range(n)]
    vobs, vinfo = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        obs, info = env.reset(seed=seed + i)
        np.testing.assert_array_equal(vobs[i], obs)
        _check_info(vinfo, i, info)
    rng = np.random.default_rng(0)
    done = np.zeros(n, dtype=bool)
    ends = pushes = 0
    for _ in range(250):
        actions = rng.uniform(-1.2, 1.2, (n, 1)).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(actions)
        for i, env in enumerate(singles):
            if done[i]:
                obs, info = env.reset()
                rew, term, trunc = 0.0, False, False
            else:
                obs, rew, term, trunc, info = env.step(actions[i])
            np.testing.assert_array_equal(vobs[i], obs)
            assert vrew[i] == rew and vterm[i] == term and vtrunc[i] == trunc
            _check_info(vinfo, i, info)
            done[i] = term or trunc
            ends += done[i]
            pushes += "push" in info
    assert ends >= 4  # autoresets were exercised
    assert pushes >= 3 or "push" not in kwargs


def test_native_matches_gymnasium_sync_vector_env() -> None:
    sync = gym.make_vec(ID, 2, vectorization_mode="sync", max_episode_steps=70)
    native = gym.make_vec(ID, 2, vectorization_mode="vector_entry_point", max_episode_steps=70)
    np.testing.assert_array_equal(sync.reset(seed=5)[0], native.reset(seed=5)[0])
    rng = np.random.default_rng(1)
    for _ in range(150):
        a = rng.uniform(-1, 1, (2, 1)).astype(np.float32)
        for x, y in zip(sync.step(a)[:4], native.step(a)[:4]):
            np.testing.assert_array_equal(x, y)


def test_same_step_autoreset_reports_final_observation() -> None:
    n, seed = 2, 3
    venv = CompassGaitVectorEnv(n, "flat", autoreset_mode="same_step", max_episode_steps=60)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    single = gym.make("roughwalk/CompassGaitFlat-v0", max_episode_steps=60)
    venv.reset(seed=seed)
    single.reset(seed=seed)
    for t in range(60):
        a = np.full((n, 1), 0.1, dtype=np.float32)
        vobs, _, vterm, vtrunc, vinfo = venv.step(a)
        obs, _, term, trunc, info = single.step(a[0])
        if t < 59:
            np.testing.assert_array_equal(vobs[0], obs)
    assert trunc and vtrunc.all() and not vterm.any()
    np.testing.assert_array_equal(vinfo["final_obs"][0], obs)
    assert vinfo["final_info"]["distance"][0] == info["distance"]
    reset_obs, _ = single.reset()
    np.testing.assert_array_equal(vobs[0], reset_obs)  # already reset in the same step
    assert vinfo["footsteps"][0] == 0


def test_per_env_seeding_and_reset_mask() -> None:
    venv = CompassGaitVectorEnv(4, "rough", autoreset_mode="disabled")
    _, info = venv.reset(seed=0)
    seeds = [t["seed"] for t in info["terrain"]]
    assert len(set(seeds)) == 4
    _, again = venv.reset(seed=[0, 1, 2, 3])
    assert [t["seed"] for t in again["terrain"]] == seeds
    venv.step(np.zeros((4, 1), np.float32))
    mask = np.array([False, True, False, False])
    _, info = venv.reset(options={"reset_mask": mask})
    assert info["time"][1] == 0.0 and info["time"][0] > 0.0


def test_bad_actions_and_arguments() -> None:
    venv = CompassGaitVectorEnv(2, "flat")
    with pytest.raises(gym.error.ResetNeeded):
        venv.step(np.zeros((2, 1), np.float32))
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        venv.step(np.array([[0.0], [np.nan]], np.float32))
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1), np.float32))
    with pytest.raises(ValueError, match="num_envs"):
        CompassGaitVectorEnv(0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        CompassGaitVectorEnv(2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="reset_mask"):
        venv.reset(options={"reset_mask": [1, 0]})


def test_spaces_and_render_fps() -> None:
    venv = gym.make_vec("roughwalk/CompassGaitSlope-v0", 5, vectorization_mode="vector_entry_point")
    obs, _ = venv.reset(seed=0)
    assert venv.observation_space.shape == (5, 14) and obs.dtype == np.float32
    assert venv.action_space.shape == (5, 1)
    assert venv.observation_space.contains(obs)
    assert venv.metadata["render_fps"] == pytest.approx(100.0)
    assert (
        venv.unwrapped.max_episode_steps
        == gym.spec("roughwalk/CompassGaitSlope-v0").max_episode_steps
    )
