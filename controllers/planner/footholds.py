"""Footholds: the terrain as the planner sees it, the foothold rules, the candidate footholds of
one step, and the search for chains of admissible footholds over the horizon.

The map is either the true :class:`envs.physics.Terrain` or heights sampled by a terrain scanner
(:meth:`TerrainMap.from_scan`). Footholds keep a margin from vertical faces (stair edges, block
borders) and kinks, give step lengths within bounds, and lie within the reach of the legs
(inter-leg angle at touchdown within bounds). A step's candidates are ranked so that those from
which a chain of admissible footholds goes on for the rest of the horizon (up to three steps)
come first, also when the actual touchdown lands a few millimetres off (on stairs the footholds
form narrow windows; one on the border of its window leaves no next step after a small miss).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from envs.physics import model
from envs.physics.model import touchdown_configuration
from envs.physics.terrain import Terrain, as_terrain, terrain_height

__all__ = [
    "FootholdChains",
    "FootholdRules",
    "TerrainMap",
    "candidate_footholds",
    "touchdown_configuration",
]

_CHAIN_DEPTH = 3  # footholds looked ahead when ranking candidates
_CHAIN_STRIDE = 4  # candidates tried first when looking for a chain (then all of them)
_LANDING_SLACK = np.array([0.008, 0.004])  # touchdown errors a foothold chain should tolerate [m]
_MEMO_LIMIT = 65536  # entries of a foothold memo before it is cleared
_MEMO_TERRAINS = 4  # terrains whose chain lengths are kept
_UNRANKED = 2**62  # sorts a candidate not ranked after every ranked one


def polyline_key(xs: np.ndarray, ys: np.ndarray) -> bytes:
    """A terrain polyline ``xs, ys`` [m] as bytes (:attr:`TerrainMap.key`)."""
    return xs.tobytes() + ys.tobytes()


class TerrainMap:
    """Terrain as the planner sees it: vectorised heights and the features to keep away from.

    Args:
        terrain: a :class:`Terrain`, a spec dict or a name (resolved by
            :func:`envs.physics.terrain.as_terrain`).
    """

    def __init__(self, terrain: Terrain | dict | str):
        self.terrain = as_terrain(terrain)
        self.xs, self.ys = self.terrain.arrays()
        self.features = self.terrain.edges()
        self.faces = self.terrain.vertical_faces()
        self._face_arr = np.array(self.faces, dtype=np.float64).reshape(-1, 3)
        self._face_x = np.ascontiguousarray(self._face_arr[:, 0])

    @classmethod
    def from_scan(
        cls, xs: Sequence[float], heights: Sequence[float], jump: float = 1e-3
    ) -> TerrainMap:
        """Map from scanned heights ``heights[k]`` [m] at increasing positions ``xs[k]`` [m].

        Between samples whose heights differ by more than ``jump`` [m] a vertical face is placed
        half-way; elsewhere the ground is linear between samples.
        """
        x = np.asarray(xs, dtype=np.float64)
        h = np.asarray(heights, dtype=np.float64)
        if x.ndim != 1 or x.shape != h.shape or x.size < 2:
            raise ValueError("terrain scan: xs and heights must be 1-D of equal length >= 2")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(h))):
            raise ValueError("terrain scan: xs and heights must be finite (no NaN)")
        if np.any(np.diff(x) <= 0):
            raise ValueError("terrain scan: xs must be strictly increasing")
        px, py = [x[0]], [h[0]]
        for k in range(1, x.size):
            if abs(h[k] - h[k - 1]) > jump:
                xm = 0.5 * (x[k - 1] + x[k])
                px += [xm, xm]
                py += [h[k - 1], h[k]]
            px.append(x[k])
            py.append(h[k])
        return cls(Terrain.from_points(px, py))

    @classmethod
    def coerce(cls, terrain: TerrainMap | Terrain | dict | str | tuple) -> TerrainMap:
        """A :class:`TerrainMap` from a map, a scan ``(xs, heights)`` [m] (:meth:`from_scan`), or
        anything :func:`envs.physics.terrain.as_terrain` resolves (a terrain, a spec dict, a
        name)."""
        if isinstance(terrain, TerrainMap):
            return terrain
        if isinstance(terrain, tuple) and len(terrain) == 2:
            return cls.from_scan(*terrain)
        return cls(terrain)

    @functools.cached_property
    def key(self) -> bytes:
        """The map's polyline as bytes: equal keys, equal terrain (the planner's memo key)."""
        return polyline_key(self.xs, self.ys)

    def height(self, x: np.ndarray | float) -> np.ndarray | float:
        """Ground height [m] at ``x`` [m] (the upper height on a vertical face)."""
        return self.terrain.height(x)

    def distance_to_feature(self, x: np.ndarray) -> np.ndarray:
        """Distance [m] from each ``x`` to the nearest face or kink (``inf`` if none)."""
        x = np.asarray(x, dtype=np.float64)
        if self.features.size == 0:
            return np.full(x.shape, np.inf)
        i = np.searchsorted(self.features, x)
        left = self.features[np.clip(i - 1, 0, self.features.size - 1)]
        right = self.features[np.clip(i, 0, self.features.size - 1)]
        return np.minimum(np.abs(x - left), np.abs(right - x))

    def faces_between(self, x0: float, x1: float) -> list[tuple[float, float]]:
        """Vertical faces strictly between ``x0`` and ``x1`` as ``(x, top height)``."""
        return [(x, max(a, b)) for x, a, b in self.faces_within(x0, x1) if x0 < x < x1]

    def faces_within(self, x0: float, x1: float) -> list[tuple[float, float, float]]:
        """Vertical faces ``(x, y_before, y_after)`` with ``x0 <= x <= x1`` [m], in order."""
        i = int(np.searchsorted(self._face_x, x0, side="left"))
        j = int(np.searchsorted(self._face_x, x1, side="right"))
        return self.faces[i:j]


@dataclass(frozen=True)
class FootholdRules:
    """Geometric rules for footholds (lengths in m, angles in rad).

    Attributes:
        step_length: preferred horizontal step length [m].
        step_min, step_max: bounds on the horizontal step length [m].
        edge_margin: least distance of a foothold from a face or kink [m].
        q1_min, q1_max: bounds on the inter-leg angle at touchdown [rad].
        max_rise, max_drop: largest height gain / loss of one step [m].
        resolution: spacing of the candidate footholds [m].
        drop_margin: extra distance per metre of drop between a foothold and a step-down riser
            behind it, so that the next swing's retracted foot clears the riser [m/m].
        rise_margin: extra distance per metre of rise between a foothold and a step-up riser
            ahead of it, so that the next swing foot clears the riser [m/m].
        drop_edge_margin: a foothold closer than ``edge_margin + drop_edge_margin`` to a
            step-down riser, ahead of it or behind it, ranks after every candidate that is not
            (a preference, not a rule) [m]: a swing foot that lands off its plan (a leg longer
            or shorter than the model's, a foot estimated off) passes such a riser and comes
            back into its face.
    """

    step_length: float
    step_min: float
    step_max: float
    edge_margin: float
    q1_min: float
    q1_max: float
    max_rise: float
    max_drop: float
    resolution: float = 0.002
    drop_margin: float = 4.0
    rise_margin: float = 4.0
    drop_edge_margin: float = 0.0

    def __post_init__(self) -> None:
        for name in ("step_length", "step_min", "step_max", "q1_min", "q1_max", "resolution"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"FootholdRules.{name} = {v!r}; allowed: finite > 0")
        for name in (
            "edge_margin", "max_rise", "max_drop", "drop_margin", "rise_margin",
            "drop_edge_margin",
        ):  # fmt: skip
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"FootholdRules.{name} = {v!r}; allowed: finite >= 0")
        if not self.step_min <= self.step_length <= self.step_max:
            raise ValueError(
                f"FootholdRules: need step_min <= step_length <= step_max, got "
                f"{self.step_min}, {self.step_length}, {self.step_max}"
            )
        if not self.q1_min < self.q1_max < math.pi:
            raise ValueError(
                f"FootholdRules: need q1_min < q1_max < pi, got {self.q1_min}, {self.q1_max}"
            )


def candidate_footholds(
    tmap: TerrainMap,
    stance: tuple[float, float],
    rules: FootholdRules,
    l: float,
    theta_target: float | None = None,
    sigma_target: float | None = None,
) -> tuple[np.ndarray, np.ndarray, str]:
    """Admissible footholds for the next step, best first.

    Args:
        tmap: terrain map.
        stance: stance-foot position ``(x, y)`` [m].
        rules: foothold rules.
        l: leg length [m].
        theta_target: preferred stance-leg angle at touchdown [rad]; when given, candidates
            are ranked by how close their touchdown ``q2`` is to it (this keeps the phase range
            of every step near the nominal one: longer steps after a step down), else by the
            distance from the preferred step length.
        sigma_target: preferred swing-leg angle ``q2 - q1`` at touchdown [rad] (the next
            step's start phase), added to the ranking with ``theta_target``.

    Returns:
        ``(x, y, reason)``: candidate foothold coordinates [m], best first (empty if none),
        and why candidates were rejected when empty.
    """
    return _candidate_footholds(
        tmap, stance, rules, _rules_array(rules), l, theta_target, sigma_target
    )


def _candidate_footholds(
    tmap: TerrainMap,
    stance: tuple[float, float],
    rules: FootholdRules,
    R: np.ndarray,
    l: float,  # noqa: E741
    theta_target: float | None,
    sigma_target: float | None,
) -> tuple[np.ndarray, np.ndarray, str]:
    """:func:`candidate_footholds` with the rules also as :func:`_rules_array` gives them."""
    mode = 0 if theta_target is None else (1 if sigma_target is None else 2)
    x, y, seen = _rule_table(
        float(stance[0]), float(stance[1]), R, tmap.xs, tmap.ys, tmap.features, tmap._face_arr,
        float(l), math.nan if theta_target is None else float(theta_target),
        math.nan if sigma_target is None else float(sigma_target), mode,
    )  # fmt: skip
    if x.size:
        return x, y, ""
    any_edge, any_height, any_reach, dh_min, dh_max = seen
    reasons = []
    if not any_edge:
        reasons.append(f"no ground {rules.edge_margin} m away from an edge")
    if not any_height:
        reasons.append(
            f"height change outside [-{rules.max_drop}, {rules.max_rise}] m "
            f"(range seen {dh_min:.3g} .. {dh_max:.3g} m)"
        )
    if not any_reach:
        reasons.append(f"inter-leg angle at touchdown outside [{rules.q1_min}, {rules.q1_max}]")
    return (
        np.zeros(0),
        np.zeros(0),
        "no admissible foothold within step length "
        f"[{rules.step_min}, {rules.step_max}] m: " + "; ".join(reasons or ["rules"]),
    )


class FootholdChains:
    """Chains of admissible footholds ahead of a stance foot (geometric foothold rules only), and
    the ranking of a step's candidate footholds by the chains they leave open.

    Chain lengths and the footholds from a stance foot are memoised per terrain (by
    :attr:`TerrainMap.key`) at 1 mm for the life of the object.

    Args:
        rules: the foothold rules.
        l: leg length [m].
        spacing: least spacing between the footholds a step tries [m].
        relaxed: the rules a step falls back on where ``rules`` leave its stance foot no
            admissible foothold (:meth:`PlannerConfig.relaxed_rules`), or None; the chains
            that rank its candidates still follow ``rules``.
    """

    def __init__(
        self,
        rules: FootholdRules,
        l: float,  # noqa: E741
        spacing: float,
        relaxed: FootholdRules | None = None,
    ):
        self.rules = rules
        self.relaxed = relaxed
        self.l = l
        self.spacing = spacing
        self.footholds: dict[tuple, tuple[np.ndarray, str]] = {}  # see chain_footholds()
        self._rules_arr = _rules_array(rules)
        self._relaxed_arr = _rules_array(relaxed if relaxed is not None else rules)
        # chain lengths by terrain: (first position [mm], lengths [position, depth, relaxed],
        # -1 where not known yet), see reach()
        self._lengths: dict[bytes, tuple[int, np.ndarray]] = {}

    def ranked(
        self,
        tmap: TerrainMap,
        stance: tuple[float, float],
        theta_target: float,
        sigma_target: float,
        depth: int,
        warm_x: float | None,
        need: int,
    ) -> tuple[np.ndarray, np.ndarray, list[int], str]:
        """Candidate footholds from ``stance`` [m] ranked as :func:`candidate_footholds` does
        (with ``theta_target`` and ``sigma_target`` [rad]), with those from which a chain of
        ``depth`` more admissible footholds exists first, and among them those that keep such a
        chain when the foot lands further off (``_LANDING_SLACK``; on stairs the admissible
        footholds form narrow windows; a foothold on the edge of its window leaves no next step
        once the actual touchdown misses it by a millimetre).

        Returns ``(x, y, picks, reason)``: ``picks`` are the indices of the footholds the search
        tries, in order: the first one within the candidate resolution of ``warm_x`` [m], then
        candidates at least ``spacing`` from those picked, in list order, up to ``need``.
        Candidates are ranked only until the picks are settled; the rest follow unranked, in
        the order of :func:`candidate_footholds`.

        Where ``rules`` give no candidate and ``relaxed`` rules do, those are ranked instead
        and ``reason`` says so (it is empty otherwise when candidates exist)."""
        rules, l = self.rules, self.l  # noqa: E741
        cx, cy, why, relaxed = self._admissible(tmap, stance, True, theta_target, sigma_target)
        if relaxed:
            why = (
                f"riser margins relaxed to {self.relaxed.drop_margin:g} / "
                f"{self.relaxed.rise_margin:g} m/m: {why}"
            )
        depth = min(int(depth), _CHAIN_DEPTH)
        # without a face or kink within reach every candidate continues alike (smooth ground)
        reach = stance[0] + (depth + 1) * rules.step_max + max(_LANDING_SLACK) + 2.0 * l
        f = tmap.features  # (sorted)
        first_ahead = int(np.searchsorted(f, stance[0] - rules.step_max, side="right"))
        ranked = depth > 0 and first_ahead < f.size and f[first_ahead] < reach
        k0, memo = self._memo(tmap, depth)
        order, picks = _ranked_order(
            cx, math.nan if warm_x is None else float(warm_x), rules.resolution, int(need),
            float(self.spacing), depth, bool(ranked), memo, k0, self._rules_arr,
            self._relaxed_arr, tmap.xs, tmap.ys, tmap.features, tmap._face_arr, float(self.l),
        )  # fmt: skip
        return cx[order], cy[order], [int(k) for k in picks], why

    def landing_rank(self, tmap: TerrainMap, x: float, depth: int) -> int:
        """0 if a chain of ``depth`` footholds continues from ``x`` [m] however far the foot
        lands off by up to the largest ``_LANDING_SLACK``, 1 for the next smaller slack, ...,
        ``len(_LANDING_SLACK)`` with no slack, one more without any chain."""
        k0, memo = self._memo(tmap, depth)
        return int(
            _landing_rank(
                float(x), depth, memo, k0, self._rules_arr, self._relaxed_arr, tmap.xs, tmap.ys,
                tmap.features, tmap._face_arr, float(self.l),
            )
        )  # fmt: skip

    def chain(self, tmap: TerrainMap, x: float, depth: int) -> bool:
        """Whether ``depth`` consecutive admissible footholds exist from a stance foot at ``x``
        [m]."""
        return self.reach(tmap, x, depth) >= depth

    def _admissible(
        self,
        tmap: TerrainMap,
        stance: tuple[float, float],
        relaxed: bool,
        theta_target: float | None = None,
        sigma_target: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, str, bool]:
        """:func:`candidate_footholds` under the rules, or, with ``relaxed``, under the
        relaxed rules where the rules give none; the last item says whether those were used
        (``reason`` is then the rules' one)."""
        args = (self.l, theta_target, sigma_target)
        cx, cy, why = _candidate_footholds(tmap, stance, self.rules, self._rules_arr, *args)
        if cx.size == 0 and relaxed and self.relaxed is not None:
            rx, ry, _ = _candidate_footholds(tmap, stance, self.relaxed, self._relaxed_arr, *args)
            if rx.size:
                return rx, ry, why, True
        return cx, cy, why, False

    def chain_footholds(
        self, tmap: TerrainMap, x: float, relaxed: bool = False
    ) -> tuple[np.ndarray, str]:
        """Admissible footholds from a stance foot at ``x`` [m] rounded to 1 mm, and why there are
        none when empty; with ``relaxed``, those of the relaxed rules where the rules give
        none."""
        xr = round(float(x), 3)
        key = (tmap.key, xr, relaxed and self.relaxed is not None)
        hit = self.footholds.get(key)
        if hit is None:
            cx, _, why, _ = self._admissible(tmap, (xr, float(tmap.height(xr))), relaxed)
            if len(self.footholds) > _MEMO_LIMIT:
                self.footholds.clear()
            hit = self.footholds[key] = (cx, why)
        return hit

    def reach(self, tmap: TerrainMap, x: float, depth: int, relaxed: bool = False) -> int:
        """How many consecutive admissible footholds (at most ``depth``) a chain from a stance
        foot at ``x`` [m] can have (``relaxed``: a step may take the relaxed rules' footholds
        where the rules give none, as the search does)."""
        if depth <= 0:
            return 0
        relaxed = relaxed and self.relaxed is not None  # without relaxed rules: the same chains
        k0, memo = self._memo(tmap, depth)
        k = _millimetres(float(x)) - k0
        if 0 <= k < memo.shape[0]:
            hit = memo[k, depth, int(relaxed)]
            if hit >= 0:
                return int(hit)
        return int(
            _chain_reach(
                k, depth, int(relaxed), memo, k0, self._rules_arr, self._relaxed_arr, tmap.xs,
                tmap.ys, tmap.features, tmap._face_arr, float(self.l),
            )
        )  # fmt: skip

    def _memo(self, tmap: TerrainMap, depth: int) -> tuple[int, np.ndarray]:
        """The chain lengths known on ``tmap`` (see :meth:`reach`), with room for ``depth``."""
        hit = self._lengths.get(tmap.key)
        if hit is None or hit[1].shape[1] <= depth:
            if hit is None and len(self._lengths) >= _MEMO_TERRAINS:
                self._lengths.clear()
            # stance feet from the map's start to a horizon's steps past its end
            k0 = math.floor(float(tmap.xs[0]) * 1000) - 1000
            k1 = math.ceil(float(tmap.xs[-1]) * 1000) + 1000 + 1000 * _CHAIN_DEPTH
            size = max(depth, 2 * _CHAIN_DEPTH) + 1
            hit = self._lengths[tmap.key] = (k0, np.full((k1 - k0, size, 2), -1, np.int8))
        return hit

    def reach_break(self, tmap: TerrainMap, x: float, depth: int, relaxed: bool = False) -> str:
        """Why the longest chain of footholds from ``x`` [m] ends (see :meth:`reach`)."""
        while True:
            cx, why = self.chain_footholds(tmap, x, relaxed)
            if cx.size == 0:
                return f"from a stance foot at x = {x:.3f} m: {why}"
            if depth <= 0:
                return ""  # the chain spans ``depth`` footholds: it does not end
            depth -= 1
            x = float(max(cx, key=lambda c: self.reach(tmap, float(c), depth, relaxed)))


@njit(cache=True, error_model="numpy")
def _foothold_table(
    x0, y0, n, step_min, res, tx, ty, features, faces, edge_margin, drop_margin, rise_margin,
    drop_edge_margin, max_rise, max_drop, q1_min, q1_max, l, step_length, theta_target,
    sigma_target, mode,
):  # fmt: skip
    """The admissible footholds among ``x0 + step_min + res * k`` (``x, y`` best first) and what
    was seen: whether any candidate is away from edges, also within the height bounds, also
    within reach, and the range of height changes (see :func:`candidate_footholds`; ``mode`` 0
    ranks by step length, 1 adds ``theta_target``, 2 also ``sigma_target``)."""
    x = np.empty(n)
    y = np.empty(n)
    dh = np.empty(n)
    score = np.empty(n)
    ok_edge = np.empty(n, dtype=np.bool_)
    ok_h = np.empty(n, dtype=np.bool_)
    ok_reach = np.empty(n, dtype=np.bool_)
    nt, nf = tx.size, features.size
    far = max(rise_margin * max_rise, drop_edge_margin)
    reach = x0 + step_min + res * (n - 1) + edge_margin + far
    # the faces with x0 <= x <= reach (the faces come in order of x)
    f0 = np.searchsorted(faces[:, 0], x0, side="left")
    f1 = np.searchsorted(faces[:, 0], reach, side="right")
    for k in range(n):
        xk = x0 + step_min + res * k
        yk = terrain_height(tx, ty, nt, xk)
        d = yk - y0
        x[k], y[k], dh[k] = xk, yk, d
        # distance to the nearest face or kink
        near = np.inf
        if nf > 0:
            i = np.searchsorted(features, xk)
            left = features[min(max(i - 1, 0), nf - 1)]
            right = features[min(max(i, 0), nf - 1)]
            near = min(abs(xk - left), abs(right - xk))
        ok = near >= edge_margin
        demote = False
        for f in range(f0, f1):
            xf, ya, yb = faces[f, 0], faces[f, 1], faces[f, 2]
            if x0 < xf and ya > yb:  # a step down between the stance foot and the candidate
                ok = ok and (xk <= xf or xk - xf >= edge_margin + drop_margin * (ya - yb))
            if 0 < yb - ya <= max_rise:  # a step up ahead of the candidate (not a wall)
                ok = ok and (xk >= xf or xf - xk >= edge_margin + rise_margin * (yb - ya))
            if ya > yb and abs(xf - xk) < edge_margin + drop_edge_margin:
                demote = True  # a step down just ahead of the candidate or just behind it
        ok_edge[k] = ok
        ok_h[k] = d <= max_rise and d >= -max_drop
        dx = xk - x0
        q1, q2 = model.touchdown_configuration(dx, d, l)
        ok_reach[k] = q1 >= q1_min and q1 <= q1_max
        if mode == 0:
            score[k] = abs(dx - step_length)
        else:
            score[k] = abs(q2 - theta_target) + 0.1 * abs(dx - step_length) / l
            if mode == 2:
                score[k] += 2.0 * abs(q2 - q1 - sigma_target)
        if demote:
            score[k] += 100.0  # ranked after every candidate clear of such a riser
    # admissible candidates by score, ties in order of x (a stable sort)
    keep = np.nonzero(ok_edge & ok_h & ok_reach)[0]
    order = keep[np.argsort(score[keep], kind="mergesort")]
    m = order.size
    seen = np.zeros(5)
    seen[0] = 1.0 if np.any(ok_edge) else 0.0
    seen[1] = 1.0 if np.any(ok_edge & ok_h) else 0.0
    seen[2] = 1.0 if np.any(ok_edge & ok_reach) else 0.0
    seen[3], seen[4] = dh.min(), dh.max()
    return x[order[:m]], y[order[:m]], seen


def _rules_array(rules: FootholdRules) -> np.ndarray:
    """The rules as :func:`_chain_reach` takes them."""
    n = int(math.floor((rules.step_max - rules.step_min) / rules.resolution)) + 1
    return np.array(
        [
            n, rules.step_min, rules.resolution, rules.edge_margin, rules.drop_margin,
            rules.rise_margin, rules.drop_edge_margin, rules.max_rise, rules.max_drop,
            rules.q1_min, rules.q1_max, rules.step_length,
        ],
        dtype=np.float64,
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _rule_table(x0, y0, R, tx, ty, features, faces, l, theta_target, sigma_target, mode):
    """:func:`_foothold_table` from the stance foot ``(x0, y0)`` [m] under the rules ``R``
    (:func:`_rules_array`)."""
    return _foothold_table(
        x0, y0, int(R[0]), R[1], R[2], tx, ty, features, faces, R[3], R[4], R[5], R[6], R[7],
        R[8], R[9], R[10], l, R[11], theta_target, sigma_target, mode,
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _chain_table(x, R, tx, ty, features, faces, l):
    """The admissible footholds from a stance foot at ``x`` [m] under the rules ``R``
    (:func:`_rules_array`), ranked by step length (:func:`candidate_footholds`)."""
    y = terrain_height(tx, ty, tx.size, x)
    cx, _, _ = _rule_table(x, y, R, tx, ty, features, faces, l, math.nan, math.nan, 0)
    return cx


@njit(cache=True, error_model="numpy")
def _millimetres(x):
    """``x`` [m] rounded to whole millimetres: where the chain lengths are kept."""
    return int(np.round(x * 1000.0))


@njit(cache=True, error_model="numpy")
def _chain_reach(k, depth, relaxed, memo, k0, rules, relaxed_rules, tx, ty, features, faces, l):
    """:meth:`FootholdChains.reach` from the stance foot at ``(k0 + k)`` mm, memoised in
    ``memo[k, depth, relaxed]`` (positions outside ``memo`` are not kept)."""
    if depth <= 0:
        return 0
    inside = 0 <= k < memo.shape[0]
    if inside and memo[k, depth, relaxed] >= 0:
        return int(memo[k, depth, relaxed])
    x = (k0 + k) / 1000.0
    cx = _chain_table(x, rules, tx, ty, features, faces, l)
    if cx.size == 0 and relaxed == 1:
        cx = _chain_table(x, relaxed_rules, tx, ty, features, faces, l)
    best = 0
    # every _CHAIN_STRIDE-th candidate first: on passable ground one of them continues
    for p in range(2):
        step = _CHAIN_STRIDE if p == 0 else 1
        for i in range(0, cx.size, step):
            kc = _millimetres(cx[i]) - k0
            r = _chain_reach(
                kc, depth - 1, relaxed, memo, k0, rules, relaxed_rules, tx, ty, features, faces, l
            )
            best = max(best, 1 + r)
            if best >= depth:
                break
        if best >= depth:
            break
    if inside:
        memo[k, depth, relaxed] = best
    return best


@njit(cache=True, error_model="numpy")
def _landing_rank(x, depth, memo, k0, rules, relaxed_rules, tx, ty, features, faces, l):
    """:meth:`FootholdChains.landing_rank` of a foothold at ``x`` [m] (the rules' chains)."""
    args = (memo, k0, rules, relaxed_rules, tx, ty, features, faces, l)
    if _chain_reach(_millimetres(x) - k0, depth, 0, *args) < depth:
        return _LANDING_SLACK.size + 1
    r = 0
    for s in _LANDING_SLACK:  # largest landing error the chain tolerates, first
        lo = _chain_reach(_millimetres(x - s) - k0, depth, 0, *args)
        if lo >= depth and _chain_reach(_millimetres(x + s) - k0, depth, 0, *args) >= depth:
            break
        r += 1
    return r


@njit(cache=True, error_model="numpy")
def _rank_candidates(
    cx, warm_x, res, need, spacing, depth, ranked, memo, k0, rules, relaxed_rules, tx, ty,
    features, faces, l,
):  # fmt: skip
    """The ranks and first picks of :meth:`FootholdChains.ranked` (``warm_x`` NaN: none): the
    candidate within ``res`` [m] of ``warm_x`` with the best rank, then rank-0 candidates in
    list order, ranked lazily until ``need`` picks ``spacing`` [m] apart are found (ranks not
    computed stay -1; without ``ranked`` every rank is 0)."""
    n = cx.size
    rank = np.full(n, -1 if ranked else 0, dtype=np.int64)
    picks = np.empty(max(need, 0), dtype=np.int64)
    args = (memo, k0, rules, relaxed_rules, tx, ty, features, faces, l)
    best = -1
    for k in range(n):  # the first match of the warm start in the ranked list
        if abs(cx[k] - warm_x) < res:
            if rank[k] < 0:
                rank[k] = _landing_rank(cx[k], depth, *args)
            if best < 0 or rank[k] < rank[best]:
                best = k
    npk = 0
    if best >= 0:
        npk = _offer(best, cx, picks, npk, need, spacing)
    for k in range(n):  # the best rank first: rank-0 candidates in list order
        if rank[k] < 0:
            rank[k] = _landing_rank(cx[k], depth, *args)
        if rank[k] == 0:
            npk = _offer(k, cx, picks, npk, need, spacing)
            if npk >= need:
                break
    return rank, picks[:npk]


@njit(cache=True, error_model="numpy")
def _ranked_order(
    cx, warm_x, res, need, spacing, depth, ranked, memo, k0, rules, relaxed_rules, tx, ty,
    features, faces, l,
):  # fmt: skip
    """The order of :meth:`FootholdChains.ranked`'s candidates (the ranked ones by rank, in
    list order within a rank, then the others in list order) and its picks as positions in
    that order: :func:`_rank_candidates`'s, then candidates in that order ``spacing`` [m]
    from the picks, up to ``need``."""
    rank, first = _rank_candidates(
        cx, warm_x, res, need, spacing, depth, ranked, memo, k0, rules, relaxed_rules, tx, ty,
        features, faces, l,
    )  # fmt: skip
    n = cx.size
    key = np.empty(n, dtype=np.int64)
    for k in range(n):
        key[k] = rank[k] if rank[k] >= 0 else _UNRANKED
    order = np.argsort(key, kind="mergesort")
    picks = np.empty(max(need, 0), dtype=np.int64)
    npk = first.size
    picks[:npk] = first
    if npk < need:
        for k in order:  # the picks not settled by the rank-0 candidates
            npk = _offer(k, cx, picks, npk, need, spacing)
            if npk >= need:
                break
    position = np.empty(n, dtype=np.int64)
    for i in range(n):
        position[order[i]] = i
    out = np.empty(npk, dtype=np.int64)
    for i in range(npk):
        out[i] = position[picks[i]]
    return order, out


@njit(cache=True, error_model="numpy")
def _offer(k, cx, picks, npk, need, spacing):
    """Pick candidate ``k`` if there is room and it is ``spacing`` [m] from the picks; the
    number of picks."""
    if npk >= need:
        return npk
    for p in range(npk):
        if not abs(cx[k] - cx[picks[p]]) >= spacing:
            return npk
    picks[npk] = k
    return npk + 1
