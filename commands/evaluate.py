"""Evaluate a policy on held-out courses: success, footsteps, distance, speed, cost of transport.

Seed split: training envs are seeded below 1,000,000 (``agents.config.TRAIN_SEED_LIMIT``);
evaluation episode ``k`` resets its env with seed ``1,000,000 + S + k`` (``--seed S``, S >= 0),
so evaluation courses are never the ones a training run starts from. Seeds 1,000,000 to
1,000,999 are the validation courses of the periodic evaluation during training (which selects
``best_model.zip``); ``--seed`` defaults to 1000, past them. The absolute seed of every
episode is recorded in the JSON/CSV output: ``env.reset(seed=...)`` replays it.

Metrics per episode: success (no failure before the episode ended, i.e. the time limit was
reached), footsteps taken (until failure or time limit), distance walked [m], mean speed
[m/s] (distance over episode duration), motor work [J] (absolute, ``int |tau q1dot| dt``), and
cost of transport ``work / (m g distance)`` with ``m`` the robot's total mass. Summary: means
over episodes; the summary cost of transport is total work over total ``m g distance``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from agents.config import TEST_SEED, ConfigError, parse_assignments
from agents.evaluate import Evaluation, evaluate, plot_learning_curve, write_csv, write_json
from agents.policies import BASELINES
from agents.runs import find_manifest
from agents.train import set_threads


def _fmt(value: Any, spec: str) -> str:
    """``value`` formatted with ``spec``, ``-`` for None."""
    return "-" if value is None else format(value, spec)


def summary_row(ev: Evaluation) -> list[str]:
    """The table row of evaluation ``ev``: policy, env, success, footsteps, distance, speed,
    CoT, failures."""
    s = ev.summary
    kw = ",".join(f"{k}={v}" for k, v in ev.env_kwargs.items())
    failures = ", ".join(f"{k} {v}" for k, v in sorted(s["failure_reasons"].items())) or "-"
    return [
        ev.policy
        if ev.policy in BASELINES
        else f"{Path(ev.policy).parent.name}/{Path(ev.policy).stem}",
        ev.env_id.removeprefix("roughwalk/") + (f" ({kw})" if kw else ""),
        f"{100 * s['success_rate']:.0f}% ({s['episodes']})",
        _fmt(s["mean_footsteps"], ".1f"),
        _fmt(s["mean_distance"], ".2f"),
        _fmt(s["mean_speed"], ".3f"),
        _fmt(s["cost_of_transport"], ".3f"),
        failures,
    ]


TABLE_COLUMNS = (
    "policy",
    "env",
    "success",
    "footsteps",
    "distance (m)",
    "speed (m/s)",
    "CoT",
    "failures",
)


def print_table(evaluations: Sequence[Evaluation], title: str | None = None) -> None:
    """Print a rich table with one row per evaluation, under ``title``."""
    table = Table(title=title)
    for i, col in enumerate(TABLE_COLUMNS):
        table.add_column(col, justify="right" if 1 < i < 7 else "left")
    for ev in evaluations:
        table.add_row(*summary_row(ev))
    Console().print(table)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk evaluate`` to ``parser``."""
    parser.add_argument(
        "--policy",
        required=True,
        help=f"one of {', '.join(BASELINES)}, or the path of a trained model (.zip)",
    )
    parser.add_argument("--env", help="env id (default for a trained model: its training env)")
    parser.add_argument(
        "--env-kwargs", nargs="*", metavar="KEY=VALUE", help="env keyword arguments (YAML values)"
    )
    parser.add_argument("--episodes", type=int, default=20, help="number of episodes")
    parser.add_argument(
        "--seed",
        type=int,
        default=TEST_SEED,
        help=f"episode k uses reset seed 1,000,000 + SEED + k (default {TEST_SEED})",
    )
    parser.add_argument("--vecnormalize", help="VecNormalize statistics (default: beside model)")
    parser.add_argument("--json", metavar="FILE", help="write summary and episodes as JSON")
    parser.add_argument("--csv", metavar="FILE", help="write one row per episode as CSV")
    parser.add_argument(
        "--plot-learning-curve",
        nargs="?",
        const="",
        metavar="PNG",
        help="plot the trained model's learning curve (default: learning_curve.png in its run)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """``roughwalk evaluate`` with the parsed ``args``; returns the exit status (2: bad
    arguments)."""
    if args.policy not in BASELINES:
        set_threads(1)
    try:
        kwargs = parse_assignments(args.env_kwargs) if args.env_kwargs else None
        ev = evaluate(
            args.policy,
            args.env,
            episodes=args.episodes,
            seed=args.seed,
            env_kwargs=kwargs,
            vecnormalize=args.vecnormalize,
            progress=not args.no_progress,
        )
    except (ConfigError, ValueError, FileNotFoundError) as exc:
        print(f"roughwalk evaluate: error: {exc}")
        return 2
    seeds = f"{ev.episodes[0].seed}-{ev.episodes[-1].seed}"
    print_table([ev], title=f"{ev.policy} on {ev.env_id}, held-out seeds {seeds}")
    if args.json:
        write_json([ev], args.json)
    if args.csv:
        write_csv([ev], args.csv)
    if args.plot_learning_curve is not None:
        if args.policy in BASELINES:
            print("roughwalk evaluate: error: --plot-learning-curve needs a trained model")
            return 2
        manifest = find_manifest(args.policy)
        run_dir = manifest.parent if manifest else Path(args.policy).parent
        out = args.plot_learning_curve or run_dir / "learning_curve.png"
        print(f"learning curve: {plot_learning_curve(run_dir, out)}")
    return 0
