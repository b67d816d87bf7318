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
        assert c.n_timesteps >= 50_000  # a real training budget, not a smoke test's
        # no agent reads the raw encoders alone: each observes the sensor-based state estimate
        specs = {cls.__name__: kw for cls, kw in c.wrapper_specs()}
        if c.is_residual:
            assert specs["ResidualWrapper"]["observe_state"] is True
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
