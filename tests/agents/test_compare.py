"""The RL-versus-control comparison: rows, the trained and evaluated agents, the table."""

from __future__ import annotations

import json
from pathlib import Path

from agents.compare import SETTINGS, chosen_model, compare


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
    assert "| flat | PPO |" in table and "ppo_flat.yaml --log-dir" in table
    data = json.loads((tmp_path / "results" / "compare.json").read_text())
    assert len(data["evaluations"]) == 2
    assert all(len(e["episodes"]) == 2 for e in data["evaluations"])
    assert [e.summary for e in result.evaluations] == [r["summary"] for r in rows]


def test_compare_reports_the_validation_best_model_when_there_is_one(tmp_path: Path):
    (tmp_path / "model.zip").write_text("final")
    assert chosen_model(tmp_path) == tmp_path / "model.zip"
    (tmp_path / "best_model.zip").write_text("best on the validation courses")
    assert chosen_model(tmp_path) == tmp_path / "best_model.zip"
