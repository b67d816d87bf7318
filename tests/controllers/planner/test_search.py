"""The search over steps: replanning from the actual state, reuse of solved step problems, speed
regulation over several replanning calls."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlanningError
from envs.physics.terrain import Terrain

from .cases import CASES, PAPER_STAIRS


def test_speed_is_regulated_after_stairs_down(planners):
    """The paper robot speeds up going down the stairs and slows back towards the gait."""
    pl = planners["paper"]
    g = pl.periodic_gait()
    terr = PAPER_STAIRS
    state, stance, prev, td = (g.q, g.qd), (0.0, 0.0), None, []
    for _ in range(12):
        plan = pl.plan(terr, state, stance, horizon=4, previous_plan=prev)
        s = plan[0]
        td.append(s.thetadot_plus)
        state, stance, prev = s.post_impact_state(), s.foothold, plan
    assert stance[1] == pytest.approx(-0.06)
    assert max(td) > 1.1 * g.qd[1]  # it did speed up on the stairs
    assert abs(td[-1] - g.qd[1]) < 0.3 * (max(td) - g.qd[1])  # and came back towards the gait


def test_replanning_starts_on_the_actual_state_and_reuses_the_previous_plan(planners):
    pl = planners["paper"]
    g = pl.periodic_gait()
    plan = pl.plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=4)
    q, qd = plan[0].post_impact_state()
    # on the plan: the new plan's first step is the old plan's second one
    again = pl.plan(PAPER_STAIRS, (q, qd), plan[0].foothold, horizon=4, previous_plan=plan)
    np.testing.assert_allclose(again[0].coeffs, plan[1].coeffs, atol=1e-6)
    assert again[0].foothold == plan[1].foothold
    # off the plan: y = 0 and y_dot = 0 at the actual post-impact state
    qa, qda = q + np.array([0.01, 0.0]), qd * np.array([0.9, 1.05])
    off = pl.plan(PAPER_STAIRS, (qa, qda), plan[0].foothold, horizon=4, previous_plan=plan)
    s = off[0]
    assert qa[0] - s.phi(qa[1]) == pytest.approx(0.0, abs=1e-14)
    assert qda[0] - s.dphi(qa[1]) * qda[1] == pytest.approx(0.0, abs=1e-13)
    assert s.thetadot_plus == pytest.approx(qda[1])
    assert np.isfinite(off.solve_time) and off.solve_time > 0


def test_reused_step_solutions_do_not_depend_on_other_terrains(planners):
    """Replanning reuses solved step problems; a planner that planned another terrain first
    makes the same plan as a fresh one."""
    pl = planners["paper"]
    g = pl.periodic_gait()
    rough = CASES["paper"]["blocks_high"]
    first = pl.plan(PAPER_STAIRS, (g.q, g.qd), (0.0, 0.0), horizon=4)
    used = pl.plan(rough, (g.q, g.qd), (0.0, 0.0), horizon=4, previous_plan=first)
    fresh = GaitPlanner("paper").plan(
        rough, (g.q, g.qd), (0.0, 0.0), horizon=4, previous_plan=first
    )
    np.testing.assert_allclose(used.footholds, fresh.footholds)
    for a, b in zip(used, fresh):
        np.testing.assert_allclose(a.coeffs, b.coeffs, atol=1e-12)


def test_a_rise_three_steps_ahead_speeds_up_the_current_step_with_the_energy_horizon(planners):
    """With ``energy_horizon = 3`` the end speed each step aims at comes backwards from three
    steps ahead (closed-form reduced dynamics and impact loss): a 1 cm rise about three step
    lengths ahead speeds up the first step, which the one-step target (the default) ignores."""
    gait = planners["paper"].periodic_gait()
    start = ((gait.q, gait.qd), (0.0, 0.0))
    flat, rise = Terrain.flat(), Terrain.stairs([0.53], [0.01])
    one = planners["paper"]
    three = GaitPlanner("paper", {"energy_horizon": 3})
    speed = {
        (name, t): pl.plan(terrain, *start, horizon=1).steps[0].thetadot_minus
        for name, pl in (("one", one), ("three", three))
        for t, terrain in (("flat", flat), ("rise", rise))
    }
    assert speed["one", "rise"] == speed["one", "flat"]
    assert speed["three", "flat"] == pytest.approx(speed["one", "flat"], rel=1e-6)
    assert speed["three", "rise"] > speed["three", "flat"] + 0.01


def test_the_end_speed_floor_keeps_a_speed_reserve_before_a_drop(planners):
    """Before a drop the end speed a step aims at is lowered by the height the next step loses
    (down to ``1.5 min_thetadot``); ``end_thetadot_floor`` keeps it higher, so a push or a
    lighter robot does not stall the step. Elsewhere it changes nothing. (On the gait without
    the preset's reserve at mid-stance, ``gait_min_thetadot = 0``, whose end speed is the lower
    one: the floor binds further from it.)"""
    assert planners["paper"].config.end_thetadot_floor == 0.8
    floored = GaitPlanner("paper", {"end_thetadot_floor": 0.8, "gait_min_thetadot": 0.0})
    plain = GaitPlanner("paper", {"end_thetadot_floor": 0.0, "gait_min_thetadot": 0.0})
    gait = plain.periodic_gait()
    start = ((gait.q, gait.qd), (0.0, 0.0))
    drop, flat = Terrain.stairs([0.2], [-0.03]), Terrain.flat()
    end = {
        (name, t): pl.plan(terrain, *start, horizon=1).steps[0].thetadot_minus
        for name, pl in (("plain", plain), ("floored", floored))
        for t, terrain in (("drop", drop), ("flat", flat))
    }
    assert end["plain", "drop"] < end["plain", "flat"] - 0.1  # slowed down before the drop
    assert end["floored", "drop"] > end["plain", "drop"] + 0.05
    assert end["floored", "flat"] == pytest.approx(end["plain", "flat"], rel=1e-9)


# A post-impact state of the paper robot 0.49 m before a 1.4 cm riser (from a walk on random
# blocks, planned without the gait's reserve at mid-stance, gait_min_thetadot = 0): searched
# depth first, the third step's first foothold leaves the climb no feasible step; another
# foothold's pair climbs, after slowing down.
_NO_RESERVE = {"gait_min_thetadot": 0.0}
_BEFORE_RISER = (
    np.array([-0.4922489666227731, -0.30270013921240413]),
    np.array([0.4186426520283657, 0.9254189825418276]),
)


@pytest.mark.parametrize("compiled_sqp,greedy_spends", [(0, 4000), (1, 3500)])
def test_pairs_first_finds_the_climb_that_a_foothold_before_the_riser_hides(
    compiled_sqp, greedy_spends
):
    """With ``pairs_first`` (the paper robot's default) the search tries the other footholds'
    pairs (a step with its next one) before searching beyond a foothold whose pair failed: the
    plan over the riser is found within the replanning budget, and is the plan the whole search
    finds; with SciPy's SLSQP and with the compiled SQP (whose failing solves end sooner)."""
    terr = Terrain.stairs([0.966], [0.014])
    state, stance = _BEFORE_RISER, (0.476, 0.0)
    solver = {"compiled_sqp": compiled_sqp}
    # (the previous order's depth-first search alone: the beam search after it plans the climb)
    greedy = GaitPlanner("paper", {"pairs_first": 0, "beam_width": 0, **_NO_RESERVE, **solver})
    with pytest.raises(PlanningError) as err:
        greedy.plan(terr, state, stance, horizon=4, max_evaluations=2000)
    assert err.value.budget_exhausted and err.value.step == 3
    whole = greedy.plan(terr, state, stance, horizon=4)
    assert whole.evaluations > greedy_spends
    paired = GaitPlanner("paper", {**_NO_RESERVE, **solver})
    assert paired.config.pairs_first == 1
    plan = paired.plan(terr, state, stance, horizon=4, max_evaluations=2000)
    assert len(plan) == 4 and plan.evaluations < 1500
    np.testing.assert_allclose(plan.footholds, whole.footholds, atol=1e-9)
    assert plan[3].foothold[1] == pytest.approx(0.014)  # on top of the riser
    assert plan[2].thetadot_minus < 0.8 * plan[1].thetadot_minus  # slowed down before it


def test_a_stance_foot_between_foothold_windows_plans_with_relaxed_riser_margins(planners):
    """Two 3 cm stairs down, the first riser 0.10 m ahead of the stance foot: with the full
    riser margins no foothold lies within the step bounds (before the riser is shorter than
    ``step_min``, past its margin longer than ``step_max``) and planning fails at step 0. The
    paper robot's planner halves the margins for that step alone, says so in the step's
    note, and plans down both stairs."""
    stairs = Terrain.stairs([0.10, 0.32], [-0.03, -0.03])
    gait = planners["paper"].periodic_gait()
    full = GaitPlanner("paper", {"relaxed_margin": 1.0})
    with pytest.raises(PlanningError, match="no admissible foothold") as err:
        full.plan(stairs, (gait.q, gait.qd), (0.0, 0.0), horizon=3)
    assert err.value.step == 0
    plan = GaitPlanner("paper").plan(stairs, (gait.q, gait.qd), (0.0, 0.0), horizon=3)
    assert len(plan) == 3
    assert plan[0].note.startswith("riser margins relaxed to 2 / 2 m/m")
    assert plan[0].foothold[0] >= 0.10 + 0.02 + 2.0 * 0.03 - 1e-9
    assert plan[0].foothold[1] == pytest.approx(-0.03)
    assert all(s.note == "" for s in plan.steps[1:])  # the rules' footholds from there on
    assert plan[2].foothold[1] == pytest.approx(-0.06)


def test_foothold_shift_moves_every_preferred_foothold(planners):
    """On level ground the periodic gait's footholds are 0.15 m apart; ``foothold_shift``
    moves each step's by about the shift (the touchdown angle the candidates are ranked
    towards turns by ``shift / (2 l cos theta-)``), and a previous plan's footholds are not
    tried first once the shift has changed."""
    gait = planners["paper"].periodic_gait()
    start = (gait.q, gait.qd)
    lengths = {}
    for shift in (-0.03, 0.0, 0.03):
        plan = GaitPlanner("paper", {"foothold_shift": shift}).plan("flat", start, (0.0, 0.0), 3)
        lengths[shift] = np.diff([0.0, *(s.foothold[0] for s in plan.steps)])
    np.testing.assert_allclose(lengths[0.0], 0.15, atol=0.002)
    np.testing.assert_allclose(lengths[0.03] - lengths[0.0], 0.03, atol=0.003)
    np.testing.assert_allclose(lengths[0.0] - lengths[-0.03], 0.03, atol=0.003)
    base = GaitPlanner("paper").plan("flat", start, (0.0, 0.0), 3)
    moved = GaitPlanner("paper", {"foothold_shift": 0.03}).plan(
        "flat", start, (0.0, 0.0), 3, previous_plan=base
    )
    assert moved[0].foothold[0] == pytest.approx(base[0].foothold[0] + 0.03, abs=0.003)
    with pytest.raises(ValueError, match=r"foothold_shift = 0.2; allowed: \[-0.1, 0.1\] m"):
        GaitPlanner("paper", {"foothold_shift": 0.2})
