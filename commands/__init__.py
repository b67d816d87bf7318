"""The ``roughwalk`` command line: the sub-commands ``demo``, ``passive``, ``bench``, ``train``,
``evaluate`` and ``compare``, one module each (``configure(parser)`` and ``run(args)``), loaded
on demand by ``main`` (``commands.cli``)."""

from typing import Any

__all__ = ["COMMANDS", "build_parser", "main"]


def __getattr__(name: str) -> Any:
    # imported on first use, so that ``python -m commands.cli`` runs the module only once
    if name in __all__:
        from . import cli

        return getattr(cli, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
