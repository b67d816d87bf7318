"""Passive walking down a slope: the walker starts near its limit cycle and (if the cycle is
stable) converges to it, with no motor at all.

Finds the passive limit cycle for the robot and slope (Newton on the step-to-step map,
starting from the classic walker's cycle on a 0.0525 rad slope), starts the walker from a
seeded random perturbation of it, and prints one row per step: time, step length, stance-leg
rate just after the impact, and the distance to the cycle.

The classic walker has a cycle on slopes of about 0.01 to 0.15 rad (stable from 0.02 to
0.07 rad), the paper's robot on about 0.05 to 0.2 rad (stable up to 0.1 rad). Starts
perturbed by more than about 0.1 may fall before they converge.
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from commands.cli import SIMULATOR_KERNELS, announce_compilation, float_range, int_range
from envs import RobotParams, SimConfig, Terrain, simulate
from envs.physics import available_presets
from envs.physics.passive import CLASSIC_CYCLE, passive_limit_cycle, slope_section_state

MAX_SLOPE = 0.25  # [rad]
MAX_PERTURB = 0.2  # [rad, rad/s]


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk passive`` to ``parser``."""
    parser.add_argument(
        "--steps", type=int_range(1, 1000), default=20, help="number of steps to walk"
    )
    parser.add_argument(
        "--slope",
        type=float_range(0, MAX_SLOPE, lo_open=True),
        default=0.0525,
        help="downhill slope angle [rad]",
    )
    parser.add_argument("--robot", choices=available_presets(), default="classic", help="robot")
    parser.add_argument(
        "--seed", type=int_range(0), default=0, help="seed of the start perturbation"
    )
    parser.add_argument(
        "--perturb",
        type=float_range(0, MAX_PERTURB),
        default=0.02,
        help="size of the start perturbation [rad, rad/s]",
    )


def run(args: argparse.Namespace) -> int:
    """``roughwalk passive`` with the parsed ``args``: the cycle, one row per step; returns the
    exit status (1 if the walker failed; no cycle for the robot and slope raises
    ``ValueError``)."""
    console = Console(highlight=False)
    announce_compilation(SIMULATOR_KERNELS, console)
    params = RobotParams.from_preset(args.robot)
    gamma = -args.slope
    try:
        # Newton starts from the classic walker's cycle on a 0.0525 rad slope
        cycle = passive_limit_cycle(params, gamma, CLASSIC_CYCLE.section)
    except RuntimeError as exc:
        raise ValueError(
            f"--slope {args.slope}: no passive limit cycle found for the {args.robot} walker on "
            "this slope (cycles exist on about 0.01-0.15 rad for classic, 0.05-0.2 rad for paper)"
        ) from exc
    z_star = cycle.state[[1, 2, 3]]
    moduli = np.sort(np.abs(cycle.eigenvalues))[::-1]
    console.print(
        f"[bold]{args.robot}[/] walker, slope {args.slope} rad: limit cycle period "
        f"{cycle.period:.6f} s, step length {cycle.step_length:.6f} m, post-impact "
        f"q2 = {z_star[0]:.6f} rad, q2dot = {z_star[2]:.6f} rad/s; Poincare eigenvalue moduli "
        + ", ".join(f"{m:.3f}" for m in moduli)
        + (" (stable)" if moduli[0] < 1 else " (unstable)")
    )
    rng = np.random.default_rng(args.seed)
    z0 = z_star + args.perturb * rng.uniform(-1.0, 1.0, 3) * np.array([0.5, 1.0, 1.0])
    q0, qd0 = slope_section_state(z0, gamma)
    duration = (args.steps + 0.5) * cycle.period * 1.5
    res = simulate(
        params,
        Terrain.slope(gamma),
        q0,
        qd0,
        duration,
        config=SimConfig(),
        stop_at_impacts=args.steps,
    )
    post = np.nonzero(np.diff(res.t) == 0)[0] + 1
    table = Table(title="passive steps")
    for col in ("step", "time [s]", "step length [m]", "q2dot+ [rad/s]", "distance to cycle"):
        table.add_column(escape(col), justify="right")
    table.add_row(
        "start", f"{res.t[0]:.4f}", "", f"{qd0[1]:.6f}", f"{np.linalg.norm(z0 - z_star):.2e}"
    )
    foot = np.zeros(2)
    dist = np.linalg.norm(z0 - z_star)
    for i, k in enumerate(post):
        z = np.array([res.q[k, 1], res.qd[k, 0], res.qd[k, 1]])
        dist = np.linalg.norm(z - z_star)
        length = float(np.hypot(*(res.footholds[i] - foot)))
        foot = res.footholds[i]
        table.add_row(
            str(i + 1), f"{res.impact_times[i]:.4f}", f"{length:.6f}", f"{z[2]:.6f}", f"{dist:.2e}"
        )
    console.print(table)
    n = len(post)
    if n:
        periods = np.diff(np.r_[0.0, res.impact_times])
        summary = (
            f"{n} steps in {res.t[-1]:.3f} s, {res.footholds[-1, 0]:.3f} m down the slope; "
            f"last period {periods[-1]:.6f} s; distance to the cycle "
            f"{np.linalg.norm(z0 - z_star):.2e} -> {dist:.2e}"
        )
    else:
        summary = f"no step: the walker failed {res.t[-1]:.3f} s after the start"
    if res.failure is not None:
        console.print(
            f"[red]{escape(summary)}; FAILED: {res.failure} at t = {res.failure_time:.4f} s "
            f"(start perturbed by {args.perturb}, seed {args.seed})"
        )
        return 1
    console.print(escape(summary) + ("; converged to the limit cycle" if dist < 1e-3 else ""))
    return 0
