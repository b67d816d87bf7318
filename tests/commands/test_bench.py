"""``roughwalk bench``: a quick section runs and prints its table."""

from commands.cli import main


def test_bench_runs_quick_simulator_section(capsys):
    assert main(["bench", "--quick", "--walkers", "16", "--only", "simulator"]) == 0
    out = capsys.readouterr().out
    assert "walker-steps" in out and "cores" in out


def test_bench_planner_section_takes_episodes_and_planner_settings(capsys, monkeypatch):
    """--episodes sets the closed-loop rows' episodes, --planner the planner's settings (named in
    the table's title); a bad setting is one line and exit status 2 before any timing."""
    monkeypatch.setenv("COLUMNS", "400")  # one line per row
    argv = ["bench", "--quick", "--only", "planner", "--episodes", "1"]
    assert main([*argv, "--planner", "clearance=0.003"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "planner clearance=0.003" in out and "difficulty 1 (1 episodes)" in out
    # the previous defaults walk the same courses in the same run, course by course
    assert "difficulty 2 (1 episodes), planner compiled_sqp=0" in out
    assert "the bare env, course by course in the same run" in out
    assert main([*argv, "--planner", "clearance=-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["roughwalk bench: error: --planner: PlannerConfig.clearance = -1; allowed: >= 0"]
