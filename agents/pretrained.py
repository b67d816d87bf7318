"""Trained agents shipped with the package, loadable by name: ``pretrained:NAME``.

Each agent is a folder of ``agents/pretrained/`` holding what ``roughwalk train`` wrote for its
best model: ``best_model.zip``, ``best_vecnormalize.pkl`` (the observation statistics) and the
run's ``manifest.json`` (its config, env and training seed), plus ``card.json``: how it was
trained (the command) and how it did on held-out courses (the command and the figures).
Anywhere a policy is named (``roughwalk evaluate --policy``, a sweep spec's ``policy``,
:func:`agents.trained.load_policy`) ``pretrained:NAME`` stands for that folder's model::

    roughwalk evaluate --policy pretrained:footstep_ppo_rough_hard --episodes 20
    policy = load_policy("pretrained:footstep_ppo_rough_hard")

Loading unpickles the model and its statistics: these ship with the package and are trusted as
the package is. Loading needs the ``rl`` extra (stable-baselines3 and torch).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = [
    "PREFIX",
    "PRETRAINED_DIR",
    "available",
    "card",
    "is_pretrained",
    "pack_run",
    "resolve_model",
]

#: the prefix that names a shipped agent
PREFIX = "pretrained:"
#: the folder of the shipped agents, one sub-folder each
PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
_MODEL = "best_model.zip"


def available() -> list[str]:
    """The names of the shipped agents, sorted."""
    if not PRETRAINED_DIR.is_dir():
        return []
    return sorted(d.name for d in PRETRAINED_DIR.iterdir() if (d / _MODEL).is_file())


def is_pretrained(spec: str) -> bool:
    """Whether ``spec`` names a shipped agent (``pretrained:NAME``, the name not checked)."""
    return isinstance(spec, str) and spec.startswith(PREFIX)


def _folder(spec: str) -> Path:
    name = spec[len(PREFIX) :]
    names = available()
    if name not in names:
        raise ValueError(
            f"unknown pretrained agent {name!r}; available: "
            + (", ".join(f"{PREFIX}{n}" for n in names) or "none")
        )
    return PRETRAINED_DIR / name


def resolve_model(spec: str) -> str:
    """The model file ``spec`` stands for: a shipped agent's for ``pretrained:NAME``, else
    ``spec`` unchanged.

    Raises:
        ValueError: ``pretrained:NAME`` with a name that is not shipped (the message lists the
            available ones).
    """
    if not is_pretrained(spec):
        return spec
    return str(_folder(spec) / _MODEL)


def card(spec: str) -> dict[str, Any]:
    """The card of the shipped agent ``pretrained:NAME`` (or ``NAME``): its training command,
    its held-out evaluation command and figures.

    Raises:
        ValueError: not a shipped agent.
    """
    folder = _folder(spec if is_pretrained(spec) else PREFIX + spec)
    return json.loads((folder / "card.json").read_text())


def pack_run(
    run_dir: str | Path,
    name: str,
    card_fields: dict[str, Any],
    dest: str | Path = PRETRAINED_DIR,
) -> Path:
    """Ship a finished run's best model as ``dest/name``: its ``best_model.zip``,
    ``best_vecnormalize.pkl`` and ``manifest.json`` (with the paths of the machine it ran on
    replaced by the package's config path and ``card_fields["train"]``), and ``card.json``
    (``card_fields``: ``agent``, ``train``, ``evaluate``, ``held_out`` and ``check``, the
    courses the tests re-walk).

    Raises:
        ValueError: a bad name, a run that did not finish, a card without those fields.
        FileExistsError: ``dest/name`` exists (a shipped agent is never overwritten).
    """
    run = Path(run_dir)
    if not (name and name.replace("_", "").isalnum() and name.islower()):
        raise ValueError(f"name = {name!r}; allowed: lower-case letters, digits and _")
    missing = [
        k for k in ("agent", "train", "evaluate", "held_out", "check") if k not in card_fields
    ]
    if missing:
        raise ValueError(f"card: missing {', '.join(missing)}")
    manifest = json.loads((run / "manifest.json").read_text())
    if manifest.get("status") != "finished":
        raise ValueError(f"{run}: the run did not finish (status {manifest.get('status')!r})")
    for f in (_MODEL, "best_vecnormalize.pkl"):
        if not (run / f).is_file():
            raise ValueError(f"{run}: no {f}")
    out = Path(dest) / name
    if out.exists():
        raise FileExistsError(f"{out} exists; a shipped agent is never overwritten")
    config = Path(str(manifest.get("config_file", ""))).name
    manifest["config_file"] = f"configs/agents/{config}" if config else None
    manifest["commands"] = [card_fields["train"]]
    out.mkdir(parents=True)
    for f in (_MODEL, "best_vecnormalize.pkl"):
        (out / f).write_bytes((run / f).read_bytes())
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    (out / "card.json").write_text(json.dumps(card_fields, indent=2) + "\n")
    return out
