"""Transverse controller in closed loop with the hybrid simulator (state feedback)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from controllers.controller import (
    MODES,
    ControllerConfig,
    PDController,
    StepRecord,
    TransverseController,
)
from controllers.feedback import feedback_law
from envs import simulate
from envs.physics import model
from envs.physics.simulator import Simulator
from envs.physics.terrain import Terrain

DT = 0.001  # control period of these tests [s]
V_FLOOR = 0.01  # V reachable with a 1 ms zero-order hold (discretisation floor)
RATE_BOUND = 0.8  # asserted bound on the per-step contraction of sqrt(V) = |x_perp|_P
#: the paper's feedback weights without the friction clip (the README's certificate figures)
PAPER_WEIGHTS = {"Q": (1.0, 1.0, 1.0), "friction_limit": 0.0}
#: the feedback weights the closed-loop tests run with: the paper's, and the robot's defaults
WEIGHTS = {"paper": PAPER_WEIGHTS, "default": None}

TERRAINS = {
    "flat": Terrain.flat(),
    "paper_stairs": Terrain.from_yaml(
        __import__("configs").CONFIG_DIR / "terrains" / "paper_stairs.yaml"
    ),
    # the paper's course mirrored (what the gait planner plans for the paper robot)
    "stairs_up": Terrain.stairs([0.4, 0.62], [0.005, 0.005]),
    # a fixed course of blocks (up and down by 5 to 12 mm), spelt out so that it does not
    # depend on the random generator
    "blocks": Terrain.stairs([0.35, 0.62, 0.9, 1.2, 1.45], [0.008, -0.012, 0.006, -0.01, 0.005]),
}


def state_from_z(step, theta, z):
    """State at phase ``theta`` whose transverse coordinates relative to ``step`` are ``z``."""
    c = step.constraint
    td = math.sqrt(step.thetadot_sq(theta) + z[0])
    return np.array([c.phi(theta) + z[1], theta, c.dphi(theta) * td + z[2], td])


def closed_loop(
    cls, terrain, z0, steps, replan=False, robot="paper", end=None, weights=None, **kwargs
):
    """Plan from the nominal start, start perturbed by ``z0`` in transverse coordinates, run
    ``steps`` footsteps. Returns (failure, records); ``end`` (a dict) receives the final
    stance-foot position; ``weights``: ControllerConfig fields that differ from the robot's
    defaults (e.g. PAPER_WEIGHTS)."""
    config = ControllerConfig.for_robot(
        robot, replan=replan, plan_steps=steps + 3, **(weights or {})
    )
    ctrl = cls(robot, terrain, config, **kwargs)
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    x0 = state_from_z(ctrl.solution.steps[0], gait.q[1], np.asarray(z0, float))
    np.testing.assert_allclose(ctrl.coords(x0[:2], x0[2:]), z0, atol=1e-9)
    sim = Simulator(ctrl.robot, ctrl.terrain, 1, dt=DT)
    sim.reset(x0[:2], x0[2:])
    b = model.input_gain(ctrl.P)  # hip torque per input unit [N m]
    while len(ctrl.records) <= steps:
        u = ctrl.control(sim.q[0].copy(), sim.qd[0].copy())
        ev = sim.step(b * u)
        if end is not None:
            end["stance"] = tuple(sim.stance_foot[0])
        if ev.status[0]:
            return sim.failure(0), ctrl.records
        assert sim.t[0] < 3.0 * steps, "no impact: the walker stalled"
        if ev.n_impacts[0]:
            ctrl.on_impact(sim.q[0].copy(), sim.qd[0].copy(), tuple(sim.stance_foot[0]), sim.t[0])
    return None, ctrl.records[:-1]


#: what a step that left the plan's tube and was replanned within may report as its fallback
TUBE_REPLANNED = ("relaxed: duration_min=0.05, torque_fraction=1", "previous plan")


def tube_replanned(rec):
    """Whether ``rec`` is a step replanned within (the state left the plan's tube), with the
    tube's relaxation or, if that failed, the plan it was on."""
    return rec.retargets > 0 and rec.fallback in TUBE_REPLANNED


def contraction_rate(values):
    """Per-step contraction of a positive sequence (least-squares fit of its logarithm)."""
    k = np.arange(len(values))
    return float(np.exp(np.polyfit(k, np.log(values), 1)[0]))


FLAT_CASES = {
    "slower": (-0.15, 0.0, 0.0),
    "slower-small": (-0.075, 0.0, 0.0),
    "faster": (0.15, 0.0, 0.0),
    "swing-rate+": (0.0, 0.0, 0.3),
    "swing-rate-": (0.0, 0.0, -0.3),
    "mixed": (0.1, -0.01, 0.2),
}


@pytest.mark.parametrize("weights", list(WEIGHTS))
@pytest.mark.parametrize("name", list(FLAT_CASES))
def test_flat_converges_from_perturbed_starts(name, weights):
    z0 = FLAT_CASES[name]
    failure, recs = closed_loop(TransverseController, "flat", z0, steps=7, weights=WEIGHTS[weights])
    assert failure is None
    assert all(r.fallback is None for r in recs)
    V = np.array([r.V_start for r in recs])
    # |x_perp| in the controller's own norm sqrt(V) contracts step after step
    above = V > V_FLOOR
    assert above[0]
    if weights == "paper":
        assert above.sum() >= 2
    if above.sum() >= 2:
        rate = contraction_rate(np.sqrt(V[above]))
        assert rate < RATE_BOUND, f"{name}: per-step contraction {rate:.3f}"
    else:  # the stiff default feedback reaches the floor within one footstep (y_dot starts)
        assert V[1] < 0.01 * V[0]
    assert np.all(np.diff(V[above]) < 0)
    assert V[-1] < 0.1 * V[0]
    # V decreases along every continuous phase (up to the zero-order-hold floor)
    for r in recs:
        if r.V_start > V_FLOOR:
            assert r.V_end < r.V_start
            assert r.V_increase < 0.03 * r.V_start
    # the speed error is removed: I at the last step start is small
    assert abs(recs[-1].xperp_start[0]) < 0.15 * max(abs(z0[0]), 0.05)


def test_first_step_solution_is_a_lyapunov_function():
    """V = z' Z^-1 z along the first step is non-increasing tick by tick (1 ms hold)."""
    failure, recs = closed_loop(TransverseController, "flat", (-0.1, 0.005, 0.1), steps=2)
    assert failure is None
    r = recs[0]
    assert r.V_end < 0.9 * r.V_start
    assert r.V_increase < 0.005 * r.V_start  # largest rise between two ticks


# start perturbations z0 = (I, y, y_dot) per course; on the blocks they are smaller because a
# fixed plan keeps only a few millimetres of clearance over the block faces
FIXED_PLAN_CASES = {
    "paper_stairs": ((-0.1, 0.0, 0.0), (0.1, 0.0, 0.1)),
    "stairs_up": ((-0.08, 0.0, 0.0), (0.08, 0.0, 0.1)),
    "blocks": ((-0.04, 0.0, 0.0), (0.05, 0.0, 0.1)),
}


@pytest.mark.parametrize("weights", list(WEIGHTS))
@pytest.mark.parametrize("terrain", list(FIXED_PLAN_CASES))
def test_rough_terrain_tracks_a_fixed_plan_from_perturbed_starts(terrain, weights):
    for z0 in FIXED_PLAN_CASES[terrain]:
        failure, recs = closed_loop(
            TransverseController, TERRAINS[terrain], z0, steps=7, weights=WEIGHTS[weights]
        )
        assert failure is None, f"{terrain} {z0}: {failure}"
        assert all(r.fallback is None for r in recs), [r.reason for r in recs]
        V = np.array([r.V_start for r in recs])
        # sqrt(V) shrinks by RATE_BOUND per step or better over the first four steps (or V is
        # down at the discretisation floor), and ends at the floor
        assert V[4] < max(RATE_BOUND**8 * V[0], V_FLOOR)
        if weights == "paper":
            assert V[-1] < V_FLOOR
        else:  # the stiff weights' P weighs y far more: the hold leaves a higher floor
            assert V[-1] < max(V_FLOOR, 0.02 * V[0])
        for r in recs:  # V decreases along each step while well above the floor
            if r.V_start > 5 * V_FLOOR:
                assert r.V_end < r.V_start
                assert r.V_increase < 0.1 * r.V_start


@pytest.mark.parametrize("terrain", ["flat", "paper_stairs", "stairs_up", "blocks"])
def test_replanning_walks_rough_terrain_from_perturbed_starts(terrain):
    for z0 in ((-0.1, 0.005, -0.1), (0.08, -0.005, 0.1)):
        failure, recs = closed_loop(
            TransverseController, TERRAINS[terrain], z0, steps=5, replan=True
        )
        assert failure is None, f"{terrain} {z0}: {failure}"
        # the planner may fail now and then (its foothold rules near stair edges); the
        # controller then carries on with the rest of the previous plan; after a replanning
        # search cut by its evaluation budget, with a shorter look-ahead or a relaxed plan
        assert all(
            r.fallback in (None, "previous plan")
            or tube_replanned(r)
            or (
                r.budget_exhausted
                and r.fallback not in ("PD on the last planned step", "hold posture", "zero input")
            )
            for r in recs
        ), [(r.fallback, r.reason) for r in recs]
        # each replanned step starts on its plan and stays close to it
        for r in recs[1:]:
            if r.fallback is None:
                assert np.abs(r.xperp_start[:2]).max() < 1e-6
            assert r.max_abs_y < 0.05


def test_classic_walker_climbs_stairs_from_perturbed_starts():
    """The classic walker (1 m legs) up two 1 cm rises with replanning at every footstep, with
    its defaults, the paper's weights (the paper robot's stiffer ones stall or slip on 5 of 16
    slow starts of this robot, I = -0.12 to -0.08, where the paper's walk all 16)."""
    stairs = Terrain.staircase(1.0, 3, 1.0, 0.01)
    for z0 in ((-0.1, 0.005, -0.1), (0.08, -0.005, 0.1)):
        end: dict = {}
        failure, recs = closed_loop(
            TransverseController,
            stairs,
            z0,
            steps=10,
            replan=True,
            robot="classic",
            end=end,
        )
        assert failure is None, f"{z0}: {failure}"
        assert all(r.fallback not in ("hold posture", "zero input") for r in recs), [
            r.reason for r in recs
        ]
        assert max(r.max_abs_y for r in recs) < 0.1
        assert end["stance"][1] == pytest.approx(0.02)  # on the second tread
        assert min(r.thetadot_start for r in recs) > 0.5  # never near a stall


def test_terrain_given_at_reset_replaces_the_one_given_at_construction():
    stairs = TERRAINS["stairs_up"]
    built = TransverseController("paper", stairs, ControllerConfig(replan=False, plan_steps=4))
    moved = TransverseController("paper", "flat", ControllerConfig(replan=False, plan_steps=4))
    gait = built.planner.periodic_gait()
    built.reset(gait.q, gait.qd)
    moved.reset(gait.q, gait.qd, terrain=stairs)
    assert moved.terrain is stairs
    for a, b in zip(built.plan.steps, moved.plan.steps, strict=True):
        np.testing.assert_array_equal(a.constraint.coeffs, b.constraint.coeffs)
        assert a.foothold == b.foothold
    np.testing.assert_array_equal(built.gain_table.gains, moved.gain_table.gains)


def test_config_validation():
    with pytest.raises(ValueError, match="horizon"):
        ControllerConfig(horizon=0)
    with pytest.raises(ValueError, match="R"):
        ControllerConfig(R=0.0)
    with pytest.raises(ValueError, match="unknown"):
        ControllerConfig.from_dict({"horizn": 3})
    with pytest.raises(ValueError, match="PD gains"):
        PDController("paper", "flat", kp=-1.0)


def test_value_of_feedback_on_the_paper_stairs():
    """Named case "paper stairs, slower start": one fixed plan over the paper's course, started
    with the speed along the motion off by I = -0.1 rad^2/s^2 (theta_dot about 0.78 instead of
    0.84 rad/s at the start), planned without the speed reserve before drops
    (``end_thetadot_floor = 0``; with it PD walks this case too). Plain PD on y leaves the speed
    error to the hybrid zero dynamics and the robot falls (trips or slips) on the way down the
    stairs; the transverse controller walks nine steps, down both stairs and on, and removes
    90 % of the speed error."""
    stairs = TERRAINS["paper_stairs"]
    z0 = (-0.1, 0.0, 0.0)
    bare = {"end_thetadot_floor": 0.0}
    failure, recs = closed_loop(TransverseController, stairs, z0, steps=9, planner=bare)
    assert failure is None
    assert all(r.fallback is None for r in recs)
    assert abs(recs[-1].xperp_end[0]) < 0.1 * abs(z0[0])
    failure_pd, recs_pd = closed_loop(PDController, stairs, z0, steps=7, planner=bare)
    assert failure_pd in ("trip", "slip", "fall")
    assert len(recs_pd) < 7


def test_usable_as_torque_callable_of_simulate():
    """envs.simulate(..., torque=controller): impacts detected from the state, replanning."""
    ctrl = TransverseController("paper", "flat")
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    res = simulate("paper", "flat", gait.q, gait.qd + np.array([0.0, 0.05]), 4.0, ctrl, dt=0.002)
    assert res.failure is None
    assert len(res.impact_times) >= 4
    assert len(ctrl.records) == len(res.impact_times) + 1
    # the located footholds agree with the simulator's to a few millimetres
    assert all(r.fallback is None for r in ctrl.records[1:])
    assert np.abs(np.array([ctrl.plan.steps[0].stance_foot[0]]) - res.footholds[-1, 0]).max() < 5e-3
    assert np.max(np.abs(res.torque)) <= ctrl.robot.tau_max + 1e-12


def test_rollout_helper_with_exact_footholds():
    ctrl = TransverseController("paper", "flat")
    gait = ctrl.planner.periodic_gait()
    out = ctrl.rollout(gait.q, gait.qd + np.array([0.1, -0.05]), 10.0, dt=0.002, steps=4)
    assert out["failure"] is None and len(out["impacts"]) == 4
    assert out["q"].shape == out["qd"].shape == (out["t"].size, 2)
    assert np.abs(out["u"]).max() <= ctrl.robot.u_max
    recs = out["records"]
    assert len(recs) == 5 and all(r.fallback is None for r in recs)
    assert all(r.riccati_time < 0.1 for r in recs[:-1])


# ---------------------------------------------------------------- the certificate per footstep
CERT_Z0 = (-0.1, 0.0, 0.0)  # start 0.1 rad^2/s^2 below the planned theta_dot^2


@pytest.mark.parametrize("terrain", ["flat", "paper_stairs"])
def test_fixed_plan_lyapunov_value_falls_from_footstep_to_footstep(terrain):
    """Fixed plan (the paper's Appendix A setting): V = x_perp' P x_perp, P = Z^-1 of each
    step's own jump-Riccati solve, falls along every step and from each step's start to the
    next, from a perturbed start, while above the 1 ms hold's floor. The paper's weights (the
    README's figures); the default weights in the next test."""
    failure, recs = closed_loop(
        TransverseController, TERRAINS[terrain], CERT_Z0, steps=6, weights=PAPER_WEIGHTS
    )
    assert failure is None and all(r.fallback is None for r in recs)
    # V at the first tick uses P of the first solve at theta+ (the tick is at theta+ exactly)
    ctrl = TransverseController(
        "paper",
        TERRAINS[terrain],
        ControllerConfig.for_mode("fixed-plan", plan_steps=9, **PAPER_WEIGHTS),
    )
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    z0 = np.asarray(CERT_Z0)
    assert recs[0].V_start == pytest.approx(z0 @ ctrl.solution.Zinv[0] @ z0, rel=1e-6)
    V_start = np.array([r.V_start for r in recs])
    V_end = np.array([r.V_end for r in recs])
    if terrain == "flat":
        assert V_start[0] == pytest.approx(0.686, abs=0.005)
        # along each step: V_end / V_start 0.53-0.86; across each impact V does not rise
        assert all(0.5 < r.V_ratio < 0.9 for r in recs)
        assert np.all(V_start[1:] < V_end[:-1])
        # from one step's start to the next: V falls by more than half (sqrt(V) by 0.68)
        assert np.all(V_start[1:] / V_start[:-1] < 0.5)
        norms = [r.max_xperp_norm for r in recs]
        assert 0.1 <= norms[0] < 0.14 and np.all(np.diff(norms) < 0)
        # inside the planner's torque reserve (0.8 of the actuator limit, 15)
        assert max(r.max_abs_u for r in recs) < 0.8 * ctrl.robot.u_max
    else:
        assert V_start[0] == pytest.approx(0.278, abs=0.005)
        # the steps before the stairs are planned close to the actuator limit (up to 12 of 15,
        # and u_max at times, depending on the plan's last bits), so V settles at the hold's
        # floor (about 0.005) after four steps instead of falling on
        above = V_start > V_FLOOR
        assert above.sum() == 3
        assert all(r.V_ratio < 0.95 for r, a in zip(recs, above, strict=True) if a)
        assert 8.0 < max(r.max_abs_u for r in recs) <= ctrl.robot.u_max
    # V_end(k) or V_start(k+1) below V_start(k) at every footstep above the floor; V_start
    # itself falls there
    falling = V_start[:-1] > V_FLOOR
    assert falling.sum() >= 3
    assert np.all((np.minimum(V_end[:-1], V_start[1:]) < V_start[:-1])[falling])
    assert np.all((np.diff(V_start) < 0)[falling])
    assert V_start[-1] < 0.1 * V_start[0]


def test_fixed_plan_lyapunov_value_falls_with_the_default_weights():
    """The same certificate with the default (stiffer) weights, whose P weighs y and y_dot far
    more: on flat ground from the same start V_end / V_start is 0.7-0.91 on every step and V
    falls by more than half from each footstep's start to the next."""
    failure, recs = closed_loop(TransverseController, "flat", CERT_Z0, steps=6)
    assert failure is None and all(r.fallback is None for r in recs)
    V_start = np.array([r.V_start for r in recs])
    V_end = np.array([r.V_end for r in recs])
    assert V_start[0] == pytest.approx(9.53, abs=0.05)
    assert all(0.65 < r.V_ratio < 0.95 for r in recs)
    assert np.all(V_start[1:] < V_end[:-1])
    assert np.all(V_start[1:] / V_start[:-1] < 0.55)
    assert V_start[-1] < 0.03 * V_start[0]


@pytest.mark.parametrize("terrain", ["flat", "paper_stairs"])
def test_replanning_starts_every_footstep_at_zero(terrain):
    """Replan mode: each step is planned from its own start state, so x_perp and V start at 0
    and V only grows over a step: its ratio is no certificate."""
    failure, recs = closed_loop(
        TransverseController, TERRAINS[terrain], CERT_Z0, steps=5, replan=True
    )
    # a replan cut by its search budget keeps a shorter look-ahead: still a fresh plan; the
    # perturbed first step leaves the plan's tube and is replanned within
    assert failure is None
    assert all(r.fallback in (None, "shorter horizon") or tube_replanned(r) for r in recs)
    assert recs[0].V_start > 0.05  # the first step runs on the plan made at reset
    for r in recs[1:]:
        assert r.V_start < 1e-12 and np.abs(r.xperp_start).max() < 1e-6
        assert r.V_end > 1e-6 and r.V_ratio > 1e6
        assert 0 < r.max_xperp_norm < 0.06
    assert ControllerConfig.for_mode("replan").mode == "replan"


def test_a_tick_records_the_transverse_coordinates_and_lyapunov_value_of_its_state():
    """control(q, qd) and control_state(x) give the same inputs and records; a record holds
    the feedback law's x_perp and V = z' Z^-1 z of its first and last ticks (the start's values
    kept as more ticks run), and the running maxima over the step."""
    config = ControllerConfig.for_robot("paper", replan=False)
    a, b = (TransverseController("paper", "flat", config) for _ in range(2))
    gait = a.planner.periodic_gait()
    for c in (a, b):
        c.reset(gait.q, gait.qd)
    st, sol = a.solution.steps[0], a.solution
    thetas = np.linspace(st.theta_plus, st.theta_minus, 9)[:-1]
    zs, V = [], []
    for k, th in enumerate(thetas):
        x = state_from_z(st, th, np.array([0.02, 0.01 * (-1) ** k, -0.05 + 0.01 * k]))
        u, I, y, yd, _ = feedback_law(a.P, x, *a.gain_table.kernel_args())
        assert a.control(x[:2].copy(), x[2:].copy()) == u
        assert b.control_state(x.copy()) == u
        zs.append([I, y, yd])
        V.append(sol.lyapunov(np.array(zs[-1]), x[1]))
        ra = a.records[-1]
        assert ra.xperp_end.tolist() == zs[-1] and ra.V_end == V[-1]
        assert ra.thetadot_end == x[3]
    zs = np.array(zs)
    assert ra.xperp_start.tolist() == zs[0].tolist() and ra.V_start == V[0]
    assert ra.ticks == thetas.size
    assert ra.V_increase == max(0.0, *np.diff(V))
    assert ra.max_xperp_norm == max(math.sqrt(I * I + y * y + yd * yd) for I, y, yd in zs)
    assert ra.max_abs_y == np.abs(zs[:, 1]).max()
    rb = b.records[-1]
    for f in ("xperp_start", "xperp_end"):
        np.testing.assert_array_equal(getattr(ra, f), getattr(rb, f))
    for f in ("V_start", "V_end", "V_increase", "max_abs_y", "max_xperp_norm", "max_abs_u"):
        assert getattr(ra, f) == getattr(rb, f)
    assert (ra.saturated, ra.thetadot_start, ra.thetadot_end) == (
        rb.saturated,
        rb.thetadot_start,
        rb.thetadot_end,
    )


def test_step_record_certificate_values():
    rec = StepRecord(index=3, V_start=0.5, V_end=0.25, max_abs_u=2.0, max_xperp_norm=0.1, ticks=9)
    assert rec.V_ratio == 0.5
    assert rec.certificate() == {
        "V_start": 0.5,
        "V_end": 0.25,
        "V_ratio": 0.5,
        "max_xperp_norm": 0.1,
        "max_abs_u": 2.0,
    }
    assert math.isnan(StepRecord(index=0).V_ratio)
    assert StepRecord(index=0, V_start=0.0, V_end=1e-3).V_ratio == math.inf
    unknown = StepRecord(index=0, V_start=0.0, V_end=1e-3, ticks=1).certificate()
    assert unknown["V_ratio"] is None and unknown["V_start"] == 0.0  # JSON has no infinity
    # a step held with PD, a posture held or zero input has no Riccati P: no V
    pd = StepRecord(
        index=0, V_start=1.0, V_end=0.5, ticks=5, fallback="PD on the last planned step"
    )
    assert pd.certificate()["V_start"] is None and pd.certificate()["max_abs_u"] == 0.0
    for kind in ("hold posture", "zero input"):
        held = StepRecord(index=0, ticks=5, fallback=kind).certificate()
        assert held["max_xperp_norm"] is None and held["V_ratio"] is None


def test_controller_modes():
    assert MODES == ("replan", "fixed-plan")
    assert ControllerConfig().mode == "replan"
    fixed = ControllerConfig.for_mode("fixed-plan", 10.0, horizon=2)
    assert fixed.mode == "fixed-plan" and not fixed.replan
    assert fixed.plan_steps == 15 + 2 + 1  # 1.5 footsteps a second for 10 s, and the horizon
    assert ControllerConfig.for_mode("fixed-plan", 10.0, plan_steps=5).plan_steps == 5
    assert ControllerConfig.for_mode("replan", 10.0).plan_steps == ControllerConfig().plan_steps
    with pytest.raises(ValueError, match="controller mode = 'fixed'; allowed: replan, fixed-plan"):
        ControllerConfig.for_mode("fixed")
    with pytest.raises(ValueError, match=r"duration = -1\.0; allowed: a finite number > 0"):
        ControllerConfig.for_mode("fixed-plan", -1.0)
    with pytest.raises(ValueError, match="give the mode, not replan"):
        ControllerConfig.for_mode("replan", replan=False)


def test_controller_defaults_per_robot(tmp_path, monkeypatch):
    from configs import CONFIG_DIR
    from envs import config_util
    from envs.config_util import read_yaml_mapping

    shipped = read_yaml_mapping(CONFIG_DIR / "controller" / "paper.yaml", "controller config")
    paper = ControllerConfig.for_robot("paper")
    assert paper == ControllerConfig.from_dict(shipped)
    assert ControllerConfig.for_robot("paper", horizon=2) == replace(paper, horizon=2)
    # no file: the class defaults (the paper's published settings)
    assert ControllerConfig.for_robot("custom") == ControllerConfig.for_robot(None)
    assert ControllerConfig.for_robot(None) == ControllerConfig()
    # a robot's file fills the fields not given, wherever a config is built from fields
    (tmp_path / "controller").mkdir()
    (tmp_path / "controller" / "paper.yaml").write_text("Q: [1.0, 9.0, 4.0]\nhorizon: 2\n")
    monkeypatch.setattr(config_util, "CONFIG_DIR", tmp_path)  # where presets are read
    mine = ControllerConfig.for_robot("paper", horizon=4)
    assert mine.Q == (1.0, 9.0, 4.0) and mine.horizon == 4
    assert ControllerConfig.for_mode("fixed-plan", 10.0, "paper").Q == (1.0, 9.0, 4.0)
    assert ControllerConfig.for_mode("fixed-plan", 10.0).Q == (1.0, 1.0, 1.0)
    ctrl = TransverseController("paper", "flat", {"tube_ticks": 3})
    assert ctrl.config == replace(ControllerConfig(Q=(1.0, 9.0, 4.0), horizon=2), tube_ticks=3)
    assert TransverseController("paper", "flat").config.Q == (1.0, 9.0, 4.0)
    # a ControllerConfig is taken as it is
    assert TransverseController("paper", "flat", ControllerConfig()).config == ControllerConfig()
    assert TransverseController("classic", "flat").config == ControllerConfig()
    (tmp_path / "controller" / "paper.yaml").write_text("Qx: [1.0, 9.0, 4.0]\n")
    with pytest.raises(ValueError, match="Qx"):
        ControllerConfig.for_robot("paper")


def tube_loop(z0, steps, pushes=(), **config):
    """Plan from the nominal flat-ground start, start ``z0`` off it in transverse coordinates,
    replan at every footstep with ``config``, push the hip by ``dv`` [m/s] at each ``(t, dv)``
    of ``pushes``; returns (failure, records)."""
    ctrl = TransverseController("paper", TERRAINS["flat"], config)
    gait = ctrl.planner.periodic_gait()
    ctrl.reset(gait.q, gait.qd)
    x0 = state_from_z(ctrl.solution.steps[0], gait.q[1], np.asarray(z0, float))
    sim = Simulator(ctrl.robot, ctrl.terrain, 1, dt=DT)
    sim.reset(x0[:2], x0[2:])
    b = model.input_gain(ctrl.P)
    todo = sorted(pushes)
    while len(ctrl.records) <= steps:
        while todo and sim.t[0] >= todo[0][0]:
            sim.push_hip(0, todo.pop(0)[1])
        ev = sim.step(b * ctrl.control(sim.q[0].copy(), sim.qd[0].copy()))
        if ev.status[0]:
            return sim.failure(0), ctrl.records
        assert sim.t[0] < 3.0 * steps, "no impact: the walker stalled"
        if ev.n_impacts[0]:
            ctrl.on_impact(sim.q[0].copy(), sim.qd[0].copy(), tuple(sim.stance_foot[0]), sim.t[0])
    return None, ctrl.records[:-1]


@pytest.mark.parametrize("weights", list(WEIGHTS))
@pytest.mark.parametrize("deficit", [-0.35, -0.4])
def test_replanning_within_a_step_rescues_a_start_slower_than_planned(deficit, weights):
    """theta_dot^2 below the plan's by 0.35-0.4 rad^2/s^2 (about 40-50 % of the gait's 0.83
    after impact: a push, a lighter robot, a poor velocity estimate at the impact): tracking
    the plan slips or trips; leaving the tube replans the rest of the step from the actual
    state, and the walker goes on. (With the gait's speed reserve at mid-stance, 0.2-0.3 less
    is tracked without a replan.)"""
    z0 = (deficit, 0.0, 0.0)
    fields = WEIGHTS[weights] or {}
    failure, recs = tube_loop(z0, 4, tube_replans=0, **fields)
    # the paper's weights let the stance foot slip, the stiff default's clip holds it: a trip
    assert failure == ("slip" if weights == "paper" else "trip") and recs[0].retargets == 0
    failure, recs = tube_loop(z0, 4, **fields)  # the paper robot's: up to two replans a step
    assert ControllerConfig().tube_energy == 0.25 and ControllerConfig().tube_replans == 1
    assert ControllerConfig.for_robot("paper").tube_replans == 2
    assert failure is None and len(recs) == 4
    assert recs[0].retargets == 1 and "left the plan's tube" in recs[0].reason
    assert recs[0].fallback.startswith("relaxed: ")  # the tube replan relaxes at once
    assert [r.retargets for r in recs[1:]] == [0, 0, 0]  # on the plan again after the impact


@pytest.mark.parametrize("replans", [1, 2])
def test_a_step_is_replanned_within_at_most_tube_replans_times(replans):
    """Two backward hip pushes of 0.06 m/s in the first step (at 0.03 s and 0.15 s): the first
    takes the state out of the plan's tube, the second out of the replanned one; a step is
    replanned within as often as ``tube_replans`` allows, and the steps after it not at all."""
    pushes = [(0.03, -0.06), (0.15, -0.06)]
    _, recs = tube_loop((0.0, 0.0, 0.0), 3, pushes=pushes, tube_replans=replans)
    assert recs[0].retargets == replans
    assert "left the plan's tube" in recs[0].reason
    assert all(r.retargets == 0 for r in recs[1:])


def test_a_replan_within_a_step_that_finds_nothing_tracks_the_step_under_way(monkeypatch):
    """A replan within the step that finds nothing to track, not even the rest of the plan
    under way (forced here; on rough ground it happens where that plan was a single step held
    with PD): the step under way is tracked on with its gains, as if no replan had been tried,
    where the controller used to go limp (zero input) until the next touchdown."""
    z0 = (-0.4, 0.0, 0.0)
    reference = tube_loop(z0, 4, tube_replans=0)
    plan_steps = TransverseController._plan_steps

    def nothing_within(self, q, qd, n, first, new_step, *args):
        if not (first or new_step):
            self.records[-1].reason = "forced: nothing to track"
            return None
        return plan_steps(self, q, qd, n, first, new_step, *args)

    monkeypatch.setattr(TransverseController, "_plan_steps", nothing_within)
    failure, recs = tube_loop(z0, 4)
    assert recs[0].retargets == 2 and recs[0].fallback == "step under way"
    assert not recs[0].pd_feedback and recs[0].certificate()["V_start"] is not None
    assert all(r.fallback not in ("hold posture", "zero input") for r in recs)
    # the same motion as without replans, tick for tick: the same failure, after as many ticks
    assert failure == reference[0] and failure is not None
    assert [r.ticks for r in recs] == [r.ticks for r in reference[1]]
    assert recs[0].max_abs_u == reference[1][0].max_abs_u > 0


def test_the_tube_is_left_alone_in_fixed_plan_mode_and_when_switched_off():
    z0 = (-0.2, 0.0, 0.0)
    for config in (
        {"tube_energy": 0.25, "tube_replans": 0},
        {"tube_energy": 0.0, "tube_y": 0.0, "tube_replans": 1},
        {"tube_energy": 0.25, "tube_replans": 1, "replan": False, "plan_steps": 6},
    ):
        _, recs = tube_loop(z0, 2, **config)
        assert all(r.retargets == 0 for r in recs), config


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("tube_energy", -0.1, r"tube_energy = -0.1; allowed: >= 0"),
        ("tube_y", math.nan, r"tube_y"),
        ("tube_phase", 1.5, r"tube_phase = 1.5; allowed: \[0, 1\]"),
        ("tube_ticks", 0, r"tube_ticks"),
        ("tube_replans", -1, r"tube_replans"),
    ],
)
def test_bad_tube_settings_are_clear_errors(field, value, match):
    with pytest.raises(ValueError, match=match):
        ControllerConfig(**{field: value})


