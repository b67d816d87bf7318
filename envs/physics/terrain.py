"""Terrain: a ground height profile ``h(x)`` made of straight segments and vertical faces.

Every kind of terrain (flat, slope, stairs, random blocks, random piecewise-linear ground) is
stored as one polyline: vertices ``(x_k, y_k)`` with non-decreasing ``x``; two consecutive
vertices with the same ``x`` form a vertical face (a riser or the side of a block). Left of the
first vertex and right of the last, the ground continues along the first / last segment.

A terrain serialises to a plain dict (``to_dict``) that rebuilds it exactly (``from_dict``), so
courses can be saved as YAML, shared and replayed.

Representations of a terrain, and the one conversion between each pair:

* :class:`Terrain`: the polyline (``xs``, ``ys``) and the spec it was built from;
* its spec dict / YAML form: :meth:`Terrain.to_dict` / :meth:`Terrain.from_dict`,
  :meth:`Terrain.to_yaml` / :meth:`Terrain.from_yaml`; a spec of a random kind without a
  ``seed`` is a generator of courses (:class:`envs.task.TerrainSource` draws the seed);
* a terrain argument (a :class:`Terrain`, a spec dict or a string): :func:`terrain_spec`
  resolves it to a Terrain or a spec, :func:`as_terrain` to a Terrain; the meaning of a string
  is defined there and nowhere else;
* the compiled arrays: :meth:`Terrain.arrays` (read-only vertices) for
  :func:`terrain_height` / :func:`terrain_slope`, padded into one row per walker by
  :meth:`envs.physics.Simulator.set_terrain`;
* the planner's map, :class:`controllers.planner.footholds.TerrainMap` (a Terrain with its
  faces and kinks, or one rebuilt from scanned heights), made by ``TerrainMap.coerce``.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numba import njit

from configs import CONFIG_DIR

from ..config_util import read_yaml_mapping

KINDS = ("flat", "slope", "stairs", "blocks", "piecewise", "points")
#: kinds drawn from a ``seed``: a spec of one of them without a seed is a generator of courses
SEEDED_KINDS = ("blocks", "piecewise")
#: kinds that a bare name builds with default fields (``"slope"``: level, angle 0; the seeded
#: kinds: a generator with default fields)
NAMED_KINDS = ("flat", "slope", "blocks", "piecewise")
#: the courses shipped with the project: ``NAME.yaml`` spec files
TERRAIN_CONFIG_DIR = CONFIG_DIR / "terrains"
#: most vertices of one course (the simulator holds every walker's course in one padded array)
MAX_VERTICES = 200_000
#: longest random course (``length`` of blocks and piecewise ground) [m]
MAX_COURSE_LENGTH = 1e4
_YAML_SUFFIXES = (".yaml", ".yml")


@njit(cache=True, error_model="numpy")
def terrain_height(tx, ty, n, x):
    """Ground height [m] at ``x`` [m] for the polyline ``tx[:n], ty[:n]`` [m]. Scalars only.

    On a vertical face (``x`` equal to the abscissa of the face) the upper height is returned.
    """
    if n == 1:
        return ty[0]
    if x <= tx[0]:
        if tx[1] > tx[0]:
            return ty[0] + (ty[1] - ty[0]) / (tx[1] - tx[0]) * (x - tx[0])
        return ty[0] if x < tx[0] else max(ty[0], ty[1])
    if x >= tx[n - 1]:
        if tx[n - 1] > tx[n - 2]:
            return ty[n - 1] + (ty[n - 1] - ty[n - 2]) / (tx[n - 1] - tx[n - 2]) * (x - tx[n - 1])
        return ty[n - 1] if x > tx[n - 1] else max(ty[n - 1], ty[n - 2])
    lo, hi = 0, n - 1  # invariant: tx[lo] <= x < tx[hi]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if tx[mid] <= x:
            lo = mid
        else:
            hi = mid
    if tx[lo] == x:
        h = ty[lo]
        k = lo - 1
        while k >= 0 and tx[k] == x:
            h = max(h, ty[k])
            k -= 1
        return h
    return ty[lo] + (ty[hi] - ty[lo]) / (tx[hi] - tx[lo]) * (x - tx[lo])


@njit(cache=True, error_model="numpy")
def terrain_heights(tx, ty, x):
    """:func:`terrain_height` [m] at every entry of the 1-D array ``x`` [m] for the polyline
    ``tx, ty`` [m] (all of its vertices)."""
    out = np.empty(x.size)
    n = tx.size
    for i in range(x.size):
        out[i] = terrain_height(tx, ty, n, x[i])
    return out


@njit(cache=True, error_model="numpy")
def terrain_slope(tx, ty, n, x):
    """Slope ``dh/dx`` (dimensionless) of the segment of the polyline ``tx[:n], ty[:n]`` [m]
    under ``x`` [m] (the segment to the right on a vertex). Scalars only."""
    if n == 1:
        return 0.0
    if x < tx[0]:
        return (ty[1] - ty[0]) / (tx[1] - tx[0]) if tx[1] > tx[0] else 0.0
    if x >= tx[n - 1]:
        return (ty[n - 1] - ty[n - 2]) / (tx[n - 1] - tx[n - 2]) if tx[n - 1] > tx[n - 2] else 0.0
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if tx[mid] <= x:
            lo = mid
        else:
            hi = mid
    return (ty[hi] - ty[lo]) / (tx[hi] - tx[lo])


def _finite(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"terrain field {name!r} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"terrain field {name!r} must be finite, got {value!r}")
    return v


def _range(name: str, value: Any, lower: float = -math.inf) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"terrain field {name!r} must be a pair [low, high]: {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a > b or a < lower:
        raise ValueError(
            f"terrain field {name!r} = {value!r} must be a finite pair low <= high, low >= {lower}"
        )
    return a, b


class Terrain:
    """Ground profile ``h(x)`` [m] as a polyline with vertical faces.

    Build one with the kind constructors (:meth:`flat`, :meth:`slope`, :meth:`stairs`,
    :meth:`staircase`, :meth:`random_blocks`, :meth:`random_piecewise`, :meth:`from_points`)
    or from a spec dict with :meth:`from_dict`.

    Args:
        xs: x of the polyline's vertices [m], non-decreasing (two equal x: a vertical face).
        ys: heights of the vertices [m], same length as ``xs``.
        spec: the spec dict that :meth:`to_dict` returns (``{"kind": ..., ...}``).
    """

    def __init__(self, xs: Sequence[float], ys: Sequence[float], spec: dict[str, Any]):
        x = np.ascontiguousarray(xs, dtype=np.float64)
        y = np.ascontiguousarray(ys, dtype=np.float64)
        if x.ndim != 1 or x.shape != y.shape or x.size < 1:
            raise ValueError("terrain points: xs and ys must be 1-D arrays of the same length >= 1")
        if x.size > MAX_VERTICES:
            raise ValueError(f"terrain points: {x.size} vertices; allowed: at most {MAX_VERTICES}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError("terrain points must be finite")
        if np.any(np.diff(x) < 0):
            raise ValueError("terrain points: x must be non-decreasing (equal x = a vertical face)")
        if x.size >= 3 and np.any((x[2:] == x[1:-1]) & (x[1:-1] == x[:-2])):
            raise ValueError("terrain points: at most two vertices may share an x")
        if x.size == 2 and x[0] == x[1]:
            raise ValueError("terrain points: a single vertical face is not a terrain")
        self.xs = x
        self.ys = y
        self.xs.flags.writeable = False
        self.ys.flags.writeable = False
        self.spec = spec

    # ------------------------------------------------------------------ constructors
    @classmethod
    def flat(cls, height: float = 0.0) -> Terrain:
        """Level ground at ``height`` [m]."""
        h = _finite("height", height)
        return cls([0.0, 1.0], [h, h], {"kind": "flat", "height": h})

    @classmethod
    def slope(cls, angle: float, height: float = 0.0) -> Terrain:
        """Constant slope of ``angle`` [rad] (positive uphill in +x, negative downhill).

        ``height`` is the ground height at ``x = 0``; ``|angle|`` must be below 0.5 rad.
        """
        a = _finite("angle", angle)
        if abs(a) >= 0.5:
            raise ValueError(f"terrain field 'angle' = {a} out of range; allowed (-0.5, 0.5) rad")
        h = _finite("height", height)
        return cls([0.0, 1.0], [h, h + math.tan(a)], {"kind": "slope", "angle": a, "height": h})

    @classmethod
    def stairs(cls, edges: Sequence[float], rises: Sequence[float], height: float = 0.0) -> Terrain:
        """Level treads separated by vertical risers.

        Args:
            edges: x positions [m] of the risers, strictly increasing.
            rises: height change [m] at each riser (negative for a step down).
            height: ground height [m] before the first riser.
        """
        _count("edges", edges, MAX_VERTICES // 2 - 1)
        e = [_finite("edges", v) for v in edges]
        r = [_finite("rises", v) for v in rises]
        if len(e) != len(r):
            raise ValueError(f"terrain 'edges' and 'rises' differ in length: {len(e)}, {len(r)}")
        if any(b <= a for a, b in zip(e, e[1:])):
            raise ValueError("terrain field 'edges' must be strictly increasing")
        h = _finite("height", height)
        xs, ys = _steps_to_points(e, r, h)
        spec = {"kind": "stairs", "edges": e, "rises": r, "height": h}
        return cls(xs, ys, spec)

    @classmethod
    def staircase(
        cls, start: float, count: int, width: float, rise: float, height: float = 0.0
    ) -> Terrain:
        """``count`` equal stairs of tread ``width`` [m] and ``rise`` [m], the first riser at
        ``start`` [m], on ground of ``height`` [m] before it."""
        top = MAX_VERTICES // 2 - 1
        try:
            integral = int(count) == count
        except (TypeError, ValueError, OverflowError):
            integral = False
        if isinstance(count, bool) or not integral or not 0 <= count <= top:
            raise ValueError(f"terrain field 'count' = {count!r}; allowed: integer in [0, {top}]")
        w = _finite("width", width)
        if w <= 0:
            raise ValueError(f"terrain field 'width' = {w}; allowed: > 0 m")
        s = _finite("start", start)
        return cls.stairs([s + i * w for i in range(int(count))], [rise] * int(count), height)

    @classmethod
    def random_blocks(
        cls,
        seed: int,
        start: float = 0.5,
        length: float = 20.0,
        width_range: Sequence[float] = (0.15, 0.4),
        height_range: Sequence[float] = (-0.02, 0.02),
    ) -> Terrain:
        """Random blocks: flat ground up to ``start`` [m], then blocks of widths drawn from
        ``width_range`` [m] whose height changes by a step drawn from ``height_range`` [m] at
        each border, over ``length`` [m]; flat after. Same seed, same terrain."""
        st, ln = _finite("start", start), _length(length)
        wr = _range("width_range", width_range)
        if wr[0] <= 0:
            raise ValueError(f"terrain field 'width_range' = {width_range!r}; allowed: low > 0 m")
        hr = _range("height_range", height_range)
        # all draws at once (a course is built at every reset of the rough envs)
        n = _pieces("blocks", ln, "width_range", wr[0], 2)
        rng = np.random.default_rng(_seed(seed))
        widths = rng.uniform(wr[0], wr[1], n)
        rises = rng.uniform(hr[0], hr[1], n)
        edges = st + np.concatenate(([0.0], np.cumsum(widths[:-1])))
        keep = edges < st + ln
        edges, rises = edges[keep], rises[keep]
        if edges.size == 0:
            xs, ys = [st - 1.0, st + 1.0], [0.0, 0.0]
        else:
            after = np.cumsum(rises)
            before = after - rises
            xs = np.concatenate(([edges[0] - 1.0], np.repeat(edges, 2), [edges[-1] + 1.0]))
            ys = np.concatenate(([0.0], np.column_stack((before, after)).ravel(), [after[-1]]))
        spec = {
            "kind": "blocks",
            "seed": int(seed),
            "start": st,
            "length": ln,
            "width_range": list(wr),
            "height_range": list(hr),
        }
        return cls(xs, ys, spec)

    @classmethod
    def random_piecewise(
        cls,
        seed: int,
        start: float = 0.5,
        length: float = 20.0,
        segment_range: Sequence[float] = (0.2, 0.6),
        slope_range: Sequence[float] = (-0.1, 0.1),
    ) -> Terrain:
        """Random piecewise-linear ground: flat up to ``start`` [m], then segments of lengths
        drawn from ``segment_range`` [m] with slopes (dh/dx) from ``slope_range`` over ``length``
        [m]; flat after. Same ``seed``, same terrain."""
        st, ln = _finite("start", start), _length(length)
        sr = _range("segment_range", segment_range)
        if sr[0] <= 0:
            raise ValueError(f"terrain field 'segment_range' = {segment_range!r}; allowed: low > 0")
        kr = _range("slope_range", slope_range)
        if max(abs(kr[0]), abs(kr[1])) >= 1.0:
            raise ValueError(f"terrain field 'slope_range' = {slope_range!r}; allowed: |slope| < 1")
        n = _pieces("piecewise", ln, "segment_range", sr[0], 1)
        rng = np.random.default_rng(_seed(seed))
        dx = rng.uniform(sr[0], sr[1], n)
        k = rng.uniform(kr[0], kr[1], n)
        x = st + np.cumsum(dx)
        m = int(np.searchsorted(x, st + ln, side="left")) + 1  # first vertex at or past the end
        x, y = x[:m], np.cumsum(dx[:m] * k[:m])
        xs = np.concatenate(([st - 1.0, st], x, [x[-1] + 1.0]))
        ys = np.concatenate(([0.0, 0.0], y, [y[-1]]))
        spec = {
            "kind": "piecewise",
            "seed": int(seed),
            "start": st,
            "length": ln,
            "segment_range": list(sr),
            "slope_range": list(kr),
        }
        return cls(xs, ys, spec)

    @classmethod
    def from_points(cls, xs: Sequence[float], ys: Sequence[float]) -> Terrain:
        """Any polyline through the vertices ``(xs, ys)`` [m]; equal consecutive ``x`` make a
        vertical face."""
        t = cls(xs, ys, {})
        t.spec = {"kind": "points", "xs": t.xs.tolist(), "ys": t.ys.tolist()}
        return t

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        """Plain-dict spec; :meth:`from_dict` rebuilds this terrain exactly (a spec given with
        its own ``xs``, ``ys`` keeps them)."""
        d = dict(self.spec)
        if d["kind"] in ("blocks", "piecewise"):
            # random courses also carry their vertices, so a replay never depends on the RNG
            d["xs"], d["ys"] = self.xs.tolist(), self.ys.tolist()
        return d

    @classmethod
    def from_dict(cls, spec: dict[str, Any] | Terrain) -> Terrain:
        """Build a terrain from a spec dict (``{"kind": ..., ...}``); see :data:`KINDS`."""
        if isinstance(spec, Terrain):
            return spec
        if not isinstance(spec, dict) or "kind" not in spec:
            raise ValueError(f"terrain spec must be a dict with a 'kind' in {KINDS}, got {spec!r}")
        d = dict(spec)
        kind = d.pop("kind")
        builders = {
            "flat": cls.flat,
            "slope": cls.slope,
            "stairs": cls.stairs,
            "blocks": cls.random_blocks,
            "piecewise": cls.random_piecewise,
            "points": cls.from_points,
        }
        if kind not in builders:
            raise ValueError(f"unknown terrain kind {kind!r}; allowed: {list(KINDS)}")
        xs, ys = d.pop("xs", None), d.pop("ys", None)
        try:
            if kind == "points":
                return cls.from_points(xs, ys)
            t = builders[kind](**d)
        except TypeError as exc:
            raise ValueError(f"bad fields for terrain kind {kind!r}: {exc}") from None
        if xs is not None or ys is not None:
            if xs is None or ys is None:
                raise ValueError(f"terrain kind {kind!r}: give both 'xs' and 'ys', or neither")
            t = cls(xs, ys, t.spec)
            # the polyline replaces the kind's: the spec keeps it, so to_dict round-trips
            t.spec = {**t.spec, "xs": t.xs.tolist(), "ys": t.ys.tolist()}
        return t

    def to_yaml(self, path: str | Path) -> None:
        """Write the spec (:meth:`to_dict`) to the YAML file at ``path``."""
        with open(path, "w") as fh:
            yaml.safe_dump(self.to_dict(), fh, sort_keys=False)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Terrain:
        """Read a spec from the YAML file at ``path`` (see :meth:`from_dict`)."""
        return cls.from_dict(_read_spec(path))

    # ------------------------------------------------------------------ queries
    @property
    def kind(self) -> str:
        """The kind of terrain (one of :data:`KINDS`)."""
        return self.spec["kind"]

    def height(self, x: float | np.ndarray) -> float | np.ndarray:
        """Ground height [m] at ``x`` [m] (scalar or array); the upper height on a face."""
        n = self.xs.size
        if np.ndim(x) == 0:
            return float(terrain_height(self.xs, self.ys, n, float(x)))
        xa = np.ascontiguousarray(x, dtype=np.float64)
        return terrain_heights(self.xs, self.ys, xa.ravel()).reshape(xa.shape)

    def slope_at(self, x: float) -> float:
        """Ground slope ``dh/dx`` of the segment under ``x`` [m] (the one to the right on a
        vertex)."""
        return float(terrain_slope(self.xs, self.ys, self.xs.size, float(x)))

    def vertical_faces(self) -> list[tuple[float, float, float]]:
        """Vertical faces as ``(x, y_before, y_after)`` [m] in order of ``x``."""
        idx = np.nonzero(np.diff(self.xs) == 0)[0]
        return [(float(self.xs[i]), float(self.ys[i]), float(self.ys[i + 1])) for i in idx]

    def edges(self) -> np.ndarray:
        """x positions [m] of all features: vertical faces and kinks of the profile."""
        x, y = self.xs, self.ys
        if x.size < 3:
            return np.zeros(0)
        dx, dy = np.diff(x), np.diff(y)
        out = []
        for k in range(1, x.size - 1):
            if dx[k] == 0 or dx[k - 1] == 0:
                out.append(x[k])
            elif not math.isclose(dy[k] / dx[k], dy[k - 1] / dx[k - 1], abs_tol=1e-12):
                out.append(x[k])
        return np.unique(np.asarray(out, dtype=np.float64))

    def next_edge(self, x: float) -> float:
        """x [m] of the first feature (face or kink) strictly ahead of ``x``; ``inf`` if none."""
        e = self.edges()
        e = e[e > x]
        return float(e[0]) if e.size else math.inf

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertex arrays ``(xs, ys)`` [m] (read-only) for compiled kernels."""
        return self.xs, self.ys

    def __repr__(self) -> str:
        return f"Terrain({self.spec.get('kind')}, {self.xs.size} vertices)"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Terrain)
            and np.array_equal(self.xs, other.xs)
            and np.array_equal(self.ys, other.ys)
        )

    __hash__ = None  # type: ignore[assignment]


