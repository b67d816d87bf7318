"""roughwalk environments: compass-gait model, terrain, simulator and Gymnasium envs."""

from .env import CompassGaitEnv
from .params import RobotParams
from .registration import register_envs
from .sensors import SensorConfig, SensorLayout, encoders_to_q, q_to_encoders
from .simulator import FAILURES, SimConfig, SimResult, Simulator, StepEvents, simulate
from .terrain import Terrain
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
