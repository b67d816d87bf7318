"""Settings of a compass-gait environment and the one place they are resolved.

An env variant is a YAML file in ``configs/envs/``. ``base.yaml`` holds every setting (with its
units); each variant (``flat``, ``stairs``, ``rough``, ``slope``) names its base (``base: base``)
and holds only what differs. :func:`load_env_config` returns a variant's merged mapping;
:func:`resolve_env_settings` turns an env config (a variant name, a YAML path or a mapping) plus
the keyword arguments of ``gym.make`` into validated :class:`EnvSettings`.

Merging, the same for a base under a variant and for keyword arguments over a config: a key
replaces the earlier value (``robot_error`` and ``push`` as a whole), except the sections
``sensors``, ``reward``, ``initial_state`` and ``simulator``, whose mappings are merged field by
field; giving ``u_max`` drops ``torque_limit`` and the reverse (one actuator limit in either
form). Keyword arguments that are ``None`` keep the config's value (``push=False`` switches
off the pushes of a config, ``robot_error=0`` its model error).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from configs import CONFIG_DIR

from .config_util import dataclass_from_mapping, read_yaml_mapping
from .disturbances import PushConfig, RobotError
from .physics.params import MAX_HIP_TORQUE, RobotParams, as_params
from .physics.simulator import SimConfig
from .sensors import SensorConfig
from .task import InitialState, RewardConfig, TerrainSource

ENV_CONFIG_DIR = CONFIG_DIR / "envs"
#: files in ``configs/envs`` that only serve as bases of the variants (not env configs)
BASE_CONFIGS = ("base",)
#: the key of an env config that names its base (a name in ``configs/envs`` or a YAML path)
BASE_KEY = "base"
OBSERVATION_MODES = ("sensors", "state")
SETTING_KEYS = (
    "robot",
    "terrain",
    "difficulty",
    "dt",
    "u_max",
    "torque_limit",
    "observation",
    "sensors",
    "reward",
    "initial_state",
    "simulator",
    "max_episode_steps",
    "robot_error",
    "push",
)
#: settings whose mappings are merged field by field
SECTION_KEYS = ("sensors", "reward", "initial_state", "simulator")
#: the two forms of the actuator limit: setting one drops the other
_LIMIT_FORMS = {"u_max": "torque_limit", "torque_limit": "u_max"}


@dataclass(frozen=True)
class EnvSettings:
    """All settings of a compass-gait environment (see :class:`envs.CompassGaitEnv`).

    Attributes:
        robot: the robot's parameters (with the actuator limit applied).
        terrain: the course, fixed or drawn at every reset.
        dt: control period [s].
        observation: ``"sensors"`` or ``"state"``.
        sensors: the simulated sensors.
        reward: the reward weights.
        initial_state: the start-state distribution.
        simulator: the simulator's numerical settings.
        max_episode_steps: time limit in control periods, or None.
        robot_error: the simulated robot's parameter errors, drawn at every reset (none by
            default; ``robot`` stays the nominal model).
        push: the hip pushes, or None (default).
    """

    robot: RobotParams
    terrain: TerrainSource
    dt: float
    observation: str
    sensors: SensorConfig
    reward: RewardConfig
    initial_state: InitialState
    simulator: SimConfig
    max_episode_steps: int | None
    robot_error: RobotError = RobotError()
    push: PushConfig | None = None

    @classmethod
    def build(cls, config: str | Path | dict[str, Any] = "flat", **overrides: Any) -> EnvSettings:
        """The same as :func:`resolve_env_settings`."""
        return resolve_env_settings(config, **overrides)


def available_env_configs() -> list[str]:
    """Names of the env variants shipped in ``configs/envs`` (bases excluded)."""
    return sorted(p.stem for p in ENV_CONFIG_DIR.glob("*.yaml") if p.stem not in BASE_CONFIGS)


def merge_env_config(
    data: dict[str, Any], changes: dict[str, Any], *, none_keeps: bool = False
) -> None:
    """Apply ``changes`` to the env config ``data`` in place (rules in the module docstring).

    Args:
        data: the mapping changed.
        changes: settings to apply, in order.
        none_keeps: a ``None`` in ``changes`` keeps ``data``'s value (keyword arguments) rather
            than replacing it (YAML files).
    """
    for key, value in changes.items():
        if value is None and none_keeps:
            continue
        if key in SECTION_KEYS and isinstance(value, dict):
            merged = dict(data.get(key) or {})
            merged.update(value)
            data[key] = merged
        else:
            data[key] = value
        if key in _LIMIT_FORMS:
            data.pop(_LIMIT_FORMS[key], None)


def load_env_config(config: str | Path | dict[str, Any]) -> dict[str, Any]:
    """Raw settings of an env variant: a name in ``configs/envs``, a YAML path, or a mapping.

    A config that names a base (``base: NAME``, a name in ``configs/envs`` or a YAML path) is
    merged over the base's settings; without one it is complete as given.
    """
    seen = () if isinstance(config, dict) else (str(config),)
    return _load(config, allow_base_names=False, seen=seen)


def _load(config: Any, *, allow_base_names: bool, seen: tuple[str, ...]) -> dict[str, Any]:
    if isinstance(config, dict):
        data = copy.deepcopy(config)
    else:
        path = Path(config)
        if path.suffix not in (".yaml", ".yml"):
            names = available_env_configs()
            if str(config) not in names and not (allow_base_names and str(config) in BASE_CONFIGS):
                raise ValueError(
                    f"unknown env config {config!r}; available: {names} or a path to a YAML file"
                )
            path = ENV_CONFIG_DIR / f"{config}.yaml"
        if not path.is_file():
            raise ValueError(f"env config file {str(path)!r} does not exist")
        data = read_yaml_mapping(path, "env config")
    if not isinstance(data, dict):
        raise ValueError(f"env config must be a mapping, got {type(data).__name__}")
    if BASE_KEY in data:
        base = data.pop(BASE_KEY)
        if not isinstance(base, (str, Path)) or str(base) in seen:
            raise ValueError(f"env config base {base!r} must name another env config or file")
        merged = _load(base, allow_base_names=True, seen=(*seen, str(base)))
        merge_env_config(merged, data)
        data = merged
    unknown = sorted(set(data) - set(SETTING_KEYS))
    if unknown:
        raise ValueError(f"unknown env setting(s) {unknown}; allowed: {list(SETTING_KEYS)}")
    return data


def resolve_env_settings(
    config: str | Path | dict[str, Any] = "flat", **overrides: Any
) -> EnvSettings:
    """Settings from an env config plus keyword overrides (``None`` keeps the config's).

    Args:
        config: a variant name in ``configs/envs``, a YAML path, or a mapping (see
            :func:`load_env_config`).
        **overrides: any of :data:`SETTING_KEYS`; ``sensors``, ``reward``, ``initial_state``
            and ``simulator`` mappings are merged into the config's field by field.

    Raises:
        ValueError: an unknown config or argument, or a value out of range (the message names
            it and what is allowed).
    """
    data = load_env_config(config)
    for key in overrides:
        if key not in SETTING_KEYS:
            raise ValueError(f"unknown env argument {key!r}; allowed: {list(SETTING_KEYS)}")
    merge_env_config(data, overrides, none_keeps=True)
    robot = as_params(data.get("robot", "paper"))
    u_max, torque_limit = data.get("u_max"), data.get("torque_limit")
    if u_max is not None and torque_limit is not None:
        raise ValueError("give the actuator limit as u_max or as torque_limit, not both")
    if torque_limit is not None:
        if isinstance(torque_limit, bool) or not isinstance(torque_limit, (int, float)):
            raise ValueError(f"torque_limit must be a number of N m, got {torque_limit!r}")
        if not (math.isfinite(torque_limit) and 0 < torque_limit <= MAX_HIP_TORQUE):
            raise ValueError(
                f"torque_limit = {torque_limit!r} out of range; allowed: (0, {MAX_HIP_TORQUE:g}] "
                "N m (hip torque at |action| = 1)"
            )
        u_max = torque_limit / robot.input_gain
    if u_max is not None:
        robot = robot.replace(u_max=u_max)
    dt = data.get("dt", 0.005)
    if isinstance(dt, bool) or not isinstance(dt, (int, float)):
        raise ValueError(f"dt must be a number of seconds, got {dt!r}")
    if not (math.isfinite(dt) and 0 < dt <= 0.1):
        raise ValueError(f"dt = {dt!r} out of range; allowed: (0, 0.1] s")
    obs = data.get("observation", "sensors")
    if obs not in OBSERVATION_MODES:
        raise ValueError(f"observation = {obs!r}; allowed: {list(OBSERVATION_MODES)}")
    if "initial_state" not in data:
        raise ValueError("env config needs an 'initial_state' with q and qd")
    sim = data.get("simulator") or {}
    if isinstance(sim, dict):
        sim = dataclass_from_mapping(SimConfig, sim, "simulator")
    elif not isinstance(sim, SimConfig):
        raise ValueError(f"simulator must be a mapping or SimConfig, got {type(sim)}")
    mes = check_max_episode_steps(data.get("max_episode_steps"))
    robot_error = RobotError.from_setting(data.get("robot_error"))
    robot_error.check(robot)
    return EnvSettings(
        robot=robot,
        terrain=TerrainSource(data.get("terrain", "flat"), data.get("difficulty", 1.0)),
        dt=float(dt),
        observation=obs,
        sensors=SensorConfig.from_dict(data.get("sensors")),
        reward=dataclass_from_mapping(RewardConfig, data.get("reward") or {}, "reward"),
        initial_state=dataclass_from_mapping(InitialState, data["initial_state"], "initial_state"),
        simulator=sim,
        max_episode_steps=mes,
        robot_error=robot_error,
        push=PushConfig.from_setting(data.get("push")),
    )


def check_max_episode_steps(value: Any) -> int | None:
    """The time limit ``value`` [control periods] checked: an integer >= 1 (an integral float
    such as ``3000.0`` is taken as one) or None.

    Raises:
        ValueError: anything else (``2.5``, ``0``, ``"3"``, ``True``), naming the setting.
    """
    if value is None:
        return None
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if not (ok and math.isfinite(value) and int(value) == value and value >= 1):
        raise ValueError(f"max_episode_steps = {value!r}; allowed: integer >= 1 or None")
    return int(value)
