"""Agent configs: loading and validation of ``configs/agents/*.yaml``.

One file describes one training run. It holds two top-level sections:

``run`` (ours): the algorithm, the environment id and run-level settings::

    run:
      algo: ppo                      # ppo | sac | td3 | a2c
      env: roughwalk/CompassGaitRough-v0
      seed: 0                        # training seed, 0 <= seed < TRAIN_SEED_LIMIT - n_envs
      eval_freq: 50000               # env steps between evaluations (0: never)
      eval_episodes: 10              # episodes per evaluation, on held-out seeds
      eval_seed: 0                   # evaluation k resets with seed 1,000,000 + eval_seed + k,
                                     # eval_seed + eval_episodes <= 1000 (validation seeds)
      checkpoint_freq: 200000        # env steps between checkpoints (0: never)
      save_replay_buffer: false      # off-policy algorithms: also checkpoint the replay buffer
      vec_env: dummy                 # dummy | subproc (one process per env) | native (the
                                     # batched vector env; not with env_wrapper)
      residual_init: default         # default | zero: zero last actor layer (start at the base)
      init_log_std: null             # initial exploration log std (PPO, A2C, SAC); null: default
      critic_warmup: 0               # env steps training only the critic, the actor frozen
      scale_ramp: 0                  # env steps ramping the residual scale up from 0

The last four (``agents.hyperparams.RUN_OPTIONS``) are the residual-learning recipe of Silver
et al. 2018: with ``residual_init: zero`` a new model's action is exactly 0, so a residual
agent starts as its base policy (``agents.residual.init_policy``); ``critic_warmup`` trains
the value function on the frozen policy's transitions first (``agents.callbacks.CriticWarmup``);
``scale_ramp`` grows the residual's authority (``agents.callbacks.ResidualScaleRamp``).

``<env id>`` (rl-zoo3's hyperparameter format): ``policy``, ``n_timesteps``, ``n_envs``,
``normalize``, ``frame_stack``, ``env_kwargs``, ``env_wrapper``, ``policy_kwargs`` and the
algorithm's own keyword arguments, with rl-zoo3's ``lin_<value>`` linear schedules; each is
checked against the table of known hyperparameters and their ranges in ``agents.hyperparams``
before stable-baselines3 sees it. Because the env id is a top-level key, the same file works
with ``python -m rl_zoo3.train --algo ppo --env <env id> --gym-packages envs --conf-file <file>``,
which ignores the ``run`` section.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs  # noqa: F401  (registers the roughwalk ids)
from agents.footstep import FootstepWrapper
from agents.hyperparams import (
    OFF_POLICY,
    ON_POLICY,
    RUN_OPTION_DEFAULTS,
    RUN_OPTIONS,
    check_hyperparams,
)
from agents.residual import ResidualWrapper
from envs.config_util import read_yaml_mapping

# Training seeds lie below TRAIN_SEED_LIMIT, evaluation seeds at or above EVAL_SEED_OFFSET, so
# the courses used to report results are never those drawn during training. The first
# VALIDATION_SEEDS evaluation seeds serve the periodic evaluation during training (which picks
# best_model.zip); reported results use TEST_SEED and above by default.
TRAIN_SEED_LIMIT = 1_000_000
EVAL_SEED_OFFSET = 1_000_000
VALIDATION_SEEDS = 1000
TEST_SEED = VALIDATION_SEEDS
MAX_SEED = 2**32 - 1


def seed_label(first: int, last: int) -> str:
    """What the evaluation seeds ``first`` to ``last`` (absolute) are: ``"validation seeds
    a-b"`` within the first :data:`VALIDATION_SEEDS` evaluation seeds (those tuned on),
    ``"held-out seeds a-b"`` past them, ``"validation and held-out seeds a-b"`` across both."""
    edge = EVAL_SEED_OFFSET + VALIDATION_SEEDS
    if first >= edge:
        kind = "held-out"
    else:
        kind = "validation" if last < edge else "validation and held-out"
    return f"{kind} seeds {first}-{last}"


# rl-zoo3 keys that are not keyword arguments of the algorithm
ZOO_KEYS = frozenset(
    {
        "n_timesteps",
        "n_envs",
        "normalize",
        "env_kwargs",
        "env_wrapper",
        "vec_env_wrapper",
        "frame_stack",
        "callback",
        "monitor_kwargs",
        "noise_type",
        "noise_std",
    }
)
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf", "delta_std")
RUN_KEYS = {
    "algo": str,
    "env": str,
    "seed": int,
    "eval_freq": int,
    "eval_episodes": int,
    "eval_seed": int,
    "checkpoint_freq": int,
    "save_replay_buffer": bool,
    "vec_env": str,
}
VEC_ENVS = ("dummy", "subproc", "native")
RUN_DEFAULTS: dict[str, Any] = {
    "seed": 0,
    "eval_freq": 50_000,
    "eval_episodes": 10,
    "eval_seed": 0,
    "checkpoint_freq": 200_000,
    "save_replay_buffer": False,
    "vec_env": "dummy",
}


class ConfigError(ValueError):
    """An agent config that cannot be used; the message names the file and the field."""


def algorithms() -> dict[str, type]:
    """Supported algorithm names -> stable-baselines3 classes."""
    from stable_baselines3 import A2C, PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C}


def algorithm_class(name: str) -> type:
    """The stable-baselines3 class of algorithm ``name`` (case-insensitive)."""
    algos = algorithms()
    try:
        return algos[name.lower()]
    except KeyError:
        raise ConfigError(
            f"unknown algorithm {name!r}; allowed: {', '.join(sorted(algos))}"
        ) from None


def check_env_id(env_id: str) -> None:
    """Raise ConfigError unless ``env_id`` is registered (``import envs`` registers ours)."""
    if env_id not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("roughwalk/"))
        raise ConfigError(
            f"unknown environment id {env_id!r}; registered roughwalk ids: {', '.join(ours)}"
        )


def resolve_object(name: str) -> Any:
    """Import ``package.module.Name`` and return ``Name``."""
    module, _, attr = name.rpartition(".")
    if not module:
        raise ConfigError(f"{name!r} is not a dotted path 'package.module.Name'")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"cannot import {name!r}: {exc}") from None


def linear_schedule(initial: float) -> Callable[[float], float]:
    """rl-zoo3's ``lin_<initial>``: decays linearly from ``initial`` to 0 over training."""
    from stable_baselines3.common.utils import LinearSchedule

    return LinearSchedule(float(initial), 0.0, 1.0)


