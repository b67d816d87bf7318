"""``roughwalk mfpt`` and ``roughwalk basin``: outputs, inputs checked before any work, and
earlier results kept unless ``--overwrite``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from agents.runs import LOCK_FILE, claim_output_folder
from commands.cli import main
from controllers.basin import periodic_reference
from controllers.controller import ControllerConfig


def _error_line(capsys: pytest.CaptureFixture, command: str) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"roughwalk {command}: error: ")
    return lines[0]


def test_mfpt_writes_results_and_stops_below_the_threshold(tmp_path: Path, capsys):
    out = tmp_path / "m"
    out.mkdir()
    (out / "mfpt.json").write_text("an earlier result")
    argv = ["mfpt", "--policy", "passive", "--roughness", "0", "0.01", "--walks", "3"]
    argv += ["--walkers", "2", "--step-cap", "5", "--out", str(out), "--overwrite"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "passive" in printed and "MFPT" in printed
    data = json.loads((out / "mfpt.json").read_text())
    # the passive walker fails within two footsteps: MFPT < 10 at the first level, so it stops
    assert len(data["levels"]) == 1
    level = data["levels"][0]
    assert level["estimate"]["failures"] == 3 and level["estimate"]["mfpt"] < 10
    assert [w["seed"] for w in level["walks"]] == [0, 1, 2]
    assert level["kaplan_meier"]["survival"][-1] == 0.0
    # the Markov-chain estimate on the same walks (every walk failed)
    chain = level["markov_chain"]
    assert chain["mfpt"] < 10 and chain["transitions"] == level["estimate"]["exposure"]
    assert "chain" in printed
    rows = list(csv.DictReader((out / "mfpt.csv").open()))
    assert len(rows) == 1 and rows[0]["policy"] == "passive" and rows[0]["walks"] == "3"
    assert float(rows[0]["markov_mfpt"]) == pytest.approx(chain["mfpt"])
    assert (out / "mfpt.png").stat().st_size > 0
    assert (out / "mfpt_survival.png").stat().st_size > 0
    names = ["mfpt.csv", "mfpt.json", "mfpt.png", "mfpt_survival.png"]
    assert sorted(p.name for p in out.iterdir()) == names


@pytest.mark.parametrize(
    ("command", "name"), [("mfpt", "mfpt.csv"), ("basin", "basin_fraction.png")]
)
def test_an_earlier_result_is_kept(tmp_path: Path, capsys, command, name):
    out = tmp_path / "r"
    out.mkdir()
    (out / name).write_text("an earlier result")
    assert main([command, "--out", str(out)]) == 2
    line = _error_line(capsys, command)
    assert "earlier result" in line and "--overwrite" in line
    assert (out / name).read_text() == "an earlier result"
    assert [p.name for p in out.iterdir()] == [name]


@pytest.mark.parametrize("command", ["mfpt", "basin"])
def test_a_folder_another_command_holds_is_refused(tmp_path: Path, capsys, command):
    out = tmp_path / "r"
    with claim_output_folder(out):
        assert main([command, "--out", str(out)]) == 2
        assert "another roughwalk command is writing there" in _error_line(capsys, command)
        assert [p.name for p in out.iterdir()] == [LOCK_FILE]


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--walks", "0"], "--walks"),
        (["--roughness", "0.02", "0.01"], "--roughness"),
        (["--roughness", "-0.01"], "--roughness"),
        (["--policy", "wander"], "--policy"),
        (["--step-cap", "x"], "--step-cap"),
        (["--confidence", "1"], "--confidence"),
        (["--env", "roughwalk/Nope-v0"], "--env"),
        (["--controller", "Q=[1,1]"], "ControllerConfig.Q"),
        (["--controller", "gain=2"], "gain"),
        (["--policy", "passive", "--controller", "Q=[1,1,1]"], "not to passive"),
        (["--planner", "clearance=-1"], "PlannerConfig.clearance"),
        (["--planner", "reach=2"], "reach"),
        (["--policy", "passive", "--planner", "clearance=0.003"], "not to passive"),
        (["--long-segment", "1.5"], "--long-segment"),
        (["--policy", "passive", "--long-segment", "0"], "not to passive"),
        (["--drop-edge-sd", "11"], "--drop-edge-sd"),
        (["--policy", "passive", "--drop-edge-sd", "9"], "not to passive"),
    ],
)
def test_mfpt_bad_input_is_one_line_exit_2(tmp_path: Path, capsys, args, match):
    out = tmp_path / "m"
    assert main(["mfpt", *args, "--out", str(out)]) == 2
    assert match in _error_line(capsys, "mfpt")
    assert not out.exists()


def test_basin_metric_follows_the_controller_weights(tmp_path: Path):
    """--controller sets the controller, hence its P: the basin's metric follows the weights."""
    argv = ["basin", "--radii", "0.1", "--per-radius", "2", "--steps", "1", "--slices", "0"]
    out = tmp_path / "b"
    assert main([*argv, "--controller", "Q=[1,1,1]", "R=2", "--out", str(out)]) == 0
    data = json.loads((out / "basin.json").read_text())
    assert data["settings"]["controller"] == {"Q": [1, 1, 1], "R": 2}
    # over the robot's defaults, recorded in full
    config = ControllerConfig.for_robot("paper", Q=(1.0, 1.0, 1.0), R=2.0)
    assert data["settings"]["controller_config"] == json.loads(json.dumps(config.to_dict()))
    np.testing.assert_allclose(data["P"], periodic_reference("paper", config).P, rtol=1e-12)
    assert not np.allclose(data["P"], periodic_reference("paper").P)


