"""Localisation of the stance foot from the terrain scanner against a terrain map.

At every touchdown the estimator dead-reckons the new stance foot from the model
(:mod:`controllers.estimator`); a model error (a leg a few per cent shorter, say) makes that
position drift by a few millimetres per footstep. The scanner's heights (relative to the stance
foot, at known offsets ahead of it) are a height profile that can be slid along the map: at the
true position the profile, shifted by the stance foot's height, matches the map; block edges
make the match sharp.

:class:`ScanLocaliser` is a point-mass (grid) Bayes filter over two quantities: the error of
the estimated foot position and the odometry's drift rate (metres of error per metre walked; a
model error makes it systematic). A priori the model is right, its drift within its
calibration, or wrong by a few per cent, with even odds. At each touchdown every drift on the
grid moves the error by its share of the step and the odometry blurs it (a fraction of the
step length); the scan's likelihood over the grid of errors (the vertical offset fitted per
shift) multiplies the belief, and the belief's mean error corrects the foot.

A scan point between two heights of the map only says on which side of an edge the foot is:
its likelihood is a step, not a bump. A Gaussian belief turned such a bound into a measurement
of the error and learnt a drift from it (a nominal robot walking up stairs learnt -2 % and
mislocated its feet by 25 mm); the grid keeps the bound as it is, and the prior's odds keep a
robot whose model is right from taking it for a drift until the scans rule that out. Where the
map is flat around the robot every shift matches equally well and the belief only moves with
the learnt drift while it widens.

The foot is corrected to a point of the belief (``ScanLocaliser.estimate``): its mean error
(``"mean"``, the default), or the mean error given the likelier of the prior's two models
(``"selected"``): given that the model is right (the drift rates within three times its
calibration's) while that carries at least half the belief, else the whole belief's mean. On a
nominal robot the wrong model's wide drifts put millimetres of error behind every footstep; a
scan point just short of an edge cuts them on one side, and the whole belief's mean then moves
the foot by a few millimetres, where the right model's, narrower (the odometry's blur alone),
moves it by less. A model the scans rule out carries no weight and the two estimates agree.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["ESTIMATES", "NOMINAL_DRIFT", "LocalisationResult", "ScanLocaliser"]

_MAX_SHIFT = 0.1  # largest error represented [m]
_GRID_POINTS = 401  # errors on the grid (0.5 mm apart)
_DRIFT_POINTS = 61  # drift rates on the grid, over +-3 drift_sigma ...
_NOMINAL_POINTS = 21  # ... and more over +-3 NOMINAL_DRIFT
#: standard deviation of the drift rate of a model that is right (its calibration)
NOMINAL_DRIFT = 0.005
#: the points of the belief the foot is corrected to (``ScanLocaliser.estimate``)
ESTIMATES = ("mean", "selected")
_SUPPORT = 1e-12  # belief below this fraction of its peak counts as zero
_RECENTRE = 0.01  # the grid follows the estimate once it is this far off [m]
_BLUR_TRUNCATE = 5.0  # the odometry's blur is cut this many standard deviations out
_NO_BLUR = np.ones(1)
_CONTACT = np.zeros(1)  # the stance foot's contact point: offset 0, height 0 (a scan point)


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
    """Grid belief about the stance foot's horizontal error and the drift rate, corrected by
    scan matching.

    Args:
        offsets: x offsets of the scan points from the stance foot [m].
        scan_sigma: standard deviation of one height reading [m] (noise and quantisation; a
            mean of ``n`` readings counts ``scan_sigma / sqrt(n)``), > 0.
        scan_range: readings at ``+-scan_range`` [m] are clipped and not used, > 0.
        odometry_error: standard deviation of the dead-reckoned step length's random error,
            relative to the step length (0.02: 2 %), >= 0.
        drift_sigma: prior standard deviation of the drift rate of a wrong model (a systematic
            relative error of the step length; 0.05 covers a leg 5 % off), in [0, 0.2].
        nominal_weight: prior probability that the model is right, its drift rate then within
            the calibration's ``NOMINAL_DRIFT`` (0.5 %), in [0, 1]. A scan that bounds the
            error on one side only then moves a nominal robot's estimate less.
        initial_sigma: standard deviation of the foot-x error at the start [m], >= 0.
        outlier: a point's residual counts at most ``outlier`` standard deviations (a truncated
            quadratic: one bad reading cannot veto a shift), > 0.
        estimate: the point the foot is corrected to, one of :data:`ESTIMATES`: ``"mean"``, the
            belief's mean error; ``"selected"``, the mean error given a right model (drift
            rates within ``3 NOMINAL_DRIFT``) while that has at least half the belief, else the
            belief's mean (see the module docstring).
    """

    def __init__(
        self,
        offsets: np.ndarray,
        scan_sigma: float,
        scan_range: float,
        odometry_error: float = 0.02,
        drift_sigma: float = 0.05,
        nominal_weight: float = 0.5,
        initial_sigma: float = 0.002,
        outlier: float = 3.0,
        estimate: str = "mean",
    ) -> None:
        checks = {
            "scan_sigma": (scan_sigma, scan_sigma > 0),
            "scan_range": (scan_range, scan_range > 0),
            "odometry_error": (odometry_error, odometry_error >= 0),
            "drift_sigma": (drift_sigma, 0 <= drift_sigma <= 0.2),
            "nominal_weight": (nominal_weight, 0 <= nominal_weight <= 1),
            "initial_sigma": (initial_sigma, 0 <= initial_sigma <= _MAX_SHIFT / 4),
            "outlier": (outlier, outlier > 0),
        }
        for name, (v, ok) in checks.items():
            if not (math.isfinite(v) and ok):
                raise ValueError(f"localisation {name} = {v!r} out of range; see ScanLocaliser")
        if estimate not in ESTIMATES:
            raise ValueError(
                f"localisation estimate = {estimate!r}; allowed: {', '.join(ESTIMATES)}"
            )
        self.estimate = estimate
        self.offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
        self._contact_offsets = np.concatenate((_CONTACT, self.offsets))  # the foot, then these
        self.scan_sigma = float(scan_sigma)
        self.scan_range = float(scan_range)
        self.odometry_error = float(odometry_error)
        self.drift_sigma = float(drift_sigma)
        self.nominal_weight = float(nominal_weight)
        self.initial_sigma = float(initial_sigma)
        self.outlier = float(outlier)
        self.errors = np.linspace(-_MAX_SHIFT, _MAX_SHIFT, _GRID_POINTS)
        self._du = float(self.errors[1] - self.errors[0])
        rmax = 3.0 * self.drift_sigma
        if rmax > 0:
            rates = np.r_[
                np.linspace(-rmax, rmax, _DRIFT_POINTS),
                np.linspace(-3 * NOMINAL_DRIFT, 3 * NOMINAL_DRIFT, _NOMINAL_POINTS),
            ]
            self.rates = np.unique(rates.round(12))
        else:
            self.rates = np.zeros(1)
        self.reset()

    def reset(self) -> None:
        """Forget the episode: the error ~ N(0, ``initial_sigma``^2) and, independent of it,
        the drift rate ~ N(0, ``NOMINAL_DRIFT``^2) with probability ``nominal_weight``, else
        N(0, ``drift_sigma``^2)."""
        r = self.rates
        if r.size > 1:  # densities times the cells' widths
            width = np.gradient(r)
            wide = np.exp(-0.5 * (r / self.drift_sigma) ** 2) / self.drift_sigma
            spike = np.exp(-0.5 * (r / NOMINAL_DRIFT) ** 2) / NOMINAL_DRIFT
            prior = ((1 - self.nominal_weight) * wide + self.nominal_weight * spike) * width
        else:
            prior = np.ones(1)
        self.belief = np.outer(prior, _gaussian(self.errors, self.initial_sigma))
        self.belief /= self.belief.sum()
        self._origin = 0.0  # the grid's zero error relative to the estimate [m]

    @property
    def drift(self) -> float:
        """Mean of the drift rate (relative error of the dead-reckoned step length)."""
        return float(self.belief.sum(axis=1) @ self.rates)

    @property
    def drift_sd(self) -> float:
        """Standard deviation of the drift rate."""
        w = self.belief.sum(axis=1)
        return math.sqrt(max(float(w @ (self.rates - self.drift) ** 2), 0.0))

    @property
    def sigma(self) -> float:
        """Standard deviation of the foot-x error [m] (at least the grid's resolution)."""
        return self._sigma_of(self.belief.sum(axis=0))

    def _sigma_of(self, w: np.ndarray) -> float:
        """:attr:`sigma` of the belief whose marginal over the errors is ``w``."""
        m = float(w @ self.errors)
        return math.sqrt(max(float(w @ (self.errors - m) ** 2), self._du**2 / 12))

    def predict(self, step: float) -> float:
        """A new footstep of dead-reckoned horizontal length ``step`` [m]: every drift rate
        moves the error by its share of the step and the odometry blurs it. Returns the mean
        error [m], to be added to the dead-reckoned foot (the belief is then centred on it)."""
        L = abs(float(step))
        if not math.isfinite(L):
            raise ValueError(f"step must be finite, got {step!r}")
        blur = self.odometry_error * L / self._du
        w = _NO_BLUR
        if blur > 0.05 and self.sigma < _MAX_SHIFT / 4:  # beyond that the scans cannot tell
            w = _gaussian_weights(blur, _BLUR_TRUNCATE)
        b = _shift_and_blur(self.belief, self.rates * L / self._du, w)
        b /= b.sum()
        self.belief = b
        return self._recentre()

    def rescale(self, ratio: float) -> None:
        """The dead reckoning's leg length was multiplied by ``ratio`` (> 0): the drift rates
        are re-referred to it (a drift ``r`` becomes ``(1 + r) / ratio - 1``)."""
        if not (math.isfinite(ratio) and ratio > 0):
            raise ValueError(f"ratio = {ratio!r}; allowed: > 0")
        if self.rates.size == 1:
            return
        old = ratio * (1.0 + self.rates) - 1.0  # the old rate each new grid rate came from
        pos = np.interp(old, self.rates, np.arange(self.rates.size), left=-1.0, right=-1.0)
        b = np.zeros_like(self.belief)
        ok = pos >= 0
        i0 = np.minimum(np.floor(pos[ok]).astype(int), self.rates.size - 2)
        f = (pos[ok] - i0)[:, None]
        b[ok] = (1.0 - f) * self.belief[i0] + f * self.belief[i0 + 1]
        if b.sum() > 0:  # else the re-referred drift is off the grid: keep the belief
            self.belief = b / b.sum()

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
        marginal = self.belief.sum(axis=0)
        sig0 = self._sigma_of(marginal)
        sigma = math.hypot(self.scan_sigma / math.sqrt(readings), map_sigma)
        support = np.flatnonzero(marginal > _SUPPORT * marginal.max())
        cols = slice(support[0], support[-1] + 1)
        d = self.errors[cols] + self._origin  # the shifts from x
        cost, b, n = self._match(x, d, s, sigma, height, known)
        if cost is None:
            return LocalisationResult(0.0, math.nan, sig0, sig0, n)
        self.belief[:, cols] *= np.exp(-(cost - cost.min()))[None, :]
        self.belief /= self.belief.sum()
        shift = self._recentre()
        k = int(np.argmin(np.abs(d - shift)))
        return LocalisationResult(shift, float(b[k]), sig0, self.sigma, n)

    def _recentre(self) -> float:
        """The estimate moves by the belief's point error (:attr:`estimate`), which becomes
        zero; returns it [m]. The grid moves with it by whole cells once it is off by more than
        ``_RECENTRE``."""
        m = float(self._point_marginal() @ self.errors) + self._origin
        self._origin -= m
        k = int(round(self._origin / self._du))
        if abs(self._origin) > _RECENTRE:
            b = np.zeros_like(self.belief)
            if k > 0:
                b[:, k:] = self.belief[:, :-k]
            else:
                b[:, :k] = self.belief[:, -k:]
            self.belief = b / b.sum()
            self._origin -= k * self._du
        return m

    def _point_marginal(self) -> np.ndarray:
        """The distribution of the error whose mean is the point estimate: the belief's
        marginal, or for ``"selected"`` the marginal given a right model while that has at
        least half the belief."""
        if self.estimate == "selected":
            right = self.belief[np.abs(self.rates) <= 3 * NOMINAL_DRIFT]
            p = float(right.sum())
            if p >= 0.5:
                return right.sum(axis=0) / p
        return self.belief.sum(axis=0)

    def _match(
        self,
        x: float,
        d: np.ndarray,
        s: np.ndarray,
        sigma: float,
        height: Callable[[np.ndarray], np.ndarray],
        known: Callable[[np.ndarray], np.ndarray] | None,
    ) -> tuple[np.ndarray | None, np.ndarray, int]:
        """Negative log-likelihood of the scan ``s`` for the foot at ``x + d`` [m] (None when
        fewer than two points fall on the known map), the foot's height at each shift [m] and
        the points used."""
        # the contact: the ground under the foot is at the foot's height
        off = self._contact_offsets
        s = np.concatenate((_CONTACT, s))
        use = np.isfinite(s) & (np.abs(s) < self.scan_range)
        X = x + d[:, None] + off[None, use]
        ok = np.asarray(known(X), dtype=bool) if known is not None else np.ones(X.shape, bool)
        # points unknown at some shift are dropped at every shift (equal footing for all)
        cols = ok.all(axis=0)
        n = int(cols.sum())
        if n < 2:
            return None, np.full(d.size, math.nan), n
        H = np.asarray(height(X[:, cols]), dtype=np.float64)
        R = H - s[use][cols][None, :]
        b = _row_medians(R)  # the stance foot's height at each shift
        z = (R - b[:, None]) / sigma
        return 0.5 * np.minimum(z * z, self.outlier**2).sum(axis=1), b, n


def _gaussian(x: np.ndarray, sigma: float) -> np.ndarray:
    """Unnormalised N(0, sigma^2) on the grid ``x`` (all mass on the point nearest 0 when sigma
    is below the grid's spacing)."""
    if x.size > 1 and sigma >= x[1] - x[0]:
        return np.exp(-0.5 * (x / sigma) ** 2)
    out = np.zeros_like(x)
    out[np.argmin(np.abs(x))] = 1.0
    return out


def _gaussian_weights(sigma: float, truncate: float) -> np.ndarray:
    """The normalised Gaussian of standard deviation ``sigma`` [grid points] on the grid points
    within ``truncate`` standard deviations, as ``scipy.ndimage.gaussian_filter1d`` makes it."""
    radius = int(truncate * sigma + 0.5)
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sigma * sigma) * x**2)
    return phi / phi.sum()


