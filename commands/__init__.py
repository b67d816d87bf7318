"""The ``roughwalk`` command line: the sub-commands ``demo``, ``passive``, ``bench``, ``train``,
``evaluate`` and ``compare``, one module each (``configure(parser)`` and ``run(args)``), loaded
on demand by :func:`main`."""

from .cli import COMMANDS, build_parser, main

__all__ = ["COMMANDS", "build_parser", "main"]
