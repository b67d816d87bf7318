"""The ``roughwalk`` command line: sub-commands loaded on demand, the error contract (one line,
exit status 2, no traceback), ``--debug``, ``--version`` and help for a terminal."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from importlib.metadata import version
from pathlib import Path

import pytest

from commands import passive
from commands.cli import COMMANDS, build_parser, command_name, main

FLAT = "roughwalk/CompassGaitFlat-v0"
ANY = "roughwalk/CompassGait-v0"


def run_cli(argv: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    """``(exit status, stdout, stderr)`` of ``roughwalk ARGV`` run in this process."""
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_help_lists_the_subcommands(capsys):
    code, out, _ = run_cli(["--help"], capsys)
    assert code == 0
    for name in COMMANDS:
        assert name in out


def test_version_is_the_installed_package_version(capsys):
    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0
    assert out.strip() == f"roughwalk {version('roughwalk')}"


def test_no_command_prints_help_and_fails(capsys):
    code, out, _ = run_cli([], capsys)
    assert code == 2 and "usage" in out


def test_unknown_option_is_rejected():
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["passive", "--bogus"])
    assert exc.value.code == 2


def test_the_command_is_the_first_argument_that_is_not_an_option():
    assert command_name(["-h", "demo", "--no-figures"]) == "demo"
    assert command_name(["--debug", "passive"]) == "passive"
    assert command_name(["--help"]) is None and command_name([]) is None


def test_only_the_module_of_the_command_run_is_imported():
    code = (
        "import sys\n"
        "from commands.cli import main\n"
        "main(['passive', '--help'])\n"
        "print(sorted(m for m in sys.modules if m.startswith(('commands.', 'agents'))))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.splitlines()[-1] == "['commands.cli', 'commands.passive']"
    assert set(COMMANDS) == {
        "demo",
        "passive",
        "bench",
        "train",
        "evaluate",
        "compare",
        "mfpt",
        "basin",
        "sweep",
    }


# ---------------------------------------------------------------- the error contract
@pytest.fixture(scope="module")
def bad_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Damaged and misplaced input files."""
    d = tmp_path_factory.mktemp("bad_inputs")
    files = {
        "terrain": d / "terrain.yaml",
        "env_config": d / "env.yaml",
        "model": d / "run" / "model.zip",  # a zip, but no model; the statistics beside it
        "stats": d / "run" / "vecnormalize.pkl",  # damaged
        "truncated": d / "truncated.pkl",
        "not_zip": d / "model_text.zip",
        "a_file": d / "a_file.txt",
        "folder": d,
    }
    files["terrain"].write_text("kind: blocks\nlength: [1,\n")
    files["env_config"].write_text("base: base\nrobot: {m: [\n")
    files["model"].parent.mkdir()
    with zipfile.ZipFile(files["model"], "w") as zf:
        zf.writestr("data", "{}")
    files["stats"].write_bytes(b"garbage")
    files["truncated"].write_bytes(b"\x80\x04\x95\x10\x00\x00")
    files["not_zip"].write_text("not a zip")
    files["a_file"].write_text("x")
    return files


