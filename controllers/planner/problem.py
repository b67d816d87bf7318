"""The step problem: one step's constraints and cost as functions of its free Bezier coefficients,
and the adaptor that hands a batched step problem to SLSQP.

For every step the Bezier coefficients ``a_0``, ``a_1`` and ``a_M`` follow from the step's start
and foothold (:class:`FixedStep`); ``a_2 .. a_{M-1}`` are free. :class:`StepEvaluator` evaluates
the step for a batch of free-coefficient vectors in one compiled call
(:func:`controllers.planner.kernel.evaluate_steps`): feasibility (``theta_dot^2`` bounded away
from zero, swing-foot clearance under the retractable-foot rule, transversal touchdown, step
duration and hip input within bounds, stance foot loaded and not slipping, impact impulse inside
the friction cone, trailing foot taking off) and a cost that regulates the walking speed
towards a target and pulls the step towards the periodic gait (:class:`GaitReference`).

The constraints are checked on each step's Chebyshev grid (dynamics: input, reaction) and on a
uniform grid (geometry, ``theta_dot^2``); between the nodes of the first the nominal input can
exceed the bound by a few percent. :data:`CONSTRAINT_GROUPS` is the one table of the constraint
groups: their order, names, sizes and how a violation is reported; the columns the kernel
writes and the names the planner reports both derive from it.

:class:`BatchProblem` gives SLSQP forward-difference Jacobians whose perturbed points are
evaluated in one batched call.
"""

from __future__ import annotations

import functools
import math
import time
from collections import namedtuple
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from envs.physics import model
from envs.physics.params import RobotParams

from .. import reduced as rd
from ..bezier import bernstein_basis, chord_coefficients
from . import kernel
from .config import PlannerConfig
from .footholds import TerrainMap
from .kernel import StepGrids, StepGround, StepScalars, StepSettings
from .plan import PeriodicGait
from .slsqp import minimize_slsqp
from .sqp import NO_START, NO_START_G, fd_points, fd_quotients, sqp_solve

__all__ = [
    "CONSTRAINT_GROUPS",
    "MIN_PHASE_SPAN",
    "BatchProblem",
    "BudgetExhausted",
    "ConstraintGroup",
    "ConstraintGroups",
    "ConstraintLayout",
    "FixedStep",
    "GaitReference",
    "GroupColumns",
    "SearchBudget",
    "StepEvaluator",
    "batch_row",
    "constraint_layout",
    "gait_reference",
    "shape_guess",
    "violation",
    "worst_violation",
]

_PACK_BLOCK = 8  # long constraint groups reach SLSQP as minima over blocks of grid points
# an SLSQP run still infeasible after _STALL_ITERATIONS iterations (violation, the sum of the
# negative constraints, above _STALL_VIOLATION) stops once its last _STALL_WINDOW iterations
# brought the violation below _STALL_GAIN times its earlier best no more
_STALL_ITERATIONS, _STALL_WINDOW, _STALL_GAIN, _STALL_VIOLATION = 25, 5, 0.95, 1e-4
_PROBLEMS_KEPT = 16  # step problems whose kernel data a StepEvaluator keeps
# the scaled solves' eigenvalue floor, relative to the largest: only a guard against a
# singular model (the eigenvalues of the paper robot's step models span a factor of about 40)
_SCALING_FLOOR = 1e-6
#: least phase range ``theta- - theta+`` of a step to a candidate foothold [rad]; footholds
#: closer are not tried
MIN_PHASE_SPAN = 0.05


# ---------------------------------------------------------------------------- constraint groups
class ConstraintGroup(NamedTuple):
    """One group of constraints of the step problem.

    Attributes:
        name: the group's name (its field in :data:`GroupColumns`).
        violation: the constraint a violated group reports (:class:`PlanningError`).
        size: entries of the group from ``(N, K + 1, F)``: Chebyshev nodes, points of the
            uniform check grid, vertical faces between the stance foot and the foothold.
        periodic_only: the group exists for the periodic gait only (last in the table).
    """

    name: str
    violation: str
    size: Callable[[int, int, int], int]
    periodic_only: bool = False


