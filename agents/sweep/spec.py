"""Sweep specs: a grid of policies x environments (with swept keyword arguments) x held-out
course seeds, read from YAML and checked whole before any episode runs.

A spec (``configs/sweeps/*.yaml``)::

    name: example                # optional; a title for the outputs
    description: ...             # optional
    episodes: 20                 # held-out courses per cell
    seed: 1000                   # episode k of every cell resets with 1,000,000 + seed + k
    policies:
      - passive                  # a baseline (passive, pd, reference), a model file (.zip)
      - reference                # or a run folder (its best_model.zip, else model.zip)
      - pretrained:footstep_ppo_rough_hard   # or a shipped agent (agents.pretrained)
      - policy: runs/ppo_rough_s0
        name: PPO s0             # label (default: the baseline's or the run folder's name)
        group: PPO               # training seeds of one agent share a group (IQM across them)
        envs: [rough]            # only these envs (default: all)
      - policy: reference
        name: reference fixed-plan
        options: {controller_mode: fixed-plan}   # options of agents.evaluate.make_eval_env
    envs:
      - name: flat               # label (default: the id without roughwalk/)
        id: roughwalk/CompassGaitFlat-v0
      - name: rough
        id: roughwalk/CompassGaitRough-v0
        kwargs: {max_episode_steps: 3000}       # keyword arguments of gym.make, as given
        sweep: {difficulty: [0.5, 1.0, 2.0]}    # one cell per value (per combination)

A ``sweep`` key with dots sets a field inside a mapping argument: ``sensors.encoder_noise``
is ``sensors: {encoder_noise: ...}``, merged into the ``kwargs``' own ``sensors``. Keyword
arguments are passed to the env as they are: the env validates them (and
:func:`check_spec` constructs every env and every policy on it before anything runs).
"""

from __future__ import annotations

import copy
import inspect
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from agents.config import TEST_SEED, ConfigError
from agents.evaluate import eval_seeds, make_env, make_eval_env
from agents.policies import BASELINES
from agents.pretrained import PREFIX, is_pretrained, resolve_model

SPEC_KEYS = ("name", "description", "episodes", "seed", "policies", "envs")
POLICY_KEYS = ("policy", "name", "group", "envs", "options")
#: options of a policy entry: the keyword arguments of ``make_eval_env`` after the env's
POLICY_OPTIONS = tuple(list(inspect.signature(make_eval_env).parameters)[3:])
ENV_KEYS = ("name", "id", "kwargs", "sweep")
ENV_NAMESPACE = "roughwalk/"
#: model files a run folder stands for, in order of preference (as ``roughwalk compare``)
RUN_MODELS = ("best_model.zip", "model.zip")


class SpecError(ConfigError):
    """A sweep spec that cannot run (the message names the file and the field)."""


@dataclass(frozen=True)
class PolicyEntry:
    """One policy of a sweep.

    Attributes:
        name: its label in the outputs.
        policy: what the evaluation loads: a baseline's name or a model file.
        source: the policy as the spec gives it (a baseline, a model file or a run folder).
        group: the agent it is one training seed of, or None.
        envs: names of the envs it runs on, or None for all.
        options: keyword arguments of ``agents.evaluate.make_eval_env`` (e.g.
            ``controller_mode``).
    """

    name: str
    policy: str
    source: str
    group: str | None = None
    envs: tuple[str, ...] | None = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class EnvEntry:
    """One environment of a sweep, with the keyword arguments it sweeps.

    Attributes:
        name: its label in the outputs.
        id: its Gymnasium id.
        kwargs: keyword arguments of ``gym.make`` common to its cells.
        sweep: swept keyword -> its values (one cell per combination).
    """

    name: str
    id: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    sweep: dict[str, list[Any]] = field(default_factory=dict)

    def settings(self) -> list[tuple[dict[str, Any], dict[str, Any]]]:
        """``(swept values, env kwargs)`` of each of its cells, in the order of the grid."""
        keys = list(self.sweep)
        out = []
        for values in itertools.product(*(self.sweep[k] for k in keys)):
            point = dict(zip(keys, values))
            out.append((point, with_swept(self.kwargs, point)))
        return out


