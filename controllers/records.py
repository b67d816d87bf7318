"""What the controller records about each footstep: :class:`StepRecord` (its plan, its
tracking, its fallbacks and the per-footstep certificate values), and what the reference
policy's online identification did after it: :class:`IdentificationRecord`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "HOLD_POSTURE",
    "PD_ON_ONE_STEP",
    "STEP_UNDER_WAY",
    "WITHOUT_PLAN",
    "ZERO_INPUT",
    "IdentificationRecord",
    "StepRecord",
]

#: ``StepRecord.fallback`` of a step held with PD on ``y`` (no two steps to track)
PD_ON_ONE_STEP = "PD on the last planned step"
#: ... of a step whose replan within it found nothing to track: the step under way is tracked on
STEP_UNDER_WAY = "step under way"
#: ... of a step with no motion to track, the robot upright: the swing leg held at the nominal
#: touchdown's inter-leg angle with PD on ``y`` (a constant constraint)
HOLD_POSTURE = "hold posture"
#: ... of a step with nothing to track at all (a non-finite state)
ZERO_INPUT = "zero input"
#: the fallbacks with no planned motion: no transverse coordinates, no certificate
WITHOUT_PLAN = (HOLD_POSTURE, ZERO_INPUT)


@dataclass(frozen=True)
class IdentificationRecord:
    """One fit of the online identification (``controllers.identification``), after a
    footstep.

    Attributes:
        footstep: the footstep that ended the stance just added (1 = the first).
        relative: the fitted coefficients ``(p1, p2, p3, p4, p5, Fc, Fv)`` relative to the
            nominal ones, minus 1.
        distance2: the fit's squared Mahalanobis distance from the nominal coefficients.
        leg_length: the leg length of the model in use after this footstep [m].
        switched: whether the model in use changed.
        seconds: wall time of the fit and the switch [s].
        note: why no model was made of the fit (an invalid robot), else None.
    """

    footstep: int
    relative: tuple[float, ...]
    distance2: float
    leg_length: float
    switched: bool
    seconds: float
    note: str | None = None


@dataclass
class StepRecord:
    """What happened during one footstep (filled in while it runs).

    Attributes:
        index: footstep number since reset.
        t_start: time at the start of the step [s] (NaN when unknown).
        thetadot_start, thetadot_end: actual ``theta_dot`` at the first and last tick [rad/s].
        thetadot_nominal: nominal ``(theta_dot+, theta_dot-)`` of the step [rad/s].
        max_abs_y: largest ``|y|`` over the step [rad].
        riccati_time: wall time of the step's Riccati solve [s]; solve_time: linearisation
            plus Riccati [s]; plan_time: planner call [s] (0 when not replanned).
        xperp_start, xperp_end: ``x_perp`` at the first and last tick of the step.
        V_start, V_end: the Lyapunov value ``V = x_perp' P x_perp`` at the step's first tick
            (just after the impact map, the start of tracking) and at its last tick (the
            pre-impact side of the next touchdown), with ``P = Z^-1`` of the jump-Riccati
            solution the step's feedback uses (the one solved at the step's start, or at a
            replan within it), interpolated at the tick's phase as the gains are: at the first
            tick ``P`` at about ``theta+``, at the last tick ``P`` at the phase just before the
            impact (the solution's value before the jump, clamped at ``theta-`` if the
            touchdown is late). NaN without gains; ``P = I`` for plain PD.
        V_increase: largest increase of ``V`` between consecutive ticks within the planned
            phase range ``[theta+, theta-]`` (should be about 0 or negative).
        max_abs_u: largest ``|u|`` over the step [input units]; saturated: ticks at the
            actuator limit.
        fallback: None, ``"shorter horizon"`` (planning failed beyond the second step; the
            look-ahead is cut there), a relaxation (``"relaxed: ..."``, possibly followed by
            ``", shorter horizon"``; ``"relaxed: ..., deeper"`` where
            ``ControllerConfig.deeper_relaxation`` planned further than the full problem),
            ``"previous plan"``, ``"least violation"``, ``"PD on the last planned step"``,
            ``"step under way"`` (a replan within the step found nothing to track, and the
            step being tracked is tracked on), ``"hold posture"`` (no step to track: the swing
            leg held at the nominal touchdown's inter-leg angle) or ``"zero input"`` (a
            non-finite state; see the module docstring of
            :mod:`controllers.controller`); reason: the planning errors of the degradations
            tried (``" | "`` between them).
        plan_evaluations: step evaluations the planner calls of the step spent (all
            degradations together; see :attr:`PlannerConfig.max_evaluations`).
        budget_exhausted: a planner call of the step was cut by its search budget.
        degradations: the degradations tried, in order (:attr:`ControllerConfig.fallbacks`
            names; ``"full problem"`` first).
        retargets: replans within the step because the estimated state left the plan's tube
            (``ControllerConfig.tube_*``).
        max_xperp_norm: largest Euclidean norm of ``x_perp = [I, y, y_dot]`` over the step
            (0 without gains).
        pd_feedback: the step's relaxed or least-violating plan is tracked with PD on ``y``
            (``ControllerConfig.relaxed_feedback``), or the step under way held with PD is
            tracked on; ``V`` is then PD's, with ``P = I``, and :meth:`certificate` reports
            none.
    """

    index: int
    t_start: float = math.nan
    thetadot_start: float = math.nan
    thetadot_end: float = math.nan
    thetadot_nominal: tuple[float, float] = (math.nan, math.nan)
    max_abs_y: float = 0.0
    riccati_time: float = math.nan
    solve_time: float = math.nan
    plan_time: float = 0.0
    xperp_start: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    xperp_end: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    V_start: float = math.nan
    V_end: float = math.nan
    V_increase: float = 0.0
    max_abs_u: float = 0.0
    saturated: int = 0
    ticks: int = 0
    fallback: str | None = None
    reason: str | None = None
    max_xperp_norm: float = 0.0
    plan_evaluations: int = 0
    budget_exhausted: bool = False
    degradations: list[str] = field(default_factory=list)
    retargets: int = 0
    pd_feedback: bool = False

    def certificate(self) -> dict[str, float | None]:
        """The step's certificate values as plain data: ``V_start``, ``V_end``, ``V_ratio``,
        ``max_xperp_norm``, ``max_abs_u``; None for what is unknown or not finite, and for
        the ``V`` values of a step without Riccati gains (held with PD, a posture held, or zero
        input)."""
        riccati = not self.pd_feedback and self.fallback not in (PD_ON_ONE_STEP, *WITHOUT_PLAN)
        values = {
            "V_start": self.V_start if riccati else math.nan,
            "V_end": self.V_end if riccati else math.nan,
            "V_ratio": self.V_ratio if riccati else math.nan,
            "max_xperp_norm": (
                self.max_xperp_norm
                if self.ticks and self.fallback not in WITHOUT_PLAN
                else math.nan
            ),
            "max_abs_u": self.max_abs_u if self.ticks else math.nan,
        }
        return {k: float(v) if math.isfinite(v) else None for k, v in values.items()}

    @property
    def V_ratio(self) -> float:
        """``V_end / V_start``: below 1 when ``V`` fell over the step (NaN when either is
        unknown; infinite when ``V_start`` is 0)."""
        if not (self.V_start >= 0 and self.V_end >= 0):
            return math.nan
        if self.V_start == 0:
            return math.inf if self.V_end > 0 else math.nan
        return self.V_end / self.V_start


# ---------------------------------------------------------------------------- controller
