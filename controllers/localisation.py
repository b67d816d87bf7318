"""Localisation of the stance foot from the terrain scanner against a terrain map.

At every touchdown the estimator dead-reckons the new stance foot from the model
(:mod:`controllers.estimator`); a model error (a leg a few per cent shorter, say) makes that
position drift by a few millimetres per footstep. The scanner's heights (relative to the stance
foot, at known offsets ahead of it) are a height profile that can be slid along the map: at the
true position the profile, shifted by the stance foot's height, matches the map; block edges
make the match sharp. :class:`ScanLocaliser` keeps a Gaussian belief (a two-state Kalman
filter) about the error of the estimated foot position and the odometry's drift rate (metres
of error per metre walked; a model error makes it systematic): at each touchdown the drift
predicts the new error and the odometry adds its variance (a fraction of the step length); the
scan's likelihood over a grid of horizontal shifts (the vertical offset fitted per shift)
multiplies the predicted error's distribution, and the posterior's mean and variance are
taken in as a measurement of the error; its mean corrects the foot. Where the map is flat
around the robot every shift matches equally well: the posterior is the prediction, and only
the learnt drift (zero on a nominal robot) corrects the foot while the variance grows.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["LocalisationResult", "ScanLocaliser"]

_MAX_SHIFT = 0.1  # largest correction searched [m]
_GRID_POINTS = 401  # shifts on the search grid


@dataclass(frozen=True)
class LocalisationResult:
    """One scan's correction.

    Attributes:
        shift: correction added to the dead-reckoned foot x [m].
        height: stance-foot height fitted to the map at the corrected position [m] (NaN when no
            scan point falls on the known map).
        sigma_prior, sigma: standard deviation of the foot-x error before and after the scan [m].
        points: scan points that fell on the known map and were used.
    """

    shift: float
    height: float
    sigma_prior: float
    sigma: float
    points: int


class ScanLocaliser:
    """Gaussian belief about the stance foot's horizontal error, corrected by scan matching.

    Args:
        offsets: x offsets of the scan points from the stance foot [m].
        scan_sigma: standard deviation of one height reading [m] (noise and quantisation; a
            mean of ``n`` readings counts ``scan_sigma / sqrt(n)``), > 0.
        scan_range: readings at ``+-scan_range`` [m] are clipped and not used, > 0.
        odometry_error: standard deviation of the dead-reckoned step length's random error,
            relative to the step length (0.02: 2 %), >= 0.
        drift_sigma: prior standard deviation of the drift rate (a systematic relative error of
            the step length; 0.05 covers a leg 5 % off), >= 0.
        initial_sigma: standard deviation of the foot-x error at the start [m], >= 0.
        outlier: a point's residual counts at most ``outlier`` standard deviations (a truncated
            quadratic: one bad reading cannot veto a shift), > 0.
    """

    def __init__(
        self,
        offsets: np.ndarray,
        scan_sigma: float,
        scan_range: float,
        odometry_error: float = 0.02,
        drift_sigma: float = 0.05,
        initial_sigma: float = 0.002,
        outlier: float = 3.0,
    ) -> None:
        checks = {
            "scan_sigma": (scan_sigma, scan_sigma > 0),
            "scan_range": (scan_range, scan_range > 0),
            "odometry_error": (odometry_error, odometry_error >= 0),
            "drift_sigma": (drift_sigma, drift_sigma >= 0),
            "initial_sigma": (initial_sigma, initial_sigma >= 0),
            "outlier": (outlier, outlier > 0),
        }
        for name, (v, ok) in checks.items():
            if not (math.isfinite(v) and ok):
                raise ValueError(f"localisation {name} = {v!r} out of range; see ScanLocaliser")
        self.offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
        self.scan_sigma = float(scan_sigma)
        self.scan_range = float(scan_range)
        self.odometry_error = float(odometry_error)
        self.drift_sigma = float(drift_sigma)
        self.initial_sigma = float(initial_sigma)
        self.outlier = float(outlier)
        self.reset()

    def reset(self) -> None:
        """Forget the episode: the error's variance back to ``initial_sigma ** 2``, the drift
        rate to zero with variance ``drift_sigma ** 2``."""
        self.drift = 0.0
        self.cov = np.diag([self.initial_sigma**2, self.drift_sigma**2])

    @property
    def sigma(self) -> float:
        """Current standard deviation of the foot-x error [m]."""
        return math.sqrt(self.cov[0, 0])

    def predict(self, step: float) -> float:
        """A new footstep of dead-reckoned horizontal length ``step`` [m]: the learnt drift
        predicts the error it adds, the odometry its variance. Returns the predicted mean
        error [m], to be added to the dead-reckoned foot (the belief is then centred on it)."""
        L = abs(float(step))
        if not math.isfinite(L):
            raise ValueError(f"step must be finite, got {step!r}")
        F = np.array([[1.0, L], [0.0, 1.0]])
        cov = F @ self.cov @ F.T
        cov[0, 0] = min(cov[0, 0] + (self.odometry_error * L) ** 2, (_MAX_SHIFT / 4) ** 2)
        self.cov = cov
        return self.drift * L

    def update(
        self,
        x: float,
        scan: np.ndarray,
        height: Callable[[np.ndarray], np.ndarray],
        known: Callable[[np.ndarray], np.ndarray] | None = None,
        readings: int = 1,
        map_sigma: float = 0.0,
    ) -> LocalisationResult:
        """Correct the stance foot's estimated x from a scan taken from it.

        Args:
            x: estimated stance-foot x [m] (the belief is centred on it).
            scan: the scanner's heights relative to the stance foot [m], one per offset (the
                mean of ``readings`` readings).
            height: the map, ``height(xs) -> heights`` [m] (vectorised).
            known: ``known(xs) -> bool`` where the map is known (default: everywhere).
            readings: number of independent readings averaged in ``scan``, >= 1.
            map_sigma: standard deviation of the map's heights [m] (0 for the true course).

        Returns the correction (:class:`LocalisationResult`), to be added to ``x``.
        """
        s = np.asarray(scan, dtype=np.float64).reshape(-1)
        if s.shape != self.offsets.shape:
            raise ValueError(f"scan must have {self.offsets.size} heights, got {s.size}")
        if int(readings) != readings or readings < 1:
            raise ValueError(f"readings = {readings!r}; allowed: integer >= 1")
        cov = self.cov
        v0 = cov[0, 0]
        sig0 = math.sqrt(v0)
        sigma = math.hypot(self.scan_sigma / math.sqrt(readings), map_sigma)
        m, var, b, n = self._match(x, sig0, s, sigma, height, known)
        shift = 0.0
        if var is not None and var < 0.99 * v0:  # below 1 %: the grid, not the scan
            # the scan's information as a measurement z +- sqrt(r) of the error
            r = 1.0 / (1.0 / var - 1.0 / v0)
            z = m + r * m / v0
            k = cov[:, 0] / (v0 + r)
            self.cov = cov - np.outer(k, cov[0, :])
            shift = float(k[0] * z)
            self.drift += float(k[1] * z)
        return LocalisationResult(shift, b, sig0, self.sigma, n)

    def _match(
        self,
        x: float,
        sig0: float,
        s: np.ndarray,
        sigma: float,
        height: Callable[[np.ndarray], np.ndarray],
        known: Callable[[np.ndarray], np.ndarray] | None,
    ) -> tuple[float, float | None, float, int]:
        """Posterior mean and variance of the shift [m, m^2] of the foot from ``x`` [m] under a
        prior ``N(0, sig0^2)``, the foot's height there [m] and the points used (variance None
        when fewer than two points fall on the known map)."""
        if sig0 <= 0.0:
            return 0.0, None, math.nan, 0
        # the contact: the ground under the foot is at the foot's height
        off = np.r_[0.0, self.offsets]
        s = np.r_[0.0, s]
        use = np.isfinite(s) & (np.abs(s) < self.scan_range)
        half = min(4.0 * sig0, _MAX_SHIFT)
        d = np.linspace(-half, half, _GRID_POINTS)
        X = x + d[:, None] + off[None, use]
        ok = np.asarray(known(X), dtype=bool) if known is not None else np.ones(X.shape, bool)
        # points unknown at some shift are dropped at every shift (equal footing for all)
        cols = ok.all(axis=0)
        n = int(cols.sum())
        if n < 2:
            return 0.0, None, math.nan, n
        H = np.asarray(height(X[:, cols]), dtype=np.float64)
        R = H - s[use][cols][None, :]
        b = np.median(R, axis=1)  # the stance foot's height at each shift
        z = (R - b[:, None]) / sigma
        cost = 0.5 * np.minimum(z * z, self.outlier**2).sum(axis=1)
        logp = -0.5 * (d / sig0) ** 2 - cost
        w = np.exp(logp - logp.max())
        w /= w.sum()
        mean = float(w @ d)
        # the grid's spacing bounds the resolution
        var = max(float(w @ (d - mean) ** 2), (d[1] - d[0]) ** 2)
        k = int(np.argmin(np.abs(d - mean)))
        return mean, var, float(b[k]), n
