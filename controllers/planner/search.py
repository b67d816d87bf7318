"""The search over steps: one planning call's depth-first search over footholds and step shapes.

Steps are optimised one after the other along the horizon (each step's end state is the next
step's start), warm-started from the previous plan; where the ground changes height a step is
optimised jointly with the next one (only the first is kept), which lets it anticipate drops and
rises. Footholds come ranked by :meth:`FootholdChains.ranked`; when a step has no feasible
solution the search backtracks to other footholds and to shapes that end closer to the gait
(depth first, with a budget of step solves). With ``PlannerConfig.pairs_first`` every
foothold's pair is tried before any step alone, so the search goes beyond a foothold from
which the next step is infeasible only when no other foothold's pair is feasible. Terrain on
which no chain of admissible footholds spans the horizon fails at once, naming the step without
a foothold.

Step problems already solved during the current walk are reused (:class:`StepSolutions`:
replanning from the planned state re-solves only the newly added step), and a look-ahead step
whose warm start (the previous plan's solution, or the second step of a jointly optimised pair)
is still feasible is kept as it is: it is optimised when it becomes the first step of a plan
from a state off the previous plan.

When the depth-first search finds no plan over the horizon, the beam search of :mod:`.beam`
(``PlannerConfig.beam_width``) searches footholds and step speeds over the whole horizon
jointly; its plan, or its branch if deeper than the search's, is the call's result.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from envs.physics import model
from envs.physics.params import RobotParams

from ..bezier import BezierConstraint, chord_coefficients
from .beam import beam_steps
from .config import PlannerConfig, PlanningError
from .footholds import FootholdChains, TerrainMap, touchdown_configuration
from .plan import PeriodicGait, Plan, StepPlan
from .problem import (
    MIN_PHASE_SPAN,
    BatchProblem,
    BudgetExhausted,
    FixedStep,
    SearchBudget,
    StepEvaluator,
    batch_row,
    gait_reference,
    shape_guess,
    violation,
    worst_violation,
)

__all__ = ["StepSearch", "StepSolutions"]

_FTOL = 1e-7  # SLSQP tolerance on the cost of a step problem
_UNBOUNDED = 2**62  # evaluations of a search without a budget


class StepSolutions:
    """The step problems a planner has solved during the current walk.

    Attributes:
        solved: free coefficients of solved step problems (and pairs), by problem key.
        hints: free coefficients of steps optimised as the second of a pair, by stance foot and
            foothold (warm starts for when they come up).
        failed: the best evaluation of step problems with no feasible solution found.
    """

    def __init__(self) -> None:
        self.solved: dict[tuple, np.ndarray] = {}
        self.hints: dict[tuple, np.ndarray] = {}
        self.failed: dict[tuple, dict] = {}

    def __len__(self) -> int:
        return len(self.solved) + len(self.hints) + len(self.failed)

    def clear(self) -> None:
        """Forget every solution."""
        self.solved.clear()
        self.hints.clear()
        self.failed.clear()


class StepSearch:
    """The state of one planning call: the search over footholds and step shapes.

    Args:
        params: robot parameters.
        config: planner settings.
        tmap: the terrain.
        gait: the periodic gait (the reference of the step costs).
        solutions: the planner's solved step problems (read and extended).
        chains: the planner's foothold-chain search.
        horizon: steps to plan.
        previous_plan: the plan made at the previous footstep (warm starts), or None.
        max_evaluations: step evaluations the search may spend (default: when replanning,
            ``config.max_evaluations``, the whole search otherwise).
    """

    def __init__(
        self,
        params: RobotParams,
        config: PlannerConfig,
        tmap: TerrainMap,
        gait: PeriodicGait,
        solutions: StepSolutions,
        chains: FootholdChains,
        horizon: int,
        previous_plan: Plan | None,
        max_evaluations: int | None = None,
        max_beam_evaluations: int | None = None,
    ):
        self.params, self.config, self.tmap = params, config, tmap
        self.P = params.vector()
        self.gait = gait
        self.solutions, self.chains = solutions, chains
        self.model = StepEvaluator(params, config, tmap)
        self.model.ref = gait_reference(gait)
        self.prev = list(previous_plan.steps) if previous_plan is not None else []
        # the previous plan's footholds are tried first, unless the preferred foothold moved
        self.warm_footholds = (
            previous_plan is None or previous_plan.config.foothold_shift == config.foothold_shift
        )
        self.horizon = horizon
        self.budget = 3 * horizon + 2 * config.candidates  # step solves left
        self.may_stall = previous_plan is not None
        # the budget bounds replanning (a previous plan is there to fall back on); a plan from
        # scratch runs its whole search unless the call sets a budget
        if max_evaluations is None:
            max_evaluations = config.max_evaluations if self.may_stall else _UNBOUNDED
        self.evaluations = SearchBudget(
            max_evaluations, config.time_budget if self.may_stall else 0.0
        )
        self.path: list[StepPlan] = []  # the steps of the branch being searched
        self.partial: list[StepPlan] = []  # the feasible steps before the deepest failure
        self.fresh = False  # the current option ran an optimisation
        self.deepest: PlanningError | None = None  # the failure furthest along the horizon
        # a step optimisation of this call has failed: from then on, when replanning (the
        # previous plan is there to fall back on), stalled SLSQP runs end early
        self.struggling = False
        self.beam = False  # the plan came from the beam search over the horizon
        self.beam_evaluations = 0  # step evaluations the beam search spent (its own budget)
        # what the beam search may spend: its configured budget, or less where the call says
        self.beam_budget = config.beam_evaluations
        if max_beam_evaluations is not None:
            self.beam_budget = min(self.beam_budget, max_beam_evaluations)

    def run(
        self, start: tuple[float, float, float, float], stance: tuple[float, float]
    ) -> list[StepPlan]:
        """The planned steps from ``start = (theta_plus, a_0, phi'(theta_plus),
        theta_dot_plus)`` [rad, rad, -, rad/s] with the stance foot at ``stance`` [m].

        Raises:
            PlanningError: no feasible plan (the deepest failure of the search), with the
                feasible steps before it (``partial``) and the evaluations spent.
        """
        H = self.horizon
        # (with the relaxed rules where the rules leave a stance foot no foothold, as the
        # steps' candidates)
        reach = self.chains.reach(self.tmap, stance[0], H, relaxed=True)
        try:
            if reach < H:  # no chain of admissible footholds that long: no search can succeed
                why = self.chains.reach_break(self.tmap, stance[0], H, relaxed=True)
                raise PlanningError(reach, "foothold", why)
            return self._steps(0, start, stance)
        except PlanningError as exc:
            exc.partial = list(self.partial)
            exc.evaluations = self.evaluations.used
            exc.budget_exhausted = self.evaluations.exhausted
            if reach < H or self.config.beam_width == 0 or self.beam_budget <= 0:
                raise
            # the footholds and speeds over the horizon searched jointly
            steps, used, cut = beam_steps(self, start, stance)
            self.evaluations.used += used
            self.beam_evaluations = used
            exc.evaluations, exc.beam_evaluations = self.evaluations.used, used
            exc.budget_exhausted |= cut
            if len(steps) == H:
                self.beam = True
                return steps
            if len(steps) <= len(exc.partial):
                raise
            # the beam got further: its deepest branch is the best plan found
            deeper = PlanningError(len(steps), "no feasible step in the beam search", str(exc))
            deeper.partial, deeper.evaluations = steps, exc.evaluations
            deeper.beam_evaluations = used
            deeper.budget_exhausted = exc.budget_exhausted
            raise deeper from exc

    def _steps(self, j: int, start: tuple, stance: tuple[float, float]) -> list[StepPlan]:
        """Depth-first search over footholds: steps ``j .. H-1`` from ``start``."""
        if j == self.horizon:
            return []
        err: PlanningError | None = None
        for step in self._step_options(j, start, stance):
            if isinstance(step, PlanningError):
                err = step
                if self.deepest is None or err.step > self.deepest.step:
                    self.partial = list(self.path[:j])
                break
            nxt = (
                step.theta_minus - step.coeffs[-1],
                -step.coeffs[-1],
                step.slope_plus,
                step.delta * step.thetadot_minus,
            )
            self.path[j:] = [step]
            try:
                return [step, *self._steps(j + 1, nxt, step.foothold)]
            except PlanningError as e:
                err = e
                if self.budget <= 0 or self.evaluations.exhausted:
                    break
        if self.deepest is None or (err is not None and err.step > self.deepest.step):
            self.deepest = err
        raise self.deepest if self.deepest is not None else PlanningError(j, "infeasible")

    def _step_options(
        self, j: int, start: tuple, stance: tuple[float, float]
    ) -> Iterator[StepPlan | PlanningError]:
        """Feasible steps for the candidate footholds, best first; a :class:`PlanningError`
        as the last item says why the others failed."""
        cfg, l, sm = self.config, self.params.l, self.model  # noqa: E741
        memo = self.solutions
        th_p, a0, slope, thd = start
        # warm start: the previous plan's step from (nearly) the same stance foot
        warm = [p for p in self.prev if abs(p.stance_foot[0] - stance[0]) < 1e-3]
        cx, cy, order, why = self._candidates(
            stance,
            th_p,
            self.horizon - 1 - j,
            warm[0].foothold[0] if warm and self.warm_footholds else None,
            cfg.candidates,
        )
        if cx.size == 0:
            yield PlanningError(j, "foothold", why)
            return
        best_fail: tuple[float, str, str] = (-math.inf, "", "")
        # Rounds over the candidate footholds, each reached only when the steps planned after
        # the previous round's options failed: (1) the configured cost; (2) ten times the weight
        # on ending the step like the periodic gait. A step is optimised jointly with the next
        # one always (lookahead 1) or where the next step changes height (lookahead 2). With
        # ``pairs_first`` each round first tries every candidate's pair (a step with a next one
        # that is feasible too), then alone the steps whose pair failed: a foothold from which
        # the next step is infeasible is searched beyond only when no other foothold's is
        rounds = (1.0, 10.0)
        # (at the horizon's last step a pair's second step is beyond it: each foothold's pair,
        # then its step alone, as without ``pairs_first``)
        staged = cfg.pairs_first and cfg.lookahead and j < self.horizon - 1
        stages = (True, False) if staged else (None,)
        paired: set[int] = set()  # candidates whose step was solved in a pair stage
        for wscale, stage, i in [(w, g, i) for w in rounds for g in stages for i in order]:
            sm.wscale = wscale
            if stage is False and i not in paired:
                continue  # solved alone in the pair stage (no next step to pair it with)
            if self.budget <= 0 or self.evaluations.exhausted:
                break
            self.budget -= 1
            self.fresh = False  # set when an optimisation runs (reused solutions cost nothing)
            fh = (float(cx[i]), float(cy[i]))
            q1m, q2m = touchdown_configuration(fh[0] - stance[0], fh[1] - stance[1], l)
            if not q2m > th_p + MIN_PHASE_SPAN:
                best_fail = max(best_fail, (-1.0, "theta increases over the step", f"{fh}"))
                continue
            fx = self.fixed_step(j, start, stance, fh, q1m, q2m)
            x0 = shape_guess(sm.ref.shape, a0, q1m, cfg.order)
            hint = memo.hints.get(_hint_key(stance, fh))
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
            # (no pair in a round's second stage: its steps are solved alone)
            nxt = (
                self._next_template(fh, q1m, q2m) if cfg.lookahead and stage is not False else None
            )
            if nxt is not None and cfg.lookahead == 2:  # where the ground changes height
                dh = abs(nxt[0].foothold[1] - fh[1]) + abs(fh[1] - stance[1])
                nxt = nxt if dh > cfg.lookahead_rise else None
            fx2 = x02 = None
            if nxt is not None:
                fx2, x02 = nxt
                k2 = [p for p in self.prev if abs(p.stance_foot[0] - fh[0]) < 1e-3]
                if k2 and abs(k2[0].foothold[0] - fx2.foothold[0]) < cfg.rules().resolution:
                    x02 = k2[0].coeffs[2:-1].copy()
                else:
                    x02 = memo.hints.get(_hint_key(fh, fx2.foothold), x02)
            ev, ok = None, False
            try:
                if fx2 is not None:
                    ev, ok = self._solve_pair(fx, x0, fx2, x02, keep)
                    if stage:
                        paired.add(i)
                if not ok and not (stage and fx2 is not None):
                    ev, ok = self._solve(fx, x0, keep)
            except BudgetExhausted:
                break
            if not self.fresh:
                self.budget += 1
            if ok:
                c = BezierConstraint(ev["a"], th_p, q2m)
                step = StepPlan(j, self.P, c, thd, stance, fh, cfg.grid, ev["arm_theta"])
                step.note = why  # the riser margins relaxed (candidates exist: else empty)
                yield step
                continue
            worst, name = worst_violation(ev["groups"])
            best_fail = max(best_fail, (worst, name, f"foothold x = {fh[0]:.3f} m"))
        spent = self.budget <= 0 or self.evaluations.exhausted
        note = "search budget exhausted" if spent and best_fail[1] else ""
        yield PlanningError(
            j,
            best_fail[1] or "search budget exhausted",
            "; ".join(filter(None, (best_fail[2], note, why))),
        )

    def _candidates(
        self,
        stance: tuple[float, float],
        theta_plus: float,
        depth: int,
        warm_x: float | None,
        need: int,
    ) -> tuple[np.ndarray, np.ndarray, list[int], str]:
        """The footholds a step from ``stance`` starting at ``theta_plus`` tries (see
        :meth:`FootholdChains.ranked`), ranked towards the gait's phase range."""
        return self.chains.ranked(
            self.tmap,
            stance,
            self._theta_target(theta_plus),
            self.gait.step.theta_plus - self._shift_angle(),  # the swing leg's, at touchdown
            depth,
            warm_x,
            need,
        )

    def fixed_step(
        self,
        j: int,
        start: tuple,
        stance: tuple[float, float],
        foothold: tuple[float, float],
        q1m: float,
        q2m: float,
    ) -> FixedStep:
        """Step ``j`` of the plan from ``start`` (``(theta_plus, a0, slope, theta_dot_plus)``)
        on ``stance`` to ``foothold`` [m], touching down at ``(q1m, q2m)`` [rad]: its end speed
        aimed at (:meth:`_end_speed`) and, for the first step, the floor of
        :attr:`PlannerConfig.speed_reserve`."""
        th_p, a0, slope, thd = start
        floor = min(self.config.speed_reserve, thd) if j == 0 and math.isfinite(thd) else 0.0
        end = self._end_speed(foothold, q1m)
        return FixedStep(th_p, a0, slope, thd, stance, foothold, q2m, q1m, end, floor)

    def _end_speed(self, foothold: tuple[float, float], q1m: float) -> float:
        """End-of-step ``theta_dot`` to aim at: the gait's, corrected by the potential energy the
        next step will gain or lose (slow down before a drop, speed up before a rise)."""
        gait, cfg = self.gait, self.config
        m22 = model.mass_matrix(self.P, q1m)[2]
        if cfg.energy_horizon > 0:
            rise = 2.0 * model.weight(self.P) / m22  # theta_dot^2 a metre of rise costs
            f = _energy_target(gait, self.tmap, foothold, cfg.step_length, cfg.energy_horizon, rise)
        else:
            dh = float(self.tmap.height(foothold[0] + cfg.step_length)) - foothold[1]
            f = gait.step.thetadot_minus**2 + 2.0 * model.weight(self.P) * dh / m22
        return math.sqrt(max(f, (1.5 * cfg.min_thetadot) ** 2, cfg.end_thetadot_floor**2))

    def _theta_target(self, theta_plus: float) -> float:
        """Preferred touchdown ``q2`` for a step starting at ``theta_plus``: the gait's, moved by
        half the start's deviation (keeps the phase range near the gait's; the deviation of
        ``theta_plus`` halves from step to step on flat ground), and turned by
        ``foothold_shift`` (a step ``2 l sin q2`` long at full leg length)."""
        st = self.gait.step
        return st.theta_minus + 0.5 * (theta_plus - st.theta_plus) + self._shift_angle()

    def _shift_angle(self) -> float:
        """The touchdown angle ``foothold_shift`` turns the preferred foothold by [rad]."""
        st = self.gait.step
        return self.config.foothold_shift / (2.0 * self.params.l * math.cos(st.theta_minus))

    def _next_template(self, fh, q1m, q2m) -> tuple[FixedStep, np.ndarray] | None:
        """The step after a step ending on ``fh`` (its start speed left open), or None."""
        cfg, l = self.config, self.params.l  # noqa: E741
        th_p2 = q2m - q1m
        cx, cy, _, _ = self._candidates(fh, th_p2, 1, None, 1)
        if cx.size == 0:
            return None
        fh2 = (float(cx[0]), float(cy[0]))
        q1n, q2n = touchdown_configuration(fh2[0] - fh[0], fh2[1] - fh[1], l)
        if not q2n > th_p2 + MIN_PHASE_SPAN:
            return None
        end = self._end_speed(fh2, q1n)
        fx2 = FixedStep(th_p2, -q1m, math.nan, math.nan, fh, fh2, q2n, q1n, end)
        return fx2, shape_guess(self.model.ref.shape, -q1m, q1n, cfg.order)

    def _problem_key(self, fx: FixedStep, fx2: FixedStep | None) -> tuple:
        """Everything a step problem (or a pair) depends on besides the planner itself."""

        def data(f: FixedStep) -> tuple:
            v = (f.theta_plus, f.a0, f.slope, f.thetadot_plus, *f.stance, *f.foothold)
            return tuple(
                round(float(x), 10) if math.isfinite(x) else None
                for x in (*v, f.thetadot_minus_ref, f.thetadot_floor)
            )

        return (
            self.tmap.key,
            self.model.wscale,
            data(fx),
            None if fx2 is None else data(fx2),
        )

    def _solve_pair(self, fx, x0, fx2, x02, keep: bool = False) -> tuple[dict, bool]:
        """SLSQP on the free coefficients of a step and the next one together; returns the
        first step's evaluation and whether both steps are feasible (``keep``: see
        :meth:`_solve`)."""
        sm, memo = self.model, self.solutions
        n = x0.size

        def batch(X):
            e1 = sm.evaluate_batch(fx, X[:, :n])
            thd2 = e1["delta"] * e1["thetadot_minus"]
            e2 = sm.evaluate_batch(fx2, X[:, n:], slope=e1["slope_plus"], thetadot_plus=thd2)
            e1["next_residuals"] = e2["residuals"]  # the pair's cost terms: both steps'
            return e1["cost"] + e2["cost"], np.concatenate([e1["g"], e2["g"]], axis=1), e1

        def residuals(ev):
            return np.concatenate([ev["residuals"], ev["next_residuals"]], axis=1)

        prob = BatchProblem(
            batch,
            self.evaluations,
            residuals,
            *sm.solve_functions(fx, fx2),
            sm.kernel_args(fx, fx2) if self.config.compiled_sqp else None,
        )
        key = self._problem_key(fx, fx2)
        if key in memo.failed:
            return memo.failed[key], False
        x = self._reuse(prob, key, np.concatenate([x0, x02]), keep)
        if x is not None:
            _, _, e1, r = prob.details(x)
            return batch_row(e1, r), True
        self.fresh = True
        x = prob.minimize(
            np.concatenate([x0, x02]),
            self.config.max_iter,
            _FTOL,
            self.struggling,
            bool(self.config.gauss_newton_scaling),
        )
        _, g, e1, r = prob.details(x)
        ok = bool(np.min(g) >= -1e-7)
        if ok:
            memo.solved[key] = x
            memo.hints[_hint_key(fx2.stance, fx2.foothold)] = x[n:]
        else:
            memo.failed[key] = batch_row(e1, r)
            self.struggling = self.may_stall
        return batch_row(e1, r), ok

    def _reuse(self, prob: BatchProblem, key: tuple, x0: np.ndarray, keep: bool):
        """A solution that needs no optimisation, or None: the solution of the same problem
        solved before (if still feasible), and with ``keep`` the warm start ``x0`` if it is
        feasible (remembered as the problem's solution)."""
        solved = self.solutions.solved
        if key in solved:
            x = solved[key]
            if np.min(prob.get(x)[1]) >= -1e-7:
                return x
        if keep and np.min(prob.get(x0)[1]) >= -1e-7:
            solved[key] = np.array(x0, dtype=np.float64)
            return x0
        return None

    def _solve(self, fx: FixedStep, x0: np.ndarray, keep: bool = False) -> tuple[dict, bool]:
        """SLSQP on the free coefficients from ``x0``; from the best point of a coarse global
        search if that fails. A problem solved before is not optimised again; with ``keep`` (a
        look-ahead step, re-optimised when it becomes the first step from a state off the plan)
        neither is one whose warm start is already feasible."""
        sm, memo = self.model, self.solutions

        def batch(X):
            ev = sm.evaluate_batch(fx, X)
            return ev["cost"], ev["g"], ev

        prob = BatchProblem(
            batch,
            self.evaluations,
            lambda ev: ev["residuals"],
            *sm.solve_functions(fx),
            sm.kernel_args(fx) if self.config.compiled_sqp else None,
        )

        def run(xs):
            x = prob.minimize(
                xs,
                self.config.max_iter,
                _FTOL,
                self.struggling,
                bool(self.config.gauss_newton_scaling),
            )
            _, g, ev, r = prob.details(x)
            return batch_row(ev, r), bool(np.min(g) >= -1e-7)

        key = self._problem_key(fx, None)
        if key in memo.failed:
            return memo.failed[key], False
        x = self._reuse(prob, key, x0, keep)
        if x is not None:
            _, _, evm, r = prob.details(x)
            return batch_row(evm, r), True
        self.fresh = True
        ev, ok = run(x0)
        if ok:
            memo.solved[key] = ev["a"][2:-1].copy()
            return ev, True
        chord = fx.a_last - fx.a0
        base = chord_coefficients(
            fx.a0, fx.a_last, np.arange(2, self.config.order), self.config.order
        )
        samples = _global_samples(self.config.order)
        scores = [
            (-float(violation(g)), -c) for c, g, _, _ in prob.evaluate_many(base + chord * samples)
        ]
        best = max(range(len(samples)), key=lambda i: scores[i])
        ev2, ok2 = run(base + chord * samples[best])
        if ok2:
            memo.solved[key] = ev2["a"][2:-1].copy()
        if ok2 or violation(ev2["g"]) < violation(ev["g"]):
            ev = ev2
        if not ok2:
            memo.failed[key] = ev
            self.struggling = self.may_stall
        return ev, ok2


