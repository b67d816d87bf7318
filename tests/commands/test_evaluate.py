"""``roughwalk evaluate``: the table, JSON/CSV outputs, errors, trained models, learning curve."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from agents.config import EVAL_SEED_OFFSET
from commands.cli import main

SLOPE = "roughwalk/CompassGaitSlope-v0"
FLAT = "roughwalk/CompassGaitFlat-v0"


def test_cli_evaluate(tmp_path: Path, capsys):
    out = tmp_path / "e.json"
    argv = ["evaluate", "--policy", "passive", "--env", SLOPE, "--episodes", "2"]
    assert main([*argv, "--seed", "3", "--json", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "success" in printed and "100%" in printed
    assert json.loads(out.read_text())["episodes"][0]["seed"] == EVAL_SEED_OFFSET + 3
    assert main(["evaluate", "--policy", "passive", "--env", "roughwalk/Nope-v0"]) == 2
    assert "unknown environment id" in capsys.readouterr().out
    assert main(["evaluate", "--policy", str(tmp_path / "missing.zip"), "--env", FLAT]) == 2
    assert "model file not found" in capsys.readouterr().out


def test_cli_evaluates_a_trained_model_and_plots_its_learning_curve(
    cli_trained_run: Path, tmp_path: Path, capsys
):
    model = cli_trained_run / "model.zip"
    png = tmp_path / "curve.png"
    argv = ["evaluate", "--policy", str(model), "--episodes", "2", "--no-progress"]
    assert main([*argv, "--csv", str(tmp_path / "m.csv"), "--plot-learning-curve", str(png)]) == 0
    assert png.is_file() and png.stat().st_size > 5000
    printed = capsys.readouterr().out
    assert f"learning curve: {png}" in printed
    rows = list(csv.DictReader(open(tmp_path / "m.csv")))
    # the env defaults to the run's, with its time limit
    assert len(rows) == 2 and {r["env_id"] for r in rows} == {FLAT}
    assert all(int(r["steps"]) <= 100 for r in rows)
    # without a file name the curve goes into the run
    assert main([*argv, "--plot-learning-curve"]) == 0
    assert (cli_trained_run / "learning_curve.png").is_file()
    baseline = ["evaluate", "--policy", "passive", "--env", FLAT, "--episodes", "1"]
    assert main([*baseline, "--no-progress", "--plot-learning-curve"]) == 2
    assert "--plot-learning-curve needs a trained model" in capsys.readouterr().out