@dataclass
class AgentConfig:
    """A validated agent config (see the module docstring for the file format).

    Attributes:
        path: the file it was read from (its stem names the run).
        algo: algorithm name (``ppo``, ``sac``, ``td3``, ``a2c``).
        env_id: Gymnasium id of the environment.
        hyperparams: the env-id section (rl-zoo3 format), overrides applied.
        seed: training seed; training env ``i`` is seeded with ``seed + i``.
        eval_freq: env steps between periodic evaluations (0: none).
        eval_episodes: episodes per periodic evaluation.
        eval_seed: first validation seed of the periodic evaluations (offset by
            ``EVAL_SEED_OFFSET``).
        checkpoint_freq: env steps between checkpoints (0: none).
        save_replay_buffer: also checkpoint the replay buffer (off-policy algorithms).
        vec_env: ``dummy``, ``subproc`` or ``native`` (see the module docstring).
        residual_init: ``default`` or ``zero`` (``agents.hyperparams.RUN_OPTIONS``).
        init_log_std: initial log standard deviation of the exploration, or None.
        critic_warmup: env steps during which only the critic learns (0: none).
        scale_ramp: env steps over which the residual scale rises from 0 (0: none).
        raw: the file's contents as read.
    """

    path: Path
    algo: str
    env_id: str
    hyperparams: dict[str, Any]
    seed: int = 0
    eval_freq: int = 50_000
    eval_episodes: int = 10
    eval_seed: int = 0
    checkpoint_freq: int = 200_000
    save_replay_buffer: bool = False
    vec_env: str = "dummy"
    residual_init: str = "default"
    init_log_std: float | None = None
    critic_warmup: int = 0
    scale_ramp: int = 0
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def name(self) -> str:
        """Short name of the run (the file's stem)."""
        return self.path.stem

    def with_seed(self, seed: int) -> AgentConfig:
        """The same config with training seed ``seed``.

        Raises:
            ConfigError: ``seed`` out of range (training envs ``seed + i`` stay below
                ``TRAIN_SEED_LIMIT``).
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ConfigError(f"{self.path}: run.seed = {seed!r}; allowed: an integer")
        n_envs = int(self.hyperparams.get("n_envs", 1))
        _check_range(self.path, "run.seed", int(seed), 0, TRAIN_SEED_LIMIT - n_envs)
        return dataclasses.replace(self, seed=int(seed))

    @property
    def algo_class(self) -> type:
        """The stable-baselines3 class of ``algo``."""
        return algorithm_class(self.algo)

    @property
    def n_timesteps(self) -> int:
        """Training budget [env steps]."""
        return int(self.hyperparams["n_timesteps"])

    @property
    def n_envs(self) -> int:
        """Number of training envs (1 unless the config says otherwise)."""
        return int(self.hyperparams.get("n_envs", 1))

    @property
    def rollout_steps(self) -> int:
        """Env steps the algorithm collects between two updates, all envs together: training
        stops at the first whole multiple of it at or beyond the budget (PPO and A2C:
        ``n_steps * n_envs``; SAC and TD3: ``train_freq * n_envs`` when ``train_freq`` counts
        steps, else ``n_envs``)."""
        defaults = inspect.signature(self.algo_class.__init__).parameters
        if self.algo in ON_POLICY:
            return int(self.hyperparams.get("n_steps", defaults["n_steps"].default)) * self.n_envs
        freq = self.hyperparams.get("train_freq", defaults["train_freq"].default)
        if isinstance(freq, list | tuple):
            freq = freq[0] if freq[1] == "step" else 1
        return int(freq) * self.n_envs

    def planned_timesteps(self, start: int = 0) -> int:
        """The env steps a training from ``start`` to the budget ends at (the budget rounded
        up to whole updates, see :attr:`rollout_steps`).

        Args:
            start: env steps already trained (a resumed run).
        """
        chunk = self.rollout_steps
        return start + -(-max(self.n_timesteps - start, 0) // chunk) * chunk

    @property
    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``gym.make`` for the env (a copy)."""
        return dict(self.hyperparams.get("env_kwargs") or {})

    @property
    def frame_stack(self) -> int | None:
        """Number of stacked observations (``VecFrameStack``), or None when not stacking."""
        n = self.hyperparams.get("frame_stack")
        return int(n) if n else None

    @property
    def normalize_kwargs(self) -> dict[str, Any] | None:
        """Keyword arguments of ``VecNormalize``, or None when not normalising."""
        norm = self.hyperparams.get("normalize", False)
        if norm is False or norm is None:
            return None
        kwargs = {} if norm is True else dict(norm)
        if "gamma" in self.hyperparams:
            kwargs.setdefault("gamma", float(self.hyperparams["gamma"]))
        return kwargs

    def wrapper_specs(self) -> list[tuple[type, dict[str, Any]]]:
        """The ``env_wrapper`` entries as (class, keyword arguments), outermost last."""
        spec = self.hyperparams.get("env_wrapper")
        if spec is None:
            return []
        entries = spec if isinstance(spec, list) else [spec]
        out = []
        for entry in entries:
            if isinstance(entry, str):
                out.append((resolve_object(entry), {}))
            elif isinstance(entry, Mapping) and len(entry) == 1:
                ((name, kwargs),) = entry.items()
                out.append((resolve_object(name), dict(kwargs or {})))
            else:
                raise ConfigError(
                    f"{self.path}: env_wrapper entries must be 'module.Class' or "
                    f"{{'module.Class': {{kwargs}}}}, got {entry!r}"
                )
        return out

    def wrap(self, env: gym.Env, training: bool = False) -> gym.Env:
        """Apply the configured ``env_wrapper`` chain to one env.

        Args:
            env: the env.
            training: also apply the wrappers that shape training only (a class attribute
                ``training_only = True``, e.g. ``agents.curriculum.TerrainCurriculum``);
                evaluation envs leave them out.
        """
        for cls, kwargs in self.wrapper_specs():
            if training or not getattr(cls, "training_only", False):
                env = cls(env, **kwargs)
        return env

    @property
    def is_residual(self) -> bool:
        """Whether the agent learns a residual on a base policy (a ``ResidualWrapper``)."""
        return any(issubclass(cls, ResidualWrapper) for cls, _ in self.wrapper_specs())

    @property
    def is_footstep(self) -> bool:
        """Whether one agent step is a footstep of the reference planner (a
        ``FootstepWrapper``)."""
        return any(issubclass(cls, FootstepWrapper) for cls, _ in self.wrapper_specs())

    def algo_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for the algorithm's constructor (schedules and noise resolved)."""
        kw = {k: copy.deepcopy(v) for k, v in self.hyperparams.items() if k not in ZOO_KEYS}
        kw.setdefault("policy", "MlpPolicy")
        for key in SCHEDULE_KEYS:
            value = kw.get(key)
            if isinstance(value, str):
                kw[key] = linear_schedule(float(value.split("_", 1)[1]))
        if isinstance(kw.get("policy_kwargs"), str):
            kw["policy_kwargs"] = _eval_policy_kwargs(kw["policy_kwargs"])
        if isinstance(kw.get("train_freq"), list):
            kw["train_freq"] = tuple(kw["train_freq"])
        if "noise_type" in self.hyperparams:
            kw["action_noise"] = self._action_noise()
        return kw

    def _action_noise(self) -> Any:
        from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

        kind = str(self.hyperparams["noise_type"]).strip()
        std = float(self.hyperparams.get("noise_std", 0.1))
        cls = {"normal": NormalActionNoise, "ornstein-uhlenbeck": OrnsteinUhlenbeckActionNoise}
        if kind not in cls:
            raise ConfigError(f"{self.path}: noise_type {kind!r}; allowed: {', '.join(cls)}")
        return cls[kind](mean=np.zeros(1), sigma=std * np.ones(1))

    def to_dict(self) -> dict[str, Any]:
        """The config as a plain dict in the file format (for the run manifest)."""
        run = {
            "algo": self.algo,
            "env": self.env_id,
            "seed": self.seed,
            "eval_freq": self.eval_freq,
            "eval_episodes": self.eval_episodes,
            "eval_seed": self.eval_seed,
            "checkpoint_freq": self.checkpoint_freq,
            "save_replay_buffer": self.save_replay_buffer,
            "vec_env": self.vec_env,
        }
        for key, default in RUN_OPTION_DEFAULTS.items():  # only when set: as older runs wrote
            if getattr(self, key) != default:
                run[key] = getattr(self, key)
        return {"run": run, self.env_id: copy.deepcopy(self.hyperparams)}


