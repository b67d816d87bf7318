"""Evaluation of a policy on held-out courses: success, footsteps, distance, speed, cost of
transport.

Seed split: training envs are seeded below 1,000,000 (``agents.config.TRAIN_SEED_LIMIT``);
evaluation episode ``k`` resets its env with seed ``1,000,000 + S + k`` (``seed=S``, S >= 0),
so evaluation courses are never the ones a training run starts from. Seeds 1,000,000 to
1,000,999 are the validation courses of the periodic evaluation during training (which selects
``best_model.zip``); ``seed`` defaults to 1000 (``agents.config.TEST_SEED``), past them. The
absolute seed of every episode is recorded in the JSON/CSV output: ``env.reset(seed=...)``
replays it.

Metrics per episode: success (no failure before the episode ended, i.e. the time limit was
reached), footsteps taken (until failure or time limit), distance walked [m], mean speed
[m/s] (distance over episode duration), motor work [J] (absolute, ``int |tau q1dot| dt``), and
cost of transport ``work / (m g distance)`` with ``m`` the robot's total mass. Summary: means
over episodes; the summary cost of transport is total work over total ``m g distance``.
"""

from __future__ import annotations

import csv
import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the roughwalk ids)
from agents.config import EVAL_SEED_OFFSET, MAX_SEED, TEST_SEED, ConfigError
from agents.policies import BASELINES, Policy
from agents.trained import TrainedPolicy, load_policy


def eval_seeds(seed: int, episodes: int) -> list[int]:
    """Absolute reset seeds of ``episodes`` evaluation episodes for user seed ``seed`` >= 0."""
    if seed < 0 or EVAL_SEED_OFFSET + seed + episodes - 1 > MAX_SEED:
        hi = MAX_SEED - EVAL_SEED_OFFSET - episodes + 1
        raise ValueError(
            f"seed = {seed} is out of range; allowed: [0, {hi}]"
            " (evaluation seeds are offset by 1,000,000 to stay disjoint from training seeds)"
        )
    if episodes < 1:
        raise ValueError(f"episodes = {episodes} is out of range; allowed: >= 1")
    return [EVAL_SEED_OFFSET + seed + k for k in range(episodes)]


@dataclass
class EpisodeResult:
    """One evaluation episode.

    Attributes:
        seed: the absolute reset seed (``env.reset(seed=seed)`` replays the episode).
        success: no failure before the episode ended.
        failure: the failure's name (``envs.FAILURES``), or None.
        steps: control steps taken.
        duration: ``steps`` times the control period [s].
        footsteps: footsteps taken.
        distance: distance walked [m].
        speed: ``distance / duration`` [m/s].
        motor_work: absolute motor work [J].
        cost_of_transport: ``motor_work / (m g distance)``, None without forward progress.
        episode_return: sum of the rewards.
    """

    seed: int
    success: bool
    failure: str | None
    steps: int
    duration: float
    footsteps: int
    distance: float
    speed: float
    motor_work: float
    cost_of_transport: float | None  # None when the walker made no forward progress
    episode_return: float


@dataclass
class Evaluation:
    """Episodes of one policy on one env, and their summary.

    Attributes:
        policy: the policy evaluated (a baseline's name or a model's path).
        env_id: Gymnasium id of the env.
        env_kwargs: keyword arguments the env was made with.
        episodes: the episodes, in seed order.
        total_mass: the robot's total mass [kg].
        gravity: gravitational acceleration [m/s^2].
        summary: the metrics over the episodes (computed by :func:`summarize` when empty).
    """

    policy: str
    env_id: str
    env_kwargs: dict[str, Any]
    episodes: list[EpisodeResult]
    total_mass: float
    gravity: float
    summary: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.summary:
            self.summary = summarize(self.episodes, self.total_mass, self.gravity)

    def to_dict(self) -> dict[str, Any]:
        """The evaluation as plain data (the JSON output)."""
        return {
            "policy": self.policy,
            "env_id": self.env_id,
            "env_kwargs": self.env_kwargs,
            "total_mass": self.total_mass,
            "gravity": self.gravity,
            "summary": self.summary,
            "episodes": [asdict(e) for e in self.episodes],
        }


