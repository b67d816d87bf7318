import math

import numpy as np
import pytest

from envs.physics import model
from envs.physics.params import PARM, PB, PRETRACT, RobotParams, available_presets


def test_presets_load_with_units_from_yaml():
    assert {"paper", "classic"} <= set(available_presets())
    p = RobotParams.from_preset("paper")
    assert p.m == 1.3 and p.mH == 2.2 and p.mHg == -1.2 and p.Ic == 0.0168
    assert math.isclose(p.l - p.lc, 0.0596)
    assert math.isclose(p.tau_max, 1.1 * 0.0671 * p.u_max)
    c = RobotParams.from_preset("classic")
    assert (c.m, c.mH, c.mHg, c.l, c.lc, c.Ic, c.Fc, c.Fv) == (5, 10, 10, 1, 0.5, 0, 0, 0)


@pytest.mark.parametrize(
    "field,value",
    [
        ("l", 0.0),
        ("l", -1.0),
        ("m", 0.0),
        ("m", -1.0),
        ("mH", -0.1),
        ("lc", 1.5),
        ("lc", -0.1),
        ("Ic", -1e-3),
        ("g", 0.0),
        ("mHg", -20.0),
        ("Fc", -1.0),
        ("u_max", 0.0),
        ("retract", -0.01),
        ("retract", 0.51),
        ("arm_distance", -0.1),
        ("arm_distance", 2.5),
        ("l", math.nan),
        ("m", math.inf),
    ],
)
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=rf"RobotParams\.{field}"):
        RobotParams.from_preset("classic").replace(**{field: value})


def test_negative_gravitational_hip_mass_is_allowed():
    p = RobotParams.from_preset("classic").replace(mHg=-2.0)
    assert p.mHg == -2.0


def test_unknown_preset_and_field():
    with pytest.raises(ValueError, match="unknown robot preset"):
        RobotParams.from_preset("nope")
    with pytest.raises(ValueError, match="unknown robot parameter"):
        RobotParams.from_dict({"m": 1, "mH": 1, "mHg": 1, "l": 1, "lc": 0.5, "foo": 1})


def test_vector_layout_matches_appendix_b():
    p = RobotParams.from_preset("paper")
    v = p.vector()
    c = p.coefficients()
    assert np.allclose(v[:8], [c[f"p{i}"] for i in range(1, 9)])
    assert math.isclose(c["p5"], p.g * (p.mHg * p.l + 2 * p.m * p.lc))


@pytest.mark.parametrize("preset", ["paper", "classic"])
def test_input_gain_is_the_torque_per_unit_input_declared_once(preset):
    p = RobotParams.from_preset(preset)
    assert p.input_gain == p.kI * p.ktau  # exactly: the one place the product is formed
    assert p.tau_max == p.kI * p.ktau * p.u_max
    P = p.vector()
    assert P[PB] == p.input_gain and model.input_gain(P) == p.input_gain
    assert RobotParams.from_preset("paper").replace(kI=2.0, ktau=0.5).input_gain == 1.0


@pytest.mark.parametrize("preset", ["paper", "classic"])
def test_foot_geometry_is_a_robot_parameter(preset):
    p = RobotParams.from_preset(preset)
    assert (p.retract, p.arm_distance) == (0.05, 0.1)  # fractions of l, as before the move
    q = p.replace(retract=0.5, arm_distance=2.0)  # the bounds are allowed
    assert (q.vector()[PRETRACT], q.vector()[PARM]) == (0.5, 2.0)
    assert RobotParams.from_dict(q.to_dict()) == q
