"""Where a sweep's tasks (and a comparison's trainings and evaluations) run: in this process
(``serial``) or as Ray tasks (``ray``), on a local Ray instance started for the run or on an
existing cluster.

Both call ``on_records(records)`` in this process as work finishes: the serial backend after
every episode, the Ray backend after every task (in the order tasks finish). The records do not
depend on the backend, the number of workers or the tasks' size.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from agents.sweep.tasks import Task, run_task, run_task_list

BACKENDS = ("serial", "ray")
#: object store of a local Ray instance [bytes]: records are small and nothing large is shared
LOCAL_OBJECT_STORE = 200 * 1024 * 1024
RAY_MISSING = (
    '--backend ray: Ray is not installed; install the sweep extra (pip install -e ".[sweep]", '
    "or pip install ray) or use --backend serial"
)

OnRecords = Callable[[list[dict[str, Any]]], None]


def run_serial(tasks: Sequence[Task], on_records: OnRecords) -> None:
    """Run ``tasks`` one after the other in this process.

    Args:
        tasks: the tasks.
        on_records: called with each episode's record (a list of one) as it ends.
    """
    for task in tasks:
        for record in run_task(task):
            on_records([record])


def import_ray() -> Any:
    """The ``ray`` module, or ValueError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ValueError(RAY_MISSING) from None
    return ray


def init_ray(workers: int | None = None, address: str | None = None) -> bool:
    """Connect to Ray: to the cluster at ``address``, or to a new local instance with
    ``workers`` CPUs (default: all cores). Nothing is done when Ray is already initialised in
    this process. Returns whether this call started the connection (then
    ``ray.shutdown()`` is the caller's).

    Args:
        workers: CPUs of a local instance (tasks run at once), >= 1; not for a cluster.
        address: a cluster's address (``ray://host:10001``, ``host:6379`` or ``auto``).
    """
    ray = import_ray()
    if ray.is_initialized():
        return False
    # no usage reporting from a machine that may have no network, no dashboard server
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if address:
        ray.init(address=address, logging_level="ERROR", log_to_driver=True)
    else:
        ray.init(
            address="local",  # a new instance, even where `ray start` left a cluster running
            num_cpus=workers or os.cpu_count() or 1,
            include_dashboard=False,
            object_store_memory=LOCAL_OBJECT_STORE,
            logging_level="ERROR",
        )
    return True


def project_root() -> str:
    """The folder this process imports the project's packages (``agents``, ``controllers``,
    ``envs``) from."""
    return str(Path(__file__).resolve().parents[2])


def check_worker_root(theirs: str, ours: str | None = None) -> None:
    """Raise ValueError where a local Ray instance's workers import the project from the folder
    ``theirs`` and this process from another (``ours``, default :func:`project_root`): Ray
    puts the folder a command runs in first on its workers' path, so a command run inside one
    checkout with ``PYTHONPATH`` pointing at another would mix their code."""
    ours = project_root() if ours is None else ours
    if theirs != ours:
        raise ValueError(
            f"--backend ray: the Ray workers import the project from {theirs}, this process "
            f"from {ours} (Ray puts the current folder first on its workers' path); run the "
            "command from another folder, or from that one without PYTHONPATH, or with "
            "--backend serial"
        )


#: how long a stopped run of calls waits for its cancelled Ray tasks to wind down (a training
#: saves a checkpoint and marks its run interrupted) [s]
CANCEL_GRACE = 120.0


def map_calls(
    fn: Callable[..., Any],
    items: Sequence[Any],
    backend: str = "serial",
    workers: int | None = None,
    address: str | None = None,
    on_result: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """``[fn(item) for item in items]``, in this process (``serial``) or as Ray tasks of one CPU
    each on a local instance or a cluster (``ray``, see :func:`init_ray`; an instance started
    here is shut down at the end).

    On a local instance the workers must import the project from the folder this process
    does (:func:`check_worker_root`). If a call fails or the caller is interrupted (Ctrl-C),
    the Ray tasks still running are cancelled with a ``KeyboardInterrupt`` inside them (what
    Ctrl-C does in the serial backend), given :data:`CANCEL_GRACE` seconds to wind down, and
    the exception is raised.

    Args:
        fn: a module-level function (Ray pickles it by reference); on a cluster every node
            needs this package installed (the same version).
        items: its arguments, one call each.
        backend: ``serial`` or ``ray``.
        workers: Ray: CPUs of a local instance (default: all cores), >= 1.
        address: Ray: a cluster's address (default: a local instance).
        on_result: called in this process as ``on_result(index, result)`` when a call ends (in
            the order calls end).

    Returns the results in the order of ``items``.
    """
    if backend not in BACKENDS:
        raise ValueError(f"--backend: unknown backend {backend!r}; allowed: {', '.join(BACKENDS)}")
    results: list[Any] = [None] * len(items)
    if backend == "serial":
        for i, item in enumerate(items):
            results[i] = fn(item)
            if on_result is not None:
                on_result(i, results[i])
        return results
    ray = import_ray()
    if not items:
        return results
    started = init_ray(workers, address)
    try:
        if address is None:  # a local instance: its workers run this machine's folders
            check_worker_root(ray.get(ray.remote(num_cpus=1)(project_root).remote()))
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = [remote.remote(item) for item in items]
        index = {ref: i for i, ref in enumerate(refs)}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    i = index[ref]
                    results[i] = ray.get(ref)
                    if on_result is not None:
                        on_result(i, results[i])
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=False)
            if pending:
                ray.wait(pending, num_returns=len(pending), timeout=CANCEL_GRACE)
            raise
    finally:
        if started:
            ray.shutdown()
    return results


def run_ray(
    tasks: Sequence[Task],
    on_records: OnRecords,
    workers: int | None = None,
    address: str | None = None,
) -> None:
    """Run ``tasks`` as Ray tasks (:func:`map_calls`), passing each task's records to
    ``on_records`` as the task finishes.

    Args:
        tasks: the tasks.
        on_records: called with each task's records as the task finishes.
        workers: CPUs of a local instance (default: all cores).
        address: a cluster's address, or None for a local instance.
    """
    map_calls(run_task_list, tasks, "ray", workers, address, lambda _, records: on_records(records))


def run_tasks(
    tasks: Sequence[Task],
    on_records: OnRecords,
    backend: str = "serial",
    workers: int | None = None,
    address: str | None = None,
) -> None:
    """Run ``tasks`` on ``backend`` (``serial`` or ``ray``), passing records to
    ``on_records`` as they finish.

    Args:
        tasks: the tasks.
        on_records: receives each batch of finished records.
        backend: ``serial`` or ``ray``.
        workers: Ray: CPUs of a local instance (default: all cores).
        address: Ray: a cluster's address (default: a local instance).
    """
    if backend == "serial":
        run_serial(tasks, on_records)
    elif backend == "ray":
        run_ray(tasks, on_records, workers, address)
    else:
        raise ValueError(f"--backend: unknown backend {backend!r}; allowed: {', '.join(BACKENDS)}")
