"""The ``roughwalk`` command line: sub-commands are wired and loaded on demand."""

import subprocess
import sys

import pytest

from commands.cli import COMMANDS, build_parser, command_name, main


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


def test_unknown_option_is_rejected():
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["passive", "--bogus"])
    assert exc.value.code == 2


def test_unknown_command_is_rejected(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["dance"])
    assert exc.value.code == 2
    assert "invalid choice: 'dance'" in capsys.readouterr().err


def test_the_command_is_the_first_argument_that_is_not_an_option():
    assert command_name(["-h", "demo", "--no-figures"]) == "demo"
    assert command_name(["--help"]) is None and command_name([]) is None


def test_only_the_module_of_the_command_run_is_imported():
    code = (
        "import sys\n"
        "from commands.cli import main\n"
        "try:\n"
        "    main(['passive', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "print(sorted(m for m in sys.modules if m.startswith(('commands.', 'agents'))))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.splitlines()[-1] == "['commands.cli', 'commands.passive']"
    assert set(COMMANDS) == {"demo", "passive", "bench", "train", "evaluate", "compare"}
