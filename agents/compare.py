"""The RL-versus-control comparison: baselines and every agent config, one table.

For each terrain setting (flat, the paper's stairs, rough blocks at two difficulty levels)
:func:`compare` evaluates the baselines (passive, PD, reference controller) and, for every
config in ``configs/agents`` whose env matches the setting, trains the agent (unless the log
folder already has a finished run of it: the latest one is reused; an interrupted run of the
same config is resumed) and evaluates it (the best model of the periodic evaluations on the
validation courses, else the final one; see :func:`chosen_model`), all on the same held-out
test seeds. It writes ``compare.json`` (every episode), ``compare.csv`` and ``compare.md`` (the
summary table with the command reproducing each row and the env steps each agent was really
trained for; see :func:`markdown_table`) to its output folder.
"""

from __future__ import annotations

import datetime as dt
import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.config import TEST_SEED, AgentConfig, ConfigError, load_config
from agents.evaluate import Evaluation, evaluate, write_csv
from agents.runs import (
    FINISHED,
    INTERRUPTED,
    atomic_write,
    atomic_write_text,
    check_writable,
    claim_output_folder,
    latest_run,
    read_manifest,
)
from agents.stats import wilson_interval
from agents.sweep.aggregate import GROUP_METRIC, across_seeds
from agents.sweep.backends import BACKENDS, import_ray, map_calls
from agents.train import run_dir_for, set_threads, train
from configs import CONFIG_DIR as _CONFIGS

CONFIG_DIR = _CONFIGS / "agents"


@dataclass(frozen=True)
class Setting:
    """A column of the comparison: an env id with keyword arguments.

    Attributes:
        name: the column's name (``flat``, ``rough``, ...).
        env_id: Gymnasium id.
        env_kwargs: keyword arguments of ``gym.make``, as ``(name, value)`` pairs.
    """

    name: str
    env_id: str
    env_kwargs: tuple[tuple[str, Any], ...] = ()

    @property
    def kwargs(self) -> dict[str, Any]:
        """``env_kwargs`` as a dict."""
        return dict(self.env_kwargs)

    def matches(self, cfg: AgentConfig) -> bool:
        """Whether the agent config ``cfg`` trains on this setting's env and keyword
        arguments."""
        return cfg.env_id == self.env_id and cfg.env_kwargs == self.kwargs


SETTINGS = (
    Setting("flat", "roughwalk/CompassGaitFlat-v0"),
    Setting("stairs", "roughwalk/CompassGaitStairs-v0"),
    Setting("rough", "roughwalk/CompassGaitRough-v0", (("difficulty", 1.0),)),
    Setting("rough-hard", "roughwalk/CompassGaitRough-v0", (("difficulty", 2.0),)),
)
BASELINE_ROWS = ("passive", "pd", "reference")


@dataclass(frozen=True)
class Comparison:
    """What :func:`compare` returns.

    Attributes:
        rows: one dict per (setting, policy, training seed) with ``setting``, ``policy``,
            ``seed`` (None for a baseline), ``budget``, ``command`` and, unless a dry run,
            ``summary`` (the columns of ``compare.md``).
        evaluations: the evaluations behind the rows, in row order (none in a dry run).
        across_seeds: the statistics across training seeds (:func:`across_training_seeds`;
            empty in a dry run).
    """

    rows: list[dict[str, Any]]
    evaluations: list[Evaluation]
    across_seeds: dict[str, Any] = field(default_factory=dict)


def agent_label(cfg: AgentConfig) -> str:
    """``PPO``, ``residual SAC``, ``per-footstep PPO``, ``residual PPO (zero init)`` (the recipe of
    ``residual_init: zero``), ...: one label per kind of agent, the group its training seeds
    and settings are pooled in across seeds."""
    kind = "residual " if cfg.is_residual else "per-footstep " if cfg.is_footstep else ""
    label = kind + cfg.algo.upper()
    return label + (" (zero init)" if cfg.residual_init == "zero" else "")


def _kwargs_args(kwargs: dict[str, Any]) -> str:
    return (" --env-kwargs " + " ".join(f"{k}={v}" for k, v in kwargs.items())) if kwargs else ""


