"""Planned steps: feasibility of the planned steps, impact invariance, open-loop validation in
the nonlinear model and in the hybrid simulator."""

import math

import numpy as np
import pytest
from numpy.polynomial import Polynomial
from scipy.integrate import solve_ivp

from controllers import reduced as rd
from controllers.bezier import bezier
from controllers.planner import TerrainMap
from envs.physics import model

from .cases import ALL_CASES, CASES, HORIZON

# steps validated open loop: with no feedback the integration error grows by the impacts (about
# 10x per step for the paper robot, 40x for the classic walker's faster gait)
OPEN_LOOP_STEPS = {"paper": 5, "classic": 4}


@pytest.mark.parametrize("robot,terrain", ALL_CASES)
def test_plans_satisfy_the_step_constraints(planners, plans, robot, terrain):
    pl, plan = planners[robot], plans[robot, terrain]
    cfg, P, l = pl.config, pl.P, pl.params.l  # noqa: E741
    tmap = TerrainMap(CASES[robot][terrain])
    assert len(plan) == HORIZON[robot]
    prev = None
    for s in plan:
        fx, fy = s.foothold
        assert fy == pytest.approx(tmap.height(fx))
        assert tmap.distance_to_feature(np.array([fx]))[0] >= cfg.edge_margin - 1e-12
        assert cfg.step_min - 1e-9 <= s.step_length <= cfg.step_max + 1e-9
        # the swing foot reaches the foothold with both legs straight
        ex, ey = model.swing_foot_position(P, s.coeffs[-1], s.theta_minus, *s.stance_foot)
        assert (ex, ey) == pytest.approx(s.foothold, abs=1e-12)
        th = np.linspace(s.theta_plus, s.theta_minus, 301)
        assert np.min(s.thetadot_sq(th)) >= 0.98 * cfg.min_thetadot**2  # nodes: >= 1
        # the input bound holds on the planner's grid nodes; between them within a few percent
        assert np.max(np.abs(s.input(th))) <= cfg.torque_fraction * pl.params.u_max * 1.03
        assert cfg.duration_min - 1e-6 <= s.duration <= cfg.duration_max + 1e-6
        # swing foot above the ground once armed, retracted foot above it before
        ph = s.phi(th)
        x_full, y_full = model.swing_foot_position(P, ph, th, *s.stance_foot)
        x_ret, y_ret = model.swing_foot_position(P, ph, th, *s.stance_foot, pl.params.retract * l)
        armed = np.maximum.accumulate(x_full - s.stance_foot[0] >= pl.params.arm_distance * l)
        assert np.all(y_ret[~armed] > tmap.height(x_ret[~armed]))
        assert np.all((y_full - tmap.height(x_full))[armed][:-1] > 0)
        # touchdown transversal: the foot moves down into the ground
        q, qd = s.pre_impact_state()
        assert model.swing_foot_velocity(P, q[0], q[1], qd[0], qd[1])[1] < 0
        if prev is not None:  # consecutive steps chain through the impact map
            q, qd = prev.post_impact_state()
            assert s.stance_foot == prev.foothold
            assert s.theta_plus == pytest.approx(q[1], abs=1e-14)
            assert s.thetadot_plus == pytest.approx(qd[1], rel=1e-12)
        prev = s


@pytest.mark.parametrize("robot,terrain", ALL_CASES)
def test_impact_invariance_holds_to_numerical_precision(plans, robot, terrain):
    """After each nominal impact, y = q1 - phi_{j+1}(q2) and its rate vanish."""
    plan = plans[robot, terrain]
    for a, b in zip(plan.steps, plan.steps[1:]):
        q, qd = a.post_impact_state()
        y = q[0] - b.phi(q[1])
        yd = qd[0] - b.dphi(q[1]) * qd[1]
        assert abs(y) < 1e-13
        assert abs(yd) < 1e-12 * max(1.0, abs(qd[1]))
    q0, qd0 = plan.initial_state()
    assert q0[0] - plan.phi(0, q0[1]) == pytest.approx(0.0, abs=1e-14)


def _poly(step):
    """phi as a power-series polynomial in theta (exact conversion of the Bezier curve)."""
    s = np.linspace(0.0, 1.0, step.coeffs.size)
    th = step.theta_plus + s * (step.theta_minus - step.theta_plus)
    p = Polynomial.fit(th, bezier(step.coeffs, s), step.coeffs.size - 1)
    return p, p.deriv(), p.deriv(2)


