"""Online identification of the robot's swing dynamics from the encoders and the applied input.

The paper's controller walked a robot whose model was identified beforehand; ours is built on
the nominal model, and a robot a few per cent off (``robot_error``) makes its plans wrong: with
every parameter at +-10 % the reference policy built on the nominal robot walks 8 of 30
validation stairs courses, and all 30 when it is built on the true parameters. Only some of
those parameters shape the motion between touchdowns, and they are identifiable from what the
controller sees.

The swing phase (:func:`envs.physics.model.accelerations`) depends on the parameters only
through the coefficients ``p1 .. p5`` of the paper's Appendix B, the input gain ``b`` and the
hip friction ``Fc, Fv``, linearly, and is unchanged when all of them are scaled by the same
factor: only their ratios are identifiable, so ``b`` stays the nominal one and ``theta = (p1,
p2, p3, p4, p5, Fc, Fv)`` is identified in the nominal input's scale. Every robot has ``p2 / p4
= l / g``; the fit ties ``p2`` to ``p4`` and the leg length, which the localisation measures
better than the dynamics (a free ``p2`` absorbs a push instead).

:class:`SwingIdentifier` fits ``theta`` by **output error with multiple shooting**: each stance
is cut into segments of about 0.15 s; each segment is simulated from its own initial state
(fitted too) under the inputs that were applied, and the simulated angles are compared with the
measured ones (a Huber loss; a segment that the fitted model still cannot explain, a push say,
is then left out and the fit repeated). Equation-error fits (regressing on differentiated
encoder readings) are biased here: the unactuated row of the dynamics is homogeneous in
``theta``, and noise in the differentiated angles pulls ``p3`` and ``p4 + p5`` to zero
together. Output error puts the noise where it is, on the measured angles. A Gaussian prior
centred on the nominal coefficients (:data:`PRIOR`) keeps the directions the data barely see
(the absolute level of ``p3`` and ``p5`` when only their ratio is excited) near the nominal
robot.

:func:`robot_from_coefficients` turns the identified coefficients into the nearest robot
(smallest relative change of ``m, mH, mHg, Ic, lc``) with a given leg length: the leg length is
a matter of geometry, measured better by the localisation's drift
(:class:`controllers.localisation.ScanLocaliser`) than by the ratio ``g p2 / p4`` of the
dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from envs.physics import model
from envs.physics.params import P1, P2, P3, P4, P5, PFC, PFV, RobotParams

from .numerics import one_blas_thread

__all__ = [
    "COEFFICIENTS",
    "PRIOR",
    "IdentifiedModel",
    "SwingIdentifier",
    "robot_from_coefficients",
    "simulate_swing",
]

#: the identified coefficients, in the order of :attr:`IdentifiedModel.theta`
COEFFICIENTS = ("p1", "p2", "p3", "p4", "p5", "Fc", "Fv")
_INDEX = np.array([P1, P2, P3, P4, P5, PFC, PFV])
#: the coefficients fitted: p2 follows p4 and the leg length (``p2 / p4 = l / g``)
_FREE = np.array([0, 2, 3, 4, 5, 6])
#: prior standard deviation of each coefficient, relative to its nominal value: products of
#: two or three parameters each +-10 % for p1..p5, a poorly known friction for Fc, Fv
PRIOR = (0.15, 0.15, 0.15, 0.15, 0.15, 0.5, 0.5)
_MIN_SAMPLES = 12  # a shorter segment is dropped
#: residuals beyond this many standard deviations count linearly (Huber loss)
ROBUST_SCALE = 3.0
#: a segment whose rms residual under the fit exceeds this many standard deviations is left out
OUTLIER_RMS = 3.0
#: relative standard deviation added to every fitted coefficient's: the swing model's own error
#: (the observer's, the discretisation's), which no amount of data removes; without it a segment
#: whose sensitivities are large makes the linearised covariance overconfident (a nominal robot
#: fitted 0.6 % off in p4 at 0.07 % standard deviation)
SD_FLOOR = 0.01
#: 99th percentile of chi-square with 6 degrees of freedom (scipy.stats.chi2.ppf(0.99, 6))
CHI2_99 = 16.812
_INIT_SCALE = (1e-3, 1e-3, 0.1, 0.1)  # typical size of the initial-state corrections


@njit(cache=True)
def simulate_swing(P, x0, u, dt, nsub):  # pragma: no cover - compiled
    """Angles ``(n, 2)`` [rad] of the swing phase sampled every ``dt`` [s] from the state
    ``x0 = [q1, q2, q1d, q2d]`` [rad, rad/s], input ``u[k]`` [input units] held over sample
    interval ``k`` (``u[n - 1]`` unused), ``nsub`` RK4 substeps per interval; no touchdown."""
    n = u.size
    out = np.empty((n, 2))
    q1, q2, w1, w2 = x0[0], x0[1], x0[2], x0[3]
    h = dt / nsub
    for k in range(n):
        out[k, 0] = q1
        out[k, 1] = q2
        if k == n - 1:
            break
        for _ in range(nsub):
            a1, a2 = model.accelerations(P, q1, q2, w1, w2, u[k])
            q1, q2, w1, w2, _w, _p, _a = model.swing_rk4(P, q1, q2, w1, w2, u[k], h, a1, a2)
    return out


@dataclass(frozen=True)
class IdentifiedModel:
    """One fit of :class:`SwingIdentifier`.

    Attributes:
        theta: ``(p1, p2, p3, p4, p5, Fc, Fv)`` in the nominal input's scale (SI units).
        relative: ``theta / nominal - 1`` per coefficient.
        sigma: posterior standard deviation of ``relative`` per coefficient (with
            :data:`SD_FLOOR` added in quadrature).
        segments: segments fitted.
        rms: root-mean-square angle residual [rad].
        distance2: squared Mahalanobis distance of the fitted coefficients (all but ``p2``)
            from the nominal ones under their posterior covariance plus :data:`SD_FLOOR`
            squared (about chi-square with 6 degrees of freedom when the robot is the nominal
            one).
    """

    theta: np.ndarray
    relative: np.ndarray
    sigma: np.ndarray
    segments: int
    rms: float
    distance2: float

    @property
    def significant(self) -> bool:
        """Whether the data reject the nominal coefficients at the 1 % level
        (``distance2`` above the 99th percentile of chi-square with 6 degrees of freedom)."""
        return self.distance2 > CHI2_99


class SwingIdentifier:
    """Identifies the swing-phase coefficients from stances of measured angles and inputs.

    Args:
        robot: the nominal robot (the prior's centre, and the input gain kept).
        dt: sample period [s], > 0.
        angle_sigma: standard deviation of a measured angle [rad] (encoder noise and
            quantisation), > 0.
        segment: length of a shooting segment [s], > 0.
        prior: prior standard deviations relative to the nominal coefficients (7 numbers > 0;
            :data:`PRIOR`).
        substeps: RK4 substeps per sample interval, >= 1.

    Attributes:
        leg_length: the leg length [m] the fit assumes (``p2`` follows ``p4`` with it; the
            nominal one unless set, e.g. from the localisation).
    """

    def __init__(
        self,
        robot: RobotParams,
        dt: float,
        angle_sigma: float,
        segment: float = 0.15,
        prior: tuple[float, ...] = PRIOR,
        substeps: int = 2,
    ) -> None:
        for name, v in (("dt", dt), ("angle_sigma", angle_sigma), ("segment", segment)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"identification {name} = {v!r}; allowed: > 0")
        p = np.asarray(prior, dtype=np.float64)
        if p.shape != (len(COEFFICIENTS),) or not np.all(np.isfinite(p) & (p > 0)):
            raise ValueError(f"identification prior = {prior!r}; allowed: 7 numbers > 0")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"identification substeps = {substeps!r}; allowed: integer >= 1")
        self.robot = robot
        self.P = robot.vector()
        self.nominal = self.P[_INDEX].copy()
        self.dt = float(dt)
        self.angle_sigma = float(angle_sigma)
        self.samples = max(_MIN_SAMPLES, round(segment / dt))
        self.prior = p
        self.substeps = int(substeps)
        self.leg_length = robot.l
        self.reset()

    def reset(self) -> None:
        """Forget the data (a new episode)."""
        self.segments: list[tuple[np.ndarray, np.ndarray]] = []
        self._z = np.zeros(len(COEFFICIENTS))
        self._x0: list[np.ndarray | None] = []  # each segment's last fitted initial correction

    def add_stance(self, q: np.ndarray, u: np.ndarray) -> int:
        """Add one stance: measured angles ``q`` (n, 2) [rad] at consecutive samples and the
        inputs ``u`` (n,) [input units], ``u[k]`` held from sample ``k`` to ``k + 1`` (the
        last one unused). Returns the segments added."""
        q = np.asarray(q, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64).reshape(-1)
        if q.ndim != 2 or q.shape[1] != 2 or u.shape != (q.shape[0],):
            raise ValueError(f"stance: q must be (n, 2) and u (n,), got {q.shape} and {u.shape}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(u))):
            raise ValueError("stance: angles and inputs must be finite")
        n, w = q.shape[0], self.samples
        added = 0
        for a in range(0, n, w):
            b = min(a + w, n)
            if n - b < w // 2:  # a short tail joins the last segment
                b = n
            if b - a >= _MIN_SAMPLES:
                self.segments.append((q[a:b].copy(), u[a:b].copy()))
                self._x0.append(None)
                added += 1
            if b == n:
                break
        return added

    def _initial_states(self, which: list[int]) -> np.ndarray:
        """Starting guesses of the segments' initial corrections: the last fit's, else rates
        from a line through a new segment's first samples."""
        x0 = np.zeros((len(which), 4))
        for i, j in enumerate(which):
            if self._x0[j] is not None:
                x0[i] = self._x0[j]
                continue
            q = self.segments[j][0]
            k = min(6, q.shape[0])
            x0[i, 2:] = np.polyfit(np.arange(k) * self.dt, q[:k], 1)[0]
        return x0

    @one_blas_thread
    def fit(self) -> IdentifiedModel | None:
        """The coefficients that best explain the segments so far (None without data).

        Segments the fitted model still cannot explain (root-mean-square residual above
        :data:`OUTLIER_RMS` standard deviations: a push, a scuff) are left out and the fit is
        repeated without them; :attr:`IdentifiedModel.segments` counts those kept."""
        if not self.segments:
            return None
        first = self._fit(list(range(len(self.segments))))
        if first is None:
            return None
        fit, rms = first
        keep = [i for i, r in enumerate(rms) if r <= OUTLIER_RMS]
        if keep and len(keep) < len(rms):
            again = self._fit(keep)
            if again is not None:
                fit = again[0]
        self._z = fit.relative.copy()
        return fit

    def _fit(self, which: list[int]) -> tuple[IdentifiedModel, np.ndarray] | None:
        """The fit to the segments ``which``, and each one's rms residual [standard
        deviations]."""
        segments = [self.segments[i] for i in which]
        nf, S = _FREE.size, len(segments)
        P = self.P.copy()
        nominal, prior, sig = self.nominal, self.prior[_FREE], self.angle_sigma
        ratio = self.leg_length / self.robot.l

        def coefficients(free: np.ndarray) -> np.ndarray:
            z = np.empty(len(COEFFICIENTS))
            z[_FREE] = free
            z[1] = (1.0 + z[3]) * ratio - 1.0  # p2 / p4 = l / g for every robot
            return z

        def residuals(p: np.ndarray) -> np.ndarray:
            P[_INDEX] = nominal * (1.0 + coefficients(p[:nf]))
            out = [p[:nf] / prior]
            for s, (q, u) in enumerate(segments):
                d = p[nf + 4 * s : nf + 4 * s + 4]
                x0 = np.array([q[0, 0] + d[0], q[0, 1] + d[1], d[2], d[3]])
                sim = simulate_swing(P, x0, u, self.dt, self.substeps)
                out.append(((sim - q) / sig).ravel())
            return np.concatenate(out)

        rows = np.cumsum([nf] + [2 * q.shape[0] for q, _ in segments])

        def jacobian(p: np.ndarray) -> np.ndarray:
            # forward differences; a segment's residuals depend on the coefficients and its own
            # initial state only, so the k-th initial component of every segment moves at once
            r0 = residuals(p)
            J = np.zeros((r0.size, p.size))
            for j in range(nf):
                h = 1e-7 * max(1.0, abs(p[j]))
                e = p.copy()
                e[j] += h
                J[:, j] = (residuals(e) - r0) / h
            for k in range(4):
                h = 1e-7 * max(1.0, float(np.max(np.abs(p[nf + k :: 4]))))
                e = p.copy()
                e[nf + k :: 4] += h
                d = (residuals(e) - r0) / h
                for s in range(S):
                    J[rows[s] : rows[s + 1], nf + 4 * s + k] = d[rows[s] : rows[s + 1]]
            return J

        p0 = np.concatenate([self._z[_FREE], self._initial_states(which).ravel()])
        scale = np.concatenate([prior, np.tile(_INIT_SCALE, S)])
        # a robust loss: samples no model explains weigh less
        res = least_squares(
            residuals,
            p0,
            jac=jacobian,
            method="trf",
            x_scale=scale,
            loss="huber",
            f_scale=ROBUST_SCALE,
        )
        free = res.x[:nf]
        try:
            cov = np.linalg.inv(res.jac.T @ res.jac)[:nf, :nf] + np.diag(np.full(nf, SD_FLOOR**2))
            distance2 = float(free @ np.linalg.solve(cov, free))
            sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        except np.linalg.LinAlgError:
            sd, distance2 = prior.copy(), 0.0
        if not (np.all(np.isfinite(free)) and math.isfinite(distance2)):
            return None
        for i, j in enumerate(which):
            self._x0[j] = res.x[nf + 4 * i : nf + 4 * i + 4].copy()
        z = coefficients(free)
        sigma = np.empty(len(COEFFICIENTS))
        sigma[_FREE] = sd
        sigma[1] = sigma[3] * ratio
        r = residuals(res.x)[nf:]
        rms = np.array([np.sqrt(np.mean(r[a - nf : b - nf] ** 2)) for a, b in zip(rows, rows[1:])])
        fit = IdentifiedModel(
            theta=nominal * (1.0 + z),
            relative=z,
            sigma=sigma,
            segments=S,
            rms=float(np.sqrt(np.mean(r * r))) * sig if r.size else 0.0,
            distance2=distance2,
        )
        return fit, rms


@one_blas_thread
def robot_from_coefficients(
    nominal: RobotParams,
    theta: np.ndarray,
    l: float | None = None,  # noqa: E741
) -> RobotParams:
    """The robot nearest to ``nominal`` (smallest relative change of ``m, mH, mHg, Ic, lc``)
    whose swing coefficients (:meth:`RobotParams.coefficients`) are ``theta[:5]``, with hip
    friction ``theta[5:7]`` and leg length ``l`` [m] (default: the nominal one); the input
    gain stays the nominal one (``theta`` is in its scale).

    Where ``theta`` is inconsistent with ``l`` (``p2 / p4 = l / g`` for every robot) the
    coefficients are matched in the least-squares sense.

    Raises:
        ValueError: no valid robot is near (the message says which parameter).
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.shape != (len(COEFFICIENTS),) or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta must be {len(COEFFICIENTS)} finite numbers")
    l = nominal.l if l is None else float(l)  # noqa: E741
    names = ("m", "mH", "mHg", "Ic", "lc")
    x_nom = np.array([getattr(nominal, k) for k in names])
    x_scale = np.abs(x_nom) + 1e-9
    base = nominal.replace(l=l, lc=min(nominal.lc * l / nominal.l, l))
    target = theta[:5]
    t_scale = np.abs(target) + 1e-12
    keys = ("p1", "p2", "p3", "p4", "p5")

    def robot(x: np.ndarray) -> RobotParams:
        return base.replace(**dict(zip(names, x)))

    def residuals(x: np.ndarray) -> np.ndarray:
        try:
            c = robot(x).coefficients()
        except ValueError:
            return np.full(10, 1e3)
        coef = np.array([c[k] for k in keys])
        return np.concatenate([1e3 * (coef - target) / t_scale, (x - x_nom) / x_scale])

    x0 = np.array([getattr(base, k) for k in names])
    res = least_squares(residuals, x0, x_scale=x_scale)
    return robot(res.x).replace(Fc=max(float(theta[5]), 0.0), Fv=max(float(theta[6]), 0.0))
