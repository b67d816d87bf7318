"""Training an RL agent (stable-baselines3 PPO or SAC, from scratch or residual) from a config.

:func:`train` writes a new run folder ``<log_dir>/<config name>_s<seed>/`` (``..._2``,
``..._3``, ... when that exists: a run is never overwritten) holding:

- ``manifest.json``: the resolved config and its base policy's settings (``base_settings``),
  every seed used (training envs, evaluation courses),
  library versions, the command line, start/finish times, the status (``running``,
  ``interrupted``, ``finished``), the env steps asked (``n_timesteps``) and trained
  (``num_timesteps``) and any resumes and interruptions;
- ``model.zip`` + ``vecnormalize.pkl``: the final agent and its observation statistics;
- ``best_model.zip`` + ``best_vecnormalize.pkl``: the best agent on the held-out evaluations;
- ``checkpoints/rl_model_<N>_steps.zip`` + ``rl_model_vecnormalize_<N>_steps.pkl``;
- ``eval/evaluations.npz`` (periodic held-out evaluations), ``monitor/`` (training episodes),
  ``tb/`` (TensorBoard: ``tensorboard --logdir <run>/tb``).

Every model zip records its algorithm and config (``agents.runs.MODEL_INFO``), so that a model
copied out of its run can still be evaluated.

Training env ``i`` is seeded with ``seed + i`` (below 1,000,000); the periodic evaluation
resets its env with the fixed seeds ``1,000,000 + eval_seed + k`` before every evaluation, so
all evaluations use the same held-out courses.

Everything is checked before anything is written. When training stops with an exception
(Ctrl-C included) the model and its statistics are saved as a checkpoint, the manifest says
``interrupted``, and ``train(cfg, log_dir=None, resume=checkpoint)`` continues the run in its
folder up to the config's ``n_timesteps`` (a finished run is continued into a new folder).
Resuming unpickles the checkpoint, its statistics and replay buffer: resume only from files
you trust.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import platform
import shutil
import sys
import time
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs  # noqa: F401  (registers the roughwalk ids, also in subprocesses)
from agents.config import EVAL_SEED_OFFSET, AgentConfig, ConfigError
from agents.hyperparams import ON_POLICY
from agents.policies import base_settings
from agents.runs import (
    FINISHED,
    INTERRUPTED,
    MODEL_INFO,
    RUNNING,
    atomic_write_text,
    check_writable,
    create_run_dir,
    find_manifest,
    find_vecnormalize,
    model_algo,
    model_data,
    read_manifest,
    read_vecnormalize,
    replay_buffer_path,
    run_status,
    save_checkpoint,
    save_model,
    write_manifest,
)


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def versions() -> dict[str, str]:
    """Versions of the libraries a result depends on."""
    import stable_baselines3
    import torch

    out = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "gymnasium": gym.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
    }
    try:
        out["roughwalk"] = version("roughwalk")
    except Exception:  # noqa: BLE001  (not installed as a distribution)
        pass
    return out


def _make_env(env_id: str, **kwargs: Any) -> gym.Env:
    """``gym.make`` of a roughwalk id (module-level, so that subprocesses can unpickle it)."""
    return gym.make(env_id, **kwargs)


def make_vec_env(
    cfg: AgentConfig,
    n_envs: int,
    seed: int | None,
    monitor_dir: Path | None,
    vec_env: str | None = None,
    training: bool = True,
) -> Any:
    """``n_envs`` copies of the config's env (with its wrappers) as an SB3 ``VecEnv``.

    ``vec_env`` (default: the config's ``run.vec_env``): ``dummy`` (one process), ``subproc``
    (one process per env) or ``native`` (the batched vector env through
    ``agents.sb3_vec_env``; no env wrappers). Env ``i`` is seeded with ``seed + i``. Training
    envs (``training``) also get the training-only wrappers (the terrain curriculum).
    """
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor

    # the adapter subclasses SB3's VecEnv: imported with SB3, not with this module
    from agents.sb3_vec_env import make_sb3_vec_env

    kind = vec_env or cfg.vec_env
    if kind == "native":
        venv = make_sb3_vec_env(cfg.env_id, n_envs=n_envs, seed=seed, **cfg.env_kwargs)
        if monitor_dir is not None:
            monitor_dir.mkdir(parents=True, exist_ok=True)
            return VecMonitor(venv, filename=str(monitor_dir / "vec"))
        return VecMonitor(venv)
    wrapper = functools.partial(cfg.wrap, training=training) if cfg.wrapper_specs() else None
    return sb3_make_vec_env(
        functools.partial(_make_env, cfg.env_id),
        n_envs=n_envs,
        seed=seed,
        env_kwargs=cfg.env_kwargs,
        wrapper_class=wrapper,
        monitor_dir=str(monitor_dir) if monitor_dir else None,
        vec_env_cls=SubprocVecEnv if kind == "subproc" and n_envs > 1 else DummyVecEnv,
    )


def check_env(cfg: AgentConfig) -> None:
    """Make, wrap and reset one env of ``cfg`` (then close it), so that bad ``env_kwargs`` or
    wrapper arguments are a ConfigError before anything is written."""
    try:
        env = gym.make(cfg.env_id, **cfg.env_kwargs)
    except (ValueError, TypeError, KeyError) as exc:
        raise ConfigError(f"{cfg.path}: env_kwargs {cfg.env_kwargs}: {exc}") from exc
    try:
        env = cfg.wrap(env, training=True)
        env.reset(seed=cfg.seed)
    except (ValueError, TypeError, KeyError) as exc:
        raise ConfigError(f"{cfg.path}: env_wrapper: {exc}") from exc
    finally:
        env.close()


def make_callbacks(cfg: AgentConfig, run_dir: Path, eval_env: Any, report: bool = True) -> list:
    """Checkpoints (with VecNormalize statistics), held-out periodic evaluation, the critic
    warm-up (``run.critic_warmup``), the residual scale ramp (``run.scale_ramp``) and the
    terrain curriculum's log (with a ``TerrainCurriculum`` wrapper).

    Args:
        cfg: the agent config (frequencies in env steps, all envs together).
        run_dir: the run folder.
        eval_env: the evaluation VecEnv (None: no evaluation).
        report: print one line per evaluation.
    """
    # the callbacks subclass SB3's: imported with SB3, not with this module
    from agents.callbacks import (
        Checkpoint,
        CriticWarmup,
        CurriculumLog,
        HeldOutEvalCallback,
        ResidualScaleRamp,
        SaveBestModel,
    )
    from agents.curriculum import TerrainCurriculum

    callbacks: list = []
    if cfg.critic_warmup > 0:
        callbacks.append(CriticWarmup(cfg.critic_warmup))
    if cfg.scale_ramp > 0:
        callbacks.append(ResidualScaleRamp(cfg.scale_ramp))
    if any(issubclass(cls, TerrainCurriculum) for cls, _ in cfg.wrapper_specs()):
        callbacks.append(CurriculumLog())
    if cfg.checkpoint_freq > 0:
        callbacks.append(
            Checkpoint(
                cfg.checkpoint_freq // cfg.n_envs, run_dir / "checkpoints", cfg.save_replay_buffer
            )
        )
    if cfg.eval_freq > 0 and eval_env is not None:
        callbacks.append(
            HeldOutEvalCallback(
                eval_env,
                seed=EVAL_SEED_OFFSET + cfg.eval_seed,
                report=report,
                n_eval_episodes=cfg.eval_episodes,
                eval_freq=max(cfg.eval_freq // cfg.n_envs, 1),
                log_path=str(run_dir / "eval"),
                best_model_save_path=None,
                callback_on_new_best=SaveBestModel(run_dir),
                deterministic=True,
                verbose=0,
            )
        )
    return callbacks


def _restore_evaluations(callbacks: list, run_dir: Path, up_to: int) -> None:
    """Give a resumed run's evaluation callback the evaluations made up to the checkpoint."""
    from agents.callbacks import HeldOutEvalCallback  # with SB3, as in make_callbacks

    path = run_dir / "eval" / "evaluations.npz"
    if not path.is_file():
        return
    data = np.load(path)
    keep = data["timesteps"] <= up_to
    for cb in callbacks:
        if isinstance(cb, HeldOutEvalCallback):
            cb.evaluations_timesteps = [int(t) for t in data["timesteps"][keep]]
            cb.evaluations_results = [list(r) for r in data["results"][keep]]
            cb.evaluations_length = [list(r) for r in data["ep_lengths"][keep]]
            if len(cb.evaluations_results):
                cb.best_mean_reward = float(np.max(np.mean(data["results"][keep], axis=1)))


def set_threads(threads: int | None) -> None:
    """Set the number of torch threads (None: leave torch's default)."""
    if threads is not None:
        import torch

        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"--threads: must be an integer >= 1, got {threads!r}")
        torch.set_num_threads(threads)


