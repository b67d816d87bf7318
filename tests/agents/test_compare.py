"""The RL-versus-control comparison: rows, the trained and evaluated agents, the table."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from agents.compare import CONFIG_DIR, SETTINGS, chosen_model, compare
from agents.config import load_config
from agents.runs import claim_output_folder
from agents.train import train


def test_compare_trains_evaluates_and_writes_the_table(tmp_path: Path):
    tiny = {"n_timesteps": 256, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1}
    result = compare(
        log_dir=tmp_path / "runs",
        out=tmp_path / "results",
        episodes=2,
        only="ppo_flat",
        baselines=("passive",),
        settings=SETTINGS[:1],
        hyperparams=tiny,
        progress=False,
    )
    rows = result.rows
    assert [(r["setting"], r["policy"]) for r in rows] == [("flat", "passive"), ("flat", "PPO")]
    assert rows[1]["budget"].startswith("256 steps")
    # no periodic evaluation within 256 steps: the final model is the one evaluated
    assert str(tmp_path / "runs" / "ppo_flat_s0" / "model.zip") in rows[1]["command"]
    assert (tmp_path / "runs" / "ppo_flat_s0" / "model.zip").is_file()
    table = (tmp_path / "results" / "compare.md").read_text()
    assert "| flat | PPO |" in table and "ppo_flat.yaml --seed 0 --log-dir" in table
    data = json.loads((tmp_path / "results" / "compare.json").read_text())
    assert len(data["evaluations"]) == 2
    assert all(len(e["episodes"]) == 2 for e in data["evaluations"])
    assert [e.summary for e in result.evaluations] == [r["summary"] for r in rows]


def test_compare_reports_the_validation_best_model_when_there_is_one(tmp_path: Path):
    (tmp_path / "model.zip").write_text("final")
    assert chosen_model(tmp_path) == tmp_path / "model.zip"
    (tmp_path / "best_model.zip").write_text("best on the validation courses")
    assert chosen_model(tmp_path) == tmp_path / "best_model.zip"


TINY = {"n_timesteps": 256, "n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1}


def _compare_flat_ppo(tmp_path: Path, hyperparams: dict, **kwargs):
    return compare(
        log_dir=tmp_path / "runs",
        out=tmp_path / "results",
        episodes=1,
        only="ppo_flat",
        baselines=(),
        settings=SETTINGS[:1],
        hyperparams=hyperparams,
        progress=False,
        **kwargs,
    )


def test_compare_reuses_the_latest_finished_run_and_reports_the_steps_it_trained(
    tmp_path: Path,
):
    cfg = load_config(CONFIG_DIR / "ppo_flat.yaml", TINY, {"eval_freq": 0})
    train(cfg, log_dir=tmp_path / "runs", progress_bar=False, tensorboard=False)
    longer = load_config(cfg.path, {**TINY, "n_timesteps": 300}, {"eval_freq": 0})
    second = train(longer, log_dir=tmp_path / "runs", progress_bar=False, tensorboard=False)
    assert second.name == "ppo_flat_s0_2"
    (row,) = _compare_flat_ppo(tmp_path, TINY, train_missing=False).rows
    assert str(second / "model.zip") in row["command"]
    # rollouts of 2 x 64 steps: 300 asked, 384 trained, and that is what the table says
    assert row["budget"].startswith("384 steps")
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["ppo_flat_s0", "ppo_flat_s0_2"]


def test_compare_resumes_an_interrupted_run_of_the_same_config(tmp_path: Path, monkeypatch):
    import importlib

    from stable_baselines3.common.callbacks import BaseCallback

    train_module = importlib.import_module("agents.train")
    make = train_module.make_callbacks

    class CtrlC(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 128:
                raise KeyboardInterrupt
            return True

    monkeypatch.setattr(train_module, "make_callbacks", lambda *a, **k: make(*a, **k) + [CtrlC()])
    with pytest.raises(KeyboardInterrupt):
        _compare_flat_ppo(tmp_path, TINY)
    monkeypatch.undo()
    run = tmp_path / "runs" / "ppo_flat_s0"
    assert json.loads((run / "manifest.json").read_text())["status"] == "interrupted"
    (row,) = _compare_flat_ppo(tmp_path, TINY).rows
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "finished" and manifest["num_timesteps"] == 256
    assert manifest["resumed_from"] == [str(run / "checkpoints" / "rl_model_128_steps.zip")]
    assert str(run / "model.zip") in row["command"]
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["ppo_flat_s0"]


def test_a_second_comparison_keeps_the_first_unless_told_to_overwrite(tmp_path: Path, monkeypatch):
    configs = tmp_path / "configs"  # one agent, on another terrain: the flat row is passive only
    configs.mkdir()
    (configs / "ppo_stairs.yaml").write_bytes((CONFIG_DIR / "ppo_stairs.yaml").read_bytes())
    kw = dict(
        config_dir=configs,
        log_dir=tmp_path / "runs",
        out=tmp_path / "results",
        episodes=1,
        baselines=("passive",),
        settings=SETTINGS[:1],
        progress=False,
    )
    compare(**kw)
    first = {p.name: p.read_bytes() for p in (tmp_path / "results").iterdir()}
    assert sorted(first) == ["compare.csv", "compare.json", "compare.md"]
    ran = []
    # the package exports the function compare under the module's name: patch the module
    monkeypatch.setattr(sys.modules["agents.compare"], "evaluate", lambda *a, **k: ran.append(a))
    with pytest.raises(ValueError, match="earlier comparison.*--overwrite"):
        compare(**kw)
    assert not ran  # refused before any episode
    assert {p.name: p.read_bytes() for p in (tmp_path / "results").iterdir()} == first
    # nor into a folder another comparison is writing to, even with --overwrite
    with claim_output_folder(tmp_path / "results"):
        with pytest.raises(ValueError, match="another roughwalk command is writing there"):
            compare(**kw, overwrite=True)
    assert not ran
    monkeypatch.undo()
    compare(**kw, overwrite=True, seed=5)
    assert (tmp_path / "results" / "compare.json").read_bytes() != first["compare.json"]
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == sorted(first)


def _compare_seeds(tmp_path: Path, name: str, **kwargs):
    return compare(
        log_dir=tmp_path / name / "runs",
        out=tmp_path / name / "results",
        episodes=2,
        only="ppo_flat",
        baselines=("passive",),
        settings=SETTINGS[:1],
        hyperparams=TINY,
        progress=False,
        seeds=(0, 3),
        **kwargs,
    )


def test_compare_trains_every_seed_and_reports_statistics_across_them(tmp_path: Path):
    result = _compare_seeds(tmp_path, "serial")
    runs = tmp_path / "serial" / "runs"
    assert sorted(p.name for p in runs.iterdir()) == ["ppo_flat_s0", "ppo_flat_s3"]
    assert [(r["policy"], r["seed"]) for r in result.rows] == [
        ("passive", None),
        ("PPO", 0),
        ("PPO", 3),
    ]
    assert "ppo_flat.yaml --seed 3 --log-dir" in result.rows[2]["command"]
    groups = {g["group"]: g for g in result.across_seeds["groups"]}
    assert groups["PPO"]["runs"] == 2 and groups["passive"]["runs"] == 1
    rates = [r["summary"]["success_rate"] for r in result.rows[1:]]
    assert min(rates) <= groups["PPO"]["iqm"] <= max(rates)
    (pair,) = result.across_seeds["improvement"]
    assert {pair["x"], pair["y"]} == {"PPO", "passive"}
    table = (tmp_path / "serial" / "results" / "compare.md").read_text()
    assert "| flat | PPO | 3 |" in table and "Across training seeds" in table
    assert "| PPO | passive |" in table
    data = json.loads((tmp_path / "serial" / "results" / "compare.json").read_text())
    assert data["across_seeds"] == result.across_seeds
    # a second comparison reuses both finished runs: nothing is trained again
    again = compare(
        log_dir=runs,
        out=tmp_path / "again",
        episodes=2,
        only="ppo_flat",
        baselines=(),
        settings=SETTINGS[:1],
        hyperparams=TINY,
        progress=False,
        seeds=(3, 0),
        train_missing=False,
    )
    assert [r["summary"] for r in again.rows] == [r["summary"] for r in result.rows[:0:-1]]


def test_compare_on_ray_trains_and_evaluates_to_the_same_results(local_ray, tmp_path: Path):
    serial = _compare_seeds(tmp_path, "serial")
    remote = _compare_seeds(tmp_path, "ray", backend="ray")
    assert sorted(p.name for p in (tmp_path / "ray" / "runs").iterdir()) == [
        "ppo_flat_s0",
        "ppo_flat_s3",
    ]
    assert [e.episodes for e in remote.evaluations] == [e.episodes for e in serial.evaluations]
    assert remote.across_seeds == serial.across_seeds
