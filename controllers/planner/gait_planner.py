"""The gait planner's entry point: :class:`GaitPlanner` (periodic gait and step-by-step plans)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import asdict
from typing import Any, ClassVar

import numpy as np

from envs.config_util import finite_pair, integer_setting
from envs.physics.params import RobotParams, as_params
from envs.physics.terrain import Terrain

from ..numerics import one_blas_thread
from .config import PlannerConfig, PlanningError
from .footholds import FootholdChains, TerrainMap, polyline_key
from .least_violation import least_violation_steps
from .periodic import GaitCache, solve_periodic_gait
from .plan import PeriodicGait, Plan
from .search import StepSearch, StepSolutions

__all__ = ["GaitPlanner"]

_UNBOUNDED = 2**62  # evaluations of a search without a budget
_SOLUTIONS_LIMIT = 4096  # solved step problems kept while replanning before they are forgotten
_MAPS_KEPT = 4  # terrain maps a planner keeps (see GaitPlanner._terrain_map)


class GaitPlanner:
    """Plans footholds and Bezier constraints step by step over the terrain ahead.

    Args:
        params: robot parameters (or a preset name).
        config: :class:`PlannerConfig`, a dict of overrides of the robot's defaults, or None for
            the robot's defaults (``configs/planner/<preset>.yaml``).

    Attributes:
        params: the robot's :class:`RobotParams`; P: its parameter vector.
        config: the :class:`PlannerConfig` (fixed after construction).
        gait_cache: periodic gaits computed by any planner (shared by all of them: a gait
            depends on its key only).
    """

    gait_cache: ClassVar[GaitCache] = GaitCache(limit=64)

    def __init__(
        self, params: RobotParams | str, config: PlannerConfig | dict[str, Any] | None = None
    ):
        self.params = as_params(params)
        if not self.params.retract < 0.5:
            raise ValueError(
                f"RobotParams.retract = {self.params.retract}; the planner allows [0, 0.5) "
                "(fraction of l)"
            )
        if config is None:
            config = PlannerConfig.for_robot(self.params.name)
        elif isinstance(config, dict):
            config = PlannerConfig.for_robot(self.params.name, **config)
        elif not isinstance(config, PlannerConfig):
            raise ValueError(f"config must be a PlannerConfig, a dict or None, got {config!r}")
        self.config = config
        self.P = self.params.vector()
        self._flat = TerrainMap("flat")
        # step problems solved during the current walk, and foothold chains (per terrain)
        self._solutions = StepSolutions()
        self._chains = FootholdChains(
            config.rules(), self.params.l, config.candidate_spacing, config.relaxed_rules()
        )
        self._gait_source: GaitPlanner = self  # the planner whose periodic gait steps pull to
        self._gait_key: tuple | None = None  # the robot and settings in the gait cache's key
        self._maps: dict[bytes, TerrainMap] = {}  # see _terrain_map

    def _terrain_map(self, terrain: Any) -> TerrainMap:
        """:meth:`TerrainMap.coerce`, the maps of the last few terrains kept: a controller
        passes its map at every footstep, and a :class:`Terrain` is its polyline alone."""
        if not isinstance(terrain, Terrain):
            return TerrainMap.coerce(terrain)
        key = polyline_key(terrain.xs, terrain.ys)
        tmap = self._maps.get(key)
        if tmap is None:
            if len(self._maps) >= _MAPS_KEPT:
                self._maps.clear()
            tmap = self._maps[key] = TerrainMap(terrain)
        return tmap

    def relaxed(self, **changes: Any) -> GaitPlanner:
        """A planner with the settings ``changes`` (fields of :class:`PlannerConfig`, e.g. a
        larger ``torque_fraction``) whose steps still pull towards this planner's periodic gait
        (the relaxation changes what is feasible, not the gait aimed at).

        Raises:
            ValueError: an unknown setting or a value out of its range.
        """
        bad = sorted(set(changes) - {f.name for f in dataclasses.fields(PlannerConfig)})
        if bad:
            raise ValueError(f"relaxed planner: unknown PlannerConfig field(s) {bad}")
        out = GaitPlanner(self.params, dataclasses.replace(self.config, **changes))
        out._gait_source = self._gait_source
        return out

    @one_blas_thread
    def periodic_gait(
        self, step_length: float | None = None, speed: float | None = None
    ) -> PeriodicGait:
        """Periodic gait on flat ground with step length ``step_length`` [m] and a speed [m/s] as
        close to ``speed`` as the constraints allow (defaults: the configuration's).

        Raises:
            PlanningError: no feasible periodic gait.
            ValueError: step length or speed out of range.
        """
        if self._gait_source is not self:
            return self._gait_source.periodic_gait(step_length, speed)
        cfg = self.config
        L = cfg.step_length if step_length is None else float(step_length)
        vt = cfg.target_speed if speed is None else float(speed)
        if not (math.isfinite(L) and 0 < L < 2 * self.params.l):
            raise ValueError(f"step_length = {L!r}; allowed: (0, 2 l) = (0, {2 * self.params.l})")
        if not (math.isfinite(vt) and vt > 0):
            raise ValueError(f"speed = {vt!r}; allowed: > 0 m/s")
        if self._gait_key is None:  # the robot and settings are fixed after construction
            self._gait_key = (tuple(self.P), tuple(sorted(asdict(cfg).items())))
        key = (*self._gait_key, L, vt)
        gait = self.gait_cache.get(key)
        if gait is None:
            gait = solve_periodic_gait(self.params, cfg, self._flat, L, vt)
            self.gait_cache.put(key, gait)
        return gait

    @one_blas_thread
    def plan(
        self,
        terrain: Any,
        state: tuple[np.ndarray, np.ndarray],
        stance_foot: tuple[float, float],
        horizon: int | None = None,
        previous_plan: Plan | None = None,
        max_evaluations: int | None = None,
        max_beam_evaluations: int | None = None,
    ) -> Plan:
        """Plan ``horizon`` steps from the post-impact ``state``.

        Args:
            terrain: a :class:`envs.physics.Terrain`, a spec, a :class:`TerrainMap`, or a scan
                ``(xs, heights)`` [m].
            state: actual post-impact ``(q, qd)`` [rad, rad/s] (``q2d > 0``).
            stance_foot: stance-foot position ``(x, y)`` [m].
            horizon: number of steps, an integer >= 1 (default ``config.horizon``).
            previous_plan: the plan made at the previous footstep (warm start). Step problems
                this planner already solved since the last call without a previous plan (same
                terrain, start state, footholds and weights, to 1e-10) are reused after one
                feasibility check instead of being optimised again; with ``None`` the planner
                forgets them, so a call without a previous plan depends on its arguments only.
            max_evaluations: step evaluations this call may spend, an integer >= 1 (default:
                ``config.max_evaluations`` when replanning, i.e. with a ``previous_plan``; a
                plan from scratch runs its whole search).
            max_beam_evaluations: step evaluations the beam search over the horizon may spend
                in this call, an integer >= 0 (0: no beam search; default and at most:
                ``config.beam_evaluations``).

        Raises:
            PlanningError: no feasible step (names the step and the violated constraint; its
                ``partial`` holds the feasible steps found before it).
            ValueError: a malformed or non-finite state or stance foot, a horizon that is not
                an integer >= 1, a budget out of its range.
        """
        t0 = time.perf_counter()
        search, start, stance = self._search(
            terrain, state, stance_foot, horizon, previous_plan, max_evaluations,
            max_beam_evaluations,
        )  # fmt: skip
        plan = Plan(search.run(start, stance), self.params, self.config)
        plan.evaluations = search.evaluations.used
        plan.beam_evaluations = search.beam_evaluations
        plan.beam = search.beam
        plan.solve_time = time.perf_counter() - t0
        return plan

    @one_blas_thread
    def plan_least_violation(
        self,
        terrain: Any,
        state: tuple[np.ndarray, np.ndarray],
        stance_foot: tuple[float, float],
        horizon: int = 2,
        previous_plan: Plan | None = None,
        max_evaluations: int | None = None,
    ) -> Plan:
        """The least-violating steps from the post-impact ``state`` (the last resort when no
        feasible plan exists; see :mod:`controllers.planner.least_violation`): up to
        ``horizon`` steps, each with its worst violation in ``Plan.violations``; the plan may
        have fewer steps than asked, or none.

        Args:
            terrain: the terrain, as for :meth:`plan`.
            state: actual post-impact ``(q, qd)`` [rad, rad/s].
            stance_foot: stance-foot position ``(x, y)`` [m].
            horizon: number of steps, an integer >= 1.
            previous_plan: as for :meth:`plan` (``None`` forgets the solved step problems).
            max_evaluations: step evaluations this call may spend, an integer >= 1 (default:
                no bound; the search is bounded by construction, ``horizon x candidates`` step
                problems of a coarse global search and 40 least-squares evaluations each).

        Raises:
            PlanningError: ``theta_dot`` not positive after the impact (nothing to track).
            ValueError: as for :meth:`plan`.
        """
        t0 = time.perf_counter()
        bound = _UNBOUNDED if max_evaluations is None else max_evaluations
        search, start, stance = self._search(
            terrain, state, stance_foot, horizon, previous_plan, bound
        )
        steps, worst = least_violation_steps(search, start, stance)
        plan = Plan(steps, self.params, self.config)
        plan.violations = worst
        plan.evaluations = search.evaluations.used
        plan.solve_time = time.perf_counter() - t0
        return plan

    def _search(
        self,
        terrain,
        state,
        stance_foot,
        horizon,
        previous_plan,
        max_evaluations,
        max_beam_evaluations=None,
    ):
        """The checked arguments of a planning call as ``(StepSearch, start, stance)``."""
        cfg = self.config
        budget = beam_budget = None
        if max_evaluations is not None:
            budget = integer_setting("max_evaluations", max_evaluations, 1)
        if max_beam_evaluations is not None:
            beam_budget = integer_setting("max_beam_evaluations", max_beam_evaluations, 0)
        H = cfg.horizon if horizon is None else integer_setting("horizon", horizon, 1)
        try:
            q = np.asarray(state[0], dtype=float).reshape(-1)
            qd = np.asarray(state[1], dtype=float).reshape(-1)
        except (TypeError, ValueError, IndexError, KeyError):
            q = qd = np.zeros(0)
        if q.shape != (2,) or qd.shape != (2,) or not np.all(np.isfinite(np.r_[q, qd])):
            raise ValueError(f"state must be finite (q, qd) pairs, got {state!r}")
        stance = finite_pair("stance_foot", stance_foot, "m")
        if not qd[1] > 0:
            raise PlanningError(0, "post-impact theta_dot positive", f"q2d = {qd[1]:.4g} rad/s")
        tmap = self._terrain_map(terrain)
        # a call without a previous plan starts afresh (its result depends on its inputs only)
        if previous_plan is None or len(self._solutions) > _SOLUTIONS_LIMIT:
            self._solutions.clear()
        gait = self.periodic_gait()
        search = StepSearch(
            self.params,
            cfg,
            tmap,
            gait,
            self._solutions,
            self._chains,
            H,
            previous_plan,
            budget,
            beam_budget,
        )
        start = (float(q[1]), float(q[0]), float(qd[0] / qd[1]), float(qd[1]))
        return search, start, stance
