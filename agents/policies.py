"""Named policies for evaluation: baselines and trained stable-baselines3 models.

Every policy has ``reset()`` (called after each ``env.reset``) and ``__call__(obs) -> action``
with the action in the env's normalised [-1, 1] scale.

- ``passive``: zero hip torque.
- ``pd``: the planned virtual constraints enforced by plain PD (``controllers.PDPolicy``).
- ``reference``: the transverse-linearization controller (``controllers.make_reference_policy``).
- a path to a model saved by ``roughwalk train`` (``model.zip``, ``best_model.zip`` or a
  checkpoint), loaded with its ``VecNormalize`` statistics and its run's env wrappers.
"""

from __future__ import annotations

import json
import pickle
import re
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
import yaml

BASELINES = ("passive", "pd", "reference")
MANIFEST = "manifest.json"


@runtime_checkable
class Policy(Protocol):
    """What ``evaluate`` and ``ResidualWrapper`` need from a policy."""

    def reset(self) -> None: ...

    def __call__(self, obs: Any) -> np.ndarray: ...


class ZeroPolicy:
    """The passive walker: a zero command whatever the observation."""

    def __init__(self, action_space: gym.spaces.Box) -> None:
        self._action = np.zeros(action_space.shape, dtype=action_space.dtype)

    def reset(self) -> None:
        """Nothing to reset."""

    def __call__(self, obs: Any) -> np.ndarray:
        return self._action.copy()


def make_baseline_policy(name: str, env: gym.Env, **kwargs: Any) -> Policy:
    """Baseline policy ``name`` (one of ``BASELINES``) for ``env`` (as ``gym.make`` returns it).

    ``kwargs`` go to ``controllers.PDPolicy`` / ``controllers.make_reference_policy`` (e.g.
    ``planner``, ``config``, ``eps``); ``passive`` takes none.
    """
    if name == "passive":
        if kwargs:
            raise ValueError(f"the passive policy takes no options, got {sorted(kwargs)}")
        return ZeroPolicy(env.action_space)
    if name == "pd":
        import controllers

        return controllers.PDPolicy(env, **kwargs)
    if name == "reference":
        import controllers

        return controllers.make_reference_policy(env, **kwargs)
    raise ValueError(f"unknown baseline policy {name!r}; allowed: {', '.join(BASELINES)}")


def find_manifest(model_path: str | Path) -> Path | None:
    """The ``manifest.json`` of the run a model file belongs to (searching up to two levels)."""
    p = Path(model_path).resolve().parent
    for d in (p, p.parent, p.parent.parent):
        if (d / MANIFEST).is_file():
            return d / MANIFEST
    return None


def find_vecnormalize(model_path: str | Path) -> Path | None:
    """The ``VecNormalize`` statistics saved with a model by ``roughwalk train``, if any.

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
    """``VecNormalize`` statistics saved by SB3, without an env attached (for normalising)."""
    with open(path, "rb") as fh:
        vn = pickle.load(fh)
    vn.training = False
    vn.norm_reward = False
    return vn


def _algo_from_zip(path: Path) -> str:
    from stable_baselines3.common.save_util import load_from_zip_file

    data, _, _ = load_from_zip_file(path, device="cpu", load_data=True)
    module = getattr((data or {}).get("policy_class"), "__module__", "")
    for name in ("ppo", "sac", "td3", "a2c"):
        if f".{name}." in module:
            return name
    raise ValueError(f"{path}: cannot tell the algorithm of this model (policy class {module!r})")


class TrainedPolicy:
    """A stable-baselines3 model acting deterministically, with its observation normalisation.

    Args:
        model_path: ``.zip`` saved by SB3.
        vecnormalize: ``VecNormalize`` statistics file; by default the one saved beside the model
            (see ``find_vecnormalize``), none if there is none.
        algo: algorithm name; by default from the run manifest or the file.

    Attributes:
        manifest: the run manifest (``roughwalk train``), or ``{}``.
        config: the run's ``AgentConfig`` (from the manifest, or from rl-zoo3's saved
            settings for a model trained with rl-zoo3), else None; its ``wrap(env)`` applies
            the env wrappers the agent was trained with (e.g. the residual).
        frame_stack: observations stacked per action (the config's ``frame_stack``), or None;
            the stack restarts at :meth:`reset`, as SB3's ``VecFrameStack`` does.
    """

    def __init__(
        self,
        model_path: str | Path,
        vecnormalize: str | Path | None = None,
        algo: str | None = None,
    ) -> None:
        from agents.config import algorithm_class, config_from_dict

        self.path = Path(model_path)
        if not self.path.is_file():
            raise FileNotFoundError(f"model file not found: {self.path}")
        manifest_path = find_manifest(self.path)
        self.manifest: dict[str, Any] = (
            json.loads(manifest_path.read_text()) if manifest_path else {}
        )
        self.config = None
        if "config" in self.manifest:
            self.config = config_from_dict(self.manifest["config"], manifest_path)
        zoo = zoo_run_files(self.path) if self.config is None else None
        if zoo is not None:
            self.config = config_from_dict(zoo_config(zoo, algo), zoo / "config.yml")
        algo = algo or (self.config.algo if self.config else None) or _algo_from_zip(self.path)
        self.model = algorithm_class(algo).load(self.path, device="cpu")
        vn_path = Path(vecnormalize) if vecnormalize else find_vecnormalize(self.path)
        self.vecnormalize_path = vn_path
        self.obs_norm = load_vecnormalize(vn_path) if vn_path else None
        self.frame_stack = self.config.frame_stack if self.config else None
        self._stack: np.ndarray | None = None

    def wrap_env(self, env: gym.Env) -> gym.Env:
        """Apply the env wrappers of the run (e.g. ``ResidualWrapper``) to ``env``."""
        return self.config.wrap(env) if self.config else env

    def reset(self) -> None:
        """Start a new episode: clear the stacked observations (``frame_stack``)."""
        self._stack = None

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """The observation as the network saw it in training (normalised, then stacked)."""
        if self.obs_norm is not None:
            obs = self.obs_norm.normalize_obs(obs)
        if not self.frame_stack:
            return obs
        obs = np.asarray(obs, dtype=np.float32)
        if self._stack is None:  # as VecFrameStack at a reset: zeros, then the first observation
            self._stack = np.zeros(obs.shape[:-1] + (obs.shape[-1] * self.frame_stack,), obs.dtype)
        d = obs.shape[-1]
        self._stack[..., :-d] = self._stack[..., d:].copy()
        self._stack[..., -d:] = obs
        return self._stack.copy()

    def __call__(self, obs: Any) -> np.ndarray:
        action, _ = self.model.predict(self.normalize(np.asarray(obs)), deterministic=True)
        return action


def load_policy(spec: str, env: gym.Env | None = None, **kwargs: Any) -> Policy:
    """A baseline by name (needs ``env``) or a trained model by path."""
    if spec in BASELINES:
        if env is None:
            raise ValueError(f"baseline policy {spec!r} needs the env")
        return make_baseline_policy(spec, env)
    if Path(spec).suffix == ".zip" or Path(spec).is_file():
        return TrainedPolicy(spec, **kwargs)
    raise ValueError(
        f"policy {spec!r} is neither a baseline ({', '.join(BASELINES)}) nor a model file"
    )
