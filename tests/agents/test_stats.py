"""Interval estimates against known values."""

import numpy as np
import pytest

from agents.stats import (
    bootstrap_interval,
    iqm,
    probability_of_improvement,
    stratified_bootstrap,
    wilson_interval,
)


@pytest.mark.parametrize(
    "k, n, low, high",
    [(8, 20, 0.2188, 0.6134), (7, 20, 0.1812, 0.5671), (20, 20, 0.8389, 1.0), (0, 20, 0.0, 0.1611)],
)
def test_wilson_known_values(k, n, low, high):
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=5e-5)
    assert hi == pytest.approx(high, abs=5e-5)


def test_wilson_narrows_with_trials_and_widens_with_confidence():
    w20 = np.diff(wilson_interval(8, 20))[0]
    w200 = np.diff(wilson_interval(80, 200))[0]
    assert w200 < w20 / 2.5
    assert np.diff(wilson_interval(8, 20, 0.99))[0] > w20


@pytest.mark.parametrize(
    "args, match",
    [((21, 20), "successes"), ((1, 0), "trials"), ((1.5, 20), "successes"), ((1, 20, 1.0), "conf")],
)
def test_wilson_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        wilson_interval(*args)


def test_bootstrap_contains_known_mean_and_is_seeded():
    rng = np.random.default_rng(7)
    x = rng.normal(0.0, 1.0, 200)
    x = (x - x.mean()) / x.std() + 3.0  # mean exactly 3, standard deviation 1
    lo, hi = bootstrap_interval(x, seed=1)
    assert lo < 3.0 < hi
    # about 2 * 1.96 * sigma / sqrt(n) wide
    assert hi - lo == pytest.approx(2 * 1.96 / np.sqrt(200), rel=0.2)
    assert bootstrap_interval(x, seed=1) == (lo, hi)


def test_bootstrap_paired_ratio_and_constant_sample():
    work = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    dist = np.array([2.0, 4.0, 6.0, 8.0, 10.0, 12.1])
    lo, hi = bootstrap_interval(
        (work, dist), lambda w, d, axis: w.sum(axis) / d.sum(axis), paired=True
    )
    assert lo <= work.sum() / dist.sum() <= hi
    assert hi - lo < 0.01
    assert bootstrap_interval([2.5] * 10) == (2.5, 2.5)


@pytest.mark.parametrize("data", [[1.0], [1.0, np.nan], [[1.0, 2.0]]])
def test_bootstrap_rejects_bad_samples(data):
    with pytest.raises(ValueError, match="data"):
        bootstrap_interval(data)


def test_iqm_of_known_arrays():
    assert iqm(np.arange(8)) == pytest.approx(3.5)  # mean of 2, 3, 4, 5
    assert iqm([1.0, 1.0, 1.0, 100.0]) == pytest.approx(1.0)  # the outlier is trimmed
    assert iqm({"a": [1, 2, 3, 4], "b": [5, 6, 7, 8]}) == pytest.approx(4.5)  # pooled


def test_stratified_bootstrap_interval():
    scores = {"flat": [0.9, 0.95, 1.0, 0.85], "rough": [0.4, 0.5, 0.6, 0.45]}
    point, lo, hi = stratified_bootstrap(scores, seed=3)
    assert point == pytest.approx(iqm(scores))
    assert lo <= point <= hi
    assert stratified_bootstrap(scores, seed=3) == (point, lo, hi)
    # resampling within each task: a task's runs all equal -> only the other task varies
    p, lo, hi = stratified_bootstrap({"a": [1.0, 1.0], "b": [0.0, 0.0]}, np.mean)
    assert (p, lo, hi) == (0.5, 0.5, 0.5)


def test_probability_of_improvement():
    x = {"flat": [0.9, 0.95, 1.0], "rough": [0.8, 0.7, 0.9]}
    y = {"flat": [0.1, 0.2, 0.3], "rough": [0.0, 0.1, 0.2]}
    assert probability_of_improvement(x, y) == (1.0, 1.0, 1.0)
    assert probability_of_improvement(y, x) == (0.0, 0.0, 0.0)
    p, lo, hi = probability_of_improvement(x, x)
    assert p == 0.5
    assert lo < 0.5 < hi
    # one task each way: 1 on flat, 0 on rough
    p, _, _ = probability_of_improvement({"a": [2.0], "b": [0.0]}, {"a": [1.0], "b": [1.0]})
    assert p == 0.5
    with pytest.raises(ValueError, match="no task in common"):
        probability_of_improvement({"a": [1.0]}, {"b": [1.0]})
