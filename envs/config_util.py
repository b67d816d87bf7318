"""Building configuration dataclasses from plain mappings (YAML sections, keyword dicts).

Every settings object of the project (robot parameters, sensors, reward, planner, controller,
...) is a frozen dataclass that validates its own fields in ``__post_init__``. This module holds
the one shared step in front of that: check that the input is a mapping, reject keys that are
not fields (naming them and listing the allowed ones) and required fields that are missing, and
turn a constructor ``TypeError`` into a ``ValueError``. A setting that moved to another object
is listed in the dataclass's ``MOVED_FIELDS`` (name -> where it is set now); giving it, as a
mapping key or a keyword argument (:func:`reject_moved_fields`), fails naming its replacement.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields, is_dataclass
from typing import Any, TypeVar

T = TypeVar("T")


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
