"""Adapter from a Gymnasium vector env to stable-baselines3's ``VecEnv`` interface.

stable-baselines3 cannot consume Gymnasium vector envs directly: it expects a ``VecEnv`` that
resets finished sub-environments within the same ``step`` call and reports the last observation
of the finished episode in ``info["terminal_observation"]`` and a time-limit end in
``info["TimeLimit.truncated"]``. :class:`SB3VecEnv` provides that on top of any Gymnasium
``VectorEnv`` in ``AutoresetMode.SAME_STEP`` (the native roughwalk vector env built with
``autoreset_mode="same_step"``, or a ``SyncVectorEnv``/``AsyncVectorEnv`` created with
``vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}``).

Example::

    venv = make_sb3_vec_env("roughwalk/CompassGaitRough-v0", n_envs=64, seed=0)
    venv = VecNormalize(VecMonitor(venv))
    PPO("MlpPolicy", venv).learn(100_000)
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

import envs  # noqa: F401  (registers the roughwalk ids)


class SB3VecEnv(VecEnv):
    """stable-baselines3 ``VecEnv`` view of a Gymnasium vector env in same-step autoreset mode.

    Args:
        venv: a ``gymnasium.vector.VectorEnv`` whose ``metadata["autoreset_mode"]`` is
            ``AutoresetMode.SAME_STEP``.
        info_every_step: copy every info key into every sub-env's info dict at every step.
            By default (False) only sub-envs whose episode just ended get a filled dict (their
            final info, ``terminal_observation`` and ``TimeLimit.truncated``); the others get
            an empty dict, which is all SB3's algorithms read and much cheaper for many envs.

    ``get_attr``/``env_method`` address the vector env itself (its sub-envs share it): the
    value or result is repeated for every requested index. Seeds set with ``seed()`` go to the
    vector env's next ``reset`` as a list (one per sub-env); options set with
    ``set_options()`` are those of sub-env 0, applied to all.
    """

    def __init__(self, venv: gym.vector.VectorEnv, info_every_step: bool = False):
        mode = venv.metadata.get("autoreset_mode")
        if mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                f"SB3VecEnv needs a vector env in AutoresetMode.SAME_STEP, got {mode!r}; "
                "make it with autoreset_mode='same_step' (native env) or "
                "vector_kwargs={'autoreset_mode': AutoresetMode.SAME_STEP} (sync/async)"
            )
        self.venv = venv
        self.info_every_step = bool(info_every_step)
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> VecEnvObs:
        seeds = self._seeds
        seed: Any = None
        if any(s is not None for s in seeds):
            seed = [s for s in seeds]
        options = self._options[0] if self._options and self._options[0] else None
        obs, infos = self.venv.reset(seed=seed, options=options)
        self.reset_infos = [_unbatch(infos, i) for i in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions = self._actions.reshape(self.venv.action_space.shape)
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        self._actions = None
        dones = np.logical_or(terminated, truncated)
        n = self.num_envs
        if self.info_every_step:
            out = [_unbatch(infos, i) for i in range(n)]
        else:
            out = [{} for _ in range(n)]
        if dones.any():
            final_obs = infos.get("final_obs")
            final_info = infos.get("final_info", {})
            for i in np.nonzero(dones)[0]:
                d = out[i]
                d.update(_unbatch(final_info, int(i)))
                if final_obs is not None:
                    d["terminal_observation"] = final_obs[i]
                d["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, np.asarray(rewards, dtype=np.float32), dones, out

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv.render()
        if frames is None:
            return [None] * self.num_envs
        return list(frames)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.venv.unwrapped, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        result = getattr(self.venv.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """False for every sub-env of ``indices``: the vector env's sub-envs are not Gymnasium
        envs, so no ``wrapper_class`` wraps them."""
        return [False for _ in self._get_indices(indices)]

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices


def _unbatch(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """Info dict of sub-env ``i`` from Gymnasium's batched info (keys with ``_key`` masks)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        mask = infos.get("_" + key)
        if mask is not None and not mask[i]:
            continue
        if isinstance(value, dict):
            out[key] = _unbatch(value, i)
        else:
            v = value[i]
            out[key] = v.item() if isinstance(v, np.generic) else v
    return out


def make_sb3_vec_env(
    env_id: str,
    n_envs: int = 1,
    seed: int | None = None,
    info_every_step: bool = False,
    **env_kwargs: Any,
) -> SB3VecEnv:
    """SB3 ``VecEnv`` of ``n_envs`` copies of the roughwalk env ``env_id`` on the native
    vector env.

    Sub-env ``i`` is seeded with ``seed + i`` at the first ``reset()``. ``env_kwargs`` go to
    the env (as for ``gym.make``); ``info_every_step`` as for :class:`SB3VecEnv`.
    """
    venv = gym.make_vec(
        env_id,
        num_envs=n_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode="same_step",
        **env_kwargs,
    )
    adapter = SB3VecEnv(venv, info_every_step=info_every_step)
    if seed is not None:
        adapter.seed(seed)
    return adapter
