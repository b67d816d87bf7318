"""Gains over the horizon and the gain table the control tick reads."""

import dataclasses

import numpy as np
import pytest

from controllers.controller import ControllerConfig
from controllers.gains import GainTable, horizon_gains, pd_gains


def test_gain_table_holds_the_current_step(chain):
    _, steps = chain
    config = ControllerConfig(grid=20)
    sol = horizon_gains(steps, config)
    table = GainTable.from_solution(sol, 40.0, 0.05, 80)
    m0 = steps[0]
    assert table.theta_plus == m0.theta_plus
    assert table.span == pytest.approx(m0.theta_minus - m0.theta_plus)
    np.testing.assert_array_equal(table.phi_coeffs, m0.power_coefficients)
    assert table.thetadot_sq.shape == table.dthetadot_sq.shape == (81,)
    th = table.speed_theta0 + table.speed_step * np.arange(81)
    np.testing.assert_allclose(table.thetadot_sq, m0.thetadot_sq(th), rtol=1e-12)
    assert table.gain_theta0 == sol.theta[0]
    assert table.gain_step == pytest.approx(sol.theta[1] - sol.theta[0])
    np.testing.assert_array_equal(table.gains, sol.K)
    assert table.gains.shape == (21, 3) and table.gains.flags.c_contiguous
    assert (table.u_max, table.late_blend) == (40.0, 0.05)
    # the compiled tick's scalars follow the fields
    changed = dataclasses.replace(table, u_max=5.0)
    assert 5.0 in changed.scalars and 40.0 not in changed.scalars
    assert changed.kernel_args()[0] is changed.scalars


def test_horizon_solution_lyapunov_matrices_and_pd_gains(chain):
    _, steps = chain
    sol = horizon_gains(steps, ControllerConfig(grid=20))
    assert sol.Zinv.shape == (21, 3, 3) and len(sol.impact_jacobians) == len(steps) - 1
    z = np.array([0.1, 0.01, -0.02])
    assert sol.lyapunov(z, sol.theta[3]) == pytest.approx(z @ sol.Zinv[3] @ z)
    pd = pd_gains(steps, 10, 400.0, 40.0)
    np.testing.assert_array_equal(pd.K, np.tile([0.0, -400.0, -40.0], (11, 1)))
    assert pd.lyapunov(z, steps[0].theta_plus) == pytest.approx(z @ z)
    with pytest.raises(ValueError, match="at least one more"):
        horizon_gains(steps[:1], ControllerConfig())
