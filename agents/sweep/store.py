"""A sweep's results folder: the spec it runs, its episodes as JSON lines, resumable.

- ``spec.json``: the spec the folder holds the results of; a different spec is refused (a
  rerun of the same spec resumes).
- ``episodes.jsonl``: one record per finished episode (see :mod:`agents.sweep.tasks`),
  appended and flushed as episodes finish, in the order they finish. A line cut short by an
  interruption is dropped when the folder is opened again; the episode is then run again.
- ``summary.json``, ``summary.csv``, ``summary.md`` (a Markdown table), ``plots/``: written
  from the records at the end.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any

import numpy as np

from agents.runs import atomic_write_text, check_writable
from agents.sweep.spec import SweepSpec

SPEC_FILE = "spec.json"
EPISODES_FILE = "episodes.jsonl"
SUMMARY_JSON = "summary.json"
SUMMARY_CSV = "summary.csv"
SUMMARY_MD = "summary.md"
PLOTS_DIR = "plots"
OUTPUTS = (SPEC_FILE, EPISODES_FILE, SUMMARY_JSON, SUMMARY_CSV, SUMMARY_MD)


def spec_identity(spec: SweepSpec) -> dict[str, Any]:
    """What makes two specs the same experiment: episodes, seed, policies and envs (not the
    name or description)."""
    data = spec.to_dict()
    return {k: data[k] for k in ("episodes", "seed", "policies", "envs")}


def read_records(path: str | Path, repair: bool = False) -> list[dict[str, Any]]:
    """The records of an ``episodes.jsonl`` file (none when it does not exist).

    Args:
        path: the file.
        repair: cut a last line left unfinished by an interruption off the file (else it is
            only skipped).

    Raises:
        ValueError: a line other than the last is not a record (a damaged file).
    """
    path = Path(path)
    if not path.is_file():
        return []
    raw = path.read_bytes()
    lines = raw.split(b"\n")
    records = []
    good = 0  # bytes of whole, valid lines
    for i, line in enumerate(lines):
        last = i == len(lines) - 1
        if not line.strip():
            good += len(line) + (0 if last else 1)
            continue
        try:
            record = json.loads(line)
            if not isinstance(record, dict) or "cell" not in record or "seed" not in record:
                raise ValueError("not a record")
            if last:  # a line without its newline: cut short while it was written
                raise ValueError("unfinished")
        except ValueError:
            if last:
                break
            raise ValueError(
                f"{path}, line {i + 1}: not an episode record (a damaged file); remove it or "
                "pass --overwrite to start again"
            ) from None
        records.append(record)
        good += len(line) + 1
    if repair and good < len(raw):
        with open(path, "r+b") as fh:
            fh.truncate(good)
    return records


class ResultsFolder:
    """The results folder ``out`` of a sweep of ``spec``.

    Args:
        out: the folder (created when missing).
        spec: the sweep.
        overwrite: start again: remove an earlier sweep's outputs (another spec's included).

    Raises:
        ValueError: the folder cannot be written, holds another spec's results (without
            ``overwrite``), or damaged records.
    """

    def __init__(self, out: str | Path, spec: SweepSpec, overwrite: bool = False) -> None:
        self.out = Path(out)
        self.spec = spec
        if self.out.exists() and not self.out.is_dir():
            raise ValueError(f"--out {self.out}: is a file, not a folder")
        check_writable(self.out, "--out")
        self.episodes_path = self.out / EPISODES_FILE
        spec_path = self.out / SPEC_FILE
        has_results = any((self.out / name).exists() for name in OUTPUTS)
        if has_results and not overwrite:
            stored = None
            if spec_path.is_file():
                try:
                    stored = json.loads(spec_path.read_text())
                except ValueError:
                    stored = None
            if stored != spec_identity(spec):
                raise ValueError(
                    f"--out {self.out}: holds the results of another sweep spec (or of an "
                    "unreadable one); choose another --out, or pass --overwrite to replace them"
                )
        self._overwrite = overwrite and has_results

    def open(self) -> set[tuple[str, int]]:
        """Create the folder (clearing an earlier sweep's outputs under ``overwrite``), record
        the spec, and return the ``(cell key, seed)`` pairs already recorded."""
        self.out.mkdir(parents=True, exist_ok=True)
        if self._overwrite:
            for name in OUTPUTS:
                (self.out / name).unlink(missing_ok=True)
            plots = self.out / PLOTS_DIR
            if plots.is_dir():
                for png in plots.glob("*.png"):
                    png.unlink()
        atomic_write_text(self.out / SPEC_FILE, json.dumps(spec_identity(self.spec), indent=2))
        records = read_records(self.episodes_path, repair=True)
        return {(r["cell"], r["seed"]) for r in records}

    def records(self) -> list[dict[str, Any]]:
        """Every record in the folder."""
        return read_records(self.episodes_path)


def _plain(value: Any) -> Any:
    """JSON for the numpy values a record may hold (arrays, numpy scalars)."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"a record holds a {type(value).__name__}, which JSON cannot store")


class RecordWriter:
    """Appends records to ``episodes.jsonl``, each line flushed to disk as it is written.

    Args:
        path: the file.
    """

    def __init__(self, path: str | Path) -> None:
        self._fh: IO[str] = open(path, "a", encoding="utf-8")  # noqa: SIM115

    def write(self, records: Iterable[dict[str, Any]]) -> None:
        """Append ``records``, one JSON object per line."""
        for r in records:
            self._fh.write(json.dumps(r, default=_plain) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file."""
        self._fh.close()

    def __enter__(self) -> RecordWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
