"""Physics of the compass-gait biped, free of any Gymnasium dependency.

Modules: :mod:`~envs.physics.params` (robot parameters and the flat parameter vector),
:mod:`~envs.physics.actuator` (the hip command's units: input, action, torque),
:mod:`~envs.physics.model` (equations of motion, impact, kinematics, contact conditions),
:mod:`~envs.physics.terrain` (ground profiles and their compiled height/slope queries),
:mod:`~envs.physics.kernel` (the simulator's compiled per-walker step),
:mod:`~envs.physics.simulator` (:class:`Simulator`, :func:`simulate`) and
:mod:`~envs.physics.passive` (the passive limit cycle down a slope).
"""

from . import model
from .kernel import FAILURES
from .params import RobotParams, as_params, available_presets
from .passive import LimitCycle, passive_limit_cycle, slope_section_state, slope_step_map
from .simulator import SimConfig, SimResult, Simulator, StepEvents, simulate
from .terrain import (
    KINDS,
    Terrain,
    as_terrain,
    available_terrains,
    terrain_height,
    terrain_slope,
    terrain_spec,
)

__all__ = [
    "FAILURES",
    "KINDS",
    "LimitCycle",
    "RobotParams",
    "SimConfig",
    "SimResult",
    "Simulator",
    "StepEvents",
    "Terrain",
    "as_params",
    "as_terrain",
    "available_presets",
    "available_terrains",
    "model",
    "passive_limit_cycle",
    "simulate",
    "slope_section_state",
    "slope_step_map",
    "terrain_height",
    "terrain_slope",
    "terrain_spec",
]
