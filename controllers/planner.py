"""Step-by-step gait planner: footholds and Bezier virtual constraints over rough terrain.

For every step ``j`` the planner chooses a foothold (:mod:`controllers.footsteps`) and a Bezier
constraint ``q1 = phi_j(theta)``, ``theta = q2``, of order ``M`` (4 by default):

* ``a_0`` and ``theta_plus`` are the post-impact configuration (for step 0 the *actual* one);
* ``a_1`` gives ``phi'(theta_plus)`` equal to the post-impact velocity direction
  ``q1d+/q2d+`` (impact invariance; for step 0 the actual velocity direction);
* ``a_M`` and ``theta_minus`` put the swing foot on the foothold with both legs straight;
* ``a_2 .. a_{M-1}`` are free: a small SLSQP problem per step picks them so that the step is
  feasible (``theta_dot^2`` bounded away from zero, swing-foot clearance under the retractable-foot
  rule, transversal touchdown, step duration and hip input within bounds, stance foot loaded and
  not slipping, impact impulse inside the friction cone, trailing foot taking off) while the
  walking speed is regulated towards a target.

Steps are optimised one after the other along the horizon (each step's end state is the next
step's start), warm-started from the previous plan; where the ground changes height a step is
optimised jointly with the next one (only the first is kept), which lets it anticipate drops and
rises. Footholds are ranked so that every step's phase range stays near the periodic gait's,
after those from which a chain of admissible footholds goes on for the rest of the horizon (up to
three steps), also when the actual touchdown lands a few millimetres off (on stairs the footholds
form narrow windows; one on the border of its window leaves no next step after a small miss);
when a step has no feasible solution the search backtracks to other footholds and to shapes
that end closer to the gait (depth first, with a budget of step solves). Terrain on which no
chain of admissible footholds spans the horizon fails at once, naming the step without a
foothold. SLSQP gets forward-difference Jacobians whose perturbed points are evaluated in one
compiled batched call (:mod:`controllers.step_kernel` through
:meth:`_StepModel.evaluate_batch`); step problems already solved during the current walk are
reused (replanning from the planned state re-solves only the newly added step), and a look-ahead
step whose warm start (the previous plan's solution, or the second step of a jointly optimised
pair) is still feasible is kept as it is: it is optimised when it becomes the first step of a
plan from a state off the previous plan. The nominal speed
profile of each step comes from the integral of the reduced dynamics
(:mod:`controllers.reduced`). The periodic flat-ground gait (:meth:`GaitPlanner.periodic_gait`)
is the reference: its speed, its post-impact speed and its shape anchor the step costs.

The constraints are checked on each step's Chebyshev grid (dynamics: input, reaction) and on a
uniform grid (geometry, ``theta_dot^2``); between the nodes of the first the nominal input can
exceed the bound by a few percent.

Conventions: control notes, sections 1 and 2. Units: rad, rad/s, m, s; hip input ``u`` in the
robot's input units (torque ``kI ktau u``).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.optimize import minimize

from envs import model
from envs.config_util import dataclass_from_mapping
from envs.params import CONFIG_DIR, RobotParams, as_params

from . import reduced as rd
from . import step_kernel as sk
from .bezier import BezierConstraint, bernstein_basis
from .footsteps import FootholdRules, TerrainMap, candidate_footholds, touchdown_configuration

__all__ = [
    "GaitPlanner",
    "PeriodicGait",
    "Plan",
    "PlannerConfig",
    "PlanningError",
    "StepPlan",
]


class PlanningError(RuntimeError):
    """No feasible plan: ``step`` (index within the horizon) and the violated ``constraint``."""

    def __init__(self, step: int, constraint: str, detail: str = ""):
        self.step = int(step)
        self.constraint = str(constraint)
        self.detail = str(detail)
        msg = f"planning failed at step {self.step}: {self.constraint}"
        super().__init__(msg + (f" ({detail})" if detail else ""))


# ---------------------------------------------------------------------------- configuration
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
        q1_min, q1_max: inter-leg angle at touchdown bounds [rad].
        max_rise, max_drop: largest height gain / loss in one step [m].
        duration_min, duration_max: step duration bounds [s] (Assumption 1).
        min_thetadot: least ``theta_dot`` over every step [rad/s].
        gait_min_thetadot: least ``theta_dot`` of the nominal periodic gait [rad/s] (a reserve of
            kinetic energy for rises; the larger of the two applies to the gait).
        torque_fraction: nominal ``|u|`` stays below this fraction of ``u_max``.
        retract: swing-foot retraction, fraction of ``l`` (same rule as the simulator).
        arm_distance: the full-length swing foot may touch down once it is this far ahead of the
            stance foot, fraction of ``l``; from then on it must stay above the ground.
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
        lookahead: 1 to optimise each step jointly with the next one (only the first is kept;
            anticipates drops and rises; slower), 2 to do so only where this step and the next
            change height by more than ``lookahead_rise`` [m] together, 0 never.
        candidates: footholds tried per step before giving up.
        candidate_spacing: least spacing between the footholds tried [m].
    """

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
    q1_min: float = 0.2
    q1_max: float = 1.0
    max_rise: float = 0.05
    max_drop: float = 0.08
    duration_min: float = 0.2
    duration_max: float = 1.5
    min_thetadot: float = 0.2
    gait_min_thetadot: float = 0.0
    torque_fraction: float = 0.8
    retract: float = 0.05
    arm_distance: float = 0.1
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
    lookahead: int = 2
    lookahead_rise: float = 0.002
    candidates: int = 4
    candidate_spacing: float = 0.01

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
            "candidates": 1,
            "lookahead": 0,
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
            "edge_margin drop_margin rise_margin max_rise max_drop retract arm_distance clearance "
            "lookahead_rise arm_clearance retracted_clearance face_clearance touchdown_slope "
            "gait_min_thetadot w_speed w_end w_shape w_torque w_slope"
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
        if not self.retract < 0.5:
            raise ValueError(f"PlannerConfig.retract = {self.retract}; allowed: [0, 0.5)")
        if self.lookahead > 2:
            raise ValueError(f"PlannerConfig.lookahead = {self.lookahead}; allowed: 0, 1 or 2")
        self.rules()  # validates the foothold fields

    def rules(self) -> FootholdRules:
        """The foothold rules of this configuration."""
        return _rules(self)

    def _make_rules(self) -> FootholdRules:
        return FootholdRules(
            step_length=self.step_length,
            step_min=self.step_min,
            step_max=self.step_max,
            edge_margin=self.edge_margin,
            drop_margin=self.drop_margin,
            rise_margin=self.rise_margin,
            q1_min=self.q1_min,
            q1_max=self.q1_max,
            max_rise=self.max_rise,
            max_drop=self.max_drop,
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PlannerConfig:
        """Build from a dict; unknown keys raise ``ValueError``."""
        return dataclass_from_mapping(cls, d, "planner")

    @classmethod
    def for_robot(cls, name: str, **changes: Any) -> PlannerConfig:
        """Defaults for a robot preset from ``configs/planner/NAME.yaml`` (built-in defaults if
        there is no such file), with ``changes`` applied."""
        path = CONFIG_DIR / "planner" / f"{name}.yaml"
        d: dict[str, Any] = {}
        if path.exists():
            with open(path) as fh:
                d = yaml.safe_load(fh) or {}
        d.update(changes)
        return cls.from_dict(d)

    @classmethod
    def from_yaml(cls, path: str | Path) -> PlannerConfig:
        with open(path) as fh:
            return cls.from_dict(yaml.safe_load(fh) or {})


@functools.lru_cache(maxsize=64)
def _rules(config: PlannerConfig) -> FootholdRules:
    return config._make_rules()


# ---------------------------------------------------------------------------- plan objects
class StepPlan:
    """One planned step: constraint, footholds and nominal motion along ``theta``.

    Attributes:
        index: step number within its plan.
        constraint: the :class:`BezierConstraint` ``q1 = phi(theta)``.
        coeffs: Bezier coefficients ``a_0 .. a_M`` [rad].
        theta_plus, theta_minus: phase at the start / planned impact [rad].
        thetadot_plus, thetadot_minus: nominal ``theta_dot`` at the start / impact [rad/s].
        stance_foot: stance-foot position ``(x, y)`` [m]; foothold: planned touchdown ``(x, y)``.
        duration: nominal step duration [s].
        delta: impact gain along the constraints, ``theta_dot+_{j+1} = delta theta_dot-_j``.
        slope_plus: post-impact ``q1d+/q2d+`` (the next step's ``phi'(theta_plus)``).
        theta_grid, thetadot_sq_grid, time_grid, psi_grid, gam_grid, input_grid: nominal profile
            on the step's Chebyshev grid (``theta_dot^2 = psi theta_dot_plus^2 + gam``, ``u``).
        arm_theta: phase at which the swing foot is planned to be armed [rad].
    """

    def __init__(
        self,
        index: int,
        P: np.ndarray,
        constraint: BezierConstraint,
        thetadot_plus: float,
        stance_foot: tuple[float, float],
        foothold: tuple[float, float],
        grid: int,
        arm_theta: float = math.nan,
    ):
        self.index = int(index)
        self.P = P
        self.constraint = constraint
        self.stance_foot = (float(stance_foot[0]), float(stance_foot[1]))
        self.foothold = (float(foothold[0]), float(foothold[1]))
        self.arm_theta = float(arm_theta)
        th = rd.phase_grid(constraint.theta_plus, constraint.theta_minus, grid)
        ph, dph, ddph = constraint.derivatives(th)
        a, b, g = rd.reduced_coefficients(P, ph, th, dph, ddph)
        psi, gam = rd.reduced_integral(th, a, b, g)
        f = psi * thetadot_plus**2 + gam
        self.theta_grid = th
        self.psi_grid, self.gam_grid = psi, gam
        self.thetadot_sq_grid = f
        self.time_grid = rd.step_time(th, f)
        self.input_grid = rd.nominal_input(P, ph, th, dph, ddph, np.sqrt(f))
        self.thetadot_plus = float(thetadot_plus)
        self.thetadot_minus = float(np.sqrt(f[-1]))
        self.duration = float(self.time_grid[-1])
        self.delta, self.slope_plus = (
            float(v) for v in rd.impact_along_constraint(P, ph[-1], dph[-1])
        )
        self._f = rd.ChebyshevSeries(f, th[0], th[-1])
        self._t = rd.ChebyshevSeries(self.time_grid, th[0], th[-1])
        self._psi = rd.ChebyshevSeries(psi, th[0], th[-1])
        self._gam = rd.ChebyshevSeries(gam, th[0], th[-1])

    # --- constraint
    @property
    def coeffs(self) -> np.ndarray:
        return self.constraint.coeffs

    @property
    def theta_plus(self) -> float:
        return self.constraint.theta_plus

    @property
    def theta_minus(self) -> float:
        return self.constraint.theta_minus

    def phi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi(theta)`` [rad]."""
        return self.constraint.phi(theta)

    def dphi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi'(theta)``."""
        return self.constraint.dphi(theta)

    def ddphi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi''(theta)`` [1/rad]."""
        return self.constraint.ddphi(theta)

    # --- nominal motion
    def thetadot_sq(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot^2`` [rad^2/s^2] (``psi theta_dot_plus^2 + Gam``)."""
        return self._f(theta)

    def thetadot(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot`` [rad/s] (> 0 inside the step)."""
        return np.sqrt(np.maximum(self._f(theta), 0.0))

    def time(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal time since the start of the step [s] at phase ``theta``."""
        return self._t(theta)

    def psi(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``psi(theta, theta_plus)`` of the reduced-dynamics integral."""
        return self._psi(theta)

    def gam(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``Gam(theta, theta_plus)`` of the reduced-dynamics integral [rad^2/s^2]."""
        return self._gam(theta)

    def reduced(self, theta: np.ndarray | float) -> tuple[Any, Any, Any]:
        """``(alpha, beta, gamma)`` of the reduced dynamics at ``theta`` (exact, any ``theta``)."""
        ph, dph, ddph = self.constraint.derivatives(theta)
        return rd.reduced_coefficients(self.P, ph, np.asarray(theta, dtype=float), dph, ddph)

    def alpha(self, theta: np.ndarray | float) -> np.ndarray | float:
        return self.reduced(theta)[0]

    def beta(self, theta: np.ndarray | float) -> np.ndarray | float:
        return self.reduced(theta)[1]

    def gamma(self, theta: np.ndarray | float) -> np.ndarray | float:
        return self.reduced(theta)[2]

    def nominal_state(self, theta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Nominal ``(q, qd)`` at ``theta``: ``q = (phi, theta)``, ``qd = (phi' thd, thd)``."""
        ph, dph, _ = self.constraint.derivatives(theta)
        thd = self.thetadot(theta)
        th = np.asarray(theta, dtype=float)
        return np.stack([ph, th + 0.0 * ph]), np.stack([dph * thd, thd + 0.0 * dph])

    def input(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal hip input ``u`` [input units] along the step (friction included)."""
        ph, dph, ddph = self.constraint.derivatives(theta)
        return rd.nominal_input(
            self.P, ph, np.asarray(theta, float), dph, ddph, self.thetadot(theta)
        )

    def pre_impact_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Nominal state just before the planned touchdown."""
        q, qd = self.nominal_state(self.theta_minus)
        return q, qd

    def post_impact_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Nominal state just after the planned touchdown (legs swapped): the next step's start."""
        q, qd = self.pre_impact_state()
        q1, q2, q1d, q2d = model.impact(self.P, q[0], q[1], qd[0], qd[1])
        return np.array([q1, q2]), np.array([q1d, q2d])

    @property
    def step_length(self) -> float:
        """Horizontal distance from stance foot to foothold [m]."""
        return self.foothold[0] - self.stance_foot[0]

    def __repr__(self) -> str:
        return (
            f"StepPlan({self.index}: theta {self.theta_plus:.4f}->{self.theta_minus:.4f}, "
            f"thd {self.thetadot_plus:.3f}->{self.thetadot_minus:.3f}, T {self.duration:.3f} s, "
            f"foothold ({self.foothold[0]:.3f}, {self.foothold[1]:.3f}))"
        )


class Plan:
    """A planned sequence of steps (step 0 starts at the current post-impact state).

    Attributes:
        steps: list of :class:`StepPlan`.
        params: the robot's :class:`RobotParams`; P: its parameter vector.
        config: the :class:`PlannerConfig` used.
        solve_time: wall time of the planning call [s].
    """

    def __init__(self, steps: list[StepPlan], params: RobotParams, config: PlannerConfig):
        self.steps = list(steps)
        self.params = params
        self.P = params.vector()
        self.config = config
        self.solve_time = math.nan

    def __len__(self) -> int:
        return len(self.steps)

    def __getitem__(self, j: int) -> StepPlan:
        return self.steps[j]

    def __iter__(self):
        return iter(self.steps)

    def phi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        return self.steps[j].phi(theta)

    def dphi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        return self.steps[j].dphi(theta)

    def ddphi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        return self.steps[j].ddphi(theta)

    def thetadot(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        return self.steps[j].thetadot(theta)

    def thetadot_sq(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        return self.steps[j].thetadot_sq(theta)

    def time(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal time since the start of step ``j`` [s]."""
        return self.steps[j].time(theta)

    def reduced(self, j: int, theta: np.ndarray | float) -> tuple[Any, Any, Any]:
        """``(alpha, beta, gamma)`` of step ``j`` at ``theta``."""
        return self.steps[j].reduced(theta)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Nominal post-impact state ``(q, qd)`` at the start of step 0."""
        return self.steps[0].nominal_state(self.steps[0].theta_plus)

    @property
    def footholds(self) -> np.ndarray:
        """Planned footholds, shape ``(H, 2)`` [m]."""
        return np.array([s.foothold for s in self.steps])

    @property
    def durations(self) -> np.ndarray:
        """Nominal step durations [s]."""
        return np.array([s.duration for s in self.steps])

    @property
    def start_times(self) -> np.ndarray:
        """Nominal start time of each step relative to the start of step 0 [s]."""
        return np.concatenate([[0.0], np.cumsum(self.durations)[:-1]])

    def __repr__(self) -> str:
        return f"Plan({len(self.steps)} steps, {self.params.name})\n  " + "\n  ".join(
            repr(s) for s in self.steps
        )


@dataclass(frozen=True)
class PeriodicGait:
    """Nominal periodic gait on flat ground.

    Attributes:
        step: the step (its end maps onto its start through the impact).
        q, qd: post-impact state ``(q1, q2)`` [rad], ``(q1d, q2d)`` [rad/s].
        step_length: [m]; period: step duration [s]; speed: step_length / period [m/s].
        zero_dynamics_gain: ``delta^2 psi(theta-)``, the step-to-step gain of
            ``theta_dot^2`` on the constraint (< 1: the hybrid zero dynamics is stable).
    """

    step: StepPlan
    q: np.ndarray
    qd: np.ndarray
    step_length: float
    period: float
    speed: float
    zero_dynamics_gain: float


# periodic gaits already computed, by (parameter vector, config, step length, speed)
_GAIT_CACHE: dict[tuple, PeriodicGait] = {}


# ---------------------------------------------------------------------------- step problem
_CONSTRAINTS = (
    "theta_dot^2 bounded away from zero",
    "alpha bounded away from zero",
    "hip input within the actuator limit",
    "swing-foot clearance",
    "stance foot loaded and not slipping",
    "swing foot reaches the arming distance above ground",
    "vertical faces cleared",
    "transversal touchdown",
    "step duration bounds",
    "impact impulse in the friction cone",
    "trailing foot takes off",
    "post-impact theta_dot positive",
    "periodic orbit exists and is stable",
)


@dataclass
class _Fixed:
    """Data of one step that the optimiser does not change."""

    theta_plus: float
    a0: float
    slope: float  # phi'(theta_plus)
    thetadot_plus: float
    stance: tuple[float, float]
    foothold: tuple[float, float]
    theta_minus: float
    a_last: float
    thetadot_minus_ref: float = math.nan  # end-of-step speed aimed at (nan: the gait's)


class _StepModel:
    """Vectorised evaluation of one step's constraints and cost for the free coefficients."""

    def __init__(self, params: RobotParams, config: PlannerConfig, tmap: TerrainMap):
        self.params, self.cfg, self.tmap = params, config, tmap
        self.P = params.vector()
        n, m = config.grid, config.order
        self.s = 0.5 * (rd.cheb_nodes(n) + 1.0)
        self.B = [bernstein_basis(m, self.s, d) for d in range(3)]
        l = params.l  # noqa: E741
        self.l = l
        self.alpha_scale = model.mass_matrix(self.P, 0.0)[2]
        self.u_lim = config.torque_fraction * params.u_max
        # uniform grid for the geometric checks (swing-foot clearance, faces, theta_dot^2)
        self.sg = np.linspace(0.0, 1.0, config.check_points + 1)
        self.Bg = bernstein_basis(m, self.sg, 0)
        self.interp = np.polynomial.chebyshev.chebvander(2.0 * self.sg - 1.0, n) @ np.linalg.inv(
            np.polynomial.chebyshev.chebvander(rd.cheb_nodes(n), n)
        )
        ramp = np.minimum(1.0, (1.0 - self.sg) / config.clearance_ramp)
        self.clear_req = config.clearance * ramp
        # periodic gait's (thetadot_minus, slope_plus, normalised shape, speed); None: periodic
        self.ref: tuple[float, float, np.ndarray, float] | None = None
        self.ref_delta = 1.0  # the gait's impact gain
        self.wscale = 1.0  # scale of the weights that pull a step towards the gait
        self._qint = np.ascontiguousarray(rd.cumulative_integral_matrix(n))
        self._face_cache: dict[tuple, tuple[Any, ...]] = {}
        self._layouts: dict[tuple, tuple[np.ndarray, int]] = {}  # constraint layouts
        S = np.zeros(sk.S_COUNT)
        S[sk.S_MIN_THD] = config.min_thetadot
        S[sk.S_ALPHA_SCALE] = self.alpha_scale
        S[sk.S_U_LIM], S[sk.S_U_MAX] = self.u_lim, params.u_max
        S[sk.S_RETRACT], S[sk.S_ARM] = config.retract * l, config.arm_distance * l
        S[sk.S_ARM_CLEAR], S[sk.S_CLEAR] = config.arm_clearance, config.clearance
        S[sk.S_RAMP], S[sk.S_RET_CLEAR] = config.clearance_ramp, config.retracted_clearance
        S[sk.S_FACE_CLEAR], S[sk.S_TD_SLOPE] = config.face_clearance, config.touchdown_slope
        S[sk.S_MU] = config.friction
        S[sk.S_DUR_MIN], S[sk.S_DUR_MAX] = config.duration_min, config.duration_max
        S[sk.S_WEIGHT] = (2 * params.m + params.mHg) * params.g
        S[sk.S_MASS] = params.total_mass
        S[sk.S_W_SPEED], S[sk.S_W_TORQUE] = config.w_speed, config.w_torque
        S[sk.S_W_END], S[sk.S_W_SLOPE] = config.w_end, config.w_slope
        S[sk.S_W_SHAPE] = config.w_shape
        self._settings = S

    def coeffs(
        self,
        fx: _Fixed,
        free: np.ndarray,
        periodic: bool = False,
        slope: np.ndarray | float | None = None,
    ) -> np.ndarray:
        """Coefficients ``a_0 .. a_M`` for free coefficients ``free`` (shape ``(k,)`` or a batch
        ``(B, k)``; the result has the same leading shape). ``slope`` overrides ``fx.slope``."""
        m = self.cfg.order
        span = fx.theta_minus - fx.theta_plus
        x = np.asarray(free, dtype=np.float64)
        a = np.empty(x.shape[:-1] + (m + 1,))
        a[..., 0] = fx.a0
        a[..., 2:m] = x
        a[..., m] = fx.a_last
        sl = fx.slope if slope is None else slope
        if periodic:  # the step's own post-impact direction
            _, sl = rd.impact_along_constraint(
                self.P, a[..., m], m * (a[..., m] - a[..., m - 1]) / span
            )
        a[..., 1] = fx.a0 + sl * span / m
        return a

    def evaluate(self, fx: _Fixed, free: np.ndarray, periodic: bool = False) -> dict[str, Any]:
        """Everything about the step with free coefficients ``free`` (shape ``(k,)``).

        With ``periodic``, ``a_1`` and ``thetadot_plus`` are those of a period-one gait (the
        step's end maps onto its start); ``fx.slope`` and ``fx.thetadot_plus`` are ignored.
        """
        return _row(
            self.evaluate_batch(fx, np.asarray(free, dtype=np.float64)[None, :], periodic), 0
        )

    def evaluate_batch(
        self,
        fx: _Fixed,
        free: np.ndarray,
        periodic: bool = False,
        slope: np.ndarray | None = None,
        thetadot_plus: np.ndarray | None = None,
    ) -> dict[str, Any]:
        """:meth:`evaluate` for a batch of free-coefficient vectors ``free`` (shape ``(B, k)``);
        every entry of the result has a leading axis of length ``B`` (``groups``: a list of
        ``(B, n_i)`` arrays; ``g``: the packed constraint vectors). ``slope`` and
        ``thetadot_plus`` (shape ``(B,)``) override ``fx.slope`` and ``fx.thetadot_plus`` row by
        row (the start of a step that follows a step being optimised)."""
        with np.errstate(all="ignore"):
            return self._evaluate(
                fx, np.asarray(free, dtype=np.float64), periodic, slope, thetadot_plus
            )

    def _faces(self, xs: float, x_foot: float) -> tuple[Any, ...]:
        """Faces between the stance foot and the foothold (abscissa, top, crossed full-length),
        and the ground slopes under the stance foot and the foothold."""
        key = (xs, x_foot)
        out = self._face_cache.get(key)
        if out is None:
            faces = self.tmap.faces_between(xs, x_foot)
            arm = self.cfg.arm_distance * self.l
            out = (
                np.array([f[0] for f in faces], dtype=np.float64),
                np.array([f[1] for f in faces], dtype=np.float64),
                np.array([f[0] - xs >= arm for f in faces], dtype=np.bool_),
                self.tmap.terrain.slope_at(xs),
                self.tmap.terrain.slope_at(x_foot),
            )
            if len(self._face_cache) > 64:
                self._face_cache.clear()
            self._face_cache[key] = out
        return out

    def _evaluate(self, fx, free, periodic, slope_in, thd_in) -> dict[str, Any]:
        cfg = self.cfg
        nb = free.shape[0]
        a = np.ascontiguousarray(self.coeffs(fx, free, periodic, slope_in))
        span = fx.theta_minus - fx.theta_plus
        xs, ys = fx.stance
        face_x, face_top, face_full, slope_stance, slope_foot = self._faces(xs, fx.foothold[0])
        layout = self._layouts.get((face_x.size, periodic))
        if layout is None:
            sizes = sk.group_sizes(self.s.size, self.sg.size, face_x.size, periodic)
            offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
            layout = self._layouts[face_x.size, periodic] = (
                offsets,
                sk.packed_size(sizes, _PACK_BLOCK),
            )
        offsets, n_packed = layout
        S = self._settings.copy()
        S[sk.S_FMIN] = (
            max(cfg.min_thetadot, cfg.gait_min_thetadot) ** 2 if periodic else cfg.min_thetadot**2
        )
        S[sk.S_XS], S[sk.S_YS] = xs, ys
        S[sk.S_SLOPE_STANCE], S[sk.S_SLOPE_FOOT] = slope_stance, slope_foot
        S[sk.S_FOOT_X] = fx.foothold[0]
        S[sk.S_THETA_PLUS], S[sk.S_SPAN] = fx.theta_plus, span
        S[sk.S_WSCALE] = self.wscale
        if self.ref is None:  # periodic gait: speed target and effort
            S[sk.S_V_TARGET] = cfg.target_speed
            shape_ref = np.zeros(a.shape[1])
        else:  # steps: the periodic gait's speed, end speed and shape (zero cost on the gait)
            thm_ref, slope_ref, shape_ref, vt = self.ref
            if math.isfinite(fx.thetadot_minus_ref):
                thm_ref = fx.thetadot_minus_ref
            S[sk.S_V_TARGET], S[sk.S_THM_REF], S[sk.S_SLOPE_REF] = vt, thm_ref, slope_ref
            S[sk.S_D_REF] = self.ref_delta
        if periodic or thd_in is None:
            thd_plus = np.full(nb, float(fx.thetadot_plus))
        else:
            thd_plus = np.ascontiguousarray(thd_in, dtype=np.float64)
        G = np.empty((nb, offsets[-1]))
        R = np.empty((nb, sk.R_COUNT))
        F = np.empty((nb, self.s.size))
        U = np.empty((nb, self.s.size))
        sk.evaluate_steps(
            self.P, a, thd_plus, periodic, self.ref is not None, S, self.s,
            self.B[0], self.B[1], self.B[2], self.Bg, self.sg, self._qint, self.interp,
            self.clear_req, self.tmap.xs, self.tmap.ys, face_x, face_top, face_full,
            np.ascontiguousarray(shape_ref, dtype=np.float64), offsets, G, R, F, U,
        )  # fmt: skip
        groups = _Groups(G, offsets)
        g = np.empty((nb, n_packed))
        sk.pack(G, offsets, _PACK_BLOCK, g)
        return {
            "a": a,
            "f": F,
            "T": R[:, sk.R_T],
            "u": U,
            "groups": groups,
            "g": g,
            "cost": R[:, sk.R_COST],
            "thetadot_minus": R[:, sk.R_THD_MINUS],
            "delta": R[:, sk.R_DELTA],
            "slope_plus": R[:, sk.R_SLOPE_PLUS],
            "speed": R[:, sk.R_SPEED],
            "arm_theta": R[:, sk.R_ARM_THETA],
            "thetadot_plus": R[:, sk.R_THD_PLUS],
            "gain": R[:, sk.R_GAIN],
        }


class _Groups:
    """The constraint groups of a batched evaluation: column blocks of ``G``, sliced on use."""

    def __init__(self, G: np.ndarray, offsets: np.ndarray):
        self.G, self.offsets = G, offsets

    def __len__(self) -> int:
        return self.offsets.size - 1

    def __getitem__(self, i: int) -> np.ndarray:
        return self.G[:, self.offsets[i] : self.offsets[i + 1]]

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def _violations(groups: list[np.ndarray]) -> tuple[float, str]:
    worst, name = 0.0, ""
    for g, nm in zip(groups, _CONSTRAINTS):
        m = float(np.min(g)) if np.size(g) else 0.0
        if not math.isfinite(m):
            m = -math.inf
        if m < worst:
            worst, name = m, nm
    return worst, name


_CHAIN_DEPTH = 3  # footholds looked ahead when ranking candidates
_CHAIN_STRIDE = 4  # candidates tried first when looking for a chain (then all of them)
_LANDING_SLACK = (0.008, 0.004)  # touchdown errors a foothold chain should tolerate [m]
_PACK_BLOCK = 8  # long constraint groups reach SLSQP as minima over blocks of grid points
_FTOL = 1e-7  # SLSQP tolerance on the cost of a step problem
# an SLSQP run still infeasible after _STALL_ITERATIONS iterations (violation, the sum of the
# negative constraints, above _STALL_VIOLATION) stops once its last _STALL_WINDOW iterations
# brought the violation below _STALL_GAIN times its earlier best no more
_STALL_ITERATIONS, _STALL_WINDOW, _STALL_GAIN, _STALL_VIOLATION = 25, 5, 0.95, 1e-4
_FD_STEP = math.sqrt(np.finfo(float).eps)  # forward-difference step of the Jacobians


class _BatchProblem:
    """Cost and constraints of a batched evaluator for SLSQP, cached by point.

    ``fn(X)`` evaluates the rows of ``X`` (shape ``(B, k)``) and returns ``(cost, g, ev)``:
    costs ``(B,)``, packed constraints ``(B, m)`` and any batch payload (kept with the row
    index). The Jacobians are forward differences whose ``k`` perturbed points are evaluated in
    one batched call (the same derivatives SLSQP would take by itself, at a fraction of the cost).
    """

    def __init__(self, fn):
        self.fn = fn
        self.cache: dict[bytes, tuple[float, np.ndarray, Any, int]] = {}
        self._jac: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def _fill(self, X: np.ndarray) -> None:
        keys = [x.tobytes() for x in X]
        todo = [i for i, k in enumerate(keys) if k not in self.cache]
        if not todo:
            return
        cost, g, ev = self.fn(X[todo])
        for r, i in enumerate(todo):
            self.cache[keys[i]] = (float(cost[r]), g[r], ev, r)

    def get(self, x: np.ndarray) -> tuple[float, np.ndarray, Any, int]:
        """``(cost, g, payload, row)`` at ``x``."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        self._fill(x[None, :])
        return self.cache[x.tobytes()]

    def evaluate_many(self, X: np.ndarray) -> list[tuple[float, np.ndarray, Any, int]]:
        """:meth:`get` for every row of ``X`` in one batched call."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        self._fill(X)
        return [self.cache[x.tobytes()] for x in X]

    def _jacobians(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.ascontiguousarray(x, dtype=np.float64)
        key = x.tobytes()
        hit = self._jac.get(key)
        if hit is not None:  # SLSQP asks for the cost's and the constraints' at each point
            return hit
        X = _fd_points(x)
        rows = self.evaluate_many(X)
        h = np.diag(X[1:]) - x  # the steps actually taken
        c0, g0 = rows[0][0], rows[0][1]
        with np.errstate(all="ignore"):
            dc = np.array([r[0] - c0 for r in rows[1:]]) / h
            dg = np.stack([r[1] - g0 for r in rows[1:]], axis=1) / h
        # a point where the step model breaks down (NaN mapped to +-1e3) gives huge slopes
        for d in (dc, dg):
            d[np.isnan(d)] = 0.0
            np.clip(d, -1e12, 1e12, out=d)
        self._jac[key] = dc, dg
        return dc, dg

    def _with_jacobian_points(self, x: np.ndarray) -> tuple[float, np.ndarray, Any, int]:
        """:meth:`get`, evaluating the forward-difference points around ``x`` in the same
        batched call (along a converging run SLSQP asks for the Jacobians at every point it
        evaluates, and a batch costs little more than a single point)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        key = x.tobytes()
        if key not in self.cache:
            self._fill(_fd_points(x))
        return self.cache[key]

    def minimize(
        self, x0: np.ndarray, maxiter: int, ftol: float, stall: bool = False
    ) -> np.ndarray:
        """SLSQP from ``x0``; returns the final point. With ``stall``, a run that stops making
        progress towards feasibility ends early (see ``_STALL_ITERATIONS``)."""
        hist: list[float] = []  # constraint violation after each iteration

        def stop_when_stalled(intermediate_result):
            g = self.get(intermediate_result.x)[1]
            hist.append(float(-np.sum(np.minimum(g, 0.0))))
            w = _STALL_WINDOW
            if len(hist) >= _STALL_ITERATIONS and hist[-1] > _STALL_VIOLATION:
                if min(hist[-w:]) > _STALL_GAIN * min(hist[:-w]):  # no progress to feasibility
                    raise StopIteration

        res = minimize(
            lambda x: self._with_jacobian_points(x)[0],
            np.asarray(x0, dtype=np.float64),
            callback=stop_when_stalled if stall else None,
            jac=lambda x: self._jacobians(x)[0],
            method="SLSQP",
            constraints=[
                {
                    "type": "ineq",
                    "fun": lambda x: self._with_jacobian_points(x)[1],
                    "jac": lambda x: self._jacobians(x)[1],
                }
            ],
            options={"maxiter": maxiter, "ftol": ftol},
        )
        return np.asarray(res.x)


def _fd_points(x: np.ndarray) -> np.ndarray:
    """``x`` and its ``k`` forward-difference neighbours (rows)."""
    k = x.size
    X = np.empty((k + 1, k))
    X[:] = x
    X[1:] += _FD_STEP * np.eye(k)
    return X


def _row(ev: dict[str, Any], r: int) -> dict[str, Any]:
    """Row ``r`` of a batched step evaluation, as :meth:`_StepModel.evaluate` returns it."""
    out: dict[str, Any] = {}
    for key, v in ev.items():
        if key == "groups":
            out[key] = [g[r] for g in v]
        elif np.ndim(v) == 1:
            out[key] = float(v[r])
        else:
            out[key] = v[r]
    return out


# ---------------------------------------------------------------------------- planner
class GaitPlanner:
    """Plans footholds and Bezier constraints step by step over the terrain ahead.

    Args:
        params: robot parameters (or a preset name).
        config: :class:`PlannerConfig`, a dict of overrides of the robot's defaults, or None for
            the robot's defaults (``configs/planner/<preset>.yaml``).
    """

    def __init__(
        self, params: RobotParams | str, config: PlannerConfig | dict[str, Any] | None = None
    ):
        self.params = as_params(params)
        if config is None:
            config = PlannerConfig.for_robot(self.params.name)
        elif isinstance(config, dict):
            config = PlannerConfig.for_robot(self.params.name, **config)
        elif not isinstance(config, PlannerConfig):
            raise ValueError(f"config must be a PlannerConfig, a dict or None, got {config!r}")
        self.config = config
        self.P = self.params.vector()
        self._flat = TerrainMap("flat")
        self._gait: PeriodicGait | None = None  # the gait of the current planning call
        # solutions of step problems already solved (by problem data), and the free coefficients
        # of steps optimised as the second of a pair (warm starts for when they come up)
        self._memo: dict[tuple, np.ndarray] = {}
        self._hints: dict[tuple, np.ndarray] = {}
        self._failed: dict[tuple, dict] = {}  # step problems with no feasible solution found
        self._terrain_key: bytes = b""
        self._horizon = 1
        self._chains: dict[tuple, int] = {}  # foothold-chain lengths, see _reach
        self._chain_candidates: dict[tuple, tuple[np.ndarray, str]] = {}  # see _chain_footholds

    # ------------------------------------------------------------------ periodic gait
    def periodic_gait(
        self, step_length: float | None = None, speed: float | None = None
    ) -> PeriodicGait:
        """Periodic gait on flat ground with the given step length [m] and a speed [m/s] as close
        to ``speed`` as the constraints allow (defaults: the configuration's)."""
        cfg = self.config
        L = cfg.step_length if step_length is None else float(step_length)
        vt = cfg.target_speed if speed is None else float(speed)
        if not (math.isfinite(L) and 0 < L < 2 * self.params.l):
            raise ValueError(f"step_length = {L!r}; allowed: (0, 2 l) = (0, {2 * self.params.l})")
        if not (math.isfinite(vt) and vt > 0):
            raise ValueError(f"speed = {vt!r}; allowed: > 0 m/s")
        key = (tuple(self.P), tuple(sorted(asdict(cfg).items())), L, vt)
        if key in _GAIT_CACHE:
            return _GAIT_CACHE[key]
        sm = _StepModel(self.params, replace(cfg, target_speed=vt), self._flat)
        q1m, q2m = touchdown_configuration(L, 0.0, self.params.l)
        m = cfg.order
        fx = _Fixed(-q2m, -q1m, 0.0, 1.0, (0.0, 0.0), (L, 0.0), q2m, q1m)
        base = -q1m + 2.0 * q1m * np.arange(2, m) / m

        def batch(X):
            ev = sm.evaluate_batch(fx, X, periodic=True)
            return ev["cost"], ev["g"], ev

        prob = _BatchProblem(batch)
        # global search over the free shape (relative to the chord), then SLSQP
        if m == 4:
            r1 = np.linspace(-1.0, 2.0, 25)
            samples = np.stack(np.meshgrid(r1, r1, indexing="ij"), -1).reshape(-1, 2)
        else:
            from scipy.stats import qmc

            samples = -1.0 + 3.0 * qmc.Sobol(m - 2, seed=0).random(512)
        starts = base + 2.0 * q1m * samples
        evs = sm.evaluate_batch(fx, starts, periodic=True)
        gall = np.concatenate(evs["groups"], axis=1)
        viol = np.where(
            np.all(np.isfinite(gall), axis=1), np.sum(np.minimum(gall, 0.0), axis=1), -np.inf
        )
        scores = list(zip(viol.tolist(), evs["cost"].tolist()))
        ranked = sorted(range(len(samples)), key=lambda i: (scores[i][0], -scores[i][1]))[::-1]
        best_x, best_key = None, None
        for i in ranked[:3]:  # multi-start SLSQP from the best samples
            xs = starts[i]
            xr = prob.minimize(xs, 100, 1e-12)
            for x in (xr, xs):
                c, g, _, _ = prob.get(x)
                rank = (min(float(np.min(g)), 0.0) >= -1e-7, -c)
                if best_key is None or rank > best_key:
                    best_x, best_key = np.asarray(x), rank
        _, g, evb, r = prob.get(best_x)
        ev = _row(evb, r)
        if np.min(g) < -1e-7:
            worst, name = _violations(ev["groups"])
            raise PlanningError(
                0, f"no periodic gait: {name}", f"step_length {L} m, violation {worst:.3g}"
            )
        c = BezierConstraint(ev["a"], fx.theta_plus, fx.theta_minus)
        step = StepPlan(0, self.P, c, ev["thetadot_plus"], (0.0, 0.0), (L, 0.0), cfg.grid)
        q, qd = step.nominal_state(step.theta_plus)
        gait = PeriodicGait(step, q, qd, L, step.duration, L / step.duration, float(ev["gain"]))
        if len(_GAIT_CACHE) > 64:
            _GAIT_CACHE.clear()
        _GAIT_CACHE[key] = gait
        return gait

    # ------------------------------------------------------------------ planning
    def plan(
        self,
        terrain: Any,
        state: tuple[np.ndarray, np.ndarray],
        stance_foot: tuple[float, float],
        horizon: int | None = None,
        previous_plan: Plan | None = None,
    ) -> Plan:
        """Plan ``horizon`` steps from the post-impact ``state``.

        Args:
            terrain: a :class:`envs.terrain.Terrain`, a spec, a :class:`TerrainMap`, or a scan
                ``(xs, heights)`` [m].
            state: actual post-impact ``(q, qd)`` [rad, rad/s] (``q2d > 0``).
            stance_foot: stance-foot position ``(x, y)`` [m].
            horizon: number of steps (default ``config.horizon``).
            previous_plan: the plan made at the previous footstep (warm start). Step problems
                this planner already solved since the last call without a previous plan (same
                terrain, start state, footholds and weights, to 1e-10) are reused after one
                feasibility check instead of being optimised again; with ``None`` the planner
                forgets them, so a call without a previous plan depends on its arguments only.

        Raises:
            PlanningError: no feasible step (names the step and the violated constraint).
            ValueError: malformed state.
        """
        t0 = time.perf_counter()
        cfg = self.config
        H = cfg.horizon if horizon is None else int(horizon)
        if H < 1:
            raise ValueError(f"horizon = {horizon!r}; allowed: integer >= 1")
        q = np.asarray(state[0], dtype=float).reshape(-1)
        qd = np.asarray(state[1], dtype=float).reshape(-1)
        if q.shape != (2,) or qd.shape != (2,) or not np.all(np.isfinite(np.r_[q, qd])):
            raise ValueError(f"state must be finite (q, qd) pairs, got {state!r}")
        if not qd[1] > 0:
            raise PlanningError(0, "post-impact theta_dot positive", f"q2d = {qd[1]:.4g} rad/s")
        tmap = TerrainMap.coerce(terrain)
        self._terrain_key = tmap.xs.tobytes() + tmap.ys.tobytes()
        # a call without a previous plan starts afresh (its result depends on its inputs only)
        if previous_plan is None or len(self._memo) + len(self._hints) + len(self._failed) > 4096:
            self._memo.clear()
            self._hints.clear()
            self._failed.clear()
        gait = self._gait = self.periodic_gait()
        sm = _StepModel(self.params, cfg, tmap)
        sm.ref = self._ref = _reference(gait)
        sm.ref_delta = gait.step.delta
        start = (float(q[1]), float(q[0]), float(qd[0] / qd[1]), float(qd[1]))
        stance = (float(stance_foot[0]), float(stance_foot[1]))
        prev = list(previous_plan.steps) if previous_plan is not None else []
        self._horizon = H
        self._budget = 3 * H + 2 * cfg.candidates
        self._fresh = False
        self._deepest: PlanningError | None = None
        # a step optimisation of this call has failed: from then on, when replanning (the
        # previous plan is there to fall back on), stalled SLSQP runs end early
        self._struggling = False
        self._may_stall = previous_plan is not None
        reach = self._reach(tmap, stance[0], H)
        if reach < H:  # no chain of admissible footholds that long: no search can succeed
            raise PlanningError(reach, "foothold", self._reach_break(tmap, stance[0], H))
        steps = self._search(0, H, sm, tmap, start, stance, prev)
        plan = Plan(steps, self.params, cfg)
        plan.solve_time = time.perf_counter() - t0
        return plan

    def _search(self, j, H, sm, tmap, start, stance, prev) -> list[StepPlan]:
        """Depth-first search over footholds: steps ``j .. H-1`` from ``start``."""
        if j == H:
            return []
        err: PlanningError | None = None
        for step in self._step_options(j, sm, tmap, start, stance, prev):
            if isinstance(step, PlanningError):
                err = step
                break
            nxt = (
                step.theta_minus - step.coeffs[-1],
                -step.coeffs[-1],
                step.slope_plus,
                step.delta * step.thetadot_minus,
            )
            try:
                return [step, *self._search(j + 1, H, sm, tmap, nxt, step.foothold, prev)]
            except PlanningError as e:
                err = e
                if self._budget <= 0:
                    break
        if self._deepest is None or (err is not None and err.step > self._deepest.step):
            self._deepest = err
        raise self._deepest if self._deepest is not None else PlanningError(j, "infeasible")

    def _step_options(self, j, sm, tmap, start, stance, prev):
        """Feasible steps for the candidate footholds, best first; a :class:`PlanningError`
        as the last item says why the others failed."""
        cfg, l = self.config, self.params.l  # noqa: E741
        th_p, a0, slope, thd = start
        # warm start: the previous plan's step from (nearly) the same stance foot
        warm = [p for p in prev if abs(p.stance_foot[0] - stance[0]) < 1e-3]
        cx, cy, order, why = self._candidates(
            tmap,
            stance,
            th_p,
            self._horizon - 1 - j,
            warm[0].foothold[0] if warm else None,
            cfg.candidates,
        )
        if cx.size == 0:
            yield PlanningError(j, "foothold", why)
            return
        best_fail: tuple[float, str, str] = (-math.inf, "", "")
        # Rounds over the candidate footholds, each reached only when the steps planned after
        # the previous round's options failed: (1) the configured cost; (2) ten times the weight
        # on ending the step like the periodic gait. A step is optimised jointly with the next
        # one always (lookahead 1) or where the next step changes height (lookahead 2).
        rounds = (1.0, 10.0)
        for wscale, i in [(w, i) for w in rounds for i in order]:
            sm.wscale = wscale
            if self._budget <= 0:
                break
            self._budget -= 1
            self._fresh = False  # set when an optimisation runs (reused solutions cost nothing)
            fh = (float(cx[i]), float(cy[i]))
            q1m, q2m = touchdown_configuration(fh[0] - stance[0], fh[1] - stance[1], l)
            if not q2m > th_p + 0.05:
                best_fail = max(best_fail, (-1.0, "theta increases over the step", f"{fh}"))
                continue
            fx = _Fixed(th_p, a0, slope, thd, stance, fh, q2m, q1m, self._end_speed(tmap, fh, q1m))
            x0 = _shape_guess(sm.ref[2], a0, q1m, cfg.order)
            hint = self._hints.get(_hint_key(stance, fh))
            solved = True  # the warm start is an optimised solution
            if warm and abs(warm[0].foothold[0] - fh[0]) < cfg.rules().resolution:
                x0 = warm[0].coeffs[2:-1].copy()
            elif hint is not None:
                x0 = hint
            else:
                solved = False
            # a look-ahead step whose warm start is an optimised solution (of the previous plan
            # or as the second step of a pair) is kept when still feasible; it is re-optimised
            # when it becomes the first step from an actual state off the plan
            keep = j > 0 and solved
            nxt = self._next_template(tmap, fh, q1m, q2m) if cfg.lookahead else None
            if nxt is not None and cfg.lookahead == 2:  # where the ground changes height
                dh = abs(nxt[0].foothold[1] - fh[1]) + abs(fh[1] - stance[1])
                nxt = nxt if dh > cfg.lookahead_rise else None
            fx2 = x02 = None
            if nxt is not None:
                fx2, x02 = nxt
                k2 = [p for p in prev if abs(p.stance_foot[0] - fh[0]) < 1e-3]
                if k2 and abs(k2[0].foothold[0] - fx2.foothold[0]) < cfg.rules().resolution:
                    x02 = k2[0].coeffs[2:-1].copy()
                else:
                    x02 = self._hints.get(_hint_key(fh, fx2.foothold), x02)
            ev, ok = None, False
            if fx2 is not None:
                ev, ok = self._solve_pair(sm, fx, x0, fx2, x02, keep)
            if not ok:
                ev, ok = self._solve(sm, fx, x0, keep)
            if not self._fresh:
                self._budget += 1
            if ok:
                c = BezierConstraint(ev["a"], th_p, q2m)
                yield StepPlan(j, self.P, c, thd, stance, fh, cfg.grid, ev["arm_theta"])
                continue
            worst, name = _violations(ev["groups"])
            best_fail = max(best_fail, (worst, name, f"foothold x = {fh[0]:.3f} m"))
        yield PlanningError(
            j,
            best_fail[1] or "search budget exhausted",
            best_fail[2] + ("" if self._budget > 0 else "; search budget exhausted"),
        )

    def _candidates(
        self,
        tmap: TerrainMap,
        stance: tuple[float, float],
        theta_plus: float,
        depth: int,
        warm_x: float | None,
        need: int,
    ) -> tuple[np.ndarray, np.ndarray, list[int], str]:
        """Candidate footholds from ``stance`` ranked as :func:`candidate_footholds` does, with
        those from which a chain of ``depth`` more admissible footholds exists first, and among
        them those that keep such a chain when the foot lands further off (``_LANDING_SLACK``; on
        stairs the admissible footholds form narrow windows; a foothold on the edge of its
        window leaves no next step once the actual touchdown misses it by a millimetre).

        Returns ``(x, y, picks, reason)``: ``picks`` are the indices of the footholds the search
        tries, in order: the first one within the candidate resolution of ``warm_x`` [m], then
        candidates at least ``candidate_spacing`` from those picked, in list order, up to
        ``need``. Candidates are ranked only until the picks are settled; the rest follow
        unranked, in the order of :func:`candidate_footholds`."""
        cfg, l = self.config, self.params.l  # noqa: E741
        cx, cy, why = candidate_footholds(
            tmap, stance, cfg.rules(), l, self._theta_target(theta_plus), self._gait.step.theta_plus
        )
        depth = min(int(depth), _CHAIN_DEPTH)
        # without a face or kink within reach every candidate continues alike (smooth ground)
        reach = stance[0] + (depth + 1) * cfg.step_max + max(_LANDING_SLACK) + 2.0 * l
        f = tmap.features
        ranked = depth > 0 and np.any((f > stance[0] - cfg.step_max) & (f < reach))
        rank = np.full(cx.size, -1 if ranked else 0)  # -1: not ranked (yet)
        near = np.zeros(0, dtype=int)
        if warm_x is not None:
            near = np.nonzero(np.abs(cx - warm_x) < cfg.rules().resolution)[0]
        for k in near:
            if rank[k] < 0:
                rank[k] = self._landing_rank(tmap, float(cx[k]), depth)
        picks: list[int] = []

        def offer(k: int) -> bool:
            """Pick candidate ``k`` if it is spaced from the picks; whether the picks are done."""
            if len(picks) < need and all(
                abs(cx[k] - cx[p]) >= cfg.candidate_spacing for p in picks
            ):
                picks.append(k)
            return len(picks) >= need

        if near.size:  # the first match in the ranked list
            offer(int(min(near, key=lambda k: (rank[k], k))))
        for k in range(cx.size):  # the best rank first: rank-0 candidates in list order
            if rank[k] < 0:
                rank[k] = self._landing_rank(tmap, float(cx[k]), depth)
            if rank[k] == 0 and offer(k):
                break
        done = rank >= 0
        order = np.r_[
            np.nonzero(done)[0][np.argsort(rank[done], kind="stable")], np.nonzero(~done)[0]
        ].astype(int)
        for k in order:  # the picks not settled by the rank-0 candidates
            if offer(int(k)):
                break
        position = np.empty(cx.size, dtype=int)
        position[order] = np.arange(cx.size)
        return cx[order], cy[order], [int(position[k]) for k in picks], why

    def _landing_rank(self, tmap: TerrainMap, x: float, depth: int) -> int:
        """0 if a chain of ``depth`` footholds continues from ``x`` [m] however far the foot
        lands off by up to the largest ``_LANDING_SLACK``, 1 for the next smaller slack, ...,
        ``len(_LANDING_SLACK)`` with no slack, one more without any chain."""
        if not self._chain(tmap, x, depth):
            return len(_LANDING_SLACK) + 1
        r = 0
        for s in _LANDING_SLACK:  # largest landing error the chain tolerates, first
            if self._chain(tmap, x - s, depth) and self._chain(tmap, x + s, depth):
                break
            r += 1
        return r

    def _chain(self, tmap: TerrainMap, x: float, depth: int) -> bool:
        """Whether ``depth`` consecutive admissible footholds exist from a stance foot at ``x``
        [m] (geometric foothold rules only; memoised per terrain at 1 mm)."""
        return self._reach(tmap, x, depth) >= depth

    def _chain_footholds(self, tmap: TerrainMap, x: float) -> tuple[np.ndarray, str]:
        """Admissible footholds from a stance foot at ``x`` rounded to 1 mm, and why there are
        none when empty (memoised per terrain)."""
        xr = round(float(x), 3)
        key = (self._terrain_key, xr)
        hit = self._chain_candidates.get(key)
        if hit is None:
            cx, _, why = candidate_footholds(
                tmap, (xr, float(tmap.height(xr))), self.config.rules(), self.params.l
            )
            if len(self._chain_candidates) > 65536:
                self._chain_candidates.clear()
            hit = self._chain_candidates[key] = (cx, why)
        return hit

    def _reach(self, tmap: TerrainMap, x: float, depth: int) -> int:
        """How many consecutive admissible footholds (at most ``depth``) a chain from a stance
        foot at ``x`` [m] can have (geometric foothold rules only; memoised at 1 mm)."""
        if depth <= 0:
            return 0
        key = (self._terrain_key, round(float(x), 3), depth)
        hit = self._chains.get(key)
        if hit is not None:
            return hit
        cx, _ = self._chain_footholds(tmap, x)
        best = 0
        # every _CHAIN_STRIDE-th candidate first: on passable ground one of them continues
        for c in (*cx[:: max(1, _CHAIN_STRIDE)], *cx):
            best = max(best, 1 + self._reach(tmap, float(c), depth - 1))
            if best >= depth:
                break
        if len(self._chains) > 65536:
            self._chains.clear()
        self._chains[key] = best
        return best

    def _reach_break(self, tmap: TerrainMap, x: float, depth: int) -> str:
        """Why the longest chain of footholds from ``x`` ends (see :meth:`_reach`)."""
        while True:
            cx, why = self._chain_footholds(tmap, x)
            if cx.size == 0:
                return f"from a stance foot at x = {x:.3f} m: {why}"
            depth -= 1
            x = float(max(cx, key=lambda c: self._reach(tmap, float(c), depth)))

    def _end_speed(self, tmap: TerrainMap, foothold: tuple[float, float], q1m: float) -> float:
        """End-of-step ``theta_dot`` to aim at: the gait's, corrected by the potential energy the
        next step will gain or lose (slow down before a drop, speed up before a rise)."""
        gait = self._gait
        assert gait is not None
        dh = float(tmap.height(foothold[0] + self.config.step_length)) - foothold[1]
        pr = self.params
        m22 = model.mass_matrix(self.P, q1m)[2]
        f = gait.step.thetadot_minus**2 + 2.0 * (2 * pr.m + pr.mHg) * pr.g * dh / m22
        return math.sqrt(max(f, (1.5 * self.config.min_thetadot) ** 2))

    def _theta_target(self, theta_plus: float) -> float:
        """Preferred touchdown ``q2`` for a step starting at ``theta_plus``: the gait's, moved by
        half the start's deviation (keeps the phase range near the gait's; the deviation of
        ``theta_plus`` halves from step to step on flat ground)."""
        st = self._gait.step
        return st.theta_minus + 0.5 * (theta_plus - st.theta_plus)

    def _next_template(self, tmap, fh, q1m, q2m) -> tuple[_Fixed, np.ndarray] | None:
        """The step after a step ending on ``fh`` (its start speed left open), or None."""
        cfg, l = self.config, self.params.l  # noqa: E741
        th_p2 = q2m - q1m
        cx, cy, _, _ = self._candidates(tmap, fh, th_p2, 1, None, 1)
        if cx.size == 0:
            return None
        fh2 = (float(cx[0]), float(cy[0]))
        q1n, q2n = touchdown_configuration(fh2[0] - fh[0], fh2[1] - fh[1], l)
        if not q2n > th_p2 + 0.05:
            return None
        end = self._end_speed(tmap, fh2, q1n)
        fx2 = _Fixed(th_p2, -q1m, math.nan, math.nan, fh, fh2, q2n, q1n, end)
        return fx2, _shape_guess(self._ref[2], -q1m, q1n, cfg.order)

    def _problem_key(self, sm: _StepModel, fx: _Fixed, fx2: _Fixed | None) -> tuple:
        """Everything a step problem (or a pair) depends on besides the planner itself."""

        def data(f: _Fixed) -> tuple:
            v = (f.theta_plus, f.a0, f.slope, f.thetadot_plus, *f.stance, *f.foothold)
            return tuple(
                round(float(x), 10) if math.isfinite(x) else None
                for x in (*v, f.thetadot_minus_ref)
            )

        return (
            self._terrain_key,
            sm.wscale,
            data(fx),
            None if fx2 is None else data(fx2),
        )

    def _solve_pair(self, sm, fx, x0, fx2, x02, keep: bool = False) -> tuple[dict, bool]:
        """SLSQP on the free coefficients of a step and the next one together; returns the
        first step's evaluation and whether both steps are feasible (``keep``: see
        :meth:`_solve`)."""
        n = x0.size

        def batch(X):
            e1 = sm.evaluate_batch(fx, X[:, :n])
            thd2 = e1["delta"] * e1["thetadot_minus"]
            e2 = sm.evaluate_batch(fx2, X[:, n:], slope=e1["slope_plus"], thetadot_plus=thd2)
            return e1["cost"] + e2["cost"], np.concatenate([e1["g"], e2["g"]], axis=1), e1

        prob = _BatchProblem(batch)
        key = self._problem_key(sm, fx, fx2)
        if key in self._failed:
            return self._failed[key], False
        x = self._reuse(prob, key, np.concatenate([x0, x02]), keep)
        if x is not None:
            _, _, e1, r = prob.get(x)
            return _row(e1, r), True
        self._fresh = True
        x = prob.minimize(np.concatenate([x0, x02]), self.config.max_iter, _FTOL, self._struggling)
        _, g, e1, r = prob.get(x)
        ok = bool(np.min(g) >= -1e-7)
        if ok:
            self._memo[key] = x
            self._hints[_hint_key(fx2.stance, fx2.foothold)] = x[n:]
        else:
            self._failed[key] = _row(e1, r)
            self._struggling = self._may_stall
        return _row(e1, r), ok

    def _reuse(self, prob: _BatchProblem, key: tuple, x0: np.ndarray, keep: bool):
        """A solution that needs no optimisation, or None: the solution of the same problem
        solved before (if still feasible), and with ``keep`` the warm start ``x0`` if it is
        feasible (remembered as the problem's solution)."""
        if key in self._memo:
            x = self._memo[key]
            if np.min(prob.get(x)[1]) >= -1e-7:
                return x
        if keep and np.min(prob.get(x0)[1]) >= -1e-7:
            self._memo[key] = np.array(x0, dtype=np.float64)
            return x0
        return None

    def _solve(
        self, sm: _StepModel, fx: _Fixed, x0: np.ndarray, keep: bool = False
    ) -> tuple[dict, bool]:
        """SLSQP on the free coefficients from ``x0``; from the best point of a coarse global
        search if that fails. A problem solved before is not optimised again; with ``keep`` (a
        look-ahead step, re-optimised when it becomes the first step from a state off the plan)
        neither is one whose warm start is already feasible."""

        def batch(X):
            ev = sm.evaluate_batch(fx, X)
            return ev["cost"], ev["g"], ev

        prob = _BatchProblem(batch)

        def run(xs):
            _, g, ev, r = prob.get(prob.minimize(xs, self.config.max_iter, _FTOL, self._struggling))
            return _row(ev, r), bool(np.min(g) >= -1e-7)

        key = self._problem_key(sm, fx, None)
        if key in self._failed:
            return self._failed[key], False
        x = self._reuse(prob, key, x0, keep)
        if x is not None:
            _, _, evm, r = prob.get(x)
            return _row(evm, r), True
        self._fresh = True
        ev, ok = run(x0)
        if ok:
            self._memo[key] = ev["a"][2:-1].copy()
            return ev, True
        chord = fx.a_last - fx.a0
        base = fx.a0 + chord * np.arange(2, self.config.order) / self.config.order
        samples = _global_samples(self.config.order)
        scores = [
            (float(np.sum(np.minimum(g, 0.0))), -c)
            for c, g, _, _ in prob.evaluate_many(base + chord * samples)
        ]
        best = max(range(len(samples)), key=lambda i: scores[i])
        ev2, ok2 = run(base + chord * samples[best])
        if ok2:
            self._memo[key] = ev2["a"][2:-1].copy()
        if ok2 or np.sum(np.minimum(ev2["g"], 0)) > np.sum(np.minimum(ev["g"], 0)):
            ev = ev2
        if not ok2:
            self._failed[key] = ev
            self._struggling = self._may_stall
        return ev, ok2


def _hint_key(stance: tuple[float, float], foothold: tuple[float, float]) -> tuple:
    return (round(stance[0], 6), round(foothold[0], 6))


def _global_samples(order: int) -> np.ndarray:
    """Free coefficients relative to the chord ``a_0 -> a_M`` for the coarse global search."""
    if order == 4:
        r = np.linspace(-1.0, 2.5, 9)
        return np.stack(np.meshgrid(r, r, indexing="ij"), -1).reshape(-1, 2)
    from scipy.stats import qmc

    return -1.0 + 3.5 * qmc.Sobol(order - 2, seed=0).random(64)


def _reference(gait: PeriodicGait) -> tuple[float, float, np.ndarray, float]:
    a = gait.step.coeffs
    base = a[0] + (a[-1] - a[0]) * np.arange(a.size) / (a.size - 1)
    rel = (a - base) / (a[-1] - a[0])
    return gait.step.thetadot_minus, gait.step.slope_plus, rel, gait.speed


def _shape_guess(rel: np.ndarray, a0: float, a_last: float, order: int) -> np.ndarray:
    k = np.arange(order + 1)
    base = a0 + (a_last - a0) * k / order
    return (base + rel * (a_last - a0))[2:-1]
