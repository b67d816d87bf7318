"""Transverse-linearization receding-horizon controller (paper Sections 3 and 4).

At every footstep the controller

1. (re)plans the motion from the actual post-impact state with the gait planner
   (:class:`controllers.planner.GaitPlanner`), or, with ``replan=False``, keeps following one plan
   made at :meth:`TransverseController.reset`;
2. linearises the transverse dynamics of the current step and the next ``horizon`` steps and
   solves the jump-Riccati equation over them (:func:`controllers.gains.horizon_gains`), and
   loads the current step's :class:`controllers.gains.GainTable`.

Every control tick then applies ``v = K(theta) x_perp`` and the partial feedback linearisation
``u = (v - R) / N`` (``y_ddot = N u + R``, hip friction included, so it is compensated), clipped to
the actuator limit: :func:`controllers.feedback.feedback_law`.

The two modes (:attr:`ControllerConfig.mode`):

- ``"fixed-plan"`` (``replan=False``), the paper's setting: one plan of ``plan_steps`` footsteps
  is made at reset and tracked with the receding-horizon jump Riccati. Its Appendix A argument
  applies: ``V = x_perp' P x_perp`` with ``P = Z^-1`` of the step's solve decreases along each
  step and does not increase when the horizon is renewed at the impact, so the planned motion is
  locally exponentially orbitally stable (for the model, without noise or model error, within a
  neighbourhood the argument does not size). When the plan runs out the controller falls back
  as described below.
- ``"replan"`` (the default): every footstep is planned afresh from the post-impact state, so
  every step starts at ``x_perp = 0`` (``V_start`` about 0): no certificate; ``V`` over a step
  only measures how far the step drifted from its own plan.

Each :class:`StepRecord` keeps ``V`` at the step's first and last tick, their ratio, the largest
``|x_perp|`` and the largest ``|u|``: the certificate made visible (evidence, not a proof).

If the full planning problem has no solution (:class:`PlanningError`), the controller degrades
in the order of ``ControllerConfig.fallbacks``, stopping at the first that gives at least two
steps (the current one and a look-ahead for the Riccati equation):

* a mapping of :class:`PlannerConfig` changes (a *relaxation*, e.g. ``{"torque_fraction":
  0.95}``): plan again with those settings, steps still pulled to the nominal periodic gait
  (``fallback = "relaxed: torque_fraction=0.95"``);
* ``"previous plan"``: the rest of the previous plan, shifted by one footstep, while it still
  looks at least one step ahead;
* ``"least violation"``: the two least-violating steps
  (:meth:`GaitPlanner.plan_least_violation`, from the last relaxation's settings).

A plan outside the full problem's constraints (from a relaxation, or the least-violating
steps) is tracked with PD on ``y`` by default (``ControllerConfig.relaxed_feedback = "pd"``,
:data:`FALLBACK_PD`), the speed along it left to the hybrid zero dynamics: its nominal input
uses the torque reserve or more, or it is not feasible at all, and the Riccati feedback's pull
on ``I`` towards its nominal speed then takes from the hip what the motion needs
(``"riccati"``: the transverse feedback, as for every other plan). Shorter look-aheads and the
previous plan were feasible with the full settings and keep the transverse feedback.

Within the full problem and each relaxation, a search that fails beyond the second step keeps
the feasible steps before the failure (``"shorter horizon"``, or the relaxation's name followed
by ``", shorter horizon"``). With ``ControllerConfig.deeper_relaxation`` (a relaxation), a full
problem that plans only such a shorter look-ahead is planned again under that relaxation, and
the deeper of the two plans is tracked (``fallback = "relaxed: ..., deeper"``, or ``"relaxed:
..., deeper, shorter horizon"``; tracked as any relaxed plan): a look-ahead that ends in a step
the full problem cannot plan is a dead end the robot would walk into. Where the planner's
beam search over the horizon (``PlannerConfig.beam_width``) is on, it runs first when the
depth-first search fails, and its plan over the whole horizon is tracked as a full plan (the
record's reason says so). When none gives two steps, a single step (the first feasible step
found, else what is left of the previous plan) is held with PD on ``y`` (``fallback = "PD on
the last planned step"``; also when the Riccati solve over the look-ahead fails, and a step
whose transverse model cannot be built ends the look-ahead). A replan within a step (the
state left the plan's tube, or :meth:`TransverseController.replan`) that finds nothing to
track, not even the rest of the plan under way, keeps tracking the step under way with its
gains (``fallback = "step under way"``).
Where nothing is left to track (no step keeps ``theta_dot`` positive, say: the robot cannot
crest what is ahead), the robot is not left limp: the swing leg is held at the nominal
touchdown's inter-leg angle (the preferred step length on level ground) with PD on ``y`` of
that constant constraint, through the same control tick, until the next touchdown or a replan
within the step finds a plan (``fallback = "hold posture"``; ``ControllerConfig.posture_hold``).
Zero input (``fallback = "zero input"``) remains only for a non-finite state.
The step's :class:`StepRecord` says which, and why (``reason``: every degradation tried, with
its planning error).

The planner's dip floor (``PlannerConfig.dip_floor``) is a preference of the full problem:
where no plan keeps it, the full problem is planned again without it (a degradation recorded
as ``"full problem without the dip floor"``, with its own whole budget) and its plan is
tracked as a full plan (no fallback); every degradation plans without the floor.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from envs.config_util import (
    dataclass_from_mapping,
    finite_pair,
    integer_setting,
    preset_settings,
    read_yaml_mapping,
    real_setting,
)
from envs.physics import model
from envs.physics.params import RobotParams, as_params
from envs.physics.simulator import SimConfig, Simulator
from envs.physics.terrain import Terrain, as_terrain

from .fallbacks import (
    DEFAULT_FALLBACKS,
    TUBE_FALLBACKS,
    fallback_items,
    fallback_name,
    relaxation_item,
)
from .feedback import (
    constraint_at,
    control_tick,
    feedback_law,
    pack_scalars,
    thetadot_sq_at,
)
from .gains import GainTable, HorizonSolution, horizon_gains, pd_gains, step_models
from .numerics import one_blas_thread
from .planner import (
    GaitPlanner,
    Plan,
    PlannerConfig,
    PlanningError,
    StepPlan,
    touchdown_configuration,
)
from .records import HOLD_POSTURE, PD_ON_ONE_STEP, STEP_UNDER_WAY, ZERO_INPUT, StepRecord
from .transverse import StepModel

__all__ = [
    "MODES",
    "PAPER_WEIGHTS",
    "ControllerConfig",
    "PDController",
    "StepRecord",
    "TransverseController",
]

#: PD gains (kp [1/s^2], kd [1/s]) on a last remaining planned step and on relaxed plans
FALLBACK_PD = (400.0, 40.0)

#: the controller's modes (:attr:`ControllerConfig.mode`): replan at every footstep, or track
#: one plan made at reset (the paper's setting, with its Appendix A certificate)
MODES = ("replan", "fixed-plan")

#: what tracks a relaxed or least-violating plan (``ControllerConfig.relaxed_feedback``)
RELAXED_FEEDBACK = ("pd", "riccati")

#: footsteps per simulated second a fixed plan is sized for when only the run's duration is
#: known (:meth:`ControllerConfig.for_mode`); the paper robot takes about 1.1
PLAN_STEPS_PER_SECOND = 1.5


# ---------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class ControllerConfig:
    """Settings of the transverse controller.

    Attributes:
        horizon: look-ahead ``h`` in footsteps beyond the current one (paper: 3), >= 1.
        Q: diagonal of the running weight on ``x_perp = [I, y, y_dot]`` (paper: ones), > 0.
        R: weight on ``v = y_ddot`` (paper: 1), > 0.
        Qj: diagonal of the weight at each impact (paper: ones), > 0.
        grid: RK4 steps per footstep of the Riccati solve (``grid + 1`` gain nodes), >= 4.
        replan: replan from the actual post-impact state at every footstep (True, mode
            ``"replan"``) or track the plan made at reset (False, mode ``"fixed-plan"``, the
            paper's setting); see the module docstring for what each mode certifies.
        plan_steps: steps planned at reset when ``replan`` is False (>= horizon + 1; choose
            enough for the whole run: past the plan's end the controller falls back); when
            replanning, ``horizon + 1`` steps are planned at each footstep.
        margin: fraction of a step's span by which the nominal speed profile is extended
            beyond its ends, for states slightly before ``theta+`` or after ``theta-``.
        late_blend: if the touchdown has not happened at the planned ``theta-``, the constraint
            is continued with its slope ``phi'`` blended to 0 over this many radians (the legs
            stop opening, the hip falls forward, the swing foot goes down); 0 extrapolates the
            Bezier polynomial instead. [rad], >= 0.
        fallbacks: the degradations tried in order when the full planning problem has no
            solution (see the module docstring): ``"previous plan"``, ``"least violation"``,
            or a mapping of :class:`PlannerConfig` fields to relaxed values (a relaxation,
            stored as sorted ``(field, value)`` pairs). Default :data:`DEFAULT_FALLBACKS`:
            ``torque_fraction`` 0.95, then 1.0; then also ``duration_min`` 0.05 s and
            ``duration_max`` 3 s; then the previous plan; then the least-violating steps. An
            empty list gives the plain chain (shorter horizon, PD on a single step).
        replan_evaluations: step evaluations (see :attr:`PlannerConfig.max_evaluations`) the
            planner calls of one replanning may spend together, the full problem and the
            relaxations (the beam search over the horizon, which has its own budget per call,
            :attr:`PlannerConfig.beam_evaluations`, not counted: see
            ``replan_beam_evaluations``); each call gets what is left
            (at most the planner's own ``max_evaluations``), the least-violating steps get the
            planner's own budget. A deterministic bound on the replanning time (about 55 us per
            evaluation on one core), >= 1. The plan at :meth:`TransverseController.reset`
            (nothing to fall back on) runs its whole search.
        replan_beam_evaluations: step evaluations the beam searches of one replanning may spend
            together, >= 0: each planner call's beam search gets what is left (at most
            :attr:`PlannerConfig.beam_evaluations`), so a replanning spends at most
            ``replan_evaluations`` plus this (plus a batch a beam pass) with the least-violating
            steps' own budget. 0 (the class default; the paper robot's preset,
            ``configs/controller/paper.yaml``, has 20,000, with the beam's near shapes alone,
            and had 40,000 before them): each call's beam search has the planner's whole
            budget (a footstep whose full problem and deeper relaxation both run one spends it
            twice).
        tube_energy: replan within a step (replan mode) when the estimated state leaves the
            plan's tube: ``|theta_dot^2 - theta_dot*^2(theta)|`` above this fraction of
            ``theta_dot*^2(theta)`` (a push, a stall in the making, a plan made from a poor
            estimate); 0 disables the energy test. >= 0.
        tube_y: ... or ``|y|`` above this [rad]; 0 disables the test. >= 0.
        tube_ticks: the state must stay out of the tube this many consecutive ticks (noise
            must not trigger a replan), >= 1.
        tube_phase: only while the step has covered at most this fraction of its phase range
            ``[theta+, theta-]`` (room left to act), in [0, 1].
        tube_replans: replans within one step at most (0 disables them), >= 0.
        tube_fallbacks: the degradations a replan within a step tries, in order (items as in
            ``fallbacks``; the full problem is not tried first). Default
            :data:`TUBE_FALLBACKS`: ``duration_min`` 0.05 s with the torque limit, then the
            current plan.
        deeper_relaxation: a relaxation (a mapping of :class:`PlannerConfig` fields to relaxed
            values, as an item of ``fallbacks``) under which a full problem that plans fewer
            steps than the look-ahead is planned again, the deeper plan tracked (see the module
            docstring); empty (default): the shorter look-ahead is tracked.
        relaxed_feedback: what tracks a plan outside the full problem's constraints (the
            step's ``fallback`` is a relaxation, ``"relaxed: ..."``, or ``"least violation"``):
            ``"pd"`` (default), PD on ``y`` with :data:`FALLBACK_PD`, no feedback on the speed
            along the motion; ``"riccati"``, the transverse feedback as for every other plan.
        friction_limit: friction coefficient (dimensionless) of a friction-cone clip on the
            input: at every tick ``u`` is also clipped to the inputs under which the nominal
            model's ground reaction on the stance foot, at the estimated state, stays inside
            ``|f_t| <= friction_limit f_n`` (no clip where no input does); 0 (default) clips to
            ``u_max`` only. Stiff feedback weights otherwise ask for hip torques that make the
            stance foot slip. >= 0.
        posture_hold: where nothing is left to track at a footstep, hold the swing leg at the
            nominal touchdown's inter-leg angle with PD on ``y`` (True, default; the record's
            ``fallback = "hold posture"``), or apply zero input until the next touchdown
            (False, the behaviour before it).
    """

    horizon: int = 3
    Q: tuple[float, float, float] = (1.0, 1.0, 1.0)
    R: float = 1.0
    Qj: tuple[float, float, float] = (1.0, 1.0, 1.0)
    grid: int = 40
    replan: bool = True
    plan_steps: int = 12
    margin: float = 0.15
    late_blend: float = 0.05
    fallbacks: tuple = DEFAULT_FALLBACKS
    replan_evaluations: int = 4000
    replan_beam_evaluations: int = 0
    tube_energy: float = 0.25
    tube_y: float = 0.0
    tube_ticks: int = 4
    tube_phase: float = 0.6
    tube_replans: int = 1
    tube_fallbacks: tuple = TUBE_FALLBACKS
    deeper_relaxation: tuple = ()
    relaxed_feedback: str = "pd"
    friction_limit: float = 0.0
    posture_hold: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "fallbacks", fallback_items(self.fallbacks))
        object.__setattr__(
            self, "tube_fallbacks", fallback_items(self.tube_fallbacks, "tube_fallbacks")
        )
        object.__setattr__(self, "deeper_relaxation", relaxation_item(self.deeper_relaxation))
        lows = {
            "horizon": 1,
            "grid": 4,
            "plan_steps": 2,
            "replan_evaluations": 1,
            "replan_beam_evaluations": 0,
            "tube_ticks": 1,
            "tube_replans": 0,
        }
        for name, lo in lows.items():
            v = integer_setting(f"ControllerConfig.{name}", getattr(self, name), lo)
            object.__setattr__(self, name, v)
        for name in ("Q", "Qj"):
            raw = getattr(self, name)
            try:
                v = tuple(real_setting(name, x) for x in raw)
            except (TypeError, ValueError):
                v = ()
            if len(v) != 3 or not all(x > 0 for x in v):
                raise ValueError(f"ControllerConfig.{name} = {raw!r}; allowed: three numbers > 0")
            object.__setattr__(self, name, v)
        R = real_setting("ControllerConfig.R", self.R, "a finite number > 0")
        if not R > 0:
            raise ValueError(f"ControllerConfig.R = {self.R!r}; allowed: a finite number > 0")
        object.__setattr__(self, "R", R)
        blend = real_setting("ControllerConfig.late_blend", self.late_blend, ">= 0 rad")
        if not blend >= 0:
            raise ValueError(f"ControllerConfig.late_blend = {self.late_blend!r}; allowed: >= 0")
        object.__setattr__(self, "late_blend", blend)
        margin = real_setting("ControllerConfig.margin", self.margin, "[0, 0.5]")
        if not (0.0 <= margin <= 0.5):
            raise ValueError(f"ControllerConfig.margin = {self.margin!r}; allowed: [0, 0.5]")
        for name in ("tube_energy", "tube_y", "tube_phase", "friction_limit"):
            v = real_setting(f"ControllerConfig.{name}", getattr(self, name), ">= 0")
            hi = 1.0 if name == "tube_phase" else math.inf
            if not (0.0 <= v <= hi):
                allowed = "[0, 1]" if name == "tube_phase" else ">= 0"
                raise ValueError(f"ControllerConfig.{name} = {v!r}; allowed: {allowed}")
            object.__setattr__(self, name, v)
        for name in ("replan", "posture_hold"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(
                    f"ControllerConfig.{name} = {getattr(self, name)!r}; allowed: True or False"
                )
        if self.relaxed_feedback not in RELAXED_FEEDBACK:
            raise ValueError(
                f"ControllerConfig.relaxed_feedback = {self.relaxed_feedback!r}; allowed: "
                + ", ".join(repr(v) for v in RELAXED_FEEDBACK)
            )

    @property
    def mode(self) -> str:
        """``"replan"`` or ``"fixed-plan"`` (one of :data:`MODES`), from :attr:`replan`."""
        return MODES[0] if self.replan else MODES[1]

    @classmethod
    def for_robot(cls, name: str | None, /, **changes: Any) -> ControllerConfig:
        """The controller's defaults for the robot preset ``name`` from
        ``configs/controller/NAME.yaml`` (the class defaults, the paper's published settings,
        where there is no such file or ``name`` is None), with ``changes`` applied."""
        return cls.from_dict(preset_settings("controller", name, "controller config", changes))

    @classmethod
    def for_mode(
        cls, mode: str, duration: float | None = None, robot: str | None = None, /, **fields: Any
    ) -> ControllerConfig:
        """The config of ``mode`` (one of :data:`MODES`) with the other ``fields`` as given.

        Args:
            mode: ``"replan"`` or ``"fixed-plan"``.
            duration: the run's simulated time [s] (> 0, finite); in fixed-plan mode without
                ``plan_steps`` the plan is sized for it: :data:`PLAN_STEPS_PER_SECOND` footsteps
                a second plus the look-ahead.
            robot: the robot preset whose defaults fill the fields not given (see
                :meth:`for_robot`; None: the class defaults).
            fields: other :class:`ControllerConfig` fields (not ``replan``).
        """
        if mode not in MODES:
            raise ValueError(f"controller mode = {mode!r}; allowed: {', '.join(MODES)}")
        if "replan" in fields:
            raise ValueError("ControllerConfig.for_mode: give the mode, not replan")
        config = cls.for_robot(robot, replan=mode == "replan", **fields)
        if mode == "fixed-plan" and duration is not None and "plan_steps" not in fields:
            d = real_setting("duration", duration, "a finite number > 0 [s]")
            if not d > 0:
                raise ValueError(f"duration = {duration!r}; allowed: a finite number > 0 [s]")
            steps = math.ceil(PLAN_STEPS_PER_SECOND * d) + config.horizon + 1
            config = replace(config, plan_steps=steps)
        return config

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> ControllerConfig:
        """Build from a dict ``d`` of the fields (unknown keys raise ``ValueError``); None gives
        the defaults."""
        if d is None:
            return cls()
        return dataclass_from_mapping(cls, d, "controller")

    @classmethod
    def from_yaml(cls, path: str | Path) -> ControllerConfig:
        """Build from the YAML file at ``path`` holding the fields (unknown keys raise
        ``ValueError``)."""
        return cls.from_dict(read_yaml_mapping(path, "controller config"))

    def to_dict(self) -> dict[str, Any]:
        """The fields as a plain dict (the inverse of :meth:`from_dict`)."""
        return asdict(self)


#: the full problem without the planner's dip floor (``PlannerConfig.dip_floor``, a preference
#: of the full problem): planned where no plan keeps the floor, tracked as the full problem's
#: plans are; every degradation plans without the floor too
WITHOUT_DIP_FLOOR: tuple = (("dip_floor", 0.0),)
FULL_WITHOUT_DIP_FLOOR = "full problem without the dip floor"

#: the paper's feedback weights (``Q``, ``R``, ``Qj``: the class defaults), whatever a robot's
#: preset sets: the basin's convergence metric and the bench's baseline solve
PAPER_WEIGHTS: dict[str, Any] = {
    name: getattr(ControllerConfig(), name) for name in ("Q", "R", "Qj")
}


def _book(outcome: Plan | PlanningError, rec: StepRecord, notes: list[str], name: str) -> int:
    """Record a planner call of the degradation ``name`` in ``rec``: the step evaluations it
    spent and, where it raised ``outcome``, whether its budget cut it and the error (in
    ``notes``). Returns what it charges to the replanning's shared budget (the beam search's
    evaluations have their own)."""
    rec.plan_evaluations += outcome.evaluations
    if isinstance(outcome, PlanningError):
        rec.budget_exhausted |= outcome.budget_exhausted
        notes.append(f"{name}: {outcome}")
    return outcome.evaluations - outcome.beam_evaluations


def _budget_spent(left: int, rec: StepRecord, notes: list[str], name: str) -> bool:
    """Whether the replanning's shared budget is spent (``left`` step evaluations) before
    the degradation ``name``; if so, say so in ``rec`` and ``notes``."""
    if left > 0:
        return False
    notes.append(f"{name}: replanning budget spent")
    rec.budget_exhausted = True
    return True


class TransverseController:
    """Receding-horizon transverse-linearization controller (state feedback).

    Args:
        robot: robot parameters or preset name.
        terrain: the terrain map (a :class:`Terrain`, spec or kind name); :meth:`reset` may
            give another one for the new run.
        config: :class:`ControllerConfig`, or a dict of the fields that differ from the robot's
            defaults (:meth:`ControllerConfig.for_robot`; None: those defaults).
        planner: a :class:`GaitPlanner`, a :class:`PlannerConfig`/dict for a new one, or None
            (the robot's default planner).

    Attributes:
        records: one :class:`StepRecord` per footstep since the last reset.
        plan: the plan being followed (None before the first one).
        solution: the current step's :class:`HorizonSolution` (None without gains).
        gain_table: the current step's :class:`GainTable` as the control tick reads it (None
            without gains: zero input).

    Use with :func:`envs.simulate`: ``simulate(robot, terrain, q0, qd0, T, torque=ctrl)`` after
    ``ctrl.reset(q0, qd0)``; as a callable it returns the hip torque [N m] and detects impacts
    from the jump of ``q2`` (the new stance foot is then located from the configuration). For
    exact footholds drive it with :meth:`on_impact` (see :meth:`rollout`).
    """

    #: the feedback acts on the speed along the motion (``I``); relaxed plans are then
    #: tracked as ``ControllerConfig.relaxed_feedback`` says
    speed_feedback = True

    def __init__(
        self,
        robot: RobotParams | str,
        terrain: Terrain | dict | str,
        config: ControllerConfig | dict | None = None,
        planner: GaitPlanner | PlannerConfig | dict | None = None,
    ):
        self.robot = as_params(robot)
        self.P = self.robot.vector()
        self.terrain = as_terrain(terrain)
        if not isinstance(config, ControllerConfig):
            config = ControllerConfig.for_robot(self.robot.name, **(config or {}))
        self.config = config
        if isinstance(planner, GaitPlanner):
            self.planner = planner
        else:
            self.planner = GaitPlanner(self.robot, planner)
        self._configured = self.planner  # the planner before adjust_planner's changes
        self._adjustment: tuple = ()
        self._extra_margin = 0.0  # widen_margins
        self._extra_drop_edge = 0.0
        self.records: list[StepRecord] = []
        self.plan: Plan | None = None
        self.solution: HorizonSolution | None = None
        self.gain_table: GainTable | None = None
        self._law_args: tuple[np.ndarray, ...] = ()  # gain_table.kernel_args()
        self._tick_args: tuple[np.ndarray, ...] = ()  # ... and the solution's Zinv
        self._phase_range = (math.nan, math.nan)  # the solution's theta[0], theta[-1] [rad]
        self._hold: tuple[np.ndarray, ...] | None = None  # the posture hold's, without gains
        self._torque_gain = float(model.input_gain(self.P))  # hip torque per input unit [N m]
        self._plan_offset = 0
        self._beam_left: int | None = None  # a replanning's beam budget left (None: no cap)
        self._relaxed: dict[tuple, GaitPlanner] = {}  # relaxed planners, by relaxation
        for level in (*self.config.fallbacks, *self.config.tube_fallbacks):
            # a relaxation out of range fails here
            if level != "previous plan":
                self._planner_for(level)
        self._stance = (0.0, 0.0)
        self._last_q2 = math.nan
        self._x = np.zeros(4)
        self._theta_start = math.nan  # theta where the current step's tracking began
        self._outside = 0  # consecutive ticks outside the plan's tube

    def set_robot(self, robot: RobotParams) -> None:
        """Plan and track with the model ``robot`` from the next (re)plan on (an identified
        one, say): a planner with the same settings for it; the current step's gains stay
        until then."""
        robot = as_params(robot)
        self._configured = GaitPlanner(robot, self._configured.config)
        self._use_adjustment(self._adjustment)
        self.robot = robot
        self.P = robot.vector()
        self._torque_gain = float(model.input_gain(self.P))

    def adjust_planner(self, **changes: float) -> None:
        """Plan with the planner settings ``changes`` (fields of :class:`PlannerConfig`, e.g.
        ``target_speed`` or ``foothold_shift``) instead of the configured ones from the next
        planning call on (the next touchdown, or a replan within the step); none: the
        configured planner again. Steps still pull towards the configured planner's periodic
        gait, and the degradations relax the adjusted settings.

        Raises:
            ValueError: an unknown field or a value out of its range.
        """
        key = tuple(sorted(changes.items()))
        if key != self._adjustment:
            self._use_adjustment(key)

    @property
    def configured_planner(self) -> GaitPlanner:
        """The planner as configured (for the model in use), before :meth:`adjust_planner`'s
        and :meth:`widen_margins`' changes."""
        return self._configured

    def widen_margins(self, extra: float, drop_edge: float = 0.0) -> None:
        """Keep footholds ``extra`` [m] further from faces and kinks than the configured
        ``PlannerConfig.edge_margin`` from the next planning call on (where a foot lands is
        uncertain: a leg length not yet measured, say), and rank footholds closer than
        ``edge_margin + drop_edge`` [m] to a step-down riser last (``drop_edge`` in place of
        ``PlannerConfig.drop_edge_margin`` where that is smaller), on top of
        :meth:`adjust_planner`'s changes; 0: the configured margins.

        Raises:
            ValueError: ``extra`` or ``drop_edge`` negative or not finite.
        """
        extra, drop_edge = float(extra), float(drop_edge)
        for name, value in (("extra margin", extra), ("drop_edge", drop_edge)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r}; allowed: >= 0 m")
        if (extra, drop_edge) != (self._extra_margin, self._extra_drop_edge):
            self._extra_margin, self._extra_drop_edge = extra, drop_edge
            self._use_adjustment(self._adjustment)

    def _use_adjustment(self, adjustment: tuple) -> None:
        """Plan with the configured planner changed by ``adjustment`` (sorted ``(field,
        value)`` pairs; a bad one raises before anything changes) and the margins widened by
        :meth:`widen_margins`."""
        base = self._configured
        changes = dict(adjustment)
        if self._extra_margin > 0:
            margin = changes.get("edge_margin", base.config.edge_margin)
            changes["edge_margin"] = margin + self._extra_margin
        drop_edge = changes.get("drop_edge_margin", base.config.drop_edge_margin)
        if self._extra_drop_edge > drop_edge:
            changes["drop_edge_margin"] = self._extra_drop_edge
        self.planner = base.relaxed(**changes) if changes else base
        self._adjustment = adjustment
        self._relaxed.clear()  # the degradations' planners derive from this one

    # ------------------------------------------------------------------ planning
    def reset(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        stance_foot: tuple[float, float] | None = None,
        t: float = 0.0,
        terrain: Terrain | dict | str | None = None,
    ) -> None:
        """Start a new run from the state ``(q, qd)`` [rad, rad/s] with the stance foot at
        ``stance_foot`` [m] (default: ``x = 0`` on the ground) at time ``t`` [s], on
        ``terrain`` (a :class:`Terrain`, spec or kind name; default: the current terrain)."""
        if terrain is not None:
            self.terrain = as_terrain(terrain)
        if stance_foot is None:
            stance_foot = (0.0, float(self.terrain.height(0.0)))
        stance = finite_pair("stance_foot", stance_foot, "m")
        self.records = []
        self.plan = None
        self.solution = None
        self._stance = stance
        self._start_step(np.asarray(q, float), np.asarray(qd, float), t, first=True)

    def on_impact(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        stance_foot: tuple[float, float],
        t: float = math.nan,
        terrain: Terrain | dict | str | None = None,
    ) -> None:
        """A touchdown happened: ``(q, qd)`` is the post-impact state [rad, rad/s],
        ``stance_foot`` the new stance-foot position [m], ``t`` the impact time [s] (NaN if
        unknown), ``terrain`` an updated terrain map (e.g. one built from the scans; default:
        the current one). Replans (or advances the fixed plan) and re-solves."""
        if terrain is not None:
            self.terrain = as_terrain(terrain)
        self._stance = finite_pair("stance_foot", stance_foot, "m")
        self._start_step(np.asarray(q, float), np.asarray(qd, float), t, first=False)

    def replan(
        self, q: np.ndarray, qd: np.ndarray, terrain: Terrain | dict | str | None = None
    ) -> None:
        """Replan the rest of the current step from the state ``(q, qd)`` (same stance foot),
        e.g. once a velocity observer has converged, on ``terrain`` if given (an updated map;
        default: the current one); ignored when ``replan`` is False."""
        if terrain is not None:
            self.terrain = as_terrain(terrain)
        if not self.config.replan or not self.records:
            return
        self._start_step(
            np.asarray(q, float), np.asarray(qd, float), math.nan, first=False, new_step=False
        )

    @one_blas_thread
    def _start_step(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        t: float,
        first: bool,
        new_step: bool = True,
        within: bool = False,
    ) -> None:
        cfg = self.config
        if new_step or not self.records:
            rec = StepRecord(index=len(self.records), t_start=float(t))
            self.records.append(rec)
            under_way = None
        else:
            rec = self.records[-1]
            under_way = (self.solution, self.plan, self._plan_offset, rec.fallback, rec.pd_feedback)
            rec.fallback = rec.reason = None
            rec.plan_evaluations, rec.budget_exhausted, rec.degradations = 0, False, []
            rec.pd_feedback = False
        self._last_q2 = float(q[1])
        if new_step or not math.isfinite(self._theta_start):
            self._theta_start = float(q[1])
        self._outside = 0
        steps: list[StepPlan] | None = None
        if first or cfg.replan:
            n = cfg.horizon + 1 if cfg.replan else max(cfg.plan_steps, cfg.horizon + 1)
            t0 = time.perf_counter()
            previous = self.plan if cfg.replan else None
            levels = cfg.tube_fallbacks if within else (None, *cfg.fallbacks)
            steps = self._plan_steps(q, qd, n, first, new_step, previous, rec, levels)
            rec.plan_time = time.perf_counter() - t0
        else:
            self._plan_offset += 1
            steps = self.plan.steps[self._plan_offset :] if self.plan is not None else []
        sol = None
        if steps:
            models = []
            for step in steps[: cfg.horizon + 1]:
                try:
                    models.extend(step_models(self.P, [step], self.terrain, cfg.margin))
                except ValueError as exc:  # a step with no motion to track: the look-ahead ends
                    rec.reason = " | ".join(filter(None, (rec.reason, f"step model: {exc}")))
                    break
            if len(models) >= 2:
                try:
                    fb = rec.fallback or ""
                    relaxed = fb.startswith("relaxed") or fb == "least violation"
                    if relaxed and cfg.relaxed_feedback == "pd" and self.speed_feedback:
                        sol = pd_gains(models, cfg.grid, *FALLBACK_PD)
                        rec.pd_feedback = True
                    else:
                        sol = self._gains(models)
                except ValueError as exc:
                    rec.reason = " | ".join(filter(None, (rec.reason, f"gains: {exc}")))
                    models = models[:1]
            if sol is None and models:
                # one step to track: no look-ahead to solve over, hold it with PD on y
                sol = pd_gains(models[:1], cfg.grid, *FALLBACK_PD)
                rec.fallback = PD_ON_ONE_STEP
        if sol is None and under_way is not None and under_way[0] is not None:
            # a replan within the step found nothing to track: track the step under way on
            self.solution, self.plan, self._plan_offset, fallback, pd = under_way
            rec.pd_feedback = pd or fallback == PD_ON_ONE_STEP
            rec.fallback = STEP_UNDER_WAY
            return
        if sol is None:
            self.solution = None
            self.gain_table = None
            self._hold = self._posture_hold(q) if cfg.posture_hold else None
            rec.fallback = ZERO_INPUT if self._hold is None else HOLD_POSTURE
            return
        self.solution = sol
        rec.riccati_time = sol.riccati_time
        rec.solve_time = sol.solve_time
        self._load(sol)

    def _plan_steps(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        n: int,
        first: bool,
        new_step: bool,
        previous: Plan | None,
        rec: StepRecord,
        levels: tuple,
    ) -> list[StepPlan] | None:
        """Plan ``n`` steps from ``(q, qd)`` trying ``levels`` in order (None: the full
        problem; then degradations as in ``ControllerConfig.fallbacks``, module docstring).
        Records what it did in ``rec``; returns the steps to track (None: nothing)."""
        single: list[StepPlan] = []  # the first lone step found (held with PD if nothing else)
        notes: list[str] = []
        left = self.config.replan_evaluations
        self._beam_left = self.config.replan_beam_evaluations or None  # None: no shared cap
        cap = self.planner.config.max_evaluations
        floored = self.planner.config.dip_floor > 0
        if floored and levels and levels[0] is None:
            levels = (None, WITHOUT_DIP_FLOOR, *levels[1:])
        for level in levels:
            full = level is None or level == WITHOUT_DIP_FLOOR
            if level is None:
                name = "full problem"
            else:
                name = FULL_WITHOUT_DIP_FLOOR if full else fallback_name(level)
            rec.degradations.append(name)
            if level == "previous plan":
                old, off = self._previous_steps(first, new_step)
                if len(old) >= 2:
                    self._plan_offset = off
                    rec.fallback, rec.reason = name, " | ".join(notes)
                    return old
                notes.append(f"{name}: fewer than two steps left")
                continue
            if level != "least violation" and _budget_spent(left, rec, notes, name):
                continue
            planner = self._planner_for(level)
            try:
                if level == "least violation":
                    plan = planner.plan_least_violation(
                        self.terrain, (q, qd), self._stance, horizon=2, previous_plan=previous
                    )
                else:
                    plan = self._budgeted_plan(planner, q, qd, n, previous, min(left, cap))
            except PlanningError as exc:
                spent = _book(exc, rec, notes, name)
                if level is None and floored:
                    # a preference: the full problem without it next, with the whole budget
                    continue
                left -= spent
                if len(exc.partial) < 2:
                    single = single or list(exc.partial)
                    continue
                # the steps before the failure are feasible: a shorter look-ahead
                plan = Plan(exc.partial, self.robot, planner.config)
                name = "shorter horizon" if level is None else f"{name}, shorter horizon"
                if full and self.config.deeper_relaxation:
                    plan, name, left = self._deeper(
                        q, qd, n, previous, rec, notes, left, cap, plan, name
                    )
            except ValueError as exc:  # a state the planner cannot start from
                notes.append(f"{name}: {exc}")
                break
            else:
                spent = _book(plan, rec, notes, name)
                if level != "least violation":  # it has the planner's own budget
                    left -= spent
                if len(plan.steps) < 2:
                    single = single or list(plan.steps)
                    notes.append(f"{name}: fewer than two steps")
                    continue
                if level == "least violation":
                    worst = min(plan.violations)
                    if worst[0] < 0:
                        notes.append(f"{name}: worst violation {worst[0]:.3g} ({worst[1]})")
            self.plan, self._plan_offset = plan, 0
            rec.fallback = None if name in ("full problem", FULL_WITHOUT_DIP_FLOOR) else name
            if plan.steps[0].note:
                notes.append(f"{name}: {plan.steps[0].note}")
            if plan.beam:
                notes.append(f"{name}: beam search over the horizon")
            rec.reason = " | ".join(notes) or None
            return plan.steps
        rec.reason = " | ".join(notes) or None
        if single:
            # keep the older plan (if any) for later fallbacks
            self._plan_offset = self._previous_steps(first, new_step)[1]
            if self.plan is None:
                self.plan = Plan(single, self.robot, self.planner.config)
            return single
        old, off = self._previous_steps(first, new_step)
        if old:
            self._plan_offset = off
            rec.fallback = "previous plan"
            return old
        return None

    def _deeper(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        n: int,
        previous: Plan | None,
        rec: StepRecord,
        notes: list[str],
        left: int,
        cap: int,
        plan: Plan,
        name: str,
    ) -> tuple[Plan, str, int]:
        """The full problem planned only ``plan``, a shorter look-ahead: plan again under
        ``ControllerConfig.deeper_relaxation`` and return the deeper plan, its fallback name and
        the replanning budget left (``plan`` and ``name`` as given where that is no deeper)."""
        level = self.config.deeper_relaxation
        relaxed = f"{fallback_name(level)}, deeper"
        rec.degradations.append(relaxed)
        if _budget_spent(left, rec, notes, relaxed):
            return plan, name, left
        planner = self._planner_for(level)
        try:
            deeper = self._budgeted_plan(planner, q, qd, n, previous, min(left, cap))
        except PlanningError as exc:
            left -= _book(exc, rec, notes, relaxed)
            if len(exc.partial) <= len(plan.steps):
                return plan, name, left
            return (
                Plan(exc.partial, self.robot, planner.config),
                f"{relaxed}, shorter horizon",
                left,
            )
        left -= _book(deeper, rec, notes, relaxed)
        return deeper, relaxed, left

    def _budgeted_plan(
        self,
        planner: GaitPlanner,
        q: np.ndarray,
        qd: np.ndarray,
        n: int,
        previous: Plan | None,
        budget: int,
    ) -> Plan:
        """``planner``'s plan of ``n`` steps from ``(q, qd)`` within ``budget`` step
        evaluations and, where :attr:`ControllerConfig.replan_beam_evaluations` caps them,
        what the replanning's beam searches have left (its whole search at reset, with no
        previous plan to fall back on).

        Raises:
            PlanningError: as :meth:`GaitPlanner.plan`.
        """
        replanning = previous is not None
        beam = self._beam_left if replanning else None
        outcome: Plan | PlanningError | None = None
        try:
            outcome = planner.plan(
                self.terrain,
                (q, qd),
                self._stance,
                horizon=n,
                previous_plan=previous,
                max_evaluations=budget if replanning else None,
                max_beam_evaluations=beam,
            )
            return outcome
        except PlanningError as exc:
            outcome = exc
            raise
        finally:
            if beam is not None and outcome is not None:
                self._beam_left = max(beam - outcome.beam_evaluations, 0)

    def _previous_steps(self, first: bool, new_step: bool) -> tuple[list[StepPlan], int]:
        """What is left of the previous plan for the current step, and its offset."""
        off = self._plan_offset
        if first or self.plan is None:
            return [], off
        off = self._plan_offset + int(new_step)
        return self.plan.steps[off:], off

    def _planner_for(self, level: Any) -> GaitPlanner:
        """The planner of a degradation: the full problem's, a relaxation's (made on first
        use), and for the least-violating steps the last relaxation's."""
        if level == "least violation":
            relaxations = [f for f in self.config.fallbacks if not isinstance(f, str)]
            level = relaxations[-1] if relaxations else None
        if level is None:
            return self.planner
        key = (id(self.planner), level)
        out = self._relaxed.get(key)
        if out is None:  # every degradation plans without the dip floor
            out = self._relaxed[key] = self.planner.relaxed(
                **{**dict(WITHOUT_DIP_FLOOR), **dict(level)}
            )
        return out

    def _gains(self, models: list[StepModel]) -> HorizonSolution:
        return horizon_gains(models, self.config)

    def _friction_clip(self) -> tuple[float, float]:
        """The control tick's friction-cone clip: ``(friction_limit, slope)``, the ground slope
        ``dh/dx`` under the stance foot (0 where the clip is off)."""
        limit = self.config.friction_limit
        return limit, (self.terrain.slope_at(self._stance[0]) if limit > 0 else 0.0)

    def _load(self, sol: HorizonSolution) -> None:
        limit, slope = self._friction_clip()
        table = GainTable.from_solution(
            sol,
            self.robot.u_max,
            self.config.late_blend,
            4 * self.config.grid,
            limit,
            slope,
        )
        self.gain_table = table
        self._law_args = table.kernel_args()
        # the tick's arguments (Z^-1 lies on the gain grid) and the planned phase range
        self._tick_args = (*self._law_args, sol.Zinv)
        self._phase_range = (float(sol.theta[0]), float(sol.theta[-1]))
        self._hold = None
        m0 = sol.steps[0]
        c = m0.constraint
        rec = self.records[-1]
        rec.thetadot_nominal = (m0.thetadot_plus, math.sqrt(m0.thetadot_sq(c.theta_minus)))

    # ------------------------------------------------------------------ control
    def coords(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """``x_perp`` of the state ``(q, qd)`` [rad, rad/s] relative to the current step, shape
        ``(3,)`` (NaN without a plan)."""
        if self.solution is None:
            return np.full(3, np.nan)
        return self.solution.steps[0].coords(np.r_[q, qd])

    def nominal(self, theta: float) -> np.ndarray:
        """Nominal ``(q1, q1d, q2d)`` of the current step at phase ``theta`` (NaN without a
        plan): ``phi(theta)``, ``phi'(theta) theta_dot*(theta)``, ``theta_dot*(theta)``, with the
        constraint continued past ``theta-`` as the feedback law does."""
        if self.solution is None:
            return np.full(3, np.nan)
        tab, pc, thetadot_sq, dthetadot_sq, _ = self._law_args
        ph, dph, _ = constraint_at(tab, pc, float(theta))
        td = math.sqrt(max(thetadot_sq_at(tab, thetadot_sq, dthetadot_sq, float(theta)), 0.0))
        return np.array([ph, dph * td, td])

    def control(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Input ``u`` [input units] for the state ``(q, qd)``; records diagnostics."""
        x = self._x
        x[0], x[1], x[2], x[3] = q[0], q[1], qd[0], qd[1]
        return self.control_state(x)

    def control_state(self, x: np.ndarray) -> float:
        """:meth:`control` for the state ``x = (q1, q2, q1d, q2d)`` [rad, rad/s] as one float64
        array (read during the call, not kept)."""
        rec = self.records[-1] if self.records else None
        if self.gain_table is None:
            return self._without_gains(x, rec)
        # x_perp goes into the step record's own array (a new record has a new one)
        z = rec.xperp_end if rec is not None else np.empty(3)
        u, I, y, yd, ref, V = control_tick(self.P, x, *self._tick_args, z)
        if rec is not None and self._leaves_tube(x[1], I, y, ref, rec):
            rec.retargets += 1
            self._start_step(
                x[:2].copy(), x[2:].copy(), math.nan, first=False, new_step=False, within=True
            )
            rec.reason = " | ".join(filter(None, ("left the plan's tube: replanned", rec.reason)))
            if self.gain_table is None:
                return self._without_gains(x, rec)
            u, I, y, yd, ref, V = control_tick(self.P, x, *self._tick_args, z)
        if rec is None:
            return u
        theta, thetadot = x[1], x[3]
        if rec.ticks == 0:
            rec.thetadot_start = thetadot
            rec.xperp_start = z.copy()
            rec.V_start = V
        elif self._phase_range[0] <= theta <= self._phase_range[1]:
            # the Lyapunov argument holds on the planned phase range of the step
            dV = V - rec.V_end
            if dV > rec.V_increase:
                rec.V_increase = dV
        rec.thetadot_end = thetadot
        rec.V_end = V
        ay, au = abs(y), abs(u)
        if ay > rec.max_abs_y:
            rec.max_abs_y = ay
        norm = math.sqrt(I * I + y * y + yd * yd)
        if norm > rec.max_xperp_norm:
            rec.max_xperp_norm = norm
        if au > rec.max_abs_u:
            rec.max_abs_u = au
        if au >= self.robot.u_max:
            rec.saturated += 1
        rec.ticks += 1
        return u

    def _without_gains(self, x: np.ndarray, rec: StepRecord | None) -> float:
        """Input of a tick with no plan's gains loaded: the posture hold's, else zero."""
        u = 0.0 if self._hold is None else feedback_law(self.P, x, *self._hold)[0]
        if rec is not None:
            rec.ticks += 1
            rec.max_abs_u = max(rec.max_abs_u, abs(u))
            rec.saturated += int(abs(u) >= self.robot.u_max)
        return u

    def _posture_hold(self, q: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """The control tick's arguments (as :meth:`GainTable.kernel_args`) that hold the swing
        leg at the nominal touchdown's inter-leg angle (a step of the planner's
        ``step_length`` on level ground) from the state's phase ``q[1]`` [rad] on: the
        constant constraint ``phi = q1``, PD on ``y`` (:data:`FALLBACK_PD`), no speed
        feedback, the actuator limit and friction clip of the plans. None where ``q`` is not
        finite."""
        if not np.all(np.isfinite(q)):
            return None
        q1, _ = touchdown_configuration(self.planner.config.step_length, 0.0, self.robot.l)
        th = float(q[1])
        tab = pack_scalars(th, 1.0, th, 1.0, th, 1.0, self.robot.u_max, 0.0, *self._friction_clip())
        kp, kd = FALLBACK_PD
        K = np.tile(np.array([0.0, -kp, -kd]), (2, 1))
        return tab, np.array([float(q1)]), np.zeros(2), np.zeros(2), K

    def _leaves_tube(self, theta: float, I: float, y: float, ref: float, rec: StepRecord) -> bool:
        """Whether the state has been outside the plan's tube (``ControllerConfig.tube_*``)
        long enough, early enough in the step, for a replan within it (``ref``: the nominal
        ``theta_dot^2`` at the phase ``theta`` [rad^2/s^2])."""
        cfg = self.config
        if not cfg.replan or rec.retargets >= cfg.tube_replans or self.solution is None:
            return False
        out = (cfg.tube_energy > 0 and abs(I) > cfg.tube_energy * max(ref, 1e-9)) or (
            cfg.tube_y > 0 and abs(y) > cfg.tube_y
        )
        self._outside = self._outside + 1 if out else 0
        if self._outside < cfg.tube_ticks:
            return False
        end = self.solution.steps[0].constraint.theta_minus
        span = end - self._theta_start
        return span > 0 and (theta - self._theta_start) <= cfg.tube_phase * span

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> float:
        """Hip torque [N m] for :func:`envs.simulate` (detects impacts from the state)."""
        if self.records and q[1] < self._last_q2 - 0.5 * abs(q[0]):
            # legs swapped: the trailing (old stance) foot is the swing foot now
            fx, _ = model.swing_foot_position(self.P, q[0], q[1], 0.0, 0.0)
            x_new = self._stance[0] - float(fx)
            self.on_impact(q, qd, (x_new, float(self.terrain.height(x_new))), t)
        self._last_q2 = float(q[1])
        return self._torque_gain * self.control(q, qd)

    # ------------------------------------------------------------------ closed loop
    def rollout(
        self,
        q0: np.ndarray,
        qd0: np.ndarray,
        duration: float,
        dt: float = 0.005,
        steps: int | None = None,
        sim_config: SimConfig | None = None,
    ) -> dict[str, Any]:
        """Closed loop with the hybrid simulator, exact footholds from its impact events.

        Args:
            q0, qd0: start state; duration: simulated time [s]; dt: control period [s];
            steps: stop after this many footsteps; sim_config: :class:`envs.physics.SimConfig`.

        Returns:
            dict with ``t, q, qd, u`` per tick, ``impacts`` (times), ``failure`` (None or the
            simulator's reason), ``records`` (:class:`StepRecord` list).
        """
        sim = Simulator(self.robot, self.terrain, 1, dt=dt, config=sim_config, parallel=False)
        foot = (0.0, float(self.terrain.height(0.0)))
        sim.reset(q0, qd0, foot)
        self.reset(np.asarray(q0, float), np.asarray(qd0, float), foot)
        b = self._torque_gain
        ts, qs, qds, us, imps = [], [], [], [], []
        n = int(math.ceil(duration / dt - 1e-9))
        failure = None
        for _ in range(n):
            q, qd = sim.q[0].copy(), sim.qd[0].copy()
            u = self.control(q, qd)
            ts.append(float(sim.t[0]))
            qs.append(q)
            qds.append(qd)
            us.append(u)
            ev = sim.step(b * u)
            if ev.status[0] != 0:
                failure = sim.failure(0)
                break
            k = int(ev.n_impacts[0])
            if k:
                imps.extend(float(v) for v in ev.impact_time[0, :k])
                self.on_impact(
                    sim.q[0].copy(), sim.qd[0].copy(), tuple(sim.stance_foot[0]), float(sim.t[0])
                )
                if steps is not None and len(imps) >= steps:
                    break
        return {
            "t": np.array(ts),
            "q": np.array(qs),
            "qd": np.array(qds),
            "u": np.array(us),
            "impacts": np.array(imps),
            "failure": failure,
            "records": self.records,
        }


class PDController(TransverseController):
    """The same planned constraints enforced by plain PD on ``y`` (the simple baseline).

    ``v = -kp y - kd y_dot`` through the same partial feedback linearisation ``u = (v - R)/N``
    (friction compensated, clipped); no feedback on ``I``, so the speed along the motion is
    left to the hybrid zero dynamics. Same planning, fallback and diagnostics as
    :class:`TransverseController` (``V`` is reported with ``Z^-1 = I``).

    Args:
        robot, terrain, config, planner: as for :class:`TransverseController`.
        kp: proportional gain [1/s^2], > 0; kd: derivative gain [1/s], > 0 (defaults: a
            critically damped pair with poles at -20 rad/s).
    """

    speed_feedback = False  # PD on y everywhere: relaxed plans need no other feedback

    def __init__(
        self,
        robot: RobotParams | str,
        terrain: Terrain | dict | str,
        config: ControllerConfig | dict | None = None,
        planner: GaitPlanner | PlannerConfig | dict | None = None,
        kp: float = 400.0,
        kd: float = 40.0,
    ):
        if not (math.isfinite(kp) and kp > 0 and math.isfinite(kd) and kd > 0):
            raise ValueError(f"PD gains kp = {kp!r}, kd = {kd!r}; allowed: > 0")
        super().__init__(robot, terrain, config, planner)
        self.kp, self.kd = float(kp), float(kd)

    def _gains(self, models: list[StepModel]) -> HorizonSolution:
        return pd_gains(models, self.config.grid, self.kp, self.kd)