def _energy_target(
    gait: PeriodicGait,
    tmap: TerrainMap,
    foothold: tuple[float, float],
    step_length: float,
    steps: int,
    rise: float,
) -> float:
    """End-of-step ``theta_dot^2`` [rad^2/s^2] that reaches the gait's end speed ``steps``
    steps after a step ending on ``foothold``, over footholds ``step_length`` apart: backward
    through the closed-form map of the gait's step (``theta_dot-^2 = psi delta^2
    theta_dot-^2 + Gam`` of the reduced dynamics, the impact's loss included), each step's rise
    costing ``rise`` per metre."""
    st = gait.step
    a = float(st.psi_grid[-1]) * st.delta**2  # end speed^2 -> next end speed^2, on the flat
    gam = float(st.gam_grid[-1])
    h = [foothold[1]] + [
        float(tmap.height(foothold[0] + k * step_length)) for k in range(1, steps + 1)
    ]
    f = st.thetadot_minus**2
    for k in range(steps, 0, -1):
        f = (f - gam + rise * (h[k] - h[k - 1])) / a
    return f


def _hint_key(stance: tuple[float, float], foothold: tuple[float, float]) -> tuple:
    return (round(stance[0], 6), round(foothold[0], 6))


def _global_samples(order: int) -> np.ndarray:
    """Free coefficients relative to the chord ``a_0 -> a_M`` for the coarse global search."""
    if order == 4:
        r = np.linspace(-1.0, 2.5, 9)
        return np.stack(np.meshgrid(r, r, indexing="ij"), -1).reshape(-1, 2)
    from scipy.stats import qmc  # deferred: scipy.stats is slow to import, rarely needed

    return -1.0 + 3.5 * qmc.Sobol(order - 2, seed=0).random(64)
