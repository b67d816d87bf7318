"""The periodic flat-ground gait: the step whose end maps onto its start through the impact.

It is the planner's reference: its speed, its post-impact speed and its shape anchor the step
costs. The free Bezier coefficients are found by a coarse global search over shapes relative to
the chord ``a_0 -> a_M`` followed by SLSQP from the best samples; the cost is the speed error and
the mean squared hip input.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from envs.physics.params import RobotParams

from ..bezier import BezierConstraint
from .config import PlannerConfig, PlanningError
from .footholds import TerrainMap, touchdown_configuration
from .plan import PeriodicGait, StepPlan
from .problem import (
    BatchProblem,
    FixedStep,
    StepEvaluator,
    batch_row,
    violation,
    worst_violation,
)

__all__ = ["GaitCache", "solve_periodic_gait"]


class GaitCache:
    """Periodic gaits already computed, by key (parameter vector, configuration, step length and
    speed); cleared when it holds more than ``limit`` gaits and another one comes.

    Args:
        limit: gaits held before the cache is cleared.
    """

    def __init__(self, limit: int = 64):
        self.limit = limit
        self._gaits: dict[tuple, PeriodicGait] = {}

    def get(self, key: tuple) -> PeriodicGait | None:
        """The gait stored under ``key``, or None."""
        return self._gaits.get(key)

    def put(self, key: tuple, gait: PeriodicGait) -> None:
        """Store ``gait`` under ``key``."""
        if len(self._gaits) > self.limit:
            self._gaits.clear()
        self._gaits[key] = gait

    def __len__(self) -> int:
        return len(self._gaits)


def solve_periodic_gait(
    params: RobotParams, config: PlannerConfig, flat: TerrainMap, step_length: float, speed: float
) -> PeriodicGait:
    """Periodic gait on the flat map ``flat`` with step length ``step_length`` [m] and a speed as
    close to ``speed`` [m/s] as the constraints allow.

    Raises:
        PlanningError: no feasible periodic gait (names the violated constraint).
    """
    cfg, L, vt = config, step_length, speed
    P = params.vector()
    sm = StepEvaluator(params, replace(cfg, target_speed=vt), flat)
    q1m, q2m = touchdown_configuration(L, 0.0, params.l)
    m = cfg.order
    fx = FixedStep(-q2m, -q1m, 0.0, 1.0, (0.0, 0.0), (L, 0.0), q2m, q1m)
    base = -q1m + 2.0 * q1m * np.arange(2, m) / m

    def batch(X):
        ev = sm.evaluate_batch(fx, X, periodic=True)
        return ev["cost"], ev["g"], ev

    prob = BatchProblem(batch)
    # global search over the free shape (relative to the chord), then SLSQP
    if m == 4:
        r1 = np.linspace(-1.0, 2.0, 25)
        samples = np.stack(np.meshgrid(r1, r1, indexing="ij"), -1).reshape(-1, 2)
    else:
        from scipy.stats import qmc  # deferred: scipy.stats is slow to import, rarely needed

        samples = -1.0 + 3.0 * qmc.Sobol(m - 2, seed=0).random(512)
    starts = base + 2.0 * q1m * samples
    evs = sm.evaluate_batch(fx, starts, periodic=True)
    gall = np.concatenate(evs["groups"], axis=1)
    viol = np.where(np.all(np.isfinite(gall), axis=1), -violation(gall, axis=1), -np.inf)
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
    ev = batch_row(evb, r)
    if np.min(g) < -1e-7:
        worst, name = worst_violation(ev["groups"])
        raise PlanningError(
            0, f"no periodic gait: {name}", f"step_length {L} m, violation {worst:.3g}"
        )
    c = BezierConstraint(ev["a"], fx.theta_plus, fx.theta_minus)
    step = StepPlan(0, P, c, ev["thetadot_plus"], (0.0, 0.0), (L, 0.0), cfg.grid)
    q, qd = step.nominal_state(step.theta_plus)
    return PeriodicGait(step, q, qd, L, step.duration, L / step.duration, float(ev["gain"]))
