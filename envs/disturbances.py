"""Disturbances of an episode: model error (``robot_error``) and hip pushes (``push``).

* :class:`RobotError`: relative half-widths of the physical robot parameters
  (:data:`envs.physics.params.PHYSICAL_PARAMS`). At every reset the simulated robot is drawn
  uniformly within them (:meth:`RobotError.draw`); the env's ``robot`` stays the nominal model.
* :class:`PushConfig`: when the hip is pushed (at times drawn at random intervals, at fixed
  times, or at a phase of every step), by how much and in which direction.
  :class:`PushSchedule` runs it for a batch of walkers: pushes are applied at the start of a
  control period, through the model (:meth:`envs.physics.Simulator.push_hip`).

Both draw only from the episode's generator, and only when they are switched on: with the
defaults (no error, no pushes) every episode is what it was without them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .config_util import dataclass_from_mapping
from .physics.kernel import F_STATUS, OK, X_Q2, X_T
from .physics.params import PHYSICAL_PARAMS, RobotParams
from .physics.simulator import Simulator

#: largest relative half-width of a parameter's error (exclusive)
MAX_RELATIVE_ERROR = 0.5
#: largest speed change of a push [m/s]
MAX_PUSH = 5.0
#: phases of a step a push can be tied to (``push.at``)
PUSH_PHASES = ("mid_stance", "touchdown")
PUSH_DIRECTIONS = ("random", "forward", "backward")
#: how ``robot_error`` draws a parameter within its half-width ``w`` (``robot_error.draw``)
ROBOT_ERROR_DRAWS = ("uniform", "sign")
#: a push due at time ``t`` happens at the first control period starting at ``t - TIME_TOL``
#: or later [s]
TIME_TOL = 1e-9


# ---------------------------------------------------------------------------- model error
@dataclass(frozen=True)
class RobotError:
    """Relative half-widths of the errors of the simulated robot's physical parameters.

    Build it with :meth:`from_setting` (the env setting ``robot_error``: a float for every
    parameter of :data:`~envs.physics.params.PHYSICAL_PARAMS`, or a mapping
    ``{name: half-width}``), each half-width in ``[0, 0.5)``.

    Attributes:
        half_widths: ``(name, half-width)`` of the perturbed parameters (half-width > 0), in
            the order of ``PHYSICAL_PARAMS``.
    """

    half_widths: tuple[tuple[str, float], ...] = ()
    draw_mode: str = "uniform"

    def __post_init__(self) -> None:
        if self.draw_mode not in ROBOT_ERROR_DRAWS:
            raise ValueError(
                f"robot_error.draw = {self.draw_mode!r}; allowed: {list(ROBOT_ERROR_DRAWS)}"
            )

    @classmethod
    def from_setting(cls, value: Any) -> RobotError:
        """The setting ``robot_error``: None or 0 (no error), a float (every physical
        parameter) or a mapping ``{parameter: half-width}``; a :class:`RobotError` as it is.
        The mapping may also hold ``all`` (a half-width for every physical parameter that it
        does not name) and ``draw``: ``"uniform"`` (default: each parameter uniform within
        ``+-w``) or ``"sign"`` (each parameter at exactly ``+w`` or ``-w``, the sign at random:
        the corners of the error box, as in a robustness benchmark).

        Raises:
            ValueError: a value that is none of those, an unknown parameter name or a
                half-width outside ``[0, 0.5)``, naming it.
        """
        if isinstance(value, RobotError):
            return value
        if value is None:
            return cls()
        mode = "uniform"
        if isinstance(value, Mapping):
            value = dict(value)
            mode = value.pop("draw", mode)
            unknown = sorted((k for k in value if k not in PHYSICAL_PARAMS + ("all",)), key=str)
            if unknown:
                raise ValueError(
                    f"robot_error: unknown parameter(s) {unknown}; allowed: "
                    f"{list(PHYSICAL_PARAMS)} (the robot's physical parameters), 'all', 'draw'"
                )
            widths = {k: _half_width(f"robot_error[{k!r}]", v) for k, v in value.items()}
            every = widths.pop("all", 0.0)
            widths = {k: widths.get(k, every) for k in PHYSICAL_PARAMS}
        else:
            w = _half_width("robot_error", value)
            widths = dict.fromkeys(PHYSICAL_PARAMS, w)
        kept = tuple((k, widths[k]) for k in PHYSICAL_PARAMS if widths.get(k, 0.0) > 0.0)
        return cls(kept, mode)

    @property
    def enabled(self) -> bool:
        """Whether any parameter is perturbed."""
        return bool(self.half_widths)

    def to_setting(self) -> dict[str, float]:
        """The setting as a mapping ``{parameter: half-width}`` (YAML serialisable), with
        ``draw`` when it is not the default."""
        out: dict[str, Any] = dict(self.half_widths)
        if self.draw_mode != "uniform":
            out["draw"] = self.draw_mode
        return out

    def draw(self, robot: RobotParams, rng: np.random.Generator) -> RobotParams:
        """The simulated robot of one episode: each perturbed parameter of the nominal
        ``robot`` times ``1 + w * U(-1, 1)`` (``draw="sign"``: ``1 + w * sign(U(-1, 1))``),
        one uniform draw per parameter from ``rng`` in the order of ``half_widths``
        (:meth:`envs.physics.RobotParams.perturbed`: ``lc`` moves with ``l``).

        Raises:
            ValueError: the draw is not a valid robot (the message names the parameter).
        """
        u = rng.uniform(-1.0, 1.0, size=len(self.half_widths))
        if self.draw_mode == "sign":
            u = np.where(u < 0.0, -1.0, 1.0)
        return self._apply(robot, {k: w * float(x) for (k, w), x in zip(self.half_widths, u)})

    def check(self, robot: RobotParams) -> None:
        """Check that the corners of the error box around ``robot`` (every parameter at
        ``+-w``) are valid robots, so that draws are (up to the non-monotone hip friction
        bound, which :meth:`draw` checks again).

        Raises:
            ValueError: naming the corner and the parameter out of range.
        """
        if not self.enabled:
            return
        names = [k for k, _ in self.half_widths]
        for signs in itertools.product((-1.0, 1.0), repeat=len(names)):
            errors = {k: s * w for (k, w), s in zip(self.half_widths, signs)}
            self._apply(robot, errors)

    @staticmethod
    def _apply(robot: RobotParams, errors: dict[str, float]) -> RobotParams:
        try:
            return robot.perturbed(errors)
        except ValueError as exc:
            where = ", ".join(f"{k} {100 * e:+.3g} %" for k, e in errors.items())
            raise ValueError(f"robot_error: at {where} the robot is not valid: {exc}") from None


def _half_width(name: str, value: Any) -> float:
    if not (_real(value) and 0.0 <= value < MAX_RELATIVE_ERROR):
        allowed = f"a relative half-width in [0, {MAX_RELATIVE_ERROR:g})"
        if name == "robot_error":
            allowed += " (0.05: every parameter within +-5 %) or a mapping {parameter: half-width}"
        raise ValueError(f"{name} = {value!r}; allowed: {allowed}")
    return float(value)


def robot_dict(robot: RobotParams) -> dict[str, float]:
    """The numeric fields of ``robot`` as a plain dict of floats (``RobotParams.from_dict``
    rebuilds it; the name is left out)."""
    return {k: float(v) for k, v in asdict(robot).items() if k != "name"}


# ---------------------------------------------------------------------------- pushes
@dataclass(frozen=True)
class PushConfig:
    """Random horizontal pushes at the hip (the env setting ``push``, a mapping of these
    fields).

    Exactly one of ``every``, ``at`` and ``times`` says when; each such time is an
    opportunity for a push (thinned by ``probability``, ``max_pushes`` and ``after``).

    Attributes:
        dv: the speed change of the hip [m/s]: a number or a range ``[lo, hi]`` drawn
            uniformly, within ``[0, 5]``.
        direction: ``"random"`` (forwards or backwards with equal chances), ``"forward"``
            (towards +x) or ``"backward"``.
        every: the interval between pushes [s], a number or a range ``[lo, hi]`` drawn anew
            for each interval, ``lo > 0``; the first interval starts at ``after``.
        at: a phase of every step: ``"mid_stance"`` (the stance leg passes the vertical,
            ``q2`` from negative to >= 0, once per step) or ``"touchdown"`` (the first control
            period of each step, and of the episode).
        times: fixed times since the reset [s], each >= 0.
        probability: chance that an opportunity is a push, in (0, 1].
        max_pushes: most pushes per episode (>= 1), or None for no limit.
        after: no pushes before this time since the reset [s], >= 0 (with ``every`` and
            ``at``).

    A push happens at the start of the first control period at or after its time (or phase):
    at most one per period and walker, on a running walker only.
    """

    dv: float | tuple[float, float]
    direction: str = "random"
    every: float | tuple[float, float] | None = None
    at: str | None = None
    times: tuple[float, ...] | None = None
    probability: float = 1.0
    max_pushes: int | None = None
    after: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "dv", _range("push.dv", self.dv, 0.0, MAX_PUSH, "m/s", lo_open=False))
        if self.direction not in PUSH_DIRECTIONS:
            raise ValueError(
                f"push.direction = {self.direction!r}; allowed: {list(PUSH_DIRECTIONS)}"
            )
        modes = [k for k in ("every", "at", "times") if getattr(self, k) is not None]
        if len(modes) != 1:
            raise ValueError(
                f"push needs exactly one of 'every' (an interval [lo, hi] s), 'at' (a phase: "
                f"{', '.join(PUSH_PHASES)}) or 'times' (a list of s); got {modes or 'none'}"
            )
        if self.every is not None:
            set_(self, "every", _range("push.every", self.every, 0.0, math.inf, "s", True))
        if self.at is not None and self.at not in PUSH_PHASES:
            raise ValueError(f"push.at = {self.at!r}; allowed: {list(PUSH_PHASES)}")
        if not (_real(self.after) and self.after >= 0.0):
            raise ValueError(f"push.after = {self.after!r}; allowed: a time >= 0 s")
        set_(self, "after", float(self.after))
        if self.times is not None:
            set_(self, "times", _times(self.times))
            if self.after != 0.0:
                raise ValueError("push.after applies to 'every' and 'at'; give the times")
        p = self.probability
        if not (_real(p) and 0.0 < p <= 1.0):
            raise ValueError(f"push.probability = {p!r}; allowed: a number in (0, 1]")
        set_(self, "probability", float(p))
        mp = self.max_pushes
        if mp is not None:
            if not (_real(mp) and mp == int(mp) and mp >= 1):
                raise ValueError(f"push.max_pushes = {mp!r}; allowed: an integer >= 1 or None")
            set_(self, "max_pushes", int(mp))

    @classmethod
    def from_setting(cls, value: Any) -> PushConfig | None:
        """The setting ``push``: None or False (no pushes), a mapping of the fields, or a
        :class:`PushConfig`.

        Raises:
            ValueError: anything else, an unknown key, a missing ``dv`` or a bad value,
                naming the field and what it allows.
        """
        if value is None or value is False or isinstance(value, PushConfig):
            return value or None
        if not isinstance(value, Mapping):
            raise ValueError(
                f"push must be a mapping (dv, and every, at or times) or null, got {value!r}"
            )
        return dataclass_from_mapping(cls, value, "push")

    def to_setting(self) -> dict[str, Any]:
        """The setting as a plain mapping (YAML serialisable; ranges as lists)."""
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        return {k: v for k, v in d.items() if v is not None}


def _real(v: Any) -> bool:
    ok = not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))
    return ok and math.isfinite(v)


def _range(
    name: str, value: Any, low: float, high: float, unit: str, lo_open: bool
) -> float | tuple[float, float]:
    """A number or a range ``[lo, hi]`` within ``[low, high]`` (``lo > low`` if ``lo_open``)."""
    opening = "(" if lo_open else "["
    top = "inf)" if math.isinf(high) else f"{high:g}]"
    allowed = f"a number or a range [lo, hi] in {opening}{low:g}, {top} {unit}"
    if isinstance(value, (list, tuple)):
        vals = list(value)
        if len(vals) != 2 or not all(_real(v) for v in vals) or vals[0] > vals[1]:
            raise ValueError(f"{name} = {value!r}; allowed: {allowed} with lo <= hi")
    elif _real(value):
        vals = [value]
    else:
        raise ValueError(f"{name} = {value!r}; allowed: {allowed}")
    for v in vals:
        if v < low or (lo_open and v == low) or v > high:
            raise ValueError(f"{name} = {value!r} out of range; allowed: {allowed}")
    return float(vals[0]) if len(vals) == 1 else (float(vals[0]), float(vals[1]))


def _times(value: Any) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or not all(_real(v) and v >= 0 for v in value):
        raise ValueError(f"push.times = {value!r}; allowed: a list of times >= 0 s")
    if not value:
        raise ValueError("push.times is empty; give at least one time [s]")
    return tuple(sorted(float(v) for v in value))


def _draw(rng: np.random.Generator, value: float | tuple[float, float]) -> float:
    """``value``, or a uniform draw from the range ``value``."""
    return rng.uniform(value[0], value[1]) if isinstance(value, tuple) else value


class PushSchedule:
    """Pushes of a batch of ``n`` walkers under one :class:`PushConfig`.

    Each walker draws from its own generator, seeded from the episode's generator at reset.
    The last step's pushes are in ``pushed`` (mask), ``time`` [s], ``dv`` [m/s] and
    ``impulse`` [N s].

    Args:
        config: the pushes.
        n: number of walkers.
    """

    def __init__(self, config: PushConfig, n: int):
        self.config = config
        self.rngs: list[np.random.Generator | None] = [None] * n
        self.pending = np.zeros(n, dtype=bool)  # ``at``: this step's opportunity is still due
        self.next_time = np.full(n, math.inf)  # ``every`` and ``times``: the next due time [s]
        self.next_index = np.zeros(n, dtype=np.int64)  # ``times``: index of the next time
        self.count = np.zeros(n, dtype=np.int64)
        self.pushed = np.zeros(n, dtype=bool)
        self.time = np.zeros(n)
        self.dv = np.zeros(n)
        self.impulse = np.zeros(n)

    def reset(self, i: int, rng: np.random.Generator) -> None:
        """Start walker ``i``'s episode: its push generator is seeded from ``rng``."""
        c = self.config
        self.rngs[i] = r = np.random.default_rng(int(rng.integers(0, 2**63 - 1)))
        self.pending[i] = True
        self.count[i] = 0
        self.pushed[i] = False
        self.next_index[i] = 0
        if c.every is not None:
            self.next_time[i] = c.after + _draw(r, c.every)
        elif c.times is not None:
            self.next_time[i] = c.times[0]

    def apply(self, sim: Simulator) -> None:
        """Push the walkers that are due at the start of this control period."""
        c, x = self.config, sim.states
        self.pushed[:] = False
        running = sim.flags[:, F_STATUS] == OK
        if c.at is not None:
            due = self.pending & running
            if c.at == "mid_stance":
                due &= x[:, X_Q2] >= 0.0
        else:
            due = running & (x[:, X_T] >= self.next_time - TIME_TOL)
        for i in np.nonzero(due)[0]:
            self._opportunity(int(i), sim)

    def _opportunity(self, i: int, sim: Simulator) -> None:
        c, r = self.config, self.rngs[i]
        t = float(sim.states[i, X_T])
        if c.at is not None:
            self.pending[i] = False
        elif c.every is not None:
            while self.next_time[i] <= t + TIME_TOL:
                self.next_time[i] += _draw(r, c.every)
        else:
            k = int(np.searchsorted(c.times, t + TIME_TOL, side="right"))
            self.next_index[i] = k
            self.next_time[i] = c.times[k] if k < len(c.times) else math.inf
        if t < c.after - TIME_TOL or (c.max_pushes is not None and self.count[i] >= c.max_pushes):
            return
        if c.probability < 1.0 and r.random() >= c.probability:
            return
        dv = _draw(r, c.dv)
        if c.direction == "backward" or (c.direction == "random" and r.random() < 0.5):
            dv = -dv
        self.impulse[i] = sim.push_hip(i, dv)
        self.count[i] += 1
        self.pushed[i] = True
        self.time[i] = t
        self.dv[i] = dv

    def after_step(self, n_impacts: np.ndarray) -> None:
        """Note the touchdowns of the step just taken (``n_impacts``, per walker): each starts
        a step with a new ``at`` opportunity."""
        if self.config.at is not None:
            self.pending |= n_impacts > 0

    def info(self, i: int) -> dict[str, float]:
        """Walker ``i``'s push of the last step: ``time`` [s], ``dv`` [m/s], ``impulse``
        [N s]."""
        return {"time": float(self.time[i]), "dv": float(self.dv[i]),
                "impulse": float(self.impulse[i])}  # fmt: skip

    def infos(self) -> dict[str, Any]:
        """The last step's pushes of all walkers in Gymnasium's batched form (zeros and a
        False mask where a walker was not pushed)."""
        m = self.pushed.copy()
        d: dict[str, Any] = {}
        for key in ("time", "dv", "impulse"):
            d[key] = np.where(m, getattr(self, key), 0.0)
            d["_" + key] = m
        return d
