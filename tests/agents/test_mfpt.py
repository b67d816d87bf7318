"""MFPT: the censored geometric estimator, Kaplan-Meier, the hazard check and walks on the
native vector env."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.mfpt import (
    NothingToCount,
    estimate_mfpt,
    geometric_check,
    kaplan_meier,
    markov_mfpt,
    policy_options,
    roughness_terrain,
    run_walks,
)
from controllers import ControllerConfig


def geometric_walks(
    rng: np.random.Generator, p: float, walks: int, cap: int
) -> tuple[np.ndarray, np.ndarray]:
    """Walks of a process failing each footstep with probability ``p``, censored at ``cap``."""
    T = rng.geometric(p, walks)  # footstep of the failure (1, 2, ...)
    failed = T <= cap
    return np.where(failed, T - 1, cap), failed


def test_estimate_recovers_p_under_heavy_censoring():
    rng = np.random.default_rng(0)
    k, d = geometric_walks(rng, 0.05, 400, 30)  # about 21 % of the walks censored
    assert 0.1 < 1 - d.mean() < 0.35
    est = estimate_mfpt(k, d)
    assert est.failures == int(d.sum())
    assert est.exposure == int(k.sum() + d.sum())
    # within 3 standard errors (sqrt(p / exposure) = 0.0027) of the truth
    assert est.p_fail == pytest.approx(0.05, abs=0.0085)
    assert est.p_interval[0] < est.p_fail < est.p_interval[1]
    assert est.mfpt == pytest.approx(1 / est.p_fail)
    assert est.mfpt_interval == pytest.approx((1 / est.p_interval[1], 1 / est.p_interval[0]))
    # ignoring the censored walks would overstate the failure rate
    naive = 1 / (k[d].mean() + 1)
    assert naive > est.p_interval[1]


def test_interval_coverage_near_nominal():
    rng = np.random.default_rng(1)
    p, hits, reps = 0.1, 0, 300
    for _ in range(reps):
        k, d = geometric_walks(rng, p, 30, 15)
        lo, hi = estimate_mfpt(k, d).p_interval
        hits += lo <= p <= hi
    # Clopper-Pearson is conservative: at least the nominal 95 %, up to about 99 %
    assert 0.92 <= hits / reps <= 0.995


def test_all_censored_gives_a_lower_bound_only():
    k = np.array([50, 50, 50, 50])
    d = np.zeros(4, dtype=bool)
    est = estimate_mfpt(k, d)
    assert est.mfpt is None and est.p_fail == 0.0
    assert math.isinf(est.mfpt_interval[1])
    # exact two-sided 95 %: p_hi = 1 - 0.025^(1/200)
    assert est.p_interval[1] == pytest.approx(1 - 0.025 ** (1 / 200), rel=1e-6)
    assert est.lower_bound == pytest.approx(1 / est.p_interval[1])
    assert est.to_dict()["mfpt_interval"][1] is None


def test_kaplan_meier_on_a_small_example():
    km = kaplan_meier([0, 1, 2, 2], [True, False, True, False])
    assert km["step"].tolist() == [1, 2, 3]
    assert km["at_risk"].tolist() == [4, 2, 1]
    assert km["failures"].tolist() == [1, 0, 1]
    assert km["survival"] == pytest.approx([0.75, 0.75, 0.0])


def test_geometric_check_accepts_geometric_and_rejects_a_fixed_failure_step():
    rng = np.random.default_rng(2)
    k, d = geometric_walks(rng, 0.1, 300, 60)
    assert geometric_check(k, d)["p_value"] > 0.01
    # every walk fails at its second footstep (a deterministic fall, not memoryless)
    fixed = geometric_check(np.full(30, 1), np.ones(30, dtype=bool))
    assert fixed["p_value"] < 1e-6
    assert [b["p_fail"] for b in fixed["blocks"]] == [0.0, 1.0]


@pytest.mark.parametrize(
    ("footsteps", "failed", "match"),
    [
        ([1, -1], [True, True], "footsteps"),
        ([1, 2], [True], "same"),
        ([1.5, 2], [True, False], "integers"),
        ([1, 2], [1, 0], "booleans"),
        ([0, 0], [False, False], "no footstep"),
    ],
)
def test_estimator_rejects_bad_input(footsteps, failed, match):
    with pytest.raises(ValueError, match=match):
        estimate_mfpt(np.array(footsteps), np.array(failed))


def test_estimator_rejects_bad_confidence():
    with pytest.raises(ValueError, match="confidence"):
        estimate_mfpt([3], [True], confidence=1.5)


def test_roughness_terrain_spec():
    spec = roughness_terrain(0.01, 50.0)
    assert spec["kind"] == "blocks" and "seed" not in spec
    assert spec["height_range"] == [-0.01, 0.01] and spec["length"] == 50.0
    with pytest.raises(ValueError, match="roughness"):
        roughness_terrain(-0.1, 10.0)


def test_passive_walks_fail_and_do_not_depend_on_the_number_of_walkers():
    a = run_walks("passive", 0.0, 3, walkers=1, step_cap=5, seed=7)
    b = run_walks("passive", 0.0, 3, walkers=3, step_cap=5, seed=7)
    assert a == b
    assert [w.seed for w in a] == [7, 8, 9]
    assert all(w.failed and w.footsteps < 5 for w in a)


def test_pd_walks_are_censored_at_the_cap_and_reproducible():
    a = run_walks("pd", 0.0, 2, walkers=2, step_cap=3, seed=0)
    assert all(not w.failed and w.end == "cap" and w.footsteps == 3 for w in a)
    assert all(w.distance > 0.2 for w in a)
    # the post-impact (theta, theta_dot) of the start and of each footstep: on flat ground
    # the stance leg starts behind the vertical and moving forwards
    for w in a:
        assert len(w.states) == w.footsteps + 1
        assert all(th < 0 < thd for th, thd in w.states[1:])
    b = run_walks("pd", 0.0, 2, walkers=1, step_cap=3, seed=0)
    assert a == b


def test_controller_settings_reach_the_policies():
    """``controller``: ControllerConfig fields of the pd and reference policies."""
    assert policy_options("reference", None) == {}
    # checked here, completed from the robot's defaults by the controller
    (config,) = policy_options("reference", {"Q": [1, 1, 1], "R": 2}).values()
    assert config == {"Q": [1, 1, 1], "R": 2}
    completed = ControllerConfig.for_robot("paper", **config)
    assert completed.Q == (1.0, 1.0, 1.0) and completed.R == 2.0
    for policy, bad, match in (
        ("passive", {"R": 2}, "not to passive"),
        ("reference", {"R": -1}, "ControllerConfig.R"),
        ("pd", {"gain": 1}, "gain"),
    ):
        with pytest.raises(ValueError, match=match):
            policy_options(policy, bad)
    walks = run_walks("reference", 0.0, 1, walkers=1, step_cap=2, controller={"R": 2})
    assert walks[0].footsteps == 2 and not walks[0].failed


def test_planner_settings_reach_the_policies():
    """``planner``: PlannerConfig fields of the pd and reference policies' gait planner."""
    assert policy_options("reference", None, {}) == {}
    opts = policy_options("pd", {"R": 2}, {"clearance": 0.003})
    assert opts == {"config": {"R": 2}, "planner": {"clearance": 0.003}}
    for policy, bad, match in (
        ("passive", {"clearance": 0.003}, "planner: applies to the pd and reference"),
        ("reference", {"clearance": -1.0}, "PlannerConfig.clearance"),
        ("reference", {"reach": 1}, "reach"),
    ):
        with pytest.raises(ValueError, match=match):
            policy_options(policy, None, bad)
    walks = run_walks("reference", 0.0, 1, walkers=1, step_cap=2, planner={"clearance": 0.003})
    assert walks[0].footsteps == 2 and not walks[0].failed


