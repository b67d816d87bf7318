"""Mean first-passage time (MFPT): footsteps to failure against terrain roughness.

Each walk is a long course of random blocks (widths 0.1-0.3 m; at every block border the
height changes by a step uniform in [-R, R], R the roughness) walked by the policy on the
native vector env with its sensors, until the walker fails or the walk is censored: at the
footstep cap (--step-cap), near the course's end, or at the time limit (--max-step-time s per
capped footstep). Walk k resets its sub-env with seed --seed + k, whatever --walkers is.

The MFPT is estimated for a memoryless failure process (a footstep fails with the same
probability p whatever came before): p = failures / footsteps attempted, MFPT = 1/p footsteps,
with the exact (Clopper-Pearson) interval of p inverted. Levels where no walk failed give only
a lower bound (shown as >=). The geometric column is the p-value of a likelihood-ratio test of
that assumption against a failure probability that changes with the footstep number (small:
the assumption does not fit; the JSON has the Kaplan-Meier survival curve of every level).
The chain column is the Markov-chain estimate (Byl and Tedrake 2009): the walks' post-impact
stance-leg states binned on a mesh (6 quantile bins of theta x 3 of theta_dot), their
footsteps counted as transitions between the cells and into failure, MFPT = 1 / (1 -
lambda_2), with a bootstrap interval over walks.

Writes OUT/mfpt.json (every walk, the Kaplan-Meier curves, the checks), OUT/mfpt.csv (one row
per policy and level), OUT/mfpt.png (MFPT against roughness on a log axis) and
OUT/mfpt_survival.png (the Kaplan-Meier survival of every level against the geometric model's
(1 - p)^k); an existing result in OUT stops the command before any walk unless --overwrite.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from agents.mfpt import (
    CENSORED,
    DEFAULT_ENV,
    MFPTResult,
    check_run_args,
    kaplan_meier,
    mfpt_sweep,
    policy_options,
)
from agents.policies import BASELINES
from agents.runs import atomic_write, atomic_write_stream, claim_output_folder
from agents.sweep.aggregate import interval_text
from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    announce_compilation,
    env_id,
    float_range,
    int_range,
    key_value,
    output_dir,
)
from controllers.reference import DEFAULT_DROP_EDGE_SD, DROP_EDGE_CAP, MAX_LEG_MARGIN

OUTPUTS = ("mfpt.json", "mfpt.csv", "mfpt.png", "mfpt_survival.png")
CSV_COLUMNS = (
    "policy",
    "roughness_m",
    "roughness_per_leg",
    "walks",
    "failures",
    "footsteps_attempted",
    "p_fail",
    "p_low",
    "p_high",
    "mfpt",
    "mfpt_low",
    "mfpt_high",
    *(f"censored_{e}" for e in CENSORED),
    "geometric_p_value",
    "markov_mfpt",
    "markov_mfpt_low",
    "markov_mfpt_high",
    "wall_time_s",
)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk mfpt`` to ``parser``."""
    parser.add_argument(
        "--policy", nargs="+", choices=BASELINES, default=["reference"], help="policies"
    )
    parser.add_argument(
        "--roughness",
        nargs="+",
        type=float_range(0, 0.2),
        default=[0.0, 0.01, 0.02],
        metavar="R",
        help="roughness levels: half-width of the block height steps [m], in increasing order",
    )
    parser.add_argument("--walks", type=int_range(1, 100_000), default=16, help="walks per level")
    parser.add_argument(
        "--walkers", type=int_range(1, 4096), default=8, help="walks at a time (sub-envs)"
    )
    parser.add_argument(
        "--step-cap", type=int_range(1, 10_000), default=100, help="footsteps per walk at most"
    )
    parser.add_argument("--seed", type=int_range(0, 2**31 - 1), default=0, help="seed of walk 0")
    parser.add_argument("--env", type=env_id, default=DEFAULT_ENV, help="robot and sensors")
    parser.add_argument(
        "--max-step-time",
        type=float_range(0, 60, lo_open=True),
        default=4.0,
        help="time limit per capped footstep [s]",
    )
    parser.add_argument(
        "--confidence",
        type=float_range(0, 1, lo_open=True, hi_open=True),
        default=0.95,
        help="confidence level of the intervals",
    )
    parser.add_argument(
        "--stop-below",
        type=float_range(0, lo_open=True),
        default=10.0,
        help="stop a policy's sweep after the first level with MFPT below this [footsteps]",
    )
    parser.add_argument(
        "--controller",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="the pd and reference policies' controller settings (ControllerConfig fields, "
        "e.g. Q=[1,1,1] for the paper's weights)",
    )
    parser.add_argument(
        "--planner",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="the pd and reference policies' gait-planner settings (PlannerConfig fields over "
        "the robot's preset, e.g. clearance=0.003)",
    )
    parser.add_argument(
        "--long-segment",
        type=float_range(0.0, 1.0),
        metavar="S",
        help="the pd and reference policies' identification also fits segments of S seconds, "
        "used where none shows a push and the data reject the nominal model (default 0.3; 0: "
        "segments of 0.15 s only, the fits before this default)",
    )
    parser.add_argument(
        "--drop-edge-sd",
        type=float_range(0.0, MAX_LEG_MARGIN),
        metavar="Z",
        help="the pd and reference policies rank footholds near a step-down riser last while "
        "the leg length is uncertain: within Z standard deviations of where a step lands, at "
        f"most {DROP_EDGE_CAP * 100:g} cm; 0: off (default {DEFAULT_DROP_EDGE_SD:g} where the "
        "policy localises, else 0)",
    )
    parser.add_argument(
        "--out", type=output_dir, default=Path("results/mfpt"), help="folder of the results"
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an earlier result in --out"
    )