def evaluate_command(policy: str, s: Setting, episodes: int, seed: int) -> str:
    """The ``roughwalk evaluate`` command reproducing one row."""
    return (
        f"roughwalk evaluate --policy {policy} --env {s.env_id}{_kwargs_args(s.kwargs)}"
        f" --episodes {episodes} --seed {seed}"
    )


def _display(path: Path) -> str:
    """``path`` relative to the working directory when below it (commands in the table)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def chosen_model(run_dir: Path) -> Path:
    """The model a run reports: ``best_model.zip`` (the best of the periodic evaluations on
    the validation courses, disjoint from the test courses) when there is one, else the final
    ``model.zip``."""
    best = run_dir / "best_model.zip"
    return best if best.is_file() else run_dir / "model.zip"


def budget(cfg: AgentConfig, run_dir: Path) -> str:
    """What a run was trained for: the env steps it really trained (its manifest's
    ``num_timesteps``; the config's budget for a run not trained yet) and its training time."""
    m = read_manifest(run_dir) if (run_dir / "manifest.json").is_file() else {}
    text = f"{int(m.get('num_timesteps', cfg.n_timesteps)):,} steps"
    if "train_seconds" in m:
        text += f", {m['train_seconds'] / 60:.0f} min"
    elif "started" in m and "finished" in m:
        wall = dt.datetime.fromisoformat(m["finished"]) - dt.datetime.fromisoformat(m["started"])
        text += f", {wall.total_seconds() / 60:.0f} min"
    return text


def load_agent_configs(
    config_dir: Path, only: str | None, hyperparams: dict[str, Any] | None
) -> list[AgentConfig]:
    """Every config of ``config_dir`` (names containing ``only``, if given).

    Raises:
        ConfigError: no such folder, no config in it, none matching ``only``, a bad config.
    """
    config_dir = Path(config_dir)
    if not config_dir.is_dir():
        raise ConfigError(f"--configs {config_dir}: no such folder")
    paths = sorted(config_dir.glob("*.yaml"))
    if not paths:
        raise ConfigError(f"--configs {config_dir}: no agent configs (*.yaml) in it")
    if only:
        chosen = [p for p in paths if only in p.stem]
        if not chosen:
            names = ", ".join(p.stem for p in paths)
            raise ConfigError(f"--only {only}: matches none of the configs ({names})")
        paths = chosen
    return [load_config(p, hyperparams) for p in paths]


def _same_config(run_dir: Path, cfg: AgentConfig) -> bool:
    recorded = read_manifest(run_dir).get("config")
    return json.dumps(recorded, sort_keys=True) == json.dumps(cfg.to_dict(), sort_keys=True)


def agent_run(
    cfg: AgentConfig, log_dir: Path, train_missing: bool = True, progress: bool = True
) -> Path:
    """The run of ``cfg`` that :func:`compare` reports: the latest finished run of it in
    ``log_dir``; else its latest interrupted run with the same config, resumed; else a new
    run, trained (``train_missing``; else ``FileNotFoundError``)."""
    finished = finished_run(cfg, log_dir)
    if finished is not None:
        return finished
    if not train_missing:
        raise FileNotFoundError(
            f"no finished run of {cfg.name} (seed {cfg.seed}) in {log_dir} (run: roughwalk "
            f"train {_display(cfg.path)} --seed {cfg.seed} --log-dir {log_dir})"
        )
    base = run_dir_for(cfg, log_dir).name
    interrupted = latest_run(log_dir, base, INTERRUPTED)
    if interrupted is not None and _same_config(interrupted, cfg):
        stops = read_manifest(interrupted).get("interruptions") or [{}]
        checkpoint = stops[-1].get("checkpoint")
        if checkpoint and Path(checkpoint).is_file():
            print(f"resuming the interrupted run {interrupted} from {checkpoint}")
            return train(cfg, log_dir=None, resume=checkpoint, progress_bar=progress, threads=None)
    return train(cfg, log_dir=log_dir, progress_bar=progress, threads=None)


def finished_run(cfg: AgentConfig, log_dir: Path) -> Path | None:
    """The latest finished run of ``cfg`` (its config name and seed) in ``log_dir``, or None."""
    return latest_run(log_dir, run_dir_for(cfg, log_dir).name, FINISHED)


def _train_job(job: tuple[AgentConfig, Path, bool]) -> str:
    """One training of :func:`compare` (a Ray task, or a call in this process): the run
    folder of ``agent_run(cfg, log_dir, progress=progress)``, on one torch thread."""
    cfg, log_dir, progress = job
    set_threads(1)
    return str(agent_run(cfg, log_dir, True, progress))


def _evaluate_job(job: tuple[str, Setting, int, int, bool]) -> Evaluation:
    """One row's evaluation of :func:`compare` (a Ray task, or a call in this process)."""
    policy, s, episodes, seed, progress = job
    if policy not in BASELINE_ROWS:
        set_threads(1)
    return evaluate(policy, s.env_id, episodes, seed, s.kwargs, progress=progress)


def seed_configs(cfg: AgentConfig, seeds: Sequence[int] | None) -> list[AgentConfig]:
    """``cfg`` at each training seed of ``seeds`` (None: its own seed only).

    Raises:
        ConfigError: a seed out of the config's range (the message names it).
    """
    if seeds is None:
        return [cfg]
    return [cfg.with_seed(s) for s in seeds]


def _check_seeds(seeds: Sequence[int] | None) -> None:
    if seeds is None:
        return
    bad = [s for s in seeds if isinstance(s, bool) or not isinstance(s, int) or s < 0]
    if not seeds or bad:
        raise ValueError(f"--seeds: training seeds must be integers >= 0, got {list(seeds)!r}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds: repeated training seed in {list(seeds)!r}")


#: the files a comparison writes to its output folder
OUTPUTS = ("compare.json", "compare.csv", "compare.md")


def compare(
    config_dir: Path = CONFIG_DIR,
    log_dir: Path = Path("runs"),
    out: Path = Path("results"),
    episodes: int = 50,
    seed: int = TEST_SEED,
    only: str | None = None,
    baselines: tuple[str, ...] = BASELINE_ROWS,
    settings: tuple[Setting, ...] = SETTINGS,
    train_missing: bool = True,
    hyperparams: dict[str, Any] | None = None,
    dry_run: bool = False,
    progress: bool = True,
    overwrite: bool = False,
    seeds: Sequence[int] | None = None,
    backend: str = "serial",
    workers: int | None = None,
    address: str | None = None,
) -> Comparison:
    """Run the comparison; returns its rows and evaluations (see :class:`Comparison`).

    The trainings run first, all of them as independent jobs (Ray tasks with ``backend="ray"``:
    a cluster trains every config and seed at once), then the evaluations, also as jobs. The
    results do not depend on the backend or the number of workers.

    Args:
        config_dir: folder of the agent configs.
        log_dir: folder of the training runs (one per config and seed, see ``agents.train``;
            on a cluster it must be a folder every node reads and writes).
        out: folder of ``compare.json``, ``compare.csv`` and ``compare.md``.
        episodes: evaluation episodes per row.
        seed: user seed of the held-out test courses (as :func:`agents.evaluate.evaluate`).
        only: only the agent configs whose name contains this.
        baselines: the baseline rows.
        settings: the terrain settings.
        train_missing: train the agents without a finished run (else raise
            ``FileNotFoundError``, before anything is trained or evaluated).
        hyperparams: hyperparameters overriding those of every config.
        dry_run: list the rows and their commands only; train, evaluate and write nothing.
        progress: show progress bars (serial backend).
        overwrite: replace the outputs of an earlier comparison in ``out`` (else that is an
            error).
        seeds: training seeds of every agent (None: each config's own seed); one row per agent
            and seed, and the statistics across seeds (:func:`across_training_seeds`).
        backend: ``serial`` (this process) or ``ray`` (see :mod:`agents.sweep.backends`).
        workers: Ray: CPUs of a local instance (default: all cores), >= 1.
        address: Ray: a cluster's address (default: a local instance).

    Raises:
        ConfigError, ValueError: bad arguments or configs, an output or log folder that cannot
            be written, an earlier comparison in ``out`` (without ``overwrite``); before anything
            is trained, evaluated or written.
    """
    for name, value, low in (("--episodes", episodes, 1), ("--seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name}: must be an integer >= {low}, got {value!r}")
    _check_seeds(seeds)
    if backend not in BACKENDS:
        raise ValueError(f"--backend: unknown backend {backend!r}; allowed: {', '.join(BACKENDS)}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)):
        raise ValueError(f"--workers: must be an integer >= 1, got {workers!r}")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers: must be an integer >= 1, got {workers!r}")
    if backend == "ray" and not dry_run:
        import_ray()
    configs = load_agent_configs(Path(config_dir), only, hyperparams)
    log_dir = Path(log_dir)
    # from scratch first, then residual; each at every training seed
    plan = [
        (
            s,
            [
                c
                for cfg in sorted(matching, key=lambda c: (c.is_residual, c.algo))
                for c in seed_configs(cfg, seeds)
            ],
        )
        for s in settings
        for matching in [[c for c in configs if s.matches(c)]]
    ]
    work = {
        "episodes": episodes,
        "seed": seed,
        "baselines": baselines,
        "train_missing": train_missing,
        "progress": progress,
        "backend": backend,
        "workers": workers,
        "address": address,
    }
    if dry_run:
        return _compare(plan, log_dir, None, **work)
    check_writable(out, "--out")
    check_writable(log_dir, "--log-dir")
    with claim_output_folder(out, OUTPUTS, overwrite, "comparison"):
        return _compare(plan, log_dir, Path(out), **work)


def _compare(
    plan: list[tuple[Setting, list[AgentConfig]]],
    log_dir: Path,
    out: Path | None,
    *,
    episodes: int,
    seed: int,
    baselines: tuple[str, ...],
    train_missing: bool,
    progress: bool,
    backend: str,
    workers: int | None,
    address: str | None,
) -> Comparison:
    """The body of :func:`compare`: train what is missing, evaluate, and write the outputs to
    ``out``, which this process holds (None: a dry run, which lists the rows only)."""
    dry_run = out is None
    runs: dict[tuple[str, int], Path] = {}
    jobs: dict[tuple[str, int], AgentConfig] = {}
    for _, agents in plan:
        for cfg in agents:
            key = (cfg.name, cfg.seed)
            done = finished_run(cfg, log_dir)
            if done is not None:
                runs[key] = done
            elif dry_run:
                runs[key] = run_dir_for(cfg, log_dir)
            elif not train_missing:
                agent_run(cfg, log_dir, train_missing=False)  # raises, naming the run
            else:
                jobs[key] = cfg
    if jobs:
        serial_progress = progress and backend == "serial"
        trained = map_calls(
            _train_job,
            [(cfg, log_dir, serial_progress) for cfg in jobs.values()],
            backend,
            workers,
            address,
        )
        runs.update(zip(jobs, (Path(p) for p in trained)))
    rows: list[dict[str, Any]] = []
    calls: list[tuple[str, Setting, int, int, bool]] = []
    for s, agents in plan:
        for name in baselines:
            cmd = evaluate_command(name, s, episodes, seed)
            rows.append(
                {"setting": s.name, "policy": name, "seed": None, "budget": "-", "command": cmd}
            )
            calls.append((name, s, episodes, seed, progress and backend == "serial"))
        kinds = Counter(agent_label(c) for c in {c.name: c for c in agents}.values())
        for cfg in agents:
            label = agent_label(cfg)
            if kinds[label] > 1:  # two configs of one kind on a setting: not one agent's seeds
                label = f"{label} [{cfg.name}]"
            run_dir = runs[(cfg.name, cfg.seed)]
            model = chosen_model(run_dir)
            train_cmd = (
                f"roughwalk train {_display(cfg.path)} --seed {cfg.seed} --log-dir {log_dir}"
            )
            cmd = f"{train_cmd} && " + evaluate_command(str(model), s, episodes, seed)
            rows.append(
                {
                    "setting": s.name,
                    "policy": label,
                    "seed": cfg.seed,
                    "budget": budget(cfg, run_dir),
                    "command": cmd,
                }
            )
            calls.append((str(model), s, episodes, seed, progress and backend == "serial"))
    if dry_run:
        return Comparison(rows, [])
    evaluations = map_calls(_evaluate_job, calls, backend, workers, address)
    for row, ev in zip(rows, evaluations):
        row["summary"] = ev.summary
    seeds_stats = across_training_seeds(rows)
    data = {
        "rows": rows,
        "across_seeds": seeds_stats,
        "evaluations": [e.to_dict() for e in evaluations],
    }
    atomic_write_text(out / "compare.json", json.dumps(data, indent=2) + "\n")
    atomic_write(out / "compare.csv", lambda tmp: write_csv(evaluations, tmp))
    atomic_write_text(out / "compare.md", markdown_table(rows, seeds_stats))
    return Comparison(rows, list(evaluations), seeds_stats)


def across_training_seeds(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The success rates of the ``rows`` across training seeds, in the manner of ``rliable``
    (:func:`agents.sweep.aggregate.across_seeds`): per policy (an agent's seeds, or a baseline
    as a group of one run) the IQM of the runs' success rates over the settings with a
    stratified-bootstrap interval, and the probability that a run of one policy walks more
    courses than a run of another, averaged over the settings both ran on."""
    cells = [
        {
            "group": r["policy"],
            "policy": f"{r['policy']} s{r['seed']}" if r["seed"] is not None else r["policy"],
            "cell": f"{r['policy']}/{r['setting']}",
            GROUP_METRIC: r["summary"][GROUP_METRIC],
        }
        for r in rows
        if r.get("summary") is not None
    ]
    return (
        across_seeds(cells) if cells else {"metric": GROUP_METRIC, "groups": [], "improvement": []}
    )


def _cell(summary: dict[str, Any] | None, key: str, spec: str, scale: float = 1.0) -> str:
    if summary is None or summary.get(key) is None:
        return "-"
    return format(summary[key] * scale, spec)


def markdown_table(rows: list[dict[str, Any]], seeds_stats: dict[str, Any] | None = None) -> str:
    """The README table (markdown) of the comparison's ``rows``: one line per (setting,
    policy, training seed), the success rate with its Wilson 95 % interval; then, with
    ``seeds_stats`` (:func:`across_training_seeds`), the IQM of every policy across its training
    seeds and the probability of improvement of each agent over each baseline."""
    lines = [
        "| terrain | policy | seed | success [%] (95 % CI) | footsteps | distance [m] "
        "| speed [m/s] | CoT | failures | training budget | command |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|---|",
    ]
    for r in rows:
        s = r.get("summary")
        reasons = (s or {}).get("failure_reasons") or {}
        failures = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "-"
        seed = "-" if r.get("seed") is None else str(r["seed"])
        lines.append(
            f"| {r['setting']} | {r['policy']} | {seed} | {_success(s)} "
            f"| {_cell(s, 'mean_footsteps', '.1f')} | {_cell(s, 'mean_distance', '.2f')} "
            f"| {_cell(s, 'mean_speed', '.3f')} | {_cell(s, 'cost_of_transport', '.3f')} "
            f"| {failures if s else '-'} | {r['budget']} | `{r['command']}` |"
        )
    if seeds_stats and seeds_stats.get("groups"):
        lines += [
            "",
            "Across training seeds (success rate of each run; IQM over runs and settings, "
            "stratified bootstrap 95 %):",
            "",
            "| policy | settings | runs per setting | IQM success [%] (95 % CI) |",
            "|---|---:|---:|---|",
        ]
        for g in seeds_stats["groups"]:
            lo, hi = g["iqm_ci"]
            lines.append(
                f"| {g['group']} | {g['tasks']} | {g['runs']} "
                f"| {100 * g['iqm']:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) |"
            )
        pairs = [
            p
            for p in seeds_stats["improvement"]
            if (p["x"] in BASELINE_ROWS) != (p["y"] in BASELINE_ROWS)
        ]
        if pairs:
            lines += [
                "",
                "| agent | baseline | P(agent walks more courses) (95 % CI) |",
                "|---|---|---|",
            ]
            for p in pairs:
                agent, base, point = p["x"], p["y"], p["p_x_better"]
                lo, hi = p["p_x_better_ci"]
                if agent in BASELINE_ROWS:  # stored as P(baseline better)
                    agent, base, point, lo, hi = base, agent, 1 - point, 1 - hi, 1 - lo
                lines.append(f"| {agent} | {base} | {point:.2f} ({lo:.2f}-{hi:.2f}) |")
    return "\n".join(lines) + "\n"


def _success(summary: dict[str, Any] | None) -> str:
    """``rate (low-high)`` [%] with the Wilson 95 % interval, or ``-``."""
    if summary is None:
        return "-"
    n = int(summary["episodes"])
    k = round(summary["success_rate"] * n)
    lo, hi = wilson_interval(k, n)
    return f"{100 * k / n:.0f} ({100 * lo:.0f}-{100 * hi:.0f})"
