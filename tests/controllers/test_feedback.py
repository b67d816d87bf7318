"""The compiled control tick: partial feedback linearisation, actuator limit, constraint."""

import dataclasses

import numpy as np
import pytest

from controllers.controller import ControllerConfig, TransverseController
from controllers.feedback import (
    constraint_at,
    control_tick,
    feedback_law,
    friction_clip,
    lyapunov_at,
    thetadot_sq_at,
)
from controllers.reduced import pfl_terms
from envs.physics import model


@pytest.fixture(scope="module")
def loaded():
    """A controller with the paper robot's periodic gait loaded (fixed plan)."""
    ctrl = TransverseController("paper", "flat", ControllerConfig(replan=False))
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    return ctrl


def test_feedback_law_matches_partial_feedback_linearisation(loaded, state_from_z):
    """The compiled tick: y_ddot = v through the model, and the actuator limit."""
    ctrl = loaded
    st = ctrl.solution.steps[0]
    th = 0.3 * st.theta_plus + 0.7 * st.theta_minus
    x = state_from_z(st, th, np.array([0.01, 0.002, -0.03]))
    u, I, y, yd, v = feedback_law(ctrl.P, x, *ctrl.gain_table.kernel_args())
    np.testing.assert_allclose([I, y, yd], [0.01, 0.002, -0.03], atol=1e-7)
    c = st.constraint
    n, r = pfl_terms(ctrl.P, *x, c.dphi(th), c.ddphi(th))
    np.testing.assert_allclose(n * u + r, v, rtol=1e-9, atol=1e-9)
    a1, a2 = model.accelerations(ctrl.P, *x, u)
    ydd = a1 - c.dphi(th) * a2 - c.ddphi(th) * x[3] ** 2
    np.testing.assert_allclose(ydd, v, rtol=1e-8, atol=1e-8)
    # a huge gain saturates at the actuator limit (and never returns NaN)
    table = dataclasses.replace(ctrl.gain_table, gains=1e6 * ctrl.gain_table.gains)
    ub = feedback_law(ctrl.P, x, *table.kernel_args())[0]
    assert abs(ub) == ctrl.robot.u_max


def test_control_tick_gives_the_separate_calls_values_exactly(loaded):
    """The controller's one-call tick: feedback_law's (u, I, y, y_dot), the nominal
    theta_dot^2 at the state's phase and V = z' Z^-1 z on the gain grid, bit for bit, on random
    states around the step (before, inside and past it), the friction clip on and off."""
    ctrl = loaded
    sol, g = ctrl.solution, ctrl.gain_table
    st = sol.steps[0]
    rng = np.random.default_rng(7)
    for table in (g, dataclasses.replace(g, friction_limit=0.3, stance_slope=0.1)):
        args = table.kernel_args()
        tab, _, f, df, _ = args
        for _ in range(200):
            th = rng.uniform(st.theta_plus - 0.1, st.theta_minus + 0.1)
            x = np.array([rng.normal(0, 0.3), th, rng.normal(0, 2.0), rng.normal(-1.5, 0.5)])
            z = np.full(3, np.nan)
            u, I, y, yd, ref, V = control_tick(ctrl.P, x, *args, sol.Zinv, z)
            assert (u, I, y, yd) == feedback_law(ctrl.P, x, *args)[:4]
            assert ref == thetadot_sq_at(tab, f, df, x[1])
            assert V == sol.lyapunov(np.array([I, y, yd]), x[1])
            th0, step = sol.theta[0], sol.theta[1] - sol.theta[0]
            assert V == lyapunov_at(sol.Zinv, th0, step, I, y, yd, x[1])
            assert z.tolist() == [I, y, yd]


