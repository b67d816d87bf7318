"""The controller's results do not depend on the number of BLAS threads."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import envs  # noqa: F401  (registers the ids)
from controllers.numerics import one_blas_thread
from controllers.planner.gait_planner import GaitPlanner
from controllers.planner.periodic import GaitCache
from controllers.reference import ReferencePolicy


def _actions(threads: int, steps: int = 600) -> np.ndarray:
    """Reference-policy actions on a rough course with model error (so the online
    identification fits and switches the model), every BLAS library limited to ``threads`` (a
    fresh periodic-gait cache, so the gait too is computed under that limit)."""
    GaitPlanner.gait_cache = GaitCache()
    with threadpool_limits(limits=threads):
        env = gym.make(
            "roughwalk/CompassGaitRough-v0",
            difficulty=1.0,
            robot_error={"all": 0.1, "draw": "sign"},
        )
        obs, _ = env.reset(seed=1_000_000)
        policy = ReferencePolicy(env)
        out = []
        for _ in range(steps):
            action = policy(obs)
            out.append(action[0])
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        assert any(r.switched for r in policy.diagnostics["identified"])
    return np.array(out)


@pytest.mark.skipif(
    not any(i["user_api"] == "blas" for i in threadpool_info()), reason="no BLAS thread pool"
)
def test_episode_is_the_same_with_one_or_two_blas_threads(monkeypatch):
    """A multithreaded BLAS sums in another order; the controller runs its linear algebra on
    one thread, so a rough-course episode (600 ticks, which amplify last-bit differences into
    1e-7-1e-6 differences of the action without it: the planner's, and the identification's
    fits) is bit for bit the same."""
    monkeypatch.setattr(GaitPlanner, "gait_cache", GaitPlanner.gait_cache)
    one, two = _actions(1), _actions(2)
    assert one.size == two.size == 600
    np.testing.assert_array_equal(one, two)


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.mark.skipif(
    not any(i["user_api"] == "blas" for i in threadpool_info()), reason="no BLAS thread pool"
)
def test_nested_calls_run_inside_the_outer_limit_which_is_then_restored():
    """A decorated function called from another runs on one BLAS thread too, and leaving the
    outer call restores the process's setting (also when the inner call raises)."""
    seen = []

    @one_blas_thread
    def inner(fail: bool) -> None:
        seen.append(_blas_threads())
        if fail:
            raise RuntimeError("inner")

    @one_blas_thread
    def outer() -> None:
        seen.append(_blas_threads())
        inner(False)
        with pytest.raises(RuntimeError):
            inner(True)
        seen.append(_blas_threads())

    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        outer()
        after = _blas_threads()
        inner(False)  # alone: its own limit
    assert before == after and set(before) == {2}
    assert all(set(s) == {1} for s in seen) and len(seen) == 5
