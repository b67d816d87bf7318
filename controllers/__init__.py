"""roughwalk controllers: Bezier virtual constraints, reduced dynamics, gait planning,
transverse linearization, jump-Riccati receding-horizon control, observer, reference policy."""

# Bezier constraints, footsteps and gait planning; transverse-linearization controller,
# observer and reference policy
from .bezier import BezierConstraint, bernstein_basis, bezier
from .controller import ControllerConfig, PDController, TransverseController
from .gains import GainTable
from .identification import SwingIdentifier
from .observer import HighGainObserver
from .planner import (
    FootholdRules,
    GaitPlanner,
    PeriodicGait,
    Plan,
    PlannerConfig,
    PlanningError,
    StepPlan,
    TerrainMap,
)
from .reference import PDPolicy, ReferencePolicy, make_reference_policy
from .riccati import solve_jump_riccati

__all__ = [
    "BezierConstraint",
    "FootholdRules",
    "GaitPlanner",
    "PeriodicGait",
    "Plan",
    "PlannerConfig",
    "PlanningError",
    "StepPlan",
    "SwingIdentifier",
    "TerrainMap",
    "bernstein_basis",
    "bezier",
    "ControllerConfig",
    "GainTable",
    "HighGainObserver",
    "PDController",
    "PDPolicy",
    "ReferencePolicy",
    "TransverseController",
    "make_reference_policy",
    "solve_jump_riccati",
]
