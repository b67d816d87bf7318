"""A sweep's statistics from its episode records.

Per cell: the success rate with its Wilson interval, the means of footsteps, distance [m] and
speed [m/s] with bootstrap intervals, the cost of transport (total motor work over total
``m g distance``, as ``roughwalk evaluate`` reports it) with a paired bootstrap interval, the
median and 95th percentile of the episodes' ``foot_error_max`` [m] (None for a policy that
does not estimate the stance foot), and the failure reasons counted. Intervals are at 95 %,
seeded: the same records give the same summary.

Across training seeds (when the spec names groups): each group is an agent, each of its
policies one training seed, each env setting a task, the score of a run on a task its success
rate. Per group the IQM with a stratified-bootstrap interval, and for every pair of groups the
probability of improvement (see :mod:`agents.stats`). A policy without a group counts as a
group of one run, so trained agents compare with the baselines.
"""

from __future__ import annotations

import csv
import io
import json
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.runs import atomic_write_text
from agents.stats import (
    CONFIDENCE,
    bootstrap_interval,
    probability_of_improvement,
    stratified_bootstrap,
    wilson_interval,
)
from agents.sweep.spec import Cell
from agents.sweep.store import SUMMARY_CSV, SUMMARY_JSON, SUMMARY_MD

#: metrics averaged per cell: (record field, summary name)
MEANS = (
    ("footsteps", "mean_footsteps"),
    ("distance", "mean_distance"),
    ("speed", "mean_speed"),
)
#: the score of a run on a task in the across-seeds statistics
GROUP_METRIC = "success_rate"


def _ratio(work: np.ndarray, weight_distance: np.ndarray, axis: int = -1) -> np.ndarray:
    """Total work over total ``m g distance`` (vectorised for the bootstrap)."""
    return work.sum(axis=axis) / weight_distance.sum(axis=axis)


def cell_summary(cell: Cell, records: Sequence[dict[str, Any]], seed: int = 0) -> dict[str, Any]:
    """The statistics of one cell from its ``records`` (at least one).

    Args:
        cell: the cell.
        records: its episode records.
        seed: seed of the bootstrap resampling.
    """
    n = len(records)
    if n == 0:
        raise ValueError(f"cell {cell.key}: no episode recorded")
    successes = sum(bool(r["success"]) for r in records)
    out: dict[str, Any] = {
        "cell": cell.key,
        "policy": cell.policy,
        "group": cell.group,
        "env": cell.env,
        "env_id": cell.env_id,
        "env_kwargs": cell.env_kwargs,
        "swept": cell.swept,
        "episodes": n,
        "seeds": [min(r["seed"] for r in records), max(r["seed"] for r in records)],
        "successes": successes,
        "success_rate": successes / n,
        "success_rate_ci": list(wilson_interval(successes, n)),
    }
    for field, name in MEANS:
        values = np.array([float(r[field]) for r in records])
        out[name] = float(values.mean())
        out[f"{name}_ci"] = list(bootstrap_interval(values, seed=seed)) if n > 1 else None
    work = np.array([float(r["motor_work"]) for r in records])
    weight = np.array([float(r["total_mass"]) * float(r["gravity"]) for r in records])
    wd = weight * np.array([max(0.0, float(r["distance"])) for r in records])
    if wd.sum() > 0:
        out["cost_of_transport"] = float(_ratio(work, wd))
        ok = n > 1 and np.count_nonzero(wd) > 1
        out["cost_of_transport_ci"] = (
            list(bootstrap_interval((work, wd), _ratio, paired=True, seed=seed)) if ok else None
        )
    else:
        out["cost_of_transport"] = out["cost_of_transport_ci"] = None
    errors = [r["foot_error_max"] for r in records if r.get("foot_error_max") is not None]
    # the policy's stance-foot estimate: each episode's worst touchdown [m]
    out["foot_error_median"], out["foot_error_p95"] = (
        (float(np.median(errors)), float(np.percentile(errors, 95))) if errors else (None, None)
    )
    out["failure_reasons"] = dict(
        sorted(Counter(r["failure"] for r in records if not r["success"]).items())
    )
    # episodes in which the policy raised an error and went limp (a defect, see EpisodeResult)
    out["policy_errors"] = sum(r.get("policy_error") is not None for r in records)
    return out


