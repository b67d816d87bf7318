"""What the compass-gait task is: the reward, the start state of an episode and the terrain.

* :class:`RewardConfig`: weights of hip progress, motor work and failure.
* :class:`InitialState`: the nominal post-impact start state, its random spread and the stance
  leg; :meth:`InitialState.sample` draws one episode's start.
* :class:`TerrainSource`: a fixed course, or a generator of random courses drawn anew from a
  seed at every reset; :func:`envs.physics.terrain.terrain_spec` resolves the ``terrain``
  argument it is built from (a name in ``configs/terrains``, a YAML path, a kind, a spec dict
  or a Terrain).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .physics.kernel import O_WABS, O_WNET, O_WPOS
from .physics.terrain import Terrain, terrain_spec

#: ``reward.work`` kind -> column of :attr:`envs.physics.StepEvents.work`
WORK_COLUMNS: dict[str, int] = {"net": O_WNET, "positive": O_WPOS, "absolute": O_WABS}
#: entries of :meth:`RewardConfig.weights`
W_PROGRESS, W_ENERGY, W_FAILURE = range(3)
#: random terrain kinds (:data:`envs.physics.terrain.SEEDED_KINDS`) -> the field that
#: ``difficulty`` scales
RANDOM_KINDS: dict[str, str] = {"blocks": "height_range", "piecewise": "slope_range"}
#: accepted stance-leg names and codes -> physical leg (0 = A, 1 = B)
LEG_CODES: dict[Any, int] = {"A": 0, "B": 1, 0: 0, 1: 1}


# ---------------------------------------------------------------------------- reward
@dataclass(frozen=True)
class RewardConfig:
    """Reward ``r = progress * dx_hip - energy * W - failure * [failed in this step]``.

    Attributes:
        progress: weight of the forward hip displacement over the step [1/m], >= 0.
        energy: weight of the motor work over the step [1/J], >= 0.
        failure: penalty when the walker fails (fall, trip, ...), >= 0.
        work: which motor work: ``"absolute"`` (``int |tau q1dot| dt``, default),
            ``"positive"`` (``int max(tau q1dot, 0) dt``) or ``"net"`` (``int tau q1dot dt``).
    """

    progress: float = 1.0
    energy: float = 0.05
    failure: float = 1.0
    work: str = "absolute"

    def __post_init__(self) -> None:
        for name in ("progress", "energy", "failure"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"reward.{name} must be a finite number, got {v!r}")
            if v < 0:
                raise ValueError(f"reward.{name} = {v!r} out of range; allowed: >= 0")
            object.__setattr__(self, name, float(v))
        if self.work not in WORK_COLUMNS:
            raise ValueError(f"reward.work = {self.work!r}; allowed: {sorted(WORK_COLUMNS)}")

    def weights(self) -> np.ndarray:
        """``[progress, energy, failure]`` as the reward kernel reads them (entries
        ``W_PROGRESS``, ``W_ENERGY``, ``W_FAILURE``)."""
        return np.array([self.progress, self.energy, self.failure])

    @property
    def work_column(self) -> int:
        """Column of :attr:`envs.physics.StepEvents.work` holding this reward's motor work."""
        return WORK_COLUMNS[self.work]


