"""The paper's experiment (Manchester et al. 2011, Section 6) with the reference controller.

The paper's robot walks three steps on the flat, one step down each of two 3 cm stairs, then
on along the flat (roughwalk/CompassGaitStairs-v0, 10 s), controlled by the reference policy:
simulated encoders and contact switches, the high-gain observer, a plan per footstep and the
transverse-linearization receding-horizon controller. Prints one row per footstep (the phase
rate theta_dot at its start and end, the largest deviation |y| from the planned constraint,
the Riccati solve time) and writes figures in the style of the paper's Figure 4 to the
output folder:

- cartoon.png: the robot every 0.3 s, stance leg red, swing leg blue;
- q2.png: the stance-leg angle q2 against time;
- q1.png: the inter-leg angle q1 (measured) and its nominal value phi(q2);
- velocities.png: the observer's q1_dot and q2_dot against their nominal values;
- walk.gif with --gif (25 frames per simulated second).

The first run compiles the simulator's and the controller's numba kernels (about a minute);
later runs load them from the cache.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    announce_compilation,
    check_output_path,
    env_id,
    float_range,
    int_range,
)
from controllers import ControllerConfig, make_reference_policy
from envs.physics import model

GIF_FPS = 25  # frames per simulated second
GIF_WIDTH = 480  # [px]


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk demo`` to ``parser``."""
    parser.add_argument(
        "--env",
        type=env_id,
        default="roughwalk/CompassGaitStairs-v0",
        help="environment id (default: the paper's course, %(default)s)",
    )
    parser.add_argument("--seed", type=int_range(0), default=0, help="episode seed")
    parser.add_argument(
        "--duration",
        type=float_range(0, lo_open=True),
        help="simulated time [s] (default: the env's whole episode, max_episode_steps x dt: "
        "10 s on the stairs)",
    )
    parser.add_argument(
        "--horizon", type=int_range(1, 10), default=3, help="look-ahead in footsteps"
    )
    parser.add_argument(
        "--output", type=Path, default=Path("outputs/demo"), help="folder for the figures"
    )
    parser.add_argument(
        "--gif", action="store_true", help=f"also write an animated GIF ({GIF_WIDTH} px wide)"
    )
    parser.add_argument("--no-figures", action="store_true", help="print the table only")


def episode_duration(env: gym.Env) -> float:
    """The simulated time of a whole episode of ``env`` [s]: its ``max_episode_steps`` times
    its control period (infinite without a time limit)."""
    steps = env.spec.max_episode_steps if env.spec is not None else None
    return math.inf if steps is None else steps * float(env.unwrapped.dt)


def _gif_frame(rgb: np.ndarray, width: int, palette: Any = None) -> Any:
    """A rendered RGB frame as a palette image ``width`` px wide (aspect kept), in the colours
    of ``palette`` (a palette image; default: 64 colours of its own)."""
    from PIL import Image

    img = Image.fromarray(np.asarray(rgb))
    if img.width != width:
        img = img.resize((width, round(img.height * width / img.width)), Image.Resampling.BOX)
    if palette is None:
        return img.quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    return img.quantize(palette=palette, dither=Image.Dither.NONE)


def rollout(
    env_id: str,
    seed: int,
    duration: float | None = None,
    horizon: int = 3,
    frames: bool = False,
) -> dict[str, Any]:
    """Run the reference policy on ``env_id``.

    Args:
        env_id: Gymnasium id of a roughwalk env.
        seed: the episode's reset seed.
        duration: simulated time [s]; None for the whole episode (see :func:`episode_duration`).
        horizon: the controller's look-ahead [footsteps].
        frames: also render ``GIF_FPS`` frames per simulated second, ``GIF_WIDTH`` px wide, in
            one palette of 64 colours.

    Returns:
        The policy's history, the true states, stance feet and legs per tick, the records, the
        failure (or None), footsteps, distance [m], the terrain and robot, and the frames
        (Pillow palette images) and their period [s].
    """
    env = gym.make(env_id, render_mode="rgb_array" if frames else None)
    policy = make_reference_policy(
        env, config=ControllerConfig(horizon=horizon), record_history=True
    )
    obs, info = env.reset(seed=seed)
    policy.reset()
    dt = env.unwrapped.dt
    duration = episode_duration(env) if duration is None else duration
    every = max(1, round(1.0 / (GIF_FPS * dt)))
    states, feet, legs, times, images = [], [], [], [], []
    failure = None
    for k in range(int(round(min(duration, episode_duration(env)) / dt))):
        states.append(np.asarray(info["state"], dtype=float))
        feet.append(np.asarray(info["stance_foot"], dtype=float))
        legs.append(int(info["stance_leg"]))
        times.append(float(info["time"]))
        if frames and k % every == 0:  # the first frame's palette for all
            images.append(_gif_frame(env.render(), GIF_WIDTH, images[0] if images else None))
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
        "time": float(info["time"]),
        "terrain": terrain,
        "robot": robot,
        "frames": images,
        "frame_period": every * dt,
    }


STEP_COLUMNS = (
    "step",
    "theta_dot start [rad/s]",
    "theta_dot end [rad/s]",
    "max |y| [rad]",
    "Riccati [ms]",
    "note",
)


