"""The controller's degradation order when the full planning problem has no solution."""

import numpy as np
import pytest

from controllers import ControllerConfig, GaitPlanner, TransverseController
from controllers.controller import FALLBACK_PD
from controllers.fallbacks import DEFAULT_FALLBACKS, fallback_name
from controllers.planner import PlanningError, touchdown_configuration
from controllers.reduced import pfl_terms
from envs.physics.terrain import Terrain

# a 7.5 mm rise the paper robot climbs with its hip input within 0.8 u_max but not within 0.3
RISE_X, RISE_HEIGHT = 0.33, 0.0075  # [m]
RISE = Terrain.stairs([RISE_X], [RISE_HEIGHT])
TIGHT = {"torque_fraction": 0.3}  # the nominal gait needs 0.24 u_max
# budgets large enough not to cut these searches (the order of degradations, budgets aside)
ROOMY = {"replan_evaluations": 10**5}
ROOMY_PLANNER = {"max_evaluations": 10**5}


@pytest.fixture(scope="module")
def gait():
    return GaitPlanner("paper").periodic_gait()


def walk(terrain, gait, config, planner=None, duration=4.0, steps=6):
    ctrl = TransverseController("paper", terrain, config, planner)
    out = ctrl.rollout(gait.q, gait.qd, duration, steps=steps)
    return out, ctrl


def test_a_relaxed_step_keeps_the_robot_walking_where_the_full_problem_has_none(gait):
    relax = ControllerConfig(fallbacks=[{"torque_fraction": 0.8}], **ROOMY)
    out, ctrl = walk(RISE, gait, relax, {**TIGHT, **ROOMY_PLANNER})
    assert out["failure"] is None and len(out["impacts"]) >= 5
    relaxed = [r for r in out["records"] if r.fallback == "relaxed: torque_fraction=0.8"]
    assert relaxed, [r.fallback for r in out["records"]]
    for r in relaxed:
        assert r.reason.startswith("full problem: planning failed at step")
        assert r.degradations == ["full problem", "relaxed: torque_fraction=0.8"]
        # a relaxed plan is tracked with PD on y (ControllerConfig.relaxed_feedback)
        assert r.pd_feedback and r.ticks > 0 and r.certificate()["V_start"] is None
    assert all(r.fallback != "zero input" for r in out["records"])
    full = [r for r in out["records"] if r.fallback is None]
    assert full and not any(r.pd_feedback for r in full)  # full plans: transverse feedback


def test_relaxed_plans_can_keep_the_transverse_feedback(gait):
    """``relaxed_feedback="riccati"`` (the previous default): the same relaxed steps are tracked
    with the Riccati feedback, whose ``V`` the certificate reports."""
    relax = ControllerConfig(
        fallbacks=[{"torque_fraction": 0.8}], relaxed_feedback="riccati", **ROOMY
    )
    out, _ = walk(RISE, gait, relax, {**TIGHT, **ROOMY_PLANNER})
    assert out["failure"] is None and len(out["impacts"]) >= 5
    relaxed = [r for r in out["records"] if r.fallback == "relaxed: torque_fraction=0.8"]
    assert relaxed and not any(r.pd_feedback for r in out["records"])
    assert all(np.isfinite(r.certificate()["V_end"]) for r in relaxed)


def test_without_degradations_the_same_course_ends_in_a_fall_or_a_single_step(gait):
    plain = ControllerConfig(fallbacks=[], **ROOMY)
    out, _ = walk(RISE, gait, plain, {**TIGHT, **ROOMY_PLANNER})
    kinds = [r.fallback for r in out["records"]]
    assert "relaxed: torque_fraction=0.8" not in kinds
    assert "PD on the last planned step" in kinds or out["failure"] is not None, kinds


