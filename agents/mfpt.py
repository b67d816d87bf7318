"""Mean first-passage time (MFPT): footsteps to failure on random terrain of a given roughness.

Metastable walking (Byl and Tedrake 2009) measures the rough-terrain robustness of a walker by
the expected number of footsteps before it fails. Here every walk is a long course of random
blocks (the widths of ``configs/terrains/rough_blocks.yaml``; at every block border the height
changes by a step drawn uniformly from ``[-roughness, roughness]``) walked by a policy on the
native vector env, one walk per sub-env at a time, until the walker fails or the walk is
censored: at the footstep cap, near the end of the course, or at the time limit.

Estimator: with a memoryless failure process (each footstep fails with the same probability
``p`` whatever came before) the footsteps to failure are geometric, and a walk that completed
``k`` footsteps contributes ``k`` survived trials plus one failed trial if it failed. The
maximum-likelihood estimate with censoring is ``p = failures / exposure`` (exposure: all
footsteps attempted, failed ones included) and ``MFPT = 1 / p`` footsteps (the failing one
counted). Its interval is the exact (Clopper-Pearson) interval of ``failures`` in ``exposure``
trials, inverted. Walks that were all censored give no estimate, only a lower bound.
:func:`kaplan_meier` gives the survival curve without the geometric assumption and
:func:`geometric_check` tests the assumption (constant hazard against a hazard constant on
blocks of footsteps).

:func:`markov_mfpt` drops the memoryless assumption for a Markov one (Byl and Tedrake 2009):
the walker's post-impact state, binned on a mesh, is a Markov chain with an absorbing failure
state, and the MFPT is ``1 / (1 - lambda_2)``, ``lambda_2`` the largest eigenvalue of the
transitions between the mesh's cells (the chain's second largest, after the failure state's
1): the expected footsteps to failure from the chain's quasi-stationary distribution. The
transitions are counted on the walks' own footsteps: with random terrain integrated out by the
walks' courses, and each walk's first post-impact state drawn from the start, not from the
mesh (the reference controller's plans look four footsteps ahead over the terrain it has
seen, so one footstep from a mesh point on a terrain bin, Byl and Tedrake's construction, is
not defined for it).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from scipy import stats

import envs  # noqa: F401  (registers the ids)
from controllers.controller import ControllerConfig
from controllers.planner import PlannerConfig
from controllers.reference import checked_deviations, checked_long_segment
from envs.physics.terrain import MAX_COURSE_LENGTH, terrain_spec

from .policies import BASELINES, make_baseline_policy

__all__ = [
    "MFPTEstimate",
    "MFPTResult",
    "MarkovEstimate",
    "NothingToCount",
    "Walk",
    "estimate_mfpt",
    "geometric_check",
    "kaplan_meier",
    "markov_mfpt",
    "mfpt_sweep",
    "roughness_terrain",
    "run_walks",
]

#: the vector env the walks run on by default (its robot, sensors and control period)
DEFAULT_ENV = "roughwalk/CompassGaitRough-v0"
#: how a walk ended when it did not fail
CENSORED = ("cap", "course_end", "time")
#: the post-impact state's mesh of :func:`markov_mfpt`: quantile bins of the stance leg's angle
#: ``theta`` and of its rate ``theta_dot`` (the coordinates of :attr:`Walk.states`)
MARKOV_BINS = (6, 3)


class NothingToCount(ValueError):
    """:func:`markov_mfpt` has no transition to count: no footstep leaves a cell of the mesh and
    no walk failed (the walks themselves are fine)."""


def _check_counts(footsteps: Any, failed: Any) -> tuple[np.ndarray, np.ndarray]:
    k = np.asarray(footsteps)
    d = np.asarray(failed)
    if k.ndim != 1 or k.size == 0 or k.shape != d.shape:
        raise ValueError(
            f"footsteps and failed must be 1-D of the same non-zero length, got shapes "
            f"{k.shape} and {d.shape}"
        )
    if not np.issubdtype(k.dtype, np.integer) or np.any(k < 0):
        raise ValueError("footsteps must be integers >= 0 (footsteps completed per walk)")
    if d.dtype != bool:
        raise ValueError(f"failed must be booleans (True: the walk failed), got {d.dtype}")
    return k.astype(np.int64), d


def _check_confidence(confidence: float) -> float:
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)):
        raise ValueError(f"confidence must be a number in (0, 1), got {confidence!r}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence = {confidence!r} out of range; allowed: (0, 1)")
    return float(confidence)


# ---------------------------------------------------------------------------- estimator
@dataclass(frozen=True)
class MFPTEstimate:
    """MFPT of a geometric failure process estimated from censored walks.

    Attributes:
        walks: number of walks; failures: walks that ended in a failure.
        exposure: footsteps attempted over all walks (completed ones plus the failed ones).
        p_fail: maximum-likelihood failure probability per footstep, ``failures / exposure``.
        p_interval: exact (Clopper-Pearson) interval of ``p_fail`` at ``confidence``.
        mfpt: ``1 / p_fail`` [footsteps], None when no walk failed (then only a lower bound).
        mfpt_interval: ``(1 / p_hi, 1 / p_lo)`` [footsteps]; the upper end is ``inf`` when no
            walk failed.
        confidence: the interval's confidence level.
    """

    walks: int
    failures: int
    exposure: int
    p_fail: float
    p_interval: tuple[float, float]
    mfpt: float | None
    mfpt_interval: tuple[float, float]
    confidence: float

    @property
    def lower_bound(self) -> float:
        """The MFPT's lower confidence limit [footsteps] (the only figure when all censored)."""
        return self.mfpt_interval[0]

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (an infinite upper limit as None)."""
        d = asdict(self)
        d["p_interval"] = list(self.p_interval)
        lo, hi = self.mfpt_interval
        d["mfpt_interval"] = [lo, hi if math.isfinite(hi) else None]
        return d


def estimate_mfpt(
    footsteps: Sequence[int] | np.ndarray,
    failed: Sequence[bool] | np.ndarray,
    confidence: float = 0.95,
) -> MFPTEstimate:
    """MFPT [footsteps] from censored walks under a geometric failure model.

    Args:
        footsteps: footsteps completed in each walk before it failed or was censored (>= 0).
        failed: per walk, True if it ended in a failure, False if it was censored.
        confidence: confidence level of the interval, in (0, 1).

    Returns:
        The estimate; with no failure, ``mfpt`` is None and ``mfpt_interval[0]`` a lower bound.
    """
    k, d = _check_counts(footsteps, failed)
    conf = _check_confidence(confidence)
    n_fail = int(d.sum())
    exposure = int(k.sum()) + n_fail
    if exposure == 0:
        raise ValueError("no footstep was attempted: nothing to estimate")
    ci = stats.binomtest(n_fail, exposure).proportion_ci(confidence_level=conf, method="exact")
    p_lo, p_hi = float(ci.low), float(ci.high)
    p = n_fail / exposure
    return MFPTEstimate(
        walks=int(k.size),
        failures=n_fail,
        exposure=exposure,
        p_fail=p,
        p_interval=(p_lo, p_hi),
        mfpt=1.0 / p if n_fail else None,
        mfpt_interval=(1.0 / p_hi, 1.0 / p_lo if p_lo > 0 else math.inf),
        confidence=conf,
    )


@dataclass(frozen=True)
class MarkovEstimate:
    """MFPT of a Markov chain on binned post-impact states (:func:`markov_mfpt`).

    Attributes:
        mfpt: ``1 / (1 - lambda_2)`` [footsteps] (None when no walk failed: ``lambda_2 = 1``).
        mfpt_interval: bootstrap percentile interval over walks at ``confidence`` (the upper
            end ``inf`` where resampled walks had no failure).
        lambda_2: largest eigenvalue of the transitions between mesh cells.
        cells: mesh cells with outgoing footsteps (the chain's transient states).
        transitions: footsteps counted (cell to cell or to failure).
        p_fail: per cell with outgoing footsteps, the fraction that failed (the mesh order).
        visits: per cell, footsteps counted out of it.
        edges: per state coordinate, the bin edges (quantiles of the pooled states).
        confidence: the interval's level; bootstrap: resamples.
    """

    mfpt: float | None
    mfpt_interval: tuple[float, float]
    lambda_2: float
    cells: int
    transitions: int
    p_fail: list[float]
    visits: list[int]
    edges: list[list[float]]
    confidence: float
    bootstrap: int

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (an infinite upper limit as None)."""
        d = asdict(self)
        lo, hi = self.mfpt_interval
        d["mfpt_interval"] = [lo, hi if math.isfinite(hi) else None]
        return d


def _chain_counts(
    cells: list[np.ndarray], failed: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Footsteps from cell to cell ``(n, n)`` and from cell to failure ``(n,)``: each walk's
    consecutive post-impact cells, and its last cell to failure if it failed."""
    N = np.zeros((n, n))
    F = np.zeros(n)
    for c, f in zip(cells, failed):
        np.add.at(N, (c[:-1], c[1:]), 1.0)
        if f:
            F[c[-1]] += 1.0
    return N, F


def _chain(N: np.ndarray, F: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(lambda_2, cells, out)``: the largest eigenvalue of the maximum-likelihood transitions
    between the chain's cells (rows of ``N`` normalised with the failures ``F``), the cells
    (mask) and the footsteps counted out of each. A footstep into a cell never left (only
    censored walks ended there) is treated as censored: its row counts without it (and a cell
    left only that way drops out too). ``lambda_2`` is 1 when no counted footstep failed."""
    keep = np.ones(N.shape[0], dtype=bool)
    while True:
        out = N[:, keep].sum(axis=1) + F
        again = keep & (out > 0)
        if np.array_equal(again, keep):
            break
        keep = again
    if not keep.any():
        return math.nan, keep, out
    if F[keep].sum() == 0:
        return 1.0, keep, out
    T = N[np.ix_(keep, keep)] / out[keep, None]
    return float(np.max(np.abs(np.linalg.eigvals(T)))), keep, out


def markov_mfpt(
    states: Sequence[np.ndarray],
    failed: Sequence[bool] | np.ndarray,
    bins: Sequence[int] = MARKOV_BINS,
    confidence: float = 0.95,
    bootstrap: int = 2000,
    seed: int = 0,
) -> MarkovEstimate:
    """MFPT [footsteps] of the Markov chain of binned post-impact states.

    Each state coordinate is cut into ``bins`` quantile bins of the pooled states (the mesh),
    the footsteps of the walks are counted as transitions between mesh cells (a failed walk's
    last one into the absorbing failure state), and the MFPT is ``1 / (1 - lambda_2)`` with
    ``lambda_2`` the largest eigenvalue of the estimated transitions between cells. Cells
    never left (only censored walks ended there) are not part of the chain.

    Args:
        states: per walk, its post-impact states ``(k + 1, d)``: the state it started from and
            the state after each of its ``k`` completed footsteps.
        failed: per walk, True if its next footstep failed, False if it was censored.
        bins: bins per state coordinate (``d`` integers >= 1).
        confidence: level of the bootstrap interval (walks resampled), in (0, 1).
        bootstrap: resamples, >= 100.
        seed: seed of the resampling.

    Raises:
        ValueError: bad input.
        NothingToCount: (a ValueError) no footstep leaves a cell and no walk failed.
    """
    conf = _check_confidence(confidence)
    fails = np.asarray(failed)
    if fails.ndim != 1 or fails.dtype != bool or fails.size != len(states) or not len(states):
        raise ValueError("failed: one boolean per walk, and at least one walk")
    X = [np.asarray(x, dtype=np.float64) for x in states]
    if any(x.ndim != 2 or x.shape[0] < 1 or x.shape[1] != len(bins) for x in X):
        raise ValueError(f"states: per walk an array (footsteps + 1, {len(bins)})")
    if not all(isinstance(b, (int, np.integer)) and b >= 1 for b in bins):
        raise ValueError(f"bins = {bins!r}; allowed: integers >= 1")
    if isinstance(bootstrap, bool) or not isinstance(bootstrap, int) or bootstrap < 100:
        raise ValueError(f"bootstrap = {bootstrap!r}; allowed: an integer >= 100")
    pooled = np.concatenate(X)
    if not np.all(np.isfinite(pooled)):
        raise ValueError("states must be finite")
    edges = [
        np.unique(np.quantile(pooled[:, j], np.linspace(0, 1, b + 1))[1:-1])
        for j, b in enumerate(bins)
    ]
    shape = tuple(len(e) + 1 for e in edges)
    cells = [
        np.ravel_multi_index(
            tuple(np.searchsorted(e, x[:, j], side="right") for j, e in enumerate(edges)), shape
        )
        for x in X
    ]
    n = int(np.prod(shape))
    N, F = _chain_counts(cells, fails, n)
    lam, keep, out = _chain(N, F)
    if not math.isfinite(lam):
        raise NothingToCount("no footstep leaves a cell and no walk failed: nothing to estimate")
    rng = np.random.default_rng(seed)
    boot = np.empty(bootstrap)
    for b in range(bootstrap):
        pick = rng.integers(0, len(cells), len(cells))
        Nb, Fb = _chain_counts([cells[i] for i in pick], fails[pick], n)
        boot[b] = _chain(Nb, Fb)[0]
    boot = boot[np.isfinite(boot)]
    with np.errstate(divide="ignore"):
        mfpts = np.where(boot < 1.0, 1.0 / (1.0 - np.minimum(boot, 1.0)), math.inf)
    a = (1.0 - conf) / 2.0
    ordered = np.sort(mfpts)  # percentiles by rank (no interpolation between infinities)
    lo = ordered[int(math.floor(a * (ordered.size - 1)))]
    hi = ordered[int(math.ceil((1.0 - a) * (ordered.size - 1)))]
    return MarkovEstimate(
        mfpt=1.0 / (1.0 - lam) if lam < 1.0 else None,
        mfpt_interval=(float(lo), float(hi)),
        lambda_2=lam,
        cells=int(keep.sum()),
        transitions=int(out.sum()),
        p_fail=[float(f) for f in F[keep] / out[keep]],
        visits=[int(v) for v in out[keep]],
        edges=[e.tolist() for e in edges],
        confidence=conf,
        bootstrap=bootstrap,
    )


def kaplan_meier(
    footsteps: Sequence[int] | np.ndarray, failed: Sequence[bool] | np.ndarray
) -> dict[str, np.ndarray]:
    """Kaplan-Meier survival over footsteps, no failure model assumed.

    A walk that completed ``k`` footsteps and failed, failed in footstep ``k + 1``; one that was
    censored survived footsteps ``1 .. k`` and is not at risk afterwards.

    Args:
        footsteps: footsteps completed per walk (>= 0).
        failed: per walk, True if it ended in a failure.

    Returns:
        ``step`` (footstep numbers 1 .. last attempted), ``at_risk`` (walks attempting it),
        ``failures`` (walks failing in it) and ``survival`` (probability of completing it).
    """
    k, d = _check_counts(footsteps, failed)
    attempted = k + d  # footsteps each walk attempted
    last = int(attempted.max())
    steps = np.arange(1, last + 1)
    at_risk = (attempted[None, :] >= steps[:, None]).sum(axis=1)
    fails = np.bincount(attempted[d], minlength=last + 1)[1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        hazard = np.where(at_risk > 0, fails / np.maximum(at_risk, 1), 0.0)
    return {
        "step": steps,
        "at_risk": at_risk,
        "failures": fails,
        "survival": np.cumprod(1.0 - hazard),
    }


def geometric_check(
    footsteps: Sequence[int] | np.ndarray,
    failed: Sequence[bool] | np.ndarray,
    edges: Sequence[int] = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024),
) -> dict[str, Any]:
    """Likelihood-ratio test of the geometric model (one failure probability for every
    footstep) against a failure probability constant on blocks of footsteps.

    Args:
        footsteps: footsteps completed per walk (>= 0).
        failed: per walk, True if it ended in a failure.
        edges: first footstep of each block (increasing, from 1); the last block is open.

    Returns:
        ``blocks`` (first and last footstep, exposure, failures, failure probability per
        block, for blocks with any exposure), ``statistic``, ``dof`` and ``p_value`` (small:
        the failure probability changes with the footstep number; None with fewer than two
        blocks holding exposure).
    """
    k, d = _check_counts(footsteps, failed)
    e = np.asarray(edges, dtype=np.int64)
    if e.ndim != 1 or e.size < 1 or e[0] != 1 or np.any(np.diff(e) <= 0):
        raise ValueError(f"edges must start at 1 and increase, got {list(edges)}")
    attempted = k + d
    blocks = []
    ll_blocks = 0.0
    for j, lo in enumerate(e):
        hi = int(e[j + 1]) - 1 if j + 1 < e.size else int(max(attempted.max(), lo))
        exposure = int(np.clip(attempted - lo + 1, 0, hi - lo + 1).sum())
        fails = int(np.count_nonzero(d & (attempted >= lo) & (attempted <= hi)))
        if exposure == 0:
            continue
        p = fails / exposure
        ll_blocks += _bernoulli_ll(fails, exposure, p)
        blocks.append(
            {"first": int(lo), "last": hi, "exposure": exposure, "failures": fails, "p_fail": p}
        )
    n_fail, exposure = int(d.sum()), int(attempted.sum())
    ll_one = _bernoulli_ll(n_fail, exposure, n_fail / exposure) if exposure else 0.0
    dof = len(blocks) - 1
    stat = max(0.0, 2.0 * (ll_blocks - ll_one))
    return {
        "blocks": blocks,
        "statistic": stat,
        "dof": dof,
        "p_value": float(stats.chi2.sf(stat, dof)) if dof >= 1 else None,
    }


def _bernoulli_ll(fails: int, trials: int, p: float) -> float:
    out = 0.0
    if fails:
        out += fails * math.log(p)
    if trials - fails:
        out += (trials - fails) * math.log1p(-p)
    return out


# ---------------------------------------------------------------------------- walks
@dataclass(frozen=True)
class Walk:
    """One walk: its seed, the footsteps completed and how it ended.

    Attributes:
        walk: its number (0, 1, ...); seed: the env seed of its reset.
        footsteps: footsteps completed; distance: hip progress [m]; time: simulated [s].
        failed: True if it ended in a failure; end: the failure reason (``fall``, ``trip``,
            ...) or why it was censored (``cap``, ``course_end``, ``time``).
        states: ``(theta, theta_dot)`` of the stance leg [rad, rad/s] at the start and at the
            first control tick after each completed footstep's touchdown (the post-impact
            states of :func:`markov_mfpt`; ``footsteps + 1`` pairs).
    """

    walk: int
    seed: int
    footsteps: int
    distance: float
    time: float
    failed: bool
    end: str
    states: tuple[tuple[float, float], ...] = ()


class _SubEnv:
    """What a policy reads from a single env, for sub-env ``i`` of a native vector env."""

    def __init__(self, venv: Any, i: int):
        self._venv, self._i = venv, i
        for name in ("robot", "params", "dt", "u_max", "torque_limit", "sensor_config"):
            setattr(self, name, getattr(venv, name))
        self.sensor_layout = venv.sensor_layout
        self.observation_mode = venv.observation_mode
        self.settings = venv.settings
        self.action_space = venv.single_action_space
        self.observation_space = venv.single_observation_space

    @property
    def unwrapped(self) -> _SubEnv:
        return self

    @property
    def terrain(self) -> Any:
        return self._venv.terrains[self._i]


def roughness_terrain(roughness: float, length: float, template: str = "rough_blocks") -> dict:
    """Spec of a random-blocks generator (no seed: one course per reset) with height steps
    uniform in ``[-roughness, roughness]`` [m] at each border, over ``length`` [m] (the block
    widths and flat start of ``template``, a random-blocks entry of ``configs/terrains``)."""
    r = _nonneg("roughness", roughness, 1.0)
    spec = terrain_spec(template)
    if not isinstance(spec, dict) or spec.get("kind") != "blocks":
        raise ValueError(f"terrain template {template!r} is not a random-blocks generator")
    spec.pop("seed", None)
    spec["height_range"] = [-r, r]
    spec["length"] = float(length)
    return spec


def _nonneg(name: str, value: Any, top: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name} must be a number in [0, {top:g}], got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and 0 <= v <= top):
        raise ValueError(f"{name} = {value!r} out of range; allowed: [0, {top:g}]")
    return v


def _positive_int(name: str, value: Any, top: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer in [1, {top}], got {value!r}")
    if not 1 <= value <= top:
        raise ValueError(f"{name} = {value} out of range; allowed: [1, {top}]")
    return int(value)


def check_run_args(
    policy: str, walks: int, walkers: int, step_cap: int, seed: int, max_step_time: float
) -> None:
    """Check the arguments of :func:`run_walks` (one-line ``ValueError`` naming the bad one)."""
    if policy not in BASELINES:
        raise ValueError(f"policy = {policy!r}; allowed: {', '.join(BASELINES)}")
    _positive_int("walks", walks, 100_000)
    _positive_int("walkers", walkers, 4096)
    _positive_int("step_cap", step_cap, 10_000)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**31:
        raise ValueError(f"seed must be an integer in [0, 2**31), got {seed!r}")
    if isinstance(max_step_time, bool) or not isinstance(max_step_time, (int, float)):
        raise ValueError(f"max_step_time must be a number in (0, 60] s, got {max_step_time!r}")
    if not 0 < max_step_time <= 60:
        raise ValueError(f"max_step_time = {max_step_time!r} out of range; allowed: (0, 60] s")


def policy_options(
    policy: str,
    controller: dict[str, Any] | None,
    planner: dict[str, Any] | None = None,
    long_segment: float | None = None,
    drop_edge_sd: float | None = None,
) -> dict[str, Any]:
    """Keyword arguments of :func:`agents.policies.make_baseline_policy` for ``policy`` with the
    controller settings ``controller`` (:class:`controllers.ControllerConfig` fields), the
    gait-planner settings ``planner`` (:class:`controllers.PlannerConfig` fields; None or
    empty: none), the online identification's ``long_segment`` [s] and the drop-edge
    preference from the leg-length uncertainty ``drop_edge_sd`` [standard deviations] (None:
    the policy's default; see :class:`controllers.ReferencePolicy`). Raises ``ValueError``
    naming a bad field, or settings for ``passive``."""
    out: dict[str, Any] = {}
    for name, value, checked in (
        ("long_segment", long_segment, checked_long_segment),
        ("drop_edge_sd", drop_edge_sd, lambda v: checked_deviations("drop_edge_sd", v)),
    ):
        if value is None:
            continue
        if policy == "passive":
            raise ValueError(f"{name}: applies to the pd and reference policies, not to passive")
        out[name] = checked(value)
    for name, value, cls, key in (
        ("controller", controller, ControllerConfig, "config"),
        ("planner", planner, PlannerConfig, "planner"),
    ):
        if not value:
            continue
        if policy == "passive":
            raise ValueError(f"{name}: applies to the pd and reference policies, not to passive")
        try:
            cls.from_dict(dict(value))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name}: {exc}") from None
        out[key] = dict(value)
    return out


def run_walks(
    policy: str,
    roughness: float,
    walks: int,
    *,
    walkers: int = 8,
    step_cap: int = 100,
    seed: int = 0,
    env_id: str = DEFAULT_ENV,
    max_step_time: float = 4.0,
    on_walk: Callable[[Walk], None] | None = None,
    controller: dict[str, Any] | None = None,
    planner: dict[str, Any] | None = None,
    long_segment: float | None = None,
    drop_edge_sd: float | None = None,
) -> list[Walk]:
    """Walk ``policy`` on courses of random blocks of ``roughness`` until each walk fails or
    is censored, ``walkers`` walks at a time on one native vector env.

    Walk ``j`` resets its sub-env with seed ``seed + j`` (course, start state and sensor noise
    from it) and gets a fresh episode of the policy, so the walks do not depend on
    ``walkers``. The course is long enough for ``step_cap`` footsteps of ``2 l`` (at most
    ``MAX_COURSE_LENGTH``).

    Args:
        policy: a baseline (``passive``, ``pd``, ``reference``), one instance per sub-env.
        roughness: half-width of the uniform block height steps [m], in [0, 1].
        walks: number of walks, >= 1.
        walkers: sub-envs walking at once, >= 1.
        step_cap: footsteps after which a walk is censored (``cap``), >= 1.
        seed: seed of walk 0, >= 0.
        env_id: the roughwalk env whose robot, sensors and control period are used (its
            terrain is replaced).
        max_step_time: time limit per capped footstep [s]; a walk is censored (``time``)
            after ``step_cap * max_step_time`` simulated seconds.
        on_walk: called with each finished walk (progress).
        controller: :class:`controllers.ControllerConfig` fields of the ``pd`` and
            ``reference`` policies (None: their defaults).
        planner: :class:`controllers.PlannerConfig` fields of their gait planner (None: the
            robot's defaults).
        long_segment: their online identification's long shooting segments [s] (None: the
            policy's default; 0: short segments only).
        drop_edge_sd: their drop-edge preference from the leg-length uncertainty [standard
            deviations] (None: the policy's default, 9 where they localise; 0: off).

    Returns:
        The walks in walk order.
    """
    check_run_args(policy, walks, walkers, step_cap, seed, max_step_time)
    policy_kwargs = policy_options(policy, controller, planner, long_segment, drop_edge_sd)
    r = _nonneg("roughness", roughness, 1.0)
    probe = gym.make(env_id)
    robot, dt = probe.unwrapped.robot, float(probe.unwrapped.dt)
    probe.close()
    template = roughness_terrain(r, 1.0)
    length = min(MAX_COURSE_LENGTH, step_cap * 2.0 * robot.l + 1.0)
    spec = {**template, "length": length}
    course_end = float(spec["start"]) + length - robot.l
    n = min(walkers, walks)
    venv = gym.make_vec(
        env_id,
        n,
        vectorization_mode="vector_entry_point",
        terrain=spec,
        difficulty=1.0,
        max_episode_steps=math.ceil(step_cap * max_step_time / dt),
        autoreset_mode="disabled",
    )
    try:
        base = venv.unwrapped
        pols = [make_baseline_policy(policy, _SubEnv(base, i), **policy_kwargs) for i in range(n)]
        slot_walk = list(range(n))
        obs, info = venv.reset(seed=[seed + j for j in range(n)])
        for p in pols:
            p.reset()
        # per slot: the walk's post-impact (theta, theta_dot) so far, and its footsteps
        states: list[list[tuple[float, float]]] = [[_stance_state(info, i)] for i in range(n)]
        seen = [0] * n
        done: dict[int, Walk] = {}
        next_walk = n
        actions = np.zeros((n, 1), dtype=np.float32)
        while len(done) < walks:
            for i in range(n):
                actions[i] = pols[i](obs[i]) if slot_walk[i] >= 0 else 0.0
            obs, _, term, trunc, info = venv.step(actions)
            ended = np.zeros(n, dtype=bool)
            seeds: list[int | None] = [None] * n
            for i in range(n):
                j = slot_walk[i]
                if j < 0:
                    continue
                steps = int(info["footsteps"][i])
                if steps > seen[i] and steps <= step_cap:
                    states[i].append(_stance_state(info, i))
                seen[i] = steps
                if term[i]:
                    end = str(info["failure"][i])
                elif steps >= step_cap:
                    end = "cap"
                elif info["stance_foot"][i][0] >= course_end:
                    end = "course_end"
                elif trunc[i]:
                    end = "time"
                else:
                    continue
                w = Walk(
                    walk=j,
                    seed=seed + j,
                    footsteps=min(steps, step_cap),
                    distance=float(info["distance"][i]),
                    time=float(info["time"][i]),
                    failed=bool(term[i]),
                    end=end,
                    states=tuple(states[i][: min(steps, step_cap) + 1]),
                )
                done[j] = w
                if on_walk is not None:
                    on_walk(w)
                if next_walk < walks:
                    slot_walk[i], seeds[i] = next_walk, seed + next_walk
                    ended[i] = True
                    next_walk += 1
                else:
                    slot_walk[i] = -1
            if ended.any():
                obs, info = venv.reset(seed=seeds, options={"reset_mask": ended})
                for i in np.nonzero(ended)[0]:
                    pols[i].reset()
                    states[i], seen[i] = [_stance_state(info, i)], 0
    finally:
        venv.close()
    return [done[j] for j in range(walks)]


def _stance_state(info: dict[str, Any], i: int) -> tuple[float, float]:
    """Sub-env ``i``'s stance-leg ``(theta, theta_dot)`` [rad, rad/s], rounded to 1e-6."""
    x = info["state"][i]
    return (round(float(x[1]), 6), round(float(x[3]), 6))


# ---------------------------------------------------------------------------- sweep
@dataclass(frozen=True)
class MFPTResult:
    """MFPT of one policy at one roughness.

    Attributes:
        policy: the policy's name; roughness: half-width of the block height steps [m];
        roughness_per_leg: ``roughness / l`` (fraction of the leg length); leg_length: ``l``
            [m].
        estimate: the censored geometric estimate; geometric: :func:`geometric_check`.
        walks: the walks; wall_time: wall-clock time of the walks [s].
        markov: the Markov-chain estimate on the walks' post-impact states
            (:func:`markov_mfpt`).
    """

    policy: str
    roughness: float
    roughness_per_leg: float
    leg_length: float
    estimate: MFPTEstimate
    geometric: dict[str, Any]
    walks: list[Walk]
    wall_time: float
    markov: MarkovEstimate | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form, the walks and the Kaplan-Meier curve included."""
        k = np.array([w.footsteps for w in self.walks])
        d = np.array([w.failed for w in self.walks])
        km = kaplan_meier(k, d)
        return {
            "policy": self.policy,
            "roughness": self.roughness,
            "roughness_per_leg": self.roughness_per_leg,
            "leg_length": self.leg_length,
            "estimate": self.estimate.to_dict(),
            "geometric_check": self.geometric,
            "markov_chain": None if self.markov is None else self.markov.to_dict(),
            "kaplan_meier": {key: v.tolist() for key, v in km.items()},
            "ends": dict(sorted(Counter(w.end for w in self.walks).items())),
            "wall_time": self.wall_time,
            "walks": [asdict(w) for w in self.walks],
        }


def _markov_or_none(
    walks: list[Walk], failed: np.ndarray, confidence: float
) -> MarkovEstimate | None:
    """:func:`markov_mfpt` of the walks, None when they give it nothing to count (no footstep
    that ends in a cell ever left, no failure): the walks are kept either way."""
    try:
        return markov_mfpt([np.array(w.states) for w in walks], failed, confidence=confidence)
    except NothingToCount:
        return None


def mfpt_sweep(
    policy: str,
    roughnesses: Sequence[float],
    walks: int,
    *,
    confidence: float = 0.95,
    stop_below: float | None = None,
    on_result: Callable[[MFPTResult], None] | None = None,
    **kwargs: Any,
) -> list[MFPTResult]:
    """:func:`run_walks` and :func:`estimate_mfpt` at each roughness [m], in the order given.

    Args:
        policy: a baseline's name.
        roughnesses: the roughness levels [m], each in [0, 1].
        walks: walks per level.
        confidence: confidence level of the intervals.
        stop_below: stop after the first level whose estimated MFPT is below this
            [footsteps] (None: run every level).
        on_result: called with each level's result.
        **kwargs: passed to :func:`run_walks` (``walkers``, ``step_cap``, ``seed``, ...).
    """
    _check_confidence(confidence)
    levels = [_nonneg("roughness", r, 1.0) for r in roughnesses]
    if not levels:
        raise ValueError("roughnesses: give at least one level")
    probe = gym.make(kwargs.get("env_id", DEFAULT_ENV))
    leg = float(probe.unwrapped.robot.l)
    probe.close()
    out = []
    for r in levels:
        t0 = time.perf_counter()
        ws = run_walks(policy, r, walks, **kwargs)
        wall = time.perf_counter() - t0
        k = np.array([w.footsteps for w in ws])
        d = np.array([w.failed for w in ws])
        res = MFPTResult(
            policy=policy,
            roughness=r,
            roughness_per_leg=r / leg,
            leg_length=leg,
            estimate=estimate_mfpt(k, d, confidence),
            geometric=geometric_check(k, d),
            walks=ws,
            wall_time=wall,
            markov=_markov_or_none(ws, d, confidence),
        )
        out.append(res)
        if on_result is not None:
            on_result(res)
        mfpt = res.estimate.mfpt
        if stop_below is not None and mfpt is not None and mfpt < stop_below:
            break
    return out
