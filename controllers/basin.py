"""Sampled basin of attraction of the reference controller around its periodic flat-ground gait.

The periodic gait (:meth:`controllers.planner.GaitPlanner.periodic_gait`) has a post-impact
state ``x*`` at phase ``theta+``. A perturbation is given in the gait's transverse coordinates
``z = [I, y, y_dot]`` (:class:`controllers.transverse.StepModel`) at the phase ``theta+`` of
``x*`` (the Poincare section through it): a swing-phase state just after a touchdown, its
trailing foot lifted off the ground or, within the foot's retraction, lowered (perturbations
that would put the retracted foot below the ground, or ``theta_dot^2 + I <= 0``, have no
state and are left out). Each perturbed start
is simulated in closed loop for ``K`` footsteps by the exact hybrid simulator with the
reference controller (:class:`controllers.TransverseController`, replanning at every footstep)
on the true state (no sensors, no observer): :meth:`TransverseController.rollout`.

``P(theta) = Z^-1`` is the jump-Riccati solution of the controller's weights over the
periodic step repeated over the horizon (:func:`controllers.gains.horizon_gains`);
``P(theta+)`` sizes the perturbations: directions are uniform on the unit sphere mapped onto
the ellipsoid ``z' P z = r^2``, so ``V`` of a start is ``r^2``.

A start *converged* when the walker completed ``K`` footsteps without a failure and its state
just before the ``K``-th touchdown has ``V_c = z' P_c(theta) z <= v_tol`` in the periodic
gait's coordinates, ``P_c`` the same solution with the paper's weights (``Q = Qj = I``,
``R = 1``; the controller's other settings): a metric that does not follow the controller's
weights, so one tolerance serves all of them (stiff weights' ``P`` weighs the speed
coordinate ``I`` a thousand times more near the touchdown, where the walks end).

Certified level set (:func:`certified_level`): the largest ``rho`` such that no sampled start
with ``V < rho`` failed to converge, chosen on one half of the samples and checked on the
other, with the exact one-sided bound on the probability that a start drawn by the same
sampler inside ``V < rho`` fails. It is a statistical statement about the sampler, the
simulator and ``K`` footsteps, not a proof: see the README's Basin section.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import stats

from envs.physics import model
from envs.physics.params import RobotParams
from envs.physics.terrain import Terrain

from .controller import PAPER_WEIGHTS, ControllerConfig, TransverseController
from .gains import HorizonSolution, horizon_gains, step_models
from .planner import GaitPlanner, PeriodicGait, PlannerConfig
from .transverse import StepModel

__all__ = [
    "DEFAULT_V_TOL",
    "BasinSample",
    "LevelSet",
    "PeriodicReference",
    "certified_level",
    "converged_fractions",
    "periodic_reference",
    "run_perturbation",
    "sample_basin",
    "slice_grid",
]

#: names of the transverse coordinates
COORDS = ("I", "y", "y_dot")
#: the end of a perturbation that has no post-impact state (not a start, left out of the counts)
NO_STATE = "no state"


#: largest ``V_c`` (the paper weights' metric) at the end of a start that counts as converged:
#: about four times the floor the unperturbed gait settles at (0.008 after 16 footsteps with the
#: paper's weights; the 5 ms zero-order hold)
DEFAULT_V_TOL = 0.03
#: the feedback weights of the convergence metric: the paper's
METRIC_WEIGHTS = PAPER_WEIGHTS


@dataclass
class PeriodicReference:
    """The periodic flat-ground gait, its transverse model and Lyapunov matrices.

    Attributes:
        robot: the robot; gait: the periodic gait; model: its step's transverse model.
        solution: the jump-Riccati solution over the periodic step repeated ``horizon + 1``
            times (``solution.lyapunov(z, theta)`` is ``V``).
        P: ``Z^-1`` at the post-impact phase ``theta+`` (3 x 3, symmetric positive definite).
        config: the controller's settings.
        metric: the same solution with :data:`METRIC_WEIGHTS` (the convergence test's ``V_c``;
            ``solution`` itself where the controller has those weights).
    """

    robot: RobotParams
    gait: PeriodicGait
    model: StepModel
    solution: HorizonSolution
    P: np.ndarray
    config: ControllerConfig
    planner: GaitPlanner = field(repr=False)
    metric: HorizonSolution | None = field(default=None, repr=False)

    def lyapunov(self, x: np.ndarray) -> float:
        """``V = z' P(theta) z`` of a state ``x = (q1, q2, q1d, q2d)`` [rad, rad/s] in the
        periodic gait's transverse coordinates ``z``."""
        return self.solution.lyapunov(self.model.coords(np.asarray(x, float)), float(x[1]))

    def convergence_value(self, x: np.ndarray) -> float:
        """``V_c = z' P_c(theta) z`` of a state ``x`` [rad, rad/s], the metric of the
        convergence test (:data:`METRIC_WEIGHTS`, whatever the controller's weights)."""
        sol = self.solution if self.metric is None else self.metric
        return sol.lyapunov(self.model.coords(np.asarray(x, float)), float(x[1]))


