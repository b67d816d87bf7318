"""The walker batch: buffers that follow the simulator, episode counters, the delay line."""

from __future__ import annotations

import numpy as np
import pytest

from envs.batch import OBS_SENSORS, OBS_STATE, ObservationBuffers, WalkerBatch
from envs.sensors import SensorConfig
from envs.settings import resolve_env_settings
from envs.task import WORK_COLUMNS


def _batch(n: int = 3, **overrides) -> WalkerBatch:
    b = WalkerBatch(resolve_env_settings("slope", **overrides), n, parallel=False)
    for i in range(n):
        b.reset_walker(i, np.random.default_rng(i))
    return b


def test_views_follow_the_simulator() -> None:
    b = _batch(reward={"work": "positive"})
    v, sim = b.sim_views, b.sim
    for name, arr in [("q", sim.q), ("qd", sim.qd), ("stance_foot", sim.stance_foot),
                      ("status", sim.status), ("n_impacts", sim.events.n_impacts)]:  # fmt: skip
        assert np.shares_memory(getattr(v, name), arr), name
    b.step(np.array([0.5, -0.5, 0.0]))
    np.testing.assert_array_equal(v.work, sim.events.work[:, WORK_COLUMNS["positive"]])
    np.testing.assert_array_equal(v.x6, np.c_[sim.q, sim.qd, sim.stance_foot])


def test_episode_counters_and_infos() -> None:
    b = _batch()
    total = np.zeros(3)
    for _ in range(150):
        b.step(np.zeros((3, 1), dtype=np.float32))
        total += b.reward
    e = b.episode
    assert b.reward is e.reward and b.terminated is e.terminated
    np.testing.assert_allclose(e.distance, total)  # zero torque: no work, no failure here
    info = b.infos()
    assert info["footsteps"].tolist() == e.footsteps.tolist() and e.footsteps.min() >= 1
    assert all(info["_" + k].all() for k in ("state", "distance", "terrain"))
    assert info["failure"].tolist() == [None] * 3
    b.reset_walker(1, np.random.default_rng(9))
    assert e.distance[1] == 0.0 and e.footsteps[1] == 0 and e.distance[0] > 0.0


@pytest.mark.parametrize("latency", [0, 1, 3])
def test_delay_line(latency: int) -> None:
    buf = ObservationBuffers(SensorConfig(latency=latency), "sensors", 2, 3)
    assert buf.mode == OBS_SENSORS and buf.latency == latency
    buf.fresh[:] = 0.0
    buf.fill(0)
    buf.fill(1)
    seen = []
    for k in range(1, 6):
        buf.fresh[:] = k
        buf.push()
        seen.append(buf.delayed()[0, 0])
    assert seen == [max(k - latency, 0) for k in range(1, 6)]
    state = ObservationBuffers(SensorConfig(latency=latency), "state", 2, 3)
    assert state.mode == OBS_STATE and state.latency == 0


def test_actions_become_torques_in_the_batchs_own_buffer() -> None:
    b = _batch(reward={"work": "net"})
    actions = np.array([[0.5], [-2.0], [0.0]], dtype=np.float32)
    before = actions.copy()
    b.step(actions)
    assert np.array_equal(actions, before)  # the caller's array is only read
    # the same walkers stepped under the torques clip(action, -1, 1) * tau_max [N m]
    assert b.torque_limit == b.robot.tau_max
    ref = _batch(reward={"work": "net"})
    ref.sim.step(np.array([0.5, -1.0, 0.0]) * b.robot.tau_max)
    assert np.array_equal(ref.sim.states, b.sim.states)
    assert np.array_equal(ref.sim.events.work, b.sim.events.work)
    with pytest.raises(ValueError, match=r"action\[1\]"):
        b.step(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        b.step(np.zeros(2))
