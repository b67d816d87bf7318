"""Basin of attraction of the reference controller around the periodic gait."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers import ControllerConfig
from controllers.basin import (
    DEFAULT_V_TOL,
    NO_STATE,
    BasinSample,
    certified_level,
    converged_fractions,
    periodic_reference,
    perturbed_state,
    run_perturbation,
    sample_basin,
    slice_grid,
)


@pytest.fixture(scope="module")
def ref():
    return periodic_reference("paper")


def test_reference_matrix_and_unperturbed_state(ref):
    assert ref.P == pytest.approx(ref.P.T)
    assert np.all(np.linalg.eigvalsh(ref.P) > 0)
    x = perturbed_state(ref, [0.0, 0.0, 0.0])
    assert x == pytest.approx(np.concatenate([ref.gait.q, ref.gait.qd]), abs=1e-9)
    z = np.array([0.05, -0.02, 0.1])
    assert ref.model.coords(perturbed_state(ref, z)) == pytest.approx(z, abs=1e-9)


def test_zero_perturbation_converges(ref):
    s = run_perturbation(ref, [0.0, 0.0, 0.0], steps=16)
    assert s.converged and s.end == "converged" and s.footsteps == 16
    # the floor of the 5 ms zero-order hold, well inside the convergence tolerance
    assert s.V0 == 0.0 and s.V_end < 0.01 < DEFAULT_V_TOL


def test_convergence_is_measured_in_a_metric_that_does_not_follow_the_weights(ref):
    """V (the ellipsoids) follows the controller's weights, V_c (the convergence test) is the
    paper weights' metric for every controller: the stiff default's walks are judged as the
    paper weights' are."""
    stiff = periodic_reference("paper", ControllerConfig.for_robot("paper"))
    paper = periodic_reference("paper", ControllerConfig())
    assert stiff.config.Q != paper.config.Q and paper.metric is paper.solution
    x = perturbed_state(ref, [0.02, 0.003, -0.05])
    x[1] += 0.3  # a phase late in the step, where the walks end
    assert stiff.convergence_value(x) == pytest.approx(paper.convergence_value(x), rel=1e-12)
    assert stiff.lyapunov(x) > 10 * paper.lyapunov(x)
    s = run_perturbation(stiff, [0.0, 0.0, 0.0], steps=16)
    assert s.converged and s.V_end < 0.01 < DEFAULT_V_TOL


def test_huge_perturbations_fail_or_have_no_state(ref):
    # 5 rad^2/s^2 more theta_dot^2 (2.4 instead of 0.91 rad/s): the degraded plans may keep
    # the walker going for a few footsteps, but far from the gait after them, or it falls
    s = run_perturbation(ref, [5.0, 0.0, 0.0], steps=4)
    assert not s.converged and s.end in ("trip", "slip", "not converged")
    assert s.end != "not converged" or s.V_end > 10.0
    # theta_dot^2 + I <= 0: no such state
    none = run_perturbation(ref, [-10.0, 0.0, 0.0], steps=4)
    assert none.end == NO_STATE and none.footsteps == 0


def test_sampled_perturbations_lie_on_their_ellipsoid(ref):
    samples = sample_basin(ref, [0.05, 0.1], per_radius=2, seed=3, steps=1)
    assert [s.V0 for s in samples] == [0.05**2, 0.05**2, 0.1**2, 0.1**2]
    z = np.array([s.z for s in samples])
    assert np.einsum("ij,jk,ik->i", z, ref.P, z) == pytest.approx([s.V0 for s in samples])
    assert sample_basin(ref, [0.05, 0.1], per_radius=2, seed=3, steps=1) == samples


def _sample(V0: float, converged: bool, end: str | None = None) -> BasinSample:
    return BasinSample(
        (0.0, 0.0, 0.0),
        V0,
        converged,
        4,
        0.0,
        end or ("converged" if converged else "fall"),
        0,
    )


def test_converged_fractions_count_starts_per_size():
    samples = [_sample(1.0, i < 8) for i in range(20)] + [_sample(4.0, True)] * 3
    samples.append(_sample(4.0, False, NO_STATE))
    rows = converged_fractions(samples)
    assert [r["r"] for r in rows] == [1.0, 2.0]
    assert rows[0]["converged"] == 8 and rows[0]["starts"] == 20 and rows[0]["fraction"] == 0.4
    assert rows[1]["starts"] == 3 and rows[1]["no_state"] == 1 and rows[1]["fraction"] == 1.0


def test_certified_level_with_holdout():
    V = np.arange(1.0, 21.0)  # 20 samples, V = 1 .. 20
    failed = V >= 15  # every start with V >= 15 fails; selection: even indices (V odd)
    level = certified_level(V, failed)
    assert level.rho == 15.0 and level.bounded_by_failure
    assert level.selection == 10 and level.certification == 10
    # held-out samples inside V < 15: V = 2, 4, ..., 14
    assert level.inside == 7 and level.failures_inside == 0
    assert level.bound == pytest.approx(1 - 0.05 ** (1 / 7))
    assert level.contains(14.9) and not level.contains(15.0)


def test_certified_level_counts_held_out_failures_and_unbounded_case():
    V = np.array([1.0, 0.5, 3.0, 2.0, 5.0, 4.0])
    failed = np.array([False, True, False, False, True, False])
    level = certified_level(V, failed)  # selection V = 1, 3, 5 (5 failed): rho = 5
    assert level.rho == 5.0 and level.inside == 3 and level.failures_inside == 1
    assert 0 < level.bound < 1
    none = certified_level(V, np.zeros(6, dtype=bool))
    assert not none.bounded_by_failure and none.rho == 5.0 and none.contains(5.0)
    assert none.inside == 3
    whole = certified_level(V, failed, holdout=False)
    assert whole.rho == 0.5 and whole.inside == 0 and whole.bound == 1.0


@pytest.mark.parametrize(
    ("V", "failed", "match"),
    [
        ([1.0], [False], "length"),
        ([1.0, -1.0], [False, False], ">= 0"),
        ([1.0, 2.0], [1], "same length"),
    ],
)
def test_certified_level_rejects_bad_input(V, failed, match):
    with pytest.raises(ValueError, match=match):
        certified_level(V, failed)


def test_run_perturbation_and_slice_reject_bad_input(ref):
    with pytest.raises(ValueError, match="z must be"):
        run_perturbation(ref, [0.0, math.nan, 0.0])
    with pytest.raises(ValueError, match="steps"):
        run_perturbation(ref, [0.0, 0.0, 0.0], steps=0)
    with pytest.raises(ValueError, match="axes"):
        slice_grid(ref, (1, 1), (0.1, 0.1), 3)
    with pytest.raises(ValueError, match="radii"):
        sample_basin(ref, [0.0], 2)