def test_least_violating_steps_replace_the_posture_hold(gait):
    """A 12.5 mm rise: no feasible step from the second footstep on; the least-violating steps
    are tracked (input applied, upright to the end of the run) where the plain chain is left
    with nothing to track (the posture held; zero input before it)."""
    rise = Terrain.stairs([0.33], [0.0125])
    # the swing foot 3 mm over the ground (the paper robot's default until it became 6 mm),
    # where the plain chain is left with nothing to track
    planner = {**ROOMY_PLANNER, "clearance": 0.003}
    plain, _ = walk(rise, gait, ControllerConfig(fallbacks=[], **ROOMY), planner, 3.0)
    assert "hold posture" in [r.fallback for r in plain["records"]]
    cfg = ControllerConfig(fallbacks=["least violation"], **ROOMY)
    out, ctrl = walk(rise, gait, cfg, planner, 3.0)
    kinds = [r.fallback for r in out["records"]]
    assert "least violation" in kinds and "hold posture" not in kinds, kinds
    assert "zero input" not in kinds
    assert out["failure"] is None and out["t"][-1] >= plain["t"][-1]
    for r in out["records"]:
        if r.fallback == "least violation":
            assert r.degradations == ["full problem", "least violation"]
            assert "least violation: worst violation" in r.reason
            assert r.max_abs_u > 0 and r.ticks > 0 and r.pd_feedback


def test_with_nothing_to_track_the_swing_leg_is_held_and_the_walk_goes_on(gait):
    """The plain chain (no degradations) on a 12.5 mm rise: after its last planned step nothing
    is left to track. The swing leg is then held at the nominal touchdown's inter-leg angle
    (a ``step_length`` step on level ground) with PD on ``y`` through the control tick (the
    input that gives ``y_ddot = -kp y - kd y_dot`` within the actuator limit): the body tips
    over the stance leg, the held foot lands on the upper tread and the full problem plans
    every footstep after it. Zero input (``posture_hold=False``, the behaviour before it) trips
    here; it is left for a non-finite state only."""
    rise = Terrain.stairs([0.33], [0.0125])
    planner = {**ROOMY_PLANNER, "clearance": 0.003}
    limp, _ = walk(
        rise, gait, ControllerConfig(fallbacks=[], posture_hold=False, **ROOMY), planner, 8.0, 12
    )
    assert [r.fallback for r in limp["records"]][3] == "zero input"
    assert limp["failure"] == "trip" and len(limp["impacts"]) == 3
    out, ctrl = walk(rise, gait, ControllerConfig(fallbacks=[], **ROOMY), planner, 8.0, 12)
    kinds = [r.fallback for r in out["records"]]
    assert kinds[:4] == [
        "shorter horizon",
        "shorter horizon",
        "PD on the last planned step",
        "hold posture",
    ], kinds
    assert out["failure"] is None and len(out["impacts"]) >= 8
    assert all(k is None for k in kinds[4:]) and len(kinds) >= 9
    held = out["records"][3]
    assert held.ticks > 0 and held.max_abs_u > 0 and held.degradations == ["full problem"]
    assert held.certificate()["V_start"] is None  # no Riccati gains: no certificate
    assert ctrl._stance[1] == pytest.approx(0.0125)  # on the upper tread
    target = touchdown_configuration(ctrl.planner.config.step_length, 0.0, ctrl.robot.l)[0]
    during = (out["t"] > out["impacts"][2]) & (out["t"] < out["impacts"][3])
    q, qd, u = out["q"][during], out["qd"][during], out["u"][during]
    assert q[0, 0] < target - 0.3  # the swing leg starts behind ...
    assert np.min(np.abs(q[:, 0] - target)) < 0.01  # ... and is brought to the held angle
    # every tick within the actuator limit: PD on y through the partial feedback linearisation
    kp, kd = FALLBACK_PD
    free = np.abs(u) < ctrl.robot.u_max
    assert free.sum() > 0.9 * u.size
    n, r = pfl_terms(ctrl.P, q[:, 0], q[:, 1], qd[:, 0], qd[:, 1], 0.0, 0.0)
    np.testing.assert_allclose(
        (n * u + r)[free], (-kp * (q[:, 0] - target) - kd * qd[:, 0])[free], rtol=1e-9
    )
    assert ctrl._posture_hold(np.array([np.nan, 0.1])) is None  # zero input's one case


