"""``roughwalk train``: overrides and run-level flags from the command line, short runs that
produce every output, and every bad input reported as one line naming the argument, exit
status 2, before anything is written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.config import load_config
from commands.cli import build_parser, main
from configs import CONFIG_DIR

AGENT_CONFIGS = CONFIG_DIR / "agents"
FLAT = str(AGENT_CONFIGS / "ppo_flat.yaml")
GOOD = {
    "run": {"algo": "ppo", "env": "roughwalk/CompassGaitFlat-v0"},
    "roughwalk/CompassGaitFlat-v0": {"n_timesteps": 1000, "n_steps": 64},
}


def _files(tmp_path: Path) -> list[str]:
    """The argument files the error cases use, made in ``tmp_path``."""
    bad_algo = tmp_path / "bad_algo.yaml"
    bad_algo.write_text(yaml.safe_dump({**GOOD, "run": {**GOOD["run"], "algo": "trpo"}}))
    (tmp_path / "a_file").write_text("")
    (tmp_path / "truncated.zip").write_bytes(b"PK\x03\x04 not a whole zip")
    return ["bad_algo.yaml", "a_file", "truncated.zip"]


# (arguments after ``train``, with {tmp} for the test's folder; what the message says)
TRAIN_ERRORS = [
    (
        [FLAT, "--hyperparams", "n_steps=abc"],
        "n_steps (from --hyperparams) must be a whole number >= 1, got 'abc'",
    ),
    (
        [FLAT, "--hyperparams", "n_steps=-5"],
        "n_steps (from --hyperparams) must be a whole number >= 1, got -5",
    ),
    (
        [FLAT, "--hyperparams", "policy=CnnPolicy"],
        "policy (from --hyperparams) must be one of 'MlpPolicy', got 'CnnPolicy'",
    ),
    (
        [FLAT, "--hyperparams", "gamma=2.0"],
        "gamma (from --hyperparams) must be a number in [0, 1], got 2.0",
    ),
    (
        [FLAT, "--hyperparams", "n_stepz=3"],
        "unknown hyperparameter(s) n_stepz for PPO (from --hyperparams)",
    ),
    ([FLAT, "--hyperparams", "oops"], "expected KEY=VALUE, got 'oops'"),
    (
        [FLAT, "--hyperparams", "env_kwargs={difficulty: 2.0}"],
        "env_kwargs {'difficulty': 2.0}: difficulty = 2.0 scales random terrain only",
    ),
    ([FLAT, "--log-dir", "{tmp}/a_file/runs"], "a_file is not a folder"),
    (
        [FLAT, "--log-dir", "/proc/roughwalk-runs"],
        "--log-dir /proc/roughwalk-runs: cannot write in /proc",
    ),
    ([FLAT, "--timesteps", "-5"], "--timesteps: must be an integer >= 1, got -5"),
    ([FLAT, "--seed", "-3"], "--seed: must be an integer >= 0, got -3"),
    ([FLAT, "--eval-freq", "-1"], "--eval-freq: must be an integer >= 0, got -1"),
    ([FLAT, "--checkpoint-freq", "-1"], "--checkpoint-freq: must be an integer >= 0, got -1"),
    ([FLAT, "--eval-episodes", "0"], "--eval-episodes: must be an integer >= 1, got 0"),
    ([FLAT, "--threads", "0"], "--threads: must be an integer >= 1, got 0"),
    (
        [FLAT, "--timesteps", "4000", "--eval-freq", "10000"],
        "--eval-freq: 10,000 is more than the 8,192 env steps of this run",
    ),
    (
        [FLAT, "--timesteps", "4000", "--checkpoint-freq", "9000"],
        "--checkpoint-freq: 9,000 is more than the 8,192 env steps",
    ),
    (["{tmp}/missing.yaml"], "config file not found"),
    (["{tmp}/bad_algo.yaml"], "unknown algorithm 'trpo'"),
    ([], "config: required (an agent config file), unless --resume is given"),
    (
        [FLAT, "--resume", "{tmp}/missing.zip"],
        "--resume {tmp}/missing.zip: no such checkpoint file",
    ),
    (
        [FLAT, "--resume", "{tmp}/truncated.zip"],
        "--resume {tmp}/truncated.zip: cannot read the model",
    ),
    (["--resume", "{tmp}/truncated.zip"], "no run manifest beside it or above it"),
]
IDS = [f"{i}-{' '.join(a[-2:])[-40:]}" for i, (a, _) in enumerate(TRAIN_ERRORS)]


def _argv(args: list[str], tmp_path: Path) -> list[str]:
    return ["train", *(a.replace("{tmp}", str(tmp_path)) for a in args)]


@pytest.mark.parametrize(("args", "message"), TRAIN_ERRORS, ids=IDS)
def test_bad_input_is_an_error_naming_it_before_anything_is_written(
    args: list[str], message: str, tmp_path: Path
):
    if "/proc/" in " ".join(args) and not Path("/proc/self").exists():
        pytest.skip("needs /proc")
    before = sorted(_files(tmp_path))
    argv = _argv(args, tmp_path)
    parsed = build_parser(["train"]).parse_args(argv)
    with pytest.raises((ValueError, OSError)) as err:
        parsed._run(parsed)
    text = str(err.value)
    assert message.replace("{tmp}", str(tmp_path)) in text and "\n" not in text
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize(("args", "message"), TRAIN_ERRORS, ids=IDS)
def test_bad_input_exits_2_with_one_line_and_no_traceback(
    args: list[str], message: str, tmp_path: Path, capsys
):
    if "/proc/" in " ".join(args) and not Path("/proc/self").exists():
        pytest.skip("needs /proc")
    _files(tmp_path)
    assert main(_argv(args, tmp_path)) == 2
    out = capsys.readouterr()
    lines = [line for line in out.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("roughwalk train: error: ")
    assert message.replace("{tmp}", str(tmp_path)) in lines[0]
    assert "Traceback" not in out.out + out.err


def test_cli_train_with_overrides(tmp_path: Path, capsys):
    cfg = AGENT_CONFIGS / "sac_flat.yaml"
    argv = ["train", str(cfg), "--timesteps", "600", "--seed", "4", "--log-dir", str(tmp_path)]
    argv += ["--no-progress", "--hyperparams", "n_envs=2", "learning_starts=200"]
    argv += ["batch_size=32", "train_freq=16", "env_kwargs={max_episode_steps: 100}"]
    assert main(argv) == 0
    run = tmp_path / "sac_flat_s4"
    out = capsys.readouterr().out
    assert str(run) in out
    # updates every 16 steps of each of the 2 envs: 600 rounds up to 608, and is reported so
    assert "this run ends at 608 steps (n_timesteps 600)" in out
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["seeds"]["training_envs"] == [4, 5]
    assert (manifest["n_timesteps"], manifest["num_timesteps"]) == (600, 608)
    assert load_config(cfg).n_timesteps > 600  # the file itself is untouched


def test_a_short_run_gets_evaluations_a_best_model_checkpoints_and_logs(
    tmp_path: Path, capsys, monkeypatch
):
    import agents.callbacks

    totals = []

    class RecordedBar(agents.callbacks.ProgressBar):
        def _on_training_start(self) -> None:
            super()._on_training_start()
            totals.append(self.pbar.total)

    monkeypatch.setattr(agents.callbacks, "ProgressBar", RecordedBar)
    argv = ["train", FLAT, "--timesteps", "4000", "--eval-freq", "1000"]
    argv += ["--checkpoint-freq", "2000", "--eval-episodes", "2", "--log-dir", str(tmp_path)]
    argv += ["--hyperparams", "n_envs=2", "n_steps=512", "batch_size=256", "n_epochs=1"]
    argv += ["env_kwargs={max_episode_steps: 100}"]
    assert main(argv) == 0
    run = tmp_path / "ppo_flat_s0"
    out = capsys.readouterr().out
    # rollouts of 2 x 512 steps: the run ends at 4,096 steps, which the bar counts to
    assert totals == [4096]
    evals = [line for line in out.splitlines() if line.startswith("eval at ")]
    assert [line.split(":")[0] for line in evals] == [
        f"eval at {n:,} steps" for n in (1000, 2000, 3000, 4000)
    ]
    assert all("success" in line and "distance" in line for line in evals)
    assert (run / "best_model.zip").is_file() and (run / "best_vecnormalize.pkl").is_file()
    assert sorted(p.name for p in (run / "checkpoints").glob("*.zip")) == [
        "rl_model_2000_steps.zip",
        "rl_model_4000_steps.zip",
    ]
    assert np.load(run / "eval" / "evaluations.npz")["results"].shape == (4, 2)
    episodes = [
        len(p.read_text().splitlines()) - 2 for p in (run / "monitor").glob("*.monitor.csv")
    ]
    assert len(episodes) == 2 and min(episodes) > 0  # 100-step episodes, 2,048 steps each
    manifest = json.loads((run / "manifest.json").read_text())
    assert (manifest["n_timesteps"], manifest["num_timesteps"]) == (4000, 4096)
    assert manifest["config"]["run"]["eval_freq"] == 1000
    # a second run of the same command goes to a new folder
    assert main(argv + ["--timesteps", "1024", "--checkpoint-freq", "0"]) == 0
    assert (tmp_path / "ppo_flat_s0_2" / "model.zip").is_file()


def test_resume_without_the_config_takes_the_runs(tmp_path: Path, capsys, monkeypatch):
    import importlib

    from stable_baselines3.common.callbacks import BaseCallback

    train_module = importlib.import_module("agents.train")
    make = train_module.make_callbacks

    class CtrlC(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 256:
                raise KeyboardInterrupt
            return True

    monkeypatch.setattr(train_module, "make_callbacks", lambda *a, **k: make(*a, **k) + [CtrlC()])
    argv = ["train", FLAT, "--timesteps", "512", "--log-dir", str(tmp_path), "--no-progress"]
    argv += ["--hyperparams", "n_envs=2", "n_steps=128", "batch_size=64", "n_epochs=1"]
    argv += ["env_kwargs={max_episode_steps: 100}"]
    assert main(argv) == 130  # Ctrl-C: saved, and said how to resume
    err = capsys.readouterr().err
    command = err.strip().splitlines()[-1].split("continue with: ")[1]
    assert command.startswith("roughwalk train --resume ")
    monkeypatch.undo()
    assert main(command.split()[1:] + ["--no-progress"]) == 0
    manifest = json.loads((tmp_path / "ppo_flat_s0" / "manifest.json").read_text())
    assert manifest["status"] == "finished" and manifest["num_timesteps"] == 512
    assert manifest["config"]["roughwalk/CompassGaitFlat-v0"]["n_steps"] == 128  # the run's
    assert len(manifest["commands"]) == 2  # both command lines are recorded
