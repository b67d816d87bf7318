"""Evaluate a policy on held-out courses: success, footsteps, distance, speed, cost of transport.

Seed split: training envs are seeded below 1,000,000. Evaluation episode k resets its env with
seed 1,000,000 + S + k (--seed S), so evaluation courses are never the ones a training run
starts from. Seeds 1,000,000 to 1,000,999 are the validation courses of the periodic
evaluation during training (which selects best_model.zip); --seed defaults to 1000, past them.
The absolute seed of every episode is in the JSON/CSV output: env.reset(seed=...) replays it.

Metrics per episode: success (no failure before the time limit), footsteps taken, distance
walked [m], mean speed [m/s], motor work [J] (absolute) and cost of transport (CoT: work over
m g distance, m the robot's total mass). The table shows means over the episodes; its CoT is
the total work over the total m g distance.

For the reference policy (the transverse controller) the JSON also holds, per episode and
completed footstep, the Lyapunov value V = x_perp' P x_perp at the step's first and last tick,
their ratio, the largest |x_perp| and |u|, and the median and largest ratio and the fraction
below 1 per episode and over all; null for the other policies. --controller-mode fixed-plan
tracks one plan made at the start of each episode (the paper's certified setting); in the
default replan mode every step starts at V = 0 and the ratios certify nothing.

Security: a trained model (.zip) and its VecNormalize statistics (.pkl) are Python pickles;
loading them can run arbitrary code. Evaluate only files you trust. The command loads the
model you name, the statistics beside it (or the --vecnormalize file) and its run's
manifest.json, nothing else.
"""

from __future__ import annotations

import argparse
import io
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from agents.config import TEST_SEED, seed_label
from agents.evaluate import (
    CONTROLLED_BASELINES,
    PERCEPTION_MODES,
    Evaluation,
    evaluate,
    learning_curve_data,
    plot_learning_curve,
    write_csv,
    write_json,
)
from agents.policies import BASELINES
from agents.pretrained import is_pretrained, resolve_model
from agents.runs import find_manifest
from agents.train import set_threads
from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    announce_compilation,
    env_id,
    float_range,
    int_range,
    key_value,
    output_file,
)
from controllers.controller import MODES
from controllers.localisation import ESTIMATES
from controllers.reference import DEFAULT_DROP_EDGE_SD, DROP_EDGE_CAP, MAX_LEG_MARGIN

ALGOS = ("ppo", "sac", "td3", "a2c")


def _fmt(value: Any, spec: str) -> str:
    """``value`` formatted with ``spec``, ``-`` for None."""
    return "-" if value is None else format(value, spec)


def summary_row(ev: Evaluation) -> list[str]:
    """The table row of evaluation ``ev``: policy, env, success, footsteps, distance, speed,
    CoT, failures."""
    s = ev.summary
    kw = ", ".join(f"{k}={v}" for k, v in ev.env_kwargs.items())
    failures = ", ".join(f"{k} {v}" for k, v in sorted(s["failure_reasons"].items())) or "-"
    return [
        ev.policy
        if ev.policy in BASELINES or is_pretrained(ev.policy)
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
    "distance [m]",
    "speed [m/s]",
    "CoT",
    "failures",
)
# the table's headers: the same names, the long ones on two lines
TABLE_HEADERS = tuple(
    {"footsteps": "foot-\nsteps", "distance [m]": "dist.\n[m]"}.get(c, c.replace(" [", "\n["))
    for c in TABLE_COLUMNS
)