def step_table(records: list, last: str | None = None) -> list[tuple[str, ...]]:
    """Rows of :data:`STEP_COLUMNS` (step, theta_dot at start and end [rad/s], max ``|y|``
    [rad], Riccati solve [ms], note), one per footstep ``records`` entry that ran; ``last``
    is added to the note of the last row (the step in progress when the run ended)."""
    ran = [r for r in records if r.ticks > 0]
    rows = []
    for i, r in enumerate(ran):
        notes = [r.fallback] if r.fallback else []
        if last and i == len(ran) - 1:
            notes.append(last)
        rows.append(
            (
                str(r.index),
                f"{r.thetadot_start:.3f}",
                f"{r.thetadot_end:.3f}",
                f"{r.max_abs_y:.4f}",
                "-" if math.isnan(r.riccati_time) else f"{r.riccati_time * 1e3:.2f}",
                "; ".join(notes),
            )
        )
    return rows


def figures(res: dict[str, Any], out: Path) -> list[Path]:
    """Write the Figure-4-style PNGs of the rollout ``res`` (see :func:`rollout`) into the
    folder ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    P = res["robot"].vector()
    t, x, foot = res["t"], res["state"], res["foot"]
    h = res["history"]
    paths = []

    # (A) cartoon every 0.3 s: swing leg blue under the stance leg red
    fig, ax = plt.subplots(figsize=(10, 3.4))
    terr = res["terrain"]
    xmin = float(np.min(foot[:, 0])) - 0.3
    xmax = float(np.max(foot[:, 0])) + 0.4
    gx = np.linspace(xmin, xmax, 800)
    ax.plot(gx, terr.height(gx), color="k", lw=1.5, zorder=1)
    for k in np.unique(np.round(np.arange(0, t[-1] + 1e-9, 0.3) / (t[1] - t[0])).astype(int)):
        if k >= len(t):
            break
        q1, q2 = x[k, 0], x[k, 1]
        xs, ys = foot[k]
        hx, hy = model.hip_position(P, q1, q2, xs, ys)
        fx, fy = model.swing_foot_position(P, q1, q2, xs, ys)
        ax.plot([hx, fx], [hy, fy], color="tab:blue", lw=1.5, zorder=2)
        ax.plot([xs, hx], [ys, hy], color="tab:red", lw=2, zorder=3)
        ax.plot([hx], [hy], "ko", ms=3, zorder=4)
    ax.plot([], [], color="tab:red", lw=2, label="stance leg")
    ax.plot([], [], color="tab:blue", lw=1.5, label="swing leg")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("height [m]")
    ax.set_title("(A) the robot every 0.3 s")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    paths.append(out / "cartoon.png")
    fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
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

    # (C) q1 against its nominal value phi(q2); legends below the axes, clear of the data
    fig, ax = plt.subplots(figsize=(7, 3.4), layout="constrained")
    ax.plot(th, qm[:, 0], lw=1, label="q1 (encoders)")
    ax.plot(th, nom[:, 0], "r--", lw=1, label="nominal phi(q2)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q1 [rad]")
    ax.set_title("(C) inter-leg angle q1")
    fig.legend(loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    paths.append(out / "q1.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    # (D), (E) observer velocities against their nominal values
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.4), sharex=True, layout="constrained")
    for ax, i, j, name in ((axes[0], 2, 1, "q1_dot"), (axes[1], 3, 2, "q2_dot")):
        ax.plot(th, xh[:, i], lw=1, label="observer" if i == 2 else None)
        ax.plot(th, nom[:, j], "r--", lw=1, label="nominal" if i == 2 else None)
        ax.set_ylabel(f"{name} [rad/s]")
    axes[0].set_title("(D) and (E) joint rates")
    axes[1].set_xlabel("t [s]")
    fig.legend(loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    paths.append(out / "velocities.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return paths


def write_gif(frames: list[Any], path: Path, frame_period: float) -> Path:
    """Write ``frames`` (Pillow images, see :func:`rollout`) shown ``frame_period`` [s] apart
    as an animated GIF to ``path``; returns it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(
        path,
        save_all=True,
        append_images=frames[1:],
        duration=round(1000 * frame_period),
        loop=0,
    )
    return path


def run(args: argparse.Namespace) -> int:
    """``roughwalk demo`` with the parsed ``args``: the table, the figures; returns the exit
    status (1 if the walker failed)."""
    console = Console(highlight=False)
    if not args.no_figures:
        check_output_path(args.output, directory=True, option="--output")
    announce_compilation(SIMULATOR_KERNELS + CONTROLLER_KERNELS, console)
    res = rollout(args.env, args.seed, args.duration, args.horizon, frames=args.gif)
    table = Table(title=escape(f"{args.env}, seed {args.seed}: one row per footstep"))
    for col in STEP_COLUMNS:
        table.add_column(escape(col), justify="right" if col != "note" else "left")
    last = "unfinished" if res["failure"] is None else f"failed: {res['failure']}"
    for row in step_table(res["records"], last=last):
        table.add_row(*(escape(c) for c in row))
    console.print(table)
    status = "walked" if res["failure"] is None else f"FAILED ({res['failure']})"
    console.print(
        f"{status}: {res['footsteps']} footsteps, {res['distance']:.2f} m in {res['time']:.2f} s"
    )
    if not args.no_figures:
        out = Path(args.output)
        for p in figures(res, out):
            console.print(f"wrote {escape(str(p))}", soft_wrap=True)
        if args.gif and res["frames"]:
            gif = write_gif(res["frames"], out / "walk.gif", res["frame_period"])
            console.print(f"wrote {escape(str(gif))}", soft_wrap=True)
    return 0 if res["failure"] is None else 1
