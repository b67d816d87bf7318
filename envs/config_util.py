"""Building configuration dataclasses from plain mappings (YAML sections, keyword dicts).

Every settings object of the project (robot parameters, sensors, reward, planner, controller,
...) is a frozen dataclass that validates its own fields in ``__post_init__``. This module holds
the one shared step in front of that: check that the input is a mapping, reject keys that are
not fields (naming them and listing the allowed ones) and required fields that are missing, and
turn a constructor ``TypeError`` into a ``ValueError``. A setting that moved to another object
is listed in the dataclass's ``MOVED_FIELDS`` (name -> where it is set now); giving it, as a
mapping key or a keyword argument (:func:`reject_moved_fields`), fails naming its replacement.

:func:`integer_setting`, :func:`real_setting` and :func:`finite_pair` check the counts, numbers
and points given as arguments (``horizon=2.7`` or a NaN foot position are errors, not silently
truncated or passed on).

:func:`read_yaml_mapping` is the one reader of the YAML files behind these settings (env, robot,
terrain, planner and controller files): a syntax error or a document that is not a mapping is a
``ValueError`` naming the file and what is wrong. :func:`preset_settings` reads a robot's
preset of planner or controller settings.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import MISSING, fields, is_dataclass
from typing import Any, TypeVar

import numpy as np
import yaml

from configs import CONFIG_DIR

T = TypeVar("T")

try:  # libyaml's parser when PyYAML has it: the same documents, several times faster
    _YAML_LOADER: type = yaml.CSafeLoader
except AttributeError:
    _YAML_LOADER = yaml.SafeLoader


def read_yaml_mapping(
    path: str | os.PathLike,
    what: str,
    *,
    allow_empty: bool = True,
    holds: str = "mapping of settings",
) -> dict[str, Any]:
    """The mapping in the YAML file at ``path`` (safe loader: plain data only).

    Args:
        path: the file.
        what: what the file holds, for the messages (``"env config"``, ``"robot"``,
            ``"terrain"``, ``"planner config"``, ``"controller config"``).
        allow_empty: an empty file (or one of comments only) gives ``{}``; otherwise it is an
            error.
        holds: what the mapping is, for the messages (``"must hold a {holds}"``).

    Raises:
        ValueError: the file is not valid YAML (``"{what} file '...' is not valid YAML: line L,
            column C: problem"``), is empty (unless ``allow_empty``) or holds something other
            than a mapping (a list, a string, ...).
        OSError: the file cannot be read (missing, a folder, no permission).
    """
    name = os.fspath(path)
    with open(name, encoding="utf-8") as fh:
        try:
            data = yaml.load(fh, Loader=_YAML_LOADER)
        except yaml.YAMLError as exc:
            problem = _yaml_problem(exc)
            raise ValueError(f"{what} file {name!r} is not valid YAML: {problem}") from None
        except UnicodeDecodeError as exc:
            raise ValueError(f"{what} file {name!r} is not UTF-8 text: {exc.reason}") from None
    if data is None:
        if allow_empty:
            return {}
        raise ValueError(f"{what} file {name!r} is empty; it must hold a {holds}")
    if not isinstance(data, dict):
        raise ValueError(
            f"{what} file {name!r} must hold a {holds} (key: value lines), "
            f"got a {type(data).__name__}"
        )
    return data


def preset_settings(
    folder: str, name: str | None, what: str, changes: Mapping[str, Any]
) -> dict[str, Any]:
    """The settings of the robot preset ``name`` in ``configs/FOLDER/NAME.yaml`` (none where
    there is no such file or ``name`` is None), updated with ``changes``: the mapping a
    settings class's ``for_robot`` builds itself from (``what`` names the file in messages)."""
    d: dict[str, Any] = {}
    if name is not None:
        path = CONFIG_DIR / folder / f"{name}.yaml"
        if path.exists():
            d = read_yaml_mapping(path, what)
    d.update(changes)
    return d


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """``"line L, column C: problem"`` of a YAML error (1-based), or its text."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    if mark is None:
        return str(problem)
    return f"line {mark.line + 1}, column {mark.column + 1}: {problem}"


def dataclass_from_mapping(cls: type[T], data: Any, name: str, *, item: str = "setting") -> T:
    """Build the dataclass ``cls`` from the mapping ``data``; an instance of ``cls`` is returned
    as it is.

    Args:
        cls: the dataclass to build; its ``__post_init__`` validates the values.
        data: a mapping of field names to values, or an instance of ``cls``.
        name: what the settings belong to, used in the error messages (``"sensor"``,
            ``"robot"``, ``"reward"``, ...).
        item: what one key is called in the error messages (``"setting"``, ``"parameter"``).

    Raises:
        ValueError: ``data`` is not a mapping (``"{name} {item}s must be a mapping, got ..."``),
            has keys that are not fields (``"unknown {name} {item}(s) [...]; allowed: [...]"``)
            or that moved elsewhere (see :func:`reject_moved_fields`),
            lacks a field without a default (``"missing {name} {item}(s) [...]"``), or the
            constructor rejects a value (the dataclass's own message, or ``"bad {name}
            {item}s: ..."`` for a ``TypeError``).
    """
    if not (isinstance(cls, type) and is_dataclass(cls)):
        raise TypeError(f"dataclass_from_mapping needs a dataclass type, got {cls!r}")
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        raise ValueError(f"{name} {item}s must be a mapping, got {type(data).__name__}")
    reject_moved_fields(cls, data)
    init_fields = [f for f in fields(cls) if f.init]
    known = {f.name for f in init_fields}
    unknown = sorted((k for k in data if k not in known), key=str)
    if unknown:
        raise ValueError(f"unknown {name} {item}(s) {unknown}; allowed: {sorted(known)}")
    required = [
        f.name for f in init_fields if f.default is MISSING and f.default_factory is MISSING
    ]
    missing = [k for k in required if k not in data]
    if missing:
        raise ValueError(f"missing {name} {item}(s) {missing}; required: {required}")
    try:
        return cls(**data)
    except TypeError as exc:
        raise ValueError(f"bad {name} {item}s: {exc}") from None


def reject_moved_fields(cls: type, keys: Any) -> None:
    """Fail on settings that moved from the dataclass ``cls`` to another object.

    Args:
        cls: a dataclass; its optional class attribute ``MOVED_FIELDS`` maps a former field's
            name to where it is set now.
        keys: the names given (a mapping's keys or keyword arguments).

    Raises:
        ValueError: ``"{cls}.{key} moved: {where}"`` for the first moved name in ``keys``.
    """
    moved = getattr(cls, "MOVED_FIELDS", None) or {}
    for key in keys:
        if key in moved:
            raise ValueError(f"{cls.__name__}.{key} moved: {moved[key]}")


def integer_setting(name: str, value: Any, low: int, high: int | None = None) -> int:
    """``value`` as an int: an integer (or an integral float such as ``3.0``) in
    ``[low, high]``.

    Raises:
        ValueError: ``"{name} = {value!r}; allowed: integer >= low"`` (or ``in [low, high]``)
            for anything else: ``2.7``, NaN, a string, None, a bool.
    """
    allowed = f"integer >= {low}" if high is None else f"integer in [{low}, {high}]"
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if ok and math.isfinite(value) and int(value) == value:
        v = int(value)
        if v >= low and (high is None or v <= high):
            return v
    raise ValueError(f"{name} = {value!r}; allowed: {allowed}")


def real_setting(name: str, value: Any, allowed: str = "a finite number") -> float:
    """``value`` as a finite float (a Python or numpy real number, not a bool).

    Raises:
        ValueError: ``"{name} = {value!r}; allowed: {allowed}"`` otherwise.
    """
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if not (ok and math.isfinite(value)):
        raise ValueError(f"{name} = {value!r}; allowed: {allowed}")
    return float(value)


def finite_pair(name: str, value: Any, unit: str) -> tuple[float, float]:
    """``value`` as two finite floats, e.g. a position ``(x, y)`` [m].

    Raises:
        ValueError: ``"{name} must be two finite numbers [unit], got ..."`` otherwise.
    """
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be two finite numbers [{unit}], got {value!r}")
    return float(a[0]), float(a[1])
