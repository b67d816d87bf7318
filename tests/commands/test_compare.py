"""``roughwalk compare``: the dry run lists the command of every row."""

from commands.cli import main


def test_compare_dry_run_lists_every_row(capsys):
    assert main(["compare", "--dry-run"]) == 0
    table = capsys.readouterr().out
    lines = [ln for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    # 4 terrain settings x (3 baselines + 4 agents)
    assert len(lines) == 4 * 7
    assert "roughwalk train" in table and "--env-kwargs difficulty=2.0" in table
    assert main(["compare", "--dry-run", "--terrains", "stairs", "rough-hard"]) == 0
    table = capsys.readouterr().out
    lines = [ln for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    assert len(lines) == 2 * 7 and {ln.split("|")[1].strip() for ln in lines} == {
        "stairs",
        "rough-hard",
    }
