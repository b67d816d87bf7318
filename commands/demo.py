"""The paper's experiment (Manchester et al. 2011, Section 6) with the reference controller.

The paper's robot walks three steps on the flat, one step down each of two 3 cm stairs, then
on along the flat (roughwalk/CompassGaitStairs-v0, 10 s), controlled by the reference policy:
simulated encoders and contact switches, the high-gain observer, a plan per footstep and the
transverse-linearization receding-horizon controller. Prints one row per footstep (the phase
rate theta_dot at its start and end, the largest deviation |y| from the planned constraint,
the Lyapunov value V = x_perp' P x_perp at the step's first and last tick and their ratio, the
largest |x_perp| and |u|, the Riccati solve time) and writes figures in the style of the
paper's Figure 4 to the output folder:

- cartoon.png: the robot every 0.3 s, stance leg red, swing leg blue;
- q2.png: the stance-leg angle q2 against time;
- q1.png: the inter-leg angle q1 (measured) and its nominal value phi(q2);
- velocities.png: the observer's q1_dot and q2_dot against their nominal values;
- walk.gif with --gif (25 frames per simulated second).

--controller-mode picks the controller's mode: replan (the default: every footstep planned
afresh from the estimated post-impact state, so every step starts at V = 0 and nothing is
certified) or fixed-plan (the paper's setting: one plan made at the start and tracked; its
Appendix A argument makes V fall from step to step near the plan for the model with continuous
feedback and no noise; with this env's 5 ms hold and the observer V hovers at a floor).

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
from rich import box
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
    key_value,
)
from controllers import ControllerConfig, make_reference_policy
from controllers.controller import MODES
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
        "--controller-mode",
        choices=MODES,
        default="replan",
        help="replan every footstep, or track one plan made at the start (the paper's "
        "certified setting) (default: %(default)s)",
    )
    parser.add_argument(
        "--plan-steps",
        type=int_range(2),
        help="footsteps of the fixed plan (fixed-plan only; default: enough for the duration, "
        "1.5 a second plus the look-ahead)",
    )
    parser.add_argument(
        "--controller",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="controller settings (ControllerConfig fields) over the robot's defaults, e.g. "
        "Q=[1,1,1] friction_limit=0 for the paper's weights",
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
    mode: str = "replan",
    plan_steps: int | None = None,
    controller: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the reference policy on ``env_id``.

    Args:
        env_id: Gymnasium id of a roughwalk env.
        seed: the episode's reset seed.
        duration: simulated time [s]; None for the whole episode (see :func:`episode_duration`).
        horizon: the controller's look-ahead [footsteps].
        frames: also render ``GIF_FPS`` frames per simulated second, ``GIF_WIDTH`` px wide, in
            one palette of 64 colours.
        mode: the controller's mode, ``"replan"`` or ``"fixed-plan"``
            (:data:`controllers.controller.MODES`).
        plan_steps: footsteps of the fixed plan (None: sized for the run's duration, see
            :meth:`controllers.ControllerConfig.for_mode`); replan mode ignores it.
        controller: other :class:`controllers.ControllerConfig` fields (not ``horizon``,
            ``replan`` or ``plan_steps``) over the robot's defaults.

    Returns:
        The policy's history, the true states, stance feet and legs per tick, the records, the
        failure (or None), footsteps, distance [m], the terrain and robot, and the frames
        (Pillow palette images) and their period [s].
    """
    check_controller(controller)
    env = gym.make(env_id, render_mode="rgb_array" if frames else None)
    dt = env.unwrapped.dt
    duration = episode_duration(env) if duration is None else duration
    fields: dict[str, Any] = {**(controller or {}), "horizon": horizon}
    if plan_steps is not None and mode == "fixed-plan":
        fields["plan_steps"] = plan_steps
    config = ControllerConfig.for_mode(
        mode,
        min(duration, episode_duration(env)) if math.isfinite(duration) else None,
        env.unwrapped.robot.name,
        **fields,
    )
    policy = make_reference_policy(env, config=config, record_history=True)
    obs, info = env.reset(seed=seed)
    policy.reset()
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
        "config": config,
    }


STEP_COLUMNS = (
    "step",
    "theta_dot start [rad/s]",
    "theta_dot end [rad/s]",
    "max |y| [rad]",
    "V start",
    "V end",
    "V end/start",
    "max |x_perp|",
    "max |u|",
    "Riccati [ms]",
    "note",
)


# the column names on two or three lines
STEP_HEADERS = (
    "step",
    "theta_dot\nstart\n[rad/s]",
    "theta_dot\nend\n[rad/s]",
    "max |y|\n[rad]",
    "V\nstart",
    "V\nend",
    "V end\n/V start",
    "max\n|x_perp|",
    "max\n|u|",
    "Riccati\n[ms]",
    "note",
)


