"""Run a sweep: every policy of a spec on every env setting it names, on the same held-out
courses, in this process or as Ray tasks; summarised with 95 % intervals.

The spec (YAML, see configs/sweeps/) lists policies (passive, pd, reference, a trained model
file or run folder), envs (an id, keyword arguments, and keyword arguments swept over lists of
values), the number of courses per cell and the seed: episode k of every cell resets with seed
1,000,000 + seed + k, as roughwalk evaluate --seed does. The whole spec is checked (every env
and every policy on it built once) before any episode runs.

Episodes are appended to OUT/episodes.jsonl as they finish (one JSON object each). Run the same
command again after an interruption: finished episodes are kept and only the others run. A
different spec in the same --out is refused unless --overwrite. At the end OUT/summary.json,
OUT/summary.csv and OUT/summary.md (a Markdown table) hold per cell the success rate with its
Wilson interval, the mean footsteps, distance, speed and the cost of transport with bootstrap
intervals, the median and 95th percentile of the episodes' largest stance-foot estimate errors
(policies that estimate the foot), and the failure reasons; with groups of training seeds in
the spec, the IQM of each group's success rates with a stratified-bootstrap interval and the
probability of improvement between groups. OUT/plots/ holds the success rate against each swept
numeric argument.

--backend ray runs tasks (a cell's run of up to 10 seeds) on a local Ray instance with --workers
CPUs, or on the cluster at --address (its nodes need this package installed); it needs the
sweep extra (pip install -e ".[sweep]"). The records are the same whatever the backend.

Security: trained models are Python pickles; loading one can run arbitrary code. Sweep only
models you trust.
"""

from __future__ import annotations

import argparse
import io
import sys
import textwrap
from pathlib import Path
from typing import Any

from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from agents.config import seed_label
from agents.sweep import load_spec, run_sweep
from agents.sweep.aggregate import COLUMNS, cell_row, interval_text
from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    add_backend_arguments,
    announce_compilation,
    int_range,
    output_dir,
)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk sweep`` to ``parser``."""
    parser.add_argument("spec", type=Path, metavar="SPEC.yaml", help="the sweep spec")
    parser.add_argument("--out", type=output_dir, required=True, help="results folder")
    add_backend_arguments(parser, "the episodes")
    parser.add_argument(
        "--chunk",
        type=int_range(1),
        help="episodes per task (default: serial one task per cell, Ray up to 10); the "
        "results do not depend on it",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="start again: remove the results in --out (without it the same spec resumes and "
        "another spec is an error)",
    )
    parser.add_argument("--no-plot", action="store_true", help="write no plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _pack(items: list[str], width: int, indent: str) -> list[str]:
    """``items`` joined by commas into lines of at most ``width`` characters, an item broken
    across lines only when it is longer than a line."""
    lines: list[str] = []
    line = ""
    for i, item in enumerate(items):
        item += "," if i < len(items) - 1 else ""
        if line and len(line) + 1 + len(item) > width:
            lines.append(line)
            line = ""
        if not line and len(indent) + len(item) > width:
            lines += textwrap.wrap(item, width, initial_indent=indent, subsequent_indent=indent)
            continue
        line = f"{line} {item}" if line else indent + item
    return lines + ([line] if line else [])


def render_summary(summary: dict[str, Any], width: int = 100, terminal: bool = True) -> str:
    """The summary as text ``width`` columns wide, nothing cut off: the cells (values with their
    95 % intervals in brackets) and, with groups of training seeds, their IQM and the
    probabilities of improvement.

    The cells are a table on a ``terminal`` wide enough for it; otherwise, and always when not
    on a terminal (piped, redirected), one block per cell: ``POLICY on ENV`` and its metrics
    (named as in :data:`COLUMNS`), wrapped at spaces.

    Args:
        summary: what ``summary.json`` holds.
        width: the width to fit [characters].
        terminal: whether the text goes to a terminal.
    """
    seeds = summary.get("seeds")
    title = f"{summary.get('name', 'sweep')}: 95 % intervals"
    if seeds:
        title += f", {seed_label(seeds[0], seeds[1])}"
    rows = [cell_row(c) for c in summary["cells"]]
    lines: list[str] = []
    text = ""
    if terminal:
        table = Table(title=escape(title), box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
        for i, col in enumerate(COLUMNS):
            table.add_column(escape(col), justify="right" if 1 < i < 7 else "left", no_wrap=True)
        for row in rows:
            table.add_row(*(escape(x) for x in row))
        buf = io.StringIO()
        Console(file=buf, width=10_000, highlight=False).print(table)
        if max(len(line.rstrip()) for line in buf.getvalue().splitlines()) <= width:
            text = "\n".join(line.rstrip() for line in buf.getvalue().splitlines()) + "\n"
    if not text:
        lines = textwrap.wrap(title, width, subsequent_indent="    ")
        for row in rows:
            lines += textwrap.wrap(f"{row[0]} on {row[1]}", width, subsequent_indent="    ")
            lines += _pack([f"{n} {v}" for n, v in zip(COLUMNS[2:], row[2:])], width, "  ")
        text = "\n".join(lines) + "\n"
    seeds_part = summary.get("across_seeds")
    if seeds_part:
        lines = ["across training seeds, success rate [%]: IQM over runs and envs [95 % CI]"]
        for g in seeds_part["groups"]:
            lines.append(
                f"  {g['group']}: {interval_text(g['iqm'], g['iqm_ci'], '.0f', 100)} "
                f"({g['runs']} runs, {g['tasks']} envs)"
            )
        for p in seeds_part["improvement"]:
            lines.append(
                f"  P({p['x']} > {p['y']}) = "
                f"{interval_text(p['p_x_better'], p['p_x_better_ci'], '.2f')}"
            )
        text += "\n".join(textwrap.fill(x, width, subsequent_indent="    ") for x in lines) + "\n"
    return text


def run(args: argparse.Namespace) -> int:
    """``roughwalk sweep`` with the parsed ``args``; returns the exit status (bad input raises
    ``ValueError``/``OSError`` before any episode runs)."""
    spec = load_spec(args.spec)
    policies = {c.policy_spec for c in spec.cells()}
    announce_compilation(SIMULATOR_KERNELS + (CONTROLLER_KERNELS if policies - {"passive"} else ()))
    result = run_sweep(
        spec,
        args.out,
        backend=args.backend,
        workers=args.workers,
        address=args.address,
        chunk=args.chunk,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        plot=not args.no_plot,
    )
    sys.stdout.write(render_summary(result.summary, Console().width, sys.stdout.isatty()))
    done = f"{result.ran} episodes run in {result.seconds:.1f} s"
    if result.skipped:
        done += f", {result.skipped} already recorded"
    print(f"{done}; results in {result.out}")
    for path in result.plots:
        print(f"plot: {path}")
    return 0