def group_scores(cells: Sequence[dict[str, Any]]) -> dict[str, dict[str, list[float]]]:
    """Group -> task (env setting) -> the runs' scores (:data:`GROUP_METRIC`), from cell
    summaries; a policy without a group is a group of its own name."""
    out: dict[str, dict[str, list[float]]] = {}
    for c in cells:
        group = c["group"] or c["policy"]
        task = c["cell"].split("/", 1)[1]
        out.setdefault(group, {}).setdefault(task, []).append(float(c[GROUP_METRIC]))
    return out


def across_seeds(cells: Sequence[dict[str, Any]], seed: int = 0) -> dict[str, Any]:
    """IQM per group and probability of improvement per pair of groups (see the module
    docstring), from cell summaries.

    Args:
        cells: cell summaries (:func:`cell_summary`).
        seed: seed of the bootstrap resampling.
    """
    scores = group_scores(cells)
    groups = []
    for name, tasks in scores.items():
        point, lo, hi = stratified_bootstrap(tasks, seed=seed)
        groups.append(
            {
                "group": name,
                "metric": GROUP_METRIC,
                "tasks": len(tasks),
                "runs": max(len(v) for v in tasks.values()),
                "iqm": point,
                "iqm_ci": [lo, hi],
            }
        )
    pairs = []
    names = list(scores)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if not set(scores[a]) & set(scores[b]):
                continue
            point, lo, hi = probability_of_improvement(scores[a], scores[b], seed=seed)
            pairs.append({"x": a, "y": b, "p_x_better": point, "p_x_better_ci": [lo, hi]})
    return {"metric": GROUP_METRIC, "groups": groups, "improvement": pairs}


def summarize_sweep(
    cells: Sequence[Cell], records: Sequence[dict[str, Any]], seed: int = 0
) -> dict[str, Any]:
    """The summary of a sweep: per cell (in grid order; cells without records left out) and,
    when some policy has a group, across training seeds.

    Args:
        cells: the grid's cells.
        records: the episode records (any order; one per cell and seed).
        seed: seed of the bootstrap resampling.
    """
    by_cell: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        by_cell.setdefault(r["cell"], []).append(r)
    summaries = [
        cell_summary(c, sorted(by_cell[c.key], key=lambda r: r["seed"]), seed)
        for c in cells
        if c.key in by_cell
    ]
    out: dict[str, Any] = {"confidence": CONFIDENCE, "cells": summaries}
    if any(c.group for c in cells) and summaries:
        out["across_seeds"] = across_seeds(summaries, seed)
    return out


CSV_COLUMNS = (
    "cell",
    "policy",
    "group",
    "env",
    "env_id",
    "env_kwargs",
    "swept",
    "episodes",
    "successes",
    "success_rate",
    "mean_footsteps",
    "mean_distance",
    "mean_speed",
    "cost_of_transport",
    "foot_error_median",
    "foot_error_p95",
)


def summary_csv(summary: dict[str, Any]) -> str:
    """The cell summaries as CSV text: one row per cell, each interval as ``_low``/``_high``
    columns after its value, the failure reasons as ``reason count; ...``."""
    header: list[str] = []
    for col in CSV_COLUMNS:
        header.append(col)
        if col == "success_rate" or col.startswith(("mean_", "cost_")):
            header += [f"{col}_low", f"{col}_high"]
    header.append("failure_reasons")
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for c in summary["cells"]:
        row: list[Any] = []
        for col in CSV_COLUMNS:
            value = c.get(col)
            row.append(json.dumps(value, sort_keys=True) if isinstance(value, dict) else value)
            if f"{col}_ci" in c:
                row += list(c[f"{col}_ci"] or ("", ""))
        row.append("; ".join(f"{k} {v}" for k, v in c["failure_reasons"].items()))
        writer.writerow(["" if v is None else v for v in row])
    return buf.getvalue()


