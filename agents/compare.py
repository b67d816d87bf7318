"""The RL-versus-control comparison: baselines and every agent config, one table.

For each terrain setting (flat, the paper's stairs, rough blocks at two difficulty levels)
:func:`compare` evaluates the baselines (passive, PD, reference controller) and, for every
config in ``configs/agents`` whose env matches the setting, trains the agent (unless its run
already has a final model) and evaluates it (the best model of the periodic evaluations on the
validation courses, else the final one; see :func:`chosen_model`), all on the same held-out
test seeds. It writes ``compare.json`` (every episode), ``compare.csv`` and ``compare.md`` (the
summary table with the command reproducing each row and the training budget; see
:func:`markdown_table`) to its output folder.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.config import TEST_SEED, AgentConfig, load_config
from agents.evaluate import Evaluation, evaluate, write_csv
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
    """Training budget of a run: env steps, and wall time from its manifest."""
    text = f"{cfg.n_timesteps:,} steps"
    manifest = run_dir / "manifest.json"
    if manifest.is_file():
        m = json.loads(manifest.read_text())
        if "started" in m and "finished" in m:
            wall = dt.datetime.fromisoformat(m["finished"]) - dt.datetime.fromisoformat(
                m["started"]
            )
            text += f", {wall.total_seconds() / 60:.0f} min"
    return text


def load_agent_configs(
    config_dir: Path, only: str | None, hyperparams: dict[str, Any] | None
) -> list[AgentConfig]:
    """Every config of ``config_dir`` (names containing ``only``, if given)."""
    paths = sorted(config_dir.glob("*.yaml"))
    if only:
        paths = [p for p in paths if only in p.stem]
    return [load_config(p, hyperparams) for p in paths]


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
        train_missing: train the agents without a final model (else raise
            ``FileNotFoundError``).
        hyperparams: hyperparameters overriding those of every config.
        dry_run: list the rows and their commands only; train, evaluate and write nothing.
        progress: show progress bars.
    """
    configs = load_agent_configs(Path(config_dir), only, hyperparams)
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
            run_dir = run_dir_for(cfg, log_dir)
            final = run_dir / "model.zip"
            train_cmd = f"roughwalk train {_display(cfg.path)} --log-dir {log_dir}"
            if not dry_run and not final.is_file():
                if not train_missing:
                    raise FileNotFoundError(f"{final} missing (run: {train_cmd})")
                train(cfg, log_dir=log_dir, progress_bar=progress, threads=None)
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
        (out / "compare.json").write_text(
            json.dumps({"rows": rows, "evaluations": [e.to_dict() for e in evaluations]}, indent=2)
            + "\n"
        )
        write_csv(evaluations, out / "compare.csv")
        (out / "compare.md").write_text(markdown_table(rows))
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