def _eval_policy_kwargs(text: str) -> dict[str, Any]:
    """rl-zoo3 writes policy_kwargs as a Python expression, e.g. ``dict(net_arch=[64, 64])``."""
    import torch.nn as nn

    try:
        value = eval(text, {"__builtins__": {}}, {"dict": dict, "nn": nn})  # noqa: S307
    except Exception as exc:
        raise ConfigError(f"policy_kwargs {text!r} is not a valid expression: {exc}") from None
    if not isinstance(value, dict):
        raise ConfigError(f"policy_kwargs must evaluate to a dict, got {value!r}")
    return value


def parse_value(text: str) -> Any:
    """Parse a command-line ``key=value`` value as YAML (numbers, booleans, lists, dicts)."""
    return yaml.safe_load(text)


def parse_assignments(items: list[str] | None) -> dict[str, Any]:
    """Command-line ``items`` as a dict: ``["a=1", "b=[64, 64]", "c:0.5"]`` ->
    ``{"a": 1, "b": [64, 64], "c": 0.5}`` (values parsed as YAML).

    ``KEY:VALUE`` (rl-zoo3's ``-params`` form) is accepted where the item has no ``=``.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, value = item.partition("=" if "=" in item else ":")
        if not sep or not key.strip():
            raise ConfigError(f"expected KEY=VALUE, got {item!r}")
        out[key.strip()] = parse_value(value)
    return out


def load_config(
    path: str | Path,
    overrides: Mapping[str, Any] | None = None,
    run_overrides: Mapping[str, Any] | None = None,
) -> AgentConfig:
    """Load and validate an agent config.

    Args:
        path: YAML file in the format of the module docstring.
        overrides: hyperparameters replacing those of the file (e.g. ``{"n_steps": 64}``).
        run_overrides: ``run`` settings replacing those of the file (e.g. ``{"seed": 3}``).

    Raises:
        ConfigError: missing or malformed file, unknown algorithm, unknown env id, unknown
            hyperparameter or run key, value out of range.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = read_yaml_mapping(
            path,
            "agent config",
            allow_empty=False,
            holds="mapping with a 'run' section and an env-id section",
        )
    except (ValueError, OSError) as exc:
        raise ConfigError(str(exc)) from None
    return config_from_dict(data, path, overrides, run_overrides)