def available_terrains() -> list[str]:
    """Names of the courses shipped in ``configs/terrains`` (usable wherever a terrain is)."""
    return sorted(p.stem for p in TERRAIN_CONFIG_DIR.glob("*.yaml"))


def terrain_spec(
    terrain: Terrain | dict[str, Any] | str | os.PathLike,
) -> Terrain | dict[str, Any]:
    """Resolve a terrain argument: the one meaning of a terrain given by name.

    A :class:`Terrain` is returned as it is, a spec dict as a deep copy. A string (or path) is,
    in this order:

    1. the name of a course shipped in ``configs/terrains`` (:func:`available_terrains`);
    2. a path to a YAML spec file (ending in ``.yaml`` or ``.yml``);
    3. a kind with default fields (:data:`NAMED_KINDS`): ``"flat"`` (height 0), ``"slope"``
       (angle 0), ``"blocks"`` or ``"piecewise"`` (random, without a seed).

    ``"flat"`` is both a shipped course and a kind, with the same meaning (level ground at
    height 0). Returns the :class:`Terrain` or the spec dict (built by :func:`as_terrain`, or
    drawn from by :class:`envs.task.TerrainSource` when it is a seedless random kind).

    Raises:
        ValueError: an unknown name or a missing file (the message lists what is allowed), or
            a value that is none of the above.
    """
    if isinstance(terrain, Terrain):
        return terrain
    if isinstance(terrain, dict):
        return copy.deepcopy(terrain)
    if not isinstance(terrain, (str, os.PathLike)):
        raise ValueError(
            f"terrain must be a Terrain, a spec dict or a name, got {type(terrain).__name__}"
        )
    name = os.fspath(terrain)
    shipped = TERRAIN_CONFIG_DIR / f"{name}.yaml"
    if shipped.is_file():
        return _read_spec(shipped)
    if name.endswith(_YAML_SUFFIXES):
        if not Path(name).is_file():
            raise ValueError(f"terrain file {name!r} does not exist")
        return _read_spec(name)
    if name in NAMED_KINDS:
        return {"kind": name, "angle": 0.0} if name == "slope" else {"kind": name}
    raise ValueError(
        f"unknown terrain {name!r}; allowed: a course in configs/terrains "
        f"{available_terrains()}, a path to a YAML spec file, a kind with default fields "
        f"{list(NAMED_KINDS)}, a spec dict or an envs.Terrain"
    )


