"""The project's YAML settings, shipped as package data: ``robots/``, ``terrains/``, ``envs/``,
``planner/``, ``controller/`` and ``agents/`` (rl-zoo3 format)."""

from pathlib import Path

#: the folder of this package's YAML files (inside the installed package or the source tree)
CONFIG_DIR: Path = Path(__file__).resolve().parent

__all__ = ["CONFIG_DIR"]