CONSTRAINT_GROUPS: tuple[ConstraintGroup, ...] = (
    # both grids
    ConstraintGroup("thetadot_sq", "theta_dot^2 bounded away from zero", lambda n, k, f: n + k),
    # the reduced inertia keeps its sign
    ConstraintGroup("alpha", "alpha bounded away from zero", lambda n, k, f: n),
    ConstraintGroup("torque", "hip input within the actuator limit", lambda n, k, f: n),
    # swing foot above the terrain between the check points
    ConstraintGroup("clearance", "swing-foot clearance", lambda n, k, f: k - 1),
    # normal force, then friction cone
    ConstraintGroup(
        "stance_reaction", "stance foot loaded and not slipping", lambda n, k, f: 2 * n
    ),
    # armed before touchdown, clear when armed
    ConstraintGroup(
        "armed", "swing foot reaches the arming distance above ground", lambda n, k, f: 2
    ),
    ConstraintGroup("faces", "vertical faces cleared", lambda n, k, f: 1 + f),
    ConstraintGroup("touchdown", "transversal touchdown", lambda n, k, f: 1),
    ConstraintGroup("duration", "step duration bounds", lambda n, k, f: 2),
    # impulse into the ground, then in the cone
    ConstraintGroup("impact", "impact impulse in the friction cone", lambda n, k, f: 2),
    ConstraintGroup("trailing_foot", "trailing foot takes off", lambda n, k, f: 1),
    ConstraintGroup("post_impact_speed", "post-impact theta_dot positive", lambda n, k, f: 1),
    # stable, real fixed point of the step-to-step map
    ConstraintGroup(
        "periodic", "periodic orbit exists and is stable", lambda n, k, f: 2, periodic_only=True
    ),
)

# first column of each constraint group, by name (the record the kernel reads)
GroupColumns = namedtuple("GroupColumns", [g.name for g in CONSTRAINT_GROUPS])


class ConstraintLayout(NamedTuple):
    """Where the constraint groups of one step problem lie.

    Attributes:
        offsets: first column of each group present, then the number of columns (int64).
        columns: :data:`GroupColumns`, first column by group name (an absent group: the end).
        packed: length of the constraint vector SLSQP gets (:func:`kernel.pack`).
    """

    offsets: np.ndarray
    columns: tuple
    packed: int


@functools.lru_cache(maxsize=64)
def constraint_layout(nodes: int, checks: int, faces: int, periodic: bool) -> ConstraintLayout:
    """The layout of :data:`CONSTRAINT_GROUPS` for ``nodes = N`` Chebyshev nodes, ``checks = K +
    1`` check points and ``faces`` vertical faces (``periodic``: with the periodic-gait group)."""
    groups = [g for g in CONSTRAINT_GROUPS if periodic or not g.periodic_only]
    sizes = [g.size(nodes, checks, faces) for g in groups]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    first = dict(zip([g.name for g in groups], offsets.tolist()))
    end = int(offsets[-1])
    columns = GroupColumns(*(first.get(g.name, end) for g in CONSTRAINT_GROUPS))
    return ConstraintLayout(offsets, columns, kernel.packed_size(sizes, _PACK_BLOCK))


