"""Former home of the compiled step evaluation; it lives in :mod:`controllers.planner.kernel`."""

from .planner.kernel import (
    StepGrids,
    StepGround,
    StepOutputs,
    StepScalars,
    StepSettings,
    evaluate_steps,
    pack,
    packed_size,
)

__all__ = [
    "StepGrids",
    "StepGround",
    "StepOutputs",
    "StepScalars",
    "StepSettings",
    "evaluate_steps",
    "pack",
    "packed_size",
]
