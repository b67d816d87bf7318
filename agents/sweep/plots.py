"""Figures of a sweep: success rate against a swept env keyword argument (difficulty,
``robot_error``, a push's size, sensor noise, ...), with the Wilson 95 % interval as a band,
one curve per policy (and per value of the env's other swept arguments)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def _number(value: Any) -> float | None:
    """``value`` as a float when it is a plain number, else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def success_curves(
    cells: Sequence[dict[str, Any]], env: str, param: str
) -> dict[str, list[tuple[float, float, float, float]]]:
    """Curve label -> points ``(x, success, low, high)`` sorted by ``x``: the cells of ``env``
    by the numeric swept value ``param`` (cells with a non-numeric value left out).

    Args:
        cells: cell summaries (``agents.sweep.aggregate.cell_summary``).
        env: the env's name.
        param: the swept keyword argument.
    """
    curves: dict[str, list[tuple[float, float, float, float]]] = {}
    for c in cells:
        if c["env"] != env or param not in c["swept"]:
            continue
        x = _number(c["swept"][param])
        if x is None:
            continue
        others = ", ".join(f"{k}={v}" for k, v in c["swept"].items() if k != param)
        label = c["policy"] + (f" ({others})" if others else "")
        lo, hi = c["success_rate_ci"]
        curves.setdefault(label, []).append((x, c["success_rate"], lo, hi))
    return {k: sorted(v) for k, v in curves.items()}


def plot_success(
    cells: Sequence[dict[str, Any]], env: str, param: str, out: str | Path, title: str = ""
) -> Path | None:
    """Plot success rate [%] against the swept ``param`` of ``env``, a Wilson band around
    each curve; writes the PNG ``out`` and returns it (None when no cell has a numeric value
    of ``param``).

    Args:
        cells: cell summaries.
        env: the env's name.
        param: the swept keyword argument (the x axis).
        out: the PNG file.
        title: the figure's title.
    """
    from matplotlib.figure import Figure

    curves = success_curves(cells, env, param)
    if not curves:
        return None
    fig = Figure(figsize=(6.4, 4.2), layout="constrained")
    ax = fig.subplots()
    for label, points in curves.items():
        x, y, lo, hi = (list(v) for v in zip(*points))
        (line,) = ax.plot(x, [100 * v for v in y], "o-", ms=4, label=label)
        ax.fill_between(
            x, [100 * v for v in lo], [100 * v for v in hi], color=line.get_color(), alpha=0.2
        )
    n = {c["episodes"] for c in cells if c["env"] == env}
    count = f"{min(n)}-{max(n)}" if len(n) > 1 else f"{n.pop()}"
    ax.set_xlabel(param)
    ax.set_ylabel("success [%] (95 % Wilson band)")
    ax.set_ylim(-2, 102)
    ax.set_title(title or f"{env}: {count} held-out courses per point")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out


def plot_sweep(cells: Sequence[dict[str, Any]], folder: str | Path) -> list[Path]:
    """One success-rate plot per env and numeric swept keyword argument, written to
    ``folder/success_<env>_<param>.png``; returns the files written.

    Args:
        cells: cell summaries.
        folder: the folder of the figures.
    """
    pairs: dict[tuple[str, str], None] = {}
    for c in cells:
        for param, value in c["swept"].items():
            if _number(value) is not None:
                pairs[(c["env"], param)] = None
    written = []
    for env, param in pairs:
        path = Path(folder) / f"success_{_slug(env)}_{_slug(param)}.png"
        if plot_success(cells, env, param, path) is not None:
            written.append(path)
    return written