class ConstraintGroups:
    """The constraint groups of a batched evaluation: column blocks of ``G``, sliced on use."""

    def __init__(self, G: np.ndarray, offsets: np.ndarray):
        self.G, self.offsets = G, offsets

    def __len__(self) -> int:
        return self.offsets.size - 1

    def __getitem__(self, i: int) -> np.ndarray:
        return self.G[:, self.offsets[i] : self.offsets[i + 1]]

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def violation(g: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    """The total constraint violation of constraint values ``g``: the sum of the negative
    values' magnitudes (0 when feasible; ``inf`` where the sum overflows, a point far outside
    the constraints, rather than a warning), over ``axis`` (None: all)."""
    with np.errstate(over="ignore"):
        return -np.sum(np.minimum(g, 0.0), axis=axis)


def worst_violation(groups: list[np.ndarray]) -> tuple[float, str]:
    """The most negative constraint of one evaluation's groups and its group's
    :attr:`ConstraintGroup.violation` (``(0.0, "")`` when none is violated)."""
    worst, name = 0.0, ""
    for g, group in zip(groups, CONSTRAINT_GROUPS):
        m = float(np.min(g)) if np.size(g) else 0.0
        if not math.isfinite(m):
            m = -math.inf
        if m < worst:
            worst, name = m, group.violation
    return worst, name


# ---------------------------------------------------------------------------- step model
@dataclass
class FixedStep:
    """Data of one step that the optimiser does not change (rad, rad/s, m)."""

    theta_plus: float
    a0: float
    slope: float  # phi'(theta_plus)
    thetadot_plus: float
    stance: tuple[float, float]
    foothold: tuple[float, float]
    theta_minus: float
    a_last: float
    thetadot_minus_ref: float = math.nan  # end-of-step speed aimed at (nan: the gait's)
    thetadot_floor: float = 0.0  # least theta_dot beyond the planner's min_thetadot


class GaitReference(NamedTuple):
    """What the step costs pull towards: the periodic gait's end-of-step ``theta_dot`` [rad/s],
    post-impact slope, normalised shape (coefficients relative to the chord ``a_0 -> a_M``),
    speed [m/s] and impact gain."""

    thetadot_minus: float
    slope_plus: float
    shape: np.ndarray
    speed: float
    delta: float


def gait_reference(gait: PeriodicGait) -> GaitReference:
    """The :class:`GaitReference` of a periodic gait."""
    a = gait.step.coeffs
    base = chord_coefficients(a[0], a[-1], np.arange(a.size), a.size - 1)
    rel = (a - base) / (a[-1] - a[0])
    return GaitReference(
        gait.step.thetadot_minus, gait.step.slope_plus, rel, gait.speed, gait.step.delta
    )


@functools.lru_cache(maxsize=32)
def _step_tables(params: RobotParams, config: PlannerConfig) -> tuple[StepGrids, StepSettings]:
    """The grids and settings of a :class:`StepEvaluator`: fixed by the robot and the planner
    settings, built once for each (planning calls make an evaluator each; the kernels only read
    them)."""
    P = params.vector()
    n, m = config.grid, config.order
    s = rd.step_fractions(n)
    B = [bernstein_basis(m, s, d) for d in range(3)]
    l = params.l  # noqa: E741
    alpha_scale = model.mass_matrix(P, 0.0)[2]
    u_lim = config.torque_fraction * params.u_max
    # uniform grid for the geometric checks (swing-foot clearance, faces, theta_dot^2)
    sg = np.linspace(0.0, 1.0, config.check_points + 1)
    Bg = bernstein_basis(m, sg, 0)
    interp = np.polynomial.chebyshev.chebvander(2.0 * sg - 1.0, n) @ np.linalg.inv(
        np.polynomial.chebyshev.chebvander(rd.cheb_nodes(n), n)
    )
    ramp = np.minimum(1.0, (1.0 - sg) / config.clearance_ramp)
    clear_req = config.clearance * ramp
    qint = np.ascontiguousarray(rd.cumulative_integral_matrix(n))
    grids = StepGrids(s, B[0], B[1], B[2], sg, Bg, qint, interp, clear_req)
    settings = StepSettings(
        min_thetadot=config.min_thetadot,
        dip_floor=config.dip_floor,
        alpha_scale=alpha_scale,
        u_lim=u_lim,
        u_max=params.u_max,
        retract=params.retract * l,
        arm=params.arm_distance * l,
        arm_clearance=config.arm_clearance,
        clearance=config.clearance,
        clearance_ramp=config.clearance_ramp,
        retracted_clearance=config.retracted_clearance,
        face_clearance=config.face_clearance,
        touchdown_slope=config.touchdown_slope,
        friction=config.friction,
        duration_min=config.duration_min,
        duration_max=config.duration_max,
        weight=model.weight(P),
        mass=params.total_mass,
        w_speed=config.w_speed,
        w_torque=config.w_torque,
        w_end=config.w_end,
        w_slope=config.w_slope,
        w_shape=config.w_shape,
    )
    return grids, StepSettings(*(float(v) for v in settings))


class StepEvaluator:
    """Vectorised evaluation of one step's constraints and cost for the free coefficients.

    Args:
        params: robot parameters.
        config: planner settings.
        tmap: the terrain.

    Attributes:
        ref: the :class:`GaitReference` the cost pulls towards; None for the periodic gait itself
            (whose cost is the speed error and the mean squared input).
        wscale: scale of the weights that pull a step towards the reference.
    """

    def __init__(self, params: RobotParams, config: PlannerConfig, tmap: TerrainMap):
        self.params, self.cfg, self.tmap = params, config, tmap
        self.P = params.vector()
        self.l = params.l
        self.grids, self.settings = _step_tables(params, config)
        self.ref: GaitReference | None = None
        self.wscale = 1.0
        self._face_cache: dict[tuple, tuple[StepGround, float, float]] = {}
        self._layouts: dict[tuple, ConstraintLayout] = {}
        self._problems: dict[tuple, tuple] = {}  # see _problem_data

    def evaluate(self, fx: FixedStep, free: np.ndarray, periodic: bool = False) -> dict[str, Any]:
        """Everything about the step with free coefficients ``free`` (shape ``(k,)``).

        With ``periodic``, ``a_1`` and ``thetadot_plus`` are those of a period-one gait (the
        step's end maps onto its start); ``fx.slope`` and ``fx.thetadot_plus`` are ignored.
        """
        return batch_row(
            self.evaluate_batch(fx, np.asarray(free, dtype=np.float64)[None, :], periodic), 0
        )

    def evaluate_batch(
        self,
        fx: FixedStep,
        free: np.ndarray,
        periodic: bool = False,
        slope: np.ndarray | None = None,
        thetadot_plus: np.ndarray | None = None,
        screen: float = -math.inf,
    ) -> dict[str, Any]:
        """:meth:`evaluate` for a batch of free-coefficient vectors ``free`` (shape ``(B, k)``);
        every entry of the result has a leading axis of length ``B`` (``groups``: a list of
        ``(B, n_i)`` arrays; ``g``: the packed constraint vectors). ``slope`` and
        ``thetadot_plus`` (shape ``(B,)``) override ``fx.slope`` and ``fx.thetadot_plus`` row by
        row (the start of a step that follows a step being optimised).

        ``screen``: for a caller that wants only the feasible rows (every constraint ``>=
        screen``): a row whose dynamics already break a constraint below ``screen`` is not
        evaluated further (:func:`kernel.evaluate_steps`); its constraints not reached are NaN
        (``g``: ``-1e3``) and its scalar outputs NaN. The feasible rows are the same, to the
        last bit, as without it."""
        with np.errstate(all="ignore"):
            return self._evaluate(
                fx, np.asarray(free, dtype=np.float64), periodic, slope, thetadot_plus, screen
            )

    def step_values(self, fx: FixedStep, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The costs ``(B,)`` and packed constraints ``(B, m)`` of :meth:`evaluate_batch` (a
        step, not the periodic gait) for the free coefficients ``free`` (``(B, k)``), in one
        compiled call: the same numbers, nothing else."""
        return self.solve_functions(fx)[0](self._free(free))

    def step_residuals(
        self, fx: FixedStep, free: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step_values` and the cost's terms ``(B, R)`` (``evaluate_batch``'s
        ``"residuals"``), in one compiled call: the same numbers."""
        return self.solve_functions(fx)[1](self._free(free))

    def pair_residuals(
        self, fx: FixedStep, fx2: FixedStep, free: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`pair_values` and the pair's cost terms ``(B, R + R2)``, the first step's then
        the second's, in one compiled call: the same numbers."""
        return self.solve_functions(fx, fx2)[1](self._free(free, 2))

    def pair_values(
        self, fx: FixedStep, fx2: FixedStep, free: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`step_values` of a step and the next one optimised together (``free``: both
        steps' free coefficients, ``(B, 2 k)``): the sum of their costs and their constraints
        side by side, the second step starting where the first ends row by row (the impact's
        ``theta_dot`` and slope; ``fx2``'s start is ignored)."""
        return self.solve_functions(fx, fx2)[0](self._free(free, 2))

    def solve_functions(
        self, fx: FixedStep, fx2: FixedStep | None = None
    ) -> tuple[Callable[[np.ndarray], tuple], Callable[[np.ndarray], tuple]]:
        """The compiled values and residual values of the step ``fx`` (with ``fx2``: the
        pair), :meth:`step_values` and :meth:`step_residuals` (:meth:`pair_values` and
        :meth:`pair_residuals`), with the problem's kernel data looked up once: as
        :class:`BatchProblem` takes them for the points of one solve, which changes neither
        the weights nor the reference. The points must be ``(B, k)`` float64 rows of the right
        width (a solve's are)."""
        P, k, common, first, second, pair = self.kernel_args(fx, fx2)
        if not pair:
            return (
                lambda X: kernel.step_values(P, X, common, first),
                lambda X: kernel.step_residuals(P, X, common, first),
            )
        return (
            lambda X: kernel.pair_values(P, X, k, common, first, second),
            lambda X: kernel.pair_residuals(P, X, k, common, first, second),
        )

    def kernel_args(self, fx: FixedStep, fx2: FixedStep | None = None) -> tuple:
        """The kernel's arguments for the step ``fx`` (with ``fx2``: the pair), as
        :func:`controllers.planner.sqp.sqp_solve` takes them: ``(P, k, common, first, second,
        pair)`` (``k`` free coefficients a step; ``second`` is ``first`` for a step alone)."""
        _, shape_ref, first = self._problem_data(fx, False)
        second = first if fx2 is None else self._problem_data(fx2, False)[2]
        k = self.cfg.order - 2
        return (self.P, k, self._common(shape_ref), first, second, fx2 is not None)

    def _common(self, shape_ref: np.ndarray) -> tuple:
        """What :func:`kernel.evaluate_shapes` takes that every step problem shares."""
        return (self.ref is not None, shape_ref, self.settings, self.grids, _PACK_BLOCK)

    def _free(self, free: np.ndarray, steps: int = 1) -> np.ndarray:
        """``free`` as the kernel takes it, checked against the order: ``(B, steps (M - 2))``."""
        free = np.ascontiguousarray(free, dtype=np.float64)
        k = steps * (self.cfg.order - 2)
        if free.ndim != 2 or free.shape[1] != k:
            raise ValueError(f"free coefficients of shape {free.shape}; allowed: (rows, {k})")
        return free

    def _faces(self, xs: float, x_foot: float) -> tuple[StepGround, float, float]:
        """The ground between the stance foot and the foothold (terrain and the faces crossed),
        and the ground slopes under the stance foot and the foothold."""
        key = (xs, x_foot)
        out = self._face_cache.get(key)
        if out is None:
            faces = self.tmap.faces_between(xs, x_foot)
            arm = self.params.arm_distance * self.l
            ground = StepGround(
                self.tmap.xs,
                self.tmap.ys,
                np.array([f[0] for f in faces], dtype=np.float64),
                np.array([f[1] for f in faces], dtype=np.float64),
                np.array([f[0] - xs >= arm for f in faces], dtype=np.bool_),
            )
            out = (ground, self.tmap.terrain.slope_at(xs), self.tmap.terrain.slope_at(x_foot))
            if len(self._face_cache) > 64:
                self._face_cache.clear()
            self._face_cache[key] = out
        return out

    def _problem_data(self, fx: FixedStep, periodic: bool) -> tuple:
        """What the kernel needs of the step problem besides its shapes: ``(layout,
        shape_ref, problem)``, the same for every batch of one problem (kept for the last few
        problems: an optimisation evaluates the same one, or a pair, many times); ``problem``:
        the step as :func:`kernel.evaluate_shapes` takes it, ``(fixed, scalars, ground,
        columns, offsets, packed)``."""
        key = (id(fx), periodic, self.wscale, id(self.ref))
        hit = self._problems.get(key)
        if hit is not None and hit[0] is fx and hit[1] is self.ref:
            return hit[2]
        cfg, grids = self.cfg, self.grids
        xs, ys = fx.stance
        ground, slope_stance, slope_foot = self._faces(xs, fx.foothold[0])
        n_faces = ground.face_x.size
        layout = self._layouts.get((n_faces, periodic))
        if layout is None:
            layout = self._layouts[n_faces, periodic] = constraint_layout(
                grids.nodes.size, grids.check.size, n_faces, periodic
            )
        floor = cfg.gait_min_thetadot if periodic else fx.thetadot_floor
        fmin = max(cfg.min_thetadot, floor) ** 2
        thm_ref = slope_ref = delta_ref = 0.0
        if self.ref is None:  # periodic gait: speed target and effort
            v_target = cfg.target_speed
            shape_ref = np.zeros(cfg.order + 1)
        else:  # steps: the periodic gait's speed, end speed and shape (zero cost on the gait)
            thm_ref, slope_ref, shape_ref, v_target, delta_ref = self.ref
            if math.isfinite(fx.thetadot_minus_ref):
                thm_ref = fx.thetadot_minus_ref
        scalars = StepScalars(
            fmin=float(fmin),
            xs=float(xs),
            ys=float(ys),
            slope_stance=float(slope_stance),
            slope_foot=float(slope_foot),
            foot_x=float(fx.foothold[0]),
            theta_plus=float(fx.theta_plus),
            span=float(fx.theta_minus - fx.theta_plus),
            wscale=float(self.wscale),
            v_target=float(v_target),
            thetadot_minus_ref=float(thm_ref),
            slope_ref=float(slope_ref),
            delta_ref=float(delta_ref),
        )
        fixed = (fx.a0, fx.a_last, fx.slope, fx.theta_plus, fx.theta_minus, fx.thetadot_plus)
        problem = (
            tuple(float(v) for v in fixed),
            scalars,
            ground,
            layout.columns,
            layout.offsets,
            layout.packed,
        )
        data = (layout, np.ascontiguousarray(shape_ref, dtype=np.float64), problem)
        if len(self._problems) >= _PROBLEMS_KEPT:
            self._problems.clear()
        self._problems[key] = (fx, self.ref, data)
        return data

    def _evaluate(self, fx, free, periodic, slope_in, thd_in, screen) -> dict[str, Any]:
        free = self._free(free)
        layout, shape_ref, problem = self._problem_data(fx, periodic)
        if periodic:  # a_1 gives the step's own post-impact slope (a period-one gait)
            m, span = self.cfg.order, fx.theta_minus - fx.theta_plus
            a_last = np.full(free.shape[0], fx.a_last)
            _, slope_in = rd.impact_along_constraint(
                self.P, a_last, m * (a_last - free[:, -1]) / span
            )
        a, out, g = kernel.evaluate_shapes(
            self.P,
            free,
            kernel.NO_ROWS
            if slope_in is None
            else np.ascontiguousarray(slope_in, dtype=np.float64),
            kernel.NO_ROWS
            if thd_in is None or periodic
            else np.ascontiguousarray(thd_in, dtype=np.float64),
            periodic,
            self._common(shape_ref),
            problem,
            float(screen),
        )
        return {
            "a": a,
            "f": out.thetadot_sq,
            "T": out.duration,
            "u": out.input,
            "groups": ConstraintGroups(out.constraints, layout.offsets),
            "g": g,
            "cost": out.cost,
            "thetadot_minus": out.thetadot_minus,
            "delta": out.delta,
            "slope_plus": out.slope_plus,
            "speed": out.speed,
            "arm_theta": out.arm_theta,
            "thetadot_plus": out.thetadot_plus,
            "gain": out.gain,
            "residuals": out.residuals,
        }


def shape_guess(rel: np.ndarray, a0: float, a_last: float, order: int) -> np.ndarray:
    """The free coefficients ``a_2 .. a_{M-1}`` of the shape ``rel`` (all coefficients relative
    to the chord, as :attr:`GaitReference.shape`) on a step from ``a_0`` to ``a_M`` [rad]."""
    k = np.arange(order + 1)
    base = chord_coefficients(a0, a_last, k, order)
    return (base + rel * (a_last - a0))[2:-1]


def batch_row(ev: dict[str, Any], r: int) -> dict[str, Any]:
    """Row ``r`` of a batched step evaluation, as :meth:`StepEvaluator.evaluate` returns it."""
    out: dict[str, Any] = {}
    for key, v in ev.items():
        if key == "groups":
            out[key] = [g[r] for g in v]
        elif np.ndim(v) == 1:
            out[key] = float(v[r])
        else:
            out[key] = v[r]
    return out


# ---------------------------------------------------------------------------- search budget
class BudgetExhausted(RuntimeError):
    """A planning call has spent its :class:`SearchBudget`."""


class SearchBudget:
    """What one planning call may spend: step evaluations (rows of the compiled kernel), and
    optionally process time.

    Args:
        evaluations: step evaluations allowed (a batch that starts within the budget is
            evaluated whole), >= 1.
        seconds: process time allowed [s] (``time.process_time``; 0: no time bound). A time
            bound makes the result depend on the machine and its load.

    Attributes:
        used: step evaluations spent so far.
        exhausted: the budget ran out (the search stopped early).
    """

    def __init__(self, evaluations: int, seconds: float = 0.0):
        self.evaluations = int(evaluations)
        self.seconds = float(seconds)
        self.used = 0
        self.exhausted = False
        self._deadline = time.process_time() + seconds if seconds > 0 else math.inf

    def another(self, evaluations: int) -> SearchBudget:
        """A budget of ``evaluations`` more step evaluations, bounded by this budget's deadline
        (one planning call's second search)."""
        out = SearchBudget(evaluations)
        out._deadline = self._deadline
        return out

    def spend(self, n: int) -> None:
        """Account for ``n`` evaluations about to be made.

        Raises:
            BudgetExhausted: the budget was already spent (nothing is accounted).
        """
        if (
            self.exhausted
            or self.used >= self.evaluations
            or (self._deadline < math.inf and time.process_time() > self._deadline)
        ):
            self.exhausted = True
            raise BudgetExhausted(f"search budget exhausted after {self.used} step evaluations")
        self.used += int(n)


# ---------------------------------------------------------------------------- SLSQP adaptor
class BatchProblem:
    """Cost and constraints of a batched evaluator for SLSQP, cached by point.

    ``fn(X)`` evaluates the rows of ``X`` (shape ``(B, k)``) and returns ``(cost, g, ev)``:
    costs ``(B,)``, packed constraints ``(B, m)`` and any batch payload (kept with the row
    index). ``values(X)`` (optional) returns only ``(cost, g)``, the same numbers at less cost:
    then points are evaluated with it, and ``fn`` runs where a point's payload is asked for
    (:meth:`details`). The Jacobians are forward differences whose ``k`` perturbed points are
    evaluated in one batched call (the same derivatives SLSQP would take by itself, at a
    fraction of the cost). With a :class:`SearchBudget` every point evaluated is accounted,
    once; once it is spent, any further evaluation raises :class:`BudgetExhausted` (a payload
    asked for at a point already evaluated is not accounted again). :meth:`minimize` accounts
    each new iterate with its forward-difference points, evaluated with it or when their
    Jacobian is asked for (a trial point of a line search, which SLSQP seldom accepts): the
    budget's accounts, and so the searches, are the same either way. ``residuals(payload)``
    (optional) gives the cost's terms of a batch, ``(B, R)`` with ``cost = sum(r^2)`` row by
    row: the Gauss-Newton model of :meth:`minimize` with ``scaled``. ``residual_values(X)``
    (optional) returns ``(cost, g, R)``, the same numbers without the payload: then the model
    is taken from it.
    """

    def __init__(
        self,
        fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, Any]],
        budget: SearchBudget | None = None,
        residuals: Callable[[Any], np.ndarray] | None = None,
        values: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
        residual_values: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
        | None = None,
        compiled: tuple | None = None,
    ):
        self.compiled = compiled
        self.fn = fn
        self.budget = budget
        self.residuals = residuals
        self.values = values
        self.residual_values = residual_values
        self.cache: dict[bytes, tuple[float, np.ndarray, Any, int]] = {}
        self._jac: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        # forward-difference batches evaluated whole: (points, costs, constraints) by point
        self._points: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # points accounted in the budget but not evaluated yet (forward differences put off)
        self._charged: set[bytes] = set()
        # the last :meth:`scaling`'s point (as bytes) with the costs and constraints there and
        # at its forward-difference points: the compiled solve's first Jacobian
        self._start: tuple = ()

    def _fill(self, X: np.ndarray, payload: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
        """Evaluate the rows of ``X`` not evaluated yet (with ``payload``, also the payload of
        those evaluated without it); ``(cost, g)`` of the batch if every row was new."""
        keys = [x.tobytes() for x in X]
        todo = self._accounted(keys)
        fresh = None
        if todo:
            rows = X[todo] if len(todo) < len(keys) else X
            if self.values is None or payload:
                cost, g, ev = self.fn(rows)
            else:
                (cost, g), ev = self.values(rows), None
            for r, i in enumerate(todo):
                self.cache[keys[i]] = (float(cost[r]), g[r], ev, r)
            if len(todo) == len(keys):
                fresh = cost, g
        if payload:  # points evaluated without their payload: once more, with it
            bare = [i for i, k in enumerate(keys) if self.cache[k][2] is None]
            if bare:
                _, _, ev = self.fn(X[bare])
                for r, i in enumerate(bare):
                    c, g_row, _, _ = self.cache[keys[i]]
                    self.cache[keys[i]] = (c, g_row, ev, r)
        return fresh

    def _accounted(self, keys: list[bytes]) -> list[int]:
        """The positions of the points ``keys`` not evaluated yet, accounted in the budget
        (which raises :class:`BudgetExhausted` once spent) before they are evaluated, but for
        those accounted already (forward differences put off)."""
        cache, charged = self.cache, self._charged
        todo = [i for i, k in enumerate(keys) if k not in cache]
        if not charged:
            due = len(todo)
        else:
            due = sum(keys[i] not in charged for i in todo)
            charged.difference_update(keys[i] for i in todo)
        if due and self.budget is not None:
            self.budget.spend(due)
        return todo

    def get(self, x: np.ndarray) -> tuple[float, np.ndarray, Any, int]:
        """``(cost, g, payload, row)`` at ``x`` (the payload None if not evaluated yet: see
        :meth:`details`)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        self._fill(x[None, :])
        return self.cache[x.tobytes()]

    def details(self, x: np.ndarray) -> tuple[float, np.ndarray, Any, int]:
        """:meth:`get` with the payload."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        self._fill(x[None, :], payload=True)
        return self.cache[x.tobytes()]

    def evaluate_many(
        self, X: np.ndarray, payload: bool = False
    ) -> list[tuple[float, np.ndarray, Any, int]]:
        """:meth:`get` (:meth:`details` with ``payload``) for every row of ``X`` in one batched
        call."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        self._fill(X, payload)
        return [self.cache[x.tobytes()] for x in X]

    def _jacobians(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.ascontiguousarray(x, dtype=np.float64)
        key = x.tobytes()
        hit = self._jac.get(key)
        if hit is not None:  # SLSQP asks for the cost's and the constraints' at each point
            return hit
        batch = self._points.pop(key, None)  # evaluated together (_with_jacobian_points)
        if batch is None:
            X = _fd_points(x)
            rows = self.evaluate_many(X)
            cost = np.array([r[0] for r in rows])
            g = np.stack([r[1] for r in rows])
        else:
            X, cost, g = batch
        dc, dg = fd_quotients(X, cost, np.ascontiguousarray(g))
        self._jac[key] = dc, dg.T
        return dc, dg.T

    def _with_jacobian_points(
        self, x: np.ndarray, eager: bool = True
    ) -> tuple[float, np.ndarray, Any, int]:
        """:meth:`get`, accounting the forward-difference points around ``x`` with it; with
        ``eager``, evaluating them in the same batched call (SLSQP asks for the Jacobians at
        the points it accepts, and a batch costs about two single points), else when
        :meth:`_jacobians` asks for them."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        key = x.tobytes()
        if key not in self.cache:
            X = _fd_points(x)
            if eager:
                fresh = self._fill(X)
                if fresh is not None:
                    self._points[key] = (X, *fresh)
            else:  # all accounted now (x's evaluation below is not accounted again)
                keys = [r.tobytes() for r in X]
                self._charged.update(keys[i] for i in self._accounted(keys))
                self._fill(X[:1])
        return self.cache[key]

    def scaling(self, x0: np.ndarray) -> np.ndarray | None:
        """``T`` such that the Gauss-Newton model of the cost at ``x0``, ``2 J^T J`` with ``J``
        the residuals' forward-difference Jacobian, is the identity in ``z`` (``x = x0 + T
        z``): ``T = V diag(w)^(-1/2) V^T`` from its eigen-decomposition, eigenvalues floored
        at :data:`_SCALING_FLOOR` of the largest. None without residuals or where the model is
        not finite or vanishes."""
        if self.residuals is None:
            return None
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        X = _fd_points(x0)
        if self.residual_values is not None:
            cost, g, R = self._residual_rows(X)
            self._start = (x0.tobytes(), cost, g)
        else:
            rows = self.evaluate_many(X, payload=True)
            R = np.stack([self.residuals(p)[r] for _, _, p, r in rows])
        with np.errstate(all="ignore"):
            J = (R[1:] - R[0]).T / (np.diag(X[1:]) - x0)
            H = 2.0 * J.T @ J
        if not np.all(np.isfinite(H)):
            return None
        w, V = np.linalg.eigh(H)
        if not w[-1] > 0:
            return None
        return (V / np.sqrt(np.maximum(w, _SCALING_FLOOR * w[-1]))) @ V.T

    def _residual_rows(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``residual_values`` at the rows of ``X``: their costs, constraints and the cost's
        terms, the rows not evaluated yet accounted and cached as :meth:`_fill` does (without
        their payload)."""
        keys = [x.tobytes() for x in X]
        todo = self._accounted(keys)
        cost, g, R = self.residual_values(X)
        for i in todo:
            self.cache[keys[i]] = (float(cost[i]), g[i], None, i)
        return cost, g, R

    def minimize(
        self,
        x0: np.ndarray,
        maxiter: int,
        ftol: float,
        stall: bool = False,
        scaled: bool = False,
    ) -> np.ndarray:
        """SLSQP from ``x0``; returns the final point. With ``stall``, a run that stops making
        progress towards feasibility ends early (see ``_STALL_ITERATIONS``). With ``scaled``
        (and residuals), in the coordinates of :meth:`scaling` at ``x0``."""
        T = self.scaling(x0) if scaled else None
        if self.compiled is not None:
            return self._minimize_compiled(x0, T, maxiter, ftol, stall)
        hist: list[float] = []  # constraint violation after each iteration

        def stalled(x: np.ndarray) -> bool:
            hist.append(float(violation(self.get(x)[1])))
            w = _STALL_WINDOW
            # still infeasible, and no progress towards feasibility of late
            return (
                len(hist) >= _STALL_ITERATIONS
                and hist[-1] > _STALL_VIOLATION
                and min(hist[-w:]) > _STALL_GAIN * min(hist[:-w])
            )

        # SLSQP accepts most first points after a Jacobian (its full step) and few of the
        # line search's shorter ones: their forward differences wait until asked for
        first = [True]

        def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
            c, g, _, _ = self._with_jacobian_points(x, eager=first[0])
            first[0] = False
            return c, g

        def jac(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            first[0] = True
            return self._jacobians(x)

        if T is None:
            return minimize_slsqp(fun, jac, x0, maxiter, ftol, stalled if stall else None)
        xs = np.array(x0, dtype=np.float64)

        def fun_z(z: np.ndarray) -> tuple[float, np.ndarray]:
            return fun(xs + T @ z)

        def jac_z(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            dc, dg = jac(xs + T @ z)
            return T.T @ dc, dg @ T

        def stalled_z(z: np.ndarray) -> bool:
            return stalled(xs + T @ z)

        z = minimize_slsqp(
            fun_z, jac_z, np.zeros_like(xs), maxiter, ftol, stalled_z if stall else None
        )
        return xs + T @ z

    def _minimize_compiled(
        self, x0: np.ndarray, T: np.ndarray | None, maxiter: int, ftol: float, stall: bool
    ) -> np.ndarray:
        """:meth:`minimize` in one compiled call (:func:`sqp.sqp_solve` on ``compiled``, the
        kernel's arguments): its rows accounted in the budget; once that is spent,
        :class:`BudgetExhausted`."""
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        if T is None:
            T = np.eye(x0.size)
        left = _UNLIMITED
        if self.budget is not None:
            self.budget.spend(0)  # raises if already spent (or past its deadline)
            left = max(self.budget.evaluations - self.budget.used, 0)
        P, k, common, first, second, pair = self.compiled
        # the scaling's rows at x0 are the solve's first Jacobian's: not evaluated again
        start = self._start
        cost0, g0 = (
            (start[1], start[2]) if start and start[0] == x0.tobytes() else (NO_START, NO_START_G)
        )
        rule = (
            float(_STALL_ITERATIONS),
            float(_STALL_WINDOW),
            float(_STALL_GAIN),
            float(_STALL_VIOLATION),
        )
        x, rows, status, _ = sqp_solve(
            P, x0, np.ascontiguousarray(T), k, common, first, second, pair,
            int(maxiter), float(ftol), bool(stall), int(left), rule,
            np.ascontiguousarray(cost0), np.ascontiguousarray(g0),
        )  # fmt: skip
        if self.budget is not None:
            self.budget.used += int(rows)
            if status == 2:
                self.budget.exhausted = True
                raise BudgetExhausted(
                    f"search budget exhausted after {self.budget.used} step evaluations"
                )
        return x


_UNLIMITED = 2**62  # rows of a compiled solve without a budget


def _fd_points(x: np.ndarray) -> np.ndarray:
    """``x`` and its ``k`` forward-difference neighbours (rows), as the compiled solve takes
    them (:func:`.sqp.fd_points`)."""
    X = np.empty((x.size + 1, x.size))
    fd_points(np.ascontiguousarray(x, dtype=np.float64), X)
    return X
