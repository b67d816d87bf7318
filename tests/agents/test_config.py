"""Agent configs: every shipped file validates; bad configs fail with a clear message."""

from __future__ import annotations

from pathlib import Path

import pytest

from agents.config import (
    EVAL_SEED_OFFSET,
    TRAIN_SEED_LIMIT,
    ConfigError,
    config_from_dict,
    load_config,
    parse_assignments,
)
from agents.residual import ResidualWrapper

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "agents"
CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))

GOOD = {
    "run": {"algo": "ppo", "env": "roughwalk/CompassGaitFlat-v0"},
    "roughwalk/CompassGaitFlat-v0": {"n_timesteps": 1000, "n_steps": 64},
}


def _with(section: str, **changes) -> dict:
    data = {k: dict(v) for k, v in GOOD.items()}
    data[section].update(changes)
    return data


def test_shipped_configs_cover_both_algorithms_both_variants_and_every_terrain():
    cfgs = [load_config(p) for p in CONFIGS]
    combos = {(c.algo, c.is_residual, c.env_id, c.env_kwargs.get("difficulty")) for c in cfgs}
    for algo in ("ppo", "sac"):
        for residual in (False, True):
            assert (algo, residual, "roughwalk/CompassGaitFlat-v0", None) in combos
            assert (algo, residual, "roughwalk/CompassGaitStairs-v0", None) in combos
            assert (algo, residual, "roughwalk/CompassGaitRough-v0", 1.0) in combos
            assert (algo, residual, "roughwalk/CompassGaitRough-v0", 2.0) in combos
    for c in cfgs:
        assert c.name.startswith(c.algo) and ("residual" in c.name) == c.is_residual
        assert c.normalize_kwargs is not None  # the observations need scaling
        kwargs = c.algo_kwargs()
        assert kwargs["policy"] == "MlpPolicy"
        specs = {cls.__name__: kw for cls, kw in c.wrapper_specs()}
        # a real training budget, not a smoke test's (agent steps: footsteps for the
        # per-footstep agents, about 110 control periods each)
        assert c.n_timesteps >= (10_000 if c.is_footstep else 50_000)
        # no agent reads the raw encoders alone: each observes the sensor-based state estimate
        if c.is_residual:
            assert specs["ResidualWrapper"]["observe_state"] is True
        elif c.is_footstep:
            assert specs["FootstepWrapper"]["observe_state"] is True
        else:
            assert "EstimatedStateObservation" in specs


def test_residual_configs_wrap_the_reference_controller():
    cfg = load_config(CONFIG_DIR / "ppo_residual_stairs.yaml")
    ((cls, kwargs),) = cfg.wrapper_specs()
    assert cls is ResidualWrapper
    assert kwargs["base"] == "reference" and 0 < kwargs["scale"] <= 1


def test_overrides_and_schedules():
    cfg = load_config(CONFIG_DIR / "ppo_flat.yaml", {"n_steps": 64}, {"seed": 12})
    assert cfg.hyperparams["n_steps"] == 64 and cfg.seed == 12
    lr = cfg.algo_kwargs()["learning_rate"]  # "lin_3e-4" in the file
    assert lr(1.0) == pytest.approx(3e-4) and lr(0.5) == pytest.approx(1.5e-4)
    assert parse_assignments(["a=1", "b=[64, 64]", "c=lin_1e-3", "d:0.5"]) == {
        "a": 1,
        "b": [64, 64],
        "c": "lin_1e-3",
        "d": 0.5,
    }
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        parse_assignments(["oops"])


def test_missing_file(tmp_path: Path):
    with pytest.raises(ConfigError, match="config file not found: .*nope.yaml"):
        load_config(tmp_path / "nope.yaml")


def test_unknown_algorithm():
    with pytest.raises(ConfigError, match=r"unknown algorithm 'dqn2'; allowed: a2c, ppo, sac, td3"):
        config_from_dict(_with("run", algo="dqn2"))


def test_unknown_env_id():
    data = _with("run", env="roughwalk/CompassGaitMoon-v0")
    with pytest.raises(ConfigError, match=r"unknown environment id 'roughwalk/CompassGaitMoon-v0'"):
        config_from_dict(data)
    with pytest.raises(ConfigError, match=r"roughwalk/CompassGaitRough-v0"):  # lists the ids
        config_from_dict(data)


