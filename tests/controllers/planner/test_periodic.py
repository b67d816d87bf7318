"""The periodic flat-ground gait: a stable fixed point of the step map, the classic walker's quoted
figures, and the cache of computed gaits."""

import numpy as np
import pytest

from controllers.planner import GaitPlanner, PlanningError
from envs.physics import model
from envs.physics.terrain import Terrain

from .cases import CASES


@pytest.mark.parametrize("robot", list(CASES))
def test_periodic_gait_is_a_fixed_point_of_the_step_map(planners, robot):
    pl = planners[robot]
    g = pl.periodic_gait()
    cfg = pl.config
    q, qd = g.step.post_impact_state()
    np.testing.assert_allclose(q, g.q, atol=1e-12)
    np.testing.assert_allclose(qd, g.qd, rtol=1e-9)
    assert g.step_length == pytest.approx(cfg.step_length)
    assert g.speed == pytest.approx(g.step_length / g.period)
    assert cfg.duration_min <= g.period <= cfg.duration_max
    assert 0.0 < g.zero_dynamics_gain < 1.0
    assert np.max(np.abs(g.step.input_grid)) <= cfg.torque_fraction * pl.params.u_max + 1e-9
    th = np.linspace(g.step.theta_plus, g.step.theta_minus, 401)
    least = g.step.thetadot(th).min()
    assert least > cfg.gait_min_thetadot - 1e-3
    if least > cfg.gait_min_thetadot + 1e-3:
        assert g.speed == pytest.approx(cfg.target_speed, rel=0.2)
    else:  # the speed reserve binds: faster than the target, to keep it
        assert g.speed > cfg.target_speed


def test_paper_gait_keeps_a_reserve_for_a_push_at_mid_stance(planners):
    """The paper robot's gait keeps theta_dot >= 0.55 rad/s at mid-stance
    (configs/planner/paper.yaml, gait_min_thetadot), above the 0.47 rad/s that a backward hip
    push of 0.15 m/s there takes off (envs.physics.model.hip_push): such a push slows the stance
    leg without turning it back. It walks at 0.22 m/s."""
    pl = planners["paper"]
    g = pl.periodic_gait()
    th = np.linspace(g.step.theta_plus, g.step.theta_minus, 401)
    thd = g.step.thetadot(th)
    k = int(np.argmin(np.abs(th)))  # mid-stance: the stance leg upright
    q1 = float(g.step.phi(th[k]))
    assert thd.min() == pytest.approx(0.55, abs=1e-3)
    dq1d, dq2d, _ = model.hip_push(pl.P, q1, float(th[k]), -0.15)
    assert dq2d == pytest.approx(-0.468, abs=0.005)
    assert thd[k] + dq2d > 0.05
    assert g.speed == pytest.approx(0.222, abs=0.002)


def test_classic_gait_keeps_a_speed_reserve_for_rises(planners):
    """The figures quoted for the classic walker (README, configs/planner/classic.yaml): its
    gait keeps theta_dot >= 0.4 rad/s at 0.61 m/s with a peak hip torque of 74 of 150 N m; a
    1 cm rise costs 40 % of its kinetic energy after touchdown; with a 40 N m hip no gait keeps
    that reserve; 2 cm rises cannot be planned."""
    pl = planners["classic"]
    g = pl.periodic_gait()
    th = np.linspace(g.step.theta_plus, g.step.theta_minus, 401)
    assert g.step.thetadot(th).min() > 0.4 - 1e-3
    assert g.speed == pytest.approx(0.61, abs=0.005)
    peak = np.abs(g.step.input(th)).max()
    assert peak == pytest.approx(74.0, abs=1.0) and peak < 0.8 * pl.params.u_max
    ke = model.kinetic_energy(pl.P, g.q[0], g.qd[0], g.qd[1])
    rise = pl.params.total_mass * pl.params.g * 0.01
    assert rise / ke == pytest.approx(0.40, abs=0.02)
    with pytest.raises(PlanningError, match="no periodic gait"):
        GaitPlanner(pl.params.replace(u_max=40.0)).periodic_gait()
    with pytest.raises(PlanningError):
        pl.plan(Terrain.staircase(1.0, 3, 1.0, 0.02), (g.q, g.qd), (0.0, 0.0), horizon=7)


def test_computed_gaits_are_shared_by_planners(planners):
    """A planner reuses the gaits any planner computed for the same robot, settings, step length
    and speed (the plans depend on the reuse being exact)."""
    pl = planners["paper"]
    g = pl.periodic_gait()
    assert GaitPlanner("paper").periodic_gait() is g
    assert (
        GaitPlanner.gait_cache.get(
            (
                tuple(pl.P),
                tuple(sorted(pl.config.to_dict().items())),
                g.step_length,
                pl.config.target_speed,
            )
        )
        is g
    )
    other = GaitPlanner("paper", {"max_iter": 59})
    assert other.periodic_gait() is not g
