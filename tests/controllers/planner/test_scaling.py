"""SLSQP in the coordinates of the cost's Gauss-Newton model (``gauss_newton_scaling``): the
same optima in fewer evaluations, and plans that pass the open-loop checks."""

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from controllers.planner import GaitPlanner
from controllers.planner.problem import (
    _SCALING_FLOOR,
    BatchProblem,
)
from controllers.reference import ReferencePolicy

from .cases import CASES, HORIZON, gait_step
from .test_plan import OPEN_LOOP_STEPS, rollout


def _step_problem(pl, shorter: float):
    length = shorter * pl.periodic_gait().step.step_length
    sm, fx, st = gait_step(pl, CASES["paper"]["flat"], length=length)
    calls = []

    def fn(X):
        calls.append(len(X))
        ev = sm.evaluate_batch(fx, X)
        return ev["cost"], ev["g"], ev

    return BatchProblem(fn, residuals=lambda ev: ev["residuals"]), st.coeffs[2:-1], calls


def test_the_scaling_whitens_the_gauss_newton_model(planners):
    """In ``z`` the Gauss-Newton model ``2 J^T J`` (``J`` the residuals' Jacobian) has its
    largest eigenvalue 1 and every eigenvalue above the floor 1: the steep directions are
    whitened, the flattest ones stretched no more than the floor allows."""
    prob, x0, _ = _step_problem(planners["paper"], 0.8)
    T = prob.scaling(x0)
    h = 1e-6
    r0 = prob.residuals(prob.get(x0)[2])[prob.get(x0)[3]]
    J = np.empty((r0.size, x0.size))
    for i in range(x0.size):
        x = x0.copy()
        x[i] += h
        c, g, ev, r = prob.get(x)
        J[:, i] = (prob.residuals(ev)[r] - r0) / h
    H = 2 * J.T @ J
    w = np.linalg.eigvalsh(T.T @ H @ T)
    assert w[-1] == pytest.approx(1.0, rel=1e-4)
    wh = np.linalg.eigvalsh(H)
    np.testing.assert_allclose(w, wh / np.maximum(wh, _SCALING_FLOOR * wh[-1]), rtol=1e-3)
    np.testing.assert_allclose(T, T.T)
    assert BatchProblem(prob.fn).scaling(x0) is None  # no residuals, no scaling


@pytest.mark.parametrize("shorter", [0.7, 0.8, 1.2])
def test_a_scaled_solve_reaches_the_same_optimum_in_fewer_evaluations(planners, shorter):
    """From the gait's shape on a shorter or longer step: both solves end feasible at the same
    cost, the scaled one after fewer batched evaluations."""
    plain, x0, calls_plain = _step_problem(planners["paper"], shorter)
    scaled, _, calls_scaled = _step_problem(planners["paper"], shorter)
    xp = plain.minimize(x0, 60, 1e-7)
    xs = scaled.minimize(x0, 60, 1e-7, scaled=True)
    cp, gp, _, _ = plain.get(xp)
    cs, gs, _, _ = scaled.get(xs)
    assert np.min(gp) >= -1e-7 and np.min(gs) >= -1e-7
    assert cs == pytest.approx(cp, rel=1e-3, abs=1e-6)
    assert plain.get(x0)[0] > 1.2 * cp  # the start was not already optimal
    assert len(calls_scaled) < len(calls_plain)


def test_the_paper_robot_plans_with_scaled_solves_the_classic_walker_without():
    """The paper robot's preset turns the scaling on (held out before it became the default);
    the dataclass and the classic walker keep the coefficients themselves."""
    assert GaitPlanner("paper").config.gauss_newton_scaling == 1
    assert GaitPlanner("classic").config.gauss_newton_scaling == 0
    assert GaitPlanner("paper", {"gauss_newton_scaling": 0}).config.gauss_newton_scaling == 0


@pytest.mark.parametrize("scaling", [0, 1])
@pytest.mark.parametrize("terrain", ["paper_stairs", "blocks_high"])
def test_plans_follow_open_loop_pfl_scaled_or_not(terrain, scaling):
    """The plans made with and without the scaling pass the same checks: the nonlinear model
    under PFL follows them through touchdowns and impacts."""
    pl = GaitPlanner("paper", {"gauss_newton_scaling": scaling})
    g = pl.periodic_gait()
    plan = pl.plan(CASES["paper"][terrain], (g.q, g.qd), (0.0, 0.0), horizon=HORIZON["paper"])
    assert len(plan) == HORIZON["paper"]
    for j, r in enumerate(rollout(pl, plan, CASES["paper"][terrain], OPEN_LOOP_STEPS["paper"])):
        assert r["y"] < 1e-6 and r["thd_err"] < 1e-5 and r["time_err"] < 1e-5, (j, r)
        assert r["foot_err"] < 1e-5, (j, r)


@pytest.mark.parametrize("scaling", [0, 1])
def test_the_reference_policy_walks_scaled_or_not(scaling):
    """In closed loop on rough ground (difficulty 1, a validation course) it walks to the time
    limit, every footstep planned in full, with the default (scaled) and the previous one."""
    env = gym.make("roughwalk/CompassGaitRough-v0", difficulty=1.0)
    policy = ReferencePolicy(env, planner={"gauss_newton_scaling": scaling})
    assert policy.controller.planner.config.gauss_newton_scaling == scaling
    obs, _ = env.reset(seed=1_000_004)
    policy.reset()
    terminated = truncated = False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(policy(obs))
    assert truncated and not terminated
    records = policy.records
    assert len(records) >= 15
    assert all(r.fallback is None for r in records)
    env.close()