def run_dir_for(cfg: AgentConfig, log_dir: str | Path) -> Path:
    """The first run folder of ``cfg`` in ``log_dir``: ``<log_dir>/<config name>_s<seed>``
    (later runs of the same config and seed are numbered, see
    ``agents.runs.create_run_dir``)."""
    return Path(log_dir) / f"{cfg.name}_s{cfg.seed}"


@dataclass
class ResumePoint:
    """A checkpoint read and checked before a resumed training writes anything.

    Attributes:
        path: the checkpoint ``.zip``.
        num_timesteps: env steps it was trained for.
        run_dir: the run folder it belongs to (the folder of its manifest), or None.
        vecnormalize: its ``VecNormalize`` statistics (no env attached), or None.
        replay_buffer: its replay buffer, or None.
    """

    path: Path
    num_timesteps: int
    run_dir: Path | None
    vecnormalize: Any = None
    replay_buffer: Any = None


def read_checkpoint(cfg: AgentConfig, checkpoint: str | Path) -> ResumePoint:
    """Read and check the checkpoint ``checkpoint`` for continuing ``cfg``: the model zip,
    the ``VecNormalize`` statistics saved beside it (when ``cfg`` normalises) and its replay
    buffer, if saved. Unpickles them: read only files you trust.

    Raises:
        FileNotFoundError: no such checkpoint.
        ValueError: unreadable files (truncated, corrupted), another algorithm, missing
            statistics; the message names ``--resume``.
    """
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.save_util import load_from_pkl, load_from_zip_file

    path = Path(checkpoint)
    if not path.is_file():
        raise FileNotFoundError(f"--resume {path}: no such checkpoint file")
    try:
        data = model_data(path)
        load_from_zip_file(path, device="cpu")
    except Exception as exc:  # noqa: BLE001  (a corrupted zip can raise anything)
        raise ValueError(f"--resume {path}: cannot read the model ({exc})") from None
    algo = model_algo(data)
    if algo is not None and algo != cfg.algo:
        raise ValueError(f"--resume {path}: a {algo.upper()} model, the config trains {cfg.algo}")
    env_id = ((data.get(MODEL_INFO) or {}).get("config") or {}).get("run", {}).get("env")
    if env_id is not None and env_id != cfg.env_id:
        raise ValueError(f"--resume {path}: trained on {env_id}, the config's env is {cfg.env_id}")
    vn = None
    if cfg.normalize_kwargs is not None:
        vn_path = find_vecnormalize(path)
        if vn_path is None:
            raise ValueError(
                f"--resume {path}: no VecNormalize statistics beside it "
                f"(the config normalises observations)"
            )
        try:
            vn = read_vecnormalize(vn_path)
        except ValueError as exc:
            raise ValueError(f"--resume: {exc}") from None
    rb = None
    rb_path = replay_buffer_path(path)
    if rb_path is not None and rb_path.is_file() and cfg.algo in ("sac", "td3"):
        try:
            rb = load_from_pkl(rb_path)
        except Exception as exc:  # noqa: BLE001
            raise ValueError(
                f"--resume: {rb_path}: cannot read the replay buffer ({exc})"
            ) from None
        if not isinstance(rb, ReplayBuffer):
            raise ValueError(f"--resume: {rb_path}: not a replay buffer")
    manifest = find_manifest(path)
    return ResumePoint(
        path, int(data.get("num_timesteps", 0)), manifest.parent if manifest else None, vn, rb
    )


