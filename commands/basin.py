"""Sampled basin of attraction of the reference controller around its periodic flat-ground gait.

Perturbs the post-impact state of the periodic gait in its transverse coordinates z = [I, y,
y_dot] at its post-impact phase theta+, and simulates each start for --steps footsteps
with the exact hybrid simulator and the reference controller (replanning at every footstep) on
the true state: no sensors, no observer. A start converged when it walked every footstep and
ended with V_c = z' P_c z <= --v-tol in the periodic gait's coordinates (P_c: the jump-Riccati
solution over the periodic step with the paper's weights, whatever the controller's, so that
one tolerance serves every controller). Perturbations: --per-radius directions
uniform on each ellipsoid z' P z = r^2, r in --radii; perturbations with no state
(theta_dot^2 + I <= 0, or the retracted trailing foot below the ground) are left out and
counted.

Certified level set: rho is the smallest V among the non-converged starts of the even-numbered
samples; the odd-numbered ones inside V < rho check it, with an exact one-sided bound on the
probability that a start drawn by this sampler inside the level set fails (about 3/N with N
starts inside and none failing, at 95 %). It is a statistical statement about this sampler,
this simulator and these footsteps, not a proof that every state in the level set converges.

Writes OUT/basin.json (settings, P, the converged fraction per radius, the level set, every
sample), OUT/basin.csv (one row per sample), OUT/basin_fraction.png and, with --slices N > 0,
two 2-D slices (N x N grids, the third coordinate 0): OUT/basin_slice_y_ydot.png and
OUT/basin_slice_I_y.png. An existing result in OUT stops the command unless --overwrite.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from agents.runs import atomic_write_stream, claim_output_folder
from agents.stats import wilson_interval
from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    announce_compilation,
    float_range,
    int_range,
    key_value,
    output_dir,
    preset_config,
)
from commands.mfpt import save_figure
from controllers.basin import (
    COORDS,
    DEFAULT_V_TOL,
    NO_STATE,
    BasinSample,
    LevelSet,
    PeriodicReference,
    certified_level,
    converged_fractions,
    periodic_reference,
    sample_basin,
    slice_grid,
)
from controllers.controller import ControllerConfig
from controllers.planner import PlannerConfig

OUTPUTS = (
    "basin.json",
    "basin.csv",
    "basin_fraction.png",
    "basin_slice_y_ydot.png",
    "basin_slice_I_y.png",
)
SLICES = {"y_ydot": (1, 2), "I_y": (0, 1)}


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk basin`` to ``parser``."""
    parser.add_argument(
        "--robot",
        choices=("paper",),
        default="paper",
        help="robot (the paper's; --v-tol is set for its gait)",
    )
    parser.add_argument(
        "--radii",
        nargs="+",
        type=float_range(0, 100, lo_open=True),
        default=[0.1, 0.25, 0.5, 0.75, 1.0, 1.5],
        metavar="R",
        help="perturbation sizes r = sqrt(z' P z), increasing",
    )
    parser.add_argument(
        "--per-radius", type=int_range(1, 100_000), default=20, help="starts per radius"
    )
    parser.add_argument(
        "--steps", type=int_range(1, 1000), default=16, help="footsteps simulated per start"
    )
    parser.add_argument(
        "--v-tol",
        type=float_range(0, lo_open=True),
        default=DEFAULT_V_TOL,
        help="largest V_c (the paper weights' metric) at the end that counts as converged (the "
        "unperturbed gait's after 16 footsteps: about 0.008)",
    )
    parser.add_argument(
        "--slices", type=int_range(0, 200), default=9, help="grid size of the 2-D slices (0: none)"
    )
    parser.add_argument(
        "--slice-radius",
        type=float_range(0, 100, lo_open=True),
        help="half-extent of the slices as a radius r (default: 1.5 x the largest of --radii)",
    )
    parser.add_argument(
        "--controller",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="the controller's settings (ControllerConfig fields, e.g. Q=[1,1,1] for the "
        "paper's weights); they set P, so V and the radii too",
    )
    parser.add_argument(
        "--planner",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="the gait planner's settings (PlannerConfig fields over the robot's preset, e.g. "
        "clearance=0.003)",
    )
    parser.add_argument(
        "--seed", type=int_range(0, 2**32 - 1), default=0, help="seed of the directions"
    )
    parser.add_argument(
        "--confidence",
        type=float_range(0, 1, lo_open=True, hi_open=True),
        default=0.95,
        help="confidence level of the intervals and of the bound",
    )
    parser.add_argument(
        "--out", type=output_dir, default=Path("results/basin"), help="folder of the results"
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an earlier result in --out"
    )


