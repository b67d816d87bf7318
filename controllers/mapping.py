"""A terrain map built from the scanner's noisy heights as the robot walks.

Every scan (heights relative to the stance foot at known offsets ahead of it) is placed at the
estimated stance foot and fused into cells of a fixed width (the mean of the readings that fell
in a cell). The fused profile is split into level blocks: a new block starts where a cell's
height differs from the running mean of the current block by more than ``jump`` and the next
cell agrees with it (a stray cell, one reading across an edge say, belongs to no block); a
block supported by fewer than ``min_samples`` scans joins the neighbour nearest in height.
Between two blocks a vertical face is placed half-way between their last and first scanned
points, and both ends of that gap are marked as kinks of the profile, so that the planner keeps
its footholds out of the whole gap (footholds are readings too; scans of footsteps whose length
is not a multiple of the scan spacing fall at different places, so the gap narrows as the robot
comes closer). Ahead of
the last scanned point the ground is taken level at the last block's height, behind the first
one at the first block's (the planner's far steps are replanned once scanned). The result is a
:class:`envs.physics.terrain.Terrain` (``kind: points``), the form the planner's
:class:`controllers.planner.footholds.TerrainMap` takes.
"""

from __future__ import annotations

import math

import numpy as np

from envs.physics.terrain import Terrain

__all__ = ["ScanMap"]

_EXTEND = 5.0  # level ground assumed beyond the scanned stretch [m]
_TILT = 1e-5  # rise across an edge's gap that marks its ends as kinks [m]