def test_adjusted_planner_settings_apply_from_the_next_plan_and_survive_a_robot_switch():
    """``adjust_planner`` plans with changed settings from the next planning call on (the
    degradations relax those), an unchanged adjustment keeps the planner, none restores the
    configured one, and switching to an identified robot keeps the adjustment."""
    ctrl = TransverseController("paper", "flat")
    configured = ctrl.planner
    ctrl.adjust_planner(foothold_shift=0.02, target_speed=0.2)
    adjusted = ctrl.planner
    assert adjusted.config.foothold_shift == 0.02 and adjusted.config.target_speed == 0.2
    assert adjusted.config.order == configured.config.order
    relaxed = ctrl._planner_for((("torque_fraction", 1.0),))
    assert relaxed.config.foothold_shift == 0.02 and relaxed.config.torque_fraction == 1.0
    ctrl.adjust_planner(target_speed=0.2, foothold_shift=0.02)
    assert ctrl.planner is adjusted
    ctrl.set_robot(ctrl.robot.replace(l=0.33))
    assert ctrl.planner.params.l == 0.33 and ctrl.planner.config == adjusted.config
    ctrl.adjust_planner()
    assert ctrl.planner.config == configured.config and ctrl.planner.params.l == 0.33
    with pytest.raises(ValueError, match="foothold_shift"):
        ctrl.adjust_planner(foothold_shift=1.0)
    with pytest.raises(ValueError, match="no_such"):
        ctrl.adjust_planner(no_such=1.0)