def _segment_dir(folder: Path, prefix: str) -> Path:
    """``folder`` if it holds nothing yet, else ``folder/<prefix><n>`` for the next n (one
    subfolder per resumed segment; the earlier logs are kept)."""
    if not folder.exists() or not any(folder.iterdir()):
        return folder
    return folder / f"{prefix}{len(list(folder.glob(prefix + '*'))) + 1}"


def _logger(run_dir: Path, name: str, tensorboard: bool, verbose: int) -> Any:
    """SB3's logger of a run, configured here: SB3's default would create an empty
    ``SB3-<date>`` folder in the system's temporary folder for every run without
    TensorBoard."""
    from stable_baselines3.common.logger import HumanOutputFormat, Logger

    formats: list = [HumanOutputFormat(sys.stdout)] if verbose >= 1 else []
    folder = None
    if tensorboard:
        try:
            import tensorboard as _tb  # noqa: F401
            from stable_baselines3.common.logger import TensorBoardOutputFormat

            tb = run_dir / "tb"
            folder = tb / f"{name}_{len(list(tb.glob(name + '_*'))) + 1 if tb.exists() else 1}"
            formats.append(TensorBoardOutputFormat(str(folder)))
        except ImportError:
            print("tensorboard is not installed: no TensorBoard logs")
    return Logger(str(folder) if folder else None, formats)


