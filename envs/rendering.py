"""Drawing of the compass-gait walker with pygame (as Gymnasium's classic-control envs do).

:class:`WalkerRenderer` draws one frame from a state and a terrain: the ground profile, both legs
(the stance leg in red, the swing leg in blue; leg ``A`` drawn solid, leg ``B`` with a light
core so the physical legs stay recognisable), the hip, achieved footholds (dark ticks), planned
footholds (green ticks, if given), and a text line with time, distance and footstep count. The
camera follows the hip. It works headless with SDL's dummy video driver
(``SDL_VIDEODRIVER=dummy``) for ``"rgb_array"``; ``"human"`` opens a window.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

RENDER_MODES = ("human", "rgb_array")

_SKY = (250, 250, 245)
_GROUND = (120, 110, 95)
_GROUND_FILL = (205, 195, 175)
_STANCE = (200, 40, 40)
_SWING = (40, 80, 200)
_HIP = (30, 30, 30)
_FOOTHOLD = (60, 60, 60)
_PLANNED = (20, 150, 60)
_TEXT = (20, 20, 20)


class WalkerRenderer:
    """Renders frames of size ``(height, width, 3)`` (uint8).

    Args:
        leg_length: leg length ``l`` [m]; sets the zoom (``view_legs`` leg lengths across).
        mode: ``"rgb_array"`` (off-screen surface) or ``"human"`` (a window).
        width, height: frame size [px].
        fps: frame rate of ``"human"`` mode.
        view_legs: visible width of the world in leg lengths.
    """

    def __init__(
        self,
        leg_length: float,
        mode: str = "rgb_array",
        width: int = 600,
        height: int = 400,
        fps: float = 50.0,
        view_legs: float = 6.0,
    ):
        if mode not in RENDER_MODES:
            raise ValueError(f"render_mode = {mode!r}; allowed: {list(RENDER_MODES)} or None")
        self.l = float(leg_length)
        self.mode = mode
        self.width, self.height = int(width), int(height)
        self.fps = float(fps)
        self.scale = self.width / (view_legs * self.l)  # px per m
        self._pygame = None
        self._screen = None
        self._surface = None
        self._clock = None
        self._font = None

    # ------------------------------------------------------------------ pygame setup
    def _init(self) -> None:
        try:
            import pygame
        except ImportError as exc:  # pragma: no cover - pygame is a dependency
            raise ImportError("rendering needs pygame: pip install pygame") from exc
        self._pygame = pygame
        if self.mode == "human":
            pygame.init()
            pygame.display.init()
            self._screen = pygame.display.set_mode((self.width, self.height))
            pygame.display.set_caption("roughwalk")
            self._clock = pygame.time.Clock()
        else:
            if "SDL_VIDEODRIVER" not in os.environ and not os.environ.get("DISPLAY"):
                os.environ["SDL_VIDEODRIVER"] = "dummy"
        self._surface = pygame.Surface((self.width, self.height))
        try:
            pygame.font.init()
            self._font = pygame.font.Font(None, 20)
        except Exception:  # noqa: BLE001 - text is optional (font module may be missing)
            self._font = None

    # ------------------------------------------------------------------ drawing
    def render(
        self,
        q: Sequence[float],
        stance_foot: Sequence[float],
        stance_leg: int,
        terrain_xs: np.ndarray,
        terrain_ys: np.ndarray,
        footholds: Sequence[tuple[float, float]] = (),
        planned: Sequence[float] = (),
        time: float = 0.0,
        distance: float = 0.0,
        steps: int = 0,
        failure: str | None = None,
        leg_length: float | None = None,
    ) -> np.ndarray | None:
        """Draw one frame; returns the RGB array in ``"rgb_array"`` mode, else ``None``.

        Args:
            q: ``(q1, q2)`` [rad] in paper coordinates.
            stance_foot: stance-foot position ``(x, y)`` [m].
            stance_leg: physical stance leg (0 = A, 1 = B).
            terrain_xs, terrain_ys: terrain polyline vertices [m].
            footholds: achieved footholds ``(x, y)`` [m].
            planned: planned foothold x positions [m] (drawn on the ground).
            time, distance, steps: shown as text; ``failure`` too when not ``None``.
            leg_length: the legs' length drawn [m] (default: the renderer's ``leg_length``,
                which sets the zoom), e.g. a simulated robot's under a model error.
        """
        if self._surface is None:
            self._init()
        pg = self._pygame
        surf = self._surface
        q1, q2 = float(q[0]), float(q[1])
        xs, ys = float(stance_foot[0]), float(stance_foot[1])
        l = self.l if leg_length is None else float(leg_length)  # noqa: E741
        hx, hy = xs + l * math.sin(q2), ys + l * math.cos(q2)
        sx, sy = hx - l * math.sin(q2 - q1), hy - l * math.cos(q2 - q1)
        # camera: hip at 40 % of the width, stance foot at 30 % of the height from the bottom
        cx = hx - 0.4 * self.width / self.scale
        cy = ys - 0.3 * self.height / self.scale

        def px(x: float, y: float) -> tuple[int, int]:
            return (
                int(round((x - cx) * self.scale)),
                int(round(self.height - (y - cy) * self.scale)),
            )

        surf.fill(_SKY)
        # terrain: polyline over the view, extended along the end segments
        x0, x1 = cx - 1.0, cx + self.width / self.scale + 1.0
        tx, ty = np.asarray(terrain_xs, dtype=float), np.asarray(terrain_ys, dtype=float)
        pts = _terrain_points(tx, ty, x0, x1)
        poly = [px(x, y) for x, y in pts]
        pg.draw.polygon(
            surf, _GROUND_FILL, poly + [(poly[-1][0], self.height), (poly[0][0], self.height)]
        )
        pg.draw.lines(surf, _GROUND, False, poly, 3)
        # footholds
        for fx, fy in footholds:
            p = px(fx, fy)
            pg.draw.line(surf, _FOOTHOLD, (p[0], p[1] - 6), (p[0], p[1] + 6), 2)
        for fx in planned:
            fy = float(np.interp(fx, tx, ty)) if tx.size > 1 else float(ty[0])
            p = px(float(fx), fy)
            pg.draw.polygon(
                surf, _PLANNED, [(p[0], p[1] - 2), (p[0] - 6, p[1] - 12), (p[0] + 6, p[1] - 12)]
            )
        # legs: swing first so the stance leg is on top
        w = max(4, int(0.05 * l * self.scale))
        legs = {stance_leg: ((xs, ys), _STANCE), 1 - stance_leg: ((sx, sy), _SWING)}
        for leg in (1 - stance_leg, stance_leg):
            (fx, fy), colour = legs[leg]
            pg.draw.line(surf, colour, px(fx, fy), px(hx, hy), w)
            if leg == 1:
                pg.draw.line(surf, (255, 255, 255), px(fx, fy), px(hx, hy), max(1, w // 3))
            pg.draw.circle(surf, colour, px(fx, fy), max(2, w // 2 + 1))
        pg.draw.circle(surf, _HIP, px(hx, hy), max(4, int(0.06 * l * self.scale)))
        if self._font is not None:
            text = f"t {time:6.2f} s   distance {distance:6.2f} m   steps {steps}"
            if failure:
                text += f"   [{failure}]"
            surf.blit(self._font.render(text, True, _TEXT), (8, 8))
        if self.mode == "human":
            self._screen.blit(surf, (0, 0))
            pg.event.pump()
            pg.display.flip()
            self._clock.tick(self.fps)
            return None
        return np.transpose(np.array(pg.surfarray.pixels3d(surf)), axes=(1, 0, 2))

    def close(self) -> None:
        """Close the window (if any) and release pygame resources."""
        if self._pygame is not None and self.mode == "human":
            self._pygame.display.quit()
            self._pygame.quit()
        self._surface = self._screen = self._pygame = None


def _terrain_points(
    tx: np.ndarray, ty: np.ndarray, x0: float, x1: float
) -> list[tuple[float, float]]:
    """Vertices of the terrain polyline between ``x0`` and ``x1`` (ends extrapolated)."""
    n = tx.size
    if n == 1:
        return [(x0, float(ty[0])), (x1, float(ty[0]))]

    def extrap(x: float, i: int, j: int) -> float:
        if tx[j] == tx[i]:
            return float(ty[j])
        return float(ty[i] + (ty[j] - ty[i]) / (tx[j] - tx[i]) * (x - tx[i]))

    pts: list[tuple[float, float]] = []
    if x0 < tx[0]:
        pts.append((x0, extrap(x0, 0, 1)))
    inside = (tx >= x0) & (tx <= x1)
    pts.extend((float(a), float(b)) for a, b in zip(tx[inside], ty[inside]))
    if x1 > tx[-1]:
        pts.append((x1, extrap(x1, n - 2, n - 1)))
    if len(pts) < 2:
        # the view lies inside one segment
        k = int(np.searchsorted(tx, x0, side="right")) - 1
        k = min(max(k, 0), n - 2)
        pts = [(x0, extrap(x0, k, k + 1)), (x1, extrap(x1, k, k + 1))]
    else:
        if pts[0][0] > x0:
            k = int(np.searchsorted(tx, x0, side="right")) - 1
            pts.insert(0, (x0, extrap(x0, k, k + 1)))
        if pts[-1][0] < x1:
            k = int(np.searchsorted(tx, x1, side="right")) - 1
            k = min(k, n - 2)
            pts.append((x1, extrap(x1, k, k + 1)))
    return pts
