"""The paper's experiment (Manchester et al. 2011, Section 6) with the reference controller.

The paper's robot walks flat for two steps, down two stairs, then on along the flat
(``roughwalk/CompassGaitStairs-v0``), controlled by the reference policy: simulated encoders and
contact switches, the high-gain observer, a plan per footstep and the transverse-linearization
receding-horizon controller. Prints one row per footstep (``theta_dot`` at its start and end,
the largest ``|y|``, the Riccati solve time; ``thd`` = ``theta_dot`` [rad/s], ``y`` [rad]) and
writes figures in the style of the paper's
Figure 4 to the output directory:

* ``cartoon.png``: the robot every 0.3 s, the stance leg in red;
* ``q2.png``: the stance-leg angle ``q2`` against time;
* ``q1.png``: the inter-leg angle ``q1`` (measured) and its nominal value ``phi(q2)``;
* ``velocities.png``: the observer's ``q1_dot`` and ``q2_dot`` against their nominal values;
* ``walk.gif`` with ``--gif``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from rich.console import Console
from rich.table import Table

from controllers import ControllerConfig, make_reference_policy
from envs.physics import model


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk demo`` to ``parser``."""
    parser.add_argument(
        "--env", default="roughwalk/CompassGaitStairs-v0", help="environment id (the paper's)"
    )
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default 0)")
    parser.add_argument(
        "--duration", type=float, default=6.0, help="simulated time [s] (default 6)"
    )
    parser.add_argument("--horizon", type=int, default=3, help="look-ahead in footsteps (3)")
    parser.add_argument(
        "--output", default="outputs/demo", help="directory for the figures (outputs/demo)"
    )
    parser.add_argument("--gif", action="store_true", help="also write an animated GIF")
    parser.add_argument("--no-figures", action="store_true", help="print the table only")


def rollout(
    env_id: str, seed: int, duration: float, horizon: int = 3, frames: bool = False
) -> dict[str, Any]:
    """Run the reference policy on ``env_id``; returns the policy's history, the true states,
    stance feet and legs per tick, the records, the failure (or None) and optional frames."""
    env = gym.make(env_id, render_mode="rgb_array" if frames else None)
    policy = make_reference_policy(
        env, config=ControllerConfig(horizon=horizon), record_history=True
    )
    obs, info = env.reset(seed=seed)
    policy.reset()
    dt = env.unwrapped.dt
    states, feet, legs, times, images = [], [], [], [], []
    failure = None
    for _ in range(int(round(duration / dt))):
        states.append(np.asarray(info["state"], dtype=float))
        feet.append(np.asarray(info["stance_foot"], dtype=float))
        legs.append(int(info["stance_leg"]))
        times.append(float(info["time"]))
        if frames:
            images.append(env.render())
        action = policy(obs)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            failure = info.get("failure")
            break
    terrain = env.unwrapped.terrain
    robot = env.unwrapped.robot
    env.close()
    hist = {k: np.asarray(v) for k, v in policy.history.items()}
    return {
        "history": hist,
        "t": np.asarray(times),
        "state": np.asarray(states),
        "foot": np.asarray(feet),
        "leg": np.asarray(legs),
        "records": policy.records,
        "diagnostics": policy.diagnostics,
        "failure": failure,
        "footsteps": int(info["footsteps"]),
        "distance": float(info["distance"]),
        "terrain": terrain,
        "robot": robot,
        "frames": images,
    }


def step_table(records: list) -> list[tuple[str, ...]]:
    """Rows ``(step, theta_dot start, theta_dot end, max |y|, Riccati ms, note)``."""
    rows = []
    for r in records:
        if r.ticks == 0:
            continue
        rows.append(
            (
                str(r.index),
                f"{r.thetadot_start:.3f}",
                f"{r.thetadot_end:.3f}",
                f"{r.max_abs_y:.4f}",
                "-" if math.isnan(r.riccati_time) else f"{r.riccati_time * 1e3:.2f}",
                r.fallback or "",
            )
        )
    return rows