def rollout(planner, plan, terrain, nsteps):
    """Enforce each step's constraint exactly (PFL, v = 0) in the nonlinear model and locate
    touchdowns of the armed full-length swing foot (retractable-foot rule)."""
    P, l = planner.P, planner.params.l  # noqa: E741
    arm = planner.params.arm_distance * l
    tmap = TerrainMap(terrain)
    q, qd = plan.initial_state()
    x = np.array([q[0], q[1], qd[0], qd[1]])
    stance = plan[0].stance_foot
    out = []
    for j in range(nsteps):
        step = plan[j]
        p0, p1, p2 = _poly(step)

        def rhs(t, z, p1=p1, p2=p2):
            q1, q2, w1, w2 = z
            n, r = rd.pfl_terms(P, q1, q2, w1, w2, p1(q2), p2(q2))
            a1, a2 = model.accelerations(P, q1, q2, w1, w2, -r / n)
            return [w1, w2, a1, a2]

        def touchdown(t, z, stance=stance):
            fx, fy = model.swing_foot_position(P, z[0], z[1], stance[0], stance[1])
            return fy - tmap.height(fx) if fx - stance[0] >= arm else 1.0

        touchdown.terminal, touchdown.direction = True, -1
        sol = solve_ivp(
            rhs,
            (0.0, 2 * step.duration),
            x,
            events=touchdown,
            rtol=1e-12,
            atol=1e-13,
            method="DOP853",
            dense_output=True,
        )
        assert sol.status == 1, f"no touchdown in step {j}"
        t_td = sol.t_events[0][0]
        tt = np.linspace(0.0, t_td, 200)
        z = sol.sol(tt)
        xm = sol.y_events[0][0]
        foot = model.swing_foot_position(P, xm[0], xm[1], *stance)
        out.append(
            {
                "y": np.max(np.abs(z[0] - p0(z[1]))),
                "thd_err": np.max(np.abs(z[3] - step.thetadot(z[1]))),
                "time_err": abs(t_td - step.duration),
                "theta_err": abs(xm[1] - step.theta_minus),
                "foot_err": math.hypot(foot[0] - step.foothold[0], foot[1] - step.foothold[1]),
            }
        )
        x = np.array(model.impact(P, *xm))
        stance = (float(foot[0]), float(foot[1]))
        if j + 1 < nsteps:  # transverse state relative to the next step right after impact
            nxt = plan[j + 1]
            out[-1]["y_plus"] = x[0] - nxt.phi(x[1])
            out[-1]["yd_plus"] = x[2] - nxt.dphi(x[1]) * x[3]
    return out


@pytest.mark.parametrize("robot,terrain", ALL_CASES)
def test_open_loop_pfl_follows_the_plan(planners, plans, robot, terrain):
    n = OPEN_LOOP_STEPS[robot]
    res = rollout(planners[robot], plans[robot, terrain], CASES[robot][terrain], nsteps=n)
    for j, r in enumerate(res):
        assert r["y"] < 1e-6, (j, r)  # the constraint holds (integration error only)
        assert r["thd_err"] < 1e-5, (j, r)  # theta_dot(theta) as planned
        assert r["time_err"] < 1e-5, (j, r)  # step duration as planned
        assert r["theta_err"] < 1e-5, (j, r)  # touchdown at theta_minus ...
        assert r["foot_err"] < 1e-5, (j, r)  # ... on the planned foothold
        if "y_plus" in r:
            assert abs(r["y_plus"]) < 1e-6 and abs(r["yd_plus"]) < 1e-5, (j, r)