def render_table(
    evaluations: Sequence[Evaluation],
    title: str | None = None,
    width: int = 80,
    terminal: bool = True,
) -> str:
    """The summary of ``evaluations`` as text ``width`` columns wide, nothing cut off.

    A table (one row per evaluation) on a ``terminal`` wide enough for it; otherwise, and
    always when not on a terminal (piped, redirected), one block per evaluation:
    ``POLICY on ENV`` and its metrics (named as in :data:`TABLE_COLUMNS`), wrapped to the
    width at spaces.

    Args:
        evaluations: the evaluations, one row each.
        title: the line above them.
        width: the width to fit [characters].
        terminal: whether the text goes to a terminal.
    """
    rows = [summary_row(ev) for ev in evaluations]
    table = Table(
        title=escape(title) if title else None,
        box=box.SIMPLE_HEAD,
        show_edge=False,
        pad_edge=False,
        padding=(0, 1, 0, 0),
    )
    for i, col in enumerate(TABLE_HEADERS):
        table.add_column(escape(col), justify="right" if 1 < i < 7 else "left", no_wrap=True)
    for row in rows:
        table.add_row(*(escape(c) for c in row))
    if terminal:
        buf = io.StringIO()
        Console(file=buf, width=10_000, highlight=False).print(table)
        if max(len(line.rstrip()) for line in buf.getvalue().splitlines()) <= width:
            buf = io.StringIO()
            Console(file=buf, width=width, highlight=False).print(table)
            return buf.getvalue()
    lines = textwrap.wrap(title, width, subsequent_indent="    ") if title else []
    for row in rows:
        lines += textwrap.wrap(f"{row[0]} on {row[1]}", width, subsequent_indent="    ")
        metrics = ", ".join(f"{name} {value}" for name, value in zip(TABLE_COLUMNS[2:], row[2:]))
        lines += textwrap.wrap(metrics, width, initial_indent="  ", subsequent_indent="  ")
    return "\n".join(lines) + "\n"


def print_table(evaluations: Sequence[Evaluation], title: str | None = None) -> None:
    """Print the summary of ``evaluations`` under ``title`` (see :func:`render_table`): a table
    on a terminal wide enough, else one block per evaluation."""
    console = Console()
    terminal = sys.stdout.isatty()
    sys.stdout.write(render_table(evaluations, title, console.width, terminal))


def certificate_line(ev: Evaluation) -> str | None:
    """One line on the Lyapunov ratios of ``ev``'s footsteps (None without any)."""
    s = ev.summary
    if s.get("V_ratio_below_1") is None:
        return None
    n = sum(len(e.certificate or ()) for e in ev.episodes)
    note = " (every step planned afresh: no certificate)" if ev.controller_mode == "replan" else ""
    return (
        f"{ev.controller_mode}: V end/start < 1 on {100 * s['V_ratio_below_1']:.0f}% of {n} "
        f"completed footsteps, median {s['V_ratio_median']:.3g}, largest "
        f"{s['V_ratio_max']:.3g}{note}"
    )