def test_degradation_order_is_configurable_and_validated():
    cfg = ControllerConfig()
    assert cfg.fallbacks == DEFAULT_FALLBACKS
    assert ControllerConfig.from_dict(cfg.to_dict()) == cfg
    custom = ControllerConfig.from_dict(
        {"fallbacks": ["least violation", {"torque_fraction": 1.0, "duration_max": 2.0}]}
    )
    assert custom.fallbacks == (
        "least violation",
        (("duration_max", 2.0), ("torque_fraction", 1.0)),
    )
    for bad in ("least violation", ["zero input"], [{"no_such_field": 1.0}], [{}], [3]):
        with pytest.raises(ValueError, match="fallbacks"):
            ControllerConfig(fallbacks=bad)
    assert cfg.posture_hold is True
    assert not ControllerConfig.from_dict({**cfg.to_dict(), "posture_hold": False}).posture_hold
    with pytest.raises(ValueError, match="posture_hold = 'no'; allowed: True or False"):
        ControllerConfig(posture_hold="no")
    with pytest.raises(ValueError, match="relaxed_feedback = 'lqr'; allowed: 'pd', 'riccati'"):
        ControllerConfig(relaxed_feedback="lqr")
    with pytest.raises(ValueError, match="torque_fraction"):  # checked by the robot's planner
        TransverseController("paper", "flat", {"fallbacks": [{"torque_fraction": 1.5}]})


def test_a_shorter_look_ahead_is_planned_again_under_the_deeper_relaxation(gait):
    """Where the full problem plans only the steps before a rise it cannot climb (a shorter
    look-ahead, the dead end it would walk into), ``deeper_relaxation`` plans the whole
    look-ahead under its relaxation, which is tracked as a relaxed plan; footsteps the full
    problem plans whole are untouched."""
    relax = {"fallbacks": [{"torque_fraction": 0.8}], **ROOMY}
    runs = {}
    for name, extra in (("plain", {}), ("deeper", {"deeper_relaxation": {"torque_fraction": 0.8}})):
        out, _ = walk(RISE, gait, ControllerConfig(**relax, **extra), {**TIGHT, **ROOMY_PLANNER})
        assert out["failure"] is None and len(out["impacts"]) >= 5
        runs[name] = out["records"]
    first_plain, first = runs["plain"][0], runs["deeper"][0]
    assert first_plain.fallback == "shorter horizon" and not first_plain.pd_feedback
    assert first_plain.reason.startswith("full problem: planning failed at step 3")
    assert first.fallback == "relaxed: torque_fraction=0.8, deeper"
    assert first.degradations == ["full problem", "relaxed: torque_fraction=0.8, deeper"]
    assert first.reason == first_plain.reason  # the full problem's failure, nothing else
    assert first.pd_feedback  # a relaxed plan: PD on y
    for r in runs["deeper"]:
        if r.fallback is None:
            assert r.degradations == ["full problem"]
    assert sum(r.fallback is None for r in runs["deeper"]) >= 3


def test_the_deeper_relaxation_is_validated():
    cfg = ControllerConfig(deeper_relaxation={"torque_fraction": 1.0, "duration_max": 3.0})
    assert cfg.deeper_relaxation == (("duration_max", 3.0), ("torque_fraction", 1.0))
    assert ControllerConfig.from_dict(cfg.to_dict()) == cfg
    assert (
        ControllerConfig().deeper_relaxation
        == ()
        == ControllerConfig(deeper_relaxation=None).deeper_relaxation
    )
    # the paper robot's default (configs/controller/paper.yaml), switched off with an empty one
    paper = ControllerConfig.for_robot("paper")
    assert paper.deeper_relaxation == (
        ("duration_max", 3.0),
        ("duration_min", 0.05),
        ("torque_fraction", 1.0),
    )
    assert ControllerConfig.for_robot("paper", deeper_relaxation={}).deeper_relaxation == ()
    for bad in ("least violation", {"no_such_field": 1.0}, {"torque_fraction": float("nan")}):
        with pytest.raises(ValueError, match="ControllerConfig.deeper_relaxation"):
            ControllerConfig(deeper_relaxation=bad)


