"""The task: reward weights and motor-work kinds, start-state sampling, terrain sources."""

from __future__ import annotations

import numpy as np
import pytest

from envs import Terrain
from envs.env import CompassGaitEnv
from envs.task import WORK_COLUMNS, InitialState, RewardConfig, TerrainSource


@pytest.mark.parametrize("work", sorted(WORK_COLUMNS))
def test_reward_work_kind_reads_its_simulator_column(work: str) -> None:
    assert RewardConfig(work=work).work_column == WORK_COLUMNS[work]
    env = CompassGaitEnv("flat", reward={"work": work})
    env.reset(seed=0)
    for a in (0.8, -0.8, 0.3):
        _, _, _, _, info = env.step(np.array([a], np.float32))
        assert info["motor_work"] == env.simulator.events.work[0, WORK_COLUMNS[work]]
    net, pos, absolute = (env.simulator.events.work[0, WORK_COLUMNS[k]] for k in
                          ("net", "positive", "absolute"))  # fmt: skip
    assert abs(net) <= absolute and 0.0 <= pos <= absolute


def test_reward_config_validates() -> None:
    assert RewardConfig().weights().tolist() == [1.0, 0.05, 1.0]
    with pytest.raises(ValueError, match="reward.work"):
        RewardConfig(work="kinetic")
    with pytest.raises(ValueError, match="finite"):
        RewardConfig(progress=float("nan"))


def test_initial_state_sampling() -> None:
    nominal = InitialState(q=(-0.5, -0.25), qd=(2.7, 1.2))
    rng = np.random.default_rng(0)
    q, qd, leg = nominal.sample(rng)
    assert q.tolist() == [-0.5, -0.25] and qd.tolist() == [2.7, 1.2] and leg == 0
    assert rng.bit_generator.state == np.random.default_rng(0).bit_generator.state  # no draw
    spread = InitialState(q=(-0.5, -0.25), qd=(2.7, 1.2), spread=(0.01, 0.01, 0.05, 0.05))
    q, qd, _ = spread.sample(np.random.default_rng(1))
    u = np.random.default_rng(1).uniform(-1.0, 1.0, size=4)
    np.testing.assert_array_equal(np.r_[q, qd], np.array([-0.5, -0.25, 2.7, 1.2]) + np.array(
        [0.01, 0.01, 0.05, 0.05]) * u)  # fmt: skip
    q, qd, leg = spread.sample(rng, state=([0.1, 0.2], [0.3, 0.4]), stance_leg="B")
    assert q.tolist() == [0.1, 0.2] and qd.tolist() == [0.3, 0.4] and leg == 1
    legs = {InitialState((0, 0), (0, 0), stance_leg="random").sample(rng)[2] for _ in range(40)}
    assert legs == {0, 1}
    with pytest.raises(ValueError, match="stance_leg"):
        nominal.sample(rng, stance_leg="C")
    with pytest.raises(ValueError, match="state"):
        nominal.sample(rng, state=(1.0, 2.0))


def test_terrain_sources() -> None:
    assert TerrainSource("flat").fixed == Terrain.flat()  # configs/terrains/flat.yaml
    fixed = TerrainSource("paper_stairs")
    assert not fixed.is_random and fixed.draw(np.random.default_rng(0)) is fixed.fixed
    rough = TerrainSource("rough_blocks", difficulty=2.0)
    a, b = rough.draw(np.random.default_rng(0)), rough.draw(np.random.default_rng(1))
    assert rough.is_random and isinstance(a, Terrain) and a != b
    assert a == rough.draw(np.random.default_rng(0))
    with pytest.raises(ValueError, match="difficulty"):
        TerrainSource("flat", difficulty=2.0)
    with pytest.raises(ValueError, match="unknown terrain"):
        TerrainSource("no_such_course")
    # a kind name of a random terrain is a generator with the kind's default fields
    blocks = TerrainSource("blocks", difficulty=2.0)
    assert blocks.is_random and blocks.template["height_range"] == [-0.04, 0.04]
