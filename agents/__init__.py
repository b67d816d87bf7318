"""roughwalk RL library: agent configs, baseline and trained policies, the residual and
estimated-state wrappers, training, evaluation and the RL-versus-control comparison.

Importing this package does not import torch or stable-baselines3: the names whose modules
subclass stable-baselines3 classes (the vector-env adapter and the training callbacks) are
loaded on first use.
"""

from importlib import import_module
from typing import Any

from .compare import SETTINGS, Comparison, Setting, compare, markdown_table
from .config import (
    EVAL_SEED_OFFSET,
    TEST_SEED,
    TRAIN_SEED_LIMIT,
    VALIDATION_SEEDS,
    AgentConfig,
    ConfigError,
    config_from_dict,
    load_config,
    parse_assignments,
)
from .curriculum import TerrainCurriculum
from .evaluate import (
    EpisodeResult,
    Evaluation,
    eval_seeds,
    evaluate,
    plot_learning_curve,
    run_episode,
    write_csv,
    write_json,
)
from .policies import BASELINES, Policy, ZeroPolicy, make_baseline_policy
from .residual import ResidualWrapper
from .runs import find_manifest, find_vecnormalize, load_vecnormalize
from .train import build, run_dir_for, save, set_threads, train
from .trained import TrainedPolicy, load_policy
from .wrappers import VELOCITY_LIMIT, EstimatedStateObservation, estimate_features

# name -> module, imported on first access (these modules import stable-baselines3)
_LAZY = {
    "SB3VecEnv": "agents.sb3_vec_env",
    "make_sb3_vec_env": "agents.sb3_vec_env",
    "HeldOutEvalCallback": "agents.callbacks",
    "SaveVecNormalizeOnBest": "agents.callbacks",
    "CriticWarmup": "agents.callbacks",
    "ResidualScaleRamp": "agents.callbacks",
    "CurriculumLog": "agents.callbacks",
}

__all__ = [
    "BASELINES",
    "EVAL_SEED_OFFSET",
    "SETTINGS",
    "TEST_SEED",
    "TRAIN_SEED_LIMIT",
    "VALIDATION_SEEDS",
    "VELOCITY_LIMIT",
    "AgentConfig",
    "Comparison",
    "ConfigError",
    "CriticWarmup",
    "CurriculumLog",
    "EpisodeResult",
    "EstimatedStateObservation",
    "Evaluation",
    "HeldOutEvalCallback",
    "Policy",
    "ResidualScaleRamp",
    "ResidualWrapper",
    "SB3VecEnv",
    "SaveVecNormalizeOnBest",
    "Setting",
    "TerrainCurriculum",
    "TrainedPolicy",
    "ZeroPolicy",
    "build",
    "compare",
    "config_from_dict",
    "estimate_features",
    "eval_seeds",
    "evaluate",
    "find_manifest",
    "find_vecnormalize",
    "load_config",
    "load_policy",
    "load_vecnormalize",
    "make_baseline_policy",
    "make_sb3_vec_env",
    "markdown_table",
    "parse_assignments",
    "plot_learning_curve",
    "run_dir_for",
    "run_episode",
    "save",
    "set_threads",
    "train",
    "write_csv",
    "write_json",
]


def __getattr__(name: str) -> Any:
    """The stable-baselines3-based names of ``_LAZY``, imported on first access (PEP 562)."""
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names, the lazily imported ones included."""
    return sorted(set(globals()) | set(_LAZY))
