"""Training an RL agent (stable-baselines3 PPO or SAC, from scratch or residual) from a config.

:func:`train` writes a run directory ``<log_dir>/<config name>_s<seed>/`` holding:

- ``manifest.json``: the resolved config, every seed used (training envs, evaluation courses),
  library versions, the command line, start/finish times and any resumes;
- ``model.zip`` + ``vecnormalize.pkl``: the final agent and its observation statistics;
- ``best_model.zip`` + ``best_vecnormalize.pkl``: the best agent on the held-out evaluations;
- ``checkpoints/rl_model_<N>_steps.zip`` + ``rl_model_vecnormalize_<N>_steps.pkl``;
- ``eval/evaluations.npz`` (periodic held-out evaluations), ``monitor/`` (training episodes),
  ``tb/`` (TensorBoard: ``tensorboard --logdir <run>/tb``).

Training env ``i`` is seeded with ``seed + i`` (below 1,000,000); the periodic evaluation
resets its env with the fixed seeds ``1,000,000 + eval_seed + k`` before every evaluation, so
all evaluations use the same held-out courses. ``train(cfg, resume=checkpoint)`` continues a
run from a checkpoint (model, VecNormalize statistics and, if saved, the replay buffer) up to
the config's ``n_timesteps``.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import platform
import re
import sys
from importlib.metadata import version
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs  # noqa: F401  (registers the roughwalk ids, also in subprocesses)
from agents.config import EVAL_SEED_OFFSET, AgentConfig
from agents.runs import MANIFEST, find_manifest, find_vecnormalize


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
) -> Any:
    """``n_envs`` copies of the config's env (with its wrappers) as an SB3 ``VecEnv``.

    ``vec_env`` (default: the config's ``run.vec_env``): ``dummy`` (one process), ``subproc``
    (one process per env) or ``native`` (the batched vector env through
    ``agents.sb3_vec_env``; no env wrappers). Env ``i`` is seeded with ``seed + i``.
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
    wrapper = cfg.wrap if cfg.wrapper_specs() else None
    return sb3_make_vec_env(
        functools.partial(_make_env, cfg.env_id),
        n_envs=n_envs,
        seed=seed,
        env_kwargs=cfg.env_kwargs,
        wrapper_class=wrapper,
        monitor_dir=str(monitor_dir) if monitor_dir else None,
        vec_env_cls=SubprocVecEnv if kind == "subproc" and n_envs > 1 else DummyVecEnv,
    )


def make_callbacks(cfg: AgentConfig, run_dir: Path, eval_env: Any) -> list:
    """Checkpoints (with VecNormalize statistics) and held-out periodic evaluation."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    # the callbacks subclass SB3's: imported with SB3, not with this module
    from agents.callbacks import HeldOutEvalCallback, SaveVecNormalizeOnBest

    callbacks: list = []
    if cfg.checkpoint_freq > 0:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(cfg.checkpoint_freq // cfg.n_envs, 1),
                save_path=str(run_dir / "checkpoints"),
                save_replay_buffer=cfg.save_replay_buffer,
                save_vecnormalize=True,
            )
        )
    if cfg.eval_freq > 0 and eval_env is not None:
        callbacks.append(
            HeldOutEvalCallback(
                eval_env,
                seed=EVAL_SEED_OFFSET + cfg.eval_seed,
                n_eval_episodes=cfg.eval_episodes,
                eval_freq=max(cfg.eval_freq // cfg.n_envs, 1),
                log_path=str(run_dir / "eval"),
                best_model_save_path=str(run_dir),
                callback_on_new_best=SaveVecNormalizeOnBest(run_dir),
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

        if threads < 1:
            raise ValueError(f"threads = {threads} is out of range; allowed: >= 1")
        torch.set_num_threads(threads)


def run_dir_for(cfg: AgentConfig, log_dir: str | Path) -> Path:
    """The run directory of ``cfg`` in ``log_dir``: ``<log_dir>/<config name>_s<seed>``."""
    return Path(log_dir) / f"{cfg.name}_s{cfg.seed}"


def _checkpoint_files(checkpoint: Path) -> tuple[Path | None, Path | None]:
    """(VecNormalize statistics, replay buffer) saved with a checkpoint, if present."""
    vn = find_vecnormalize(checkpoint)
    m = re.fullmatch(r"(.*)_(\d+)_steps", checkpoint.stem)
    rb = None
    if m:
        cand = checkpoint.with_name(f"{m.group(1)}_replay_buffer_{m.group(2)}_steps.pkl")
        rb = cand if cand.is_file() else None
    return vn, rb


def build(
    cfg: AgentConfig,
    run_dir: Path,
    resume: Path | None = None,
    tensorboard: bool = True,
    verbose: int = 0,
) -> tuple[Any, Any, Any]:
    """The model, its training VecEnv and the evaluation VecEnv (None without evaluation).

    Args:
        cfg: the agent config.
        run_dir: the run directory (monitor logs, TensorBoard logs).
        resume: build from this checkpoint, with its VecNormalize statistics and, if saved,
            its replay buffer (default: from scratch).
        tensorboard: write TensorBoard logs (if tensorboard is installed).
        verbose: SB3 verbosity (0, 1, 2).
    """
    from stable_baselines3.common.vec_env import VecFrameStack, VecNormalize

    algo_cls = cfg.algo_class
    n_envs = cfg.n_envs
    resume_path = resume
    monitor = run_dir / "monitor"
    if resume_path is not None:  # one folder per resumed segment, the earlier logs are kept
        monitor = monitor / f"resume{len(list(monitor.glob('resume*'))) + 1}"
    env = make_vec_env(cfg, n_envs, cfg.seed, monitor)
    eval_kind = "native" if cfg.vec_env == "native" else "dummy"  # same wrapper chain
    norm = cfg.normalize_kwargs
    eval_env = (
        make_vec_env(cfg, 1, EVAL_SEED_OFFSET + cfg.eval_seed, None, eval_kind)
        if cfg.eval_freq
        else None
    )
    if norm is not None:
        if resume_path is not None:
            vn_path, _ = _checkpoint_files(resume_path)
            if vn_path is None:
                raise FileNotFoundError(
                    f"no VecNormalize statistics saved with {resume_path} (expected beside it)"
                )
            env = VecNormalize.load(str(vn_path), env)
            env.training = True
        else:
            env = VecNormalize(env, **norm)
        if eval_env is not None:
            eval_kwargs = {**norm, "training": False, "norm_reward": False}
            eval_env = VecNormalize(eval_env, **eval_kwargs)
    if cfg.frame_stack:  # over the normalised observations, as rl-zoo3 stacks them
        env = VecFrameStack(env, cfg.frame_stack)
        if eval_env is not None:
            eval_env = VecFrameStack(eval_env, cfg.frame_stack)

    tb_log = None
    if tensorboard:
        try:
            import tensorboard as _tb  # noqa: F401

            tb_log = str(run_dir / "tb")
        except ImportError:
            print("tensorboard is not installed: no TensorBoard logs")

    if resume_path is not None:
        model = algo_cls.load(str(resume_path), env=env, device="cpu", tensorboard_log=tb_log)
        _, rb_path = _checkpoint_files(resume_path)
        if rb_path is not None and hasattr(model, "load_replay_buffer"):
            model.load_replay_buffer(str(rb_path))
    else:
        model = algo_cls(
            env=env,
            seed=cfg.seed,
            device="cpu",
            tensorboard_log=tb_log,
            verbose=verbose,
            **cfg.algo_kwargs(),
        )

    return model, env, eval_env


def save(model: Any, path: str | Path) -> None:
    """Save ``model`` to ``path`` (.zip) and its VecNormalize statistics beside it."""
    path = Path(path)
    model.save(str(path))
    vn = model.get_vec_normalize_env()
    if vn is not None:
        stats = "vecnormalize.pkl" if path.stem == "model" else f"{path.stem}_vecnormalize.pkl"
        vn.save(str(path.with_name(stats)))


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
        log_dir: folder of the runs; None with ``resume``: the checkpoint's run.
        resume: continue from this checkpoint ``.zip`` up to the config's ``n_timesteps``.
        progress_bar: show SB3's progress bar.
        verbose: SB3 verbosity (0, 1, 2).
        tensorboard: write TensorBoard logs (if tensorboard is installed).
        threads: torch threads (None: torch's default). One is fastest for these small
            networks: on 2 busy cores, two threads made PPO more than ten times slower.
    """
    set_threads(threads)
    resume_path = Path(resume) if resume else None
    if resume_path is not None:
        if not resume_path.is_file():
            raise FileNotFoundError(f"checkpoint not found: {resume_path}")
        manifest_path = find_manifest(resume_path)
        if log_dir is not None:
            run_dir = run_dir_for(cfg, log_dir)
        elif manifest_path is not None:
            run_dir = manifest_path.parent
        else:
            run_dir = resume_path.parent
    else:
        run_dir = run_dir_for(cfg, log_dir if log_dir is not None else "runs")
    run_dir.mkdir(parents=True, exist_ok=True)

    manifest_file = run_dir / MANIFEST
    manifest: dict[str, Any] = (
        json.loads(manifest_file.read_text())
        if resume_path is not None and manifest_file.is_file()
        else {}
    )
    n_envs = cfg.n_envs
    manifest.update(
        {
            "config": cfg.to_dict(),
            "config_file": str(cfg.path),
            "algo": cfg.algo,
            "env_id": cfg.env_id,
            "env_kwargs": cfg.env_kwargs,
            "residual": cfg.is_residual,
            "n_timesteps": cfg.n_timesteps,
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
    manifest.setdefault("started", _now())
    manifest.setdefault("commands", []).append(" ".join(sys.argv))
    if resume_path is not None:
        manifest.setdefault("resumed_from", []).append(str(resume_path))
    manifest_file.write_text(json.dumps(manifest, indent=2) + "\n")
    (run_dir / "config.yaml").write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))

    model, env, eval_env = build(cfg, run_dir, resume_path, tensorboard, verbose)
    remaining = cfg.n_timesteps - (model.num_timesteps if resume_path is not None else 0)
    callbacks = make_callbacks(cfg, run_dir, eval_env)
    if resume_path is not None:
        _restore_evaluations(callbacks, run_dir, model.num_timesteps)
    if remaining > 0:
        model.learn(
            total_timesteps=remaining,
            callback=callbacks,
            progress_bar=progress_bar,
            reset_num_timesteps=resume_path is None,
            tb_log_name=cfg.name,
        )
    save(model, run_dir / "model.zip")
    env.close()
    if eval_env is not None:
        eval_env.close()
    manifest["finished"] = _now()
    manifest["num_timesteps"] = int(model.num_timesteps)
    manifest_file.write_text(json.dumps(manifest, indent=2) + "\n")
    return run_dir
