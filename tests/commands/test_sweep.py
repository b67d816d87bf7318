"""``roughwalk sweep``: the shipped tiny spec, trained run folders, one-line errors."""

import json
import re
import sys

import pytest
import yaml

from agents.runs import LOCK_FILE, claim_output_folder
from commands.cli import main
from configs import CONFIG_DIR

TINY = CONFIG_DIR / "sweeps" / "tiny.yaml"
FLAT = "roughwalk/CompassGaitFlat-v0"


def test_tiny_spec_runs_and_resumes(tmp_path, capsys):
    out = tmp_path / "tiny"
    assert main(["sweep", str(TINY), "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "tiny: 95 % intervals, held-out seeds 1001000-1001001" in text
    assert "pd on rough (difficulty=2.0)" in text
    assert "success [%] 0 [0, 66] (0/2)" in text  # the passive walker trips on every course
    assert "12 episodes run in" in text
    assert "plot: " in text and (out / "plots" / "success_rough_difficulty.png").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["cells"]) == 6
    # the same command again: nothing to run, the same summary
    assert main(["sweep", str(TINY), "--out", str(out), "--no-progress", "--no-plot"]) == 0
    assert "0 episodes run in" in capsys.readouterr().out
    assert json.loads((out / "summary.json").read_text()) == summary


def test_trained_run_folders_grouped_by_training_seed(cli_trained_run, tmp_path, capsys):
    spec = {
        "episodes": 2,
        "policies": [
            {"policy": str(cli_trained_run), "name": "ppo s0", "group": "ppo"},
            {"policy": "passive", "name": "zero"},
        ],
        "envs": [
            {"name": "flat", "id": "roughwalk/CompassGaitFlat-v0"},
            {"name": "stairs", "id": "roughwalk/CompassGaitStairs-v0"},
        ],
    }
    for env in spec["envs"]:
        env["kwargs"] = {"max_episode_steps": 100}
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--no-progress", "--no-plot"]) == 0
    text = capsys.readouterr().out
    assert "ppo s0 on stairs" in text
    assert "across training seeds" in text and "P(ppo > zero) = " in text
    summary = json.loads((out / "summary.json").read_text())
    ppo = summary["cells"][0]
    assert ppo["policy"] == "ppo s0" and ppo["group"] == "ppo"
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    # a run folder without best_model.zip stands for its final model
    assert records[0]["policy_spec"] == str(cli_trained_run / "model.zip")


def write_spec(tmp_path, **changes):
    data = yaml.safe_load(TINY.read_text())
    data.update(changes)
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    "changes, extra, message",
    [
        ({"policies": ["walker"]}, [], r"policies\[0\].policy: unknown policy 'walker'"),
        ({"envs": [{"id": "roughwalk/Moon-v0"}]}, [], "unknown environment id 'roughwalk/Moon-v0'"),
        ({"envs": [{"id": FLAT, "kwargs": {"gravity": 1}}]}, [], "gravity"),
        ({"policies": []}, [], "policies: must be a non-empty list"),
        ({"seed": -5}, [], "seed: must be an integer >= 0, got -5"),
        ({"repeat": 2}, [], "unknown key 'repeat'"),
        ({}, ["--workers", "2"], "--workers and --address apply to --backend ray"),
        ({}, ["--workers", "0"], "argument --workers: must be an integer >= 1, got 0"),
    ],
)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, changes, extra, message):
    path = write_spec(tmp_path, **changes)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("roughwalk sweep: error: ") and len(err.strip().splitlines()) == 1
    assert re.search(message, err)
    assert not out.exists()


def test_missing_spec_and_ray(tmp_path, capsys, monkeypatch):
    assert main(["sweep", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o")]) == 2
    assert "sweep spec not found" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails
    argv = ["sweep", str(TINY), "--out", str(tmp_path / "o"), "--backend", "ray"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--backend ray: Ray is not installed" in err and 'pip install -e ".[sweep]"' in err
    assert not (tmp_path / "o").exists()


def test_another_spec_in_out_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "spec.json").write_text("{}")
    (out / "episodes.jsonl").write_text("")
    assert main(["sweep", str(TINY), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "holds the results of another sweep spec" in err and "--overwrite" in err
    assert (out / "spec.json").read_text() == "{}"


def test_a_sweep_into_a_folder_another_command_holds_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    with claim_output_folder(out):  # e.g. the same sweep started twice
        assert main(["sweep", str(TINY), "--out", str(out), "--no-progress"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1
        assert "another roughwalk command is writing there" in err
        assert [p.name for p in out.iterdir()] == [LOCK_FILE]