def config_from_dict(
    data: Mapping[str, Any],
    path: str | Path = "<config>",
    overrides: Mapping[str, Any] | None = None,
    run_overrides: Mapping[str, Any] | None = None,
) -> AgentConfig:
    """Validate a config given as a dict.

    Args:
        data: the file's contents (a ``run`` section and an env-id section).
        path: where it came from, for the messages and the run's name.
        overrides: hyperparameters replacing those of ``data``.
        run_overrides: ``run`` settings replacing those of ``data``.

    Raises:
        ConfigError: as :func:`load_config`.
    """
    path = Path(path)
    run = data.get("run")
    if not isinstance(run, dict):
        raise ConfigError(f"{path}: missing 'run' section (with at least 'algo' and 'env')")
    run = {**RUN_DEFAULTS, **RUN_OPTION_DEFAULTS, **run, **(run_overrides or {})}
    unknown = sorted(set(run) - set(RUN_KEYS) - set(RUN_OPTIONS))
    if unknown:
        raise ConfigError(
            f"{path}: unknown run setting(s) {', '.join(unknown)}; "
            f"allowed: {', '.join([*RUN_KEYS, *RUN_OPTIONS])}"
        )
    for key in ("algo", "env"):
        if key not in run:
            raise ConfigError(f"{path}: run.{key} is required")
    for key, spec in RUN_OPTIONS.items():
        try:
            run[key] = spec.check(run[key])
        except ValueError as exc:
            raise ConfigError(f"{path}: run.{key} must be {exc}, got {run[key]!r}") from None
    for key, typ in RUN_KEYS.items():
        value = run[key]
        ok = isinstance(value, typ) and not (typ is int and isinstance(value, bool))
        if not ok:
            raise ConfigError(f"{path}: run.{key} must be {typ.__name__}, got {value!r}")
    algo = run["algo"].lower()
    try:
        algorithm_class(algo)
    except ConfigError as exc:
        raise ConfigError(f"{path}: run.algo: {exc}") from None
    env_id = run["env"]
    try:
        check_env_id(env_id)
    except ConfigError as exc:
        raise ConfigError(f"{path}: run.env: {exc}") from None
    hyper = data.get(env_id)
    if not isinstance(hyper, dict):
        raise ConfigError(
            f"{path}: missing hyperparameter section '{env_id}' (rl-zoo3 format, keyed by the "
            "env id given in run.env)"
        )
    hyper = {**copy.deepcopy(hyper), **copy.deepcopy(dict(overrides or {}))}
    hyper = _check_hyperparams(path, algo, hyper, set(overrides or {}))
    n_envs = int(hyper.get("n_envs", 1))
    _check_range(path, "run.seed", run["seed"], 0, TRAIN_SEED_LIMIT - n_envs)
    _check_range(path, "run.eval_episodes", run["eval_episodes"], 1, VALIDATION_SEEDS)
    _check_range(
        path, "run.eval_seed", run["eval_seed"], 0, VALIDATION_SEEDS - run["eval_episodes"]
    )
    _check_range(path, "run.eval_freq", run["eval_freq"], 0, None)
    _check_range(path, "run.checkpoint_freq", run["checkpoint_freq"], 0, None)
    cfg = AgentConfig(
        path=path,
        algo=algo,
        env_id=env_id,
        hyperparams=hyper,
        seed=run["seed"],
        eval_freq=run["eval_freq"],
        eval_episodes=run["eval_episodes"],
        eval_seed=run["eval_seed"],
        checkpoint_freq=run["checkpoint_freq"],
        save_replay_buffer=run["save_replay_buffer"],
        vec_env=run["vec_env"],
        residual_init=run["residual_init"],
        init_log_std=run["init_log_std"],
        critic_warmup=run["critic_warmup"],
        scale_ramp=run["scale_ramp"],
        raw=dict(data),
    )
    if cfg.vec_env not in VEC_ENVS:
        raise ConfigError(f"{path}: run.vec_env = {cfg.vec_env!r}; allowed: {', '.join(VEC_ENVS)}")
    if cfg.vec_env == "native" and cfg.wrapper_specs():
        raise ConfigError(
            f"{path}: run.vec_env = 'native' cannot apply env_wrapper (it wraps single envs); "
            "use 'dummy' or 'subproc'"
        )
    for cls, kwargs in cfg.wrapper_specs():  # resolve the wrapper classes now, for a clear error
        _check_wrapper_arguments(path, cls, kwargs)
    _check_run_options(cfg)
    return cfg


