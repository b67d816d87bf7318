"""Transverse-linearization receding-horizon controller (paper Sections 3 and 4).

At every footstep the controller

1. (re)plans the motion from the actual post-impact state with the gait planner
   (:class:`controllers.planner.GaitPlanner`), or, with ``replan=False``, keeps following one plan
   made at :meth:`TransverseController.reset`;
2. linearises the transverse dynamics of the current step and the next ``horizon`` steps
   (:mod:`controllers.transverse`), with the phase ``theta`` as independent variable;
3. solves the jump-Riccati equation backwards from ``Z(t_f) = 0`` over those steps
   (:mod:`controllers.riccati`) and keeps the gain ``K(theta) = -R^-1 B' Z^-1`` of the current
   step on a uniform ``theta`` grid.

Every control tick then applies ``v = K(theta) x_perp`` and the partial feedback linearisation
``u = (v - R) / N`` (``y_ddot = N u + R``, hip friction included, so it is compensated), clipped to
the actuator limit. The tick is one compiled function (:func:`feedback_law`).

If planning fails (:class:`PlanningError`) beyond the second step, the look-ahead is shortened
to the feasible steps (``fallback = "shorter horizon"``). If it fails earlier, the controller
keeps the rest of the previous plan (shifted by one footstep, ``fallback = "previous plan"``)
while that still looks at least one step ahead, and otherwise plans the first step alone when
that is feasible. With a single planned step there is nothing to solve the Riccati equation
over: that step's constraint is held with PD on ``y`` (``fallback = "PD on the last planned
step"``). With no plan at all it applies zero input (``fallback = "zero input"``). The step's
:class:`StepRecord` says which, and why (``reason``).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numba import njit

from envs import model
from envs.config_util import dataclass_from_mapping
from envs.params import RobotParams, as_params
from envs.terrain import Terrain, as_terrain

from .planner import GaitPlanner, Plan, PlannerConfig, PlanningError, StepPlan
from .riccati import solve_jump_riccati
from .transverse import StepModel, impact_jacobian

__all__ = [
    "ControllerConfig",
    "PDController",
    "StepRecord",
    "TransverseController",
    "constraint_at",
    "feedback_law",
    "horizon_gains",
]

_jit = njit(cache=True, error_model="numpy")

#: PD gains (kp [1/s^2], kd [1/s]) used on a last remaining planned step
FALLBACK_PD = (400.0, 40.0)

# layout of the per-step float table used by the compiled tick
T_TP, T_SPAN, T_F0, T_FD, T_K0, T_KD, T_UMAX, T_B, T_LATE = range(9)
N_T = 9


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
        replan: replan from the actual post-impact state at every footstep (True) or follow
            the plan made at reset (False).
        plan_steps: steps planned at reset when ``replan`` is False (>= horizon + 1); when
            replanning, ``horizon + 1`` steps are planned at each footstep.
        margin: fraction of a step's span by which the nominal speed profile is extended
            beyond its ends, for states slightly before ``theta+`` or after ``theta-``.
        late_blend: if the touchdown has not happened at the planned ``theta-``, the constraint
            is continued with its slope ``phi'`` blended to 0 over this many radians (the legs
            stop opening, the hip falls forward, the swing foot goes down); 0 extrapolates the
            Bezier polynomial instead. [rad], >= 0.
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

    def __post_init__(self) -> None:
        for name in ("horizon", "grid", "plan_steps"):
            v = getattr(self, name)
            lo = {"horizon": 1, "grid": 4, "plan_steps": 2}[name]
            if isinstance(v, bool) or int(v) != v or v < lo:
                raise ValueError(f"ControllerConfig.{name} = {v!r}; allowed: integer >= {lo}")
            object.__setattr__(self, name, int(v))
        for name in ("Q", "Qj"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 3 or not all(math.isfinite(x) and x > 0 for x in v):
                raise ValueError(f"ControllerConfig.{name} = {v!r}; allowed: three numbers > 0")
            object.__setattr__(self, name, v)
        if not (math.isfinite(float(self.R)) and float(self.R) > 0):
            raise ValueError(f"ControllerConfig.R = {self.R!r}; allowed: > 0")
        object.__setattr__(self, "R", float(self.R))
        if not (math.isfinite(float(self.late_blend)) and float(self.late_blend) >= 0):
            raise ValueError(f"ControllerConfig.late_blend = {self.late_blend!r}; allowed: >= 0")
        object.__setattr__(self, "late_blend", float(self.late_blend))
        if not (0.0 <= float(self.margin) <= 0.5):
            raise ValueError(f"ControllerConfig.margin = {self.margin!r}; allowed: [0, 0.5]")
        if not isinstance(self.replan, (bool, np.bool_)):
            raise ValueError(f"ControllerConfig.replan = {self.replan!r}; allowed: True or False")

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> ControllerConfig:
        """Build from a dict (unknown keys raise ``ValueError``); None gives the defaults."""
        if d is None:
            return cls()
        return dataclass_from_mapping(cls, d, "controller")

    @classmethod
    def from_yaml(cls, path: str | Path) -> ControllerConfig:
        with open(path) as fh:
            return cls.from_dict(yaml.safe_load(fh) or {})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# ---------------------------------------------------------------------------- compiled tick
@_jit
def _hermite(tab0, h, vals, ders, th):
    """Cubic Hermite interpolation on a uniform grid (clamped to the grid)."""
    n = vals.size - 1
    r = (th - tab0) / h
    if r <= 0.0:
        return vals[0]
    if r >= n:
        return vals[n]
    k = int(r)
    if k >= n:
        k = n - 1
    t = r - k
    t2 = t * t
    t3 = t2 * t
    return (
        (2 * t3 - 3 * t2 + 1) * vals[k]
        + (t3 - 2 * t2 + t) * h * ders[k]
        + (-2 * t3 + 3 * t2) * vals[k + 1]
        + (t3 - t2) * h * ders[k + 1]
    )


@_jit
def constraint_at(tab, pc, q2):
    """``(phi, phi', phi'')`` of the loaded step at phase ``q2``, including the continuation
    past the planned touchdown (see ``ControllerConfig.late_blend``)."""
    span = tab[T_SPAN]
    s = (q2 - tab[T_TP]) / span
    late = q2 - (tab[T_TP] + span)  # phase past the planned touchdown [rad]
    if late > 0.0 and tab[T_LATE] > 0.0:
        s = 1.0
    m = pc.size - 1
    ph = pc[m]
    dph = 0.0
    ddph = 0.0
    for k in range(m - 1, -1, -1):
        ddph = ddph * s + 2.0 * dph
        dph = dph * s + ph
        ph = ph * s + pc[k]
    dph /= span
    ddph /= span * span
    if late > 0.0 and tab[T_LATE] > 0.0:
        # touchdown is late: stop opening the legs (phi' -> 0 over T_LATE rad), so the hip
        # falls forward and the swing foot moves down onto the ground
        d0 = tab[T_LATE]
        if late < d0:
            ph = ph + dph * late - 0.5 * dph / d0 * late * late
            ddph = -dph / d0
            dph = dph * (1.0 - late / d0)
        else:
            ph = ph + 0.5 * dph * d0
            dph = 0.0
            ddph = 0.0
    return ph, dph, ddph


@_jit
def feedback_law(P, x, tab, pc, Fv, Fd, K):
    """One control tick: input ``u`` [input units] for the state ``x = (q1, q2, q1d, q2d)``.

    Args:
        P: robot parameter vector.
        x: state (estimate) ``(q1, q2, q1d, q2d)``.
        tab: step table (``T_*`` layout): ``theta+``, span, grids of ``F*`` and ``K``, ``u_max``.
        pc: power-basis coefficients of ``phi`` in ``s = (theta - theta+) / span`` (ascending).
        Fv, Fd: nominal ``theta_dot^2`` and its ``theta`` derivative on the ``F*`` grid.
        K: gains ``(n + 1, 3)`` on the ``K`` grid (linear interpolation, clamped).

    Returns:
        ``(u, I, y, y_dot, v)``.
    """
    q1, q2, q1d, q2d = x[0], x[1], x[2], x[3]
    ph, dph, ddph = constraint_at(tab, pc, q2)
    y = q1 - ph
    yd = q1d - dph * q2d
    I = q2d * q2d - _hermite(tab[T_F0], tab[T_FD], Fv, Fd, q2)
    nk = K.shape[0] - 1
    r = (q2 - tab[T_K0]) / tab[T_KD]
    if r <= 0.0:
        k0, w = 0, 0.0
    elif r >= nk:
        k0, w = nk - 1, 1.0
    else:
        k0 = int(r)
        if k0 >= nk:
            k0 = nk - 1
        w = r - k0
    v = 0.0
    comp = (I, y, yd)
    for i in range(3):
        v += ((1.0 - w) * K[k0, i] + w * K[k0 + 1, i]) * comp[i]
    # y_ddot = N u + R (friction included in R)
    a1, a2 = model.accelerations(P, q1, q2, q1d, q2d, 0.0)
    r0 = a1 - dph * a2 - ddph * q2d * q2d
    b1, b2 = model.accelerations(P, q1, q2, q1d, q2d, 1.0)
    nn = (b1 - dph * b2 - ddph * q2d * q2d) - r0
    u = (v - r0) / nn
    umax = tab[T_UMAX]
    if u > umax:
        u = umax
    elif u < -umax:
        u = -umax
    if not (u == u):
        u = 0.0
    return u, I, y, yd, v


# ---------------------------------------------------------------------------- horizon solve
@dataclass
class HorizonSolution:
    """Gains of the current step from one jump-Riccati solve.

    Attributes:
        steps: the transverse models of the steps in the horizon (current first).
        theta: gain nodes of the current step [rad]; K: gains ``(n + 1, 3)``;
        P: Lyapunov matrices ``Z^-1`` at the nodes; F: the impact jacobians used.
        solve_time: wall time of linearisation + Riccati [s]; riccati_time: Riccati only [s].
    """

    steps: list[StepModel]
    theta: np.ndarray
    K: np.ndarray
    P: np.ndarray
    F: list[np.ndarray]
    solve_time: float
    riccati_time: float

    def lyapunov(self, z: np.ndarray, theta: float) -> float:
        """``V = z' Z^-1 z`` at phase ``theta`` (linear interpolation of ``Z^-1``)."""
        th = self.theta
        r = np.clip((theta - th[0]) / (th[1] - th[0]), 0, th.size - 1 - 1e-12)
        k = int(r)
        w = r - k
        Pm = (1 - w) * self.P[k] + w * self.P[k + 1]
        return float(z @ Pm @ z)


def step_models(
    P: np.ndarray, steps: list[StepPlan], terrain: Terrain | None, margin: float = 0.15
) -> list[StepModel]:
    """Transverse models of planned steps; the switching surface at each foothold follows the
    ground slope there (0 without a terrain)."""
    out = []
    for s in steps:
        slope = 0.0 if terrain is None else terrain.slope_at(s.foothold[0])
        out.append(StepModel(P, s.constraint, s.thetadot_plus, slope, margin=margin))
    return out


def horizon_gains(models: list[StepModel], config: ControllerConfig) -> HorizonSolution:
    """Linearise the steps and solve the jump-Riccati equation over them (current step first).

    Raises:
        ValueError: fewer than two steps or a non-controllable horizon.
    """
    if len(models) < 2:
        raise ValueError("horizon_gains: need the current step and at least one more")
    t0 = time.perf_counter()
    n = config.grid
    A, B, W, L = [], [], [], []
    for m in models:
        th = np.linspace(m.theta_plus, m.theta_minus, 2 * n + 1)
        a, b, w = m.phase_matrices(th)
        A.append(a)
        B.append(b)
        W.append(w)
        L.append(m.theta_minus - m.theta_plus)
    F = [impact_jacobian(models[j], models[j + 1]) for j in range(len(models) - 1)]
    t1 = time.perf_counter()
    sol = solve_jump_riccati(
        A, B, L, F, np.diag(config.Q), np.array([[config.R]]), np.diag(config.Qj), w=W
    )
    t2 = time.perf_counter()
    m0 = models[0]
    theta = np.linspace(m0.theta_plus, m0.theta_minus, n + 1)
    return HorizonSolution(models, theta, sol.K[0][:, 0, :].copy(), sol.P[0], F, t2 - t0, t2 - t1)


# ---------------------------------------------------------------------------- diagnostics
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
        V_start, V_end: ``z' Z^-1 z`` at the first and last tick.
        V_increase: largest increase of ``V`` between consecutive ticks within the planned
            phase range ``[theta+, theta-]`` (should be about 0 or negative).
        max_abs_u: largest ``|u|`` [input units]; saturated: ticks at the actuator limit.
        fallback: None, ``"shorter horizon"`` (planning failed beyond the second step; the
            look-ahead is cut there), ``"previous plan"``, ``"PD on the last planned step"`` or
            ``"zero input"`` (see the module docstring); reason: the planning error.
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


# ---------------------------------------------------------------------------- controller
class TransverseController:
    """Receding-horizon transverse-linearization controller (state feedback).

    Args:
        robot: robot parameters or preset name.
        terrain: the terrain map (a :class:`Terrain`, spec or kind name).
        config: :class:`ControllerConfig` or a dict of its fields.
        planner: a :class:`GaitPlanner`, a :class:`PlannerConfig`/dict for a new one, or None
            (the robot's default planner).

    Use with :func:`envs.simulate`: ``simulate(robot, terrain, q0, qd0, T, torque=ctrl)`` after
    ``ctrl.reset(q0, qd0)``; as a callable it returns the hip torque [N m] and detects impacts
    from the jump of ``q2`` (the new stance foot is then located from the configuration). For
    exact footholds drive it with :meth:`on_impact` (see :meth:`rollout`).
    """

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
        self.config = ControllerConfig.from_dict(config)
        if isinstance(planner, GaitPlanner):
            self.planner = planner
        else:
            self.planner = GaitPlanner(self.robot, planner)
        self.records: list[StepRecord] = []
        self.plan: Plan | None = None
        self.solution: HorizonSolution | None = None
        self._plan_offset = 0
        self._tab = np.zeros(N_T)
        self._pc = np.zeros(self.planner.config.order + 1)
        self._Fv = np.zeros(2)
        self._Fd = np.zeros(2)
        self._K = np.zeros((2, 3))
        self._active = False
        self._stance = (0.0, 0.0)
        self._last_q2 = math.nan
        self._x = np.zeros(4)

    # ------------------------------------------------------------------ planning
    def reset(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        stance_foot: tuple[float, float] | None = None,
        t: float = 0.0,
    ) -> None:
        """Start a new run from the state ``(q, qd)`` with the stance foot at ``stance_foot``
        (default: ``x = 0`` on the ground)."""
        if stance_foot is None:
            stance_foot = (0.0, float(self.terrain.height(0.0)))
        self.records = []
        self.plan = None
        self.solution = None
        self._stance = (float(stance_foot[0]), float(stance_foot[1]))
        self._start_step(np.asarray(q, float), np.asarray(qd, float), t, first=True)

    def on_impact(
        self, q: np.ndarray, qd: np.ndarray, stance_foot: tuple[float, float], t: float = math.nan
    ) -> None:
        """A touchdown happened: ``(q, qd)`` is the post-impact state, ``stance_foot`` the new
        stance-foot position [m]. Replans (or advances the fixed plan) and re-solves."""
        self._stance = (float(stance_foot[0]), float(stance_foot[1]))
        self._start_step(np.asarray(q, float), np.asarray(qd, float), t, first=False)

    def replan(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Replan the rest of the current step from the state ``(q, qd)`` (same stance foot),
        e.g. once a velocity observer has converged; ignored when ``replan`` is False."""
        if not self.config.replan or not self.records:
            return
        self._start_step(
            np.asarray(q, float), np.asarray(qd, float), math.nan, first=False, new_step=False
        )

    def _start_step(
        self, q: np.ndarray, qd: np.ndarray, t: float, first: bool, new_step: bool = True
    ) -> None:
        cfg = self.config
        if new_step or not self.records:
            rec = StepRecord(index=len(self.records), t_start=float(t))
            self.records.append(rec)
        else:
            rec = self.records[-1]
            rec.fallback = rec.reason = None
        self._last_q2 = float(q[1])
        steps: list[StepPlan] | None = None
        if first or cfg.replan:
            n = cfg.horizon + 1 if cfg.replan else max(cfg.plan_steps, cfg.horizon + 1)
            t0 = time.perf_counter()
            previous = self.plan if cfg.replan else None
            failed_at = None
            while steps is None:
                try:
                    plan = self.planner.plan(
                        self.terrain, (q, qd), self._stance, horizon=n, previous_plan=previous
                    )
                    self.plan, self._plan_offset = plan, 0
                    steps = plan.steps
                except PlanningError as exc:
                    rec.reason = str(exc)
                    failed_at = exc.step
                    if exc.step < 2 or n <= 2:
                        break
                    # the first exc.step steps are feasible: plan a shorter look-ahead
                    n = exc.step
                    rec.fallback = "shorter horizon"
                except ValueError as exc:
                    rec.reason = str(exc)
                    break
            if steps is None:
                steps = self._fallback_steps(q, qd, failed_at, first, new_step, previous, rec)
            rec.plan_time = time.perf_counter() - t0
        else:
            self._plan_offset += 1
            steps = self.plan.steps[self._plan_offset :] if self.plan is not None else []
        sol = None
        if steps:
            steps = steps[: cfg.horizon + 1]
            try:
                models = step_models(self.P, steps, self.terrain, cfg.margin)
                if len(models) >= 2:
                    sol = self._gains(models)
                else:
                    # one planned step left: no look-ahead to solve over, hold it with PD on y
                    sol = pd_gains(models, cfg.grid, *FALLBACK_PD)
                    rec.fallback = "PD on the last planned step"
            except ValueError as exc:
                rec.reason = rec.reason or str(exc)
                sol = None
        if sol is None:
            rec.fallback = "zero input"
            self._active = False
            self.solution = None
            return
        self.solution = sol
        rec.riccati_time = sol.riccati_time
        rec.solve_time = sol.solve_time
        self._load(sol)
        self._active = True

    def _fallback_steps(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        failed_at: int | None,
        first: bool,
        new_step: bool,
        previous: Plan | None,
        rec: StepRecord,
    ) -> list[StepPlan] | None:
        """Steps to use when planning failed: the rest of the previous plan if it still looks
        ahead, else a fresh single step (when the first step was feasible), else whatever is
        left of the previous plan."""
        old: list[StepPlan] = []
        off = self._plan_offset
        if not first and self.plan is not None:
            off = self._plan_offset + int(new_step)
            old = self.plan.steps[off:]
        if len(old) >= 2:
            self._plan_offset = off
            rec.fallback = "previous plan"
            return old
        if failed_at == 1:
            try:
                one = self.planner.plan(
                    self.terrain, (q, qd), self._stance, horizon=1, previous_plan=previous
                )
            except (PlanningError, ValueError):
                one = None
            if one is not None:
                # keep the older plan (if any) for later fallbacks
                self._plan_offset = off
                if self.plan is None:
                    self.plan = one
                return one.steps
        if old:
            self._plan_offset = off
            rec.fallback = "previous plan"
            return old
        return None

    def _gains(self, models: list[StepModel]) -> HorizonSolution:
        return horizon_gains(models, self.config)

    def _load(self, sol: HorizonSolution) -> None:
        m0 = sol.steps[0]
        c = m0.constraint
        order = c.order
        # power-basis coefficients of phi in s (exact for a polynomial of this order)
        s = 0.5 * (1 - np.cos(np.pi * np.arange(order + 1) / order))
        self._pc = np.polynomial.polynomial.polyfit(s, c.phi(c.theta_plus + s * c.span), order)
        ng = 4 * self.config.grid
        a = c.theta_plus - m0.margin * c.span
        b = c.theta_minus + m0.margin * c.span
        thF = np.linspace(a, b, ng + 1)
        self._Fv = np.ascontiguousarray(m0.thetadot_sq(thF))
        self._Fd = np.ascontiguousarray(m0.dthetadot_sq(thF))
        self._K = np.ascontiguousarray(sol.K)
        tab = np.zeros(N_T)
        tab[T_TP], tab[T_SPAN] = c.theta_plus, c.span
        tab[T_F0], tab[T_FD] = a, thF[1] - thF[0]
        tab[T_K0], tab[T_KD] = sol.theta[0], sol.theta[1] - sol.theta[0]
        tab[T_UMAX] = self.robot.u_max
        tab[T_B] = self.robot.kI * self.robot.ktau
        tab[T_LATE] = self.config.late_blend
        self._tab = tab
        rec = self.records[-1]
        rec.thetadot_nominal = (m0.thetadot_plus, math.sqrt(m0.thetadot_sq(c.theta_minus)))

    # ------------------------------------------------------------------ control
    @property
    def active(self) -> bool:
        """Whether a transverse gain is loaded (False: zero-input fallback)."""
        return self._active

    def coords(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """``x_perp`` of the state relative to the current step (NaN without a plan)."""
        if self.solution is None:
            return np.full(3, np.nan)
        return self.solution.steps[0].coords(np.r_[q, qd])

    def nominal(self, theta: float) -> np.ndarray:
        """Nominal ``(q1, q1d, q2d)`` of the current step at phase ``theta`` (NaN without a
        plan): ``phi(theta)``, ``phi'(theta) theta_dot*(theta)``, ``theta_dot*(theta)``, with the
        constraint continued past ``theta-`` as the feedback law does."""
        if self.solution is None:
            return np.full(3, np.nan)
        ph, dph, _ = constraint_at(self._tab, self._pc, float(theta))
        td = math.sqrt(
            max(_hermite(self._tab[T_F0], self._tab[T_FD], self._Fv, self._Fd, float(theta)), 0.0)
        )
        return np.array([ph, dph * td, td])

    def control(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Input ``u`` [input units] for the state ``(q, qd)``; records diagnostics."""
        x = self._x
        x[0], x[1], x[2], x[3] = q[0], q[1], qd[0], qd[1]
        rec = self.records[-1] if self.records else None
        if not self._active:
            if rec is not None:
                rec.ticks += 1
            return 0.0
        u, I, y, yd, _ = feedback_law(self.P, x, self._tab, self._pc, self._Fv, self._Fd, self._K)
        if rec is not None:
            z = np.array([I, y, yd])
            V = self.solution.lyapunov(z, x[1])
            if rec.ticks == 0:
                rec.thetadot_start = x[3]
                rec.xperp_start = z
                rec.V_start = V
            elif self.solution.theta[0] <= x[1] <= self.solution.theta[-1]:
                # the Lyapunov argument holds on the planned phase range of the step
                rec.V_increase = max(rec.V_increase, V - rec.V_end)
            rec.thetadot_end = x[3]
            rec.xperp_end = z
            rec.V_end = V
            rec.max_abs_y = max(rec.max_abs_y, abs(y))
            rec.max_abs_u = max(rec.max_abs_u, abs(u))
            rec.saturated += int(abs(u) >= self.robot.u_max)
            rec.ticks += 1
        return u

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> float:
        """Hip torque [N m] for :func:`envs.simulate` (detects impacts from the state)."""
        if self.records and q[1] < self._last_q2 - 0.5 * abs(q[0]):
            # legs swapped: the trailing (old stance) foot is the swing foot now
            fx, _ = model.swing_foot_position(self.P, q[0], q[1], 0.0, 0.0)
            x_new = self._stance[0] - float(fx)
            self.on_impact(q, qd, (x_new, float(self.terrain.height(x_new))), t)
        self._last_q2 = float(q[1])
        return self.robot.kI * self.robot.ktau * self.control(q, qd)

    # ------------------------------------------------------------------ closed loop
    def rollout(
        self,
        q0: np.ndarray,
        qd0: np.ndarray,
        duration: float,
        dt: float = 0.005,
        steps: int | None = None,
        sim_config: Any = None,
    ) -> dict[str, Any]:
        """Closed loop with the hybrid simulator, exact footholds from its impact events.

        Args:
            q0, qd0: start state; duration: simulated time [s]; dt: control period [s];
            steps: stop after this many footsteps; sim_config: :class:`envs.simulator.SimConfig`.

        Returns:
            dict with ``t, q, qd, u`` per tick, ``impacts`` (times), ``failure`` (None or the
            simulator's reason), ``records`` (:class:`StepRecord` list).
        """
        from envs.simulator import Simulator

        sim = Simulator(self.robot, self.terrain, 1, dt=dt, config=sim_config, parallel=False)
        foot = (0.0, float(self.terrain.height(0.0)))
        sim.reset(q0, qd0, foot)
        self.reset(np.asarray(q0, float), np.asarray(qd0, float), foot)
        b = self.robot.kI * self.robot.ktau
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
        kp: proportional gain [1/s^2], > 0; kd: derivative gain [1/s], > 0 (defaults: a
            critically damped pair with poles at -20 rad/s).
    """

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


def pd_gains(models: list[StepModel], grid: int, kp: float, kd: float) -> HorizonSolution:
    """Constant gains ``v = -kp y - kd y_dot`` on the current step (``Z^-1 = I`` for ``V``)."""
    m0 = models[0]
    theta = np.linspace(m0.theta_plus, m0.theta_minus, grid + 1)
    K = np.tile(np.array([0.0, -kp, -kd]), (grid + 1, 1))
    P = np.tile(np.eye(3), (grid + 1, 1, 1))
    return HorizonSolution(models, theta, K, P, [], math.nan, math.nan)
