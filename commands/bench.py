"""Speed of the simulator, the environments, the controller and the gait planner.

Prints one table: the simulator stepping one walker and a batch of walkers, the envs through
gym.make and the native vector env, the Riccati solve and the control tick, and the
planner's replanning time per footstep. Compilation and warm-up are excluded from the
timings; each timing is the fastest of repeated runs. A full run takes about 2 minutes,
--quick a few seconds per section. --episodes sets the episodes of the closed-loop planner rows
(a p99 over 6 is about their second-slowest footstep), --planner the gait planner's settings of
the planner section (e.g. compiled_sqp=0, the previous default).
"""

from __future__ import annotations

import argparse
import gc
import os
import time
from collections.abc import Callable
from dataclasses import replace

import gymnasium as gym
import numba
import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from commands.cli import (
    CONTROLLER_KERNELS,
    SIMULATOR_KERNELS,
    announce_compilation,
    int_range,
    key_value,
    preset_config,
)
from configs import CONFIG_DIR
from controllers.controller import PAPER_WEIGHTS, TransverseController
from controllers.feedback import feedback_law
from controllers.gains import horizon_gains, step_models
from controllers.observer import HighGainObserver, observer_update
from controllers.planner import GaitPlanner, Plan, PlannerConfig, PlanningError
from controllers.reference import ReferencePolicy
from envs import RobotParams, Simulator, Terrain
from envs.physics.passive import CLASSIC_CYCLE

Row = tuple[str, str, str]
Section = Callable[[argparse.Namespace], list[Row]]

# the classic walker's passive cycle down a 0.0525 rad slope (post-impact state)
_SLOPE = CLASSIC_CYCLE.slope
_Q0 = CLASSIC_CYCLE.q
_QD0 = CLASSIC_CYCLE.qd
DRAKE_STEPS_PER_S = 41_000  # Drake's C++ compass gait, 10 ms steps per second (reference)


def _timed(fn: Callable[[], None], min_time: float) -> float:
    """Call ``fn`` repeatedly for at least ``min_time`` seconds (and 3 times); return the
    fastest call [s] (the least disturbed by other load on the machine)."""
    best, calls, start = float("inf"), 0, time.perf_counter()
    while calls < 3 or time.perf_counter() - start < min_time:
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        calls += 1
    return best


def simulator_section(args: argparse.Namespace) -> list[Row]:
    """Single walker (one Python call per 10 ms step) and a batch of walkers (multi-threaded
    and single-threaded kernels), the classic walker walking passively down a slope. Timings
    are the fastest of repeated runs."""
    params, terrain = RobotParams.from_preset("classic"), Terrain.slope(_SLOPE)
    t_min = 0.3 if args.quick else 2.0
    rows: list[Row] = []

    sim = Simulator(params, terrain, 1, dt=0.01)
    sim.reset(_Q0, _QD0)
    sim.step(0.0)  # compile / load from cache
    walked = 1.0 if args.quick else 2.0
    n = round(walked / sim.dt)

    def walk() -> None:
        sim.reset(_Q0, _QD0)
        for _ in range(n):
            sim.step(0.0)

    per_walk = _timed(walk, t_min)
    if sim.failure() is not None:
        raise RuntimeError(f"benchmark walker failed: {sim.failure()}")
    rows.append(("1 walker: simulated s per wall s", f"{walked / per_walk:,.0f}", "x"))
    rows.append(("1 walker: one 10 ms step() call", f"{per_walk / n * 1e6:.2f}", "us"))
    rows.append(("1 walker: steps per second", f"{n / per_walk:,.0f}", "1/s"))

    nb = args.walkers
    rng = np.random.default_rng(0)
    q0 = np.asarray(_Q0) + rng.uniform(-1e-3, 1e-3, (nb, 2))
    torque = np.zeros(nb)
    chunk = 10
    for parallel in (True, False):
        batch = Simulator(params, terrain, nb, dt=0.01, parallel=parallel)
        batch.reset(q0, np.broadcast_to(_QD0, (nb, 2)))
        batch.step(torque)

        def steps(batch: Simulator = batch) -> None:
            for _ in range(chunk):
                batch.step(torque)

        per_step = _timed(steps, t_min) / chunk
        if batch.status.any():
            raise RuntimeError("benchmark batch: some walkers failed")
        how = f"{numba.get_num_threads()} thr" if parallel else "1 thr"
        rows.append((f"{nb} walkers, {how}: walker-steps/s", f"{nb / per_step:,.0f}", "1/s"))
        rows.append(
            (
                f"{nb} walkers, {how}: simulated s/wall s",
                f"{nb * 0.01 / per_step:,.0f}",
                "x",
            )
        )
    rows.append(("reference: Drake C++ compass gait", f"{DRAKE_STEPS_PER_S:,}", "steps/s"))
    rows.append(("machine: os.cpu_count()", str(os.cpu_count()), "cores"))
    rows.append(("machine: numba threads", str(numba.get_num_threads()), "threads"))
    rows.append(("machine: numba threading layer", numba.threading_layer(), ""))
    return rows