def slice_extent(ref: PeriodicReference, axes: tuple[int, int], r: float) -> tuple[float, float]:
    """Half-extents of the ellipse ``z' P z = r^2`` in the plane of ``axes`` (others zero)."""
    Pab = ref.P[np.ix_(axes, axes)]
    inv = np.linalg.inv(Pab)
    return (r * math.sqrt(inv[0, 0]), r * math.sqrt(inv[1, 1]))


def _plot_fraction(rows: list[dict[str, Any]], level: LevelSet, path: Path, conf: float) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    rs = [row["r"] for row in rows if row["starts"]]
    fr = [row["fraction"] for row in rows if row["starts"]]
    lo = [row["low"] for row in rows if row["starts"]]
    hi = [row["high"] for row in rows if row["starts"]]
    ax.fill_between(rs, lo, hi, alpha=0.25, label=f"Wilson {round(100 * conf)} %")
    ax.plot(rs, fr, "o-", label="converged fraction")
    ax.axvline(math.sqrt(level.rho), color="k", ls="--", label="certified sqrt(rho)")
    ax.set_xlabel("perturbation size r = sqrt(z' P z)")
    ax.set_ylabel("converged fraction")
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path)


def _plot_slice(
    ref: PeriodicReference,
    name: str,
    ga: np.ndarray,
    gb: np.ndarray,
    samples: list[BasinSample],
    level: LevelSet,
    radii: list[float],
    path: Path,
) -> None:
    import matplotlib.pyplot as plt

    a, b = SLICES[name]
    code = np.array(
        [2 if s.end == NO_STATE else (1 if s.converged else 0) for s in samples], dtype=float
    ).reshape(ga.size, gb.size)
    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    from matplotlib.colors import ListedColormap

    cmap = ListedColormap(["#d62728", "#2ca02c", "#bbbbbb"])
    ax.pcolormesh(gb, ga, code, cmap=cmap, vmin=0, vmax=2, shading="nearest")
    Pab = ref.P[np.ix_((b, a), (b, a))]
    X, Y = np.meshgrid(np.linspace(gb[0], gb[-1], 200), np.linspace(ga[0], ga[-1], 200))
    Vg = Pab[0, 0] * X * X + 2 * Pab[0, 1] * X * Y + Pab[1, 1] * Y * Y
    ax.contour(X, Y, Vg, levels=sorted(r * r for r in radii), colors="k", linewidths=0.5)
    ax.contour(X, Y, Vg, levels=[level.rho], colors="b", linewidths=2)
    ax.set_xlabel(COORDS[b])
    ax.set_ylabel(COORDS[a])
    ax.set_title(
        f"green: converged, red: not, grey: no state; blue: V = rho; {COORDS[3 - a - b]} = 0",
        fontsize=8,
    )
    save_figure(fig, path)


def _sample_dict(s: BasinSample, kind: str) -> dict[str, Any]:
    return {
        "kind": kind,
        "I": s.z[0],
        "y": s.z[1],
        "y_dot": s.z[2],
        "V0": s.V0,
        "converged": s.converged,
        "end": s.end,
        "footsteps": s.footsteps,
        "V_end": None if math.isnan(s.V_end) else s.V_end,
        "fallbacks": s.fallbacks,
    }


def run(args: argparse.Namespace) -> int:
    """``roughwalk basin`` with the parsed ``args``; returns the exit status (bad input raises
    ``ValueError`` before any simulation)."""
    import matplotlib

    matplotlib.use("Agg")
    radii = list(args.radii)
    if any(b <= a for a, b in zip(radii, radii[1:])):
        raise ValueError(f"--radii: sizes must increase, got {radii}")
    config = preset_config(ControllerConfig, "--controller", args.controller, args.robot)
    planner = preset_config(PlannerConfig, "--planner", args.planner, args.robot)
    out: Path = args.out
    with claim_output_folder(out, OUTPUTS, args.overwrite):
        return _measure(args, out, radii, config, planner)


