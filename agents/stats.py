"""Interval estimates for evaluation results.

- :func:`wilson_interval`: the Wilson score interval of a success rate (binomial proportion).
- :func:`bootstrap_interval`: a seeded bootstrap interval (``scipy.stats.bootstrap``, BCa) of
  a statistic of one sample, or of paired samples (a ratio such as the cost of transport).
- Across training seeds, after Agarwal et al., *Deep RL at the Edge of the Statistical
  Precipice* (NeurIPS 2021) and their ``rliable`` package, with its definitions: the
  interquartile mean :func:`iqm` (the mean of the middle 50 % of all runs' scores, pooled over
  tasks, ``scipy.stats.trim_mean`` with 25 % cut at each end), :func:`stratified_bootstrap`
  (runs resampled with replacement within each task, percentile interval) and
  :func:`probability_of_improvement` (``P(X > Y)`` per task from the Mann-Whitney U statistic,
  ties counted half, averaged over the tasks both have).

Scores across training seeds are given per task as ``{task: scores of the runs}``; tasks may
have different numbers of runs.
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import scipy.stats

#: default confidence level of every interval
CONFIDENCE = 0.95
#: default bootstrap resamples (scipy's default for one sample; rliable uses 50,000 for the
#: aggregate metrics, which changes the interval's ends by well under a percent point)
RESAMPLES = 9999

_RNG_KEYWORD = "rng" if "rng" in inspect.signature(scipy.stats.bootstrap).parameters else None


def _check_confidence(confidence: float) -> None:
    if not (isinstance(confidence, (int, float)) and 0 < confidence < 1):
        raise ValueError(f"confidence = {confidence!r} is out of range; allowed: (0, 1)")


def _check_resamples(n_resamples: int) -> None:
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, (int, np.integer)):
        raise ValueError(f"n_resamples = {n_resamples!r} must be an integer >= 100")
    if n_resamples < 100:
        raise ValueError(f"n_resamples = {n_resamples} is out of range; allowed: >= 100")


def _sample(values: Any, name: str, min_size: int = 1) -> np.ndarray:
    """``values`` as a finite 1-D float array of at least ``min_size`` entries."""
    try:
        x = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a sequence of numbers") from None
    if x.ndim != 1:
        raise ValueError(f"{name}: must be one-dimensional, got shape {x.shape}")
    if x.size < min_size:
        raise ValueError(f"{name}: needs at least {min_size} values, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: every value must be finite")
    return x


def wilson_interval(
    successes: int, trials: int, confidence: float = CONFIDENCE
) -> tuple[float, float]:
    """The Wilson score interval of a success probability from ``successes`` of ``trials``.

    Unlike the normal approximation it stays inside [0, 1] and is informative at 0 and at
    ``trials`` successes (20 of 20 gives [0.839, 1] at 95 %).

    Args:
        successes: number of successes, ``0 <= successes <= trials``.
        trials: number of trials, >= 1.
        confidence: confidence level in (0, 1).

    Returns:
        ``(low, high)`` as fractions in [0, 1].
    """
    for name, value in (("successes", successes), ("trials", trials)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"{name} = {value!r} must be an integer")
    if trials < 1:
        raise ValueError(f"trials = {trials} is out of range; allowed: >= 1")
    if not 0 <= successes <= trials:
        raise ValueError(f"successes = {successes} is out of range; allowed: [0, {trials}]")
    _check_confidence(confidence)
    z = float(scipy.stats.norm.ppf(0.5 + confidence / 2))
    p = successes / trials
    denom = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    # exact ends at 0 and n successes (the formula gives them up to rounding)
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


def bootstrap_interval(
    data: Any,
    statistic: Callable[..., Any] = np.mean,
    *,
    paired: bool = False,
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float]:
    """A bootstrap confidence interval (bias-corrected and accelerated) of ``statistic``.

    Args:
        data: one sample (a sequence of numbers), or with ``paired`` a sequence of samples of
            the same length resampled together (e.g. ``(work, distance)`` for a ratio).
        statistic: ``statistic(sample, ..., axis=-1)``, vectorised like ``np.mean``.
        paired: ``data`` holds several paired samples.
        confidence: confidence level in (0, 1).
        n_resamples: bootstrap resamples, >= 100.
        seed: seed of the resampling (same seed, same interval).

    Returns:
        ``(low, high)``; ``(v, v)`` when every resample gives the same value ``v`` (e.g. a
        constant sample).

    Raises:
        ValueError: fewer than 2 values, a non-finite value, samples of unequal length.
    """
    _check_confidence(confidence)
    _check_resamples(n_resamples)
    if paired:
        samples = [_sample(d, f"data[{i}]", 2) for i, d in enumerate(data)]
        if not samples or len({s.size for s in samples}) != 1:
            raise ValueError("data: paired samples must be non-empty and of equal length")
    else:
        samples = [_sample(data, "data", 2)]
    point = statistic(*samples, axis=-1)
    if all(np.all(s == s[0]) for s in samples):
        return float(point), float(point)
    kwargs: dict[str, Any] = {
        "n_resamples": n_resamples,
        "confidence_level": confidence,
        "paired": paired,
        "vectorized": True,
        "method": "BCa",
    }
    rng = np.random.default_rng(seed)
    kwargs[_RNG_KEYWORD or "random_state"] = rng
    with np.errstate(all="ignore"):
        with warnings.catch_warnings():
            # BCa on a sample with few distinct values (e.g. 19 of 20 the same) warns and may
            # give NaN: the percentile interval is used then
            warnings.simplefilter("ignore", scipy.stats.DegenerateDataWarning)
            res = scipy.stats.bootstrap(tuple(samples), statistic, **kwargs)
            low, high = res.confidence_interval
            if not (np.isfinite(low) and np.isfinite(high)):
                kwargs["method"] = "percentile"
                kwargs[_RNG_KEYWORD or "random_state"] = np.random.default_rng(seed)
                res = scipy.stats.bootstrap(tuple(samples), statistic, **kwargs)
                low, high = res.confidence_interval
    return float(low), float(high)


def _task_scores(scores: Mapping[Any, Sequence[float]], name: str) -> dict[Any, np.ndarray]:
    """``scores`` checked: a non-empty mapping task -> finite 1-D scores, at least one each."""
    if not isinstance(scores, Mapping) or not scores:
        raise ValueError(f"{name}: must be a non-empty mapping task -> scores of the runs")
    return {task: _sample(v, f"{name}[{task!r}]") for task, v in scores.items()}


def iqm(scores: Any) -> float:
    """Interquartile mean: the mean of the middle 50 % of the scores (25 % trimmed at each
    end, ``scipy.stats.trim_mean``), pooled over all runs and tasks as in ``rliable``.

    Args:
        scores: an array of scores (any shape), or a mapping task -> scores of the runs.
    """
    if isinstance(scores, Mapping):
        flat = np.concatenate(list(_task_scores(scores, "scores").values()))
    else:
        flat = _sample(np.ravel(np.asarray(scores, dtype=np.float64)), "scores")
    return float(scipy.stats.trim_mean(flat, 0.25))


def stratified_bootstrap(
    scores: Mapping[Any, Sequence[float]],
    statistic: Callable[..., np.ndarray] | None = None,
    *,
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """The point value and a stratified-bootstrap percentile interval of an aggregate metric.

    Each resample draws, for every task separately, as many runs as the task has, with
    replacement (``rliable``'s ``StratifiedBootstrap``); the aggregate is computed on the
    pooled resampled scores.

    Args:
        scores: task -> scores of the runs (e.g. the success rate of each training seed).
        statistic: aggregate of pooled scores, ``statistic(x, axis=-1)`` vectorised like
            ``np.mean`` (rows of ``x`` are resamples); default the IQM.
        confidence: confidence level in (0, 1).
        n_resamples: resamples, >= 100.
        seed: seed of the resampling.

    Returns:
        ``(point, low, high)``.
    """
    _check_confidence(confidence)
    _check_resamples(n_resamples)
    tasks = _task_scores(scores, "scores")
    if statistic is None:

        def statistic(x: np.ndarray, axis: int = -1) -> np.ndarray:
            return scipy.stats.trim_mean(x, 0.25, axis=axis)

    pooled = np.concatenate(list(tasks.values()))
    point = float(statistic(pooled, axis=-1))
    rng = np.random.default_rng(seed)
    parts = [x[rng.integers(0, x.size, size=(n_resamples, x.size))] for x in tasks.values()]
    values = np.asarray(statistic(np.concatenate(parts, axis=1), axis=-1))
    alpha = (1 - confidence) / 2
    low, high = np.quantile(values, [alpha, 1 - alpha])
    return point, float(low), float(high)


def _prob_greater(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``P(X > Y) + P(X = Y) / 2`` between the rows of ``x`` (..., m) and ``y`` (..., n)."""
    diff = x[..., :, None] - y[..., None, :]
    return ((diff > 0) + 0.5 * (diff == 0)).mean(axis=(-2, -1))


def probability_of_improvement(
    x: Mapping[Any, Sequence[float]],
    y: Mapping[Any, Sequence[float]],
    *,
    confidence: float = CONFIDENCE,
    n_resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """The probability that a run of algorithm X scores higher than a run of Y on a task,
    averaged over the tasks both were run on, with a stratified-bootstrap percentile interval
    (the runs of X and of Y resampled independently within each task).

    Per task it is the Mann-Whitney U statistic over ``m n`` (ties count half): 1 when every
    run of X beats every run of Y, 0.5 for identical samples.

    Args:
        x: task -> scores of X's runs.
        y: task -> scores of Y's runs.
        confidence: confidence level in (0, 1).
        n_resamples: resamples, >= 100.
        seed: seed of the resampling.

    Returns:
        ``(point, low, high)``.

    Raises:
        ValueError: no task in common, or bad scores.
    """
    _check_confidence(confidence)
    _check_resamples(n_resamples)
    xs, ys = _task_scores(x, "x"), _task_scores(y, "y")
    common = [t for t in xs if t in ys]
    if not common:
        raise ValueError("x and y have no task in common")
    point = float(np.mean([_prob_greater(xs[t], ys[t]) for t in common]))
    rng = np.random.default_rng(seed)
    per_task = []
    for t in common:
        a, b = xs[t], ys[t]
        ia = rng.integers(0, a.size, size=(n_resamples, a.size))
        ib = rng.integers(0, b.size, size=(n_resamples, b.size))
        step = max(1, 2_000_000 // (a.size * b.size))  # bounded memory for many runs
        per_task.append(
            np.concatenate(
                [
                    _prob_greater(a[ia[i : i + step]], b[ib[i : i + step]])
                    for i in range(0, n_resamples, step)
                ]
            )
        )
    values = np.mean(per_task, axis=0)
    alpha = (1 - confidence) / 2
    low, high = np.quantile(values, [alpha, 1 - alpha])
    return point, float(low), float(high)
