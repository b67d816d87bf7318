"""``roughwalk bench``: a quick section runs and prints its table."""

from commands.cli import main


def test_bench_runs_quick_simulator_section(capsys):
    assert main(["bench", "--quick", "--walkers", "16", "--only", "simulator"]) == 0
    out = capsys.readouterr().out
    assert "walker-steps" in out and "cores" in out
