"""Planner settings (:class:`PlannerConfig`, its foothold rules) and the planner's error.

Every setting is declared once, with its unit, in :class:`PlannerConfig`; the robot presets'
defaults live in ``configs/planner/<preset>.yaml``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from envs.config_util import (
    dataclass_from_mapping,
    preset_settings,
    read_yaml_mapping,
    reject_moved_fields,
)
from envs.physics.params import MOVED_TO_ROBOT

from .footholds import FootholdRules

__all__ = ["PlannerConfig", "PlanningError"]


#: quasi-random shapes in each of the beam search's two sets per foothold (near the gait's
#: shape and over the global search's range; :func:`controllers.planner.beam.beam_shapes`)
BEAM_SHAPES = 32


class PlanningError(RuntimeError):
    """No feasible plan: ``step`` (index within the horizon), the violated ``constraint`` and
    an optional ``detail`` (free text added to the message).

    A failed search also says what it found (set by :meth:`GaitPlanner.plan`): ``partial``, the
    feasible steps ``0 .. step - 1`` before the failure (a list of :class:`StepPlan`, the best
    plan found), ``evaluations`` (step evaluations spent, the beam search's included),
    ``beam_evaluations`` (those of the beam search over the horizon, which has its own budget,
    ``PlannerConfig.beam_evaluations`` or less where the call set less) and
    ``budget_exhausted`` (the search was cut by its budget, ``PlannerConfig.max_evaluations`` /
    ``time_budget``).
    """

    def __init__(self, step: int, constraint: str, detail: str = ""):
        self.step = int(step)
        self.constraint = str(constraint)
        self.detail = str(detail)
        self.partial: list = []
        self.evaluations = 0
        self.beam_evaluations = 0
        self.budget_exhausted = False
        msg = f"planning failed at step {self.step}: {self.constraint}"
        super().__init__(msg + (f" ({detail})" if detail else ""))

    def __reduce__(self) -> tuple:
        """Pickle (and copy) with the constructor's arguments and what the search set: a
        failure crosses process boundaries (vectorised envs, Ray workers) whole."""
        return type(self), (self.step, self.constraint, self.detail), self.__dict__


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings (SI units; lengths in m unless said "fraction of l").

    Attributes:
        order: Bezier order ``M`` (>= 4).
        grid: Chebyshev grid size ``n`` per step (``n + 1`` nodes) for the dynamics.
        check_points: intervals of the uniform grid on which the swing-foot geometry and
            ``theta_dot^2`` are checked.
        horizon: steps planned by default.
        target_speed: walking speed the plan regulates towards [m/s].
        step_length: preferred horizontal step length [m]; ``step_min``/``step_max`` bounds.
        edge_margin: least distance of a foothold from a face or kink [m].
        drop_margin: extra distance from a step-down riser behind a foothold, per metre of drop
            (room for the next swing's retracted foot to clear the riser) [m/m].
        rise_margin: extra distance from a step-up riser ahead of a foothold, per metre of rise
            (room for the next swing foot to clear the riser) [m/m].
        drop_edge_margin: footholds closer than ``edge_margin + drop_edge_margin`` to a
            step-down riser (ahead of them or behind them) rank after every other admissible
            foothold [m]: a preference, not a rule. A foot that lands off its plan (a leg
            longer or shorter than the model's, a foot estimated off) otherwise passes such a
            riser and swings back into its face. 0 (default): off.
        relaxed_margin: the fraction of ``drop_margin``, ``rise_margin`` and
            ``drop_edge_margin`` a step keeps where the full margins leave its stance foot no
            admissible foothold, in [0, 1] (1: no relaxation). On stairs the admissible
            footholds form windows; a foot that landed between two (a model error, a push)
            would otherwise have no step at all. The step's constraints still check the swing
            foot's clearance over the riser, and footholds are still ranked by the chains the
            full margins leave open.
        q1_min, q1_max: inter-leg angle at touchdown bounds [rad].
        max_rise, max_drop: largest height gain / loss in one step [m].
        duration_min, duration_max: step duration bounds [s] (Assumption 1).
        min_thetadot: least ``theta_dot`` over every step [rad/s].
        end_thetadot_floor: least end-of-step ``theta_dot`` the planner aims at [rad/s] (a
            speed reserve before drops, where the end speed is otherwise lowered by the
            height the next step loses; at least ``1.5 * min_thetadot``). A target, not a
            constraint: a step that cannot reach it is still feasible.
        gait_min_thetadot: least ``theta_dot`` of the nominal periodic gait [rad/s] (a reserve of
            kinetic energy for rises; the larger of the two applies to the gait).
        speed_reserve: the first step of a plan (the one under way, from the actual state)
            keeps ``theta_dot`` at or above ``min(speed_reserve, theta_dot at its start)``
            [rad/s]: a plan from a slowed robot may not slow it further below this (0: off,
            only ``min_thetadot``). Meant for the replans within a step, in a relaxation of
            :attr:`controllers.ControllerConfig.tube_fallbacks`: a replan that would slow the
            robot further then fails, and the current plan is kept.
        dip_floor: over every step ``theta_dot`` stays at or above this fraction of the
            step's own start ``theta_dot``, in [0, 1) (0: off). A reserve relative to the
            step's speed: it bounds how deep a step may dip towards a stall at mid-stance (a
            long step over a high apex), while a slowed robot (a push) may still plan slow
            steps. The reference controller takes it as a preference: where no plan keeps
            it, it plans without it (:mod:`controllers.controller`).
        torque_fraction: nominal ``|u|`` stays below this fraction of ``u_max``.
        clearance: least height of the armed swing foot above the ground away from touchdown
            [m]; it ramps down to 0 over the last ``clearance_ramp`` fraction of the step.
        arm_clearance: least height of the full-length swing foot when it gets armed [m]; the
            requirement rises from it to ``clearance`` over ``clearance_ramp`` of the step.
        retracted_clearance: least height of the retracted swing foot above the ground [m].
        face_clearance: least height of the swing foot over the top of a vertical face [m].
        touchdown_slope: least descent rate of the swing foot at touchdown,
            ``-d(clearance)/d theta`` [m/rad] (transversal impact).
        friction: friction coefficient used for the stance foot and the impact impulse.
        w_speed, w_end, w_shape, w_torque, w_slope: cost weights (speed error, error of the
            next step's post-impact ``theta_dot`` w.r.t. the periodic gait's, shape deviation
            from the periodic gait, mean squared input relative to ``u_max`` (periodic gait
            only), post-impact slope deviation).
        max_iter: SLSQP iterations per step.
        max_evaluations: step evaluations (rows of the compiled step kernel: SLSQP points and
            their forward-difference neighbours, global-search samples) one replanning call (one
            with a previous plan to fall back on) may spend; the search then stops and reports
            the best it found (a deterministic, machine-independent budget). A plan from
            scratch runs its whole search.
        time_budget: process time one replanning call may spend [s] (``time.process_time``);
            0 for no time bound (the default). A time bound cuts searches at a point that
            depends on the machine and its load: same seed, same result no longer holds.
        lookahead: 1 to optimise each step jointly with the next one (only the first is kept;
            anticipates drops and rises; slower), 2 to do so only where this step and the next
            change height by more than ``lookahead_rise`` [m] together, 0 never.
        energy_horizon: 0 (default): each step's end speed is the gait's, corrected by the
            height the next step gains or loses; n >= 1: the speed that reaches the gait's end
            speed ``n`` steps later over footholds ``step_length`` apart, backwards through the
            gait step's closed-form reduced dynamics and impact loss (a rise further ahead
            speeds up the current step).
        pairs_first: 1: with a look-ahead, try every candidate foothold's step jointly with the
            next one before any step alone (a foothold from which no next step exists, say
            too close before a riser, is then searched beyond only as a last resort); 0
            tries each foothold's pair and then the step alone before the next foothold.
        foothold_shift: moves the preferred foothold of every step by about this much [m]
            (the touchdown angle the candidates are ranked towards turns by ``shift / (2 l cos
            theta-)``); 0 for the periodic gait's. A per-footstep lever for a learned policy
            (``agents.footstep.FootstepWrapper``); within +-0.1 m.
        candidates: footholds tried per step before giving up.
        candidate_spacing: least spacing between the footholds tried [m].
        beam_width: when the depth-first search finds no plan over the horizon, a beam search
            over footholds and sampled step shapes (:mod:`controllers.planner.beam`) keeps
            this many branches per depth and returns the cheapest feasible sequence that spans
            the horizon (else the deepest one, when deeper than the search's); 0 turns it off.
        beam_footholds: candidate footholds a beam step tries (the ranked candidates, as
            ``candidates`` for the depth-first search).
        beam_speeds: shapes a beam step keeps per foothold besides the cheapest, spread over
            the post-impact speeds they lead to (slowest to fastest).
        beam_evaluations: step evaluations one beam search may spend (besides the
            depth-first search's ``max_evaluations``; a deterministic bound; a planning call
            may give it less, :meth:`GaitPlanner.plan`'s ``max_beam_evaluations``).
        beam_coarse: where > 0, the beam search first runs with this many of each of its two
            sets of :data:`BEAM_SHAPES` quasi-random shapes per foothold (the first points of
            each Sobol set) and runs with all of them only where that spans no horizon, with
            the evaluations left; 0: all of them at once. The paper robot's preset has 8 (held
            out; before, 0). An integer in [0, BEAM_SHAPES].
        beam_full: with ``beam_coarse`` > 0, 1: where the coarse pass spans no horizon, the
            search runs again with all the shapes (the dataclass's default); 0: the coarse
            pass alone. Ignored with ``beam_coarse`` 0.
        beam_far: 1: each beam step also tries the set of shapes over the global search's
            whole range (the dataclass's and the classic walker's default); 0: only the gait's
            shape and those near it (half the evaluations a foothold; the paper robot's preset,
            held out with a beam budget of 20,000 a replanning; before, 1).
        gauss_newton_scaling: 1: each SLSQP solve of a step (or a pair) runs in coordinates
            in which the Gauss-Newton model of its cost (a sum of squares) at the start point
            is the identity, SLSQP's first Hessian model, up to a floor on its flattest
            directions (about half the iterations; the optima are the same within the
            solver's tolerance, the plans not bit for bit; the paper robot's preset); 0
            (the dataclass's and the classic walker's default): in the free coefficients
            themselves.
        compiled_sqp: 1: each solve of a step (or a pair) runs in one compiled call
            (:mod:`controllers.planner.sqp`: an SQP of SLSQP's structure whose QP and
            iterations run next to the step kernel, without SciPy's per-iteration QP set-up
            and the Python between evaluations; the paper robot's preset, held out); 0 (the
            dataclass's and the classic walker's default): SciPy's SLSQP driven from Python.
            The same problems and acceptance test; the iterates, and so the plans, differ.

    The swing-foot geometry is the robot's (:attr:`envs.physics.RobotParams.retract`,
    :attr:`~envs.physics.RobotParams.arm_distance`, the simulator's rule): the planned swing
    foot is retracted until it is ``arm_distance * l`` ahead of the stance foot, may touch down
    from then on and must stay above the ground.
    """

    MOVED_FIELDS: ClassVar[dict[str, str]] = {
        key: MOVED_TO_ROBOT.format(key=key) for key in ("retract", "arm_distance")
    }

    order: int = 4
    grid: int = 32
    check_points: int = 96
    horizon: int = 5
    target_speed: float = 0.3
    step_length: float = 0.15
    step_min: float = 0.08
    step_max: float = 0.24
    edge_margin: float = 0.02
    drop_margin: float = 4.0
    rise_margin: float = 4.0
    drop_edge_margin: float = 0.0
    relaxed_margin: float = 1.0
    q1_min: float = 0.2
    q1_max: float = 1.0
    max_rise: float = 0.05
    max_drop: float = 0.08
    duration_min: float = 0.2
    duration_max: float = 1.5
    min_thetadot: float = 0.2
    end_thetadot_floor: float = 0.0
    gait_min_thetadot: float = 0.0
    speed_reserve: float = 0.0
    dip_floor: float = 0.0
    torque_fraction: float = 0.8
    clearance: float = 0.004
    clearance_ramp: float = 0.3
    arm_clearance: float = 0.001
    retracted_clearance: float = 0.002
    face_clearance: float = 0.003
    touchdown_slope: float = 0.02
    friction: float = 0.8
    w_speed: float = 1.0
    w_end: float = 0.3
    w_shape: float = 0.01
    w_torque: float = 0.2
    w_slope: float = 0.05
    max_iter: int = 60
    max_evaluations: int = 2000
    time_budget: float = 0.0
    lookahead: int = 2
    lookahead_rise: float = 0.002
    energy_horizon: int = 0
    pairs_first: int = 0
    foothold_shift: float = 0.0
    candidates: int = 4
    candidate_spacing: float = 0.01
    beam_width: int = 0
    beam_footholds: int = 8
    beam_speeds: int = 5
    beam_evaluations: int = 40000
    beam_coarse: int = 0
    beam_full: int = 1
    beam_far: int = 1
    gauss_newton_scaling: int = 0
    compiled_sqp: int = 0

    def __new__(cls, *args: Any, **kwargs: Any) -> PlannerConfig:
        """Reject the settings that moved to :class:`envs.physics.RobotParams`, naming the
        replacement."""
        reject_moved_fields(cls, kwargs)
        return super().__new__(cls)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ValueError(f"PlannerConfig.{f.name} must be a number, got {v!r}")
            if not math.isfinite(float(v)):
                raise ValueError(f"PlannerConfig.{f.name} must be finite, got {v!r}")
        ints = {
            "order": 4,
            "grid": 8,
            "check_points": 8,
            "horizon": 1,
            "max_iter": 1,
            "max_evaluations": 1,
            "candidates": 1,
            "lookahead": 0,
            "energy_horizon": 0,
            "pairs_first": 0,
            "beam_width": 0,
            "beam_footholds": 1,
            "beam_speeds": 0,
            "beam_evaluations": 1,
            "beam_coarse": 0,
            "beam_full": 0,
            "beam_far": 0,
            "gauss_newton_scaling": 0,
            "compiled_sqp": 0,
        }
        for name, lo in ints.items():
            v = getattr(self, name)
            if int(v) != v or v < lo:
                raise ValueError(f"PlannerConfig.{name} = {v!r}; allowed: integer >= {lo}")
            object.__setattr__(self, name, int(v))
        pos = (
            "target_speed step_length step_min step_max duration_min duration_max min_thetadot "
            "torque_fraction friction clearance_ramp candidate_spacing"
        ).split()
        for name in pos:
            if not getattr(self, name) > 0:
                raise ValueError(f"PlannerConfig.{name} = {getattr(self, name)!r}; allowed: > 0")
        nonneg = (
            "edge_margin drop_margin rise_margin drop_edge_margin relaxed_margin max_rise max_drop "
            "clearance lookahead_rise arm_clearance retracted_clearance face_clearance "
            "touchdown_slope gait_min_thetadot speed_reserve end_thetadot_floor w_speed w_end "
            "w_shape w_torque w_slope time_budget"
        ).split()
        for name in nonneg:
            if not getattr(self, name) >= 0:
                raise ValueError(f"PlannerConfig.{name} = {getattr(self, name)!r}; allowed: >= 0")
        if not self.duration_min < self.duration_max:
            raise ValueError("PlannerConfig: need duration_min < duration_max")
        if not self.torque_fraction <= 1:
            raise ValueError(
                f"PlannerConfig.torque_fraction = {self.torque_fraction}; allowed: <= 1"
            )
        if not abs(self.foothold_shift) <= 0.1:
            raise ValueError(
                f"PlannerConfig.foothold_shift = {self.foothold_shift}; allowed: [-0.1, 0.1] m"
            )
        if not 0 <= self.dip_floor < 1:
            raise ValueError(f"PlannerConfig.dip_floor = {self.dip_floor!r}; allowed: [0, 1)")
        if not self.relaxed_margin <= 1:
            raise ValueError(
                f"PlannerConfig.relaxed_margin = {self.relaxed_margin}; allowed: [0, 1]"
            )
        for name in (
            "pairs_first",
            "beam_full",
            "beam_far",
            "gauss_newton_scaling",
            "compiled_sqp",
        ):
            if getattr(self, name) > 1:
                raise ValueError(f"PlannerConfig.{name} = {getattr(self, name)}; allowed: 0 or 1")
        if self.beam_coarse > BEAM_SHAPES:
            raise ValueError(
                f"PlannerConfig.beam_coarse = {self.beam_coarse}; allowed: [0, {BEAM_SHAPES}]"
            )
        if self.lookahead > 2:
            raise ValueError(f"PlannerConfig.lookahead = {self.lookahead}; allowed: 0, 1 or 2")
        self.rules()  # validates the foothold fields

    def rules(self) -> FootholdRules:
        """The foothold rules of this configuration."""
        return _rules(self)

    def relaxed_rules(self) -> FootholdRules | None:
        """The foothold rules with the riser margins scaled by ``relaxed_margin`` (None when
        that changes nothing)."""
        if self.relaxed_margin >= 1 or (
            self.drop_margin == 0 and self.rise_margin == 0 and self.drop_edge_margin == 0
        ):
            return None
        return dataclasses.replace(
            self.rules(),
            drop_margin=self.drop_margin * self.relaxed_margin,
            rise_margin=self.rise_margin * self.relaxed_margin,
            drop_edge_margin=self.drop_edge_margin * self.relaxed_margin,
        )

    def _make_rules(self) -> FootholdRules:
        return FootholdRules(
            step_length=self.step_length,
            step_min=self.step_min,
            step_max=self.step_max,
            edge_margin=self.edge_margin,
            drop_margin=self.drop_margin,
            rise_margin=self.rise_margin,
            drop_edge_margin=self.drop_edge_margin,
            q1_min=self.q1_min,
            q1_max=self.q1_max,
            max_rise=self.max_rise,
            max_drop=self.max_drop,
        )

    def to_dict(self) -> dict[str, Any]:
        """The settings as a plain dict (the form :meth:`from_dict` reads)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PlannerConfig:
        """Build from a dict ``d`` of settings; unknown keys raise ``ValueError``."""
        return dataclass_from_mapping(cls, d, "planner")

    @classmethod
    def for_robot(cls, name: str, **changes: Any) -> PlannerConfig:
        """Defaults for the robot preset ``name`` from ``configs/planner/NAME.yaml`` (built-in
        defaults if there is no such file), with ``changes`` applied."""
        return cls.from_dict(preset_settings("planner", name, "planner config", changes))

    @classmethod
    def from_yaml(cls, path: str | Path) -> PlannerConfig:
        """Build from the YAML file of settings at ``path`` (unknown keys raise
        ``ValueError``)."""
        return cls.from_dict(read_yaml_mapping(path, "planner config"))


@functools.lru_cache(maxsize=64)
def _rules(config: PlannerConfig) -> FootholdRules:
    return config._make_rules()
