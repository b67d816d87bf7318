"""Rendering: frames of the declared shape without a display, human mode, video recording."""

from __future__ import annotations

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import envs  # noqa: E402, F401  (registers the ids)
from envs.rendering import WalkerRenderer  # noqa: E402

STANCE_RED = (200, 40, 40)


def _has_colour(frame: np.ndarray, colour: tuple[int, int, int]) -> bool:
    return bool(np.any(np.all(frame == np.asarray(colour, dtype=np.uint8), axis=-1)))


@pytest.mark.parametrize(
    "env_id", ["roughwalk/CompassGaitStairs-v0", "roughwalk/CompassGaitSlope-v0"]
)
def test_rgb_array_frames(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    frames = [env.render()]
    for _ in range(120):
        env.step(np.zeros(1, np.float32))
    frames.append(env.render())
    for frame in frames:
        assert frame.shape == (400, 600, 3) and frame.dtype == np.uint8
        assert _has_colour(frame, STANCE_RED)  # the stance leg is highlighted
        assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5  # sky, ground, legs, text
    assert not np.array_equal(frames[0], frames[1])
    env.close()


def test_human_mode_runs_headless() -> None:
    env = gym.make("roughwalk/CompassGaitFlat-v0", render_mode="human")
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(1, np.float32))
    assert env.render() is None
    env.close()


def test_renderer_draws_planned_footholds_and_rejects_bad_mode() -> None:
    env = gym.make("roughwalk/CompassGaitFlat-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.unwrapped.planned_footholds = [0.15, 0.3]
    assert _has_colour(env.render(), (20, 150, 60))
    with pytest.raises(ValueError, match="render_mode"):
        WalkerRenderer(0.32, mode="svg")
    with pytest.warns(UserWarning, match="svg"), pytest.raises(ValueError, match="render_mode"):
        gym.make("roughwalk/CompassGaitFlat-v0", render_mode="svg")


def test_vector_env_frames() -> None:
    venv = gym.make_vec(
        "roughwalk/CompassGaitFlat-v0", 2, vectorization_mode="vector_entry_point",
        render_mode="rgb_array",
    )  # fmt: skip
    venv.reset(seed=0)
    frames = venv.render()
    assert len(frames) == 2 and all(f.shape == (400, 600, 3) for f in frames)
    venv.close()


def test_record_video(tmp_path) -> None:
    pytest.importorskip("moviepy")
    env = gym.make("roughwalk/CompassGaitSlope-v0", render_mode="rgb_array", max_episode_steps=30)
    folder = tmp_path / "videos"
    env = gym.wrappers.RecordVideo(env, str(folder), episode_trigger=lambda e: True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.zeros(1, np.float32))
        done = term or trunc
    env.close()
    videos = list(folder.glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 0