def build(
    cfg: AgentConfig,
    run_dir: Path,
    resume: str | Path | ResumePoint | None = None,
    tensorboard: bool = True,
    verbose: int = 0,
) -> tuple[Any, Any, Any]:
    """The model, its training VecEnv and the evaluation VecEnv (None without evaluation).

    On failure it removes the log folders it created and closes the envs.

    Args:
        cfg: the agent config.
        run_dir: the run directory (monitor logs, TensorBoard logs).
        resume: build from this checkpoint (a path, or read by :func:`read_checkpoint`), with
            its VecNormalize statistics and, if saved, its replay buffer (default: from
            scratch).
        tensorboard: write TensorBoard logs (if tensorboard is installed).
        verbose: SB3 verbosity (0, 1, 2).
    """
    from stable_baselines3.common.vec_env import VecFrameStack, VecNormalize

    point = read_checkpoint(cfg, resume) if isinstance(resume, str | Path) else resume
    monitor = _segment_dir(run_dir / "monitor", "resume")
    tb_before = set((run_dir / "tb").iterdir()) if (run_dir / "tb").is_dir() else set()
    new_monitor = not monitor.exists()
    env = eval_env = None
    try:
        env = make_vec_env(cfg, cfg.n_envs, cfg.seed, monitor)
        eval_kind = "native" if cfg.vec_env == "native" else "dummy"  # same wrapper chain
        if cfg.eval_freq:
            eval_env = make_vec_env(
                cfg, 1, EVAL_SEED_OFFSET + cfg.eval_seed, None, eval_kind, training=False
            )
        norm = cfg.normalize_kwargs
        if norm is not None:
            if point is not None:
                point.vecnormalize.set_venv(env)
                env = point.vecnormalize
                env.training = True
            else:
                env = VecNormalize(env, **norm)
            if eval_env is not None:
                eval_env = VecNormalize(
                    eval_env, **{**norm, "training": False, "norm_reward": False}
                )
        if cfg.frame_stack:  # over the normalised observations, as rl-zoo3 stacks them
            env = VecFrameStack(env, cfg.frame_stack)
            if eval_env is not None:
                eval_env = VecFrameStack(eval_env, cfg.frame_stack)
        model = _model(cfg, env, point, verbose)
        model.set_logger(_logger(run_dir, cfg.name, tensorboard, verbose))
    except BaseException:
        for e in (env, eval_env):
            if e is not None:
                e.close()
        if new_monitor and monitor != run_dir / "monitor":
            shutil.rmtree(monitor, ignore_errors=True)
        if (run_dir / "tb").is_dir():
            for p in set((run_dir / "tb").iterdir()) - tb_before:
                shutil.rmtree(p, ignore_errors=True)
        raise
    return model, env, eval_env


