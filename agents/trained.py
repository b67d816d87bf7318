"""Trained stable-baselines3 models as policies, and policies by name (baseline or model file).

A model saved by ``roughwalk train`` (``model.zip``, ``best_model.zip`` or a checkpoint) or by
rl-zoo3 is loaded with its ``VecNormalize`` statistics and its run's env wrappers.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.config import algorithm_class, config_from_dict
from agents.policies import BASELINES, Policy, make_baseline_policy
from agents.runs import (
    find_manifest,
    find_vecnormalize,
    load_vecnormalize,
    zoo_config,
    zoo_run_files,
)


def _algo_from_zip(path: Path) -> str:
    """The algorithm name (``ppo``, ``sac``, ...) of a model file, from its policy class."""
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
        """The observation ``obs`` as the network saw it in training (normalised, then
        stacked)."""
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
    """The policy ``spec``: a baseline by name (for ``env``, which it needs) or a trained model
    by path (``kwargs`` go to :class:`TrainedPolicy`)."""
    if spec in BASELINES:
        if env is None:
            raise ValueError(f"baseline policy {spec!r} needs the env")
        return make_baseline_policy(spec, env)
    if Path(spec).suffix == ".zip" or Path(spec).is_file():
        return TrainedPolicy(spec, **kwargs)
    raise ValueError(
        f"policy {spec!r} is neither a baseline ({', '.join(BASELINES)}) nor a model file"
    )