def _check_wrapper_arguments(path: Path, cls: type, kwargs: dict[str, Any]) -> None:
    """Unknown keyword arguments of an ``env_wrapper`` entry, and those its class checks
    without an env (a ``check_arguments`` static method), are a ConfigError."""
    name = f"{cls.__module__}.{cls.__qualname__}"
    params = inspect.signature(cls).parameters
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        allowed = [k for k in list(params)[1:] if params[k].kind is not params[k].VAR_POSITIONAL]
        unknown = sorted(set(kwargs) - set(allowed))
        if unknown:
            raise ConfigError(
                f"{path}: env_wrapper {name}: unknown argument(s) {', '.join(unknown)}; "
                f"allowed: {', '.join(allowed)}"
            )
    check = getattr(cls, "check_arguments", None)
    if check is not None:
        try:
            check(**kwargs)
        except ValueError as exc:
            raise ConfigError(f"{path}: env_wrapper {name}: {exc}") from None


def _check_run_options(cfg: AgentConfig) -> None:
    """The residual-learning options against the algorithm and its hyperparameters."""
    kwargs = cfg.algo_kwargs()
    if cfg.scale_ramp and not cfg.is_residual:
        raise ConfigError(f"{cfg.path}: run.scale_ramp needs an agents.residual.ResidualWrapper")
    if cfg.init_log_std is not None:
        if cfg.algo not in RUN_OPTIONS["init_log_std"].algos:
            raise ConfigError(
                f"{cfg.path}: run.init_log_std: {cfg.algo.upper()} has no log standard deviation "
                "(its exploration is noise_type/noise_std)"
            )
        if "log_std_init" in (kwargs.get("policy_kwargs") or {}) and cfg.algo != "sac":
            raise ConfigError(
                f"{cfg.path}: run.init_log_std and policy_kwargs.log_std_init both set the "
                "initial exploration; give one"
            )
    if cfg.residual_init == "zero" and cfg.algo in OFF_POLICY:
        learning_starts = kwargs.get("learning_starts")
        if learning_starts is None:
            sig = inspect.signature(cfg.algo_class.__init__).parameters
            learning_starts = sig["learning_starts"].default
        if learning_starts > 0:
            raise ConfigError(
                f"{cfg.path}: run.residual_init = 'zero' needs learning_starts: 0 (got "
                f"{learning_starts}): {cfg.algo.upper()} acts uniformly at random before "
                "learning_starts, not from the zero-initialised policy; use run.critic_warmup "
                "to train the critic first"
            )


def _check_range(path: Path, name: str, value: int, lo: int, hi: int | None) -> None:
    if value < lo or (hi is not None and value > hi):
        allowed = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ConfigError(f"{path}: {name} = {value} is out of range; allowed: {allowed}")


def _check_hyperparams(
    path: Path, algo: str, hyper: dict[str, Any], overridden: set[str]
) -> dict[str, Any]:
    """``hyper`` checked against the table of ``agents.hyperparams`` (values normalised)."""
    try:
        return check_hyperparams(algo, hyper, str(path), overridden)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