def _model(cfg: AgentConfig, env: Any, point: ResumePoint | None, verbose: int) -> Any:
    """The SB3 model on ``env``: new, or loaded from ``point``; records ``MODEL_INFO``."""
    algo_cls = cfg.algo_class
    if point is not None:
        try:
            model = algo_cls.load(str(point.path), env=env, device="cpu")
        except (ValueError, AssertionError, KeyError, RuntimeError) as exc:
            raise ValueError(f"--resume {point.path}: does not fit {cfg.path}: {exc}") from exc
        if point.replay_buffer is not None:
            model.replay_buffer = point.replay_buffer
            model.replay_buffer.device = model.device
    else:
        try:
            model = algo_cls(
                env=env, seed=cfg.seed, device="cpu", verbose=verbose, **cfg.algo_kwargs()
            )
        except (TypeError, ValueError, AssertionError) as exc:
            raise ConfigError(
                f"{cfg.path}: {cfg.algo.upper()} rejects the hyperparameters: {exc}"
            ) from exc
        if cfg.residual_init == "zero" or cfg.init_log_std is not None:
            from agents.residual import init_policy

            init_policy(model, cfg.residual_init == "zero", cfg.init_log_std)
    info = {"algo": cfg.algo, "config": json.loads(json.dumps(cfg.to_dict(), default=str))}
    setattr(model, MODEL_INFO, info)
    return model


def save(model: Any, path: str | Path) -> None:
    """Save ``model`` to ``path`` (.zip) and its VecNormalize statistics beside it (see
    ``agents.runs.vecnormalize_path``), each file all or nothing."""
    save_model(model, path)


def _resume_target(point: ResumePoint, log_dir: str | Path | None) -> tuple[Path | None, Path]:
    """(the run folder to continue in place, or None for a new run; the log folder of a new
    run) for a resumed training."""
    if log_dir is not None:
        return None, Path(log_dir)
    if point.run_dir is None:
        raise ValueError(
            f"--resume {point.path}: not inside a run folder (no manifest.json beside it or "
            "above it); give --log-dir for the new run"
        )
    if run_status(read_manifest(point.run_dir)) == FINISHED:
        return None, point.run_dir.parent  # a finished run is kept as it is
    return point.run_dir, point.run_dir.parent


def _check_run_dir_writable(run_dir: Path) -> None:
    """Raise ValueError unless the run folder and its subfolders can be written in."""
    for sub in ("", "checkpoints", "eval", "monitor", "tb"):
        folder = run_dir / sub
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"{run_dir}: {folder} is not a folder")
        if folder.exists():
            check_writable(folder, "run folder")


def _last_update(cfg: AgentConfig, num_timesteps: int) -> int:
    """The env steps of the last update at or before ``num_timesteps`` (PPO and A2C, whose
    checkpoints may fall inside a rollout: its steps are not in the model, and a run resumed
    there collects the rollout again, ending with as many updates as an uninterrupted run);
    ``num_timesteps`` itself for SAC and TD3."""
    if cfg.algo not in ON_POLICY:
        return num_timesteps
    return num_timesteps - num_timesteps % cfg.rollout_steps


def _notes(cfg: AgentConfig, start: int) -> list[str]:
    """What the run will do that the config does not say: rounding of the budget, periodic
    evaluations or checkpoints beyond its end."""
    planned = cfg.planned_timesteps(start)
    notes = []
    if planned != cfg.n_timesteps:
        notes.append(
            f"{cfg.algo.upper()} trains in updates of {cfg.rollout_steps:,} env steps: "
            f"this run ends at {planned:,} steps (n_timesteps {cfg.n_timesteps:,})"
        )
    for key, flag, what in (
        ("eval_freq", "--eval-freq", "periodic evaluation (no best_model.zip)"),
        ("checkpoint_freq", "--checkpoint-freq", "checkpoint"),
    ):
        freq = getattr(cfg, key)
        if freq > planned - start:
            notes.append(
                f"run.{key} {freq:,} > the {planned - start:,} steps of this run: no {what}; "
                f"set {flag}"
            )
    return notes