def as_terrain(spec: Terrain | dict[str, Any] | str | os.PathLike) -> Terrain:
    """A :class:`Terrain` from a Terrain, a spec dict or a name (resolved by
    :func:`terrain_spec`); a random kind needs its ``seed``."""
    if isinstance(spec, Terrain):
        return spec
    if not isinstance(spec, dict):
        spec = terrain_spec(spec)
    if isinstance(spec, dict) and spec.get("kind") in SEEDED_KINDS and "seed" not in spec:
        raise ValueError(
            f"terrain kind {spec['kind']!r} is random and needs a seed: pass a spec dict with "
            "'seed' (an env's terrain may omit it: a new course is drawn at every reset)"
        )
    return Terrain.from_dict(spec)


def _read_spec(path: str | os.PathLike) -> dict[str, Any]:
    """The spec dict in the YAML file ``path``."""
    return read_yaml_mapping(path, "terrain", allow_empty=False, holds="spec mapping")


def _length(value: Any) -> float:
    """The ``length`` [m] of a random course, checked against :data:`MAX_COURSE_LENGTH`."""
    ln = _finite("length", value)
    if not 0 <= ln <= MAX_COURSE_LENGTH:
        raise ValueError(
            f"terrain field 'length' = {ln!r} out of range; allowed: [0, {MAX_COURSE_LENGTH:g}] m"
        )
    return ln