def _cases() -> list[tuple[str, list[str], tuple[str, ...]]]:
    """(id, argv with {placeholders} of ``bad_files``, fragments the one error line holds)."""
    ev = ["evaluate", "--policy", "passive", "--no-progress", "--episodes", "1"]
    return [
        ("evaluate-episodes-0", [*ev, "--env", FLAT, "--episodes", "0"], ("--episodes", ">= 1")),
        ("evaluate-episodes--1", [*ev, "--env", FLAT, "--episodes=-1"], ("--episodes", ">= 1")),
        ("evaluate-episodes-abc", [*ev, "--env", FLAT, "--episodes", "abc"], ("--episodes",)),
        ("evaluate-seed--1", [*ev, "--env", FLAT, "--seed=-1"], ("--seed", ">= 0", "-1")),
        ("evaluate-cartpole", [*ev, "--env", "CartPole-v1"], ("--env", "not a roughwalk env")),
        ("evaluate-unknown-env", [*ev, "--env", "roughwalk/Nope-v0"], ("--env", "unknown env")),
        (
            "evaluate-env-kwargs-yaml",
            [*ev, "--env", FLAT, "--env-kwargs", "difficulty=[1,"],
            ("--env-kwargs", "difficulty=[1,", "YAML"),
        ),
        (
            "evaluate-env-kwargs-unknown",
            [*ev, "--env", FLAT, "--env-kwargs", "bogus=1"],
            ("bogus", "allowed"),
        ),
        (
            "evaluate-terrain-yaml",
            [*ev, "--env", ANY, "--env-kwargs", "terrain={terrain}"],
            ("{terrain}", "not valid YAML", "line 3"),
        ),
        (
            "evaluate-env-config-yaml",
            [*ev, "--env", ANY, "--env-kwargs", "config={env_config}"],
            ("{env_config}", "not valid YAML"),
        ),
        (
            "evaluate-torque-limit-huge",
            [*ev, "--env", FLAT, "--env-kwargs", "torque_limit=1.0e+100"],
            ("torque_limit", "allowed: (0, 10000] N m"),
        ),
        (
            "evaluate-robot-stiff-friction",
            [
                *ev,
                "--env",
                ANY,
                "--env-kwargs",
                "robot={{name: x, m: 1, mH: 1, mHg: 1, l: 1, lc: 0.5, Fv: 1.0e+3}}",
            ],
            ("RobotParams.Fv", "N m s/rad", "allowed: [0, "),
        ),
        (
            "evaluate-terrain-length-huge",
            [*ev, "--env", ANY, "--env-kwargs", "terrain={{kind: blocks, length: 1.0e+12}}"],
            ("'length'", "allowed: [0, 10000] m"),
        ),
        (
            "evaluate-stats-beside-model",
            ["evaluate", "--policy", "{model}", "--env", FLAT],
            ("{stats}", "VecNormalize statistics"),
        ),
        (
            "evaluate-stats-truncated",
            ["evaluate", "--policy", "{model}", "--env", FLAT, "--vecnormalize", "{truncated}"],
            ("{truncated}", "VecNormalize statistics", "truncated"),
        ),
        (
            "evaluate-model-not-zip",
            ["evaluate", "--policy", "{not_zip}", "--env", FLAT],
            ("{not_zip}", "not a zip"),
        ),
        (
            "evaluate-model-missing",
            ["evaluate", "--policy", "{a_file}.zip", "--env", FLAT],
            ("--policy", "not found"),
        ),
        ("evaluate-algo", ["evaluate", "--policy", "{model}", "--algo", "dqn"], ("--algo", "ppo")),
        (
            "evaluate-json-under-a-file",
            [*ev, "--env", FLAT, "--json", "{a_file}/out.json"],
            ("--json", "is a file, not a folder"),
        ),
        (
            "evaluate-csv-a-folder",
            [*ev, "--env", FLAT, "--csv", "{folder}"],
            ("--csv", "is a folder"),
        ),
        (
            "evaluate-curve-of-a-baseline",
            [*ev, "--env", FLAT, "--plot-learning-curve"],
            ("--plot-learning-curve", "trained model"),
        ),
        (
            "evaluate-curve-without-data",
            ["evaluate", "--policy", "{model}", "--env", FLAT, "--plot-learning-curve"],
            ("no learning curve", "evaluation"),
        ),
        ("demo-unknown-env", ["demo", "--env", "unknown"], ("--env", "roughwalk/CompassGait")),
        ("demo-seed--3", ["demo", "--seed", "-3"], ("--seed", ">= 0", "-3")),
        ("demo-duration-0", ["demo", "--duration", "0"], ("--duration", "> 0")),
        ("demo-duration-nan", ["demo", "--duration", "nan"], ("--duration", "> 0")),
        ("demo-horizon-0", ["demo", "--horizon", "0"], ("--horizon", "[1, 10]")),
        ("demo-output-a-file", ["demo", "--output", "{a_file}"], ("--output", "is a file")),
        ("passive-robot", ["passive", "--robot", "nope"], ("--robot", "classic", "paper")),
        ("passive-perturb-10", ["passive", "--perturb", "10"], ("--perturb", "[0, 0.2]")),
        ("passive-perturb-0.5", ["passive", "--perturb", "0.5"], ("--perturb", "[0, 0.2]")),
        ("passive-slope-0", ["passive", "--slope", "0"], ("--slope", "(0, 0.25]")),
        ("passive-slope-no-cycle", ["passive", "--slope", "0.005"], ("--slope", "no passive")),
        ("passive-steps-0", ["passive", "--steps", "0"], ("--steps", "[1, 1000]")),
        ("bench-walkers-0", ["bench", "--walkers", "0"], ("--walkers", "[1, 1000000]")),
        ("unknown-command", ["dance"], ("invalid choice: 'dance'",)),
    ]


