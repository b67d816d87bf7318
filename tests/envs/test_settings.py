"""Env settings: variants merged over the base, the one resolver, keyword overrides."""

from __future__ import annotations

import gymnasium as gym
import pytest
import yaml

import envs  # noqa: F401  (registers the ids)
from envs.physics import RobotParams
from envs.registration import ENV_IDS, NAMESPACE
from envs.settings import (
    EnvSettings,
    available_env_configs,
    load_env_config,
    resolve_env_settings,
)

PAPER_SENSORS = {
    "encoder_resolution": 0.0015339807878856412,
    "encoder_noise": 0.001,
    "scan_count": 10,
    "scan_offset": 0.05,
    "scan_spacing": 0.05,
    "scan_noise": 0.002,
    "scan_resolution": 0.001,
    "scan_range": 0.3,
    "latency": 0,
}
PAPER_START = {
    "q": [-0.5, -0.25],
    "qd": [2.7, 1.2],
    "spread": [0.01, 0.01, 0.05, 0.05],
    "stance_leg": "A",
}
#: the complete settings of each variant, as the files gave them before they were split into a
#: base and differences
EXPECTED = {
    "flat": {
        "robot": "paper",
        "terrain": "flat",
        "difficulty": 1.0,
        "dt": 0.005,
        "u_max": None,
        "max_episode_steps": 3000,
        "observation": "sensors",
        "sensors": PAPER_SENSORS,
        "reward": {"progress": 1.0, "energy": 0.05, "failure": 1.0, "work": "absolute"},
        "initial_state": PAPER_START,
        "simulator": {},
        "robot_error": 0.0,
        "push": None,
    },
    "stairs": {
        "robot": "paper",
        "terrain": "paper_stairs",
        "difficulty": 1.0,
        "dt": 0.005,
        "u_max": None,
        "max_episode_steps": 2000,
        "observation": "sensors",
        "sensors": PAPER_SENSORS,
        "reward": {"progress": 1.0, "energy": 0.05, "failure": 1.0, "work": "absolute"},
        "initial_state": PAPER_START,
        "simulator": {},
        "robot_error": 0.0,
        "push": None,
    },
    "rough": {
        "robot": "paper",
        "terrain": "rough_blocks",
        "difficulty": 1.0,
        "dt": 0.005,
        "u_max": None,
        "max_episode_steps": 3000,
        "observation": "sensors",
        "sensors": PAPER_SENSORS,
        "reward": {"progress": 1.0, "energy": 0.05, "failure": 1.0, "work": "absolute"},
        "initial_state": PAPER_START,
        "simulator": {},
        "robot_error": 0.0,
        "push": None,
    },
    "slope": {
        "robot": "classic",
        "terrain": "classic_slope",
        "difficulty": 1.0,
        "dt": 0.01,
        "u_max": None,
        "max_episode_steps": 2000,
        "observation": "sensors",
        "sensors": {
            "encoder_resolution": 0.0015339807878856412,
            "encoder_noise": 0.001,
            "scan_count": 10,
            "scan_offset": 0.1,
            "scan_spacing": 0.15,
            "scan_noise": 0.002,
            "scan_resolution": 0.001,
            "scan_range": 1.0,
            "latency": 0,
        },
        "reward": {"progress": 1.0, "energy": 0.01, "failure": 1.0, "work": "absolute"},
        "initial_state": {
            "q": [-0.54255, -0.218775],
            "qd": [0.716732, 1.092867],
            "spread": [0.005, 0.005, 0.02, 0.02],
            "stance_leg": "A",
        },
        "simulator": {},
        "robot_error": 0.0,
        "push": None,
    },
}
# the paper's stairs climbed: the stairs settings on their own course
EXPECTED["stairs_up"] = {**EXPECTED["stairs"], "terrain": "paper_stairs_up"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_variants_merge_to_their_complete_settings(name: str) -> None:
    data = load_env_config(name)
    assert data == EXPECTED[name]
    assert all(type(data[k]) is type(v) for k, v in EXPECTED[name].items())  # 1.0 stays float
    data["sensors"]["latency"] = 5  # a fresh copy each time
    assert load_env_config(name) == EXPECTED[name]


def test_registered_ids_use_their_variant() -> None:
    assert available_env_configs() == sorted(EXPECTED)  # the base is no variant
    for env_id, config in ENV_IDS.items():
        spec = gym.spec(f"{NAMESPACE}/{env_id}")
        assert spec.kwargs == {"config": config}
        assert spec.max_episode_steps == EXPECTED[config]["max_episode_steps"]
        assert spec.entry_point == "envs.env:CompassGaitEnv"
        assert spec.vector_entry_point == "envs.vector_env:CompassGaitVectorEnv"
    assert not any("base" in spec_id.lower() for spec_id in gym.registry)
    with pytest.raises(ValueError, match=r"unknown env config 'base'; available: \['flat'"):
        load_env_config("base")


def test_keyword_overrides_merge_sections_field_by_field() -> None:
    s = resolve_env_settings("slope", sensors={"latency": 2}, reward={"failure": 3.0}, dt=None)
    assert s.sensors.latency == 2 and s.sensors.scan_offset == 0.1 and s.sensors.scan_range == 1.0
    assert s.reward.failure == 3.0 and s.reward.energy == 0.01
    assert s.dt == 0.01  # None keeps the config's value
    start = resolve_env_settings("flat", initial_state={"stance_leg": "B"}).initial_state
    assert start.stance_leg == "B" and start.q == (-0.5, -0.25)
    # one actuator limit: an override in one form replaces the config's other form
    config = {**EXPECTED["flat"], "u_max": None, "torque_limit": 0.5}
    assert resolve_env_settings(config, u_max=3.0).robot.u_max == 3.0
    assert EnvSettings.build("slope").dt == resolve_env_settings("slope").dt
    with pytest.raises(ValueError, match="unknown env argument 'colour'"):
        resolve_env_settings("flat", colour="red")


def test_user_configs_complete_or_over_a_base(tmp_path) -> None:
    # a complete mapping or file, as before
    full = tmp_path / "mine.yaml"
    full.write_text(yaml.safe_dump({**EXPECTED["flat"], "dt": 0.004}))
    assert load_env_config(str(full)) == {**EXPECTED["flat"], "dt": 0.004}
    assert load_env_config({**EXPECTED["slope"]}) == EXPECTED["slope"]
    # or only the differences from a variant (a name or a file)
    small = tmp_path / "small.yaml"
    small.write_text("base: slope\nsensors: {latency: 1}\nterrain: flat\n")
    expected = {**EXPECTED["slope"], "terrain": "flat"}
    expected["sensors"] = {**EXPECTED["slope"]["sensors"], "latency": 1}
    assert load_env_config(str(small)) == expected
    assert load_env_config({"base": str(small), "dt": 0.02}) == {**expected, "dt": 0.02}
    env = gym.make("roughwalk/CompassGait-v0", config=str(small), reward={"energy": 0.0})
    assert env.unwrapped.dt == 0.01 and env.unwrapped.settings.reward.energy == 0.0
    loop = tmp_path / "loop.yaml"
    loop.write_text(f"base: {loop}\n")
    with pytest.raises(ValueError, match="base"):
        load_env_config(str(loop))
    with pytest.raises(ValueError, match=r"unknown env setting\(s\) \['colour'\]"):
        load_env_config({"base": "flat", "colour": "red"})


@pytest.mark.parametrize("key", ["retract", "arm_distance"])
def test_foot_geometry_is_set_on_the_robot_not_the_simulator(key: str, tmp_path) -> None:
    with pytest.raises(ValueError, match=rf"SimConfig\.{key} moved.*RobotParams\.{key}"):
        resolve_env_settings("flat", simulator={key: 0.1})
    mine = tmp_path / "mine.yaml"
    mine.write_text(f"base: flat\nsimulator: {{{key}: 0.1}}\n")
    with pytest.raises(ValueError, match=rf"RobotParams\.{key}"):
        gym.make("roughwalk/CompassGait-v0", config=str(mine))
    robot = RobotParams.from_preset("paper").replace(**{key: 0.2})
    settings = resolve_env_settings("flat", robot=robot, torque_limit=0.5)
    assert getattr(settings.robot, key) == 0.2  # kept when the actuator limit is applied
    assert settings.robot.u_max == 0.5 / robot.input_gain