def figures(res: dict[str, Any], out: Path) -> list[Path]:
    """Write the Figure-4-style PNGs; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    P = res["robot"].vector()
    t, x, foot = res["t"], res["state"], res["foot"]
    h = res["history"]
    paths = []

    # (A) cartoon every 0.3 s, the stance leg in red
    fig, ax = plt.subplots(figsize=(10, 3))
    terr = res["terrain"]
    xmin = float(np.min(foot[:, 0])) - 0.3
    xmax = float(np.max(foot[:, 0])) + 0.4
    gx = np.linspace(xmin, xmax, 800)
    ax.plot(gx, terr.height(gx), color="k", lw=1.5)
    for k in np.unique(np.round(np.arange(0, t[-1] + 1e-9, 0.3) / (t[1] - t[0])).astype(int)):
        if k >= len(t):
            break
        q1, q2 = x[k, 0], x[k, 1]
        xs, ys = foot[k]
        hx, hy = model.hip_position(P, q1, q2, xs, ys)
        fx, fy = model.swing_foot_position(P, q1, q2, xs, ys)
        ax.plot([xs, hx], [ys, hy], color="tab:red", lw=2)
        ax.plot([hx, fx], [hy, fy], color="tab:blue", lw=1.5)
        ax.plot([hx], [hy], "ko", ms=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("height [m]")
    ax.set_title("(A) every 0.3 s; stance leg red")
    fig.tight_layout()
    paths.append(out / "cartoon.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    th = h["t"] if h["t"].size else t
    qm = h["q_meas"]
    xh = h["x_hat"]
    nom = h["nominal"]

    # (B) q2 against time
    fig, ax = plt.subplots(figsize=(7, 3))
    ax.plot(th, qm[:, 1], lw=1)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q2 [rad]")
    ax.set_title("(B) stance-leg angle q2 (encoders)")
    fig.tight_layout()
    paths.append(out / "q2.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    # (C) q1 against its nominal value phi(q2)
    fig, ax = plt.subplots(figsize=(7, 3))
    ax.plot(th, qm[:, 0], lw=1, label="q1 (encoders)")
    ax.plot(th, nom[:, 0], "r--", lw=1, label="nominal phi(q2)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q1 [rad]")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("(C) inter-leg angle q1")
    fig.tight_layout()
    paths.append(out / "q1.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    # (D), (E) observer velocities against their nominal values
    fig, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for ax, i, j, name in ((axes[0], 2, 1, "q1_dot"), (axes[1], 3, 2, "q2_dot")):
        ax.plot(th, xh[:, i], lw=1, label=f"{name} (observer)")
        ax.plot(th, nom[:, j], "r--", lw=1, label="nominal")
        ax.set_ylabel(f"{name} [rad/s]")
        ax.legend(loc="best", fontsize=8)
    axes[0].set_title("(D) and (E) joint rates")
    axes[1].set_xlabel("t [s]")
    fig.tight_layout()
    paths.append(out / "velocities.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return paths


def write_gif(frames: list[np.ndarray], path: Path, dt: float, every: int = 4) -> Path:
    """Animated GIF of rendered frames (every ``every``-th frame)."""
    from PIL import Image

    imgs = [Image.fromarray(np.asarray(f)) for f in frames[::every]]
    path.parent.mkdir(parents=True, exist_ok=True)
    imgs[0].save(
        path, save_all=True, append_images=imgs[1:], duration=int(1000 * dt * every), loop=0
    )
    return path


def run(args: argparse.Namespace) -> int:
    """``roughwalk demo`` with the parsed ``args``: the table, the figures; returns the exit
    status (1 if the walker failed)."""
    console = Console()
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise SystemExit("--duration must be > 0 s")
    if args.horizon < 1:
        raise SystemExit("--horizon must be >= 1")
    res = rollout(args.env, args.seed, args.duration, args.horizon, frames=args.gif)
    table = Table(title=f"{args.env}, seed {args.seed}: one row per footstep")
    for col in ("step", "thd start", "thd end", "max |y|", "Riccati ms", "note"):
        table.add_column(col, justify="right" if col != "note" else "left")
    for row in step_table(res["records"]):
        table.add_row(*row)
    console.print(table)
    status = "walked" if res["failure"] is None else f"FAILED ({res['failure']})"
    console.print(
        f"{status}: {res['footsteps']} footsteps, {res['distance']:.2f} m in {res['t'][-1]:.2f} s"
    )
    if not args.no_figures:
        out = Path(args.output)
        for p in figures(res, out):
            console.print(f"wrote {p}")
        if args.gif and res["frames"]:
            dt = float(res["t"][1] - res["t"][0]) if len(res["t"]) > 1 else 0.005
            console.print(f"wrote {write_gif(res['frames'], out / 'walk.gif', dt)}")
    return 0 if res["failure"] is None else 1