def periodic_reference(
    robot: RobotParams | str = "paper",
    config: ControllerConfig | dict | None = None,
    planner: PlannerConfig | dict | None = None,
) -> PeriodicReference:
    """The periodic gait of ``robot`` (a preset name or parameters) and the Lyapunov matrices of
    the controller with ``config`` (a :class:`ControllerConfig`, or the fields that differ from
    the robot's defaults, :meth:`ControllerConfig.for_robot`); the controller replans with the
    planner settings ``planner`` (a :class:`PlannerConfig`, or the fields that differ from the
    robot's defaults; None: the defaults)."""
    params = robot if isinstance(robot, RobotParams) else RobotParams.from_preset(robot)
    if isinstance(config, ControllerConfig):
        cfg = config
    else:
        cfg = ControllerConfig.for_robot(params.name, **(config or {}))
    planner = GaitPlanner(params, planner)
    gait = planner.periodic_gait()
    models = step_models(params.vector(), [gait.step] * (cfg.horizon + 1), None, cfg.margin)
    sol = horizon_gains(models, cfg)
    P = 0.5 * (sol.Zinv[0] + sol.Zinv[0].T)
    metric_cfg = replace(cfg, **METRIC_WEIGHTS)
    metric = sol if metric_cfg == cfg else horizon_gains(models, metric_cfg)
    return PeriodicReference(params, gait, models[0], sol, P, cfg, planner, metric)


def perturbed_state(ref: PeriodicReference, z: Sequence[float]) -> np.ndarray | None:
    """The state ``(q1, q2, q1d, q2d)`` at the periodic gait's post-impact phase ``theta+``
    whose transverse coordinates are ``z = [I, y, y_dot]``; None when there is none: ``I``
    at or below ``-theta_dot+^2``, or the retracted trailing foot below the (flat) ground."""
    dI, dy, dyd = (float(v) for v in z)
    m, robot = ref.model, ref.robot
    th = m.theta_plus
    F = float(m.thetadot_sq(th)) + dI
    if F <= 0:
        return None
    phi, dphi, _ = m.derivatives(th)
    q1 = float(phi) + dy
    _, fy = model.swing_foot_position(robot.vector(), q1, th, 0.0, 0.0, robot.retract * robot.l)
    if fy < 0:
        return None
    thd = math.sqrt(F)
    return np.array([q1, th, float(dphi) * thd + dyd, thd])


@dataclass(frozen=True)
class BasinSample:
    """One perturbed start and what became of it.

    Attributes:
        z: the perturbation ``[I, y, y_dot]`` [rad^2/s^2, rad, rad/s]; V0: ``z' P z``.
        converged: completed ``K`` footsteps and ended with ``V_c <= v_tol``.
        footsteps: footsteps completed; V_end: ``V_c`` (the convergence metric) before the last
            touchdown (NaN if none).
        end: ``converged``, ``not converged`` (walked but ``V_c > v_tol``), the simulator's
            failure reason (``fall``, ``trip``, ...) or ``no state`` (no such post-impact state).
        fallbacks: footsteps on which the controller fell back (planning failed).
    """

    z: tuple[float, float, float]
    V0: float
    converged: bool
    footsteps: int
    V_end: float
    end: str
    fallbacks: int