# ---------------------------------------------------------------------------- start state
@dataclass(frozen=True)
class InitialState:
    """Start of every episode: a post-impact state of a nominal gait plus a uniform spread.

    Attributes:
        q: nominal ``(q1, q2)`` [rad] (paper coordinates).
        qd: nominal ``(q1dot, q2dot)`` [rad/s].
        spread: half-widths of the uniform perturbation of ``(q1, q2, q1dot, q2dot)``
            [rad, rad, rad/s, rad/s], each >= 0.
        stance_leg: physical stance leg at the start: ``"A"``, ``"B"`` or ``"random"``.
    """

    q: tuple[float, float]
    qd: tuple[float, float]
    spread: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    stance_leg: str = "A"

    def __post_init__(self) -> None:
        for name, size in (("q", 2), ("qd", 2), ("spread", 4)):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise ValueError(f"initial_state.{name} must be {size} finite numbers, got {v}")
            if name == "spread" and np.any(v < 0):
                raise ValueError(f"initial_state.spread = {v.tolist()}; allowed: each >= 0")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if self.stance_leg not in ("A", "B", "random"):
            raise ValueError(
                f"initial_state.stance_leg = {self.stance_leg!r}; allowed: 'A', 'B', 'random'"
            )

    def sample(
        self, rng: np.random.Generator, state: Any = None, stance_leg: Any = None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """One episode's start ``(q [rad], qd [rad/s], stance leg 0 = A / 1 = B)``.

        Args:
            rng: the episode's generator (the spread, then a random stance leg, are drawn from
                it, each only when used).
            state: the reset option ``"state"``: an exact ``(q, qd)`` (no spread), or None.
            stance_leg: the reset option ``"stance_leg"`` (``"A"`` or ``"B"``), or None.
        """
        if state is not None:
            q, qd = state_option(state)
        else:
            x = np.array(self.q + self.qd)
            if any(self.spread):
                x = x + np.asarray(self.spread) * rng.uniform(-1.0, 1.0, size=4)
            q, qd = x[:2], x[2:]
        if stance_leg is not None:
            if stance_leg not in LEG_CODES:
                raise ValueError(f"reset option stance_leg = {stance_leg!r}; allowed: 'A', 'B'")
            leg = LEG_CODES[stance_leg]
        elif self.stance_leg == "random":
            leg = int(rng.integers(0, 2))
        else:
            leg = LEG_CODES[self.stance_leg]
        return q, qd, leg


def state_option(state: Any) -> tuple[np.ndarray, np.ndarray]:
    """The reset option ``"state"`` checked: ``(q [rad], qd [rad/s])``, two finite each."""
    try:
        q, qd = state
        q = np.asarray(q, dtype=np.float64)
        qd = np.asarray(qd, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"reset option 'state' must be (q, qd) with two angles and two rates, got {state!r}"
        ) from None
    if (
        q.shape != (2,)
        or qd.shape != (2,)
        or not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd)))
    ):
        raise ValueError(
            f"reset option 'state' must be finite (q, qd) of shape (2,), got {state!r}"
        )
    return q, qd


# ---------------------------------------------------------------------------- terrain
class TerrainSource:
    """Fixed terrain, or a generator of random terrain drawn anew from a seed at each reset.

    A spec dict of a random kind (``blocks``, ``piecewise``) without a ``seed`` is a generator:
    each episode draws ``seed`` from the env's ``np_random``. ``difficulty`` scales the random
    kinds' heights (``height_range`` of blocks, ``slope_range`` of piecewise ground).

    Args:
        terrain: a :class:`Terrain`, a spec dict or a name (see
            :func:`envs.physics.terrain.terrain_spec`).
        difficulty: scale of the random kinds' heights, finite >= 0 (1: as specified).
    """

    def __init__(self, terrain: Terrain | dict[str, Any] | str, difficulty: float = 1.0):
        if isinstance(difficulty, bool) or not isinstance(difficulty, (int, float)):
            raise ValueError(f"difficulty must be a number >= 0, got {difficulty!r}")
        if not (math.isfinite(difficulty) and difficulty >= 0):
            raise ValueError(f"difficulty = {difficulty!r} out of range; allowed: finite >= 0")
        self.difficulty = float(difficulty)
        spec = terrain_spec(terrain)
        self.template: dict[str, Any] | None = None
        self.fixed: Terrain | None = None
        if isinstance(spec, Terrain):
            if self.difficulty != 1.0:
                raise ValueError("difficulty applies to terrain specs, not to a built Terrain")
            self.fixed = spec
            return
        kind = spec.get("kind")
        if self.difficulty != 1.0:
            key = RANDOM_KINDS.get(kind)
            if key is None:
                raise ValueError(
                    f"difficulty = {difficulty} scales random terrain only (kinds "
                    f"{sorted(RANDOM_KINDS)}); the terrain kind is {kind!r}"
                )
            if "xs" in spec:
                raise ValueError("difficulty cannot rescale a terrain given by its vertices")
            lo, hi = spec.get(key, (-0.02, 0.02) if kind == "blocks" else (-0.1, 0.1))
            spec[key] = [float(lo) * self.difficulty, float(hi) * self.difficulty]
        if kind in RANDOM_KINDS and "seed" not in spec:
            self.template = spec
            Terrain.from_dict({**spec, "seed": 0})  # validate the fields now
        else:
            self.fixed = Terrain.from_dict(spec)

    @property
    def is_random(self) -> bool:
        """True for a generator of random courses."""
        return self.template is not None

    def draw(self, rng: np.random.Generator) -> Terrain:
        """The terrain of a new episode (a fresh random course when this is a generator)."""
        if self.fixed is not None:
            return self.fixed
        seed = int(rng.integers(0, 2**31 - 1))
        return Terrain.from_dict({**self.template, "seed": seed})

    def preview(self) -> Terrain:
        """A terrain to build the simulator with before the first reset."""
        return (
            self.fixed
            if self.fixed is not None
            else Terrain.from_dict({**self.template, "seed": 0})
        )
