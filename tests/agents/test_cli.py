"""The ``roughwalk`` command line: sub-commands are wired and do what they print."""

import re

import pytest

from agents.cli import build_parser, main


def test_help_lists_the_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in ("demo", "passive", "bench", "train", "evaluate"):
        assert name in out


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage" in capsys.readouterr().out


def test_passive_walk_converges_to_the_limit_cycle(capsys):
    assert main(["passive", "--steps", "12", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    # the cycle of the control notes, and a distance to it that shrinks over the run
    assert "0.7344" in out and "0.5359" in out
    dists = [float(m) for m in re.findall(r"(\d\.\d+e[-+]\d+)\W*$", out, flags=re.M)]
    assert len(dists) >= 10
    assert dists[-1] < 0.05 * dists[0]


def test_bench_runs_quick_simulator_section(capsys):
    assert main(["bench", "--quick", "--walkers", "16", "--only", "simulator"]) == 0
    out = capsys.readouterr().out
    assert "walker-steps" in out and "cores" in out


def test_unknown_option_is_rejected():
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["passive", "--bogus"])
    assert exc.value.code == 2
