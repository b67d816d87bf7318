"""The ``roughwalk`` command line: one sub-command per module, loaded on demand."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Iterable, Sequence

# sub-command -> module defining ``configure(parser)`` and ``run(args) -> int``, and its help
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("commands.demo", "the paper's stairs experiment with the reference controller"),
    "passive": ("commands.passive", "passive walking of the classic walker down a slope"),
    "bench": ("commands.bench", "simulator, environment and controller speed"),
    "train": ("commands.train", "train an RL agent from a config"),
    "evaluate": ("commands.evaluate", "evaluate a policy on held-out terrain"),
    "compare": ("commands.compare", "baselines versus RL agents on every terrain, one table"),
}


def build_parser(configured: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """Parser listing every sub-command.

    Args:
        configured: the sub-commands whose modules are imported and whose arguments are added
            (default: all); the others are listed with their help only, so that a command
            line imports just the module of the sub-command it runs.
    """
    parser = argparse.ArgumentParser(
        prog="roughwalk",
        description="Compass-gait walking over rough terrain: simulation, control and RL.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = set(COMMANDS if configured is None else configured)
    for name, (module, help_text) in COMMANDS.items():
        if name not in chosen:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip())
        mod.configure(p)
        p.set_defaults(_run=mod.run)
    return parser


def command_name(argv: Sequence[str]) -> str | None:
    """The sub-command a command line names: its first argument that is not an option (the
    ``roughwalk`` parser itself takes no option with a value), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``roughwalk`` command.

    Args:
        argv: the arguments after ``roughwalk`` (default: ``sys.argv[1:]``).

    Returns:
        The exit status: the sub-command's, or 2 when no sub-command is given.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    name = command_name(argv)
    parser = build_parser([name] if name in COMMANDS else [])
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
