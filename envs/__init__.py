"""roughwalk environments: compass-gait model, terrain, simulator and Gymnasium envs."""

from .params import RobotParams

__all__ = ["RobotParams"]