def test_the_identifications_long_segments_reach_the_policies():
    """``long_segment``: the pd and reference policies' identification (0: short segments)."""
    assert policy_options("reference", None, None, 0.0) == {"long_segment": 0.0}
    for policy, bad, match in (
        ("passive", 0.3, "long_segment: applies to the pd and reference"),
        ("reference", 1.5, r"long_segment = 1.5; allowed: a number in \[0, 1\]"),
        ("pd", float("nan"), "long_segment = nan"),
    ):
        with pytest.raises(ValueError, match=match):
            policy_options(policy, None, None, bad)
    walks = run_walks("reference", 0.0, 1, walkers=1, step_cap=2, long_segment=0.0)
    assert walks[0].footsteps == 2 and not walks[0].failed


def test_the_drop_edge_preference_reaches_the_policies():
    """``drop_edge_sd``: the pd and reference policies' footholds away from step-down risers
    while the leg length is uncertain."""
    assert policy_options("pd", None, None, None, 9.0) == {"drop_edge_sd": 9.0}
    for policy, bad, match in (
        ("passive", 9.0, "drop_edge_sd: applies to the pd and reference"),
        ("reference", 11.0, r"drop_edge_sd = 11.0; allowed: a number in \[0, 10"),
        ("pd", "wide", "drop_edge_sd = 'wide'"),
    ):
        with pytest.raises(ValueError, match=match):
            policy_options(policy, None, None, None, bad)
    walks = run_walks("reference", 0.01, 1, walkers=1, step_cap=2, drop_edge_sd=9.0)
    assert walks[0].footsteps == 2 and not walks[0].failed


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"policy": "wander"}, "policy"),
        ({"walks": 0}, "walks"),
        ({"roughness": -0.01}, "roughness"),
        ({"step_cap": 0}, "step_cap"),
        ({"seed": -1}, "seed"),
        ({"max_step_time": 0.0}, "max_step_time"),
    ],
)
def test_run_walks_rejects_bad_arguments(kwargs, match):
    args = {"policy": "passive", "roughness": 0.0, "walks": 1, **kwargs}
    with pytest.raises(ValueError, match=match):
        run_walks(args.pop("policy"), args.pop("roughness"), args.pop("walks"), **args)


