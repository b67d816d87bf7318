"""The ``roughwalk`` command line: one sub-command per module, loaded on demand."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

# sub-command -> module defining ``configure(parser)`` and ``run(args) -> int``
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("agents.demo", "the paper's stairs experiment with the reference controller"),
    "passive": ("agents.passive", "passive walking of the classic walker down a slope"),
    "bench": ("agents.bench", "simulator, environment and controller speed"),
    "train": ("agents.train", "train an RL agent from a config"),
    "evaluate": ("agents.evaluate", "evaluate a policy on held-out terrain"),
    "compare": ("agents.compare", "baselines versus RL agents on every terrain, one table"),
}


def build_parser() -> argparse.ArgumentParser:
    """Parser with every sub-command whose module is present."""
    parser = argparse.ArgumentParser(
        prog="roughwalk",
        description="Compass-gait walking over rough terrain: simulation, control and RL.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name == module:
                continue
            raise
        p = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip())
        mod.configure(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``roughwalk`` command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
