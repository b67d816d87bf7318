"""Shared helpers of the agent tests: shipped configs shrunk to smoke-test size."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from agents.config import AgentConfig, load_config
from agents.train import train

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "agents"
CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))
# one thread per test process: the suite runs with pytest -n 2 on 2 cores
torch.set_num_threads(1)
SMOKE_EPISODE_STEPS = 200  # time limit of the smoke-test episodes (1 s of walking)


def smoke_config(path: Path, timesteps: int | None = None) -> AgentConfig:
    """A shipped config with tiny batches and budget (same algorithm, env and wrappers).

    Residual configs get a smaller budget: every env step also runs the reference controller,
    whose footstep planning dominates their cost. A critic warm-up lasts a quarter of it.
    """
    cfg = load_config(path)
    # per-footstep agents: one agent step walks a whole footstep (about 110 env steps)
    footstep = cfg.is_footstep
    small = cfg.is_residual or footstep
    limit = SMOKE_EPISODE_STEPS // 2 if small else SMOKE_EPISODE_STEPS
    env_kwargs = {**cfg.env_kwargs, "max_episode_steps": limit}
    if cfg.algo == "ppo":
        n = timesteps or (16 if footstep else 128 if small else 2048)
        hyper = {"n_envs": 2, "n_steps": n // 4, "batch_size": min(64, n // 2), "n_epochs": 2}
    else:
        n = timesteps or (128 if small else 1200)
        hyper = {
            "n_envs": 2,
            "learning_starts": 0 if cfg.residual_init == "zero" else n // 3,
            "train_freq": 8,
            "gradient_steps": 2,
            "batch_size": 64,
            "buffer_size": 5000,
        }
    hyper.update(n_timesteps=n, env_kwargs=env_kwargs)
    run = {"eval_freq": n // 2, "eval_episodes": 1 if small else 2, "checkpoint_freq": n // 2}
    if cfg.critic_warmup:
        run["critic_warmup"] = n // 4
    return load_config(path, hyper, run)


@pytest.fixture(scope="session")
def smoke():
    """``smoke(path, timesteps=None)``: a shipped config shrunk for a smoke test."""
    return smoke_config


@pytest.fixture(scope="session")
def trained_ppo_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny PPO run on flat ground (from scratch), trained once per session."""
    cfg = smoke_config(CONFIG_DIR / "ppo_flat.yaml")
    return train(cfg, log_dir=tmp_path_factory.mktemp("runs"), progress_bar=False)


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray instance with 2 CPUs for the module (the test is skipped without Ray)."""
    ray = pytest.importorskip("ray")
    from agents.sweep.backends import init_ray

    assert init_ray(workers=2)
    yield ray
    ray.shutdown()
