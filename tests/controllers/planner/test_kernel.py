"""The planner kernel's contact conditions are the model's: the stance-reaction, impact and
trailing-foot margins it writes are those of :mod:`envs.physics.model` at the step's nodes."""

import math

import numpy as np
import pytest

from controllers import reduced as rd
from controllers.bezier import BezierConstraint
from controllers.planner import TerrainMap
from controllers.planner.problem import CONSTRAINT_GROUPS, FixedStep, StepEvaluator
from envs.physics import Terrain, model

GROUP = {g.name: i for i, g in enumerate(CONSTRAINT_GROUPS)}


@pytest.mark.parametrize("angle", [0.0, 0.06, -0.04])
def test_contact_margins_are_the_model_functions(planners, angle):
    pl = planners["paper"]
    st = pl.periodic_gait().step
    tmap = TerrainMap(Terrain.slope(angle))
    sm = StepEvaluator(pl.params, pl.config, tmap)
    x0 = 0.2
    x1 = x0 + st.step_length
    fx = FixedStep(
        st.theta_plus,
        st.coeffs[0],
        st.slope_plus,
        st.thetadot_plus,
        (x0, tmap.height(x0)),
        (x1, tmap.height(x1)),
        st.theta_minus,
        st.coeffs[-1],
    )
    rng = np.random.default_rng(1)
    free = st.coeffs[2:-1] + 0.02 * rng.standard_normal((4, st.coeffs.size - 3))
    ev = sm.evaluate_batch(fx, free)
    cfg, P, l = sm.settings, sm.P, pl.params.l  # noqa: E741
    nx, ny = model.ground_normal(math.tan(angle))  # the same ground under both feet
    lo = 0.25 * cfg.min_thetadot**2
    thd_ref = max(cfg.min_thetadot, 1e-3)
    th = fx.theta_plus + (fx.theta_minus - fx.theta_plus) * sm.grids.nodes
    n = th.size
    for b in range(free.shape[0]):
        ph, dph, ddph = BezierConstraint(ev["a"][b], fx.theta_plus, fx.theta_minus).derivatives(th)
        f = np.maximum(ev["f"][b], lo)
        thd = np.sqrt(f)
        al, be, ga = rd.reduced_coefficients(P, ph, th, dph, ddph)
        al = np.maximum(al, 0.02 * cfg.alpha_scale)
        q1dd, q2dd = rd.nominal_accelerations(al, be, ga, dph, ddph, f)
        fn, ft = model.stance_reaction(P, ph, th, dph * thd, thd, q1dd, q2dd, nx, ny)
        margin = cfg.friction * fn - np.abs(ft)
        for i in range(n):
            assert model.friction_cone_margin(fn[i], ft[i], cfg.friction) == margin[i]
        stance = ev["groups"][GROUP["stance_reaction"]][b] * cfg.weight
        np.testing.assert_allclose(stance[:n], fn, rtol=1e-9, atol=1e-9 * cfg.weight)
        np.testing.assert_allclose(stance[n:], margin, rtol=1e-9, atol=1e-9 * cfg.weight)
        # impact at the last node: impulse under the foothold, take-off of the trailing foot
        pre = (ph[-1], th[-1], dph[-1] * thd[-1], thd[-1])
        post = model.impact(P, *pre)
        i_n, i_t = model.normal_tangential(*model.impact_impulse(P, *pre, *post), nx, ny)
        sc = cfg.mass * l * thd_ref
        impact = ev["groups"][GROUP["impact"]][b] * sc
        np.testing.assert_allclose(
            impact,
            [i_n, model.friction_cone_margin(i_n, i_t, cfg.friction)],
            rtol=1e-9,
            atol=1e-9 * sc,
        )
        lift = model.trailing_foot_normal_velocity(P, *post, nx, ny)
        trailing = ev["groups"][GROUP["trailing_foot"]][b][0] * l * thd_ref
        assert trailing == pytest.approx(lift, rel=1e-9, abs=1e-9 * l * thd_ref)