@pytest.mark.parametrize(
    ("section", "change", "message"),
    [
        ("roughwalk/CompassGaitFlat-v0", {"n_stepz": 64}, r"unknown hyperparameter\(s\) n_stepz"),
        (
            "roughwalk/CompassGaitFlat-v0",
            {"n_timesteps": -5},
            "n_timesteps must be a whole number >= 1, got -5",
        ),
        ("roughwalk/CompassGaitFlat-v0", {"learning_rate": "cos_1e-3"}, "lin_<number>"),
        ("roughwalk/CompassGaitFlat-v0", {"env_wrapper": "agents.nowhere.Wrap"}, "cannot import"),
        ("roughwalk/CompassGaitFlat-v0", {"normalize": "yes"}, "normalize must be"),
        ("roughwalk/CompassGaitFlat-v0", {"frame_stack": 0}, "frame_stack must be a whole"),
        ("roughwalk/CompassGaitFlat-v0", {"callback": "x.Y"}, "callback is not supported"),
        ("roughwalk/CompassGaitFlat-v0", {"device": "cuda"}, r"unknown hyperparameter\(s\) dev"),
        ("run", {"seed": TRAIN_SEED_LIMIT}, r"run.seed = 1000000 is out of range"),
        ("run", {"eval_seed": 995}, r"run.eval_seed = 995 is out of range; allowed: in \[0, 990\]"),
        ("run", {"evalfreq": 10}, r"unknown run setting\(s\) evalfreq"),
        ("run", {"eval_freq": "often"}, "run.eval_freq must be int"),
    ],
)
def test_bad_values_name_the_field(section, change, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(_with(section, **change))


def test_missing_sections(tmp_path: Path):
    with pytest.raises(ConfigError, match="missing 'run' section"):
        config_from_dict({"roughwalk/CompassGaitFlat-v0": {"n_timesteps": 10}})
    with pytest.raises(ConfigError, match="missing hyperparameter section"):
        config_from_dict({"run": GOOD["run"]})
    bad = tmp_path / "bad.yaml"
    bad.write_text("run: [unclosed")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(bad)


def test_seed_ranges_are_disjoint():
    assert TRAIN_SEED_LIMIT <= EVAL_SEED_OFFSET
    cfg = load_config(CONFIG_DIR / "sac_flat.yaml", run_overrides={"seed": 5})
    assert cfg.seed + cfg.n_envs <= TRAIN_SEED_LIMIT


def test_the_hyperparameter_table_matches_the_algorithms():
    """Every known hyperparameter is a keyword of its algorithm or an rl-zoo3 key, and every
    keyword of the algorithms is either known, unsupported, or set by the trainer."""
    import inspect

    from agents.config import ZOO_KEYS, algorithms
    from agents.hyperparams import HYPERPARAMETERS, UNSUPPORTED

    set_by_trainer = {"self", "env", "seed", "device", "tensorboard_log", "verbose"}
    for algo, cls in algorithms().items():
        keywords = set(inspect.signature(cls.__init__).parameters) - {"_init_setup_model"}
        known = {name for name, a in HYPERPARAMETERS if a == algo}
        assert known <= keywords | ZOO_KEYS, algo
        assert keywords - set_by_trainer <= known | set(UNSUPPORTED), algo


def test_values_are_normalised_and_checked_against_their_ranges():
    cfg = config_from_dict(
        _with("roughwalk/CompassGaitFlat-v0", learning_rate="1e-3", n_timesteps=2.0e3, gamma=1)
    )
    # YAML reads 1e-3 as text; a whole float budget is a whole number
    assert cfg.hyperparams["learning_rate"] == 1e-3 and cfg.hyperparams["n_timesteps"] == 2000
    assert isinstance(cfg.hyperparams["n_timesteps"], int)
    for change, message in [
        ({"gamma": 2.0}, r"gamma must be a number in \[0, 1\], got 2.0"),
        ({"n_steps": "abc"}, "n_steps must be a whole number >= 1, got 'abc'"),
        ({"n_steps": 64.5}, "n_steps must be a whole number >= 1, got 64.5"),
        ({"n_steps": True}, "n_steps must be a whole number >= 1, got True"),
        ({"policy": "CnnPolicy"}, "policy must be one of 'MlpPolicy', got 'CnnPolicy'"),
        ({"clip_range": "lin_-1"}, "clip_range must be a number > 0 or 'lin_<number>'"),
        ({"learning_rate": float("nan")}, "learning_rate must be a number > 0"),
        ({"normalize": {"clip_obs": 0}}, r"normalize must be .*\(clip_obs: a number > 0\)"),
        ({"n_steps": 1, "n_envs": 1}, "n_steps times n_envs must be at least 2"),
        ({"buffer_size": 100}, r"unknown hyperparameter\(s\) buffer_size for PPO"),
    ]:
        with pytest.raises(ConfigError, match=message):
            config_from_dict(_with("roughwalk/CompassGaitFlat-v0", **change))
    with pytest.raises(ConfigError, match=r"gamma \(from --hyperparams\) must be"):
        load_config(CONFIG_DIR / "sac_flat.yaml", {"gamma": -0.1})


def test_planned_timesteps_round_the_budget_up_to_whole_updates():
    cfg = load_config(CONFIG_DIR / "ppo_flat.yaml", {"n_timesteps": 4000})
    assert cfg.rollout_steps == 1024 * 8 and cfg.planned_timesteps() == 8192
    assert cfg.planned_timesteps(start=8192) == 8192  # nothing left to do
    sac = load_config(CONFIG_DIR / "sac_flat.yaml", {"n_timesteps": 600, "train_freq": 16})
    assert sac.planned_timesteps() == 16 * sac.n_envs * -(-600 // (16 * sac.n_envs))


@pytest.mark.parametrize(
    ("run", "hyper", "message"),
    [
        ({"residual_int": "zero"}, {}, r"unknown run setting\(s\) residual_int; allowed: .*"),
        ({"residual_init": "ones"}, {}, "run.residual_init must be one of 'default', 'zero'"),
        ({"init_log_std": 5}, {}, r"run.init_log_std must be a number in \[-20, 2\] or null"),
        ({"critic_warmup": -1}, {}, "run.critic_warmup must be a whole number >= 0, got -1"),
        ({"critic_warmup": 1.5}, {}, "run.critic_warmup must be a whole number >= 0"),
        (
            {"init_log_std": -1.0},
            {"policy_kwargs": {"log_std_init": -2.0}},
            "run.init_log_std and policy_kwargs.log_std_init both",
        ),
        ({"algo": "td3", "init_log_std": -1.0}, {}, "TD3 has no log standard deviation"),
        ({"scale_ramp": 100}, {}, "run.scale_ramp needs an agents.residual.ResidualWrapper"),
        ({"algo": "sac", "residual_init": "zero"}, {}, "needs learning_starts: 0 \\(got 100\\)"),
        (
            {},
            {"env_wrapper": {"agents.curriculum.TerrainCurriculum": {"level": 3}}},
            r"TerrainCurriculum: unknown argument\(s\) level; allowed: min_difficulty, ",
        ),
        (
            {},
            {"env_wrapper": {"agents.curriculum.TerrainCurriculum": {"promote": 2}}},
            r"TerrainCurriculum: promote = 2; allowed: a number in \(0, 1\]",
        ),
        (
            {},
            {"env_wrapper": {"agents.residual.ResidualWrapper": {"scal": 0.3}}},
            r"ResidualWrapper: unknown argument\(s\) scal; allowed: base, scale, ",
        ),
    ],
)
def test_residual_recipe_settings_are_checked(run, hyper, message):
    data = _with("run", **run)
    data["roughwalk/CompassGaitFlat-v0"].update(hyper)
    if data["run"]["algo"] != "ppo":
        data["roughwalk/CompassGaitFlat-v0"].pop("n_steps")
    with pytest.raises(ConfigError, match=message):
        config_from_dict(data)


def test_residual_recipe_settings_are_kept_in_the_run_record():
    plain = config_from_dict(GOOD)
    assert set(plain.to_dict()["run"]).isdisjoint({"residual_init", "critic_warmup"})  # as before
    cfg = config_from_dict(_with("run", residual_init="zero", critic_warmup=512.0))
    assert (cfg.residual_init, cfg.init_log_std, cfg.critic_warmup) == ("zero", None, 512)
    again = config_from_dict(cfg.to_dict())
    assert (again.residual_init, again.critic_warmup) == ("zero", 512)
    zero = load_config(CONFIG_DIR / "sac_residual_rough_hard_zero.yaml")
    assert (zero.residual_init, zero.init_log_std, zero.critic_warmup) == ("zero", -2.0, 10_000)