def train(
    cfg: AgentConfig,
    log_dir: str | Path | None = "runs",
    resume: str | Path | None = None,
    progress_bar: bool = True,
    verbose: int = 0,
    tensorboard: bool = True,
    threads: int | None = 1,
) -> Path:
    """Train the agent of ``cfg``; returns the run directory (layout in the module docstring).

    Args:
        cfg: the agent config.
        log_dir: folder of the runs; a new run folder is made in it. With ``resume``: None
            continues an interrupted run in its own folder (a finished one into a new folder
            beside it); a folder: a new run there, starting from the checkpoint.
        resume: continue from this checkpoint ``.zip`` up to the config's ``n_timesteps``
            (unpickles it and its statistics: resume only from files you trust).
        progress_bar: show a progress bar.
        verbose: SB3 verbosity (0, 1, 2).
        tensorboard: write TensorBoard logs (if tensorboard is installed).
        threads: torch threads (None: torch's default). One is fastest for these small
            networks: on 2 busy cores, two threads made PPO more than ten times slower.

    Raises:
        ConfigError, ValueError, FileNotFoundError: bad inputs, before anything is written.
        KeyboardInterrupt or any exception of the training itself, after saving the run's
        state as a checkpoint and marking it interrupted in the manifest.
    """
    set_threads(threads)
    if log_dir is None and resume is None:
        log_dir = "runs"
    check_env(cfg)
    point = read_checkpoint(cfg, resume) if resume is not None else None
    start = _last_update(cfg, point.num_timesteps) if point else 0
    if point is not None and start >= cfg.n_timesteps:
        raise ValueError(
            f"--resume {point.path}: already trained {start:,} env steps, the budget "
            f"(n_timesteps) is {cfg.n_timesteps:,}: nothing to train; raise --timesteps"
        )
    in_place, parent = _resume_target(point, log_dir) if point else (None, Path(log_dir))
    if in_place is not None:
        _check_run_dir_writable(in_place)
    else:
        check_writable(parent, "--log-dir")
    notes = _notes(cfg, start)
    if point is not None and start != point.num_timesteps:
        notes.insert(
            0,
            f"the checkpoint was saved {point.num_timesteps - start:,} env steps into a rollout "
            f"of {cfg.rollout_steps:,}: training goes on from the update before it, at "
            f"{start:,} env steps, as the run would have",
        )

    # everything is checked: from here on, files are written
    run_dir = in_place or create_run_dir(parent, run_dir_for(cfg, parent).name)
    if in_place is None and run_dir != run_dir_for(cfg, parent):
        notes.insert(0, f"{run_dir_for(cfg, parent)} holds an earlier run: this run is {run_dir}")
    try:
        model, env, eval_env = build(cfg, run_dir, point, tensorboard, verbose)
    except BaseException:
        if in_place is None:
            shutil.rmtree(run_dir, ignore_errors=True)
        raise
    if point is not None:
        model.num_timesteps = start
    for note in notes:
        print(f"note: {note}")
    manifest = _start_manifest(cfg, run_dir, point, in_place is not None, start)
    atomic_write_text(run_dir / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))

    from agents.callbacks import ProgressBar

    callbacks = make_callbacks(cfg, run_dir, eval_env)
    if point is not None and in_place is not None:
        _restore_evaluations(callbacks, run_dir, start)
    bar = ProgressBar(cfg.planned_timesteps(start) - start) if progress_bar else None
    t0 = time.monotonic()
    try:
        model.learn(
            total_timesteps=cfg.n_timesteps - start,
            callback=callbacks + ([bar] if bar else []),
            reset_num_timesteps=point is None,
        )
    except BaseException as exc:
        if bar is not None:
            bar.close()
        _interrupted(cfg, model, run_dir, manifest, exc, time.monotonic() - t0)
        _close(env, eval_env)
        raise
    save_model(model, run_dir / "model.zip")
    _close(env, eval_env)
    _add_time(manifest, time.monotonic() - t0)
    manifest.update(status=FINISHED, finished=_now(), num_timesteps=int(model.num_timesteps))
    write_manifest(run_dir, manifest)
    return run_dir