def test_widened_margins_compose_with_adjustments_and_survive_a_robot_switch():
    """``widen_margins`` adds to the configured edge margin from the next plan on, on top of
    ``adjust_planner``'s changes; 0 restores the configured margin; bad values raise."""
    ctrl = TransverseController("paper", "flat")
    base = ctrl.planner.config.edge_margin
    ctrl.widen_margins(0.01)
    assert ctrl.planner.config.edge_margin == pytest.approx(base + 0.01)
    assert ctrl.configured_planner.config.edge_margin == base
    ctrl.adjust_planner(foothold_shift=0.02)
    cfg = ctrl.planner.config
    assert cfg.foothold_shift == 0.02 and cfg.edge_margin == pytest.approx(base + 0.01)
    relaxed = ctrl._planner_for((("torque_fraction", 1.0),))
    assert relaxed.config.edge_margin == pytest.approx(base + 0.01)
    ctrl.set_robot(ctrl.robot.replace(l=0.33))
    assert ctrl.planner.config.edge_margin == pytest.approx(base + 0.01)
    ctrl.widen_margins(0.0)
    assert ctrl.planner.config.edge_margin == base and ctrl.planner.config.foothold_shift == 0.02
    for bad in (-0.01, float("nan")):
        with pytest.raises(ValueError, match="extra margin"):
            ctrl.widen_margins(bad)
