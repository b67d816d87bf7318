"""The Ray backend on a local Ray instance (started once for the module): the same records as
the serial backend."""

import pytest

from agents.evaluate import evaluate
from agents.sweep import read_records, run_sweep, spec_from_dict
from agents.sweep.backends import init_ray
from agents.sweep.store import EPISODES_FILE

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray instance with 2 CPUs for the module."""
    assert init_ray(workers=2)
    yield ray
    ray.shutdown()


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