def _close(*vec_envs: Any) -> None:
    for env in vec_envs:
        if env is not None:
            try:
                env.close()
            except Exception:  # noqa: BLE001  (subprocess envs may be gone after Ctrl-C)
                pass


def _add_time(manifest: dict[str, Any], seconds: float) -> None:
    manifest["train_seconds"] = round(manifest.get("train_seconds", 0.0) + seconds, 1)


def _start_manifest(
    cfg: AgentConfig, run_dir: Path, point: ResumePoint | None, in_place: bool, start: int = 0
) -> dict[str, Any]:
    """Write the manifest of a run that starts (or resumes, from ``start`` env steps) training,
    and return it."""
    manifest = read_manifest(run_dir) if in_place else {}
    n_envs = cfg.n_envs
    manifest.update(
        {
            "status": RUNNING,
            "config": cfg.to_dict(),
            "config_file": str(cfg.path),
            "algo": cfg.algo,
            "env_id": cfg.env_id,
            "env_kwargs": cfg.env_kwargs,
            "residual": cfg.is_residual,
            "n_timesteps": cfg.n_timesteps,
            "planned_timesteps": cfg.planned_timesteps(start),
            "num_timesteps": start,
            "seeds": {
                "training": cfg.seed,
                "training_envs": [cfg.seed + i for i in range(n_envs)],
                "evaluation": [
                    EVAL_SEED_OFFSET + cfg.eval_seed + k for k in range(cfg.eval_episodes)
                ],
                "algorithm": cfg.seed,
            },
            "versions": versions(),
        }
    )
    manifest.pop("finished", None)
    if "base_settings" not in manifest:  # a resumed run keeps those it started with
        manifest["base_settings"] = run_base_settings(cfg)
    manifest.setdefault("started", _now())
    manifest.setdefault("commands", []).append(" ".join(sys.argv))
    if point is not None:
        manifest.setdefault("resumed_from", []).append(str(point.path))
    write_manifest(run_dir, manifest)
    return manifest


def run_base_settings(cfg: AgentConfig) -> list[dict[str, Any]]:
    """The resolved settings of the base policies an agent of ``cfg`` acts on
    (:func:`agents.policies.base_settings` of an evaluation env with its wrappers); [] for an
    agent without one. A run's manifest records them, so that an evaluation on a release
    whose defaults changed can say what its base no longer shares."""
    if not cfg.wrapper_specs():
        return []
    env = cfg.wrap(gym.make(cfg.env_id, **cfg.env_kwargs))
    try:
        return base_settings(env)
    finally:
        env.close()


def _interrupted(
    cfg: AgentConfig,
    model: Any,
    run_dir: Path,
    manifest: dict[str, Any],
    exc: BaseException,
    seconds: float,
) -> None:
    """Save the state of a training stopped by ``exc`` as a checkpoint, mark the run
    interrupted and print one line saying how to resume."""
    reason = "Ctrl-C" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
    reason = reason.splitlines()[0] if reason else type(exc).__name__
    steps = int(model.num_timesteps)
    _add_time(manifest, seconds)
    manifest.update(status=INTERRUPTED, num_timesteps=steps)
    entry: dict[str, Any] = {"at": _now(), "num_timesteps": steps, "reason": reason}
    try:
        ckpt = save_checkpoint(model, run_dir / "checkpoints", cfg.save_replay_buffer)
    except Exception as save_exc:  # noqa: BLE001  (report the training's error, not this one)
        manifest.setdefault("interruptions", []).append(entry)
        write_manifest(run_dir, manifest)
        print(
            f"training stopped ({reason}) at {steps:,} steps; its state could not be saved "
            f"({save_exc})",
            file=sys.stderr,
        )
        return
    entry["checkpoint"] = str(ckpt)
    manifest.setdefault("interruptions", []).append(entry)
    write_manifest(run_dir, manifest)
    print(
        f"training stopped ({reason}) at {steps:,} of {cfg.n_timesteps:,} steps, saved in "
        f"{ckpt}; continue with: roughwalk train --resume {ckpt}",
        file=sys.stderr,
    )
