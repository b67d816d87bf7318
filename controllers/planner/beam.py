"""The beam search over the horizon: footholds and step speeds chosen jointly.

The depth-first search (:mod:`.search`) optimises one step (or a pair) at a time towards a
speed aimed one step ahead, so a sequence that must shed or gain speed several steps before a
rise or a drop is found only by luck. When it fails, the planner searches the horizon as a
whole: every step of every kept branch tries its candidate footholds (the ranked list of
:meth:`FootholdChains.ranked`, ``PlannerConfig.beam_footholds`` of them), and for each foothold
a fixed set of shapes (the periodic gait's, quasi-random shapes near it and, unless
``PlannerConfig.beam_far`` is 0, over the whole range of the coarse global search) evaluated in
one compiled batch. Of each foothold's feasible shapes it keeps the cheapest and
``beam_speeds`` more spread over the post-impact speeds they lead to (the slowest, the fastest
and evenly between), so that branches reaching the next rise slower or faster stay in the
search. Of all children of a depth it keeps the ``beam_width``
cheapest by the cost accumulated over the branch, at most two per foothold. The result is a
plan of feasible (not optimised) steps over the whole horizon, or the deepest branch found.
With ``PlannerConfig.beam_coarse`` a coarse pass comes first, with the first few shapes of
each set: its budget then reaches more branches, and where it spans the horizon the full set
is not tried (with ``PlannerConfig.beam_full`` 0, nowhere).

Nothing here optimises: the steps are the sampled shapes themselves, every constraint of the
step problem holds on them as for any planned step, and the next footstep's depth-first search
starts from them (they are the previous plan's warm starts).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from ..bezier import BezierConstraint, chord_coefficients
from .config import BEAM_SHAPES
from .footholds import touchdown_configuration
from .plan import StepPlan
from .problem import MIN_PHASE_SPAN, BudgetExhausted, SearchBudget, shape_guess

if TYPE_CHECKING:
    from .search import StepSearch

__all__ = ["beam_steps", "beam_shapes"]

_FEASIBLE = -1e-7  # least constraint value of a feasible step (as in the search)
_PER_FOOTHOLD = 2  # branches kept per foothold at each depth (diversity)
_NEAR_SPAN = 0.4  # half-width of the box around the gait's shape (fractions of the chord)


@functools.lru_cache(maxsize=8)
def beam_shapes(order: int) -> tuple[np.ndarray, np.ndarray]:
    """The quasi-random shapes a beam step tries for Bezier order ``order``: offsets of the
    free coefficients from the gait's shape (``(32, order - 2)``, within +-0.4 of the chord)
    and free coefficients relative to the chord over the global search's range
    (``(32, order - 2)``, in ``[-1, 2.5]``). Fixed (Sobol, seeded): same call, same plan."""
    from scipy.stats import qmc  # deferred: scipy.stats is slow to import

    k = order - 2
    near = _NEAR_SPAN * (2.0 * qmc.Sobol(k, seed=1).random(BEAM_SHAPES) - 1.0)
    far = -1.0 + 3.5 * qmc.Sobol(k, seed=0).random(BEAM_SHAPES)
    near.setflags(write=False)
    far.setflags(write=False)
    return near, far


class _Branch:
    """One kept branch: its steps so far, accumulated cost, and the start of its next step."""

    __slots__ = ("cost", "steps", "start", "stance")

    def __init__(self, cost: float, steps: list, start: tuple, stance: tuple[float, float]):
        self.cost, self.steps, self.start, self.stance = cost, steps, start, stance


def beam_steps(
    search: StepSearch, start: tuple[float, float, float, float], stance: tuple[float, float]
) -> tuple[list[StepPlan], int, bool]:
    """The beam search from ``start = (theta_plus, a_0, phi'(theta_plus), theta_dot_plus)``
    [rad, rad, -, rad/s] with the stance foot at ``stance`` [m], over ``search.horizon`` steps:
    with ``PlannerConfig.beam_coarse`` > 0, a coarse pass first (that many of each set of
    shapes), then, where it spans no horizon and ``PlannerConfig.beam_full`` is 1, the full
    search with the evaluations left.

    Returns ``(steps, evaluations, exhausted)``: the cheapest branch that spans the horizon,
    else the deepest branch found (possibly empty; the full pass's where the two reach as
    deep), as :class:`StepPlan` s; the step evaluations spent (at most the search's
    ``beam_budget``, ``PlannerConfig.beam_evaluations`` unless the planning call set less,
    plus one batch a pass; the call's ``time_budget`` bounds it too); and whether the budget
    cut the search.
    """
    cfg, budget = search.config, search.beam_budget
    used = 0
    coarse: list[StepPlan] = []
    if cfg.beam_coarse > 0:
        coarse, used, cut = _beam_pass(search, start, stance, cfg.beam_coarse, budget)
        if len(coarse) == search.horizon or cut or not cfg.beam_full:
            return coarse, used, cut
    steps, more, cut = _beam_pass(search, start, stance, BEAM_SHAPES, budget - used)
    return (steps if len(steps) >= len(coarse) else coarse), used + more, cut


def _beam_pass(
    search: StepSearch,
    start: tuple[float, float, float, float],
    stance: tuple[float, float],
    shapes: int,
    evaluations: int,
) -> tuple[list[StepPlan], int, bool]:
    """One beam search (:func:`beam_steps`) with the first ``shapes`` of each set of
    :func:`beam_shapes` and a budget of ``evaluations`` step evaluations."""
    cfg, sm, l = search.config, search.model, search.params.l  # noqa: E741
    budget = search.evaluations.another(evaluations)  # (and the call's time bound)
    near, far = beam_shapes(cfg.order)
    near, far = near[:shapes], far[: shapes if cfg.beam_far else 0]
    rel = sm.ref.shape
    sm.wscale = 1.0
    beam = [_Branch(0.0, [], start, stance)]
    deepest: list = []
    for j in range(search.horizon):
        children: list[_Branch] = []
        for br in beam:
            if budget.exhausted:
                break
            children.extend(_expand(search, br, j, near, far, rel, budget, l))
        if not children:
            break
        children.sort(key=lambda b: b.cost)
        per: dict[float, int] = {}
        beam = []
        for b in children:
            key = round(b.stance[0], 6)
            if per.get(key, 0) < _PER_FOOTHOLD:
                per[key] = per.get(key, 0) + 1
                beam.append(b)
                if len(beam) >= cfg.beam_width:
                    break
        deepest = beam[0].steps
    steps = [
        StepPlan(
            j,
            search.P,
            BezierConstraint(a, fx.theta_plus, fx.theta_minus),
            fx.thetadot_plus,
            fx.stance,
            fx.foothold,
            cfg.grid,
            arm,
        )
        for j, (fx, a, arm) in enumerate(deepest)
    ]
    return steps, budget.used, budget.exhausted


def _expand(search, br: _Branch, j: int, near, far, rel, budget: SearchBudget, l: float):
    """The children of one branch: per candidate foothold, its kept feasible shapes."""
    cfg, sm = search.config, search.model
    th_p, a0, slope, thd = br.start
    cx, cy, order, _ = search._candidates(
        br.stance, th_p, search.horizon - 1 - j, None, cfg.beam_footholds
    )
    out = []
    for i in order:
        fh = (float(cx[i]), float(cy[i]))
        q1m, q2m = touchdown_configuration(fh[0] - br.stance[0], fh[1] - br.stance[1], l)
        if not q2m > th_p + MIN_PHASE_SPAN:
            continue
        fx = search.fixed_step(j, br.start, br.stance, fh, q1m, q2m)
        chord = q1m - a0
        gait_shape = shape_guess(rel, a0, q1m, cfg.order)
        base = chord_coefficients(a0, q1m, np.arange(2, cfg.order), cfg.order)
        X = np.vstack([gait_shape[None], gait_shape + chord * near, base + chord * far])
        try:
            budget.spend(X.shape[0])
        except BudgetExhausted:  # the branches keep what they have
            break
        ev = sm.evaluate_batch(fx, X, screen=_FEASIBLE)  # only the feasible rows are kept
        ok = np.nonzero(np.min(ev["g"], axis=1) >= _FEASIBLE)[0]
        if ok.size == 0:
            continue
        for r in _kept_rows(ev, ok, cfg.beam_speeds):
            nxt = (
                q2m - q1m,
                -q1m,
                float(ev["slope_plus"][r]),
                float(ev["delta"][r] * ev["thetadot_minus"][r]),
            )
            if not (math.isfinite(nxt[2]) and nxt[3] > 0):
                continue
            step = (fx, ev["a"][r].copy(), float(ev["arm_theta"][r]))
            out.append(_Branch(br.cost + float(ev["cost"][r]), [*br.steps, step], nxt, fh))
    return out


def _kept_rows(ev: dict, ok: np.ndarray, n: int) -> list[int]:
    """Of the feasible rows ``ok``: the cheapest, and ``n`` spread evenly over the post-impact
    speeds they lead to, from the slowest to the fastest (each row once)."""
    rows = [int(ok[np.argmin(ev["cost"][ok])])]
    if n > 0:
        by_speed = ok[np.argsort(ev["delta"][ok] * ev["thetadot_minus"][ok], kind="stable")]
        for q in np.linspace(0.0, 1.0, n):
            r = int(by_speed[int(round(q * (by_speed.size - 1)))])
            if r not in rows:
                rows.append(r)
    return rows
