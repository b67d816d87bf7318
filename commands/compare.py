"""Run the whole RL-versus-control comparison: baselines and every agent config, one table.

For each terrain setting (flat, the paper's stairs, rough blocks at two difficulty levels) it
evaluates the baselines (passive, PD, reference controller) and, for every config in
``configs/agents`` whose env matches the setting, trains the agent and evaluates it (the best
model of the periodic evaluations on the validation courses, else the final one), all on the
same held-out test seeds; with ``--seeds`` every agent is trained at each training seed and the
table adds the IQM across seeds and the probability of improvement over each baseline. With
``--backend ray`` the trainings (then the evaluations) run as Ray tasks, on a local instance of
``--workers`` CPUs or on the cluster at ``--address`` (whose nodes share ``--log-dir``). A
finished run of the config in ``--log-dir`` is reused (the latest
one); an interrupted run of the same config is resumed; otherwise a new run is trained. It
writes ``compare.json`` (every episode), ``compare.csv`` and ``compare.md`` (the summary table
with the command reproducing each row and the env steps each agent was really trained for) to
``--out`` and prints the table. Reusing or resuming a run unpickles its files: use log folders
you trust.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.compare import CONFIG_DIR, SETTINGS, compare, markdown_table
from agents.config import TEST_SEED, seed_label
from agents.evaluate import eval_seeds
from agents.train import set_threads
from commands.cli import add_backend_arguments, int_range
from commands.evaluate import print_table


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``roughwalk compare`` to ``parser``."""
    parser.add_argument("--configs", type=Path, default=CONFIG_DIR, help="agent config folder")
    parser.add_argument("--only", help="only agent configs whose name contains this")
    parser.add_argument(
        "--terrains",
        nargs="+",
        choices=[x.name for x in SETTINGS],
        metavar="TERRAIN",
        help="only these terrain settings, of "
        + ", ".join(x.name for x in SETTINGS)
        + " (default: all)",
    )
    parser.add_argument(
        "--log-dir",
        type=Path,
        default=Path("runs"),
        help="runs folder: the latest finished run of each config is reused (default: runs)",
    )
    parser.add_argument("--out", type=Path, default=Path("results"), help="output folder")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier comparison's outputs in --out (else that is an error)",
    )
    parser.add_argument("--episodes", type=int, default=50, help="episodes per row")
    parser.add_argument(
        "--seed", type=int, default=TEST_SEED, help="held-out seed offset (as evaluate)"
    )
    parser.add_argument(
        "--no-train",
        action="store_true",
        help="fail instead of training agents with no finished run in --log-dir",
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="print the table of commands, run nothing"
    )
    parser.add_argument(
        "--seeds",
        nargs="+",
        type=int_range(0),
        metavar="SEED",
        help="training seeds of every agent: one run each (RUNS/<config>_s<seed>), one row "
        "each, and the IQM and probability of improvement across them (default: each "
        "config's own seed)",
    )
    add_backend_arguments(parser, "the trainings and evaluations")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")


def run(args: argparse.Namespace) -> int:
    """``roughwalk compare`` with the parsed ``args``; returns the exit status (130: stopped by
    Ctrl-C; a training in progress was saved).

    Raises:
        ValueError, OSError: bad arguments or configs, before anything is run or written.
    """
    set_threads(args.threads)
    try:
        result = compare(
            config_dir=args.configs,
            log_dir=args.log_dir,
            out=args.out,
            episodes=args.episodes,
            seed=args.seed,
            only=args.only,
            settings=tuple(x for x in SETTINGS if not args.terrains or x.name in args.terrains),
            train_missing=not args.no_train,
            dry_run=args.dry_run,
            progress=not args.no_progress,
            overwrite=args.overwrite,
            seeds=args.seeds,
            backend=args.backend,
            workers=args.workers,
            address=args.address,
        )
    except KeyboardInterrupt:
        return 130
    if args.dry_run:
        print(markdown_table(result.rows), end="")
    else:
        seeds = eval_seeds(args.seed, args.episodes)
        courses = seed_label(seeds[0], seeds[-1])
        title = f"{courses} (--seed {args.seed}), {args.episodes} episodes"
        print_table(result.evaluations, title=title)
        for g in result.across_seeds.get("groups", []):
            if g["runs"] > 1:
                lo, hi = g["iqm_ci"]
                print(
                    f"{g['group']}: IQM success {100 * g['iqm']:.0f} % ({100 * lo:.0f}-"
                    f"{100 * hi:.0f} %) over {g['runs']} training seeds x {g['tasks']} settings"
                )
        print(f"results in {args.out}/compare.md, compare.json, compare.csv")
    return 0