def summarize(episodes: Sequence[EpisodeResult], total_mass: float, g: float) -> dict[str, Any]:
    """Aggregate metrics over episodes (see the module docstring)."""
    n = len(episodes)
    failed = [e for e in episodes if not e.success]
    distance = sum(e.distance for e in episodes)
    work = sum(e.motor_work for e in episodes)
    return {
        "episodes": n,
        "success_rate": sum(e.success for e in episodes) / n,
        "mean_footsteps": float(np.mean([e.footsteps for e in episodes])),
        "mean_footsteps_failed": (
            float(np.mean([e.footsteps for e in failed])) if failed else None
        ),
        "mean_distance": float(np.mean([e.distance for e in episodes])),
        "mean_speed": float(np.mean([e.speed for e in episodes])),
        "cost_of_transport": work / (total_mass * g * distance) if distance > 0 else None,
        "mean_return": float(np.mean([e.episode_return for e in episodes])),
        "failure_reasons": dict(Counter(e.failure for e in failed if e.failure)),
    }


def _robot(env: gym.Env) -> tuple[float, float, float]:
    """(total mass [kg], g [m/s^2], control period [s]) of a roughwalk env."""
    base = env.unwrapped
    params = base.params
    return float(params.total_mass), float(params.g), float(base.dt)


def run_episode(
    env: gym.Env, policy: Policy, seed: int, max_steps: int | None = None
) -> EpisodeResult:
    """Roll ``policy`` out on ``env`` from ``reset(seed=seed)`` until the episode ends (or
    after ``max_steps`` steps, if given)."""
    mass, g, dt = _robot(env)
    obs, info = env.reset(seed=seed)
    policy.reset()
    total_return = 0.0
    steps = 0
    work = 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total_return += float(reward)
        work += float(info.get("motor_work", 0.0))
        steps += 1
        if max_steps is not None and steps >= max_steps:
            break
    failure = info.get("failure") or None
    distance = float(info.get("distance", 0.0))
    duration = steps * dt
    return EpisodeResult(
        seed=seed,
        success=failure is None,
        failure=failure,
        steps=steps,
        duration=duration,
        footsteps=int(info.get("footsteps", 0)),
        distance=distance,
        speed=distance / duration if duration > 0 else 0.0,
        motor_work=work,
        cost_of_transport=work / (mass * g * distance) if distance > 0 else None,
        episode_return=total_return,
    )


def make_eval_env(
    policy_spec: str,
    env_id: str | None,
    env_kwargs: dict[str, Any] | None = None,
    vecnormalize: str | None = None,
) -> tuple[gym.Env, Policy, str, dict[str, Any]]:
    """The env (with the agent's wrappers) and the policy for ``policy_spec``.

    Args:
        policy_spec: a baseline's name (``BASELINES``) or the path of a trained model.
        env_id: Gymnasium id; None for a trained model's own env (from its run).
        env_kwargs: keyword arguments of ``gym.make`` (default: a trained model's own).
        vecnormalize: a trained model's ``VecNormalize`` statistics (default: beside it).

    Returns:
        ``(env, policy, env_id, env_kwargs)``, with the env id and keyword arguments used.
    """
    trained = None
    if policy_spec not in BASELINES:
        trained = load_policy(policy_spec, vecnormalize=vecnormalize)
        assert isinstance(trained, TrainedPolicy)
        if env_id is None and trained.config is not None:
            env_id = trained.config.env_id
            if env_kwargs is None:
                env_kwargs = trained.config.env_kwargs
    if env_id is None:
        raise ConfigError("--env is required (no run manifest to take it from)")
    if env_id not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("roughwalk/"))
        raise ConfigError(f"unknown environment id {env_id!r}; registered: {', '.join(ours)}")
    env_kwargs = dict(env_kwargs or {})
    env = gym.make(env_id, **env_kwargs)
    if trained is not None:
        env = trained.wrap_env(env)
        if env.observation_space.shape != trained.model.observation_space.shape:
            raise ConfigError(
                f"{policy_spec}: the model expects observations of shape "
                f"{trained.model.observation_space.shape}, {env_id} gives "
                f"{env.observation_space.shape}"
            )
        return env, trained, env_id, env_kwargs
    return env, load_policy(policy_spec, env), env_id, env_kwargs


