"""Shared helpers of the command tests: a tiny agent trained through the command line."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from commands.cli import main
from configs import CONFIG_DIR

AGENT_CONFIGS = CONFIG_DIR / "agents"
# one thread per test process: the suite runs with pytest -n 2 on 2 cores
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def cli_trained_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny PPO run on flat ground trained by ``roughwalk train``, once per session."""
    log_dir = tmp_path_factory.mktemp("cli_runs")
    argv = ["train", str(AGENT_CONFIGS / "ppo_flat.yaml"), "--timesteps", "256"]
    argv += ["--log-dir", str(log_dir), "--no-progress", "--hyperparams", "n_envs=2"]
    argv += ["n_steps=64", "batch_size=64", "n_epochs=1", "env_kwargs={max_episode_steps: 100}"]
    assert main(argv) == 0
    return log_dir / "ppo_flat_s0"
