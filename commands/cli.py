"""The ``roughwalk`` command line: one sub-command per module, loaded on demand.

Errors: a command reports bad input by raising ``ValueError`` or ``OSError`` (or argparse
rejects an argument); :func:`main` prints it as one line ``roughwalk CMD: error: MESSAGE`` on
stderr and returns 2 (``--debug`` also prints the traceback). Ctrl-C returns 130. Any other
exception is a bug: it propagates with its traceback (exit status 1), which is what a bug
report needs.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import re
import sys
import tempfile
import textwrap
import traceback
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import yaml

# sub-command -> module defining ``configure(parser)`` and ``run(args) -> int``, and its help
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("commands.demo", "the paper's stairs experiment with the reference controller"),
    "passive": ("commands.passive", "passive walking of the classic walker down a slope"),
    "bench": ("commands.bench", "simulator, environment and controller speed"),
    "train": ("commands.train", "train an RL agent from a config"),
    "evaluate": ("commands.evaluate", "evaluate a policy on held-out terrain"),
    "compare": ("commands.compare", "baselines versus RL agents on every terrain, one table"),
    "mfpt": ("commands.mfpt", "mean first-passage time (footsteps to failure) against roughness"),
    "basin": ("commands.basin", "sampled basin of attraction of the reference controller"),
    "sweep": ("commands.sweep", "a grid of policies x envs x held-out courses, with intervals"),
}

ENV_NAMESPACE = "roughwalk/"


def package_version() -> str:
    """The installed version of the ``roughwalk`` package (``unknown`` when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("roughwalk")
    except PackageNotFoundError:
        return "unknown (not installed)"


def plain_text(doc: str) -> str:
    """A docstring as terminal text: reST roles and literals (``x``, :class:`x`) unquoted."""
    doc = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", doc)
    return re.sub(r"``([^`]+)``|`([^`]+)`", lambda m: m.group(1) or m.group(2), doc)


class HelpFormatter(argparse.HelpFormatter):
    """Help for a terminal: descriptions keep their paragraphs and bullets (refilled to the
    width, markup removed), and options show their defaults."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        out = []
        for para in re.split(r"\n\s*\n", plain_text(textwrap.dedent(text)).strip()):
            for item in re.split(r"\n(?=\s*[-*] )", para):
                lead = "- " if re.match(r"\s*[-*] ", item) else ""
                body = " ".join(item.split()[1:] if lead else item.split())
                out.append(
                    textwrap.fill(
                        body,
                        width,
                        initial_indent=indent + lead,
                        subsequent_indent=indent + " " * len(lead),
                        break_on_hyphens=False,
                    )
                )
            out.append("")
        return "\n".join(out).rstrip()

    def _get_help_string(self, action: argparse.Action) -> str:
        help_text = plain_text(action.help or "")
        default = action.default
        if (
            "%(default)" in help_text
            or "default:" in help_text
            or default is None
            or default is False
            or default is argparse.SUPPRESS
            or not (action.option_strings or action.nargs in ("?", "*"))
        ):
            return help_text
        return f"{help_text} (default: %(default)s)"


class ArgumentParser(argparse.ArgumentParser):
    """An argparse parser whose errors are one line ``PROG: error: MESSAGE`` (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        """Print ``message`` as one line on stderr and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def one_line(message: object) -> str:
    """``message`` (an exception or text) on one line; a YAML error as its place and problem."""
    if isinstance(message, yaml.MarkedYAMLError) and message.problem_mark is not None:
        mark = message.problem_mark
        where = "" if mark.name.startswith("<") else f"{mark.name}, "
        return (
            f"invalid YAML ({where}line {mark.line + 1}, column {mark.column + 1}: "
            f"{message.problem})"
        )
    text = " ".join(str(message).split())
    if isinstance(message, BaseException) and not text:
        return type(message).__name__
    return text


# ---------------------------------------------------------------- argument types
def _number(
    kind: type, lo: float | None, hi: float | None, lo_open: bool, hi_open: bool
) -> Callable[[str], Any]:
    """An argparse type: a ``kind`` (int or float) within the given bounds."""
    name = "an integer" if kind is int else "a number"
    if lo is not None and hi is not None:
        allowed = f"{name} in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    elif lo is not None:
        allowed = f"{name} {'>' if lo_open else '>='} {lo}"
    elif hi is not None:
        allowed = f"{name} {'<' if hi_open else '<='} {hi}"
    else:
        allowed = f"a finite {name.split()[-1]}"

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}") from None
        bad = not math.isfinite(value)
        bad = bad or (lo is not None and (value <= lo if lo_open else value < lo))
        bad = bad or (hi is not None and (value >= hi if hi_open else value > hi))
        if bad:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def int_range(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """An argparse ``type=``: an integer in ``[lo, hi]`` (either bound may be None)."""
    return _number(int, lo, hi, False, False)


def float_range(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> Callable[[str], float]:
    """An argparse ``type=``: a finite number between ``lo`` and ``hi`` (closed bounds unless
    ``lo_open``/``hi_open``; either bound may be None)."""
    return _number(float, lo, hi, lo_open, hi_open)


def key_value(text: str) -> tuple[str, Any]:
    """An argparse ``type=``: one ``KEY=VALUE`` setting (the value read as YAML)."""
    from agents.config import parse_assignments

    try:
        ((key, value),) = parse_assignments([text]).items()
    except Exception as exc:  # ConfigError, or YAML's error on a malformed value
        problem = getattr(exc, "problem", None) or " ".join(str(exc).split())
        raise argparse.ArgumentTypeError(
            f"{text!r} is not KEY=VALUE with a YAML value ({problem})"
        ) from None
    return key, value


def preset_config(cls: Any, option: str, pairs: list[tuple[str, Any]] | None, robot: str) -> Any:
    """``cls.for_robot(robot, ...)`` (a controller or planner config class) with the settings of
    an option's ``KEY=VALUE`` pairs over the robot preset's defaults; a bad field or value
    raises ``ValueError`` naming the option."""
    try:
        return cls.for_robot(robot, **dict(pairs or ()))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{option}: {exc}") from None


def env_id(text: str) -> str:
    """An argparse ``type=``: a registered roughwalk env id (``roughwalk/...``)."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the roughwalk ids)

    ours = sorted(k for k in gym.registry if k.startswith(ENV_NAMESPACE))
    if text not in ours:
        what = "not a roughwalk env" if text in gym.registry else "unknown env id"
        raise argparse.ArgumentTypeError(f"{what} {text!r}; allowed: {', '.join(ours)}")
    return text


def check_output_path(path: str | Path, *, directory: bool = False, option: str = "") -> Path:
    """Check, without creating anything, that the file (or, with ``directory``, the folder)
    ``path`` can be written; returns it as a Path. ``option``: the command-line option that
    named it, for the error message.

    Raises:
        ValueError: the path is a folder where a file is wanted (or the reverse), or a parent of
            it is a file, or it cannot be written there (the reason included).
    """
    p = Path(path)
    prefix = f"{option}: " if option else ""
    want = "a folder" if directory else "a file"
    if p.exists():
        if directory != p.is_dir():
            raise ValueError(f"{prefix}{p} is {'a file' if directory else 'a folder'}, not {want}")
        if not os.access(p, os.W_OK):
            raise ValueError(f"{prefix}{p} is not writable")
        if not directory:
            return p
    parent = p if p.is_dir() else p.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{prefix}cannot write {p}: {parent} is a file, not a folder")
    try:  # a real probe: permissions, read-only file systems
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise ValueError(f"{prefix}cannot write {p}: {exc.strerror or exc} in {parent}") from None
    return p


def output_file(text: str) -> Path:
    """An argparse ``type=``: a file path that can be written (nothing is created)."""
    try:
        return check_output_path(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def output_dir(text: str) -> Path:
    """An argparse ``type=``: a folder that exists and is writable or can be created."""
    try:
        return check_output_path(text, directory=True)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_backend_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """``--backend``, ``--address`` and ``--workers``: where ``what`` (``the episodes``, say)
    run (:mod:`agents.sweep.backends`)."""
    from agents.sweep.backends import BACKENDS

    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="serial",
        help=f"where {what} run: this process, or Ray tasks (the sweep extra)",
    )
    parser.add_argument(
        "--address",
        help="Ray: the address of an existing cluster (ray://HOST:10001, HOST:6379 or auto; "
        "default: a local instance)",
    )
    parser.add_argument(
        "--workers",
        type=int_range(1),
        help=f"Ray: CPUs of the local instance, {what} run at once (default: all cores)",
    )


# ---------------------------------------------------------------- numba's first compilation
COMPILING = "compiling the simulator and controller kernels (first run only, about a minute)..."
# modules holding the numba kernels of the simulator and env, and of the controller
SIMULATOR_KERNELS = ("envs.physics.kernel", "envs.batch", "envs.sensors")
CONTROLLER_KERNELS = (
    "controllers.planner.kernel",
    "controllers.riccati",
    "controllers.feedback",
    "controllers.observer",
)


def kernels_need_compiling(modules: Iterable[str]) -> bool:
    """Whether some of the ``modules`` (names) has numba kernels of which none is in numba's
    on-disk cache (a fresh install, or its source changed since): the first call compiles."""
    from numba.core.dispatcher import Dispatcher

    for name in modules:
        module = importlib.import_module(name)
        kernels = [
            obj
            for obj in vars(module).values()
            if isinstance(obj, Dispatcher) and obj.__module__ == name
        ]
        try:
            cached = [bool(k._cache._cache_file._load_index()) for k in kernels]
        except Exception:  # numba's cache internals changed: say nothing
            return False
        if kernels and not any(cached):
            return True
    return False


def announce_compilation(modules: Iterable[str], console: object | None = None) -> bool:
    """Print :data:`COMPILING` once, when :func:`kernels_need_compiling` (``modules``), so that a
    first run does not sit silent; returns whether it printed. ``console``: a rich
    ``Console`` to print to (default: stdout)."""
    if not kernels_need_compiling(modules):
        return False
    if console is None:
        print(COMPILING, flush=True)
    else:
        console.print(COMPILING, markup=False, soft_wrap=True)
    return True


# ---------------------------------------------------------------- parser and entry point
def build_parser(configured: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """Parser listing every sub-command.

    Args:
        configured: the sub-commands whose modules are imported and whose arguments are added
            (default: all); the others are listed with their help only, so that a command
            line imports just the module of the sub-command it runs.
    """
    parser = ArgumentParser(
        prog="roughwalk",
        description="Compass-gait walking over rough terrain: simulation, control and RL.",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"roughwalk {package_version()}")
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of an error (any position)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = set(COMMANDS if configured is None else configured)
    for name, (module, help_text) in COMMANDS.items():
        if name not in chosen:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        mod = importlib.import_module(module)
        p = sub.add_parser(
            name,
            help=help_text,
            description=mod.__doc__ or help_text,
            formatter_class=HelpFormatter,
        )
        mod.configure(p)
        p.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
        )
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
        The exit status: the sub-command's; 0 after ``--help`` or ``--version``; 2 for bad
        input (one line on stderr) or no sub-command; 130 when interrupted.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    name = command_name(argv)
    known = name in COMMANDS
    prog = f"roughwalk {name}" if known else "roughwalk"
    try:
        parser = build_parser([name] if known else [])
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help, --version, or a rejected argument (printed)
            return exc.code if isinstance(exc.code, int) else 2
        if not getattr(args, "_run", None):
            parser.print_help()
            return 2
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, yaml.YAMLError) as exc:
        if "--debug" in argv:
            traceback.print_exc()
        print(f"{prog}: error: {one_line(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