@dataclass(frozen=True)
class Cell:
    """One policy on one env setting: the unit the summary reports.

    Attributes:
        key: unique label, ``POLICY/ENV`` plus ``[key=value,...]`` for swept values.
        policy: the policy's label.
        policy_spec: what the evaluation loads (baseline name or model file).
        group: the policy's group, or None.
        env: the env's label.
        env_id: Gymnasium id.
        env_kwargs: keyword arguments of ``gym.make``.
        swept: the swept keyword arguments' values of this cell.
        policy_options: keyword arguments of ``agents.evaluate.make_eval_env``.
    """

    key: str
    policy: str
    policy_spec: str
    group: str | None
    env: str
    env_id: str
    env_kwargs: dict[str, Any]
    swept: dict[str, Any]
    policy_options: dict[str, Any] = field(default_factory=dict)

    @property
    def setting(self) -> str:
        """The env part of the key (the task of the across-seeds statistics)."""
        return self.key.split("/", 1)[1]


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep spec.

    Attributes:
        name: title of the outputs.
        description: free text.
        episodes: courses per cell.
        seed: user seed: episode ``k`` resets with ``1,000,000 + seed + k``.
        policies: the policies.
        envs: the environments.
        path: the file it was read from, or None.
    """

    name: str
    description: str
    episodes: int
    seed: int
    policies: tuple[PolicyEntry, ...]
    envs: tuple[EnvEntry, ...]
    path: Path | None = None

    @property
    def seeds(self) -> list[int]:
        """The absolute reset seeds of every cell's episodes."""
        return eval_seeds(self.seed, self.episodes)

    def cells(self) -> list[Cell]:
        """Every cell of the grid: policies x their envs x swept values, in spec order."""
        out = []
        for p in self.policies:
            for e in self.envs:
                if p.envs is not None and e.name not in p.envs:
                    continue
                for point, kwargs in e.settings():
                    swept = ",".join(f"{k}={_text(v)}" for k, v in point.items())
                    key = f"{p.name}/{e.name}" + (f"[{swept}]" if swept else "")
                    out.append(
                        Cell(key, p.name, p.policy, p.group, e.name, e.id, kwargs, point, p.options)
                    )
        return out

    def to_dict(self) -> dict[str, Any]:
        """The spec as plain data (what a results folder records to recognise its spec)."""
        return {
            "name": self.name,
            "description": self.description,
            "episodes": self.episodes,
            "seed": self.seed,
            "policies": [
                {"name": p.name, "policy": p.policy, "source": p.source, "group": p.group}
                | ({"envs": list(p.envs)} if p.envs is not None else {})
                | ({"options": p.options} if p.options else {})
                for p in self.policies
            ],
            "envs": [
                {"name": e.name, "id": e.id, "kwargs": e.kwargs, "sweep": e.sweep}
                for e in self.envs
            ],
        }


def _text(value: Any) -> str:
    """A swept value as text in a cell key (JSON for mappings and lists)."""
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True)