def run_perturbation(
    ref: PeriodicReference,
    z: Sequence[float],
    steps: int = 16,
    v_tol: float = DEFAULT_V_TOL,
    dt: float = 0.005,
) -> BasinSample:
    """Simulate the reference controller from the perturbed post-impact state ``z``.

    Args:
        ref: the periodic gait (:func:`periodic_reference`).
        z: perturbation ``[I, y, y_dot]`` [rad^2/s^2, rad, rad/s], finite.
        steps: footsteps ``K`` to walk, >= 1.
        v_tol: largest ``V_c`` (the convergence metric) at the end that counts as converged, > 0.
        dt: control period [s], > 0.
    """
    zz = np.asarray(z, dtype=np.float64)
    if zz.shape != (3,) or not np.all(np.isfinite(zz)):
        raise ValueError(f"z must be 3 finite numbers [I, y, y_dot], got {z!r}")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    if not (math.isfinite(v_tol) and v_tol > 0):
        raise ValueError(f"v_tol = {v_tol!r}; allowed: > 0")
    if not (math.isfinite(dt) and 0 < dt <= 0.05):
        raise ValueError(f"dt = {dt!r} s; allowed: (0, 0.05]")
    V0 = float(zz @ ref.P @ zz)
    zt = (float(zz[0]), float(zz[1]), float(zz[2]))
    x0 = perturbed_state(ref, zz)
    if x0 is None:
        return BasinSample(zt, V0, False, 0, math.nan, NO_STATE, 0)
    ctrl = TransverseController(ref.robot, Terrain.flat(), ref.config, ref.planner)
    out = ctrl.rollout(x0[:2], x0[2:], duration=3.0 * steps * ref.gait.period, dt=dt, steps=steps)
    n = int(out["impacts"].size)
    fallbacks = sum(r.fallback is not None for r in out["records"])
    V_end = math.nan
    if n:
        last = np.concatenate([out["q"][-1], out["qd"][-1]])
        V_end = ref.convergence_value(last)
    if out["failure"] is not None:
        end = str(out["failure"])
    elif n < steps:
        end = "not converged"  # out of time: stalled
    else:
        end = "converged" if V_end <= v_tol else "not converged"
    return BasinSample(zt, V0, end == "converged", n, V_end, end, fallbacks)


