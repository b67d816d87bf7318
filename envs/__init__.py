"""roughwalk environments: compass-gait model, terrain, simulator and Gymnasium envs."""

from .env import CompassGaitEnv
from .physics import (
    FAILURES,
    RobotParams,
    SimConfig,
    SimResult,
    Simulator,
    StepEvents,
    Terrain,
    simulate,
)
from .physics.encoders import encoders_to_q, q_to_encoders
from .registration import register_envs
from .sensors import SensorConfig, SensorLayout
from .vector_env import CompassGaitVectorEnv

# Gymnasium environments: the "roughwalk/..." ids are registered on import
register_envs()

__all__ = [
    "CompassGaitEnv",
    "CompassGaitVectorEnv",
    "SensorConfig",
    "SensorLayout",
    "encoders_to_q",
    "q_to_encoders",
    "register_envs",
    "FAILURES",
    "RobotParams",
    "SimConfig",
    "SimResult",
    "Simulator",
    "StepEvents",
    "Terrain",
    "simulate",
]