class ScanMap:
    """Terrain map fused from terrain scans.

    Args:
        cell: width of a fusion cell [m], > 0.
        jump: least height difference between two blocks [m], > 0 (smaller steps are merged
            into one level block).
        min_samples: scans a block needs to stand on its own, integer >= 1.
        noise: standard deviation of one reading [m], >= 0: a cell of weight ``w`` starts a new
            block only beyond ``max(jump, 3 noise / sqrt(w))`` from the current one.
    """

    def __init__(
        self, cell: float = 0.001, jump: float = 0.0015, min_samples: int = 2, noise: float = 0.002
    ) -> None:
        if not (math.isfinite(cell) and cell > 0):
            raise ValueError(f"mapping cell = {cell!r} out of range; allowed: > 0 m")
        if not (math.isfinite(jump) and jump > 0):
            raise ValueError(f"mapping jump = {jump!r} out of range; allowed: > 0 m")
        if isinstance(min_samples, bool) or int(min_samples) != min_samples or min_samples < 1:
            raise ValueError(f"mapping min_samples = {min_samples!r}; allowed: integer >= 1")
        if not (math.isfinite(noise) and noise >= 0):
            raise ValueError(f"mapping noise = {noise!r} out of range; allowed: >= 0 m")
        self.noise = float(noise)
        self.cell = float(cell)
        self.jump = float(jump)
        self.min_samples = int(min_samples)
        self.reset()

    def reset(self) -> None:
        """Forget every reading."""
        self._sum: dict[int, float] = {}
        self._weight: dict[int, float] = {}
        self._count: dict[int, int] = {}
        self._terrain: Terrain | None = None
        self.x_min = math.inf
        self.x_max = -math.inf

    def add(self, xs: np.ndarray, heights: np.ndarray, weight: float = 1.0) -> None:
        """Fuse readings ``heights`` [m] at positions ``xs`` [m] (absolute, map frame), each
        weighing ``weight`` (> 0; the number of readings averaged in it); non-finite readings
        are skipped."""
        if not (math.isfinite(weight) and weight > 0):
            raise ValueError(f"weight = {weight!r} out of range; allowed: > 0")
        x = np.asarray(xs, dtype=np.float64).reshape(-1)
        h = np.asarray(heights, dtype=np.float64).reshape(-1)
        if x.shape != h.shape:
            raise ValueError(f"xs and heights must have the same length, got {x.size}, {h.size}")
        ok = np.isfinite(x) & np.isfinite(h)
        for xi, hi in zip(x[ok], h[ok], strict=True):
            k = int(math.floor(xi / self.cell))
            self._sum[k] = self._sum.get(k, 0.0) + float(hi) * weight
            self._weight[k] = self._weight.get(k, 0.0) + weight
            self._count[k] = self._count.get(k, 0) + 1
        if ok.any():
            self.x_min = min(self.x_min, float(x[ok].min()))
            self.x_max = max(self.x_max, float(x[ok].max()))
            self._terrain = None

    def add_scan(
        self, foot: tuple[float, float], offsets: np.ndarray, scan: np.ndarray, weight: float = 1.0
    ) -> None:
        """Fuse one scan: ``scan[k]`` [m] relative to the stance foot ``foot = (x, y)`` [m] at
        ``x + offsets[k]``, weighing ``weight`` (the readings averaged in it)."""
        x = foot[0] + np.asarray(offsets, dtype=np.float64)
        self.add(x, foot[1] + np.asarray(scan, dtype=np.float64), weight)

    def known(self, xs: np.ndarray) -> np.ndarray:
        """Where the map is scanned: ``x_min <= xs <= x_max`` (boolean, the shape of ``xs``)."""
        x = np.asarray(xs, dtype=np.float64)
        return (x >= self.x_min) & (x <= self.x_max)

    def foot_height(self, x: float, offsets: np.ndarray, scan: np.ndarray) -> float:
        """Height [m] of a stance foot at ``x`` [m] that scanned ``scan`` [m] (relative to it) at
        ``offsets`` [m]: the median of ``map - scan`` over the points the map already covers
        (robust to an edge the dead-reckoned ``x`` misplaces), else the map's height at
        ``x``."""
        xs = x + np.asarray(offsets, dtype=np.float64)
        s = np.asarray(scan, dtype=np.float64)
        ok = self.known(xs) & np.isfinite(s)
        if ok.sum() < 3:
            return float(self.terrain().height(x))
        return float(np.median(self.terrain().height(xs[ok]) - s[ok]))

    def cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The fused cells in order: centres [m], mean heights [m], weights, scan counts."""
        keys = sorted(self._count)
        w = np.array([self._weight[k] for k in keys], dtype=np.float64)
        cnt = np.array([self._count[k] for k in keys], dtype=np.int64)
        mean = np.array([self._sum[k] for k in keys], dtype=np.float64) / np.maximum(w, 1e-300)
        return (np.array(keys, dtype=np.float64) + 0.5) * self.cell, mean, w, cnt

    def blocks(self) -> list[tuple[float, float, float]]:
        """Level blocks ``(x_first, x_last, height)`` [m]: first and last scanned cell centres
        and the mean height, in order of x."""
        x, h, n, cnt = self.cells()
        if x.size == 0:
            return []
        # a cell's height is uncertain by its readings' noise: a new level must stand out of it
        tol = np.maximum(self.jump, 3.0 * self.noise / np.sqrt(n))
        groups: list[list[int]] = [[0]]
        for i in range(1, x.size):
            g = groups[-1]
            mean = np.average(h[g], weights=n[g])
            far = abs(h[i] - mean) > tol[i]
            # the next cell must confirm a new level (a single stray reading does not)
            confirmed = i + 1 >= x.size or abs(h[i + 1] - h[i]) <= max(tol[i], tol[i + 1])
            if not far:
                g.append(i)
            elif confirmed:
                groups.append([i])
            # else: a stray cell (a reading across an edge, say) belongs to no block
        merged = True
        while merged and len(groups) > 1:
            merged = False
            for j, g in enumerate(groups):
                if cnt[g].sum() >= self.min_samples:
                    continue
                hj = np.average(h[g], weights=n[g])
                nb = [k for k in (j - 1, j + 1) if 0 <= k < len(groups)]
                k = min(nb, key=lambda k: abs(np.average(h[groups[k]], weights=n[groups[k]]) - hj))
                lo, hi = min(j, k), max(j, k)
                groups[lo : hi + 1] = [sorted(groups[lo] + groups[hi])]
                merged = True
                break
        out = [(g, float(np.average(h[g], weights=n[g]))) for g in groups]
        j = 0
        while j + 1 < len(out):  # neighbours that ended up within ``jump`` are one block
            (ga, ha), (gb, hb) = out[j], out[j + 1]
            if abs(ha - hb) <= self.jump:
                g = ga + gb
                out[j : j + 2] = [(g, float(np.average(h[g], weights=n[g])))]
            else:
                j += 1
        return [(float(x[g[0]]), float(x[g[-1]]), hg) for g, hg in out]

    def terrain(self) -> Terrain:
        """The map as a :class:`Terrain`: level blocks, faces half-way between them, level
        ground beyond the scanned stretch.

        Raises:
            ValueError: nothing has been scanned yet.
        """
        if self._terrain is not None:
            return self._terrain
        b = self.blocks()
        if not b:
            raise ValueError("the terrain map has no readings yet")
        px = [b[0][0] - _EXTEND]
        py = [b[0][2]]
        for (_, x1, h1), (x0, _, h0) in zip(b[:-1], b[1:], strict=True):
            xm = 0.5 * (x1 + x0)
            if x0 - x1 > 2.5 * self.cell:
                # kinks (a 10 um tilt) at both ends of the gap: footholds keep their margin from
                # the whole stretch where the edge may be
                px += [x1, xm, xm, x0]
                py += [h1, h1 + _TILT, h0 + _TILT, h0]
            else:
                px += [xm, xm]
                py += [h1, h0]
        px.append(b[-1][1] + _EXTEND)
        py.append(b[-1][2])
        self._terrain = Terrain.from_points(px, py)
        return self._terrain
