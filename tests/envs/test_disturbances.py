"""Env options ``robot_error`` and ``push``: draws, bounds, info, determinism, the push through
the model, the defaults unchanged, the checkers, clear errors, YAML."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import yaml

import envs  # noqa: F401  (registers the ids)
from envs.disturbances import PushConfig, RobotError
from envs.physics import RobotParams, Simulator
from envs.physics.params import PHYSICAL_PARAMS
from envs.settings import resolve_env_settings

STAIRS = "roughwalk/CompassGaitStairs-v0"
ROUGH = "roughwalk/CompassGaitRough-v0"
#: the classic walker walks down its slope with no motor: long episodes under zero actions
SLOPE = "roughwalk/CompassGaitSlope-v0"
PAPER = RobotParams.from_preset("paper")


def _run(env: gym.Env, seed: int, steps: int, action: float = 0.0) -> list[dict]:
    """Infos of an episode under a constant action (stops at the episode's end)."""
    _, info = env.reset(seed=seed)
    infos = [info]
    a = np.array([action], dtype=np.float32)
    for _ in range(steps):
        _, _, term, trunc, info = env.step(a)
        infos.append(info)
        if term or trunc:
            break
    return infos


# ---------------------------------------------------------------------------- robot_error
def test_robot_error_draws_are_reproducible_within_bounds_and_the_robot_stays_nominal():
    env = gym.make(ROUGH, robot_error=0.1)
    u = env.unwrapped
    drawn = []
    for seed in range(20):
        _, info = env.reset(seed=seed)
        true = info["robot"]
        assert all(type(v) is float for v in true.values())
        assert u.robot == PAPER and u.params == PAPER  # what a controller may know
        assert RobotParams.from_dict({**true, "name": "paper"}) == u.simulator.params[0]
        for name in PHYSICAL_PARAMS:
            nominal = getattr(PAPER, name)
            if name == "lc":  # moves with l, then by its own error
                ratio = (true["lc"] / true["l"]) / (PAPER.lc / PAPER.l)
            else:
                ratio = true[name] / nominal
            assert 0.9 <= ratio <= 1.1, name
        for name in ("g", "kI", "u_max", "retract", "arm_distance"):
            assert true[name] == getattr(PAPER, name)
        drawn.append(true)
    assert len({d["l"] for d in drawn}) == 20  # a new robot every episode
    again = gym.make(ROUGH, robot_error=0.1)
    for seed in (0, 7, 19):
        assert again.reset(seed=seed)[1]["robot"] == drawn[seed]


def test_robot_error_mapping_perturbs_only_the_parameters_named():
    env = gym.make(STAIRS, robot_error={"l": 0.05, "ktau": 0.2})
    for seed in range(5):
        _, info = env.reset(seed=seed)
        true = info["robot"]
        changed = {k for k in PHYSICAL_PARAMS if true[k] != getattr(PAPER, k)}
        assert changed == {"l", "lc", "ktau"}
        assert true["lc"] / true["l"] == pytest.approx(PAPER.lc / PAPER.l)


def test_robot_error_sign_draws_put_every_parameter_at_a_corner():
    """``draw: sign`` puts each parameter at exactly +-w (random sign, same generator draws as
    the uniform mode); ``all`` gives every parameter not named its width."""
    env = gym.make(STAIRS, robot_error={"all": 0.1, "ktau": 0.2, "draw": "sign"})
    uniform = gym.make(STAIRS, robot_error={"all": 0.1, "ktau": 0.2})
    signs: list[bool] = []

    def ratio(robot: dict, name: str) -> float:
        if name == "lc":  # moves with l, then by its own error
            return (robot["lc"] / robot["l"]) / (PAPER.lc / PAPER.l)
        return robot[name] / getattr(PAPER, name)

    for seed in range(8):
        true = env.reset(seed=seed)[1]["robot"]
        ref = uniform.reset(seed=seed)[1]["robot"]
        for name in PHYSICAL_PARAMS:
            w = 0.2 if name == "ktau" else 0.1
            assert abs(ratio(true, name) - 1.0) == pytest.approx(w, rel=1e-12), name
            assert (ratio(true, name) > 1.0) == (ratio(ref, name) > 1.0), name  # same draws
            signs.append(ratio(true, name) > 1.0)
    assert 0.3 < np.mean(signs) < 0.7
    setting = env.unwrapped.settings.robot_error.to_setting()
    assert setting["draw"] == "sign" and setting["ktau"] == 0.2 and setting["m"] == 0.1
    assert RobotError.from_setting(setting) == env.unwrapped.settings.robot_error


def test_robot_error_changes_the_simulated_robot_only():
    """Same course, start and sensor noise as without the error; the torque is the true
    motor's; the hip progress uses the true leg."""
    a = gym.make(ROUGH)
    b = gym.make(ROUGH, robot_error=0.1)
    oa, ia = a.reset(seed=4)
    ob, ib = b.reset(seed=4)
    np.testing.assert_array_equal(oa, ob)
    assert ia["terrain"] == ib["terrain"] and "robot" not in ia
    np.testing.assert_array_equal(ia["state"], ib["state"])
    true = RobotParams.from_dict(ib["robot"])
    sim = Simulator(true, b.unwrapped.terrain, dt=b.unwrapped.dt)
    sim.reset(ib["state"][:2], ib["state"][2:])
    for _ in range(60):
        _, _, term, _, info = b.step(np.array([0.5], dtype=np.float32))
        sim.step(0.5 * true.tau_max)
        np.testing.assert_array_equal(info["state"], sim.state(0))
        if term:
            break
    hip = sim.stance_foot[0, 0] + true.l * np.sin(sim.q[0, 1])
    assert info["distance"] == pytest.approx(hip - true.l * np.sin(ib["state"][1]), abs=1e-12)


def test_an_invalid_error_box_is_an_error_naming_the_parameter():
    with pytest.raises(ValueError, match=r"robot_error: at l -30 %, lc \+30 % .*RobotParams\.lc ="):
        gym.make(STAIRS, robot_error={"l": 0.3, "lc": 0.3})


# ---------------------------------------------------------------------------- defaults
def test_defaults_leave_episodes_unchanged():
    """Off by default: no extra info, no extra draws (the next episode's course is the same),
    and the episode is the nominal robot's (a plain simulator under the same torques)."""
    plain = gym.make(ROUGH)
    off = gym.make(ROUGH, robot_error=0.0, push=False)
    assert plain.unwrapped.settings.robot_error == RobotError()
    assert plain.unwrapped.settings.push is None
    ia, ib = _run(plain, 3, 150, 0.2), _run(off, 3, 150, 0.2)
    assert len(ia) == len(ib)
    for x, y in zip(ia, ib):
        assert "robot" not in x and "push" not in x
        np.testing.assert_array_equal(x["state"], y["state"])
    assert plain.reset()[1]["terrain"] == off.reset()[1]["terrain"]
    _, info = plain.reset(seed=8)
    sim = Simulator(PAPER, plain.unwrapped.terrain, dt=plain.unwrapped.dt)
    sim.reset(info["state"][:2], info["state"][2:])
    for _ in range(100):
        info = plain.step(np.array([0.2], dtype=np.float32))[4]
        sim.step(float(np.float32(0.2)) * PAPER.tau_max)
        np.testing.assert_array_equal(info["state"], sim.state(0))


# ---------------------------------------------------------------------------- push
def test_mid_stance_pushes_are_recorded_and_deterministic():
    kw = {"push": {"dv": [0.05, 0.15], "at": "mid_stance"}}
    env = gym.make(SLOPE, **kw)
    infos = _run(env, 2, 600)
    pushes = [(k, i["push"]) for k, i in enumerate(infos) if "push" in i]
    assert len(pushes) >= 2
    for k, p in pushes:
        assert 0.05 <= abs(p["dv"]) <= 0.15 and np.sign(p["impulse"]) == np.sign(p["dv"])
        # pushed at the start of the first control period with the stance leg past vertical
        assert p["time"] == pytest.approx(infos[k - 1]["time"])
        assert infos[k - 1]["state"][1] >= 0.0
        assert infos[k]["footsteps"] == infos[k - 1]["footsteps"]
    assert [p for _, p in pushes] == [i["push"] for i in _run(gym.make(SLOPE, **kw), 2, 600)
                                      if "push" in i]  # fmt: skip
    # one push per step: between two pushes there is a touchdown
    steps = [infos[k]["footsteps"] for k, _ in pushes]
    assert steps == sorted(set(steps))


def test_push_is_the_model_impulse_applied_before_the_step():
    """The env's push equals Simulator.push_hip at the start of the period, bit for bit."""
    pushed = gym.make(STAIRS, push={"dv": 0.1, "times": [0.2], "direction": "backward"})
    plain = gym.make(STAIRS)
    pushed.reset(seed=2)
    plain.reset(seed=2)
    a = np.array([0.1], dtype=np.float32)
    for _ in range(40):  # 0.2 s
        pushed.step(a)
        plain.step(a)
    _, _, _, _, info = pushed.step(a)
    assert info["push"]["dv"] == -0.1 and info["push"]["time"] == pytest.approx(0.2)
    impulse = plain.unwrapped.simulator.push_hip(0, -0.1)
    assert impulse == info["push"]["impulse"]
    np.testing.assert_array_equal(plain.step(a)[4]["state"], info["state"])


def test_push_intervals_times_limits_and_probability():
    env = gym.make(SLOPE, push={"dv": 0.02, "every": [0.2, 0.3], "direction": "forward"})
    infos = _run(env, 0, 600)
    assert infos[-1]["failure"] is None
    times = [i["push"]["time"] for i in infos if "push" in i]
    gaps = np.diff([0.0, *times])
    assert len(times) >= 20 and np.all(gaps >= 0.2 - 1e-9) and np.all(gaps <= 0.3 + 0.01)
    assert {i["push"]["dv"] for i in infos if "push" in i} == {0.02}
    env = gym.make(SLOPE, push={"dv": 0.02, "times": [0.1, 0.52, 1.0]})
    times = [i["push"]["time"] for i in _run(env, 0, 300) if "push" in i]
    assert times == pytest.approx([0.1, 0.52, 1.0])
    env = gym.make(SLOPE, push={"dv": 0.02, "every": 0.05, "max_pushes": 3, "after": 0.5})
    times = [i["push"]["time"] for i in _run(env, 0, 300) if "push" in i]
    assert times == pytest.approx([0.55, 0.6, 0.65])
    env = gym.make(SLOPE, push={"dv": 0.01, "every": 0.01, "probability": 0.3})
    n = sum("push" in i for i in _run(env, 0, 200))
    assert 0.15 * 200 < n < 0.45 * 200  # 200 opportunities in 2 s
    dirs = {np.sign(i["push"]["dv"]) for i in _run(env, 1, 200) if "push" in i}
    assert dirs == {-1.0, 1.0}


def test_touchdown_pushes_start_every_step():
    env = gym.make(SLOPE, push={"dv": 0.01, "at": "touchdown", "direction": "forward"})
    infos = _run(env, 0, 400)
    assert infos[-1]["footsteps"] >= 4
    pushed = [k for k, i in enumerate(infos) if "push" in i]
    assert pushed[0] == 1  # the first period of the episode
    for k in pushed[1:]:
        assert infos[k - 1]["impacts"] > 0
    assert len(pushed) == 1 + sum(i["impacts"] > 0 for i in infos[: pushed[-1]])


# ---------------------------------------------------------------------------- API
@pytest.mark.parametrize("observation", ["sensors", "state"])
def test_checkers_pass_with_both_options(observation: str) -> None:
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    kw = {"robot_error": 0.05, "push": {"dv": 0.1, "every": [0.01, 0.02]}}
    env = gym.make(STAIRS, observation=observation, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        check_env(env.unwrapped)
        sb3_check_env(gym.make(STAIRS, observation=observation, **kw), warn=True)


BAD = [
    ({"robot_error": -0.1}, r"robot_error = -0\.1; allowed: a relative half-width in \[0, 0\.5\)"),
    ({"robot_error": 0.5}, r"robot_error = 0\.5; allowed"),
    ({"robot_error": "big"}, r"robot_error = 'big'; allowed"),
    ({"robot_error": True}, r"robot_error = True; allowed"),
    ({"robot_error": {"leg": 0.1}}, r"robot_error: unknown parameter\(s\) \['leg'\]; allowed"),
    ({"robot_error": {"g": 0.1}}, r"unknown parameter\(s\) \['g'\]"),
    ({"robot_error": {"l": 0.7}}, r"robot_error\['l'\] = 0\.7; allowed: a relative half-width"),
    ({"robot_error": {"all": 0.1, "draw": "corners"}}, r"robot_error\.draw = 'corners'; allo"),
    ({"push": {"dv": -0.1, "at": "mid_stance"}}, r"push\.dv = -0\.1 out of range; allowed"),
    ({"push": {"dv": 6, "at": "mid_stance"}}, r"push\.dv = 6 out of range; allowed: .* 5\] m/s"),
    ({"push": {"dv": [0.2, 0.1], "at": "mid_stance"}}, r"push\.dv = \[0\.2, 0\.1\]; .*lo <= hi"),
    ({"push": {"at": "mid_stance"}}, r"missing push setting\(s\) \['dv'\]"),
    ({"push": {"dv": 0.1}}, r"push needs exactly one of 'every'.*got none"),
    ({"push": {"dv": 0.1, "at": "mid_stance", "every": 1}}, r"exactly one of .*\['every', 'at'\]"),
    ({"push": {"dv": 0.1, "at": "heel"}}, r"push\.at = 'heel'; allowed: \['mid_stance', 'touch"),
    ({"push": {"dv": 0.1, "every": 0}}, r"push\.every = 0 out of range; allowed: .*\(0, inf\) s"),
    ({"push": {"dv": 0.1, "times": [-1]}}, r"push\.times = \[-1\]; allowed: a list of times"),
    ({"push": {"dv": 0.1, "at": "mid_stance", "when": 1}}, r"unknown push setting\(s\) \['when'\]"),
    ({"push": {"dv": 0.1, "at": "mid_stance", "direction": "up"}}, r"push\.direction = 'up'"),
    ({"push": {"dv": 0.1, "at": "mid_stance", "probability": 0}}, r"push\.probability = 0;"),
    ({"push": {"dv": 0.1, "at": "mid_stance", "max_pushes": 0}}, r"push\.max_pushes = 0;"),
    ({"push": {"dv": 0.1, "times": [1.0], "after": 2}}, r"push\.after applies to 'every' and"),
    ({"push": {"dv": 0.1, "every": 1, "after": -1}}, r"push\.after = -1; allowed: a time >= 0"),
    ({"push": "often"}, r"push must be a mapping .* got 'often'"),
]


@pytest.mark.parametrize(("kwargs", "match"), BAD)
def test_bad_option_values_are_one_line_errors(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match) as exc:
        gym.make(STAIRS, **kwargs)
    assert "\n" not in str(exc.value)


def test_options_round_trip_through_the_env_config_yaml(tmp_path) -> None:
    push = {"dv": [0.05, 0.1], "at": "mid_stance", "direction": "backward", "max_pushes": 2}
    path = tmp_path / "pushed.yaml"
    path.write_text(
        yaml.safe_dump({"base": "stairs", "robot_error": {"l": 0.05}, "push": push}),
        encoding="utf-8",
    )
    s = resolve_env_settings(path)
    assert s.robot_error.to_setting() == {"l": 0.05}
    assert s.push == PushConfig.from_setting(push)
    again = yaml.safe_load(yaml.safe_dump(s.push.to_setting()))
    assert PushConfig.from_setting(again) == s.push
    assert resolve_env_settings(path, push=False, robot_error=0).push is None
    env = gym.make("roughwalk/CompassGait-v0", config=str(path))
    assert "robot" in env.reset(seed=0)[1]
