"""The work of a sweep: tasks of one cell and a run of its seeds, and the per-episode records
they produce.

A record is one episode as plain data (a JSON object of ``episodes.jsonl``): the cell's key,
policy, group, env, keyword arguments and swept values, then the episode's fields
(:class:`agents.evaluate.EpisodeResult`: ``seed``, ``success``, ``failure``, ``footsteps``,
``distance``, ``speed``, ``motor_work``, ``cost_of_transport``, ...) and the robot's
``total_mass`` [kg] and ``gravity`` [m/s^2]. An episode depends on its cell and seed only, not
on the episodes run before it in the same env, so any split into tasks gives the same records;
and the controller's linear algebra runs on one BLAS thread whatever the backend
(:mod:`controllers.numerics`: a multithreaded BLAS sums in another order, and a walk on rough
ground amplifies the last bits into different footholds).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from agents.policies import BASELINES
from agents.sweep.spec import Cell

#: episodes per task when not given: enough to make a task's start-up (env, policy, a
#: worker's imports) small beside its episodes, few enough to spread a cell over workers
MAX_CHUNK = 10


@dataclass(frozen=True)
class Task:
    """Episodes of one cell, run one after the other in one env.

    Attributes:
        cell: the cell.
        seeds: the absolute reset seeds of its episodes.
    """

    cell: Cell
    seeds: tuple[int, ...]


def episode_record(cell: Cell, result: Any, total_mass: float, gravity: float) -> dict[str, Any]:
    """One episode of ``cell`` as a record (see the module docstring).

    Args:
        cell: the cell it belongs to.
        result: the episode (:class:`agents.evaluate.EpisodeResult`).
        total_mass: the robot's total mass [kg].
        gravity: gravitational acceleration [m/s^2].
    """
    head = {
        "cell": cell.key,
        "policy": cell.policy,
        "policy_spec": cell.policy_spec,
        "group": cell.group,
        "policy_options": cell.policy_options,
        "env": cell.env,
        "env_id": cell.env_id,
        "env_kwargs": cell.env_kwargs,
        "swept": cell.swept,
    }
    return head | asdict(result) | {"total_mass": total_mass, "gravity": gravity}


def run_task(task: Task) -> Iterator[dict[str, Any]]:
    """Run the episodes of ``task`` in one env with one policy; yields each record as its
    episode ends."""
    from agents.evaluate import make_eval_env, run_episode
    from agents.train import set_threads

    cell = task.cell
    if cell.policy_spec not in BASELINES:
        set_threads(1)  # one core per task; the same arithmetic in every worker
    env, policy, _, _ = make_eval_env(
        cell.policy_spec, cell.env_id, cell.env_kwargs, **cell.policy_options
    )
    try:
        base = env.unwrapped
        mass, g = float(base.params.total_mass), float(base.params.g)
        for seed in task.seeds:
            yield episode_record(cell, run_episode(env, policy, seed), mass, g)
    finally:
        env.close()


def run_task_list(task: Task) -> list[dict[str, Any]]:
    """All records of ``task`` (what a remote worker returns)."""
    return list(run_task(task))


def chunk_size(episodes: int, workers: int) -> int:
    """Episodes per task for ``episodes`` to run on ``workers``: about four tasks per worker,
    at most :data:`MAX_CHUNK` episodes each."""
    return max(1, min(MAX_CHUNK, math.ceil(episodes / (4 * max(1, workers)))))


def make_tasks(
    cells: Sequence[Cell], seeds: Sequence[int], done: set[tuple[str, int]], chunk: int
) -> list[Task]:
    """The tasks that run every (cell, seed) pair not in ``done``, ``chunk`` episodes each
    (runs of consecutive seeds of one cell; cells in order).

    Args:
        cells: the cells.
        seeds: the absolute reset seeds of every cell.
        done: ``(cell key, seed)`` pairs already recorded.
        chunk: episodes per task, >= 1.
    """
    if chunk < 1:
        raise ValueError(f"chunk = {chunk} is out of range; allowed: >= 1")
    tasks = []
    for cell in cells:
        todo = [s for s in seeds if (cell.key, s) not in done]
        tasks += [Task(cell, tuple(todo[i : i + chunk])) for i in range(0, len(todo), chunk)]
    return tasks