@pytest.mark.parametrize("robot,terrain", [("paper", "paper_stairs"), ("classic", "stairs_up")])
def test_plan_is_walkable_in_the_hybrid_simulator(planners, plans, robot, terrain):
    """The project's simulator (retractable feet, located touchdowns, impact and friction
    checks) with the constraints enforced by PFL plus light PD on y (zero-order hold at 1 ms):
    no trip, slip or stuck impact, and touchdowns on the planned footholds."""
    from envs import SimConfig, simulate

    pl, plan = planners[robot], plans[robot, terrain]
    P, n_steps = pl.P, 6
    current = {"j": 0, "q1": plan.initial_state()[0][0]}

    def torque(t, q, qd):
        if current["q1"] > 0.1 and q[0] < -0.1:  # q1 jumps from + to - at an impact
            current["j"] += 1
        current["q1"] = q[0]
        step = plan[min(current["j"], len(plan) - 1)]
        ph, dph, ddph = step.constraint.derivatives(q[1])
        n, r = rd.pfl_terms(P, q[0], q[1], qd[0], qd[1], dph, ddph)
        v = -400.0 * (q[0] - ph) - 40.0 * (qd[0] - dph * qd[1])
        return float(model.input_gain(P) * (v - r) / n)

    q0, qd0 = plan.initial_state()
    T = float(plan.durations[:n_steps].sum()) - 0.5 * plan.durations[n_steps - 1]
    res = simulate(
        robot, CASES[robot][terrain], q0, qd0, T, torque, dt=1e-3, config=SimConfig.accurate()
    )
    assert res.failure is None
    assert len(res.footholds) == n_steps - 1
    # no replanning in between: the landing error grows from step to step (1.5 % of l)
    atol = 0.015 * pl.params.l
    np.testing.assert_allclose(res.footholds, plan.footholds[: n_steps - 1], atol=atol)
    np.testing.assert_allclose(
        np.diff(np.r_[0.0, res.impact_times]), plan.durations[: n_steps - 1], rtol=0.05
    )


def test_planned_arming_phase_matches_the_simulator(planners, plans):
    """The planner applies the simulator's retractable-foot rule: the swing foot is armed where
    it gets ahead by the arming distance (located between check points, where the full-length
    foot must already clear the ground), so the simulator arms it at the planned phase."""
    from envs import SimConfig
    from envs.physics.simulator import Simulator

    pl, plan = planners["paper"], plans["paper", "blocks_high"]
    P = pl.P
    sim = Simulator("paper", CASES["paper"]["blocks_high"], dt=2e-4, config=SimConfig.accurate())
    sim.reset(*plan.initial_state())
    for step in list(plan)[:3]:
        armed_at = None
        for _ in range(20000):
            q, qd = sim.q[0], sim.qd[0]
            ph, dph, ddph = step.constraint.derivatives(q[1])
            n, r = rd.pfl_terms(P, q[0], q[1], qd[0], qd[1], dph, ddph)
            v = -400.0 * (q[0] - ph) - 40.0 * (qd[0] - dph * qd[1])
            ev = sim.step(float(model.input_gain(P) * (v - r) / n))
            if armed_at is None and sim.armed[0]:
                armed_at = float(sim.q[0][1])
            if ev.n_impacts[0] or ev.status[0]:
                break
        assert ev.status[0] == 0 and ev.n_impacts[0] == 1
        assert armed_at == pytest.approx(step.arm_theta, abs=5e-4)


@pytest.mark.parametrize("robot,terrain", [("paper", "paper_stairs"), ("classic", "flat")])
def test_a_step_plans_profile_is_the_reduced_dynamics_of_its_constraint(plans, robot, terrain):
    """Each planned step's nominal profile (compiled in one call) is, to the last bit, what
    :mod:`controllers.reduced`'s functions give on its grid: ``psi, Gam``, ``theta_dot^2``,
    the time, the input and the impact's gain and slope."""
    for st in plans[robot, terrain].steps:
        th = st.theta_grid
        ph, dph, ddph = st.constraint.derivatives(th)
        a, b, g = rd.reduced_coefficients(st.P, ph, th, dph, ddph)
        psi, gam = rd.reduced_integral(th, a, b, g)
        f = psi * st.thetadot_plus**2 + gam
        assert np.array_equal(st.psi_grid, psi) and np.array_equal(st.gam_grid, gam)
        assert np.array_equal(st.thetadot_sq_grid, f)
        assert np.array_equal(st.time_grid, rd.step_time(th, f))
        assert np.array_equal(st.input_grid, rd.nominal_input(st.P, ph, th, dph, ddph, np.sqrt(f)))
        delta, slope = rd.impact_along_constraint(st.P, ph[-1], dph[-1])
        assert (st.delta, st.slope_plus) == (float(delta), float(slope))
