"""``roughwalk evaluate``: the summary, JSON/CSV outputs, inputs checked before any episode,
trained models, the learning curve, and tables readable in 80 columns."""

from __future__ import annotations

import csv
import importlib
import json
import shutil
from pathlib import Path

import pytest

from agents.config import EVAL_SEED_OFFSET
from agents.evaluate import EpisodeResult, Evaluation, load_trained
from commands.cli import main
from commands.evaluate import TABLE_COLUMNS, render_table, summary_row

SLOPE = "roughwalk/CompassGaitSlope-v0"
FLAT = "roughwalk/CompassGaitFlat-v0"


@pytest.fixture
def episode_count(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the episodes run (``agents.evaluate.run_episode`` calls)."""
    calls = [0]
    module = importlib.import_module("agents.evaluate")
    real = module.run_episode

    def counted(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(module, "run_episode", counted)
    return calls


def test_cli_evaluate(tmp_path: Path, capsys, episode_count):
    out = tmp_path / "sub" / "e.json"
    argv = ["evaluate", "--policy", "passive", "--env", SLOPE, "--episodes", "2"]
    assert main([*argv, "--seed", "3", "--json", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "success 100% (2)" in printed and "distance [m]" in printed
    assert json.loads(out.read_text())["episodes"][0]["seed"] == EVAL_SEED_OFFSET + 3
    assert episode_count[0] == 2
    assert [p.name for p in out.parent.iterdir()] == ["e.json"]  # no temporary file left


def test_existing_results_are_kept_unless_told_to_overwrite(tmp_path: Path, capsys, episode_count):
    out, table = tmp_path / "e.json", tmp_path / "e.csv"
    argv = ["evaluate", "--policy", "passive", "--env", SLOPE, "--episodes", "1", "--no-progress"]
    assert main([*argv, "--json", str(out), "--csv", str(table)]) == 0
    first = (out.read_bytes(), table.read_bytes())
    for option, path in (("--json", out), ("--csv", table)):
        assert main([*argv, "--seed", "4", option, str(path)]) == 2
        err = capsys.readouterr().err
        assert f"error: {option} {path}: the file exists" in err and "--overwrite" in err
    assert episode_count[0] == 1  # the refused runs ran no episode
    assert (out.read_bytes(), table.read_bytes()) == first
    assert main([*argv, "--seed", "4", "--json", str(out), "--overwrite"]) == 0
    assert json.loads(out.read_text())["episodes"][0]["seed"] == EVAL_SEED_OFFSET + 4


def test_output_paths_are_checked_before_any_episode(tmp_path: Path, capsys, episode_count):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    argv = ["evaluate", "--policy", "passive", "--env", FLAT, "--episodes", "3", "--no-progress"]
    for bad in (["--json", str(blocker / "e.json")], ["--csv", str(tmp_path)]):
        assert main([*argv, *bad]) == 2
        assert "error: argument --" in capsys.readouterr().err
    # a model whose run has nothing to plot fails before its episodes too
    run = tmp_path / "run"
    run.mkdir()
    shutil.make_archive(str(run / "model"), "zip", root_dir=run)
    assert main([*argv, "--policy", str(run / "model.zip"), "--plot-learning-curve"]) == 2
    assert "no learning curve" in capsys.readouterr().err
    assert episode_count[0] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "run"]


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


def test_a_model_moved_out_of_its_run_names_its_algorithm(cli_trained_run: Path, tmp_path: Path):
    for name in ("model.zip", "vecnormalize.pkl"):
        shutil.copy(cli_trained_run / name, tmp_path / name)
    policy = load_trained(tmp_path / "model.zip", algo="ppo")
    assert type(policy.model).__name__ == "PPO"
    assert policy.vecnormalize_path == tmp_path / "vecnormalize.pkl"


# ---------------------------------------------------------------- tables in 80 columns
def _evaluation(policy: str, env_id: str, kwargs: dict, failures: list[str | None]) -> Evaluation:
    """An evaluation of made-up episodes (one per entry of ``failures``)."""
    episodes = [
        EpisodeResult(
            seed=EVAL_SEED_OFFSET + k,
            success=f is None,
            failure=f,
            steps=2000,
            duration=10.0,
            footsteps=11,
            distance=1.83,
            speed=0.183,
            motor_work=2.0,
            cost_of_transport=0.012,
            episode_return=1.5,
        )
        for k, f in enumerate(failures)
    ]
    return Evaluation(policy, env_id, kwargs, episodes, total_mass=10.0, gravity=9.81)


COMPARE_LIKE = [
    _evaluation("reference", "roughwalk/CompassGaitStairs-v0", {}, [None] * 50),
    _evaluation(
        "runs/sac_residual_rough_hard_s0/best_model.zip",
        "roughwalk/CompassGaitRough-v0",
        {"difficulty": 2.0, "max_episode_steps": 3000},
        [None, "fall", "trip", "slip", "stuck", "liftoff"] * 5,
    ),
    _evaluation("passive", "roughwalk/CompassGaitRough-v0", {"difficulty": 1.0}, ["fall"] * 50),
]


@pytest.mark.parametrize("terminal", [True, False], ids=["terminal", "piped"])
def test_tables_are_readable_in_80_columns(terminal: bool):
    title = "runs/sac_residual_rough_hard_s0/best_model.zip on roughwalk/CompassGaitRough-v0, seeds"
    text = render_table(COMPARE_LIKE, title=title, width=80, terminal=terminal)
    assert "…" not in text and "..." not in text
    assert max(len(line) for line in text.splitlines()) <= 80
    flat = " ".join(text.split())
    for ev in COMPARE_LIKE:
        for cell in summary_row(ev):  # every cell whole, on one line or wrapped at spaces
            assert " ".join(cell.split()) in flat, cell
    for name in TABLE_COLUMNS[2:]:
        assert name in text
    assert "sac_residual_rough_hard_s0/best_model on CompassGaitRough-v0" in text


def test_a_table_that_fits_the_terminal_stays_a_table():
    short = [COMPARE_LIKE[0]]
    text = render_table(short, title="t", width=80, terminal=True)
    assert max(len(line) for line in text.splitlines()) <= 80
    header = next(line for line in text.splitlines() if line.startswith("policy"))
    assert header.split() == ["policy", "env", "success", *"steps [m] [m/s] CoT failures".split()]
    row = next(line for line in text.splitlines() if line.startswith("reference"))
    assert row.split() == " ".join(summary_row(short[0])).split()
    # the same piped: one block per evaluation, the same numbers
    piped = render_table(short, title="t", width=120, terminal=False)
    assert piped.splitlines()[1] == "reference on CompassGaitStairs-v0"
    assert "success 100% (50)" in piped


# ---------------------------------------------------------------- the certificate per footstep
STAIRS = "roughwalk/CompassGaitStairs-v0"


def test_the_json_holds_the_lyapunov_values_of_the_reference_policy(tmp_path: Path, capsys):
    out, table = tmp_path / "fixed.json", tmp_path / "fixed.csv"
    argv = ["evaluate", "--policy", "reference", "--env", STAIRS, "--episodes", "1"]
    argv += ["--no-progress", "--controller-mode", "fixed-plan"]
    assert main([*argv, "--json", str(out), "--csv", str(table)]) == 0
    assert "fixed-plan: V end/start < 1 on" in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["controller_mode"] == "fixed-plan"
    (episode,) = data["episodes"]
    steps = episode["certificate"]
    # every touchdown ends a completed footstep; the one in progress at the end is left out
    assert len(steps) == episode["footsteps"] >= 8
    assert [s["index"] for s in steps] == list(range(len(steps)))
    for s in steps:
        assert s["V_ratio"] == pytest.approx(s["V_end"] / s["V_start"])
        assert 0 < s["max_xperp_norm"] < 1 and 0 < s["max_abs_u"] <= 15 + 1e-6
    ratios = [s["V_ratio"] for s in steps]
    assert episode["V_ratio_max"] == max(ratios)
    assert episode["V_ratio_below_1"] == pytest.approx(sum(r < 1 for r in ratios) / len(ratios))
    assert data["summary"]["V_ratio_median"] == episode["V_ratio_median"]
    row = next(csv.DictReader(open(table)))
    assert "certificate" not in row and float(row["V_ratio_max"]) == pytest.approx(max(ratios))


def test_policies_without_the_transverse_controller_have_no_certificate(tmp_path: Path, capsys):
    out = tmp_path / "passive.json"
    argv = ["evaluate", "--policy", "passive", "--env", SLOPE, "--episodes", "1", "--no-progress"]
    assert main([*argv, "--json", str(out)]) == 0
    assert "V end/start" not in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["controller_mode"] is None and data["summary"]["V_ratio_median"] is None
    assert data["episodes"][0]["certificate"] is None


def test_the_controller_mode_is_checked_before_any_episode(capsys, episode_count):
    argv = ["evaluate", "--env", STAIRS, "--episodes", "1", "--no-progress"]
    assert main([*argv, "--policy", "passive", "--controller-mode", "fixed-plan"]) == 2
    assert "--controller-mode: applies to the pd and reference policies" in capsys.readouterr().err
    assert main([*argv, "--policy", "reference", "--plan-steps", "9"]) == 2
    assert "--plan-steps: applies to --controller-mode fixed-plan only" in capsys.readouterr().err
    assert main([*argv, "--policy", "reference", "--controller-mode", "fixed"]) == 2
    assert "invalid choice: 'fixed'" in capsys.readouterr().err
    assert episode_count[0] == 0


def test_controller_settings_from_the_command_line(tmp_path: Path, capsys, episode_count):
    """``--planner``, ``--controller`` and ``--observer-eps`` reach the reference policy (here:
    its first-wave settings, on one course); bad ones are one-line errors before any episode."""
    argv = ["evaluate", "--env", STAIRS, "--episodes", "1", "--no-progress"]
    bad = [
        (["--policy", "reference", "--planner", "speed=1"], "unknown planner setting"),
        (["--policy", "reference", "--controller", "horizon=0"], "ControllerConfig.horizon = 0"),
        (["--policy", "reference", "--observer-eps", "0"], "observer_eps = 0.0; allowed"),
        (["--policy", "passive", "--observer-eps", "0.02"], "applies to the pd and reference"),
        (["--policy", "passive", "--identify", "0"], "identify: applies to the pd and reference"),
        (["--policy", "reference", "--identify", "-1"], "--identify: must be"),
        (["--policy", "reference", "--leg-margin", "11"], "--leg-margin: must be"),
        (["--policy", "passive", "--leg-margin", "1"], "leg_margin: applies to the pd and"),
        (["--policy", "reference", "--long-segment", "2"], "--long-segment: must be"),
        (["--policy", "passive", "--long-segment", "0"], "long_segment: applies to the pd and"),
        (["--policy", "reference", "--drop-edge-sd", "-1"], "--drop-edge-sd: must be"),
        (["--policy", "passive", "--drop-edge-sd", "1"], "drop_edge_sd: applies to the pd and"),
    ]
    for extra, message in bad:
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert episode_count[0] == 0
    out = tmp_path / "first_wave.json"
    first_wave = ["--identify", "0", "--perception", "known-map", "--observer-eps", "0.02"]
    first_wave += ["--planner", "end_thetadot_floor=0", "--controller", "tube_replans=0"]
    assert main([*argv, "--policy", "reference", *first_wave, "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["summary"]["success_rate"] == 1.0 and episode_count[0] == 1
