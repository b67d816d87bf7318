"""The robot's encoder and contact-switch model (:mod:`envs.physics.encoders`)."""

from __future__ import annotations

import numpy as np
import pytest

from envs.physics.encoders import encoders_to_q, q_to_encoders, stance_from_contacts


def test_encoder_geometry_round_trip() -> None:
    rng = np.random.default_rng(0)
    q1, q2 = rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50)
    for leg in (0, 1):
        hip, leg_a = q_to_encoders(q1, q2, leg)
        back = encoders_to_q(hip, leg_a, leg)
        np.testing.assert_allclose(back, (q1, q2), atol=1e-15)
    # physical meaning: leg A's absolute angle is q2 when A stands, the swing angle otherwise
    assert q_to_encoders(0.4, 0.1, 0) == (0.4, 0.1)
    hip, leg_a = q_to_encoders(0.4, 0.1, 1)
    assert leg_a == pytest.approx(0.1 - 0.4) and hip == pytest.approx(-0.4)
    # the hip encoder does not flip sign at an impact: alpha_A - alpha_B is continuous
    # (impact q+ = (-q1, q2 - q1) with the legs swapped)
    q1m, q2m = 0.5, 0.25
    before = q_to_encoders(q1m, q2m, 0)
    after = q_to_encoders(-q1m, q2m - q1m, 1)
    np.testing.assert_allclose(before, after, atol=1e-15)


def test_stance_from_contacts() -> None:
    assert stance_from_contacts(1.0, 0.0) == 0
    assert stance_from_contacts(0.0, 1.0) == 1
    assert stance_from_contacts(1.0, 1.0, previous=1) == 1
    assert stance_from_contacts(0.0, 0.0) == 0
