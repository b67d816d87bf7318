"""Step-by-step gait planner: footholds and Bezier virtual constraints over rough terrain.

For every step ``j`` the planner chooses a foothold and a Bezier constraint
``q1 = phi_j(theta)``, ``theta = q2``, of order ``M`` (4 by default):

* ``a_0`` and ``theta_plus`` are the post-impact configuration (for step 0 the *actual* one);
* ``a_1`` gives ``phi'(theta_plus)`` equal to the post-impact velocity direction
  ``q1d+/q2d+`` (impact invariance; for step 0 the actual velocity direction);
* ``a_M`` and ``theta_minus`` put the swing foot on the foothold with both legs straight;
* ``a_2 .. a_{M-1}`` are free: a small SLSQP problem per step picks them so that the step is
  feasible while the walking speed is regulated towards a target.

The package follows the method section by section:

* :mod:`.config`: the settings (:class:`PlannerConfig`) and :class:`PlanningError`;
* :mod:`.plan`: the plan objects (:class:`StepPlan`, :class:`Plan`, :class:`PeriodicGait`);
* :mod:`.footholds`: the terrain map, the foothold rules and candidates, and the search for
  chains of admissible footholds that ranks them;
* :mod:`.problem`: the step problem (constraints and cost of one step, the one table of its
  constraint groups, the SLSQP adaptor), evaluated by the compiled :mod:`.kernel`;
* :mod:`.periodic`: the periodic flat-ground gait, the reference of the step costs;
* :mod:`.search`: one planning call's depth-first search over footholds and step shapes;
* :mod:`.least_violation`: the least-violating steps, when no feasible step exists;
* :mod:`.gait_planner`: :class:`GaitPlanner`, the entry point.

Conventions: control notes, sections 1 and 2. Units: rad, rad/s, m, s; hip input ``u`` in the
robot's input units (torque ``kI ktau u``).
"""

from .config import PlannerConfig, PlanningError
from .footholds import FootholdRules, TerrainMap, candidate_footholds, touchdown_configuration
from .gait_planner import GaitPlanner
from .plan import PeriodicGait, Plan, StepPlan

__all__ = [
    "FootholdRules",
    "GaitPlanner",
    "PeriodicGait",
    "Plan",
    "PlannerConfig",
    "PlanningError",
    "StepPlan",
    "TerrainMap",
    "candidate_footholds",
    "touchdown_configuration",
]
