"""Old import path of the terrain, replaced by :mod:`envs.physics.terrain`.

Re-exports the names other modules import from here; new code imports from ``envs.physics``.
"""

from .physics.terrain import (
    KINDS,
    Terrain,
    as_terrain,
    terrain_height,
    terrain_heights,
    terrain_slope,
)

__all__ = ["KINDS", "Terrain", "as_terrain", "terrain_height", "terrain_heights", "terrain_slope"]