def chain_walks(rng, T, fail, values, walks, cap):
    """Walks of a Markov chain over cells with values ``values`` (theta_dot; theta 0),
    transitions ``T`` and failure probabilities ``fail`` per cell, censored at ``cap``."""
    states, failed = [], []
    for _ in range(walks):
        c = int(rng.integers(len(values)))
        xs, f = [(0.0, values[c])], False
        for _ in range(cap):
            r = rng.random()
            if r < fail[c]:
                f = True
                break
            c = int(rng.choice(len(values), p=T[c] / T[c].sum()))
            xs.append((0.0, values[c]))
        states.append(np.array(xs))
        failed.append(f)
    return states, np.array(failed)


def test_markov_mfpt_recovers_a_known_chain():
    """Two post-impact cells, one slow and risky, one fast and safe: the chain's MFPT
    ``1 / (1 - lambda_2)`` and each cell's failure probability are recovered from censored
    walks."""
    rng = np.random.default_rng(1)
    fail = np.array([0.2, 0.02])
    T = np.array([[0.3, 0.5], [0.2, 0.78]])  # rows + fail = 1
    lam = max(abs(np.linalg.eigvals(T)))
    states, failed = chain_walks(rng, T, fail, [0.5, 1.5], 1500, 60)
    est = markov_mfpt(states, failed, bins=(1, 2), bootstrap=200)
    assert est.cells == 2 and est.lambda_2 == pytest.approx(lam, abs=0.01)
    assert est.mfpt == pytest.approx(1 / (1 - lam), rel=0.1)
    assert est.mfpt_interval[0] < est.mfpt < est.mfpt_interval[1]
    assert est.p_fail == pytest.approx(list(fail), abs=0.02)


def test_markov_mfpt_of_one_cell_is_the_geometric_estimate():
    rng = np.random.default_rng(2)
    k, d = geometric_walks(rng, 0.05, 300, 30)
    states = [np.column_stack([np.zeros(n + 1), np.ones(n + 1)]) for n in k]
    est = markov_mfpt(states, d, bins=(1, 1), bootstrap=100)
    assert est.cells == 1
    assert est.mfpt == pytest.approx(estimate_mfpt(k, d).mfpt, rel=1e-12)
    # no failure: only censored walks, no finite MFPT
    none = markov_mfpt(states, np.zeros(len(states), dtype=bool), bins=(1, 1), bootstrap=100)
    assert none.mfpt is None and none.lambda_2 == 1.0 and none.mfpt_interval[1] == math.inf


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"failed": [True]}, "one boolean per walk"),
        ({"bins": (0, 2)}, "bins"),
        ({"bootstrap": 10}, "bootstrap"),
        ({"states": [np.ones((3, 3)), np.ones((2, 3))]}, "states"),
        ({"states": [np.full((2, 2), np.nan), np.ones((2, 2))]}, "finite"),
    ],
)
def test_markov_mfpt_rejects_bad_input(kwargs, match):
    args = {"states": [np.ones((3, 2)), np.ones((2, 2))], "failed": [True, False]}
    with pytest.raises(ValueError, match=match):
        markov_mfpt(**{**args, **kwargs})


def test_markov_mfpt_without_anything_to_count_is_a_clear_error():
    """Censored walks whose footsteps all end in cells never left: no chain to estimate."""
    states = [np.array([[0.0, 1.0], [0.1, 2.0]]), np.array([[0.2, 3.0]])]
    with pytest.raises(NothingToCount, match="nothing to estimate"):
        markov_mfpt(states, [False, False], bins=(2, 2), bootstrap=100)
    assert issubclass(NothingToCount, ValueError)