def test_constraint_and_speed_match_the_step_model_inside_the_step(loaded):
    ctrl = loaded
    st = ctrl.solution.steps[0]
    tab, pc, f, df, _ = ctrl.gain_table.kernel_args()
    for th in np.linspace(st.theta_plus, st.theta_minus, 7):
        np.testing.assert_allclose(constraint_at(tab, pc, th), st.derivatives(th), atol=1e-9)
        assert thetadot_sq_at(tab, f, df, th) == pytest.approx(st.thetadot_sq(th), rel=1e-6)


def test_late_touchdown_blends_the_slope_to_zero(loaded):
    """Past theta- the constraint keeps its value and slope continuous and stops opening the
    legs after late_blend rad."""
    ctrl = loaded
    g = ctrl.gain_table
    tab, pc = g.scalars, g.phi_coeffs
    end = g.theta_plus + g.span
    ph0, dph0, _ = constraint_at(tab, pc, end)
    ph, dph, _ = constraint_at(tab, pc, end + 1e-9)
    assert ph == pytest.approx(ph0, abs=1e-8) and dph == pytest.approx(dph0, rel=1e-6)
    ph, dph, ddph = constraint_at(tab, pc, end + 2 * g.late_blend)
    assert dph == 0.0 and ddph == 0.0
    assert ph == pytest.approx(ph0 + 0.5 * dph0 * g.late_blend, rel=1e-12)


def test_friction_clip_keeps_the_stance_reaction_in_the_cone(loaded, state_from_z):
    """``ControllerConfig.friction_limit``: the input is clipped to the nearest one whose
    stance-foot reaction lies in the friction cone; an input inside it is left alone."""
    ctrl = loaded
    P, umax = ctrl.P, ctrl.robot.u_max
    st = ctrl.solution.steps[0]
    x = state_from_z(st, 0.5 * (st.theta_plus + st.theta_minus), np.array([0.0, 0.004, 0.05]))
    mu = 0.2  # the full input needs about 0.25 at mid-stance: the cone binds on both sides

    def margin(u, slope=0.0):
        nx, ny = model.ground_normal(slope)
        a1, a2 = model.accelerations(P, *x, u)
        fn, ft = model.stance_reaction(P, *x, a1, a2, nx, ny)
        return model.friction_cone_margin(fn, ft, mu)

    us = np.linspace(-umax, umax, 301)
    inside = np.array([margin(u) >= 0 for u in us])
    assert inside.any() and not inside[0] and not inside[-1]
    lo, hi = us[inside].min(), us[inside].max()
    for slope in (0.0, 0.05):
        nx, ny = model.ground_normal(slope)
        for u in us:
            c = friction_clip(P, *x, u, mu, nx, ny, umax)
            assert margin(c, slope) >= -1e-9
            if margin(u, slope) >= 0:
                assert c == u
    for u in (-umax, umax):  # the nearest admissible input: the cone's edge
        c = friction_clip(P, *x, u, mu, *model.ground_normal(0.0), umax)
        assert margin(c) == pytest.approx(0.0, abs=1e-9)
        assert lo - 0.2 < c < lo + 1e-9 if u < 0 else hi - 1e-9 < c < hi + 0.2
    # through the tick: a huge gain stops at the cone's edge instead of the actuator limit
    table = dataclasses.replace(
        ctrl.gain_table, gains=1e6 * ctrl.gain_table.gains, friction_limit=mu
    )
    u = feedback_law(P, x, *table.kernel_args())[0]
    assert abs(u) < umax and margin(u) == pytest.approx(0.0, abs=1e-9)
    # the controller passes its setting to the table (off, 0, by default); 0 clips to the
    # actuator limit only
    assert ctrl.gain_table.friction_limit == ctrl.config.friction_limit == 0.0
    off = dataclasses.replace(table, friction_limit=0.0)
    assert abs(feedback_law(P, x, *off.kernel_args())[0]) == umax
    with pytest.raises(ValueError, match="friction_limit"):
        ControllerConfig(friction_limit=-0.1)
    with pytest.raises(ValueError, match="friction_limit"):
        ControllerConfig(friction_limit=float("inf"))
