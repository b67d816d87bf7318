"""Evaluation sweeps: a grid of policies x environments (and their swept keyword arguments) x
held-out course seeds, run in this process or as Ray tasks, streamed to a resumable results
folder, summarised with interval estimates.

- :mod:`agents.sweep.spec`: the spec (YAML) and its checks;
- :mod:`agents.sweep.tasks`: tasks (a cell's run of seeds) and per-episode records;
- :mod:`agents.sweep.backends`: the serial and Ray backends;
- :mod:`agents.sweep.store`: the results folder (``episodes.jsonl``, resumable);
- :mod:`agents.sweep.aggregate`: per-cell and across-training-seed statistics;
- :mod:`agents.sweep.plots`: success rate against a swept argument.

Ray is optional (``pip install -e ".[sweep]"``); the serial backend needs none.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.runs import claim_output_folder
from agents.sweep.aggregate import summarize_sweep, write_summary
from agents.sweep.backends import BACKENDS, import_ray, run_tasks
from agents.sweep.plots import plot_sweep
from agents.sweep.spec import (
    Cell,
    EnvEntry,
    PolicyEntry,
    SpecError,
    SweepSpec,
    check_spec,
    load_spec,
    resolve_policy,
    spec_from_dict,
)
from agents.sweep.store import PLOTS_DIR, RecordWriter, ResultsFolder, read_records
from agents.sweep.tasks import Task, chunk_size, make_tasks, run_task

__all__ = [
    "BACKENDS",
    "Cell",
    "EnvEntry",
    "PolicyEntry",
    "SpecError",
    "SweepResult",
    "SweepSpec",
    "Task",
    "check_spec",
    "chunk_size",
    "load_spec",
    "make_tasks",
    "read_records",
    "resolve_policy",
    "run_sweep",
    "run_task",
    "spec_from_dict",
    "summarize_sweep",
]


@dataclass
class SweepResult:
    """What :func:`run_sweep` did.

    Attributes:
        out: the results folder.
        summary: the summary written to ``summary.json``.
        ran: episodes run by this call.
        skipped: episodes found already recorded (a resumed sweep).
        seconds: wall-clock time of the episodes [s].
        plots: the figures written.
    """

    out: Path
    summary: dict[str, Any]
    ran: int
    skipped: int
    seconds: float
    plots: list[Path] = field(default_factory=list)


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    *,
    backend: str = "serial",
    workers: int | None = None,
    address: str | None = None,
    chunk: int | None = None,
    overwrite: bool = False,
    progress: bool = False,
    plot: bool = True,
) -> SweepResult:
    """Run the sweep ``spec`` into the folder ``out``, or resume it there.

    Everything is checked first (the folder, the backend, every env and policy of the grid);
    then the episodes not yet recorded in ``out/episodes.jsonl`` run and are appended as they
    finish; then ``summary.json``, ``summary.csv`` and the plots are written from all records.

    Args:
        spec: the sweep.
        out: the results folder.
        backend: ``serial`` (this process) or ``ray``.
        workers: Ray: CPUs of a local instance (default: all cores), >= 1.
        address: Ray: a cluster's address (default: a local instance).
        chunk: episodes per task (default: :func:`agents.sweep.tasks.chunk_size`); the records
            do not depend on it.
        overwrite: start again, removing the results in ``out`` (without it the same spec
            resumes and another spec is an error).
        progress: show a progress bar.
        plot: write the success plots of swept numeric arguments to ``out/plots/``.

    Raises:
        ValueError: a bad spec, folder or option, or Ray missing for ``backend="ray"``.
    """
    if backend not in BACKENDS:
        raise ValueError(f"--backend: unknown backend {backend!r}; allowed: {', '.join(BACKENDS)}")
    for name, value in (("--workers", workers), ("--chunk", chunk)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise ValueError(f"{name}: must be an integer >= 1, got {value!r}")
        if value is not None and value < 1:
            raise ValueError(f"{name}: must be an integer >= 1, got {value}")
    if backend == "serial" and (workers is not None or address is not None):
        raise ValueError("--workers and --address apply to --backend ray")
    if address is not None and workers is not None:
        raise ValueError("--workers applies to a local Ray instance, not to a cluster (--address)")
    if backend == "ray":
        import_ray()
    with claim_output_folder(out, what="sweep"):
        folder = ResultsFolder(out, spec, overwrite)
        check_spec(spec)
        return _run(folder, spec, backend, workers, address, chunk, progress, plot)


def _run(
    folder: ResultsFolder,
    spec: SweepSpec,
    backend: str,
    workers: int | None,
    address: str | None,
    chunk: int | None,
    progress: bool,
    plot: bool,
) -> SweepResult:
    """The body of :func:`run_sweep`, in a folder it holds."""
    done = folder.open()
    cells, seeds = spec.cells(), spec.seeds
    todo = len(cells) * len(seeds) - len(done)
    if chunk is None:
        chunk = len(seeds) if backend == "serial" else chunk_size(todo, workers or os.cpu_count())
    tasks = make_tasks(cells, seeds, done, chunk)
    ran = 0
    start = time.perf_counter()
    with RecordWriter(folder.episodes_path) as writer, _progress(progress, todo) as advance:

        def on_records(records: list[dict[str, Any]]) -> None:
            nonlocal ran
            writer.write(records)
            ran += len(records)
            advance(len(records))

        run_tasks(tasks, on_records, backend, workers, address)
    seconds = time.perf_counter() - start
    summary = {"name": spec.name, "description": spec.description, "episodes": spec.episodes}
    summary |= {"seeds": [seeds[0], seeds[-1]]}
    summary |= summarize_sweep(cells, folder.records())
    write_summary(summary, folder.out)
    plots = plot_sweep(summary["cells"], folder.out / PLOTS_DIR) if plot else []
    return SweepResult(folder.out, summary, ran, len(cells) * len(seeds) - todo, seconds, plots)


class _progress:
    """A rich progress bar over ``total`` episodes (nothing when not ``show``); the context
    value is ``advance(n)``."""

    def __init__(self, show: bool, total: int) -> None:
        self._bar: Any = None
        self._task: Any = None
        if show and total > 0:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._bar = Progress(
                TextColumn("episodes"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
            )
            self._task = self._bar.add_task("sweep", total=total)

    def __enter__(self) -> Any:
        if self._bar is None:
            return lambda n: None
        self._bar.start()
        return lambda n: self._bar.advance(self._task, n)

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.stop()