CASES = _cases()


@pytest.mark.parametrize(("argv", "fragments"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_with_exit_status_2(
    argv, fragments, bad_files, capsys, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)  # anything a command wrote by default would land here
    fill = {k: str(v) for k, v in bad_files.items()}
    argv = [a.format(**fill) for a in argv]
    code, out, err = run_cli(argv, capsys)
    lines = err.strip().splitlines()
    assert code == 2, (out, err)
    assert len(lines) == 1, err
    name = argv[0] if argv[0] in COMMANDS else None
    assert lines[0].startswith(f"roughwalk {name}: error: " if name else "roughwalk: error: ")
    for fragment in fragments:
        assert fragment.format(**fill) in lines[0]
    assert "Traceback" not in err + out
    assert not list(tmp_path.iterdir())  # nothing written


def test_debug_shows_the_traceback(bad_files, capsys):
    argv = ["evaluate", "--policy", "passive", "--env", ANY, "--debug"]
    code, _, err = run_cli([*argv, "--env-kwargs", f"terrain={bad_files['terrain']}"], capsys)
    assert code == 2
    assert "Traceback (most recent call last)" in err
    assert err.strip().splitlines()[-1].startswith("roughwalk evaluate: error: ")
    code, _, err = run_cli(["--debug", "passive", "--slope", "0.005"], capsys)
    assert code == 2 and "Traceback" in err


def test_interrupt_is_one_line_and_status_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(passive, "run", interrupted)
    code, _, err = run_cli(["passive"], capsys)
    assert code == 130 and err == "roughwalk passive: interrupted\n"


def test_a_bug_keeps_its_traceback(monkeypatch):
    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(passive, "run", broken)
    with pytest.raises(ZeroDivisionError, match="a bug"):
        main(["passive"])


# ---------------------------------------------------------------- help for a terminal
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_is_plain_text_with_defaults(name, capsys):
    code, out, _ = run_cli([name, "--help"], capsys)
    assert code == 0
    for markup in ("``", ":class:", ":func:", ":data:", "* "):
        assert markup not in out, markup
    text = out.split("\n\n", 1)[1]  # after the usage lines: the description and the options
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "(default: " in out


def test_demo_help_keeps_its_bullets_and_shows_defaults(capsys):
    code, out, _ = run_cli(["demo", "--help"], capsys)
    assert code == 0
    bullets = [line for line in out.splitlines() if line.startswith("- ")]
    assert [b.split(":")[0] for b in bullets] == [
        "- cartoon.png",
        "- q2.png",
        "- q1.png",
        "- velocities.png",
        "- walk.gif with --gif (25 frames per simulated second).",
    ][: len(bullets)] and len(bullets) == 5
    assert "(default: 0)" in out and "(default: outputs/demo)" in out
    assert "three steps on the flat" in " ".join(out.split())


# ---------------------------------------------------------------- numba's first compilation
def test_the_first_compilation_is_announced_once(tmp_path, monkeypatch, capsys):
    from commands.cli import COMPILING, announce_compilation, kernels_need_compiling

    (tmp_path / "fresh_kernels.py").write_text(
        "from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert kernels_need_compiling(["fresh_kernels"])
    assert announce_compilation(["fresh_kernels"])
    assert capsys.readouterr().out == COMPILING + "\n"
    assert sys.modules["fresh_kernels"].twice(2.0) == 4.0  # compiles and caches
    assert not kernels_need_compiling(["fresh_kernels"])
    assert not announce_compilation(["fresh_kernels"]) and capsys.readouterr().out == ""