def _row(res: MFPTResult) -> dict[str, Any]:
    est = res.estimate
    ends = [w.end for w in res.walks]
    return {
        "policy": res.policy,
        "roughness_m": res.roughness,
        "roughness_per_leg": res.roughness_per_leg,
        "walks": est.walks,
        "failures": est.failures,
        "footsteps_attempted": est.exposure,
        "p_fail": est.p_fail,
        "p_low": est.p_interval[0],
        "p_high": est.p_interval[1],
        "mfpt": est.mfpt,
        "mfpt_low": est.mfpt_interval[0],
        "mfpt_high": est.mfpt_interval[1] if math.isfinite(est.mfpt_interval[1]) else None,
        **{f"censored_{e}": ends.count(e) for e in CENSORED},
        "geometric_p_value": res.geometric["p_value"],
        **_markov_columns(res),
        "wall_time_s": res.wall_time,
    }


def _markov_columns(res: MFPTResult) -> dict[str, Any]:
    if res.markov is None:
        return {"markov_mfpt": None, "markov_mfpt_low": None, "markov_mfpt_high": None}
    m = res.markov.to_dict()  # (an infinite upper limit as None)
    lo, hi = m["mfpt_interval"]
    return {"markov_mfpt": m["mfpt"], "markov_mfpt_low": lo, "markov_mfpt_high": hi}


def format_row(res: MFPTResult) -> str:
    """One printed line for a level: roughness, MFPT with its interval, failures, walls."""
    est = res.estimate
    lo, hi = est.mfpt_interval
    pct = round(100 * est.confidence)
    if est.mfpt is None:
        mfpt = f">= {lo:.1f} (no failure; {pct} % lower bound)"
    else:
        mfpt = interval_text(est.mfpt, (lo, hi), ".1f")
    gp = res.geometric["p_value"]
    m = res.markov
    chain = "-" if m is None else interval_text(m.mfpt, m.mfpt_interval, ".1f")
    return (
        f"{res.policy:9s} R = {res.roughness * 1000:6.2f} mm ({res.roughness_per_leg:6.2%} of l): "
        f"MFPT {mfpt} footsteps; {est.failures}/{est.walks} walks failed in {est.exposure} "
        f"footsteps; geometric p = {'-' if gp is None else f'{gp:.2f}'}; chain {chain}; "
        f"{res.wall_time:.0f} s"
    )