def env_section(args: argparse.Namespace) -> list[Row]:
    """Gymnasium environments: one env through ``gym.make`` (its wrappers included) and the
    native vector env at 1, 64 and ``--walkers`` envs; BipedalWalker-v3 for scale if Box2D is
    installed. Passive walking down the slope (no resets), and random actions on rough terrain
    (falls and resets included)."""
    t_min = 0.3 if args.quick else 2.0
    rows: list[Row] = []
    rng = np.random.default_rng(0)

    def timed(fn: Callable[[], None], mean: bool) -> float:
        # passive walking: the fastest call (least disturbed by other load); with resets: the
        # mean over the whole run, so that the resets are counted at their real frequency
        if not mean:
            return _timed(fn, t_min)
        fn()
        calls, start = 0, time.perf_counter()
        while calls < 3 or time.perf_counter() - start < t_min:
            fn()
            calls += 1
        return (time.perf_counter() - start) / calls

    def single(env_id: str, random_actions: bool) -> float:
        env = gym.make(env_id)
        env.reset(seed=0)
        acts = (
            rng.uniform(-1, 1, (4096, 1)).astype(np.float32)
            if random_actions
            else np.zeros((4096, 1), np.float32)
        )
        state = {"k": 0}

        def chunk() -> None:
            for _ in range(1000):
                k = state["k"] = (state["k"] + 1) % 4096
                _, _, term, trunc, _ = env.step(acts[k])
                if term or trunc:
                    env.reset()

        return 1000 / timed(chunk, random_actions)

    def vector(env_id: str, n: int, random_actions: bool) -> float:
        venv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point")
        venv.reset(seed=0)
        acts = (
            rng.uniform(-1, 1, (8, n, 1)).astype(np.float32)
            if random_actions
            else np.zeros((8, n, 1), np.float32)
        )
        state = {"k": 0}
        reps = max(1, 4096 // n)

        def steps() -> None:
            for _ in range(reps):
                state["k"] = (state["k"] + 1) % 8
                venv.step(acts[state["k"]])

        steps()
        return n * reps / timed(steps, random_actions)

    slope, rough = "roughwalk/CompassGaitSlope-v0", "roughwalk/CompassGaitRough-v0"
    rows.append(
        ("gym.make Slope (passive, 10 ms): steps per second", f"{single(slope, False):,.0f}", "1/s")
    )
    rows.append(
        (
            "gym.make Rough (random, 5 ms, resets; mean): steps per second",
            f"{single(rough, True):,.0f}",
            "1/s",
        )
    )
    for n in sorted({1, 64, args.walkers}):
        rate = vector(slope, n, False)
        rows.append((f"vector Slope x{n} (passive): env-steps per second", f"{rate:,.0f}", "1/s"))
    # the same batch stepped by the bare simulator, right after: the environment's share
    venv = gym.make_vec(slope, args.walkers, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    sim = venv.unwrapped.simulator
    torque = np.zeros(args.walkers)
    reps = max(1, 4096 // args.walkers)

    def sim_steps() -> None:
        for _ in range(reps):
            sim.step(torque)

    sim_steps()
    sim_rate = args.walkers * reps / _timed(sim_steps, t_min)
    env_rate = vector(slope, args.walkers, False)
    rows.append(
        (
            f"vector Slope x{args.walkers} / bare simulator (same run)",
            f"{env_rate:,.0f} / {sim_rate:,.0f}",
            "1/s",
        )
    )
    rate = vector(rough, args.walkers, True)
    rows.append(
        (
            f"vector Rough x{args.walkers} (random, autoresets; mean): env-steps/s",
            f"{rate:,.0f}",
            "1/s",
        )
    )
    try:
        bw = gym.make("BipedalWalker-v3")
    except Exception:  # noqa: BLE001 - Box2D is optional
        rows.append(("BipedalWalker-v3 (gym.make): steps per second", "n/a (no Box2D)", ""))
    else:
        bw.reset(seed=0)

        def bw_chunk() -> None:
            for _ in range(200):
                _, _, term, trunc, _ = bw.step(bw.action_space.sample())
                if term or trunc:
                    bw.reset()

        rate = 200 / _timed(bw_chunk, t_min)
        rows.append(("BipedalWalker-v3 (gym.make): steps per second", f"{rate:,.0f}", "1/s"))
    return rows


def controller_section(args: argparse.Namespace) -> list[Row]:
    """Transverse controller of the paper robot: one footstep's jump-Riccati solve at h = 3
    (the paper: about 0.5 s in MATLAB) and the linearisation plus solve (flat-ground plan), the
    planner's replanning call (flat, and per footstep of a state-feedback walk over the
    paper's stairs), and one control tick (observer update plus feedback law). Medians."""
    reps = 20 if args.quick else 200
    ctrl = TransverseController("paper", "flat", {"horizon": 3, "replan": False})
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    steps = ctrl.plan.steps[:4]
    ric, full, ric_paper = [], [], []
    # the robot's defaults (the paper robot: stiff weights) and the paper's weights, same plan
    paper_weights = replace(ctrl.config, **PAPER_WEIGHTS)
    for _ in range(reps):
        t0 = time.perf_counter()
        models = step_models(ctrl.P, steps, ctrl.terrain)
        sol = horizon_gains(models, ctrl.config)
        full.append(time.perf_counter() - t0)
        ric.append(sol.riccati_time)
        ric_paper.append(horizon_gains(models, paper_weights).riccati_time)
    plan_t = []
    prev = None
    for _ in range(max(3, reps // 20)):
        t0 = time.perf_counter()
        prev = ctrl.planner.plan(ctrl.terrain, (gait.q, gait.qd), (0.0, 0.0), 4, prev)
        plan_t.append(time.perf_counter() - t0)
    # replanning at every footstep of a walk over the paper's stairs (state feedback)
    stairs = Terrain.from_yaml(CONFIG_DIR / "terrains" / "paper_stairs.yaml")
    walker = TransverseController("paper", stairs, {"horizon": 3})
    out = walker.rollout(gait.q, gait.qd, 8.0 if args.quick else 12.0, dt=0.005)
    stairs_plan = [r.plan_time for r in out["records"] if r.plan_time > 0][1:]
    obs = HighGainObserver(ctrl.robot, 0.005, 0.02)
    obs.reset(gait.q, gait.qd)
    x, P, n = obs.x, ctrl.P, 20000 if not args.quick else 2000
    tab, pc, Fv, Fd, K = ctrl.gain_table.kernel_args()
    q1, q2 = float(gait.q[0]), float(gait.q[1])
    observer_update(P, x, q1, q2, q1, q2, 0.0, 0.005, 0.02, obs.nsub)
    feedback_law(P, x, tab, pc, Fv, Fd, K)
    x[:] = (*gait.q, *gait.qd)
    t0 = time.perf_counter()
    for _ in range(n):
        observer_update(P, x, q1, q2, q1, q2, 0.0, 0.005, 0.02, obs.nsub)
        feedback_law(P, x, tab, pc, Fv, Fd, K)
    tick = (time.perf_counter() - t0) / n
    return [
        ("Riccati solve, one footstep, h = 3", f"{np.median(ric) * 1e3:.3f}", "ms"),
        (
            "Riccati solve, one footstep, h = 3, the paper's weights (Q = Qj = I, R = 1)",
            f"{np.median(ric_paper) * 1e3:.3f}",
            "ms",
        ),
        ("linearisation + Riccati, one footstep", f"{np.median(full) * 1e3:.2f}", "ms"),
        ("replanning (planner, 4 steps, flat)", f"{np.median(plan_t) * 1e3:.1f}", "ms"),
        (
            f"replanning per footstep, paper stairs walk ({len(stairs_plan)} steps"
            + (f", {out['failure']}" if out["failure"] else "")
            + ")",
            f"{np.median(stairs_plan) * 1e3:.1f}" if stairs_plan else "-",
            "ms",
        ),
        ("control tick (observer + feedback law)", f"{tick * 1e6:.2f}", "us"),
    ]


def _replanning_walk(planner, terrain, footsteps: int, perturb: bool, seed: int):
    """Replan 4 steps at every footstep of a walk from the periodic gait's post-impact state,
    following each plan's first step; with ``perturb`` the next start state is moved off the
    plan (``q1`` by up to 0.01 rad, each velocity by up to 5 %). A replan cut by the planner's
    search budget goes on with the feasible steps it found, as the controller does ("shorter
    horizon"), when there are at least two. Returns the solve times after the first call [s],
    whether all footsteps were planned, and how many replans the budget cut."""
    rng = np.random.default_rng(seed)
    gait = planner.periodic_gait()
    state, stance, prev, times, cuts = (gait.q, gait.qd), (0.0, 0.0), None, [], 0
    for k in range(footsteps):
        t0 = time.perf_counter()
        try:
            plan = planner.plan(terrain, state, stance, horizon=4, previous_plan=prev)
        except PlanningError as exc:
            if not (exc.budget_exhausted and len(exc.partial) >= 2):
                return times, False, cuts
            plan = Plan(exc.partial, planner.params, planner.config)
            cuts += 1
        if k > 0:
            times.append(time.perf_counter() - t0)
        q, qd = plan[0].post_impact_state()
        if perturb:
            q = q + np.array([0.01 * rng.uniform(-1.0, 1.0), 0.0])
            qd = qd * (1.0 + 0.05 * rng.uniform(-1.0, 1.0, 2))
        state, stance, prev = (q, qd), plan[0].foothold, plan
    return times, True, cuts


def planner_section(args: argparse.Namespace) -> list[Row]:
    """Gait planner of the paper robot: replanning time per footstep (4-step horizon, 15
    footsteps; median over the footsteps of all courses) from the planned post-impact state and
    from a perturbed one, the share of random-block courses planned to the end, and the
    replanning time per footstep of the reference policy walking the rough environment."""
    seeds = 2 if args.quick else 8
    courses = {
        "flat": [Terrain.flat()],
        "paper stairs": [Terrain.from_yaml(CONFIG_DIR / "terrains" / "paper_stairs.yaml")],
        "stairs up 3 x 1 cm": [Terrain.staircase(0.4, 3, 0.3, 0.01)],
    }
    for h in (0.005, 0.01):
        courses[f"random blocks +-{h * 1e3:.0f} mm, 0.15-0.3 m"] = [
            Terrain.random_blocks(s, 0.3, 3.0, (0.15, 0.3), (-h, h)) for s in range(seeds)
        ]
    rows: list[Row] = []
    changes = dict(args.planner or ())
    planner = GaitPlanner("paper", changes)
    for name, terrains in courses.items():
        for perturb in (False, True):
            times, ok, cuts = [], 0, 0
            for i, terrain in enumerate(terrains):
                t, good, cut = _replanning_walk(planner, terrain, 15, perturb, seed=i)
                times += t
                ok += good
                cuts += cut
            label = f"replanning per footstep, {name}" + (", perturbed" if perturb else "")
            if len(terrains) > 1:
                label += f" ({ok}/{len(terrains)} courses planned"
                label += f", {cuts} replans cut by the budget)" if cuts else ")"
            value = f"{np.median(times) * 1e3:.1f}" if times else "-"
            rows.append((label, value, "ms"))
    episodes = args.episodes or (2 if args.quick else 6)
    # the defaults, and the previous defaults (SciPy's SLSQP driven from Python instead of the
    # compiled SQP) on the same courses, course by course in turn
    for difficulty in (1.0, 2.0):
        rows += _closed_loop_replanning(episodes, difficulty, [{}, {"compiled_sqp": 0}], changes)
    return rows


def _walk(
    env: gym.Env,
    act: Callable[[np.ndarray], np.ndarray],
    seed: int,
    reset: Callable[[], None] | None = None,
    limit: int | None = None,
) -> int:
    """Walk one episode of ``env`` from ``reset(seed=seed)`` with the actions ``act(obs)``
    (``reset``: called after the env's, e.g. the policy's), until it ends or for ``limit``
    steps; the steps walked."""
    obs, _ = env.reset(seed=seed)
    if reset is not None:
        reset()
    n, done = 0, False
    while not done and (limit is None or n < limit):
        obs, _, terminated, truncated, _ = env.step(act(obs))
        done = terminated or truncated
        n += 1
    return n


#: env steps each setting of the closed-loop rows walks untimed first (10 ms each: the first
#: footsteps, with their replans and identification fits)
_WARM_UP_STEPS = 300


def _closed_loop_replanning(
    episodes: int,
    difficulty: float,
    planners: list[dict],
    base: dict | None = None,
) -> list[Row]:
    """Replanning per footstep of the reference policy (sensors, observer, replanning at every
    touchdown) on ``CompassGaitRough-v0`` at ``difficulty``, evaluation seeds 1,001,000 on,
    with each of ``planners`` (changes to the robot's planner defaults, named in the rows; {}:
    the defaults): median, 95th and 99th percentile over the footsteps of ``episodes`` episodes
    (the planner call, degradations included), and the step evaluations it spends (the same on
    any machine); the env steps per second of the whole loop (policy and env) against the bare
    env on the same courses under zero input; and the time of its online identification per
    fit (median, 95th percentile, largest). Each setting first walks the first
    :data:`_WARM_UP_STEPS` steps of the first course, untimed, then Python's garbage is
    collected (what the imports and the compilation left; the timed walks' own collections
    are timed). Then each course is walked with
    every setting and then by the bare env (as many steps as the first setting's walk) before
    the next course, so that a machine whose speed drifts during the run slows them alike.
    ``base``: planner changes of the whole run (``--planner``, named in the title)."""
    env = gym.make("roughwalk/CompassGaitRough-v0", difficulty=difficulty)
    policies = [ReferencePolicy(env, planner={**(base or {}), **p}) for p in planners]
    times: list[list[float]] = [[] for _ in planners]
    work: list[list[int]] = [[] for _ in planners]  # step evaluations: the machine aside
    fits: list[list[float]] = [[] for _ in planners]
    steps, seconds = [0] * len(planners), [0.0] * len(planners)
    bare_steps, bare_seconds = 0, 0.0
    zero = np.zeros(1, dtype=np.float32)
    for policy in policies:  # warm-up, untimed: the first footsteps' planning and fits
        _walk(env, policy, 1_001_000, policy.reset, _WARM_UP_STEPS)
    # the objects left by imports and compilation collected now, not in a timed footstep
    # (a full collection takes about as long as the slowest replans)
    gc.collect()
    for k in range(episodes):
        order = range(len(policies)) if k % 2 == 0 else range(len(policies) - 1, -1, -1)
        for i in order:  # every other course in the reverse order: neither always walks first
            policy = policies[i]
            t0 = time.perf_counter()
            n = _walk(env, policy, 1_001_000 + k, policy.reset)
            seconds[i] += time.perf_counter() - t0
            steps[i] += n
            times[i] += [r.plan_time for r in policy.records[1:] if r.plan_time > 0]
            work[i] += [r.plan_evaluations for r in policy.records[1:] if r.plan_time > 0]
            fits[i] += [r.seconds for r in policy.diagnostics["identified"]]
            if i == 0:
                walked = n
        # the bare env on the same course under zero input, as many steps
        t0, n = time.perf_counter(), 0
        while n < walked:
            n += _walk(env, lambda _: zero, 1_001_000 + k, limit=walked - n)
        bare_seconds += time.perf_counter() - t0
        bare_steps += n
    env.close()
    bare = bare_steps / bare_seconds
    rows: list[Row] = []
    for planner, t, w, f, n, sec in zip(planners, times, work, fits, steps, seconds):
        loop = n / sec
        median, p95, p99 = np.percentile(t, [50, 95, 99]) * 1e3 if t else (np.nan,) * 3
        f50, f95, fmax = (*np.percentile(f, [50, 95]), max(f)) if f else (np.nan,) * 3
        where = (
            f"reference policy, CompassGaitRough-v0 difficulty {difficulty:g} ({episodes} episodes)"
        )
        if planner:
            where += ", planner " + ", ".join(f"{k}={v}" for k, v in planner.items())
        rows += [
            (
                f"replanning per footstep in closed loop (median / p95 / p99): {where}",
                f"{median:.1f} / {p95:.1f} / {p99:.1f}",
                "ms",
            ),
            (
                f"step evaluations per footstep in closed loop (median / mean / p99): {where}",
                f"{np.median(w):.0f} / {np.mean(w):.0f} / {np.percentile(w, 99):.0f}" if w else "-",
                "",
            ),
            (
                f"reference policy in the loop, env steps/s (its own planning, identification "
                f"and sensors included) / the bare env, course by course in the same run: {where}",
                f"{loop:,.0f} / {bare:,.0f} (x{bare / loop:.0f})",
                "steps/s",
            ),
            (
                f"online identification per fit, first 6 footsteps (median / p95 / max): {where}",
                f"{f50 * 1e3:.0f} / {f95 * 1e3:.0f} / {fmax * 1e3:.0f}",
                "ms",
            ),
        ]
    return rows


#: benchmark sections, run in order: (title, function)
SECTIONS: list[tuple[str, Section]] = [
    ("simulator", simulator_section),
    ("environment", env_section),
    ("controller", controller_section),
    ("planner", planner_section),
]


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk bench`` to ``parser``."""
    parser.add_argument("--quick", action="store_true", help="short timings (a few seconds)")
    parser.add_argument(
        "--walkers",
        type=int_range(1, 1_000_000),
        default=1024,
        help="batch size of the batched benchmarks",
    )
    parser.add_argument(
        "--only",
        action="append",
        choices=[name for name, _ in SECTIONS],
        help="run only this section (repeatable)",
    )
    parser.add_argument(
        "--episodes",
        type=int_range(1, 10_000),
        help="episodes of each closed-loop planner row (default 6, 2 with --quick): the p99 of "
        "6 episodes is about their second-slowest footstep",
    )
    parser.add_argument(
        "--planner",
        nargs="+",
        type=key_value,
        metavar="KEY=VALUE",
        help="the gait planner's settings for the planner section (PlannerConfig fields over "
        "the paper robot's preset, e.g. compiled_sqp=0 for the previous default)",
    )


def run(args: argparse.Namespace) -> int:
    """``roughwalk bench`` with the parsed ``args``: run the sections, print one table; returns
    the exit status."""
    preset_config(PlannerConfig, "--planner", args.planner, "paper")  # checked before any timing
    announce_compilation(SIMULATOR_KERNELS + CONTROLLER_KERNELS)
    title = "roughwalk bench" + (" (quick)" if args.quick else "")
    if args.planner:
        title += ", planner " + ", ".join(f"{k}={v}" for k, v in args.planner)
    table = Table(title=title)
    table.add_column("section")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for name, section in SECTIONS:
        if args.only and name not in args.only:
            continue
        for i, (quantity, value, unit) in enumerate(section(args)):
            table.add_row(*(escape(c) for c in (name if i == 0 else "", quantity, value, unit)))
        table.add_section()
    Console().print(table)
    return 0
