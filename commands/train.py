"""Train an RL agent (stable-baselines3 PPO or SAC, from scratch or residual) from a config.

``roughwalk train configs/agents/ppo_rough.yaml`` writes a run directory
``<log-dir>/<config name>_s<seed>/`` holding:

- ``manifest.json``: the resolved config, every seed used (training envs, evaluation courses),
  library versions, the command line, start/finish times and any resumes;
- ``model.zip`` + ``vecnormalize.pkl``: the final agent and its observation statistics;
- ``best_model.zip`` + ``best_vecnormalize.pkl``: the best agent on the held-out evaluations;
- ``checkpoints/rl_model_<N>_steps.zip`` + ``rl_model_vecnormalize_<N>_steps.pkl``;
- ``eval/evaluations.npz`` (periodic held-out evaluations), ``monitor/`` (training episodes),
  ``tb/`` (TensorBoard: ``tensorboard --logdir <run>/tb``).

Training env ``i`` is seeded with ``seed + i`` (below 1,000,000); the periodic evaluation
resets its env with the fixed seeds ``1,000,000 + eval_seed + k`` before every evaluation, so
all evaluations use the same held-out courses. ``--resume CHECKPOINT`` continues a run from a
checkpoint (model, VecNormalize statistics and, if saved, the replay buffer) up to the config's
``n_timesteps``.
"""

from __future__ import annotations

import argparse

from agents.config import ConfigError, load_config, parse_assignments
from agents.train import train


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk train`` to ``parser``."""
    parser.add_argument("config", help="agent config (configs/agents/*.yaml)")
    parser.add_argument("--timesteps", type=int, help="override n_timesteps")
    parser.add_argument("--seed", type=int, help="override run.seed (training seed)")
    parser.add_argument("--resume", metavar="CHECKPOINT", help="continue from a checkpoint .zip")
    parser.add_argument(
        "--log-dir",
        help="directory of runs (default: runs/; with --resume: the checkpoint's run)",
    )
    parser.add_argument(
        "--hyperparams",
        "-params",
        nargs="*",
        metavar="KEY=VALUE",
        help="override hyperparameters (YAML values), as rl-zoo3's -params",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", type=int, default=0, help="SB3 verbosity (0, 1, 2)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")


def run(args: argparse.Namespace) -> int:
    """``roughwalk train`` with the parsed ``args``; returns the exit status (2: bad config)."""
    try:
        overrides = parse_assignments(args.hyperparams)
        if args.timesteps is not None:
            overrides["n_timesteps"] = args.timesteps
        run_overrides = {"seed": args.seed} if args.seed is not None else None
        cfg = load_config(args.config, overrides, run_overrides)
        log_dir = args.log_dir if (args.log_dir or args.resume) else "runs"
        run_dir = train(
            cfg,
            log_dir=log_dir,
            resume=args.resume,
            progress_bar=not args.no_progress,
            verbose=args.verbose,
            threads=args.threads,
        )
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        print(f"roughwalk train: error: {exc}")
        return 2
    print(f"run saved in {run_dir}")
    return 0