def plot_mfpt(results: list[MFPTResult], path: Path, leg: float) -> None:
    """MFPT against roughness, log MFPT axis, one curve per policy with interval bars; levels
    with no failure as lower-bound triangles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, policy in enumerate(dict.fromkeys(r.policy for r in results)):
        color = f"C{k}"
        rs = [r for r in results if r.policy == policy]
        est = [r for r in rs if r.estimate.mfpt is not None]
        x = [1000 * r.roughness for r in est]
        y = [r.estimate.mfpt for r in est]
        lo = [r.estimate.mfpt - r.estimate.mfpt_interval[0] for r in est]
        hi = [min(r.estimate.mfpt_interval[1], 1e9) - r.estimate.mfpt for r in est]
        ax.errorbar(x, y, yerr=[lo, hi], marker="o", color=color, capsize=3, label=policy)
        cens = [r for r in rs if r.estimate.mfpt is None]
        if cens:
            ax.plot(
                [1000 * r.roughness for r in cens],
                [r.estimate.lower_bound for r in cens],
                "^",
                color=color,
                markersize=9,
                label=f"{policy}: no failure (lower bound)",
            )
    ax.set_yscale("log")
    ax.set_xlabel("roughness: block height steps within +-R [mm]")
    pct = round(100 * results[0].estimate.confidence)
    ax.set_ylabel(f"MFPT [footsteps], {pct} % intervals")
    ax.grid(True, which="both", alpha=0.3)
    sec = ax.secondary_xaxis("top", functions=(lambda r: r / (10 * leg), lambda f: f * 10 * leg))
    sec.set_xlabel("R [% of leg length]")
    ax.legend(fontsize=8)
    save_figure(fig, path)


def plot_survival(results: list[MFPTResult], path: Path) -> None:
    """Kaplan-Meier survival per level (steps) against the geometric model (dashed), one
    panel per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    policies = list(dict.fromkeys(r.policy for r in results))
    fig, axes = plt.subplots(
        1, len(policies), figsize=(4.8 * len(policies), 3.8), squeeze=False, sharey=True
    )
    for ax, policy in zip(axes[0], policies):
        for k, r in enumerate(x for x in results if x.policy == policy):
            km = kaplan_meier([w.footsteps for w in r.walks], [w.failed for w in r.walks])
            steps = np.concatenate(([0], km["step"]))
            surv = np.concatenate(([1.0], km["survival"]))
            label = f"R = {1000 * r.roughness:g} mm"
            ax.step(steps, np.maximum(surv, 1e-3), where="post", color=f"C{k}", label=label)
            ax.plot(steps, (1 - r.estimate.p_fail) ** steps, "--", color=f"C{k}", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylim(1e-3 * 0.8, 1.2)
        ax.set_xlabel("footsteps")
        ax.set_title(f"{policy}: Kaplan-Meier (steps), geometric (dashed)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("survival")
    save_figure(fig, path)


def save_figure(fig: Any, path: Path) -> None:
    """Save the matplotlib ``fig`` as ``path`` (PNG, via a temporary file: no partial file
    is left) and close it."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.tight_layout()
        atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))
    finally:
        plt.close(fig)


def run(args: argparse.Namespace) -> int:
    """``roughwalk mfpt`` with the parsed ``args``; returns the exit status (bad input raises
    ``ValueError`` before any walk)."""
    levels = list(args.roughness)
    if any(b <= a for a, b in zip(levels, levels[1:])):
        raise ValueError(f"--roughness: levels must increase, got {levels}")
    policies = list(dict.fromkeys(args.policy))
    check_run_args(
        policies[0], args.walks, args.walkers, args.step_cap, args.seed, args.max_step_time
    )
    controller = dict(args.controller or ())
    planner = dict(args.planner or ())
    for policy in [p for p in policies if p != "passive"] or policies:
        # a bad one stops here
        policy_options(policy, controller, planner, args.long_segment, args.drop_edge_sd)
    out: Path = args.out
    with claim_output_folder(out, OUTPUTS, args.overwrite):
        return _measure(args, out, levels, policies, controller, planner)


def _measure(
    args: argparse.Namespace,
    out: Path,
    levels: list[float],
    policies: list[str],
    controller: dict[str, Any],
    planner: dict[str, Any],
) -> int:
    """``roughwalk mfpt``'s walks and outputs, in the folder ``out`` it holds (``controller``,
    ``planner``: the pd and reference policies' ControllerConfig and PlannerConfig fields)."""
    announce_compilation(
        SIMULATOR_KERNELS + (CONTROLLER_KERNELS if policies != ["passive"] else ())
    )
    results: list[MFPTResult] = []
    for policy in policies:
        results += mfpt_sweep(
            policy,
            levels,
            args.walks,
            confidence=args.confidence,
            stop_below=args.stop_below,
            on_result=lambda r: print(format_row(r), flush=True),
            walkers=args.walkers,
            step_cap=args.step_cap,
            seed=args.seed,
            env_id=args.env,
            max_step_time=args.max_step_time,
            controller=controller if policy != "passive" else None,
            planner=planner if policy != "passive" else None,
            long_segment=args.long_segment if policy != "passive" else None,
            drop_edge_sd=args.drop_edge_sd if policy != "passive" else None,
        )
    leg = results[0].leg_length
    settings = {
        "env": args.env,
        "walks": args.walks,
        "walkers": args.walkers,
        "step_cap": args.step_cap,
        "seed": args.seed,
        "max_step_time": args.max_step_time,
        "confidence": args.confidence,
        "controller": controller,
        "planner": planner,
        "long_segment": args.long_segment,
        "drop_edge_sd": args.drop_edge_sd,
        "leg_length": leg,
        "mfpt": "1/p footsteps (the failing one counted); p = failures / footsteps attempted",
    }
    text = json.dumps({"settings": settings, "levels": [r.to_dict() for r in results]}, indent=1)
    atomic_write_stream(out / "mfpt.json", lambda fh: fh.write(text + "\n"))

    def write_csv(fh: Any) -> None:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for r in results:
            writer.writerow(_row(r))

    atomic_write_stream(out / "mfpt.csv", write_csv)
    plot_mfpt(results, out / "mfpt.png", leg)
    plot_survival(results, out / "mfpt_survival.png")
    print(f"wrote {out}/mfpt.json, mfpt.csv, mfpt.png and mfpt_survival.png")
    return 0
