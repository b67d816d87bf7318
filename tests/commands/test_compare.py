"""``roughwalk compare``: the dry run lists the command of every row; bad input is one line
naming the argument, exit status 2, before anything runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from commands.cli import build_parser, main


def test_compare_dry_run_lists_every_row(capsys):
    assert main(["compare", "--dry-run"]) == 0
    table = capsys.readouterr().out
    lines = [ln for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    # 4 terrain settings x (3 baselines + 4 agents), and on rough-hard the 2 residual "_zero"
    # agents and the per-footstep one
    assert len(lines) == 4 * 7 + 3
    assert "roughwalk train" in table and "--env-kwargs difficulty=2.0" in table
    assert "| rough-hard | per-footstep PPO | 0 |" in table
    assert main(["compare", "--dry-run", "--terrains", "stairs", "rough-hard"]) == 0
    table = capsys.readouterr().out
    lines = [ln for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    assert len(lines) == 2 * 7 + 3 and {ln.split("|")[1].strip() for ln in lines} == {
        "stairs",
        "rough-hard",
    }


def test_compare_dry_run_lists_a_row_per_training_seed(capsys):
    assert main(["compare", "--dry-run", "--terrains", "flat", "--seeds", "0", "1", "2"]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| flat")]
    # 3 baselines, then 4 agents x 3 seeds
    assert len(lines) == 3 + 4 * 3
    assert [ln.split("|")[3].strip() for ln in lines[3:6]] == ["0", "1", "2"]
    assert "ppo_flat.yaml --seed 2 --log-dir" in lines[5]


def test_two_configs_of_one_kind_on_a_setting_are_not_pooled_as_seeds(tmp_path: Path, capsys):
    from agents.compare import CONFIG_DIR

    for name in ("ppo_flat", "ppo_flat_b"):
        (tmp_path / f"{name}.yaml").write_bytes((CONFIG_DIR / "ppo_flat.yaml").read_bytes())
    (tmp_path / "ppo_residual_rough_hard_zero.yaml").write_bytes(
        (CONFIG_DIR / "ppo_residual_rough_hard_zero.yaml").read_bytes()
    )
    argv = ["compare", "--configs", str(tmp_path), "--terrains", "flat", "rough-hard"]
    assert main([*argv, "--dry-run"]) == 0
    labels = [ln.split("|")[2].strip() for ln in capsys.readouterr().out.splitlines()[2:]]
    assert labels[3:5] == ["PPO [ppo_flat]", "PPO [ppo_flat_b]"]
    assert labels[-1] == "residual PPO (zero init)"


# (arguments after ``compare``, with {tmp} for the test's folder; what the message says)
COMPARE_ERRORS = [
    (["--configs", "/nonexistent", "--dry-run"], "--configs /nonexistent: no such folder"),
    (
        ["--configs", "{tmp}/empty", "--dry-run"],
        "--configs {tmp}/empty: no agent configs (*.yaml) in it",
    ),
    (
        ["--only", "nothing_like_this", "--dry-run"],
        "--only nothing_like_this: matches none of the configs",
    ),
    (["--episodes", "0", "--dry-run"], "--episodes: must be an integer >= 1, got 0"),
    (["--seed", "-1", "--dry-run"], "--seed: must be an integer >= 0, got -1"),
    (["--threads", "0", "--dry-run"], "--threads: must be an integer >= 1, got 0"),
    (["--seeds", "1", "1", "--dry-run"], "--seeds: repeated training seed in [1, 1]"),
    (["--seeds", "999999", "--dry-run"], "run.seed = 999999 is out of range; allowed: in [0,"),
    (["--out", "{tmp}/a_file/results"], "--out {tmp}/a_file/results: {tmp}/a_file is not a folder"),
    (
        ["--log-dir", "{tmp}/a_file/runs"],
        "--log-dir {tmp}/a_file/runs: {tmp}/a_file is not a folder",
    ),
]


def _argv(args: list[str], tmp_path: Path) -> list[str]:
    (tmp_path / "empty").mkdir(exist_ok=True)
    (tmp_path / "a_file").write_text("")
    return ["compare", *(a.replace("{tmp}", str(tmp_path)) for a in args)]


@pytest.mark.parametrize(("args", "message"), COMPARE_ERRORS)
def test_bad_input_is_an_error_naming_it(args: list[str], message: str, tmp_path: Path, capsys):
    parsed = build_parser(["compare"]).parse_args(_argv(args, tmp_path))
    with pytest.raises((ValueError, OSError)) as err:
        parsed._run(parsed)
    text = str(err.value)
    assert message.replace("{tmp}", str(tmp_path)) in text and "\n" not in text
    assert capsys.readouterr().out == ""  # nothing listed, evaluated or trained
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "empty"]


@pytest.mark.parametrize(("args", "message"), COMPARE_ERRORS)
def test_bad_input_exits_2_with_one_line_and_no_traceback(
    args: list[str], message: str, tmp_path: Path, capsys
):
    assert main(_argv(args, tmp_path)) == 2
    out = capsys.readouterr()
    lines = [line for line in out.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("roughwalk compare: error: ")
    assert message.replace("{tmp}", str(tmp_path)) in lines[0]
    assert "Traceback" not in out.out + out.err