def interval_text(value: Any, ci: Any, spec: str, scale: float = 1.0) -> str:
    """``value [low, high]`` formatted with ``spec`` (``-`` for None)."""
    if value is None:
        return "-"
    text = format(scale * value, spec)
    if ci:
        text += f" [{format(scale * ci[0], spec)}, {format(scale * ci[1], spec)}]"
    return text


#: the columns of a cell's row in the summary tables (:func:`cell_row`)
COLUMNS = (
    "policy",
    "env",
    "success [%]",
    "footsteps",
    "distance [m]",
    "speed [m/s]",
    "CoT",
    "failures",
)


def cell_row(c: dict[str, Any]) -> list[str]:
    """The table row of a cell summary ``c`` (intervals in brackets)."""
    swept = ", ".join(f"{k}={v}" for k, v in c["swept"].items())
    return [
        c["policy"],
        c["env"] + (f" ({swept})" if swept else ""),
        f"{interval_text(c['success_rate'], c['success_rate_ci'], '.0f', 100)} "
        f"({c['successes']}/{c['episodes']})",
        interval_text(c["mean_footsteps"], c["mean_footsteps_ci"], ".1f"),
        interval_text(c["mean_distance"], c["mean_distance_ci"], ".2f"),
        interval_text(c["mean_speed"], c["mean_speed_ci"], ".3f"),
        interval_text(c["cost_of_transport"], c["cost_of_transport_ci"], ".3f"),
        ", ".join(f"{k} {v}" for k, v in c["failure_reasons"].items()) or "-",
    ]


def _markdown(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """The lines of a Markdown table."""
    return ["| " + " | ".join(map(str, r)) + " |" for r in (header, ["---"] * len(header), *rows)]


def summary_markdown(summary: dict[str, Any]) -> str:
    """The summary as Markdown: one row per cell, in grid order (:func:`cell_row`: success
    with its Wilson interval, the means and the cost of transport with their bootstrap
    intervals, the failure reasons); then, with groups of training seeds, the IQM per group and
    the probability of improvement per pair of groups."""
    level = round(100 * summary.get("confidence", CONFIDENCE))
    lines = _markdown(COLUMNS, [cell_row(c) for c in summary["cells"]])
    seeds = summary.get("across_seeds")
    if seeds:
        groups = [
            (g["group"], g["tasks"], g["runs"], interval_text(g["iqm"], g["iqm_ci"], ".0f", 100))
            for g in seeds["groups"]
        ]
        header = ("group", "tasks", "runs", f"IQM of the success rate [%] ({level} % interval)")
        lines += ["", *_markdown(header, groups)]
        if seeds["improvement"]:
            pairs = [
                (p["x"], p["y"], interval_text(p["p_x_better"], p["p_x_better_ci"], ".2f"))
                for p in seeds["improvement"]
            ]
            lines += ["", *_markdown(("x", "y", f"P(x better than y) ({level} % interval)"), pairs)]
    return "\n".join(lines) + "\n"


def write_summary(summary: dict[str, Any], out: str | Path) -> tuple[Path, Path, Path]:
    """Write ``summary.json``, ``summary.csv`` and ``summary.md`` in the folder ``out`` (each
    all or nothing); returns their paths."""
    out = Path(out)
    js = atomic_write_text(out / SUMMARY_JSON, json.dumps(summary, indent=2) + "\n")
    cs = atomic_write_text(out / SUMMARY_CSV, summary_csv(summary))
    md = atomic_write_text(out / SUMMARY_MD, summary_markdown(summary))
    return js, cs, md
