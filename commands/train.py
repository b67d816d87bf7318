"""Train an RL agent (stable-baselines3 PPO or SAC, from scratch or residual) from a config.

``roughwalk train configs/agents/ppo_rough.yaml`` writes a new run folder
``<log-dir>/<config name>_s<seed>/`` (``..._2``, ``..._3``, ... when that exists: a run is never
overwritten) holding:

- ``manifest.json``: the resolved config and its base policy's settings (``base_settings``),
  every seed used (training envs, evaluation courses),
  library versions, the command line, start/finish times, the status and the env steps asked
  (``n_timesteps``) and trained (``num_timesteps``);
- ``model.zip`` + ``vecnormalize.pkl``: the final agent and its observation statistics;
- ``best_model.zip`` + ``best_vecnormalize.pkl``: the best agent on the held-out evaluations;
- ``checkpoints/rl_model_<N>_steps.zip`` + ``rl_model_vecnormalize_<N>_steps.pkl``;
- ``eval/evaluations.npz`` (periodic held-out evaluations), ``monitor/`` (training episodes),
  ``tb/`` (TensorBoard: ``tensorboard --logdir <run>/tb``).

Training env ``i`` is seeded with ``seed + i`` (below 1,000,000); the periodic evaluation
resets its env with the fixed seeds ``1,000,000 + eval_seed + k`` before every evaluation, so
all evaluations use the same held-out courses; one line is printed per evaluation.

Everything is checked before anything is written. Ctrl-C (or an error) during training saves
the model as a checkpoint, marks the run interrupted and prints the command that continues
it: ``--resume CHECKPOINT`` continues an interrupted run in its folder up to the config's
``n_timesteps`` (a finished run, or with ``--log-dir``, into a new run folder). Without a
config, ``--resume`` takes the config of the checkpoint's run. Resuming unpickles the
checkpoint zip and the ``VecNormalize`` statistics and replay buffer saved beside it, which can
run code: resume only from files you trust.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.config import ConfigError, config_from_dict, load_config, parse_assignments
from agents.runs import find_manifest, read_manifest
from agents.train import train


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk train`` to ``parser``."""
    parser.add_argument(
        "config",
        nargs="?",
        help="agent config (configs/agents/*.yaml); with --resume, default: the run's own",
    )
    parser.add_argument("--timesteps", type=int, help="override n_timesteps (env steps)")
    parser.add_argument("--seed", type=int, help="override run.seed (training seed)")
    parser.add_argument(
        "--eval-freq",
        type=int,
        metavar="STEPS",
        help="env steps between periodic evaluations, 0 for none (default: the config's)",
    )
    parser.add_argument(
        "--eval-episodes", type=int, metavar="N", help="episodes per evaluation (default: config)"
    )
    parser.add_argument(
        "--checkpoint-freq",
        type=int,
        metavar="STEPS",
        help="env steps between checkpoints, 0 for none (default: the config's)",
    )
    parser.add_argument(
        "--resume",
        metavar="CHECKPOINT",
        help="continue from a checkpoint .zip (also model.zip); unpickles it and the "
        "statistics and replay buffer saved beside it, which can run code: only files you trust",
    )
    parser.add_argument(
        "--log-dir",
        help="folder of runs; a new numbered run folder is made in it (default: runs/; with "
        "--resume: continue the checkpoint's interrupted run in place)",
    )
    parser.add_argument(
        "--hyperparams",
        "-params",
        nargs="*",
        metavar="KEY=VALUE",
        help="override hyperparameters (YAML values), as rl-zoo3's -params",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--verbose", type=int, default=0, choices=(0, 1, 2), help="SB3 verbosity (default 0)"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")


def _at_least(flag: str, value: int | None, low: int) -> None:
    if value is not None and value < low:
        raise ValueError(f"{flag}: must be an integer >= {low}, got {value}")


def _run_config(checkpoint: str) -> tuple[dict, Path]:
    """The config dict recorded in the manifest of the checkpoint's run, and its file name."""
    manifest_path = find_manifest(checkpoint)
    if manifest_path is None:
        raise ValueError(
            f"--resume {checkpoint}: no run manifest beside it or above it to take the config "
            "from; give the config file"
        )
    manifest = read_manifest(manifest_path.parent)
    if not isinstance(manifest.get("config"), dict):
        raise ValueError(f"{manifest_path}: not a valid run manifest (no config)")
    return manifest["config"], Path(manifest.get("config_file") or manifest_path)


def run(args: argparse.Namespace) -> int:
    """``roughwalk train`` with the parsed ``args``; returns the exit status (130: stopped by
    Ctrl-C, after saving the run).

    Raises:
        ValueError, OSError: bad arguments or config, before anything is written.
    """
    _at_least("--timesteps", args.timesteps, 1)
    _at_least("--seed", args.seed, 0)
    _at_least("--eval-freq", args.eval_freq, 0)
    _at_least("--eval-episodes", args.eval_episodes, 1)
    _at_least("--checkpoint-freq", args.checkpoint_freq, 0)
    _at_least("--threads", args.threads, 1)
    if args.config is None and not args.resume:
        raise ValueError("config: required (an agent config file), unless --resume is given")
    overrides = parse_assignments(args.hyperparams)
    if args.timesteps is not None:
        overrides["n_timesteps"] = args.timesteps
    flags = {
        "seed": args.seed,
        "eval_freq": args.eval_freq,
        "eval_episodes": args.eval_episodes,
        "checkpoint_freq": args.checkpoint_freq,
    }
    run_overrides = {k: v for k, v in flags.items() if v is not None}
    if args.config is None:
        data, path = _run_config(args.resume)
        cfg = config_from_dict(data, path, overrides, run_overrides)
    else:
        cfg = load_config(args.config, overrides, run_overrides)
    planned = cfg.planned_timesteps()
    for flag, value in (
        ("--eval-freq", args.eval_freq),
        ("--checkpoint-freq", args.checkpoint_freq),
    ):
        if value is not None and value > planned:
            raise ConfigError(
                f"{flag}: {value:,} is more than the {planned:,} env steps of this run, so it "
                f"would never happen; allowed: 0 (never) to {planned}"
            )
    try:
        run_dir = train(
            cfg,
            log_dir=args.log_dir if (args.log_dir or args.resume) else "runs",
            resume=args.resume,
            progress_bar=not args.no_progress,
            verbose=args.verbose,
            threads=args.threads,
        )
    except KeyboardInterrupt:
        return 130  # the run was saved and the way to resume it printed
    print(f"run saved in {run_dir}")
    return 0
