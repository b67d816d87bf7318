"""Sensor models: quantisation, noise statistics, latency, stance inference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from envs.env import CompassGaitEnv
from envs.physics.encoders import q_to_encoders
from envs.sensors import SensorConfig, SensorLayout, seed_streams, standard_normal

QUIET = {"encoder_noise": 0.0, "scan_noise": 0.0, "encoder_resolution": 0.0, "scan_resolution": 0.0}


def test_layout_decodes_encoders_contacts_and_scan() -> None:
    layout = SensorLayout(3, (0.1, 0.2, 0.3))
    obs = np.array([-0.4, -0.3, 0.0, 1.0, 0.01, 0.02, 0.03], dtype=np.float32)
    d = layout.decode(obs)
    assert d["stance_leg"] == 1
    np.testing.assert_allclose(d["q"], [0.4, -0.3 + 0.4], atol=1e-6)
    np.testing.assert_allclose(d["scan"], [0.01, 0.02, 0.03], atol=1e-7)
    batch = layout.decode(np.stack([obs, obs]))
    assert batch["q"].shape == (2, 2)
    with pytest.raises(ValueError, match="entries"):
        layout.decode(obs[:5])


@pytest.mark.parametrize(
    ("field", "value"),
    [("encoder_noise", -1.0), ("scan_count", 2.5), ("latency", -1), ("scan_spacing", 0.0)],
)
def test_sensor_config_rejects_bad_values(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        SensorConfig(**{field: value})
    with pytest.raises(ValueError, match="unknown sensor"):
        SensorConfig.from_dict({"colour": 1})


def test_quantisation_step() -> None:
    res = 2 * math.pi / 512
    env = CompassGaitEnv("slope", sensors={**QUIET, "encoder_resolution": res})
    obs, info = env.reset(seed=3)
    for _ in range(60):
        q1, q2 = info["state"][:2]
        hip, leg_a = q_to_encoders(q1, q2, info["stance_leg"])
        for reading, true in ((obs[0], hip), (obs[1], leg_a)):
            k = float(reading) / res
            assert abs(k - round(k)) < 1e-4  # on the encoder grid
            assert abs(float(reading) - true) <= res / 2 + 1e-6  # nearest count
        obs, _, _, _, info = env.step(np.zeros(1, np.float32))


def test_encoder_and_scan_noise_statistics() -> None:
    sigma, scan_sigma = 0.01, 0.004
    env = CompassGaitEnv(
        "flat",
        sensors={**QUIET, "encoder_noise": sigma, "scan_noise": scan_sigma, "scan_count": 6},
    )
    state = ([-0.5, -0.25], [2.7, 1.2])
    env.reset(seed=0)
    errs, scans = [], []
    for _ in range(1500):
        obs, _ = env.reset(options={"state": state})
        errs.append([obs[0] + 0.5, obs[1] + 0.25])  # stance leg A: readings q1, q2
        scans.append(obs[4:])  # flat ground: true heights are 0
    errs, scans = np.asarray(errs), np.asarray(scans).ravel()
    n = errs.shape[0]
    assert np.all(np.abs(errs.mean(axis=0)) < 4 * sigma / math.sqrt(n))
    np.testing.assert_allclose(errs.std(axis=0), sigma, rtol=0.08)
    assert abs(np.corrcoef(errs.T)[0, 1]) < 0.1  # independent encoders
    assert abs(scans.mean()) < 4 * scan_sigma / math.sqrt(scans.size)
    assert scans.std() == pytest.approx(scan_sigma, rel=0.06)
    # the compiled generator itself: moments of a standard normal
    streams = seed_streams(np.random.default_rng(1), 2)
    z = np.empty(200_000)
    standard_normal(streams, 0, z)
    assert abs(z.mean()) < 0.01 and z.std() == pytest.approx(1.0, abs=0.01)
    assert np.mean(np.abs(z) > 1.959964) == pytest.approx(0.05, abs=0.003)
    assert abs(np.mean(z**3)) < 0.03 and np.mean(z**4) == pytest.approx(3.0, abs=0.06)


def test_same_seed_same_noise_different_seed_different_noise() -> None:
    env = CompassGaitEnv("flat")
    a, _ = env.reset(seed=5)
    b, _ = env.reset(seed=5)
    c, _ = env.reset(seed=6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a[4:], c[4:])


def test_latency_delays_the_whole_vector() -> None:
    k = 3
    fresh = CompassGaitEnv("slope", sensors=QUIET)
    late = CompassGaitEnv("slope", sensors={**QUIET, "latency": k})
    o0, _ = fresh.reset(seed=1)
    l0, _ = late.reset(seed=1)
    ref, got = [o0], [l0]
    rng = np.random.default_rng(0)
    for _ in range(40):
        a = rng.uniform(-0.1, 0.1, 1).astype(np.float32)
        ref.append(fresh.step(a)[0])
        got.append(late.step(a)[0])
    for t in range(len(got)):
        np.testing.assert_array_equal(got[t], ref[max(0, t - k)])


def test_stance_inferred_from_contacts_through_impacts() -> None:
    res = 2 * math.pi / 4096
    env = CompassGaitEnv("slope", sensors={**QUIET, "encoder_resolution": res})
    obs, info = env.reset(seed=0)
    layout = env.sensor_layout
    legs_seen = []
    impacts = 0
    while impacts < 3:
        obs, _, terminated, _, info = env.step(np.zeros(1, np.float32))
        assert not terminated
        d = layout.decode(obs)
        assert d["stance_leg"] == info["stance_leg"]
        # q2 = leg_a - hip with leg B in stance: two quantisation errors add up
        np.testing.assert_allclose(d["q"], info["state"][:2], atol=res + 1e-6)
        if info["impacts"]:
            impacts += info["impacts"]
            legs_seen.append(d["stance_leg"])
    assert legs_seen == [1, 0, 1]  # alternates, starting from leg A in stance