def _algo(text: str) -> str:
    """An argparse ``type=``: an algorithm name."""
    if text.lower() not in ALGOS:
        raise argparse.ArgumentTypeError(f"unknown algorithm {text!r}; allowed: {', '.join(ALGOS)}")
    return text.lower()


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk evaluate`` to ``parser``."""
    parser.add_argument(
        "--policy",
        required=True,
        help=f"one of {', '.join(BASELINES)}, a shipped agent (pretrained:NAME; "
        "`roughwalk evaluate --policy pretrained:` lists them) or the path of a trained model "
        "(.zip; a pickle: load only files you trust)",
    )
    parser.add_argument(
        "--env", type=env_id, help="env id (default for a trained model: its training env)"
    )
    parser.add_argument(
        "--env-kwargs",
        nargs="*",
        type=key_value,
        metavar="KEY=VALUE",
        help="env keyword arguments, values in YAML (default for a trained model: its own)",
    )
    parser.add_argument("--episodes", type=int_range(1), default=20, help="number of episodes")
    parser.add_argument(
        "--seed",
        type=int_range(0),
        default=TEST_SEED,
        help="episode k uses reset seed 1,000,000 + SEED + k",
    )
    parser.add_argument(
        "--vecnormalize",
        metavar="PKL",
        help="the model's VecNormalize statistics (a pickle: load only files you trust; "
        "default: the file saved beside the model)",
    )
    parser.add_argument(
        "--algo",
        type=_algo,
        help=f"the model's algorithm ({', '.join(ALGOS)}; default: from its run or its file), "
        "for a model moved out of its run folder",
    )
    parser.add_argument(
        "--controller-mode",
        choices=MODES,
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' controller: replan every "
        "footstep (their default) or track one plan made at the start of each episode",
    )
    parser.add_argument(
        "--plan-steps",
        type=int_range(2),
        help="footsteps of the fixed plan (--controller-mode fixed-plan only; default: enough "
        "for the episode, 1.5 a second plus the look-ahead)",
    )
    parser.add_argument(
        "--perception",
        choices=PERCEPTION_MODES,
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' perception: the course's map "
        "with a dead-reckoned stance foot (known-map), the stance foot located by the "
        "terrain scan on the map (localise, their default), or a map built from the scans "
        "(mapping)",
    )
    parser.add_argument(
        "--planner",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' gait-planner settings "
        "(PlannerConfig fields over the robot's preset, e.g. end_thetadot_floor=0)",
    )
    parser.add_argument(
        "--controller",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' controller settings "
        "(ControllerConfig fields, e.g. tube_replans=0)",
    )
    parser.add_argument(
        "--observer-eps",
        type=float,
        metavar="S",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' observer time constant [s] "
        "(default 0.04; the paper's: 0.02)",
    )
    parser.add_argument(
        "--identify",
        type=int_range(0),
        metavar="N",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies identify the swing dynamics "
        "online after each of the first N footsteps and switch to the identified model when "
        "the data reject the nominal one (default 6; 0: the nominal model throughout)",
    )
    parser.add_argument(
        "--long-segment",
        type=float_range(0.0, 1.0),
        metavar="S",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies' identification also fits "
        "segments of S seconds, used where none shows a push and the data reject the nominal "
        "model (default 0.3; 0: segments of 0.15 s only, the fits before this default)",
    )
    parser.add_argument(
        "--leg-margin",
        type=float_range(0.0, MAX_LEG_MARGIN),
        metavar="Z",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies widen their foothold margins by "
        "Z standard deviations of the leg-length uncertainty (the localiser's; default 0, off)",
    )
    parser.add_argument(
        "--drop-edge-sd",
        type=float_range(0.0, MAX_LEG_MARGIN),
        metavar="Z",
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies rank footholds near a "
        "step-down riser last while the leg length is uncertain: within Z standard deviations "
        f"of where a step lands, at most {DROP_EDGE_CAP * 100:g} cm; 0: off (default "
        f"{DEFAULT_DROP_EDGE_SD:g} where the policy localises, else 0)",
    )
    parser.add_argument(
        "--foot-estimate",
        choices=ESTIMATES,
        help=f"the {' and '.join(CONTROLLED_BASELINES)} policies correct the stance foot to this "
        "point of the localisation's belief: its mean (default), or the mean given the likelier "
        "of a right and a wrong model (selected)",
    )
    parser.add_argument(
        "--json", type=output_file, metavar="FILE", help="write summary and episodes as JSON"
    )
    parser.add_argument(
        "--csv", type=output_file, metavar="FILE", help="write one row per episode as CSV"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace existing --json/--csv files (else an existing file is an error)",
    )
    parser.add_argument(
        "--plot-learning-curve",
        nargs="?",
        const="",
        metavar="PNG",
        help="plot the trained model's learning curve (default file: learning_curve.png in "
        "its run)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _learning_curve_path(args: argparse.Namespace) -> tuple[Path, Path] | None:
    """``(run folder, PNG)`` of ``--plot-learning-curve``, checked before any episode runs."""
    if args.plot_learning_curve is None:
        return None
    if args.policy in BASELINES:
        raise ValueError("--plot-learning-curve: needs a trained model, not a baseline")
    model = resolve_model(args.policy)
    manifest = find_manifest(model)
    run_dir = manifest.parent if manifest else Path(model).parent
    learning_curve_data(run_dir)
    out = Path(args.plot_learning_curve or run_dir / "learning_curve.png")
    try:
        output_file(str(out))
    except argparse.ArgumentTypeError as exc:
        raise ValueError(f"--plot-learning-curve: {exc}") from None
    return run_dir, out


def run(args: argparse.Namespace) -> int:
    """``roughwalk evaluate`` with the parsed ``args``; returns the exit status (bad input
    raises ``ValueError``/``OSError`` before any episode runs)."""
    trained = args.policy not in BASELINES
    if trained:
        set_threads(1)
        try:
            model = resolve_model(args.policy)
        except ValueError as exc:
            raise ValueError(f"--policy: {exc}") from None
        if not Path(model).is_file():
            raise FileNotFoundError(f"--policy: model file not found: {args.policy}")
    elif args.algo or args.vecnormalize:
        raise ValueError("--algo and --vecnormalize apply to trained models, not to baselines")
    if args.controller_mode is not None and args.policy not in CONTROLLED_BASELINES:
        raise ValueError(
            f"--controller-mode: applies to the {' and '.join(CONTROLLED_BASELINES)} policies, "
            f"not to {args.policy}"
        )
    if args.plan_steps is not None and args.controller_mode != "fixed-plan":
        raise ValueError("--plan-steps: applies to --controller-mode fixed-plan only")
    if args.perception is not None and args.policy not in CONTROLLED_BASELINES:
        raise ValueError(
            f"--perception: applies to the {' and '.join(CONTROLLED_BASELINES)} policies, "
            f"not to {args.policy}"
        )
    for option, path in (("--json", args.json), ("--csv", args.csv)):
        if path is not None and path.exists() and not args.overwrite:
            raise ValueError(
                f"{option} {path}: the file exists (an earlier result); choose another name or "
                "pass --overwrite"
            )
    curve = _learning_curve_path(args)
    kwargs = dict(args.env_kwargs) if args.env_kwargs else None
    announce_compilation(
        SIMULATOR_KERNELS + (CONTROLLER_KERNELS if args.policy != "passive" else ())
    )
    try:
        ev = evaluate(
            args.policy,
            args.env,
            episodes=args.episodes,
            seed=args.seed,
            env_kwargs=kwargs,
            vecnormalize=args.vecnormalize,
            progress=not args.no_progress,
            algo=args.algo,
            controller_mode=args.controller_mode,
            plan_steps=args.plan_steps,
            perception=args.perception,
            planner=dict(args.planner) if args.planner else None,
            controller=dict(args.controller) if args.controller else None,
            observer_eps=args.observer_eps,
            identify=args.identify,
            leg_margin=args.leg_margin,
            drop_edge_sd=args.drop_edge_sd,
            foot_estimate=args.foot_estimate,
            long_segment=args.long_segment,
        )
    except ValueError as exc:
        message = str(exc)
        if trained and "cannot tell the algorithm" in message and "--algo" not in message:
            raise ValueError(f"{exc}; name it with --algo") from exc
        raise
    seeds = seed_label(ev.episodes[0].seed, ev.episodes[-1].seed)
    print_table([ev], title=f"{ev.policy} on {ev.env_id}, {seeds}")
    line = certificate_line(ev)
    if line:
        print(line)
    errors = [e for e in ev.episodes if e.policy_error is not None]
    if errors:
        print(
            f"warning: the policy raised an error and went limp in {len(errors)} of "
            f"{len(ev.episodes)} episodes (seed {errors[0].seed}: {errors[0].policy_error})"
        )
    if args.json:
        write_json([ev], args.json)
    if args.csv:
        write_csv([ev], args.csv)
    if curve is not None:
        print(f"learning curve: {plot_learning_curve(*curve)}")
    return 0
