"""``roughwalk train``: overrides from the command line, bad configs reported without a
traceback."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from agents.config import load_config
from commands.cli import main
from configs import CONFIG_DIR

AGENT_CONFIGS = CONFIG_DIR / "agents"
GOOD = {
    "run": {"algo": "ppo", "env": "roughwalk/CompassGaitFlat-v0"},
    "roughwalk/CompassGaitFlat-v0": {"n_timesteps": 1000, "n_steps": 64},
}


def test_cli_reports_bad_config_without_traceback(tmp_path: Path, capsys):
    assert main(["train", str(tmp_path / "missing.yaml")]) == 2
    assert "config file not found" in capsys.readouterr().out
    cfg = tmp_path / "bad_algo.yaml"
    data = {k: dict(v) for k, v in GOOD.items()}
    data["run"]["algo"] = "trpo"
    cfg.write_text(yaml.safe_dump(data))
    assert main(["train", str(cfg), "--log-dir", str(tmp_path)]) == 2
    assert "unknown algorithm 'trpo'" in capsys.readouterr().out


def test_cli_train_with_overrides(tmp_path: Path, capsys):
    cfg = AGENT_CONFIGS / "sac_flat.yaml"
    argv = ["train", str(cfg), "--timesteps", "600", "--seed", "4", "--log-dir", str(tmp_path)]
    argv += ["--no-progress", "--hyperparams", "n_envs=2", "learning_starts=200"]
    argv += ["batch_size=32", "train_freq=16", "env_kwargs={max_episode_steps: 100}"]
    assert main(argv) == 0
    run = tmp_path / "sac_flat_s4"
    assert str(run) in capsys.readouterr().out
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["seeds"]["training_envs"] == [4, 5]
    assert manifest["num_timesteps"] >= 600  # whole vec-env steps: SB3 may overshoot by n_envs
    assert load_config(cfg).n_timesteps > 600  # the file itself is untouched
