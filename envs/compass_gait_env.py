"""Former home of the Gymnasium layer, kept so that old imports keep working.

The code now lives in :mod:`envs.settings` (settings and their loader), :mod:`envs.task`
(reward, start state, terrain source), :mod:`envs.batch` (the walker batch and its kernels) and
:mod:`envs.env` (the env and the action scaling).
"""

from .batch import PARALLEL_MIN_WALKERS, WalkerBatch
from .env import CompassGaitEnv, actions_to_torques
from .settings import (
    ENV_CONFIG_DIR,
    OBSERVATION_MODES,
    EnvSettings,
    available_env_configs,
    load_env_config,
)
from .task import TERRAIN_CONFIG_DIR, InitialState, RewardConfig, TerrainSource, terrain_spec

__all__ = [
    "ENV_CONFIG_DIR",
    "OBSERVATION_MODES",
    "PARALLEL_MIN_WALKERS",
    "TERRAIN_CONFIG_DIR",
    "CompassGaitEnv",
    "EnvSettings",
    "InitialState",
    "RewardConfig",
    "TerrainSource",
    "WalkerBatch",
    "actions_to_torques",
    "available_env_configs",
    "load_env_config",
    "terrain_spec",
]
