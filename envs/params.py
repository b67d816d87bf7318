"""Old import path of the robot parameters, replaced by :mod:`envs.physics.params`.

Re-exports the names other modules import from here; new code imports from ``envs.physics``.
"""

from configs import CONFIG_DIR

from .physics.params import (
    N_PARAMS,
    P1,
    P2,
    P3,
    P4,
    P5,
    P6,
    P7,
    P8,
    PB,
    PFC,
    PFV,
    PG,
    PIC,
    PL,
    PLC,
    PM,
    PMH,
    PMHG,
    PUMAX,
    RobotParams,
    as_params,
    available_presets,
)

__all__ = [
    "CONFIG_DIR",
    "N_PARAMS",
    "P1",
    "P2",
    "P3",
    "P4",
    "P5",
    "P6",
    "P7",
    "P8",
    "PB",
    "PFC",
    "PFV",
    "PG",
    "PIC",
    "PL",
    "PLC",
    "PM",
    "PMH",
    "PMHG",
    "PUMAX",
    "RobotParams",
    "as_params",
    "available_presets",
]
