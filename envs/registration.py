"""Registration of the roughwalk environments with Gymnasium (done on ``import envs``).

Ids (namespace ``roughwalk``), each with the native vector env as ``vector_entry_point``:

* ``roughwalk/CompassGait-v0``: fully configurable by keyword arguments (defaults: ``flat``).
* ``roughwalk/CompassGaitFlat-v0``: the paper's robot on level ground.
* ``roughwalk/CompassGaitStairs-v0``: the paper's experiment, flat, down two stairs, flat.
* ``roughwalk/CompassGaitStairsUp-v0``: the same course climbed, up two 1 cm stairs.
* ``roughwalk/CompassGaitRough-v0``: random blocks drawn anew from the seed at every reset
  (keyword ``difficulty`` scales the block heights).
* ``roughwalk/CompassGaitSlope-v0``: the classic walker on a 0.0525 rad downhill.

The settings (and ``max_episode_steps``) of each id live in ``configs/envs/<name>.yaml``, merged
over ``configs/envs/base.yaml`` (:func:`envs.settings.load_env_config`).
"""

from __future__ import annotations

import gymnasium as gym

from .settings import load_env_config

NAMESPACE = "roughwalk"

#: id (without namespace) -> env config name in configs/envs
ENV_IDS: dict[str, str] = {
    "CompassGait-v0": "flat",
    "CompassGaitFlat-v0": "flat",
    "CompassGaitStairs-v0": "stairs",
    "CompassGaitStairsUp-v0": "stairs_up",
    "CompassGaitRough-v0": "rough",
    "CompassGaitSlope-v0": "slope",
}


def register_envs() -> list[str]:
    """Register every roughwalk id that is not registered yet; returns all full ids."""
    ids = []
    steps: dict[str, int | None] = {}  # each config file is read once
    for name, config in ENV_IDS.items():
        full = f"{NAMESPACE}/{name}"
        ids.append(full)
        if full in gym.registry:
            continue
        if config not in steps:
            steps[config] = load_env_config(config).get("max_episode_steps")
        gym.register(
            id=full,
            entry_point="envs.env:CompassGaitEnv",
            vector_entry_point="envs.vector_env:CompassGaitVectorEnv",
            max_episode_steps=steps[config],
            kwargs={"config": config},
        )
    return ids
