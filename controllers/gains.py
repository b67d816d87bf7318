"""Gains of the receding-horizon controller over the planned steps (paper Section 4).

At every footstep the controller linearises the transverse dynamics of the current step and
the next ``horizon`` steps (:mod:`controllers.transverse`), with the phase ``theta`` as
independent variable, and solves the jump-Riccati equation backwards from ``Z(t_f) = 0`` over
those steps (:mod:`controllers.riccati`): :func:`horizon_gains`. It keeps the gain
``K(theta) = -R^-1 B' Z^-1`` of the current step on a uniform ``theta`` grid
(:class:`HorizonSolution`). :func:`pd_gains` gives the plain PD gains on ``y`` that the PD
baseline and the last-planned-step fallback use instead.

:class:`GainTable` is the current step as the compiled control tick reads it
(:func:`controllers.feedback.feedback_law`): the constraint in power form, the nominal speed
profile and the gains on uniform phase grids, and the actuator limit.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from envs.physics.terrain import Terrain

from .feedback import lyapunov_at, pack_scalars
from .numerics import one_blas_thread
from .riccati import solve_jump_riccati
from .transverse import StepModel, impact_jacobian

if TYPE_CHECKING:  # annotations only (the controller module imports this one)
    from .controller import ControllerConfig
    from .planner import StepPlan

__all__ = ["GainTable", "HorizonSolution", "horizon_gains", "pd_gains", "step_models"]


@dataclass
class HorizonSolution:
    """Gains of the current step from one jump-Riccati solve.

    Attributes:
        steps: the transverse models of the steps in the horizon (current first).
        theta: gain nodes of the current step [rad]; K: gains ``(n + 1, 3)``;
        Zinv: the Lyapunov matrices ``Z^-1`` (``V = z' Z^-1 z``) at the nodes, ``(n + 1, 3, 3)``;
        impact_jacobians: the impact jacobians ``F_j`` used between the steps.
        solve_time: wall time of linearisation + Riccati [s]; riccati_time: Riccati only [s].
    """

    steps: list[StepModel]
    theta: np.ndarray
    K: np.ndarray
    Zinv: np.ndarray
    impact_jacobians: list[np.ndarray]
    solve_time: float
    riccati_time: float

    def lyapunov(self, z: np.ndarray, theta: float) -> float:
        """``V = z' Z^-1 z`` at phase ``theta`` (linear interpolation of ``Z^-1``)."""
        th = self.theta
        return lyapunov_at(
            self.Zinv, th[0], th[1] - th[0], float(z[0]), float(z[1]), float(z[2]), float(theta)
        )


@dataclass(frozen=True)
class GainTable:
    """The current step as the control tick reads it: constraint, nominal speed and gains.

    Build it with :meth:`from_solution`; run a tick with
    ``feedback_law(P, x, *table.kernel_args())`` (:func:`controllers.feedback.feedback_law`).

    Attributes:
        theta_plus: phase at the start of the step [rad].
        span: ``theta_minus - theta_plus`` [rad].
        phi_coeffs: power-basis coefficients of ``phi`` in ``s = (theta - theta_plus) / span``,
            ascending powers [rad].
        speed_theta0: phase of the first node of the speed grid [rad] (the step extended by its
            model's margin).
        speed_step: spacing of the speed grid [rad].
        thetadot_sq: nominal ``theta_dot^2`` at the speed-grid nodes [rad^2/s^2].
        dthetadot_sq: its ``theta`` derivative at the same nodes [rad/s^2].
        gain_theta0: phase of the first gain node [rad].
        gain_step: spacing of the gain nodes [rad].
        gains: ``K`` at the gain nodes, shape ``(n + 1, 3)``: ``v = K x_perp``.
        u_max: actuator limit [input units].
        late_blend: phase over which ``phi'`` is blended to 0 past a late touchdown [rad]
            (0: the polynomial is extrapolated).
        friction_limit: friction coefficient of the input's friction-cone clip
            (``ControllerConfig.friction_limit``; 0: off).
        stance_slope: ground slope ``dh/dx`` under the stance foot (dimensionless).
        scalars: the scalar fields packed for the compiled tick (derived, not an argument).
    """

    theta_plus: float
    span: float
    phi_coeffs: np.ndarray
    speed_theta0: float
    speed_step: float
    thetadot_sq: np.ndarray = field(repr=False)
    dthetadot_sq: np.ndarray = field(repr=False)
    gain_theta0: float
    gain_step: float
    gains: np.ndarray = field(repr=False)
    u_max: float
    late_blend: float
    friction_limit: float = 0.0
    stance_slope: float = 0.0
    scalars: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        packed = pack_scalars(
            self.theta_plus,
            self.span,
            self.speed_theta0,
            self.speed_step,
            self.gain_theta0,
            self.gain_step,
            self.u_max,
            self.late_blend,
            self.friction_limit,
            self.stance_slope,
        )
        object.__setattr__(self, "scalars", packed)

    @classmethod
    def from_solution(
        cls,
        solution: HorizonSolution,
        u_max: float,
        late_blend: float,
        speed_intervals: int,
        friction_limit: float = 0.0,
        stance_slope: float = 0.0,
    ) -> GainTable:
        """The table of the solution's current step.

        Args:
            solution: the gains of the current step.
            u_max: actuator limit [input units].
            late_blend: see :attr:`late_blend` [rad].
            speed_intervals: intervals of the speed grid over the step and its margins.
            friction_limit: see :attr:`friction_limit` (0: off).
            stance_slope: see :attr:`stance_slope`.
        """
        m0 = solution.steps[0]
        c = m0.constraint
        a = c.theta_plus - m0.margin * c.span
        b = c.theta_minus + m0.margin * c.span
        th = np.linspace(a, b, speed_intervals + 1)
        return cls(
            theta_plus=c.theta_plus,
            span=c.span,
            phi_coeffs=m0.power_coefficients,
            speed_theta0=a,
            speed_step=float(th[1] - th[0]),
            thetadot_sq=np.ascontiguousarray(m0.thetadot_sq(th)),
            dthetadot_sq=np.ascontiguousarray(m0.dthetadot_sq(th)),
            gain_theta0=float(solution.theta[0]),
            gain_step=float(solution.theta[1] - solution.theta[0]),
            gains=np.ascontiguousarray(solution.K),
            u_max=u_max,
            late_blend=late_blend,
            friction_limit=friction_limit,
            stance_slope=stance_slope,
        )

    def kernel_args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(scalars, phi_coeffs, thetadot_sq, dthetadot_sq, gains)``: the arguments of
        :func:`controllers.feedback.feedback_law` after ``P`` and ``x``."""
        return self.scalars, self.phi_coeffs, self.thetadot_sq, self.dthetadot_sq, self.gains


@one_blas_thread
def step_models(
    P: np.ndarray, steps: list[StepPlan], terrain: Terrain | None, margin: float = 0.15
) -> list[StepModel]:
    """Transverse models of planned steps (``P``: robot parameter vector); the switching
    surface at each foothold follows the ground slope there (0 without a terrain)."""
    out = []
    for s in steps:
        slope = 0.0 if terrain is None else terrain.slope_at(s.foothold[0])
        out.append(StepModel(P, s.constraint, s.thetadot_plus, slope, margin=margin))
    return out


@one_blas_thread
def horizon_gains(models: list[StepModel], config: ControllerConfig) -> HorizonSolution:
    """Linearise the steps and solve the jump-Riccati equation over them (current step first),
    with the weights and grid of ``config``.

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
    K = sol.K[0][:, 0, :].copy()
    return HorizonSolution(models, theta, K, sol.Zinv[0], F, t2 - t0, t2 - t1)


def pd_gains(models: list[StepModel], grid: int, kp: float, kd: float) -> HorizonSolution:
    """Constant gains ``v = -kp y - kd y_dot`` on the current step (``Z^-1 = I`` for ``V``);
    ``kp`` [1/s^2], ``kd`` [1/s], ``grid`` intervals of the gain grid."""
    m0 = models[0]
    theta = np.linspace(m0.theta_plus, m0.theta_minus, grid + 1)
    K = np.tile(np.array([0.0, -kp, -kd]), (grid + 1, 1))
    Zinv = np.tile(np.eye(3), (grid + 1, 1, 1))
    return HorizonSolution(models, theta, K, Zinv, [], math.nan, math.nan)