def _measure(
    args: argparse.Namespace,
    out: Path,
    radii: list[float],
    config: ControllerConfig,
    planner: PlannerConfig,
) -> int:
    """``roughwalk basin``'s measurement and outputs, in the folder ``out`` it holds."""
    announce_compilation(SIMULATOR_KERNELS + CONTROLLER_KERNELS)
    t0 = time.perf_counter()
    ref = periodic_reference(args.robot, config, planner)
    samples = sample_basin(ref, radii, args.per_radius, args.seed, args.steps, args.v_tol)
    t_shells = time.perf_counter() - t0
    rows = converged_fractions(samples)
    for row in rows:
        interval = (None, None)
        if row["starts"]:
            interval = wilson_interval(row["converged"], row["starts"], args.confidence)
        row["low"], row["high"] = interval
    pct = round(100 * args.confidence)
    for row in rows:
        print(
            f"r = {row['r']:6.3f}: {row['converged']:4d}/{row['starts']:<4d} converged "
            f"({row['fraction']:.0%}, Wilson {pct} %: {row['low']:.0%}-{row['high']:.0%})"
            + (f"; {row['no_state']} without a post-impact state" if row["no_state"] else ""),
            flush=True,
        )
    valid = [s for s in samples if s.end != NO_STATE]
    if len(valid) < 2:
        raise ValueError(
            "--radii: fewer than two perturbations had a post-impact state; use smaller radii"
        )
    level = certified_level(
        [s.V0 for s in valid], [not s.converged for s in valid], args.confidence
    )
    slices: dict[str, Any] = {}
    slice_r = args.slice_radius or 1.5 * radii[-1]
    records = [_sample_dict(s, "shell") for s in samples]
    inside_fail = 0
    t1 = time.perf_counter()
    if args.slices:
        for name, axes in SLICES.items():
            ext = slice_extent(ref, axes, slice_r)
            ga, gb, ss = slice_grid(ref, axes, ext, args.slices, args.steps, args.v_tol)
            slices[name] = (ga, gb, ss)
            records += [_sample_dict(s, f"slice {name}") for s in ss]
            inside_fail += sum(
                s.end != NO_STATE and not s.converged and level.contains(s.V0) for s in ss
            )
    t_slices = time.perf_counter() - t1
    print(
        f"certified level set: V {'<' if level.bounded_by_failure else '<='} rho = "
        f"{level.rho:.4g} (r {'<' if level.bounded_by_failure else '<='} "
        f"{math.sqrt(level.rho):.3f}), "
        + (
            "the smallest V of a non-converged start"
            if level.bounded_by_failure
            else "the largest sampled V (no selection start failed)"
        )
        + f" among {level.selection} selection starts; {level.inside} of "
        f"{level.certification} held-out starts inside, {level.failures_inside} not converged: "
        f"P(not converged | this sampler, inside) < {level.bound:.3g} at {pct} % confidence"
    )
    if args.slices:
        print(f"slice starts that did not converge inside V < rho: {inside_fail}")
    print(f"wall time: {t_shells:.0f} s for {len(samples)} starts, {t_slices:.0f} s for slices")
    settings = {
        "robot": args.robot,
        "radii": radii,
        "per_radius": args.per_radius,
        "steps": args.steps,
        "v_tol": args.v_tol,
        "seed": args.seed,
        "confidence": args.confidence,
        "slices": args.slices,
        "slice_radius": slice_r,
        "controller": dict(args.controller or ()),
        "controller_config": config.to_dict(),
        "planner": dict(args.planner or ()),
        "planner_config": planner.to_dict(),
        "simulation": "exact hybrid simulator, reference controller on the true state",
    }
    data = {
        "settings": settings,
        "periodic_gait": {
            "q": ref.gait.q.tolist(),
            "qd": ref.gait.qd.tolist(),
            "period": ref.gait.period,
            "step_length": ref.gait.step_length,
        },
        "P": ref.P.tolist(),
        "fractions": rows,
        "level_set": {**level.to_dict(), "slice_failures_inside": inside_fail},
        "wall_time_s": {"shells": t_shells, "slices": t_slices},
        "samples": records,
    }
    text = json.dumps(data, indent=1)
    atomic_write_stream(out / "basin.json", lambda fh: fh.write(text + "\n"))

    def write_csv(fh: Any) -> None:
        writer = csv.DictWriter(fh, fieldnames=list(records[0]))
        writer.writeheader()
        writer.writerows(records)

    atomic_write_stream(out / "basin.csv", write_csv)
    _plot_fraction(rows, level, out / "basin_fraction.png", args.confidence)
    for name, (ga, gb, ss) in slices.items():
        _plot_slice(ref, name, ga, gb, ss, level, radii, out / f"basin_slice_{name}.png")
    print(f"wrote {out}/basin.json, basin.csv and the figures")
    return 0
