"""The degradation order of the transverse controller (``ControllerConfig.fallbacks``): its
default, how its items are checked and stored, and how each is reported."""

from __future__ import annotations

from typing import Any

from envs.config_util import real_setting

from .planner import PlannerConfig

__all__ = [
    "DEFAULT_FALLBACKS",
    "NAMED_FALLBACKS",
    "TUBE_FALLBACKS",
    "fallback_items",
    "fallback_name",
    "relaxation_item",
]

#: the named degradations of ``ControllerConfig.fallbacks`` (the others are relaxations)
NAMED_FALLBACKS = ("previous plan", "least violation")

#: default degradation order: the planning torque reserve (0.8 of ``u_max``) relaxed to 0.95,
#: then to the limit, then the duration bounds too; the rest of the previous plan; the
#: least-violating steps
DEFAULT_FALLBACKS: tuple = (
    (("torque_fraction", 0.95),),
    (("torque_fraction", 1.0),),
    (("duration_max", 3.0), ("duration_min", 0.05), ("torque_fraction", 1.0)),
    "previous plan",
    "least violation",
)

#: what a replan within a step (the state left the plan's tube) tries: the motion must change
#: now, so the torque reserve and the shortest duration are relaxed at once; if that fails the
#: current plan is kept (the least-violating steps, tried here too, did worse on validation
#: courses with pushes)
TUBE_FALLBACKS: tuple = (
    (("duration_min", 0.05), ("torque_fraction", 1.0)),
    "previous plan",
)


def fallback_items(raw: Any, field: str = "fallbacks") -> tuple:
    """``ControllerConfig.fallbacks`` in its stored form: names, and relaxations as sorted
    ``(field, value)`` pairs.

    Args:
        raw: a sequence whose items are ``"previous plan"``, ``"least violation"`` or a
            mapping (or ``(field, value)`` pairs) of :class:`PlannerConfig` fields to relaxed
            values.
        field: the :class:`ControllerConfig` field the errors name.

    Raises:
        ValueError: an item of another kind, an unknown field or a non-finite value.
    """
    allowed = (
        "a list whose items are 'previous plan', 'least violation' or a mapping of "
        "PlannerConfig fields to relaxed values"
    )
    if isinstance(raw, (str, bytes)) or not hasattr(raw, "__iter__"):
        raise ValueError(f"ControllerConfig.{field} = {raw!r}; allowed: {allowed}")
    out: list = []
    planner_fields = set(PlannerConfig.__dataclass_fields__)
    for item in raw:
        if isinstance(item, str):
            if item not in NAMED_FALLBACKS:
                raise ValueError(f"ControllerConfig.{field}: unknown item {item!r}; {allowed}")
            out.append(item)
            continue
        try:
            pairs = dict(item.items() if hasattr(item, "items") else item)
        except (TypeError, ValueError):
            raise ValueError(
                f"ControllerConfig.{field}: bad item {item!r}; allowed: {allowed}"
            ) from None
        bad = sorted(set(pairs) - planner_fields)
        if bad or not pairs:
            raise ValueError(
                f"ControllerConfig.{field}: relaxation {item!r} names no or unknown "
                f"PlannerConfig fields {bad}"
            )
        out.append(
            tuple(
                sorted(
                    (str(k), real_setting(f"ControllerConfig.{field}: {k}", v))
                    for k, v in pairs.items()
                )
            )
        )
    return tuple(out)


def relaxation_item(raw: Any) -> tuple:
    """``ControllerConfig.deeper_relaxation`` in its stored form: one relaxation as sorted
    ``(field, value)`` pairs, or ``()`` for none.

    Args:
        raw: a mapping (or ``(field, value)`` pairs) of :class:`PlannerConfig` fields to
            relaxed values; empty or None for none.

    Raises:
        ValueError: a named degradation, an unknown field or a non-finite value.
    """
    if raw is None or (hasattr(raw, "__len__") and not isinstance(raw, str) and len(raw) == 0):
        return ()
    if isinstance(raw, (str, bytes)):
        raise ValueError(
            f"ControllerConfig.deeper_relaxation = {raw!r}; allowed: a mapping of "
            "PlannerConfig fields to relaxed values"
        )
    return fallback_items((raw,), "deeper_relaxation")[0]


def fallback_name(item: Any) -> str:
    """How the degradation ``item`` (a stored item of :func:`fallback_items`) is reported in
    ``StepRecord.fallback``."""
    if isinstance(item, str):
        return item
    return "relaxed: " + ", ".join(f"{k}={v:g}" for k, v in item)
