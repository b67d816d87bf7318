"""Former home of the foothold selection; it lives in :mod:`controllers.planner.footholds`."""

from .planner.footholds import (
    FootholdRules,
    TerrainMap,
    candidate_footholds,
    touchdown_configuration,
)

__all__ = ["FootholdRules", "TerrainMap", "candidate_footholds", "touchdown_configuration"]
