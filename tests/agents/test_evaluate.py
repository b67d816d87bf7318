"""Evaluation: metrics on constructed cases, seed split, outputs, trained models, comparison."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from agents.config import EVAL_SEED_OFFSET, TEST_SEED, TRAIN_SEED_LIMIT, seed_label
from agents.evaluate import (
    Evaluation,
    eval_seeds,
    evaluate,
    make_eval_env,
    plot_learning_curve,
    run_episode,
    write_csv,
    write_json,
)
from agents.policies import ZeroPolicy
from controllers import ControllerConfig
from controllers.planner import PlannerConfig

SLOPE = "roughwalk/CompassGaitSlope-v0"
FLAT = "roughwalk/CompassGaitFlat-v0"


class Constant:
    """Stand-in policy: the same command at every step."""

    def __init__(self, value: float) -> None:
        self.value = np.array([value], dtype=np.float32)

    def reset(self) -> None:
        pass

    def __call__(self, obs):
        return self.value


def test_seeds_are_held_out_and_validated():
    assert eval_seeds(0, 3) == [EVAL_SEED_OFFSET, EVAL_SEED_OFFSET + 1, EVAL_SEED_OFFSET + 2]
    assert min(eval_seeds(TEST_SEED, 5)) >= TRAIN_SEED_LIMIT
    with pytest.raises(ValueError, match="seed = -1 is out of range"):
        eval_seeds(-1, 3)
    with pytest.raises(ValueError, match="episodes = 0"):
        eval_seeds(0, 0)


def test_reports_name_validation_and_held_out_seeds_apart():
    """The first 1,000 evaluation seeds are the validation courses (tuned on): a report of them
    never calls them held out."""
    assert seed_label(*eval_seeds(0, 100)[::99]) == "validation seeds 1000000-1000099"
    assert seed_label(*eval_seeds(TEST_SEED, 200)[::199]) == "held-out seeds 1001000-1001199"
    assert seed_label(1_000_990, 1_001_009) == "validation and held-out seeds 1000990-1001009"


def test_a_policy_that_always_walks():
    # the classic walker on its slope walks passively: zero torque never fails
    ev = evaluate("passive", SLOPE, episodes=3, seed=0)
    env = gym.make(SLOPE)
    limit, dt = env.spec.max_episode_steps, env.unwrapped.dt
    s = ev.summary
    assert s["success_rate"] == 1.0 and s["failure_reasons"] == {}
    assert s["mean_footsteps_failed"] is None
    for e in ev.episodes:
        assert e.success and e.failure is None and e.steps == limit
        assert e.duration == pytest.approx(limit * dt)
        # about one 0.536 m step every 0.734 s on the passive limit cycle
        assert e.footsteps == pytest.approx(e.duration / 0.734461, abs=2)
        assert e.speed == pytest.approx(e.distance / e.duration)
        assert e.speed == pytest.approx(0.535919 / 0.734461, rel=0.1)
        assert e.motor_work == 0.0 and e.cost_of_transport == 0.0  # no torque, no work
    assert s["cost_of_transport"] == 0.0
    assert s["mean_distance"] == pytest.approx(np.mean([e.distance for e in ev.episodes]))
    assert [e.seed for e in ev.episodes] == eval_seeds(0, 3)


def test_a_policy_that_always_falls():
    env = gym.make(FLAT)
    mass, g = env.unwrapped.params.total_mass, env.unwrapped.params.g
    results = [run_episode(env, Constant(1.0), seed) for seed in eval_seeds(0, 4)]
    ev = Evaluation("constant", FLAT, {}, results, mass, g)
    s = ev.summary
    assert s["success_rate"] == 0.0
    assert sum(s["failure_reasons"].values()) == 4
    assert set(s["failure_reasons"]) <= set(envs.FAILURES)
    for e in results:
        assert not e.success and e.failure in s["failure_reasons"]
        assert e.steps < env.spec.max_episode_steps
        assert e.motor_work > 0  # full torque on a moving hip does work
        if e.distance > 0:
            assert e.cost_of_transport == pytest.approx(e.motor_work / (mass * g * e.distance))
    assert s["mean_footsteps_failed"] == pytest.approx(np.mean([e.footsteps for e in results]))
    total_work = sum(e.motor_work for e in results)
    total_dist = sum(e.distance for e in results)
    assert s["cost_of_transport"] == pytest.approx(total_work / (mass * g * total_dist))


def test_same_seed_same_result_and_episodes_replay():
    a = evaluate("passive", FLAT, episodes=2, seed=7)
    b = evaluate("passive", FLAT, episodes=2, seed=7)
    assert a.to_dict() == b.to_dict()
    # an episode is replayed from its recorded absolute seed alone
    env = gym.make(FLAT)
    again = run_episode(env, ZeroPolicy(env.action_space), a.episodes[1].seed)
    assert again == a.episodes[1]


def test_json_and_csv_outputs(tmp_path: Path):
    ev = evaluate("passive", SLOPE, episodes=2, seed=0)
    write_json([ev], tmp_path / "out.json")
    write_csv([ev], tmp_path / "out.csv")
    data = json.loads((tmp_path / "out.json").read_text())
    assert data["summary"]["success_rate"] == 1.0 and len(data["episodes"]) == 2
    assert data["episodes"][0]["seed"] == EVAL_SEED_OFFSET
    rows = list(csv.DictReader(open(tmp_path / "out.csv")))
    assert len(rows) == 2 and rows[1]["seed"] == str(EVAL_SEED_OFFSET + 1)
    assert float(rows[0]["distance"]) == pytest.approx(ev.episodes[0].distance)


def test_trained_model_evaluation_and_learning_curve(trained_ppo_run: Path, tmp_path: Path):
    model = trained_ppo_run / "model.zip"
    png = plot_learning_curve(trained_ppo_run, tmp_path / "curve.png")
    assert png.is_file() and png.stat().st_size > 5000
    # the env defaults to the run's (with its smoke-test time limit)
    ev = evaluate(str(model), None, episodes=2, seed=0)
    assert ev.env_id == FLAT and ev.env_kwargs == {"max_episode_steps": 200}
    assert all(e.steps <= 200 for e in ev.episodes)
    # a checkpoint is evaluated with its own normalisation statistics
    ckpt = next((trained_ppo_run / "checkpoints").glob("rl_model_*_steps.zip"))
    evaluate(str(ckpt), None, episodes=1, seed=0)


def test_envs_other_than_roughwalk_ones_are_refused():
    from agents.config import ConfigError
    from agents.evaluate import make_env

    with pytest.raises(ConfigError, match="'CartPole-v1'.*registered: roughwalk/"):
        make_env("CartPole-v1")
    with pytest.raises(ValueError, match="bogus"):
        make_env(FLAT, {"bogus": 1})


def test_damaged_statistics_and_models_are_value_errors(tmp_path: Path):
    from agents.evaluate import check_vecnormalize, load_trained

    pkl = tmp_path / "vecnormalize.pkl"
    pkl.write_bytes(b"\x80\x04K\x01.")  # a valid pickle of the number 1
    with pytest.raises(ValueError, match="vecnormalize.pkl: not VecNormalize statistics"):
        check_vecnormalize(pkl)
    pkl.write_bytes(b"\x80\x04\x95")
    with pytest.raises(ValueError, match="vecnormalize.pkl: .*VecNormalize statistics"):
        check_vecnormalize(pkl)
    (tmp_path / "model.zip").write_text("text")
    with pytest.raises(ValueError, match="not a zip archive"):
        load_trained(tmp_path / "model.zip")
    with pytest.raises(FileNotFoundError):
        load_trained(tmp_path / "other.zip")


def test_outputs_appear_whole_or_not_at_all(tmp_path: Path):
    ev = evaluate("passive", SLOPE, episodes=1, seed=0)
    out = tmp_path / "deep" / "out.csv"
    write_csv([ev], out)
    before = out.read_text()

    class Broken(Evaluation):
        @property
        def episodes(self):  # fails halfway through writing
            raise RuntimeError("disk gone")

        @episodes.setter
        def episodes(self, value):
            pass

    broken = Broken("passive", SLOPE, {}, [], 1.0, 9.81, summary={"x": 1})
    with pytest.raises(RuntimeError, match="disk gone"):
        write_csv([broken], out)
    assert out.read_text() == before  # the previous file is intact
    assert sorted(p.name for p in out.parent.iterdir()) == ["out.csv"]  # no temporary file


def test_a_run_without_episodes_or_evaluations_has_no_learning_curve(tmp_path: Path):
    from agents.evaluate import learning_curve_data

    (tmp_path / "monitor").mkdir()
    (tmp_path / "monitor" / "0.monitor.csv").write_text('#{"t_start": 0}\nr,l,t\n')
    (tmp_path / "eval").mkdir()
    with pytest.raises(ValueError, match="no learning curve to plot"):
        learning_curve_data(tmp_path)
    with pytest.raises(ValueError, match="no learning curve to plot"):
        plot_learning_curve(tmp_path, tmp_path / "curve.png")
    assert not (tmp_path / "curve.png").exists()
    np.savez(tmp_path / "eval" / "evaluations.npz", timesteps=[100, 200], results=[[1.0], [2.0]])
    episodes, evals = learning_curve_data(tmp_path)
    assert len(episodes) == 0 and list(evals["timesteps"]) == [100, 200]
    assert plot_learning_curve(tmp_path, tmp_path / "curve.png").stat().st_size > 5000


@pytest.mark.parametrize("perception", ["known-map", "localise", "mapping"])
def test_perception_modes_reach_the_reference_estimator(perception):
    env, policy, _, _ = make_eval_env(
        "reference", "roughwalk/CompassGaitStairs-v0", perception=perception
    )
    est = policy.estimator
    assert (est.localise, est.mapping) == (perception == "localise", perception == "mapping")
    env.close()


@pytest.mark.parametrize(
    ("policy", "perception", "match"),
    [
        ("reference", "gps", r"perception = 'gps'; allowed: known-map, localise, mapping"),
        ("passive", "localise", r"perception: applies to the pd and reference policies"),
    ],
)
def test_bad_perception_is_a_clear_error(policy, perception, match):
    with pytest.raises(ValueError, match=match):
        make_eval_env(policy, "roughwalk/CompassGaitStairs-v0", perception=perception)


def test_identification_is_on_by_default_and_off_with_identify_0():
    env, policy, _, _ = make_eval_env("reference", "roughwalk/CompassGaitStairs-v0")
    assert policy.identify == 6 and policy.identifier is not None
    env.close()
    env, policy, _, _ = make_eval_env("pd", "roughwalk/CompassGaitStairs-v0", identify=0)
    assert policy.identify == 0 and policy.identifier is None
    env.close()


def test_planner_controller_and_observer_options_reach_the_reference_policy():
    env, policy, _, _ = make_eval_env(
        "reference",
        "roughwalk/CompassGaitStairs-v0",
        planner={"min_thetadot": 0.45},
        controller={"horizon": 2},
        observer_eps=0.03,
        identify=2,
        leg_margin=2.5,
        foot_estimate="selected",
        drop_edge_sd=6.0,
    )
    assert policy.identify == 2 and policy.leg_margin == 2.5 and policy.drop_edge_sd == 6.0
    assert policy.estimator.localiser.estimate == "selected"
    assert policy.settings()["foot_estimate"] == "selected"
    ctrl = policy.controller
    assert ctrl.planner.config.min_thetadot == 0.45
    # the rest of the planner config is the robot preset's
    assert ctrl.planner.config.target_speed == PlannerConfig.for_robot("paper").target_speed
    assert ctrl.config.horizon == 2 and ctrl.config.mode == "replan"
    # ... and so is the rest of the controller config
    assert ctrl.config == ControllerConfig.for_robot("paper", horizon=2)
    assert policy.estimator.observer.eps == 0.03
    env.close()


@pytest.mark.parametrize(
    ("policy", "options", "match"),
    [
        ("reference", {"planner": {"min_thetadot": -1}}, r"min_thetadot"),
        ("reference", {"planner": {"speed": 1}}, r"speed"),
        ("reference", {"controller": {"horizon": 0}}, r"horizon"),
        ("reference", {"controller": {"gain": 1}}, r"controller setting.*gain"),
        ("reference", {"controller": {"robot": "classic"}}, r"controller setting.*robot"),
        ("reference", {"observer_eps": 0.0}, r"observer_eps = 0.0; allowed: a number > 0"),
        ("reference", {"observer_eps": "fast"}, r"observer_eps = 'fast'; allowed"),
        ("passive", {"planner": {"min_thetadot": 0.3}}, r"planner: applies to the pd and"),
        ("passive", {"observer_eps": 0.03}, r"observer_eps: applies to the pd and reference"),
        ("reference", {"identify": -1}, r"identify = -1; allowed: an integer >= 0"),
        ("reference", {"identify": True}, r"identify = True; allowed: an integer >= 0"),
        ("passive", {"identify": 0}, r"identify: applies to the pd and reference"),
        ("reference", {"leg_margin": -0.5}, r"leg_margin = -0.5; allowed: a number in \[0, 10"),
        ("reference", {"leg_margin": "wide"}, r"leg_margin = 'wide'; allowed"),
        ("passive", {"leg_margin": 1.0}, r"leg_margin: applies to the pd and reference"),
        (
            "reference",
            {"leg_margin": 1.0, "perception": "known-map"},
            r"leg_margin: needs the terrain-scan localisation",
        ),
        ("reference", {"foot_estimate": "median"}, r"foot_estimate = 'median'; allowed: mean"),
        ("passive", {"foot_estimate": "mean"}, r"foot_estimate: applies to the pd and"),
        ("reference", {"long_segment": -0.1}, r"long_segment = -0.1; allowed: a number in \[0, 1"),
        ("passive", {"long_segment": 0.0}, r"long_segment: applies to the pd and reference"),
        ("reference", {"drop_edge_sd": 12}, r"drop_edge_sd = 12; allowed: a number in \[0, 10"),
        ("passive", {"drop_edge_sd": 1.0}, r"drop_edge_sd: applies to the pd and reference"),
        (
            "reference",
            {"foot_estimate": "selected", "perception": "known-map"},
            r"foot_estimate = 'selected': a point of the localisation's belief, which needs",
        ),
    ],
)
def test_bad_controller_options_are_clear_errors(policy, options, match):
    with pytest.raises(ValueError, match=match):
        make_eval_env(policy, "roughwalk/CompassGaitStairs-v0", **options)


def test_episodes_record_the_policys_foothold_error():
    """On legs 5 % shorter than the policy's model, dead reckoning mislocates the feet by
    centimetres within 9 footsteps; the terrain-scan localisation keeps them within 2.5 (its
    95th percentile over 200 such courses is 21 mm, README). A policy without a foot estimate
    records None."""
    from agents.policies import make_baseline_policy

    env = gym.make("roughwalk/CompassGaitRough-v0", robot_error={"l": 0.05, "draw": "sign"},
                   max_episode_steps=1600)  # fmt: skip
    seed = 1_000_005  # a draw with the shorter legs
    assert env.reset(seed=seed)[1]["robot"]["l"] < env.unwrapped.robot.l
    located = run_episode(env, make_baseline_policy("reference", env), seed)
    dead = run_episode(env, make_baseline_policy("reference", env, localise=False), seed)
    assert located.footsteps >= 9
    assert located.foot_error_max < 0.025 and dead.foot_error_max > 0.05  # m
    assert run_episode(env, ZeroPolicy(env.action_space), seed).foot_error_max is None


def test_a_policy_error_is_recorded_not_hidden_in_a_failure(capsys, monkeypatch):
    """The reference policy survives an error inside its controller by going limp (a rollout
    never crashes); the episode names the error, the summary counts it and ``roughwalk
    evaluate`` warns, so a defect does not pass for a trip."""
    from agents.policies import make_baseline_policy
    from commands.cli import main
    from controllers.reference import ReferencePolicy

    env = gym.make("roughwalk/CompassGaitRough-v0", difficulty=1.0)
    seed = 1_000_004
    policy = make_baseline_policy("reference", env)
    fine = run_episode(env, policy, seed)
    assert fine.success and fine.policy_error is None

    def broken(self, q, leg):
        raise IndexError("tuple index out of range")

    monkeypatch.setattr(ReferencePolicy, "_tick", broken)
    bad = run_episode(env, policy, seed)
    assert not bad.success and bad.policy_error == "IndexError: tuple index out of range"
    mass, g = env.unwrapped.params.total_mass, env.unwrapped.params.g
    s = Evaluation("reference", FLAT, {}, [fine, bad], mass, g).summary
    assert s["policy_errors"] == 1
    assert main(["evaluate", "--policy", "reference", "--env", FLAT, "--episodes", "1"]) == 0
    assert "went limp in 1 of 1 episodes" in capsys.readouterr().out


def test_an_agent_on_a_changed_base_is_warned_naming_the_settings(tmp_path):
    """A run's manifest records the resolved settings of the base its agent acts on
    (``base_settings``); evaluated where those differ (defaults changed since), the agent is
    still evaluated, with a warning naming each changed setting."""
    import shutil
    import warnings

    from agents.evaluate import BaseChangedWarning, make_env
    from agents.policies import base_settings, settings_changes
    from agents.pretrained import PRETRAINED_DIR
    from agents.trained import TrainedPolicy

    shutil.copytree(PRETRAINED_DIR / "residual_ppo_rough_d3", tmp_path / "run")
    model = tmp_path / "run" / "best_model.zip"
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    trained = TrainedPolicy(model)
    env = trained.wrap_env(make_env(trained.config.env_id, trained.config.env_kwargs))
    now = base_settings(env)
    env.close()
    assert [b["wrapper"] for b in now] == ["ResidualWrapper"] and settings_changes(now, now) == []
    # a base recorded before an option existed had its old behaviour (ADDED_SETTINGS)
    older = [{k: v for k, v in now[0].items() if k != "foot_estimate"}]
    added = ("speed_reserve", "dip_floor", "drop_edge_margin")
    older[0]["planner"] = {k: v for k, v in now[0]["planner"].items() if k not in added}
    other = [{**now[0], "foot_estimate": "selected"}]
    reserve = [{**now[0], "planner": {**now[0]["planner"], "speed_reserve": 0.4}}]
    for recorded, changed in (
        (now, []),
        (older, []),
        (other, ["foot_estimate"]),
        (reserve, ["speed_reserve"]),
        (json.loads(json.dumps(now)), ["deeper_relaxation"]),
    ):
        if "deeper_relaxation" in changed:
            recorded[0]["controller"]["deeper_relaxation"] = [["torque_fraction", 0.9]]
        (tmp_path / "run" / "manifest.json").write_text(
            json.dumps({**manifest, "base_settings": recorded})
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            env, _, _, _ = make_eval_env(str(model), None)
            env.close()
        said = [str(w.message) for w in caught if w.category is BaseChangedWarning]
        if not changed:
            assert said == []
        elif changed == ["foot_estimate"]:
            assert len(said) == 1 and "[0].foot_estimate: 'selected', now 'mean'" in said[0]
        elif changed == ["speed_reserve"]:
            assert len(said) == 1 and "[0].planner.speed_reserve: 0.4, now 0.0" in said[0]
        else:
            assert len(said) == 1
            assert "[0].controller.deeper_relaxation: [['torque_fraction', 0.9]], now []" in said[0]
