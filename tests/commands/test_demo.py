"""``roughwalk demo``: the paper's experiment runs, prints its table and writes its figures."""

import argparse

from commands import demo
from commands.cli import main


def test_demo_writes_table_and_figures(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    demo.configure(parser)
    args = parser.parse_args(["--duration", "2.5", "--output", str(tmp_path)])
    code = demo.run(args)
    out = capsys.readouterr().out
    assert "thd start" in out and "Riccati" in out
    for name in ("cartoon.png", "q2.png", "q1.png", "velocities.png"):
        p = tmp_path / name
        assert p.exists() and p.stat().st_size > 5000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert code == 0, out


def test_demo_rollout_and_table_rows():
    res = demo.rollout("roughwalk/CompassGaitFlat-v0", seed=1, duration=1.5)
    rows = demo.step_table(res["records"])
    assert len(rows) >= 2
    h = res["history"]
    assert h["x_hat"].shape[1] == 4 and h["nominal"].shape[1] == 3
    assert res["failure"] is None


def test_demo_is_a_cli_subcommand(tmp_path, capsys):
    code = main(
        ["demo", "--duration", "1.0", "--no-figures", "--env", "roughwalk/CompassGaitFlat-v0"]
    )
    assert code == 0
    assert "footsteps" in capsys.readouterr().out
