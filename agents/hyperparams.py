"""The hyperparameters an agent config may set, with the values each one allows.

:data:`HYPERPARAMETERS` is the one table of them: rl-zoo3's keys (``n_timesteps``, ``n_envs``,
``normalize``, ...) and the keyword arguments of the stable-baselines3 algorithms that
``roughwalk train`` passes on. :func:`check_hyperparams` checks a config's section against it
before stable-baselines3 sees any value, so that ``gamma: 2.0`` or ``n_steps: abc`` is an error
naming the key and its range, not a failure deep inside torch.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

ON_POLICY = ("ppo", "a2c")
OFF_POLICY = ("sac", "td3")
ALL = ON_POLICY + OFF_POLICY
NO_LIMIT = math.inf


@dataclass(frozen=True)
class Hyperparameter:
    """What one hyperparameter allows.

    Attributes:
        name: the key.
        algos: the algorithms that take it.
        kind: ``int`` (a whole number), ``float`` (a finite number), ``schedule`` (a number or
            rl-zoo3's ``lin_<number>``, which decays linearly to 0), ``bool``, ``choice``
            (one of ``choices``), ``mapping`` (a dict), ``expression`` (a dict, or rl-zoo3's
            Python expression text such as ``dict(net_arch=[64, 64])``), ``wrapper`` (checked
            when the classes are imported), or a name handled by :func:`check_hyperparams`.
        lo: smallest allowed value (numbers).
        hi: largest allowed value (numbers).
        lo_open: ``lo`` itself is excluded.
        hi_open: ``hi`` itself is excluded.
        choices: the allowed values of a ``choice``, and values allowed besides the range
            (e.g. ``None``, ``"auto"``).
        doc: what it is, with its unit.
    """

    name: str
    algos: tuple[str, ...]
    kind: str
    lo: float = -NO_LIMIT
    hi: float = NO_LIMIT
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[Any, ...] = ()
    doc: str = ""

    def allowed(self) -> str:
        """The allowed values, in words (for error messages)."""
        what = {"int": "a whole number", "float": "a number", "schedule": "a number"}.get(
            self.kind, ""
        )
        if self.kind in ("int", "float", "schedule"):
            if self.lo > -NO_LIMIT and self.hi < NO_LIMIT:
                what += f" in {'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}"
                what += ")" if self.hi_open else "]"
            elif self.lo > -NO_LIMIT:
                what += f" {'>' if self.lo_open else '>='} {_num(self.lo)}"
            elif self.hi < NO_LIMIT:
                what += f" {'<' if self.hi_open else '<='} {_num(self.hi)}"
            if self.kind == "schedule":
                what += " or 'lin_<number>' (same range)"
        elif self.kind == "bool":
            what = "true or false"
        elif self.kind == "choice":
            return "one of " + ", ".join(_yaml(c) for c in self.choices)
        elif self.kind == "mapping":
            what = "a mapping {key: value}"
        elif self.kind == "expression":
            what = "a mapping or a Python expression such as 'dict(net_arch=[64, 64])'"
        extra = [_yaml(c) for c in self.choices]
        return what + (f" or {' or '.join(extra)}" if extra else "")

    def check(self, value: Any) -> Any:
        """``value`` as the algorithm takes it (whole floats as ints, number strings as
        floats); raises ValueError with :meth:`allowed` when it is not allowed."""
        if any(type(value) is type(c) and value == c for c in self.choices):
            return value
        if self.kind == "choice":
            raise ValueError(self.allowed())
        if self.kind == "bool":
            if isinstance(value, bool):
                return value
            raise ValueError(self.allowed())
        if self.kind == "mapping":
            if isinstance(value, Mapping):
                return dict(value)
            raise ValueError(self.allowed())
        if self.kind == "expression":
            if isinstance(value, Mapping | str):
                return value
            raise ValueError(self.allowed())
        if self.kind == "schedule" and isinstance(value, str) and value.startswith("lin_"):
            self._in_range(_number(value[4:], self))
            return value
        number = _number(value, self)
        if self.kind == "int":
            if number != int(number):
                raise ValueError(self.allowed())
            number = int(number)
        self._in_range(number)
        return number

    def _in_range(self, x: float) -> None:
        low = x > self.lo if self.lo_open else x >= self.lo
        high = x < self.hi if self.hi_open else x <= self.hi
        if not (math.isfinite(x) and low and high):
            raise ValueError(self.allowed())


def _yaml(value: Any) -> str:
    """``value`` as written in a YAML config."""
    if value is None or isinstance(value, bool):
        return "null" if value is None else str(value).lower()
    return repr(value)


def _num(x: float) -> str:
    return str(int(x)) if x == int(x) else str(x)


def _number(value: Any, spec: Hyperparameter) -> float:
    """A number from a config value (YAML reads ``1e-3`` as text: it is accepted)."""
    if isinstance(value, bool):
        raise ValueError(spec.allowed())
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            pass
    raise ValueError(spec.allowed())


def _h(name: str, algos: tuple[str, ...], kind: str, doc: str, **kw: Any) -> Hyperparameter:
    return Hyperparameter(name, algos, kind, doc=doc, **kw)


_TABLE = (
    # rl-zoo3's keys
    _h("n_timesteps", ALL, "int", "training budget [env steps]", lo=1),
    _h("n_envs", ALL, "int", "number of training envs", lo=1),
    _h(
        "policy",
        ALL,
        "choice",
        "policy network (the observations are vectors)",
        choices=("MlpPolicy",),
    ),
    _h("normalize", ALL, "normalize", "VecNormalize: true/false or its keyword arguments"),
    _h("frame_stack", ALL, "int", "observations stacked per action", lo=1, choices=(None, False)),
    _h("env_kwargs", ALL, "mapping", "keyword arguments of gym.make"),
    _h("env_wrapper", ALL, "wrapper", "'module.Class' or {'module.Class': {kwargs}}, or a list"),
    _h(
        "noise_type",
        OFF_POLICY,
        "choice",
        "exploration noise",
        choices=("normal", "ornstein-uhlenbeck"),
    ),
    _h("noise_std", OFF_POLICY, "float", "exploration noise scale [action units]", lo=0),
    # the algorithms' keyword arguments
    _h("policy_kwargs", ALL, "expression", "keyword arguments of the policy (net_arch, ...)"),
    _h("learning_rate", ALL, "schedule", "optimiser step size", lo=0, lo_open=True),
    _h("gamma", ALL, "float", "discount factor", lo=0, hi=1),
    _h("stats_window_size", ALL, "int", "episodes averaged in the logged statistics", lo=1),
    _h("n_steps", ON_POLICY, "int", "env steps per env in each rollout", lo=1),
    _h("n_steps", OFF_POLICY, "int", "n-step returns", lo=1),
    _h("batch_size", ("ppo",), "int", "minibatch size [samples]", lo=2),
    _h("batch_size", OFF_POLICY, "int", "minibatch size [samples]", lo=1),
    _h("n_epochs", ("ppo",), "int", "passes over each rollout", lo=1),
    _h("gae_lambda", ON_POLICY, "float", "GAE bias-variance trade-off", lo=0, hi=1),
    _h("clip_range", ("ppo",), "schedule", "policy clipping", lo=0, lo_open=True),
    _h(
        "clip_range_vf", ("ppo",), "schedule", "value clipping", lo=0, lo_open=True, choices=(None,)
    ),
    _h("normalize_advantage", ON_POLICY, "bool", "normalise the advantages"),
    _h("ent_coef", ON_POLICY, "float", "entropy bonus weight", lo=0),
    _h("ent_coef", ("sac",), "ent_coef", "entropy weight ('auto': learnt)"),
    _h("vf_coef", ON_POLICY, "float", "value loss weight", lo=0),
    _h("max_grad_norm", ON_POLICY, "float", "gradient clipping norm", lo=0, lo_open=True),
    _h(
        "target_kl",
        ("ppo",),
        "float",
        "early stopping KL limit",
        lo=0,
        lo_open=True,
        choices=(None,),
    ),
    _h("use_sde", ("ppo", "a2c", "sac"), "bool", "state-dependent exploration"),
    _h(
        "sde_sample_freq",
        ("ppo", "a2c", "sac"),
        "int",
        "steps between noise draws (-1: per rollout)",
        lo=-1,
    ),
    _h("rms_prop_eps", ("a2c",), "float", "RMSprop epsilon", lo=0, lo_open=True),
    _h("use_rms_prop", ("a2c",), "bool", "RMSprop instead of Adam"),
    _h("buffer_size", OFF_POLICY, "int", "replay buffer size [transitions]", lo=1),
    _h("learning_starts", OFF_POLICY, "int", "env steps before learning starts", lo=0),
    _h("tau", OFF_POLICY, "float", "target network update rate", lo=0, hi=1, lo_open=True),
    _h("train_freq", OFF_POLICY, "train_freq", "n or [n, 'step' | 'episode'] between updates"),
    _h(
        "gradient_steps",
        OFF_POLICY,
        "int",
        "gradient steps per update (-1: as many as env steps)",
        lo=1,
        choices=(-1,),
    ),
    _h("optimize_memory_usage", OFF_POLICY, "bool", "memory-efficient replay buffer"),
    _h("target_update_interval", ("sac",), "int", "gradient steps between target updates", lo=1),
    _h(
        "target_entropy",
        ("sac",),
        "float",
        "entropy target ('auto': -dim(action))",
        choices=("auto",),
    ),
    _h("use_sde_at_warmup", ("sac",), "bool", "state-dependent exploration before learning starts"),
    _h("policy_delay", ("td3",), "int", "critic updates per policy update", lo=1),
    _h("target_policy_noise", ("td3",), "float", "target policy smoothing noise", lo=0),
    _h("target_noise_clip", ("td3",), "float", "target policy noise clip", lo=0),
)

#: (name, algorithm) -> what it allows; the table of every known hyperparameter
HYPERPARAMETERS: dict[tuple[str, str], Hyperparameter] = {
    (h.name, algo): h for h in _TABLE for algo in h.algos
}
#: keys rl-zoo3 knows that roughwalk train does not apply, and what to use instead
UNSUPPORTED = {
    "vec_env_wrapper": "use env_wrapper, frame_stack or normalize",
    "callback": "use env_wrapper, frame_stack or normalize",
    "monitor_kwargs": "use env_wrapper, frame_stack or normalize",
    "action_noise": "use noise_type and noise_std",
    "replay_buffer_class": "the default replay buffer is used",
    "replay_buffer_kwargs": "the default replay buffer is used",
    "rollout_buffer_class": "the default rollout buffer is used",
    "rollout_buffer_kwargs": "the default rollout buffer is used",
}
NORMALIZE_KEYS: dict[str, Hyperparameter] = {
    "norm_obs": _h("norm_obs", ALL, "bool", "normalise observations"),
    "norm_reward": _h("norm_reward", ALL, "bool", "normalise rewards"),
    "clip_obs": _h("clip_obs", ALL, "float", "observation clip", lo=0, lo_open=True),
    "clip_reward": _h("clip_reward", ALL, "float", "reward clip", lo=0, lo_open=True),
    "epsilon": _h("epsilon", ALL, "float", "variance floor", lo=0, lo_open=True),
    "gamma": _h("gamma", ALL, "float", "discount of the reward normalisation", lo=0, hi=1),
}


#: the ``run`` settings of the residual-learning recipe (ours, not rl-zoo3's: it ignores ``run``)
RUN_OPTIONS: dict[str, Hyperparameter] = {
    h.name: h
    for h in (
        _h(
            "residual_init",
            ALL,
            "choice",
            "the policy's last actor layer: 'zero' (the agent starts at a zero action, a "
            "residual agent exactly at its base policy) or 'default' (stable-baselines3's)",
            choices=("default", "zero"),
        ),
        _h(
            "init_log_std",
            ("ppo", "a2c", "sac"),
            "float",
            "initial log standard deviation of the exploration (PPO/A2C: log_std; SAC: the "
            "log-std layer's bias, its weights zeroed) [log action units]; null: the default",
            lo=-20,
            hi=2,
            choices=(None,),
        ),
        _h(
            "critic_warmup",
            ALL,
            "int",
            "env steps at the start of training during which only the critic (value function) "
            "learns, the actor frozen [env steps]",
            lo=0,
        ),
        _h(
            "scale_ramp",
            ALL,
            "int",
            "env steps over which the training envs' residual scale rises linearly from 0 to "
            "the ResidualWrapper's scale (0: the full scale from the start) [env steps]",
            lo=0,
        ),
    )
}
#: the defaults of :data:`RUN_OPTIONS` (a config without them trains as before)
RUN_OPTION_DEFAULTS: dict[str, Any] = {
    "residual_init": "default",
    "init_log_std": None,
    "critic_warmup": 0,
    "scale_ramp": 0,
}


def known(algo: str) -> list[str]:
    """The hyperparameters algorithm ``algo`` takes, sorted."""
    return sorted({name for name, a in HYPERPARAMETERS if a == algo})


def _check_special(kind: str, value: Any, spec: Hyperparameter) -> Any:
    if kind == "normalize":
        if value is None or isinstance(value, bool):
            return value
        if not isinstance(value, Mapping):
            raise ValueError("true/false or a dict of VecNormalize keyword arguments")
        out = {}
        for key, v in value.items():
            if key not in NORMALIZE_KEYS:
                raise ValueError(
                    f"a dict of VecNormalize keyword arguments ({', '.join(NORMALIZE_KEYS)}); "
                    f"{key!r} is not one"
                )
            try:
                out[key] = NORMALIZE_KEYS[key].check(v)
            except ValueError as exc:
                raise ValueError(
                    f"a dict of VecNormalize keyword arguments ({key}: {exc})"
                ) from None
        return out
    if kind == "ent_coef":
        if isinstance(value, str) and value.startswith("auto"):
            rest = value[4:]
            if rest == "" or (rest.startswith("_") and _positive(rest[1:])):
                return value
        elif _positive(value):
            return float(value)
        raise ValueError("a number > 0, 'auto' or 'auto_<initial value>'")
    if kind == "train_freq":
        steps = Hyperparameter("train_freq", ALL, "int", lo=1)
        if isinstance(value, list | tuple) and len(value) == 2 and value[1] in ("step", "episode"):
            return [steps.check(value[0]), value[1]]
        try:
            return steps.check(value)
        except ValueError:
            raise ValueError("a whole number >= 1 or [n, 'step' | 'episode']") from None
    return value  # "wrapper": resolved and checked by AgentConfig.wrapper_specs


def _positive(value: Any) -> bool:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return False
    return not isinstance(value, bool) and math.isfinite(x) and x > 0


def check_hyperparams(
    algo: str, hyper: Mapping[str, Any], source: str, overridden: Collection[str] = ()
) -> dict[str, Any]:
    """``hyper`` checked against :data:`HYPERPARAMETERS` for ``algo``, values normalised.

    Args:
        algo: the algorithm (``ppo``, ``sac``, ``td3``, ``a2c``).
        hyper: the config's hyperparameter section (overrides applied).
        source: where ``hyper`` comes from, for the messages (the config file).
        overridden: the keys given on the command line (``--hyperparams``), so named in the
            messages.

    Raises:
        ValueError: an unsupported or unknown key, a value outside its range; the message
            names the key and what it allows.
    """

    def where(key: str) -> str:
        return f"{source}: {key}" + (" (from --hyperparams)" if key in overridden else "")

    unsupported = sorted(set(hyper) & set(UNSUPPORTED))
    if unsupported:
        key = unsupported[0]
        raise ValueError(f"{where(key)} is not supported by roughwalk train; {UNSUPPORTED[key]}")
    unknown = sorted(k for k in hyper if (k, algo) not in HYPERPARAMETERS)
    if unknown:
        raise ValueError(
            f"{source}: unknown hyperparameter(s) {', '.join(unknown)} for {algo.upper()}"
            f"{' (from --hyperparams)' if set(unknown) & set(overridden) else ''}; "
            f"allowed: {', '.join(known(algo))}"
        )
    if "n_timesteps" not in hyper:
        raise ValueError(f"{where('n_timesteps')} is required in the hyperparameter section")
    out: dict[str, Any] = {}
    for key, value in hyper.items():
        spec = HYPERPARAMETERS[(key, algo)]
        try:
            if spec.kind in ("normalize", "ent_coef", "train_freq", "wrapper"):
                out[key] = _check_special(spec.kind, value, spec)
            else:
                out[key] = spec.check(value)
        except ValueError as exc:
            raise ValueError(f"{where(key)} must be {exc}, got {value!r}") from None
    if algo in ON_POLICY and out.get("n_steps", 2) * out.get("n_envs", 1) < 2:
        raise ValueError(f"{where('n_steps')} times n_envs must be at least 2 (one rollout)")
    return out