@njit(cache=True)
def _row_medians(R):  # pragma: no cover - compiled
    """``np.median(R, axis=1)`` as numpy gives it: each row's middle value, the mean of its two
    middle values for an even count (numpy's mean: ``(0 + a + b) / 2``, so a zero median is
    +0), NaN where the row holds one."""
    nr, n = R.shape
    out = np.empty(nr)
    row = np.empty(n)  # the row sorted (insertion: rows are short)
    h = n // 2
    for j in range(nr):
        nan = False
        for i in range(n):
            v = R[j, i]
            nan |= v != v
            k = i
            while k > 0 and row[k - 1] > v:
                row[k] = row[k - 1]
                k -= 1
            row[k] = v
        if nan:
            out[j] = np.nan
        elif n % 2:
            out[j] = 0.0 + row[h]
        else:
            out[j] = (0.0 + row[h - 1] + row[h]) / 2
    return out


@njit(cache=True)
def _shift_and_blur(p, a, w):  # pragma: no cover - compiled
    """Each row ``j`` of ``p`` moved by ``a[j]`` grid points (linear interpolation; mass moved
    off the grid is lost), then correlated with the symmetric weights ``w`` (odd length; zero
    beyond the grid): ``scipy.ndimage.correlate1d``'s sums in its order, so the same numbers as
    that filter (``mode="constant"``) on the moved rows."""
    nr, n = p.shape
    r = (w.size - 1) // 2
    out = np.empty_like(p)
    line = np.zeros(n + 2 * r)  # one moved row with r zeros either side
    acc = np.empty(n)  # a row's sums (an array of its own: the loops below vectorise)
    for j in range(nr):
        k = math.floor(-a[j])  # moved[i] = p[j, i - a[j]]
        f = -a[j] - k
        for i in range(n):
            s = i + k
            t0 = p[j, s] if 0 <= s < n else 0.0
            t1 = p[j, s + 1] if 0 <= s + 1 < n else 0.0
            line[r + i] = t0 * (1.0 - f) + t1 * f
        for i in range(n):
            acc[i] = line[r + i] * w[r]
        for d in range(r, 0, -1):  # the outermost pair first
            wd = w[r - d]
            lo = line[r - d : r - d + n]
            hi = line[r + d : r + d + n]
            for i in range(n):
                acc[i] += (lo[i] + hi[i]) * wd
        out[j] = acc
    return out