def evaluate(
    policy_spec: str,
    env_id: str | None,
    episodes: int = 20,
    seed: int = TEST_SEED,
    env_kwargs: dict[str, Any] | None = None,
    vecnormalize: str | None = None,
    progress: bool = False,
) -> Evaluation:
    """Evaluate a baseline (``passive``, ``pd``, ``reference``) or a trained model (path).

    Args:
        policy_spec: a baseline's name or the path of a trained model (``.zip``).
        env_id: Gymnasium id; None for a trained model's own env.
        episodes: number of episodes.
        seed: user seed; episode ``k`` resets with ``EVAL_SEED_OFFSET + seed + k``.
        env_kwargs: keyword arguments of ``gym.make`` (default: a trained model's own).
        vecnormalize: a trained model's ``VecNormalize`` statistics (default: beside it).
        progress: show a progress bar.
    """
    seeds = eval_seeds(seed, episodes)
    env, policy, env_id, env_kwargs = make_eval_env(policy_spec, env_id, env_kwargs, vecnormalize)
    mass, g, _ = _robot(env)
    iterator: Any = seeds
    if progress:
        from rich.progress import track

        iterator = track(seeds, description=f"{Path(policy_spec).name} on {env_id}")
    try:
        results = [run_episode(env, policy, s) for s in iterator]
    finally:
        env.close()
    return Evaluation(policy_spec, env_id, env_kwargs, results, mass, g)


def write_json(evaluations: Sequence[Evaluation], path: str | Path) -> None:
    """Write the ``evaluations`` with their per-episode results to ``path`` as JSON (one
    object for one evaluation, else a list)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    data = [ev.to_dict() for ev in evaluations]
    Path(path).write_text(json.dumps(data[0] if len(data) == 1 else data, indent=2) + "\n")


def write_csv(evaluations: Sequence[Evaluation], path: str | Path) -> None:
    """Write the episodes of the ``evaluations`` to ``path`` as CSV: one row per episode,
    with the policy and env in the first columns."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in EpisodeResult.__dataclass_fields__.values()]
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["policy", "env_id", "env_kwargs", *names])
        for ev in evaluations:
            kw = json.dumps(ev.env_kwargs, sort_keys=True)
            for e in ev.episodes:
                writer.writerow([ev.policy, ev.env_id, kw, *(getattr(e, n) for n in names)])


def read_monitor_logs(folder: str | Path) -> np.ndarray:
    """Training episodes of SB3 ``Monitor`` logs: rows ``(return, length, t)`` of all envs in
    ``folder``, in order of wall time ``t`` [s], then those of each resumed segment
    (``folder/resume1``, ``resume2``, ...)."""
    folder = Path(folder)
    segments = [folder] + sorted(
        folder.glob("resume*"), key=lambda p: int(p.name.removeprefix("resume") or 0)
    )
    parts = []
    for seg in segments:
        rows = []
        for path in sorted(seg.glob("*.monitor.csv")):
            with open(path) as fh:
                fh.readline()  # JSON header
                rows += [(float(r["r"]), float(r["l"]), float(r["t"])) for r in csv.DictReader(fh)]
        data = np.array(rows, dtype=np.float64).reshape(-1, 3)
        parts.append(data[np.argsort(data[:, 2], kind="stable")])
    return np.concatenate(parts)


def plot_learning_curve(run_dir: str | Path, out: str | Path) -> Path:
    """Plot the training episode returns and the periodic evaluation returns of the run in
    ``run_dir`` against env steps; writes the PNG ``out`` and returns its path."""
    from matplotlib.figure import Figure

    run_dir = Path(run_dir)
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    plotted = False
    episodes = read_monitor_logs(run_dir / "monitor")
    if len(episodes):
        steps = np.cumsum(episodes[:, 1])
        window = max(1, len(episodes) // 50)
        ret = np.convolve(episodes[:, 0], np.ones(window) / window, mode="valid")
        ax.plot(steps[window - 1 :], ret, lw=1, label=f"training (mean of {window} episodes)")
        plotted = True
    evals = run_dir / "eval" / "evaluations.npz"
    if evals.is_file():
        data = np.load(evals)
        mean, std = data["results"].mean(axis=1), data["results"].std(axis=1)
        ax.errorbar(data["timesteps"], mean, yerr=std, fmt="o-", ms=3, label="held-out evaluation")
        plotted = True
    if not plotted:
        raise FileNotFoundError(f"{run_dir}: no monitor logs or evaluations to plot")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(run_dir.name)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out