def test_a_stance_foot_between_foothold_windows_walks_on_with_relaxed_riser_margins(gait):
    """Two 3 cm stairs down, the first riser 0.10 m ahead: with the full riser margins no
    problem has a foothold at the first step and the controller has nothing to track (it holds
    the posture; before, zero input); the paper robot's planner relaxes the margins for that
    step (recorded in the step's reason) and the robot walks down both stairs."""
    stairs = Terrain.stairs([0.10, 0.32], [-0.03, -0.03])
    plain, _ = walk(stairs, gait, ControllerConfig(), {"relaxed_margin": 1.0}, duration=4.0)
    assert plain["records"][0].fallback == "hold posture"
    out, ctrl = walk(stairs, gait, ControllerConfig(), duration=4.0)
    first = out["records"][0]
    assert first.fallback is None and "riser margins relaxed" in first.reason
    assert out["failure"] is None and len(out["impacts"]) >= 5
    assert all(r.fallback != "zero input" for r in out["records"])
    assert ctrl._stance[1] == pytest.approx(-0.06)  # on the lower tread


def test_the_beam_search_keeps_walking_where_the_depth_first_search_runs_into_a_rise(
    rise_after_drops,
):
    """The constructed course of ``tests/controllers/planner/test_beam.py`` (three drops, then a
    13 mm rise; a validation course at difficulty 2), walked from the state where the
    depth-first search first planned only three of four steps: without the beam search the
    look-ahead shrinks step after step, then least-violating steps, then a trip; with it the
    plans span the horizon and the robot walks on over the rise."""
    c = rise_after_drops
    course = c.terrain(shift=c.stance[0])  # the stance foot at x = 0, where rollouts start
    q, qd = np.array(c.state[0]), np.array(c.state[1])
    outs = {}
    for width in (32, 0):
        ctrl = TransverseController("paper", course, ControllerConfig(), {"beam_width": width})
        outs[width] = ctrl.rollout(q, qd, 6.0, steps=8)
    beam, dfs = outs[32], outs[0]
    assert beam["failure"] is None and len(beam["impacts"]) >= 7
    assert any("beam search over the horizon" in (r.reason or "") for r in beam["records"])
    assert all(r.fallback is None for r in beam["records"])
    assert dfs["failure"] == "trip" and len(dfs["impacts"]) < 5
    assert [r.fallback for r in dfs["records"][:3]] == [
        "shorter horizon",
        "shorter horizon",
        "least violation",
    ]


@pytest.mark.parametrize("compiled_sqp", [0, 1])
def test_the_beam_search_does_not_spend_the_relaxations_budget(gait, compiled_sqp):
    """The beam search over the horizon has its own budget: where the full problem's
    depth-first search and beam fail, the relaxation gets the replanning budget the depth-first
    search left. Before, the beam's evaluations were charged to that budget too, and on this
    rise the relaxed search of the third footstep ran out of it ("search budget exhausted")
    and left a shorter look-ahead. Here every relaxed footstep plans the relaxed problem, with
    either solver. How many footsteps need the relaxation (one or two) turns on the last bits
    of the floating point (the CPU's vector paths, the BLAS build), so it is not asserted."""
    relax = ControllerConfig(fallbacks=[{"torque_fraction": 0.8}])
    out, ctrl = walk(RISE, gait, relax, {**TIGHT, "beam_width": 32, "compiled_sqp": compiled_sqp})
    recs = out["records"]
    assert max(r.plan_evaluations for r in recs) > relax.replan_evaluations  # the beam ran
    relaxed = [r for r in recs if (r.fallback or "").startswith("relaxed")]
    assert 1 <= len(relaxed) <= 2
    assert {r.fallback for r in relaxed} == {"relaxed: torque_fraction=0.8"}
    for r in relaxed:
        assert r.reason.startswith("full problem: planning failed")
        assert "relaxed: torque_fraction=0.8: planning failed" not in r.reason, r.reason
    # up the rise and walking on (the step after the climb is slow: 4 or 5 impacts in 4 s)
    assert out["failure"] is None and len(out["impacts"]) >= 4
    assert ctrl._stance[0] > RISE_X + 0.15 and ctrl._stance[1] == pytest.approx(RISE_HEIGHT)


