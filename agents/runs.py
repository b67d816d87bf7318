"""Files of a training run: the run manifest, the saved ``VecNormalize`` statistics, and the
settings rl-zoo3 saves beside a model it trained.

``roughwalk train`` writes ``<run>/manifest.json`` and saves ``<name>.zip`` with its statistics
beside it (see :func:`find_vecnormalize`); rl-zoo3 saves ``<run>/<env>.zip`` with
``<run>/<env>/{args,config}.yml`` and ``vecnormalize.pkl``.
"""

from __future__ import annotations

import pickle
import re
from pathlib import Path
from typing import Any

import yaml

MANIFEST = "manifest.json"


def find_manifest(model_path: str | Path) -> Path | None:
    """The ``manifest.json`` of the run the model file ``model_path`` belongs to (searching up
    to two levels), or None."""
    p = Path(model_path).resolve().parent
    for d in (p, p.parent, p.parent.parent):
        if (d / MANIFEST).is_file():
            return d / MANIFEST
    return None


def find_vecnormalize(model_path: str | Path) -> Path | None:
    """The ``VecNormalize`` statistics saved with the model ``model_path`` by ``roughwalk
    train`` (or rl-zoo3), if any.

    ``checkpoints/rl_model_<N>_steps.zip`` -> ``rl_model_vecnormalize_<N>_steps.pkl``;
    ``best_model.zip`` -> ``best_vecnormalize.pkl``; ``model.zip`` -> ``vecnormalize.pkl``;
    ``<name>.zip`` -> ``<name>_vecnormalize.pkl``.
    """
    p = Path(model_path)
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    if m:
        candidate = p.with_name(f"{m.group(1)}_vecnormalize_{m.group(2)}_steps.pkl")
    elif p.stem == "best_model":
        candidate = p.with_name("best_vecnormalize.pkl")
    elif p.stem == "model":
        candidate = p.with_name("vecnormalize.pkl")
    else:
        candidate = p.with_name(f"{p.stem}_vecnormalize.pkl")
    if not candidate.is_file():  # rl-zoo3's layout: <run>/<env>.zip, <run>/<env>/vecnormalize.pkl
        candidate = p.with_suffix("") / "vecnormalize.pkl"
    return candidate if candidate.is_file() else None


class _ZooLoader(yaml.SafeLoader):
    """Reads rl-zoo3's ``args.yml``/``config.yml`` (an OrderedDict of pairs) safely."""


def _ordered_dict(loader: yaml.SafeLoader, node: yaml.Node) -> dict[str, Any]:
    (pairs,) = loader.construct_sequence(node, deep=True)
    return {k: v for k, v in pairs}


_ZooLoader.add_constructor(
    "tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered_dict
)


def zoo_run_files(model_path: str | Path) -> Path | None:
    """The folder of rl-zoo3's saved settings for a model it trained, if there is one.

    rl-zoo3 saves ``<run>/<env>.zip`` with ``<run>/<env>/{args,config}.yml`` and
    ``vecnormalize.pkl``.
    """
    p = Path(model_path)
    d = p.with_suffix("")
    return d if (d / "args.yml").is_file() and (d / "config.yml").is_file() else None


def zoo_config(folder: Path, algo: str | None = None) -> dict[str, Any]:
    """An agent-config dict (``run`` + env-id section) from rl-zoo3's saved settings."""
    args = yaml.load((folder / "args.yml").read_text(), Loader=_ZooLoader)
    hyper = yaml.load((folder / "config.yml").read_text(), Loader=_ZooLoader)
    env_id = args["env"]
    algo = algo or args["algo"]
    if isinstance(hyper.get("normalize"), dict):
        hyper["normalize"] = {k: v for k, v in hyper["normalize"].items() if k != "gamma"}
    return {"run": {"algo": algo, "env": env_id, "eval_freq": 0}, env_id: hyper}


def load_vecnormalize(path: str | Path) -> Any:
    """The ``VecNormalize`` statistics SB3 saved in ``path``, without an env attached (for
    normalising observations; no updates, no reward normalisation)."""
    with open(path, "rb") as fh:
        vn = pickle.load(fh)
    vn.training = False
    vn.norm_reward = False
    return vn
