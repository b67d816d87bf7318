"""The Ray backend on a local Ray instance (started once for the module): the same records as
the serial backend."""

import pytest

from agents.evaluate import evaluate
from agents.sweep import read_records, run_sweep, spec_from_dict
from agents.sweep.backends import check_worker_root, map_calls, project_root
from agents.sweep.store import EPISODES_FILE

pytest.importorskip("ray")


def _square_or_fail(x: int) -> int:
    if x < 0:
        raise ArithmeticError(f"negative {x}")
    return x * x


@pytest.mark.parametrize("backend", ["serial", "ray"])
def test_map_calls_returns_results_in_order_and_reports_each(local_ray, backend):
    seen = []
    items = [3, 1, 2, 0]
    out = map_calls(_square_or_fail, items, backend, on_result=lambda i, r: seen.append((i, r)))
    assert out == [9, 1, 4, 0]
    assert sorted(seen) == [(0, 9), (1, 1), (2, 4), (3, 0)]
    assert map_calls(_square_or_fail, [], backend) == []


@pytest.mark.parametrize("backend", ["serial", "ray"])
def test_map_calls_raises_a_failed_call(local_ray, backend):
    with pytest.raises(ArithmeticError, match="negative -2"):
        map_calls(_square_or_fail, [1, -2, 3], backend)
    with pytest.raises(ValueError, match="--backend: unknown backend 'dask'"):
        map_calls(_square_or_fail, [1], "dask")


def test_the_workers_must_import_the_code_this_process_runs(local_ray):
    """A local instance's workers import the project from this process's folder (the tests run
    from the checkout they import); another folder, as where a command runs inside one checkout
    with PYTHONPATH pointing at another, is an error naming both before any task runs."""
    theirs = local_ray.get(local_ray.remote(project_root).remote())
    assert theirs == project_root()
    check_worker_root(theirs)
    with pytest.raises(ValueError, match="workers import the project from /elsewhere, this"):
        check_worker_root("/elsewhere")


def test_ray_and_serial_give_identical_records(local_ray, tmp_path):
    spec = spec_from_dict(
        {
            "episodes": 2,
            "policies": ["passive", "pd"],
            "envs": [
                {
                    "name": "rough",
                    "id": "roughwalk/CompassGaitRough-v0",
                    "kwargs": {"difficulty": 2.0, "max_episode_steps": 300},
                }
            ],
        }
    )
    # an evaluation in this process first, on the default BLAS threads: the sweep's records
    # must not depend on what the process computed before (the planner's shared gaits)
    evaluate("pd", spec.envs[0].id, episodes=1, env_kwargs=spec.envs[0].kwargs)
    serial = run_sweep(spec, tmp_path / "serial", plot=False)
    # one task per episode: the episodes of a cell run in different worker processes
    remote = run_sweep(spec, tmp_path / "ray", backend="ray", chunk=1, plot=False)
    assert remote.ran == serial.ran == 4
    assert local_ray.is_initialized()  # a Ray instance the sweep did not start is left running

    def records(out):
        return sorted(read_records(out / EPISODES_FILE), key=lambda r: (r["cell"], r["seed"]))

    assert records(tmp_path / "ray") == records(tmp_path / "serial")
    assert remote.summary == serial.summary