def with_swept(kwargs: dict[str, Any], point: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` with the swept ``point`` set in (dotted keys set fields of mapping
    arguments); ``kwargs`` itself is left unchanged."""
    out = copy.deepcopy(kwargs)
    for key, value in point.items():
        *parents, leaf = key.split(".")
        target = out
        for part in parents:
            nxt = target.get(part)
            if nxt is None:
                nxt = target[part] = {}
            elif not isinstance(nxt, dict):
                raise SpecError(f"sweep key {key!r}: {part!r} is not a mapping in the kwargs")
            target = nxt
        target[leaf] = copy.deepcopy(value)
    return out


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def resolve_policy(text: str) -> str:
    """What the evaluation loads for the policy ``text``: a baseline's name as it is, a shipped
    agent's name (``pretrained:NAME``) as it is, a run folder's ``best_model.zip`` (else
    ``model.zip``), a model file as it is.

    Raises:
        ValueError: none of these.
    """
    if text in BASELINES:
        return text
    if is_pretrained(text):
        resolve_model(text)  # a shipped agent's name, checked; loaded by that name
        return text
    path = Path(text)
    if path.is_dir():
        for name in RUN_MODELS:
            if (path / name).is_file():
                return str(path / name)
        raise ValueError(f"run folder {text} holds no {' or '.join(RUN_MODELS)}")
    if path.is_file():
        return text
    raise ValueError(
        f"unknown policy {text!r}; allowed: {', '.join(BASELINES)}, a model file (.zip), a "
        "run folder or pretrained:NAME"
    )


def _policy_entry(i: int, item: Any) -> PolicyEntry:
    where = f"policies[{i}]"
    if isinstance(item, str):
        item = {"policy": item}
    if not isinstance(item, dict):
        raise SpecError(f"{where}: must be a policy name or path, or a mapping with {POLICY_KEYS}")
    unknown = sorted(set(item) - set(POLICY_KEYS))
    if unknown:
        raise SpecError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(POLICY_KEYS)}")
    source = item.get("policy")
    if not isinstance(source, str) or not source:
        raise SpecError(f"{where}.policy: required, a baseline name or a path")
    try:
        policy = resolve_policy(source)
    except ValueError as exc:
        raise SpecError(f"{where}.policy: {exc}") from None
    if policy in BASELINES:
        default_name = policy
    elif is_pretrained(policy):
        default_name = policy[len(PREFIX) :]
    elif Path(source).is_dir():
        default_name = Path(source).resolve().name
    else:
        default_name = f"{Path(source).resolve().parent.name}/{Path(source).stem}"
    name = item.get("name", default_name)
    group = item.get("group")
    for key, value in (("name", name), ("group", group)):
        if value is not None and (not isinstance(value, str) or not value or "/" in value):
            raise SpecError(f"{where}.{key}: must be a non-empty string without '/'")
    envs = item.get("envs")
    if envs is not None:
        if not isinstance(envs, list) or not envs or not all(isinstance(e, str) for e in envs):
            raise SpecError(f"{where}.envs: must be a non-empty list of env names")
        envs = tuple(envs)
    options = item.get("options") or {}
    if not isinstance(options, dict):
        raise SpecError(f"{where}.options: must be a mapping; keys: {', '.join(POLICY_OPTIONS)}")
    for key in options:
        if key not in POLICY_OPTIONS:
            raise SpecError(
                f"{where}.options: unknown option {key!r}; allowed: {', '.join(POLICY_OPTIONS)}"
            )
    return PolicyEntry(name, policy, source, group, envs, dict(options))


def _env_entry(i: int, item: Any) -> EnvEntry:
    where = f"envs[{i}]"
    if isinstance(item, str):
        item = {"id": item}
    if not isinstance(item, dict):
        raise SpecError(f"{where}: must be an env id or a mapping with {ENV_KEYS}")
    unknown = sorted(set(item) - set(ENV_KEYS))
    if unknown:
        raise SpecError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(ENV_KEYS)}")
    env_id = item.get("id")
    if not isinstance(env_id, str) or not env_id:
        raise SpecError(f"{where}.id: required, a roughwalk env id")
    name = item.get("name", env_id.removeprefix(ENV_NAMESPACE))
    if not isinstance(name, str) or not name or "/" in name:
        raise SpecError(f"{where}.name: must be a non-empty string without '/'")
    kwargs = item.get("kwargs") or {}
    if not isinstance(kwargs, dict) or not all(isinstance(k, str) for k in kwargs):
        raise SpecError(f"{where}.kwargs: must be a mapping of keyword arguments")
    sweep = item.get("sweep") or {}
    if not isinstance(sweep, dict):
        raise SpecError(f"{where}.sweep: must be a mapping keyword -> list of values")
    for key, values in sweep.items():
        if not isinstance(key, str) or not all(key.split(".")):
            raise SpecError(f"{where}.sweep: bad keyword {key!r}")
        if not isinstance(values, list) or not values:
            raise SpecError(f"{where}.sweep.{key}: must be a non-empty list of values")
        texts = [_text(v) for v in values]
        if len(set(texts)) != len(texts):
            raise SpecError(f"{where}.sweep.{key}: repeated value")
        if key in kwargs:
            raise SpecError(f"{where}.sweep.{key}: also given in kwargs (give it in one place)")
    entry = EnvEntry(name, env_id, kwargs, {k: list(v) for k, v in sweep.items()})
    try:
        entry.settings()
    except SpecError as exc:
        raise SpecError(f"{where}: {exc}") from None
    return entry


def spec_from_dict(data: Any, path: str | Path | None = None) -> SweepSpec:
    """A :class:`SweepSpec` from its mapping, its form checked (see :func:`check_spec` for the
    check that builds every env and policy).

    Args:
        data: the spec's mapping (as read from YAML).
        path: the file it came from, named in errors.

    Raises:
        SpecError: an unknown key, a missing or bad field, an empty grid, bad seeds, an
            unknown policy, repeated names (the message names the file and the field).
    """
    prefix = f"{path}: " if path is not None else ""
    try:
        return _spec_from_dict(data, path)
    except SpecError as exc:
        raise SpecError(f"{prefix}{exc}") from None


def _spec_from_dict(data: Any, path: str | Path | None) -> SweepSpec:
    if not isinstance(data, dict):
        raise SpecError("a sweep spec must be a mapping with policies, envs and episodes")
    unknown = sorted(set(data) - set(SPEC_KEYS))
    if unknown:
        raise SpecError(f"unknown key {unknown[0]!r}; allowed: {', '.join(SPEC_KEYS)}")
    episodes = data.get("episodes")
    if not _is_int(episodes) or episodes < 1:
        raise SpecError(f"episodes: must be an integer >= 1, got {episodes!r}")
    seed = data.get("seed", TEST_SEED)
    if not _is_int(seed) or seed < 0:
        raise SpecError(f"seed: must be an integer >= 0, got {seed!r}")
    try:
        eval_seeds(seed, episodes)
    except ValueError as exc:
        raise SpecError(f"seed: {exc}") from None
    name = data.get("name", Path(path).stem if path is not None else "sweep")
    description = data.get("description", "")
    if not isinstance(name, str) or not isinstance(description, str):
        raise SpecError("name and description: must be strings")
    for key in ("policies", "envs"):
        if not isinstance(data.get(key), list) or not data[key]:
            raise SpecError(f"{key}: must be a non-empty list (an empty grid runs nothing)")
    policies = tuple(_policy_entry(i, p) for i, p in enumerate(data["policies"]))
    envs = tuple(_env_entry(i, e) for i, e in enumerate(data["envs"]))
    names = [e.name for e in envs]
    for n in names:
        if names.count(n) > 1:
            raise SpecError(f"envs: the name {n!r} is used twice (give each env a name)")
    for i, p in enumerate(policies):
        for e in p.envs or ():
            if e not in names:
                raise SpecError(
                    f"policies[{i}].envs: unknown env {e!r}; the spec's envs: {', '.join(names)}"
                )
    spec = SweepSpec(name, description, episodes, seed, policies, envs, None)
    keys = [c.key for c in spec.cells()]
    for k in keys:
        if keys.count(k) > 1:
            raise SpecError(
                f"policies: two entries give the cell {k!r} (name the policies apart, or "
                "restrict them to different envs)"
            )
    return SweepSpec(name, description, episodes, seed, policies, envs, _path(path))


def _path(path: str | Path | None) -> Path | None:
    return Path(path) if path is not None else None


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check the form of the sweep spec in the YAML file ``path``.

    Raises:
        FileNotFoundError: no such file.
        SpecError: not valid YAML, or a bad spec (see :func:`spec_from_dict`).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"sweep spec not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or " ".join(str(exc).split())
        raise SpecError(f"{path}: not valid YAML{where}: {problem}") from None
    return spec_from_dict(data, path)


def check_spec(spec: SweepSpec) -> None:
    """Construct every env setting of ``spec`` once, then every policy on each env setting it
    runs on (loading trained models, checking their observation shapes): the whole grid's
    errors come out here, before any episode runs.

    Raises:
        SpecError: an unknown env id or keyword argument, a bad value, a model that does not
            fit its env (the message names the file, the entry and the cell).
    """
    prefix = f"{spec.path}: " if spec.path is not None else ""
    for i, e in enumerate(spec.envs):
        for point, kwargs in e.settings():
            at = f"envs[{i}] ({e.name}" + (f", {point}" if point else "") + ")"
            try:
                make_env(e.id, kwargs).close()
            except (ValueError, OSError) as exc:
                raise SpecError(f"{prefix}{at}: {' '.join(str(exc).split())}") from None
    for cell in spec.cells():
        try:
            env, *_ = make_eval_env(
                cell.policy_spec, cell.env_id, cell.env_kwargs, **cell.policy_options
            )
            env.close()
        except (ValueError, OSError) as exc:
            raise SpecError(f"{prefix}cell {cell.key}: {' '.join(str(exc).split())}") from None
