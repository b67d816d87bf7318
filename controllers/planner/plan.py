"""Plan objects: one planned step (:class:`StepPlan`), a plan of several (:class:`Plan`), and the
periodic flat-ground gait the planner steers towards (:class:`PeriodicGait`).

A step's nominal motion along ``theta`` comes from the integral of the reduced dynamics
(:mod:`controllers.reduced`) on the step's Chebyshev grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from envs.physics import model
from envs.physics.params import RobotParams

from .. import reduced as rd
from ..bezier import BezierConstraint
from .config import PlannerConfig

__all__ = ["PeriodicGait", "Plan", "StepPlan"]


@njit(cache=True, error_model="numpy")
def _step_profile(P, ph, th, dph, ddph, thetadot_plus_sq, q):
    """A step's nominal profile on its grid ``th`` [rad] (the constraint's ``ph, dph, ddph``
    there), in one compiled call of :mod:`controllers.reduced`: ``psi, Gam``, ``theta_dot^2 =
    psi theta_dot_plus^2 + Gam`` [rad^2/s^2], the time [s] (where ``theta_dot^2 > 0``), the
    nominal input, and the impact's gain and post-impact slope (``q``: the grid's
    cumulative-integral matrix)."""
    a, b, g = rd.reduced_coefficients(P, ph, th, dph, ddph)
    n = th.size
    half = 0.5 * (th[n - 1] - th[0])
    psi, gam = np.empty(n), np.empty(n)
    rd.grid_reduced_integral(a, b, g, q, half, -np.inf, psi, gam)
    f = psi * thetadot_plus_sq + gam
    thd, time = np.empty(n), np.empty(n)
    rd.grid_step_time(f, q, half, 0.0, thd, time)
    u = rd.nominal_input(P, ph, th, dph, ddph, np.sqrt(f))
    delta, slope = rd.impact_along_constraint(P, ph[n - 1], dph[n - 1])
    return psi, gam, f, time, u, delta, slope


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
        P: the robot's parameter vector (``RobotParams.vector()``).
        note: how the step's foothold departs from the planner's rules ("" if it does not;
            e.g. relaxed riser margins, :attr:`PlannerConfig.relaxed_margin`).
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
        self.note = ""
        th = rd.phase_grid(constraint.theta_plus, constraint.theta_minus, grid)
        ph, dph, ddph = constraint.derivatives(th)
        psi, gam, f, time, u, delta, slope = _step_profile(
            P, ph, th, dph, ddph, float(thetadot_plus) ** 2, rd.cumulative_integral_matrix(grid)
        )
        if np.any(~(f > 0)):  # (rd.step_time's check and message)
            raise ValueError("step_time: theta_dot^2 must be > 0 on the whole grid (one grid)")
        self.theta_grid = th
        self.psi_grid, self.gam_grid = psi, gam
        self.thetadot_sq_grid = f
        self.time_grid = time
        self.input_grid = u
        self.thetadot_plus = float(thetadot_plus)
        self.thetadot_minus = float(np.sqrt(f[-1]))
        self.duration = float(self.time_grid[-1])
        self.delta, self.slope_plus = float(delta), float(slope)
        self._f = rd.ChebyshevSeries(f, th[0], th[-1])
        self._t = rd.ChebyshevSeries(self.time_grid, th[0], th[-1])
        self._psi = rd.ChebyshevSeries(psi, th[0], th[-1])
        self._gam = rd.ChebyshevSeries(gam, th[0], th[-1])

    # --- constraint
    @property
    def coeffs(self) -> np.ndarray:
        """Bezier coefficients ``a_0 .. a_M`` [rad]."""
        return self.constraint.coeffs

    @property
    def theta_plus(self) -> float:
        """Phase at the start of the step [rad]."""
        return self.constraint.theta_plus

    @property
    def theta_minus(self) -> float:
        """Phase at the planned impact [rad]."""
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
        """Nominal ``theta_dot^2`` [rad^2/s^2] (``psi theta_dot_plus^2 + Gam``) at phase
        ``theta`` [rad]."""
        return self._f(theta)

    def thetadot(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot`` [rad/s] (> 0 inside the step) at phase ``theta`` [rad]."""
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
        """``alpha(theta)`` of the reduced dynamics."""
        return self.reduced(theta)[0]

    def beta(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``beta(theta)`` of the reduced dynamics."""
        return self.reduced(theta)[1]

    def gamma(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``gamma(theta)`` of the reduced dynamics."""
        return self.reduced(theta)[2]

    def nominal_state(self, theta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Nominal ``(q, qd)`` at ``theta``: ``q = (phi, theta)``, ``qd = (phi' thd, thd)``."""
        ph, dph, _ = self.constraint.derivatives(theta)
        thd = self.thetadot(theta)
        th = np.asarray(theta, dtype=float)
        return np.stack([ph, th + 0.0 * ph]), np.stack([dph * thd, thd + 0.0 * dph])

    def input(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal hip input ``u`` [input units] along the step (friction included) at phase
        ``theta`` [rad]."""
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
        evaluations: step evaluations the planning call spent (see
            :attr:`PlannerConfig.max_evaluations`), the beam search's included.
        beam_evaluations: those of the beam search over the horizon (its own budget,
            :attr:`PlannerConfig.beam_evaluations`).
        violations: per step, ``(worst, constraint)``: the most negative constraint value and
            the violated constraint's name (``(0.0, "")`` for a feasible step); a plan of the
            least-violating steps (:meth:`GaitPlanner.plan_least_violation`) may have some.
        beam: the steps come from the beam search over the horizon (the depth-first search
            found no plan; :attr:`PlannerConfig.beam_width`).
    """

    def __init__(self, steps: list[StepPlan], params: RobotParams, config: PlannerConfig):
        self.steps = list(steps)
        self.params = params
        self.P = params.vector()
        self.config = config
        self.solve_time = math.nan
        self.evaluations = 0
        self.beam_evaluations = 0
        self.violations: list[tuple[float, str]] = [(0.0, "")] * len(self.steps)
        self.beam = False

    def __len__(self) -> int:
        return len(self.steps)

    def __getitem__(self, j: int) -> StepPlan:
        return self.steps[j]

    def __iter__(self):
        return iter(self.steps)

    def phi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi_j(theta)`` of step ``j`` [rad]."""
        return self.steps[j].phi(theta)

    def dphi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi_j'(theta)`` of step ``j``."""
        return self.steps[j].dphi(theta)

    def ddphi(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """``phi_j''(theta)`` of step ``j`` [1/rad]."""
        return self.steps[j].ddphi(theta)

    def thetadot(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot`` [rad/s] of step ``j`` at phase ``theta`` [rad]."""
        return self.steps[j].thetadot(theta)

    def thetadot_sq(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal ``theta_dot^2`` [rad^2/s^2] of step ``j`` at phase ``theta`` [rad]."""
        return self.steps[j].thetadot_sq(theta)

    def time(self, j: int, theta: np.ndarray | float) -> np.ndarray | float:
        """Nominal time since the start of step ``j`` [s] at phase ``theta`` [rad]."""
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
