"""Passive walking down a slope: the step-to-step (Poincare) map on the post-impact section and
its fixed point, the passive limit cycle, found by Newton's method.

The classic walker (``RobotParams.from_preset("classic")``) on a slope of -0.0525 rad has the
cycle of the control notes: post-impact stance angle ``q2 = -0.218775`` rad, stance rate
``q2d = 1.092867`` rad/s, period 0.734461 s, step length 0.535919 m.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .params import RobotParams
from .simulator import SimConfig, simulate
from .terrain import Terrain


class CycleStart(NamedTuple):
    """Post-impact state of a passive cycle down a slope, in the terms of the control notes.

    Attributes:
        slope: ground angle [rad], negative downhill.
        q2: stance-leg angle [rad].
        swing: swing-leg angle ``q2 - q1`` [rad].
        q2d: stance-leg rate [rad/s].
        swing_rate: swing-leg rate ``q2d - q1d`` [rad/s].
    """

    slope: float
    q2: float
    swing: float
    q2d: float
    swing_rate: float

    @property
    def q(self) -> tuple[float, float]:
        """``(q1, q2)`` [rad]."""
        return (self.q2 - self.swing, self.q2)

    @property
    def qd(self) -> tuple[float, float]:
        """``(q1d, q2d)`` [rad/s]."""
        return (self.q2d - self.swing_rate, self.q2d)

    @property
    def section(self) -> tuple[float, float, float]:
        """The post-impact section point ``(q2, q1d, q2d)`` [rad, rad/s] (see
        :func:`slope_section_state`)."""
        return (self.q2, self.q2d - self.swing_rate, self.q2d)


#: the classic walker's passive cycle down a 0.0525 rad slope (control notes, section 1), to six
#: digits: a start state near the cycle and a guess for :func:`passive_limit_cycle`
CLASSIC_CYCLE = CycleStart(
    slope=-0.0525, q2=-0.218775, swing=0.323775, q2d=1.092867, swing_rate=0.376135
)


@dataclass(frozen=True)
class LimitCycle:
    """A periodic passive gait down a slope, on the post-impact Poincare section.

    Attributes:
        state: post-impact ``(q1, q2, q1d, q2d)`` [rad, rad/s] of the cycle.
        period: step period [s].
        step_length: distance between consecutive footholds [m].
        jacobian: (3, 3) Jacobian of the step-to-step map in the section coordinates
            ``(q2, q1d, q2d)`` [rad, rad/s] (central finite differences).
        eigenvalues: its eigenvalues (moduli below 1: stable).
    """

    state: np.ndarray
    period: float
    step_length: float
    jacobian: np.ndarray
    eigenvalues: np.ndarray


def slope_section_state(z: Sequence[float], slope: float) -> tuple[np.ndarray, np.ndarray]:
    """Section coordinates ``z = (q2, q1d, q2d)`` [rad, rad/s] right after an impact on a
    constant slope of ``slope`` [rad] (negative downhill) -> ``(q, qd)`` [rad, rad/s]: both feet
    on the ground, so ``q1 = 2 (q2 + slope)``."""
    q2, q1d, q2d = (float(v) for v in z)
    return np.array([2.0 * (q2 + slope), q2]), np.array([q1d, q2d])


def slope_step_map(
    params: RobotParams | str,
    slope: float,
    z: Sequence[float],
    config: SimConfig | None = None,
) -> tuple[np.ndarray, float, float]:
    """One passive step down a slope of ``slope`` [rad] from the post-impact section point ``z``
    [rad, rad/s] (see :func:`slope_section_state`): returns the next section point, the step
    period [s] and the step length [m]. Raises ``RuntimeError`` if the walker fails or does not
    step within 5 s."""
    q0, qd0 = slope_section_state(z, slope)
    res = simulate(params, Terrain.slope(slope), q0, qd0, 5.0, config=config, stop_at_impacts=1)
    if res.failure is not None or len(res.impact_times) < 1:
        raise RuntimeError(f"no passive step from {list(z)}: failure {res.failure}")
    k = int(np.nonzero(np.diff(res.t) == 0)[0][0]) + 1
    znew = np.array([res.q[k, 1], res.qd[k, 0], res.qd[k, 1]])
    return znew, float(res.impact_times[0]), float(np.hypot(*res.footholds[0]))


def passive_limit_cycle(
    params: RobotParams | str,
    slope: float,
    guess: Sequence[float],
    config: SimConfig | None = None,
    tol: float = 1e-11,
    fd_step: float = 1e-6,
) -> LimitCycle:
    """Fixed point of the passive step-to-step map down a slope by Newton's method.

    Args:
        params: robot parameters or preset name.
        slope: ground angle [rad], negative downhill.
        guess: starting section point ``(q2, q1d, q2d)`` [rad, rad/s] just after an impact.
        config: simulator settings (default :meth:`SimConfig.accurate`).
        tol: convergence tolerance on the section point [rad, rad/s].
        fd_step: finite-difference step of the Jacobian [rad, rad/s].

    Raises:
        RuntimeError: the walker fails, or Newton does not converge in 20 iterations.
    """
    cfg = config if config is not None else SimConfig.accurate()
    z = np.asarray(guess, dtype=np.float64).copy()
    if z.shape != (3,) or not np.all(np.isfinite(z)):
        raise ValueError(f"guess must be 3 finite numbers (q2, q1d, q2d), got {guess!r}")

    def jac(z: np.ndarray) -> np.ndarray:
        J = np.empty((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = fd_step
            J[:, j] = (
                slope_step_map(params, slope, z + e, cfg)[0]
                - slope_step_map(params, slope, z - e, cfg)[0]
            ) / (2 * fd_step)
        return J

    for _ in range(20):
        fz = slope_step_map(params, slope, z, cfg)[0]
        dz = np.linalg.solve(jac(z) - np.eye(3), z - fz)
        z = z + dz
        if np.max(np.abs(dz)) < tol:
            break
    else:
        raise RuntimeError("passive limit cycle: Newton did not converge")
    J = jac(z)
    _, period, length = slope_step_map(params, slope, z, cfg)
    q, qd = slope_section_state(z, slope)
    return LimitCycle(
        state=np.r_[q, qd],
        period=period,
        step_length=length,
        jacobian=J,
        eigenvalues=np.linalg.eigvals(J),
    )