def _pieces(kind: str, length: float, field: str, shortest: float, per_piece: int) -> int:
    """Number of random pieces drawn for a course of ``length`` [m] whose pieces are at least
    ``shortest`` [m] long, checked so that the course stays within :data:`MAX_VERTICES`."""
    pieces = length / shortest + 1.0
    if per_piece * pieces + 2 > MAX_VERTICES:
        raise ValueError(
            f"terrain kind {kind!r}: 'length' = {length:g} m over pieces of at least "
            f"{field}[0] = {shortest:g} m makes up to {per_piece * pieces + 2:.4g} vertices; "
            f"allowed: at most {MAX_VERTICES} (shorten 'length' or lengthen '{field}')"
        )
    return int(math.ceil(length / shortest)) + 1


def _count(name: str, values: Any, top: int) -> None:
    """Reject a sequence field with more than ``top`` entries (before converting them)."""
    try:
        size = len(values)
    except TypeError:
        raise ValueError(f"terrain field {name!r} must be a list of numbers") from None
    if size > top:
        raise ValueError(f"terrain field {name!r} has {size} entries; allowed: at most {top}")


def _seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"terrain field 'seed' = {seed!r}; allowed: integer >= 0")
    return int(seed)


def _steps_to_points(
    edges: Sequence[float], rises: Sequence[float], h0: float
) -> tuple[list[float], list[float]]:
    xs, ys = [(edges[0] if edges else 0.0) - 1.0], [h0]
    h = h0
    for e, r in zip(edges, rises):
        xs.append(e)
        ys.append(h)
        if r != 0.0:
            h += r
            xs.append(e)
            ys.append(h)
    xs.append((edges[-1] if edges else 0.0) + 1.0)
    ys.append(h)
    return xs, ys