def test_basin_and_mfpt_take_planner_settings(tmp_path: Path):
    """--planner: the gait planner's settings over the robot's preset (the swing foot's
    clearance of an earlier release, say), recorded with the results."""
    argv = ["basin", "--radii", "0.1", "--per-radius", "2", "--steps", "1", "--slices", "0"]
    out = tmp_path / "b"
    assert main([*argv, "--planner", "clearance=0.003", "--out", str(out)]) == 0
    settings = json.loads((out / "basin.json").read_text())["settings"]
    assert settings["planner"] == {"clearance": 0.003}
    assert settings["planner_config"]["clearance"] == 0.003
    assert settings["planner_config"]["face_clearance"] == 0.003  # the rest: the preset's
    assert periodic_reference("paper").planner.config.clearance == 0.006
    assert periodic_reference("paper", None, {"clearance": 0.003}).planner.config.clearance == 0.003
    argv = ["mfpt", "--policy", "reference", "--roughness", "0", "--walks", "1", "--walkers", "1"]
    out = tmp_path / "m"
    assert main([*argv, "--step-cap", "2", "--planner", "clearance=0.003", "--out", str(out)]) == 0
    data = json.loads((out / "mfpt.json").read_text())
    assert data["settings"]["planner"] == {"clearance": 0.003}
    assert data["levels"][0]["walks"][0]["footsteps"] == 2
    out = tmp_path / "m0"
    assert main([*argv, "--step-cap", "2", "--long-segment", "0", "--out", str(out)]) == 0
    data = json.loads((out / "mfpt.json").read_text())
    assert data["settings"]["long_segment"] == 0.0
    out = tmp_path / "m9"
    assert main([*argv, "--step-cap", "2", "--drop-edge-sd", "9", "--out", str(out)]) == 0
    assert json.loads((out / "mfpt.json").read_text())["settings"]["drop_edge_sd"] == 9.0


def test_basin_writes_results(tmp_path: Path, capsys):
    out = tmp_path / "b"
    argv = ["basin", "--radii", "0.1", "0.2", "--per-radius", "2", "--steps", "2"]
    assert main([*argv, "--slices", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "certified level set" in printed and "r =  0.100" in printed
    data = json.loads((out / "basin.json").read_text())
    assert [r["starts"] + r["no_state"] for r in data["fractions"]] == [2, 2]
    assert data["level_set"]["selection"] == 2 and data["level_set"]["certification"] == 2
    assert len(data["samples"]) == 4 + 2 * 4
    rows = list(csv.DictReader((out / "basin.csv").open()))
    assert {r["kind"] for r in rows} == {"shell", "slice y_ydot", "slice I_y"}
    for name in ("basin_fraction.png", "basin_slice_y_ydot.png", "basin_slice_I_y.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--radii", "1", "0.5"], "--radii"),
        (["--radii", "0"], "--radii"),
        (["--per-radius", "0"], "--per-radius"),
        (["--steps", "-1"], "--steps"),
        (["--v-tol", "0"], "--v-tol"),
        (["--robot", "giant"], "--robot"),
        (["--controller", "R=0"], "ControllerConfig.R"),
        (["--planner", "clearance=-1"], "--planner: PlannerConfig.clearance"),
        (["--controller", "gain=2"], "gain"),
        (["--controller", "Q"], "--controller"),
    ],
)
def test_basin_bad_input_is_one_line_exit_2(tmp_path: Path, capsys, args, match):
    out = tmp_path / "b"
    assert main(["basin", *args, "--out", str(out)]) == 2
    assert match in _error_line(capsys, "basin")
    assert not out.exists()