def _g(value: float | None) -> str:
    """``value`` with 2 significant digits, ``-`` for None."""
    return "-" if value is None else f"{value:.2g}"


def step_table(records: list, last: str | None = None) -> list[tuple[str, ...]]:
    """Rows of :data:`STEP_COLUMNS` (step, theta_dot at start and end [rad/s], max ``|y|``
    [rad], ``V`` at the first and last tick and their ratio, max ``|x_perp|``, max ``|u|``
    [input units], Riccati solve [ms], note), one per footstep ``records`` entry that ran;
    ``last`` is added to the note of the last row (the step in progress when the run ended)."""
    ran = [r for r in records if r.ticks > 0]
    rows = []
    for i, r in enumerate(ran):
        notes = [r.fallback] if r.fallback else []
        if last and i == len(ran) - 1:
            notes.append(last)
        cert = r.certificate()
        rows.append(
            (
                str(r.index),
                f"{r.thetadot_start:.3f}",
                f"{r.thetadot_end:.3f}",
                f"{r.max_abs_y:.4f}",
                _g(cert["V_start"]),
                _g(cert["V_end"]),
                _g(cert["V_ratio"]),
                _g(cert["max_xperp_norm"]),
                _g(cert["max_abs_u"]),
                "-" if math.isnan(r.riccati_time) else f"{r.riccati_time * 1e3:.2f}",
                "; ".join(notes),
            )
        )
    return rows


def certificate_summary(records: list, mode: str) -> str:
    """One line on the footsteps completed in ``records`` (all but the last one that ran):
    how often ``V`` fell over a step and from one step's start to the next, in ``mode``."""
    ran = [r.certificate() for r in records if r.ticks > 0]
    done = ran[:-1]
    ratios = [c["V_ratio"] for c in done if c["V_ratio"] is not None]
    starts = [c["V_start"] for c in ran]
    pairs = [(a, b) for a, b in zip(starts, starts[1:]) if a is not None and b is not None]
    fell = sum(r < 1 for r in ratios)
    line = f"{mode}: V end/start < 1 on {fell} of {len(ratios)} completed footsteps"
    if mode == "replan":
        return line + " (every step is planned afresh from its start state: V start is about 0)"
    falls = sum(b < a for a, b in pairs)
    return line + f"; V start fell from one footstep to the next {falls} of {len(pairs)} times"


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


def check_controller(controller: dict[str, Any] | None) -> None:
    """Check the demo's controller settings: :class:`ControllerConfig` fields other than those
    with their own argument; ``ValueError`` naming a bad one."""
    own = {"horizon": "--horizon", "replan": "--controller-mode", "plan_steps": "--plan-steps"}
    for key, option in own.items():
        if key in (controller or {}):
            raise ValueError(f"--controller: {key} has its own option, {option}")
    ControllerConfig.from_dict(dict(controller or {}))


def run(args: argparse.Namespace) -> int:
    """``roughwalk demo`` with the parsed ``args``: the table, the figures; returns the exit
    status (1 if the walker failed)."""
    console = Console(highlight=False)
    if args.plan_steps is not None and args.controller_mode != "fixed-plan":
        raise ValueError("--plan-steps: applies to --controller-mode fixed-plan only")
    check_controller(dict(args.controller or ()))
    if not args.no_figures:
        check_output_path(args.output, directory=True, option="--output")
    announce_compilation(SIMULATOR_KERNELS + CONTROLLER_KERNELS, console)
    res = rollout(
        args.env,
        args.seed,
        args.duration,
        args.horizon,
        frames=args.gif,
        mode=args.controller_mode,
        plan_steps=args.plan_steps,
        controller=dict(args.controller or ()),
    )
    title = f"{args.env}, seed {args.seed}, {args.controller_mode}: one row per footstep"
    table = Table(title=escape(title), box=box.SIMPLE_HEAD, show_edge=False, padding=(0, 1, 0, 0))
    for col, header in zip(STEP_COLUMNS, STEP_HEADERS, strict=True):
        numeric = col != "note"
        table.add_column(escape(header), justify="right" if numeric else "left", no_wrap=numeric)
    last = "unfinished" if res["failure"] is None else f"failed: {res['failure']}"
    for row in step_table(res["records"], last=last):
        table.add_row(*(escape(c) for c in row))
    # as wide as the table needs: a narrower console would cut its numbers off
    width = max(console.width, Console(width=1000).measure(table).maximum)
    Console(highlight=False, width=width).print(table)
    console.print(escape(certificate_summary(res["records"], args.controller_mode)), soft_wrap=True)
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