def test_the_dip_floor_is_a_preference_of_the_full_problem(gait):
    """No step of the gait keeps 95 % of its start speed over its apex: with that dip floor
    every footstep plans the full problem without it, tracked as the full problem is (the
    transverse feedback, no fallback), and the walk is the one without the floor to the last
    digit; a floor of 0.5, which the gait's steps keep, plans the full problem with it."""
    plain, _ = walk("flat", gait, ControllerConfig(**ROOMY), ROOMY_PLANNER)
    runs = {}
    for floor in (0.95, 0.5):
        out, _ = walk(
            "flat", gait, ControllerConfig(**ROOMY), {**ROOMY_PLANNER, "dip_floor": floor}
        )
        assert out["failure"] is None and len(out["impacts"]) >= 5
        runs[floor] = out
    for r in runs[0.95]["records"]:
        assert r.fallback is None and not r.pd_feedback
        assert r.degradations == ["full problem", "full problem without the dip floor"]
        assert r.reason.startswith("full problem: planning failed at step 0")
    for key in ("q", "qd", "u", "impacts"):
        np.testing.assert_array_equal(runs[0.95][key], plain[key])
    for r in runs[0.5]["records"]:
        assert r.fallback is None and r.degradations == ["full problem"]


@pytest.mark.parametrize("cap,expected", [(40000, [40000, 25000, 10000, 0]), (0, [None] * 4)])
def test_a_replanning_shares_its_beam_budget_across_its_planner_calls(
    gait, monkeypatch, cap, expected
):
    """With ``replan_beam_evaluations`` the beam searches of one replanning share that budget:
    each planner call's beam gets what the calls before it left (here every call's beam
    spends 15,000 and fails). 0, the class default: no cap passed, each call's beam has the
    planner's own budget. The plan at reset (nothing to fall back on) is never capped."""
    cfg = ControllerConfig(replan_beam_evaluations=cap)
    ctrl = TransverseController("paper", "flat", cfg)
    seen = []
    real = GaitPlanner.plan

    def spy(self, *args, **kwargs):
        seen.append(kwargs.get("max_beam_evaluations"))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(GaitPlanner, "plan", spy)
    ctrl.reset(gait.q, gait.qd)
    assert seen == [None]

    def failing(self, *args, **kwargs):
        seen.append(kwargs.get("max_beam_evaluations"))
        exc = PlanningError(0, "hip input within the actuator limit")
        exc.evaluations, exc.beam_evaluations = 15010, 15000
        raise exc

    monkeypatch.setattr(GaitPlanner, "plan", failing)
    seen.clear()
    ctrl.replan(gait.q, gait.qd)
    rec = ctrl.records[-1]
    assert rec.degradations[:4] == ["full problem", *(fallback_name(f) for f in cfg.fallbacks[:3])]
    assert seen == expected
    assert rec.fallback in ("previous plan", "least violation")
    with pytest.raises(ValueError, match="replan_beam_evaluations"):
        ControllerConfig(replan_beam_evaluations=-1)


def test_one_beam_budget_per_replanning_is_the_paper_robots_default():
    """The paper robot's presets cap a replanning's beam searches at 20,000 step evaluations
    together (configs/controller/paper.yaml), each beam step trying the near shapes alone
    (configs/planner/paper.yaml: beam_far 0); the class defaults and the robots without a preset
    keep each call's own budget and the far shapes. The earlier records' settings, which their
    specs, agent configs and manifests pin, give them again: ``replan_beam_evaluations=0`` (or
    40,000, the default before the near shapes) with ``beam_far=1``."""
    assert ControllerConfig.for_robot("paper").replan_beam_evaluations == 20000
    assert ControllerConfig().replan_beam_evaluations == 0
    assert ControllerConfig.for_robot("classic").replan_beam_evaluations == 0
    for pinned in (0, 40000):
        cfg = ControllerConfig.for_robot("paper", replan_beam_evaluations=pinned)
        assert cfg.replan_beam_evaluations == pinned
    ctrl = TransverseController("paper", "flat")
    assert ctrl.config.replan_beam_evaluations == 20000 and ctrl.planner.config.beam_far == 0
    ctrl = TransverseController("paper", "flat", planner={"beam_far": 1})
    assert ctrl.planner.config.beam_far == 1
    assert TransverseController("classic", "flat").planner.config.beam_far == 1