def sphere_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` directions uniform on the unit sphere of R^3, ``(n, 3)``."""
    u = rng.standard_normal((n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def sample_basin(
    ref: PeriodicReference,
    radii: Sequence[float],
    per_radius: int,
    seed: int = 0,
    steps: int = 16,
    v_tol: float = DEFAULT_V_TOL,
    on_sample: Callable[[BasinSample], None] | None = None,
) -> list[BasinSample]:
    """Perturbations ``z = r L^-T u`` (``P = L L'``, ``u`` uniform on the unit sphere), so that
    ``z' P z = r^2``, ``per_radius`` of them at each radius ``r`` in ``radii`` (> 0), each run by
    :func:`run_perturbation` (with ``V0`` set to ``r^2`` exactly); directions from
    ``np.random.default_rng(seed)``.

    Args:
        ref: the periodic gait; radii: perturbation sizes ``r``; per_radius: starts per size,
            >= 1; seed: seed of the directions; steps, v_tol: as for :func:`run_perturbation`;
        on_sample: called with each finished sample (progress).
    """
    rs = [float(r) for r in radii]
    if not rs or not all(math.isfinite(r) and r > 0 for r in rs):
        raise ValueError(f"radii must be numbers > 0, got {list(radii)!r}")
    if isinstance(per_radius, bool) or not isinstance(per_radius, (int, np.integer)):
        raise ValueError(f"per_radius must be an integer >= 1, got {per_radius!r}")
    if per_radius < 1:
        raise ValueError(f"per_radius = {per_radius}; allowed: >= 1")
    rng = np.random.default_rng(seed)
    Linv_t = np.linalg.inv(np.linalg.cholesky(ref.P)).T
    out = []
    for r in rs:
        for u in sphere_directions(rng, per_radius):
            # V0 = r^2 exactly, so that starts of one size are one level of V
            s = replace(run_perturbation(ref, r * (Linv_t @ u), steps, v_tol), V0=r * r)
            out.append(s)
            if on_sample is not None:
                on_sample(s)
    return out


def converged_fractions(samples: Sequence[BasinSample]) -> list[dict[str, Any]]:
    """Per perturbation size ``r = sqrt(V0)`` (rounded to 12 digits), in increasing ``r``:
    ``starts`` (perturbations with a post-impact state; ``no_state``: those without, left
    out), ``converged`` and the ``fraction`` (intervals: ``agents.stats.wilson_interval``)."""
    groups: dict[float, list[BasinSample]] = {}
    for s in samples:
        groups.setdefault(round(math.sqrt(s.V0), 12), []).append(s)
    rows = []
    for r in sorted(groups):
        g = [s for s in groups[r] if s.end != NO_STATE]
        k = sum(s.converged for s in g)
        rows.append(
            {
                "r": r,
                "starts": len(g),
                "no_state": len(groups[r]) - len(g),
                "converged": k,
                "fraction": k / len(g) if g else math.nan,
            }
        )
    return rows


@dataclass(frozen=True)
class LevelSet:
    """A level set ``V < rho`` of ``V = z' P z`` checked on held-out samples.

    Attributes:
        rho: the level: the smallest ``V`` of a failed selection sample, or, when none failed
            (``bounded_by_failure`` False), the largest ``V`` of the selection samples (the
            level set then ends where the sampling does; ``V <= rho`` counts as inside).
        selection: samples used to choose ``rho``; certification: samples checking it.
        inside: certification samples with ``V < rho``; failures_inside: of those, the ones
            that did not converge (0 unless the level set is wrong somewhere).
        bound: one-sided exact (Clopper-Pearson) upper bound, at ``confidence``, on the
            probability that a start drawn by the same sampler with ``V < rho`` fails
            (about ``3 / inside`` with no failure at 95 %).
        largest_sampled: the largest sampled ``V``.
    """

    rho: float
    selection: int
    certification: int
    inside: int
    failures_inside: int
    bound: float
    confidence: float
    largest_sampled: float
    bounded_by_failure: bool

    def contains(self, V: float) -> bool:
        """Whether ``V`` lies in the level set (``V < rho``, or ``V <= rho`` when ``rho`` is
        the largest sampled ``V``)."""
        return V < self.rho or (not self.bounded_by_failure and V <= self.rho)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return dict(self.__dict__)


def certified_level(
    V: Sequence[float] | np.ndarray,
    failed: Sequence[bool] | np.ndarray,
    confidence: float = 0.95,
    holdout: bool = True,
) -> LevelSet:
    """The largest ``rho`` with no failed sample below it, and its held-out check.

    With ``holdout`` the even-numbered samples choose ``rho`` (the smallest ``V`` among their
    failures) and the odd-numbered ones check it, so the bound is not biased by the choice;
    without it, all samples do both (the bound is then optimistic).

    Args:
        V: ``z' P z`` of each sampled start (>= 0).
        failed: per sample, True if it did not converge.
        confidence: level of the one-sided bound, in (0, 1).
        holdout: split the samples into selection and certification halves.
    """
    v = np.asarray(V, dtype=np.float64)
    f = np.asarray(failed, dtype=bool)
    if v.ndim != 1 or v.shape != f.shape or v.size < (2 if holdout else 1):
        raise ValueError(
            f"V and failed must be 1-D of the same length (>= {2 if holdout else 1}), got "
            f"shapes {v.shape} and {f.shape}"
        )
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("V must be finite and >= 0")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence = {confidence!r} out of range; allowed: (0, 1)")
    sel = np.arange(v.size) % 2 == 0 if holdout else np.ones(v.size, dtype=bool)
    cert = ~sel if holdout else sel
    fails_sel = v[sel & f]
    if fails_sel.size:
        rho = float(fails_sel.min())
        inside = cert & (v < rho)
    else:
        rho = float(v[sel].max())
        inside = cert & (v <= rho)
    n_in, k_in = int(inside.sum()), int((inside & f).sum())
    if n_in:
        ci = stats.binomtest(k_in, n_in, alternative="less").proportion_ci(confidence, "exact")
        bound = float(ci.high)
    else:
        bound = 1.0
    return LevelSet(
        rho=rho,
        selection=int(sel.sum()),
        certification=int(cert.sum()),
        inside=n_in,
        failures_inside=k_in,
        bound=bound,
        confidence=float(confidence),
        largest_sampled=float(v.max()),
        bounded_by_failure=bool(fails_sel.size),
    )


def slice_grid(
    ref: PeriodicReference,
    axes: tuple[int, int],
    extent: tuple[float, float],
    n: int,
    steps: int = 16,
    v_tol: float = DEFAULT_V_TOL,
    on_sample: Callable[[BasinSample], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, list[BasinSample]]:
    """A 2-D slice: an ``n x n`` grid over coordinates ``axes`` (indices into ``[I, y,
    y_dot]``) within ``+-extent`` (two half-widths, > 0), the third coordinate 0, each point
    run by :func:`run_perturbation` with ``steps`` and ``v_tol`` on the periodic gait ``ref``;
    ``on_sample`` is called with each sample. Returns the two grid vectors and the samples
    (row-major, first axis slowest)."""
    a, b = axes
    if a == b or not {a, b} <= {0, 1, 2}:
        raise ValueError(f"axes must be two different indices of [I, y, y_dot], got {axes!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 2 <= n <= 200:
        raise ValueError(f"n must be an integer in [2, 200], got {n!r}")
    if not all(math.isfinite(e) and e > 0 for e in extent):
        raise ValueError(f"extent must be two numbers > 0, got {extent!r}")
    ga = np.linspace(-extent[0], extent[0], n)
    gb = np.linspace(-extent[1], extent[1], n)
    out = []
    for va in ga:
        for vb in gb:
            z = np.zeros(3)
            z[a], z[b] = va, vb
            s = run_perturbation(ref, z, steps, v_tol)
            out.append(s)
            if on_sample is not None:
                on_sample(s)
    return ga, gb, out
