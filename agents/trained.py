"""Trained stable-baselines3 models as policies, and policies by name (baseline or model file).

A model saved by ``roughwalk train`` (``model.zip``, ``best_model.zip`` or a checkpoint) or by
rl-zoo3 is loaded with its ``VecNormalize`` statistics and its run's env wrappers. Models saved
by ``roughwalk train`` carry their algorithm and config in the zip, so they load also when
copied out of their run folder (with their statistics file beside them, or named).

Loading a model zip or a ``vecnormalize.pkl`` unpickles it, which can run arbitrary code: load
only files you trust. The algorithm and config are read from the zip's JSON part first,
without unpickling anything.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.config import algorithm_class, config_from_dict
from agents.policies import BASELINES, Policy, make_baseline_policy
from agents.pretrained import PREFIX, resolve_model
from agents.runs import (
    MODEL_INFO,
    find_manifest,
    find_vecnormalize,
    load_vecnormalize,
    model_algo,
    model_data,
    read_manifest,
    vecnormalize_path,
    zoo_config,
    zoo_run_files,
)


class TrainedPolicy:
    """A stable-baselines3 model acting deterministically, with its observation normalisation.

    Args:
        model_path: ``.zip`` saved by SB3.
        vecnormalize: ``VecNormalize`` statistics file; by default the one saved beside the model
            (see ``find_vecnormalize``), none if there is none.
        algo: algorithm name (``ppo``, ``sac``, ``td3``, ``a2c``); by default the one recorded
            in the model, its run or its policy class.

    Raises:
        FileNotFoundError: no model file.
        ValueError: not a readable model, an unknown or contradicting ``algo``, or a model
            trained on normalised observations whose statistics are missing.

    Attributes:
        manifest: the run manifest (``roughwalk train``), or ``{}``.
        config: the run's ``AgentConfig`` (from the manifest, from the config recorded in the
            model, or from rl-zoo3's saved settings for a model trained with rl-zoo3), else
            None; its ``wrap(env)`` applies the env wrappers the agent was trained with (e.g.
            the residual).
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
        data = model_data(self.path)  # JSON only: nothing unpickled yet
        recorded = model_algo(data)
        if algo is not None:
            algorithm_class(algo)  # a clear error for an unknown name
            algo = algo.lower()
            if recorded is not None and recorded != algo:
                raise ValueError(f"--algo {algo}: {self.path} is a {recorded.upper()} model")
        manifest_path = find_manifest(self.path)
        self.manifest: dict[str, Any] = read_manifest(manifest_path.parent) if manifest_path else {}
        self.config = None
        if "config" in self.manifest:
            self.config = config_from_dict(self.manifest["config"], manifest_path)
        info = data.get(MODEL_INFO) or {}
        if self.config is None and isinstance(info.get("config"), dict):
            self.config = config_from_dict(info["config"], self.path)
        zoo = zoo_run_files(self.path) if self.config is None else None
        if zoo is not None:
            self.config = config_from_dict(zoo_config(zoo, algo), zoo / "config.yml")
        algo = algo or recorded or (self.config.algo if self.config else None)
        if algo is None:
            raise ValueError(
                f"{self.path}: cannot tell the algorithm of this model; name it (--algo)"
            )
        vn_path = Path(vecnormalize) if vecnormalize else find_vecnormalize(self.path)
        if vn_path is None and self.config is not None and self.config.normalize_kwargs:
            raise ValueError(
                f"{self.path}: trained on normalised observations, but no VecNormalize "
                f"statistics beside it (expected {vecnormalize_path(self.path).name}); "
                "copy them with the model or name them (--vecnormalize)"
            )
        try:
            self.model = algorithm_class(algo).load(self.path, device="cpu")
        except Exception as exc:  # noqa: BLE001  (a corrupted zip can raise anything)
            raise ValueError(f"{self.path}: cannot load the {algo.upper()} model ({exc})") from None
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


def load_policy(
    spec: str,
    env: gym.Env | None = None,
    algo: str | None = None,
    vecnormalize: str | Path | None = None,
) -> Policy:
    """The policy ``spec``: a baseline by name (for ``env``, which it needs) or a trained model
    by path (a :class:`TrainedPolicy`; unpickles the model and its statistics).

    Args:
        spec: a baseline's name (``BASELINES``), the path of a model ``.zip`` or a shipped
            agent, ``pretrained:NAME`` (:mod:`agents.pretrained`).
        env: the env (baselines only).
        algo: a trained model's algorithm (``ppo``, ``sac``, ``td3``, ``a2c``); by default the
            one recorded in the model, its run or its policy class.
        vecnormalize: a trained model's ``VecNormalize`` statistics (default: beside it).
    """
    if spec in BASELINES:
        if env is None:
            raise ValueError(f"baseline policy {spec!r} needs the env")
        return make_baseline_policy(spec, env)
    spec = resolve_model(spec)
    if Path(spec).suffix == ".zip" or Path(spec).is_file():
        return TrainedPolicy(spec, vecnormalize=vecnormalize, algo=algo)
    raise ValueError(
        f"policy {spec!r} is neither a baseline ({', '.join(BASELINES)}), a model file nor "
        f"{PREFIX}NAME"
    )
