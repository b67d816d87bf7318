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
from dataclasses import dataclass
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
    latest_run,
    read_manifest,
    refuse_earlier_outputs,
)
from agents.train import run_dir_for, train
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
        rows: one dict per (setting, policy) with ``setting``, ``policy``, ``budget``,
            ``command`` and, unless a dry run, ``summary`` (the columns of ``compare.md``).
        evaluations: the evaluations behind the rows, in row order (none in a dry run).
    """

    rows: list[dict[str, Any]]
    evaluations: list[Evaluation]


def agent_label(cfg: AgentConfig) -> str:
    """``PPO``, ``residual SAC``, ..."""
    return ("residual " if cfg.is_residual else "") + cfg.algo.upper()


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
    base = run_dir_for(cfg, log_dir).name
    finished = latest_run(log_dir, base, FINISHED)
    if finished is not None:
        return finished
    if not train_missing:
        raise FileNotFoundError(
            f"no finished run of {cfg.name} in {log_dir} (run: roughwalk train "
            f"{_display(cfg.path)} --log-dir {log_dir})"
        )
    interrupted = latest_run(log_dir, base, INTERRUPTED)
    if interrupted is not None and _same_config(interrupted, cfg):
        stops = read_manifest(interrupted).get("interruptions") or [{}]
        checkpoint = stops[-1].get("checkpoint")
        if checkpoint and Path(checkpoint).is_file():
            print(f"resuming the interrupted run {interrupted} from {checkpoint}")
            return train(cfg, log_dir=None, resume=checkpoint, progress_bar=progress, threads=None)
    return train(cfg, log_dir=log_dir, progress_bar=progress, threads=None)


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
) -> Comparison:
    """Run the comparison; returns its rows and evaluations (see :class:`Comparison`).

    Args:
        config_dir: folder of the agent configs.
        log_dir: folder of the training runs (one per config, see ``agents.train``).
        out: folder of ``compare.json``, ``compare.csv`` and ``compare.md``.
        episodes: evaluation episodes per row.
        seed: user seed of the held-out test courses (as :func:`agents.evaluate.evaluate`).
        only: only the agent configs whose name contains this.
        baselines: the baseline rows.
        settings: the terrain settings.
        train_missing: train the agents without a finished run (else raise
            ``FileNotFoundError``).
        hyperparams: hyperparameters overriding those of every config.
        dry_run: list the rows and their commands only; train, evaluate and write nothing.
        progress: show progress bars.
        overwrite: replace the outputs of an earlier comparison in ``out`` (else that is an
            error).

    Raises:
        ConfigError, ValueError: bad arguments or configs, an output or log folder that cannot
            be written, an earlier comparison in ``out`` (without ``overwrite``); before anything
            is trained, evaluated or written.
    """
    for name, value, low in (("--episodes", episodes, 1), ("--seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name}: must be an integer >= {low}, got {value!r}")
    configs = load_agent_configs(Path(config_dir), only, hyperparams)
    if not dry_run:
        check_writable(out, "--out")
        check_writable(log_dir, "--log-dir")
        refuse_earlier_outputs(out, OUTPUTS, overwrite, "comparison")
    rows: list[dict[str, Any]] = []
    evaluations: list[Evaluation] = []
    for s in settings:
        for name in baselines:
            cmd = evaluate_command(name, s, episodes, seed)
            row = {"setting": s.name, "policy": name, "budget": "-", "command": cmd}
            if not dry_run:
                ev = evaluate(name, s.env_id, episodes, seed, s.kwargs, progress=progress)
                evaluations.append(ev)
                row["summary"] = ev.summary
            rows.append(row)
        agents = sorted((c for c in configs if s.matches(c)), key=lambda c: (c.is_residual, c.algo))
        for cfg in agents:  # from scratch first, then residual
            train_cmd = f"roughwalk train {_display(cfg.path)} --log-dir {log_dir}"
            if dry_run:
                base = run_dir_for(cfg, log_dir)
                run_dir = latest_run(log_dir, base.name, FINISHED) or base
            else:
                run_dir = agent_run(cfg, Path(log_dir), train_missing, progress)
            model = chosen_model(run_dir)
            cmd = f"{train_cmd} && " + evaluate_command(str(model), s, episodes, seed)
            row = {"setting": s.name, "policy": agent_label(cfg), "command": cmd}
            if not dry_run:
                ev = evaluate(str(model), s.env_id, episodes, seed, s.kwargs, progress=progress)
                evaluations.append(ev)
                row["summary"] = ev.summary
            row["budget"] = budget(cfg, run_dir)
            rows.append(row)
    if not dry_run:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(
            out / "compare.json",
            json.dumps({"rows": rows, "evaluations": [e.to_dict() for e in evaluations]}, indent=2)
            + "\n",
        )
        atomic_write(out / "compare.csv", lambda tmp: write_csv(evaluations, tmp))
        atomic_write_text(out / "compare.md", markdown_table(rows))
    return Comparison(rows, evaluations)


def _cell(summary: dict[str, Any] | None, key: str, spec: str, scale: float = 1.0) -> str:
    if summary is None or summary.get(key) is None:
        return "-"
    return format(summary[key] * scale, spec)


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The README table (markdown) of the comparison's ``rows``: one line per (setting,
    policy)."""
    lines = [
        "| terrain | policy | success [%] | footsteps | distance [m] | speed [m/s] | CoT "
        "| failures | training budget | command |",
        "|---|---|---:|---:|---:|---:|---:|---|---|---|",
    ]
    for r in rows:
        s = r.get("summary")
        reasons = (s or {}).get("failure_reasons") or {}
        failures = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "-"
        lines.append(
            f"| {r['setting']} | {r['policy']} | {_cell(s, 'success_rate', '.0f', 100)} "
            f"| {_cell(s, 'mean_footsteps', '.1f')} | {_cell(s, 'mean_distance', '.2f')} "
            f"| {_cell(s, 'mean_speed', '.3f')} | {_cell(s, 'cost_of_transport', '.3f')} "
            f"| {failures if s else '-'} | {r['budget']} | `{r['command']}` |"
        )
    return "\n".join(lines) + "\n"
