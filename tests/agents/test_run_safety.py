"""Runs are never lost: no overwriting, nothing written by a rejected train or a failed resume,
an interrupted training saved and resumable, models usable outside their run folder."""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.callbacks import BaseCallback

from agents.config import ConfigError, load_config
from agents.evaluate import evaluate
from agents.runs import (
    LOCK_FILE,
    atomic_write,
    claim_output_folder,
    model_algo,
    model_data,
    numbered_runs,
)
from agents.train import train
from agents.trained import TrainedPolicy, load_policy

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "agents"
# the module (the package's attribute ``agents.train`` is the function)
train_module = importlib.import_module("agents.train")


def snapshot(folder: Path) -> dict[str, str]:
    """Every file and folder below ``folder``: relative path -> sha256 of the contents."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        if p.is_file()
        else "folder"
        for p in sorted(folder.rglob("*"))
    }


@pytest.fixture
def finished_run(trained_ppo_run: Path, tmp_path: Path) -> Path:
    """A copy of a finished tiny PPO run in ``tmp_path/runs``."""
    run = tmp_path / "runs" / trained_ppo_run.name
    shutil.copytree(trained_ppo_run, run)
    return run


class StopAt(BaseCallback):
    """Raises ``exc`` once the model has trained ``steps`` env steps (a Ctrl-C stand-in)."""

    def __init__(self, steps: int, exc: BaseException) -> None:
        super().__init__()
        self.steps, self.exc = steps, exc

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.steps:
            raise self.exc
        return True


def stop_training_at(monkeypatch, steps: int, exc: BaseException | None = None) -> None:
    """Make every training of this test stop with ``exc`` at ``steps`` env steps."""
    make = train_module.make_callbacks

    def with_stop(*args, **kwargs):
        return make(*args, **kwargs) + [StopAt(steps, exc or KeyboardInterrupt())]

    monkeypatch.setattr(train_module, "make_callbacks", with_stop)


def test_a_second_train_into_the_same_folder_keeps_the_first_run(finished_run: Path, smoke):
    before = snapshot(finished_run)
    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=256)
    second = train(cfg, log_dir=finished_run.parent, progress_bar=False, tensorboard=False)
    third = train(cfg, log_dir=finished_run.parent, progress_bar=False, tensorboard=False)
    assert snapshot(finished_run) == before
    assert [second.name, third.name] == [f"{finished_run.name}_2", f"{finished_run.name}_3"]
    assert numbered_runs(finished_run.parent, finished_run.name) == [finished_run, second, third]
    assert json.loads((third / "manifest.json").read_text())["status"] == "finished"


@pytest.mark.parametrize(
    ("overrides", "run_overrides", "message"),
    [
        ({"env_kwargs": {"difficulty": 2.0}}, {}, "scales random terrain only"),
        ({"gamma": 2.0}, {}, r"gamma \(from --hyperparams\) must be a number in \[0, 1\]"),
        ({"policy_kwargs": {"no_such_option": 1}}, {}, "PPO rejects the hyperparameters"),
    ],
)
def test_a_rejected_train_leaves_the_finished_run_untouched(
    finished_run: Path, overrides, run_overrides, message
):
    before = snapshot(finished_run.parent)
    with pytest.raises(ConfigError, match=message):
        cfg = load_config(CONFIG_DIR / "ppo_flat.yaml", overrides, run_overrides)
        train(cfg, log_dir=finished_run.parent, progress_bar=False)
    assert snapshot(finished_run.parent) == before  # no new run folder either


def test_an_interrupted_training_is_saved_and_resumes_to_the_budget(
    smoke, tmp_path: Path, monkeypatch, capsys
):
    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=2048)  # rollouts of 1024 steps
    stop_training_at(monkeypatch, 512)  # within the first rollout
    with pytest.raises(KeyboardInterrupt):
        train(cfg, log_dir=tmp_path, progress_bar=True, tensorboard=False)
    run = tmp_path / "ppo_flat_s0"
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "interrupted" and manifest["num_timesteps"] == 512
    ckpt = run / "checkpoints" / "rl_model_512_steps.zip"
    assert manifest["interruptions"][-1]["checkpoint"] == str(ckpt)
    assert (run / "checkpoints" / "rl_model_vecnormalize_512_steps.pkl").is_file()
    assert not (run / "model.zip").exists()  # a finished run's file: not made by an interrupt
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err == [
        f"training stopped (Ctrl-C) at 512 of 2,048 steps, saved in {ckpt}; "
        f"continue with: roughwalk train --resume {ckpt}"
    ]
    monkeypatch.undo()
    resumed = train(cfg, log_dir=None, resume=ckpt, progress_bar=False, tensorboard=False)
    assert resumed == run  # an interrupted run continues in its own folder
    manifest = json.loads((run / "manifest.json").read_text())
    # the checkpoint holds the model before the first update: the first rollout is collected
    # again, and the run ends at the budget in whole rollouts, as the uninterrupted run
    assert manifest["status"] == "finished" and manifest["n_timesteps"] == 2048
    assert manifest["num_timesteps"] == manifest["planned_timesteps"] == 2048
    assert manifest["resumed_from"] == [str(ckpt)]
    assert (run / "model.zip").is_file()
    assert list(np.load(run / "eval" / "evaluations.npz")["timesteps"]) == [1024, 2048]
    assert any((run / "monitor" / "resume1").glob("*.monitor.csv"))


def test_any_error_during_training_saves_the_run(smoke, tmp_path: Path, monkeypatch, capsys):
    cfg = smoke(CONFIG_DIR / "sac_flat.yaml", timesteps=600)
    cfg.save_replay_buffer = True
    stop_training_at(monkeypatch, 300, RuntimeError("the simulator broke"))
    with pytest.raises(RuntimeError, match="the simulator broke"):
        train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    run = tmp_path / "sac_flat_s0"
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "interrupted"
    assert manifest["interruptions"][0]["reason"] == "RuntimeError: the simulator broke"
    steps = manifest["num_timesteps"]
    assert (run / "checkpoints" / f"rl_model_replay_buffer_{steps}_steps.pkl").is_file()
    assert "continue with: roughwalk train --resume" in capsys.readouterr().err
    assert not list(run.rglob(".*.partial"))


@pytest.mark.parametrize("broken", ["model", "statistics"])
def test_a_failed_resume_changes_nothing(smoke, tmp_path: Path, monkeypatch, broken: str):
    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=1024)
    stop_training_at(monkeypatch, 512)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    monkeypatch.undo()
    run = tmp_path / "ppo_flat_s0"
    ckpt = run / "checkpoints" / "rl_model_512_steps.zip"
    target = ckpt if broken == "model" else run / "checkpoints/rl_model_vecnormalize_512_steps.pkl"
    target.write_bytes(target.read_bytes()[:300])  # truncated
    before = snapshot(tmp_path)
    with pytest.raises(ValueError, match=r"--resume.*cannot read"):
        train(cfg, log_dir=None, resume=ckpt, progress_bar=False)
    assert snapshot(tmp_path) == before  # no resumed_from entry, no monitor/resume1


def test_a_read_only_or_impossible_run_folder_is_an_error_at_the_start(
    smoke, tmp_path: Path, monkeypatch
):
    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=1024)
    stop_training_at(monkeypatch, 512)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    monkeypatch.undo()
    run = tmp_path / "ppo_flat_s0"
    shutil.rmtree(run / "eval")
    (run / "eval").write_text("not a folder")
    before = snapshot(tmp_path)
    with pytest.raises(ValueError, match="eval is not a folder"):
        train(cfg, log_dir=None, resume=run / "checkpoints" / "rl_model_512_steps.zip")
    assert snapshot(tmp_path) == before
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with pytest.raises(ValueError, match=r"--log-dir .*a_file.* is not a folder"):
        train(cfg, log_dir=blocker / "runs")


def test_a_model_copied_out_of_its_run_evaluates(trained_ppo_run: Path, tmp_path: Path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(trained_ppo_run / "model.zip", elsewhere / "agent.zip")
    shutil.copy(trained_ppo_run / "vecnormalize.pkl", elsewhere / "agent_vecnormalize.pkl")
    assert model_algo(model_data(elsewhere / "agent.zip")) == "ppo"  # recorded in the zip
    # no run manifest: the env, its keyword arguments and wrappers come from the zip too
    ev = evaluate(str(elsewhere / "agent.zip"), None, episodes=1, seed=0)
    inside = evaluate(str(trained_ppo_run / "model.zip"), None, episodes=1, seed=0)
    assert ev.env_id == inside.env_id and ev.episodes == inside.episodes
    with pytest.raises(ValueError, match="is a PPO model"):
        load_policy(str(elsewhere / "agent.zip"), algo="sac")
    (elsewhere / "agent_vecnormalize.pkl").unlink()
    with pytest.raises(ValueError, match="no VecNormalize statistics beside it"):
        TrainedPolicy(elsewhere / "agent.zip")
    policy = load_policy(
        str(elsewhere / "agent.zip"), algo="ppo", vecnormalize=trained_ppo_run / "vecnormalize.pkl"
    )
    assert isinstance(policy, TrainedPolicy) and policy.obs_norm is not None


def test_models_saved_without_their_algorithm_are_recognised(trained_ppo_run: Path, tmp_path):
    from stable_baselines3 import A2C, PPO

    model = PPO.load(trained_ppo_run / "model.zip", device="cpu")
    del model.roughwalk  # as saved before the algorithm was recorded
    model.save(tmp_path / "old_ppo.zip")
    a2c = A2C("MlpPolicy", "Pendulum-v1", device="cpu")
    a2c.save(tmp_path / "old_a2c.zip")
    assert model_algo(model_data(tmp_path / "old_ppo.zip")) == "ppo"
    assert model_algo(model_data(tmp_path / "old_a2c.zip")) == "a2c"
    policy = TrainedPolicy(
        tmp_path / "old_ppo.zip", vecnormalize=trained_ppo_run / "vecnormalize.pkl"
    )
    assert policy.config is None and isinstance(policy.model, PPO)


def test_files_are_written_all_or_nothing(tmp_path: Path):
    target = tmp_path / "model.zip"
    target.write_bytes(b"the previous model")

    def broken_writer(tmp: Path) -> None:
        tmp.write_bytes(b"half a mod")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(target, broken_writer)
    assert target.read_bytes() == b"the previous model"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.zip"]


HOLD = (
    "import sys; from agents.runs import claim_output_folder\n"
    "try:\n"
    "    with claim_output_folder(sys.argv[1]):\n"
    "        pass\n"
    "except ValueError as exc:\n"
    "    print(exc); sys.exit(2)\n"
)


def test_an_output_folder_is_held_by_one_command_at_a_time(tmp_path: Path):
    out = tmp_path / "results"
    with claim_output_folder(out, ("summary.json",)) as held:
        assert held == out and (out / LOCK_FILE).read_text().startswith("process ")
        # another process, and another claim in this one, are refused while it is held
        other = subprocess.run(
            [sys.executable, "-c", HOLD, str(out)], capture_output=True, text=True, check=False
        )
        assert other.returncode == 2, other.stderr
        assert "another roughwalk command is writing there (process" in other.stdout
        with pytest.raises(ValueError, match="another roughwalk command is writing there"):
            with claim_output_folder(out):
                pass
        (out / "summary.json").write_text("the first command's result")
    # released: no lock file left, the result kept, and the next command may write there
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]
    other = subprocess.run([sys.executable, "-c", HOLD, str(out)], check=False)
    assert other.returncode == 0


def test_a_crashed_holder_does_not_block_the_folder(tmp_path: Path):
    out = tmp_path / "results"
    out.mkdir()
    # a lock file left by a process that was killed: the lock went with the process
    (out / LOCK_FILE).write_text("process 12345\n")
    with claim_output_folder(out):
        assert (out / LOCK_FILE).read_text() == f"process {os.getpid()}\n"
    assert list(out.iterdir()) == []


def test_a_refused_or_failed_command_leaves_no_new_folder(tmp_path: Path):
    out = tmp_path / "new" / "results"
    with pytest.raises(RuntimeError, match="failed"):
        with claim_output_folder(out):
            raise RuntimeError("failed before writing")
    assert not (tmp_path / "new").exists()
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "mfpt.json").write_text("an earlier result")
    with pytest.raises(ValueError, match="holds an earlier result"):
        with claim_output_folder(earlier, ("mfpt.json",)):
            pass
    assert [p.name for p in earlier.iterdir()] == ["mfpt.json"]


def test_training_leaves_no_folder_in_the_system_temp_folder(smoke, tmp_path: Path, monkeypatch):
    system_tmp = tmp_path / "tmp"
    system_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=256)
    train(cfg, log_dir=tmp_path / "runs", progress_bar=False, tensorboard=False)
    model, _, _ = train_module.build(cfg, tmp_path / "built", tensorboard=False)
    model.learn(128)
    assert list(system_tmp.iterdir()) == []
