"""State estimation from the environment's sensors: encoders, contact switches, observer.

:class:`SensorStateEstimator` turns the sensor observation of the roughwalk envs into an
estimate of the full state ``(q1, q2, q1d, q2d)``, the stance leg and the stance-foot position,
as the paper's controller does. Every tick it decodes the two encoders into ``q`` with the
stance leg from the contact switches and advances the high-gain observer
(:mod:`controllers.observer`) with the input applied over the last period. When the contact
switches report a new stance leg, the touchdown inside the last period is located on the
terrain map by integrating the observer's model from the previous estimate
(:func:`controllers.observer.predict_touchdown`); the impact map is applied to the estimate
there and the stance foot moves to the located foothold (dead reckoning on the map).

Perception (the loop of the paper's Figure 1 closed through the terrain scanner):

- ``localise=True``: at each touchdown the dead-reckoned foothold is corrected by matching the
  scan against the map (:class:`controllers.localisation.ScanLocaliser`), so a model error
  (a leg a few per cent off) no longer makes the foot position drift step after step; on level
  ground the scan carries no horizontal information and the correction is zero.
- ``mapping=True``: the true course is never read; the map the touchdowns are located on (and
  the planner plans on) is built from the scans as the robot walks
  (:class:`controllers.mapping.ScanMap`), in a frame whose origin is the first stance foot.

The reference policy (:mod:`controllers.reference`) and the RL observation wrapper
(``agents.wrappers.EstimatedStateObservation``) share it, so learned and classical controllers
see the same estimate.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.physics.encoders import encoders_to_q, stance_from_contacts
from envs.physics.params import RobotParams
from envs.physics.terrain import Terrain

from .localisation import ESTIMATES, LocalisationResult, ScanLocaliser
from .mapping import ScanMap
from .observer import (
    HighGainObserver,
    angle_sigma,
    eps_for_noise,
    observer_impact,
    observer_update,
    predict_touchdown,
    substeps_for,
)

__all__ = ["IMPACT", "START", "TICK", "SensorStateEstimator"]

_MAX_READINGS = 50  # scan readings averaged at most (their noise is not perfectly independent)

#: what :meth:`SensorStateEstimator.update` reports about a tick
START, TICK, IMPACT = "start", "tick", "impact"


def _scan_sigma(sensors: Any) -> float:
    """Standard deviation of one scanner reading [m]: its Gaussian noise and the quantisation's
    uniform error."""
    return math.hypot(sensors.scan_noise, sensors.scan_resolution / math.sqrt(12.0))


class SensorStateEstimator:
    """Estimated state of a roughwalk env's walker from its sensor observations.

    Args:
        env: the environment (as ``gym.make`` returns it; wrappers are looked through); it must
            expose ``robot``, ``dt``, ``u_max`` and ``sensor_layout`` and observe sensors.
        eps: observer time constant [s] (paper: 0.02), > 0; None: from the encoders' noise
            (:func:`controllers.observer.eps_for_noise`: 0.04 s on the nominal sensors).
        initial_velocity: velocity guess ``(q1d, q2d)`` [rad/s] at the start of an episode;
            default: the environment's nominal start velocity (its configuration, not the
            episode's true state), else zero.
        localise: correct the stance foot at each touchdown by matching the terrain scan against
            the map (needs ``scan_count >= 2``); None: wherever the env has that scanner and
            ``mapping`` is off (the reference policy's default).
        mapping: plan on a map built from the scans (no access to the true course); the
            origin of its frame is the first stance foot (heights relative to it).
        odometry_error: standard deviation of a dead-reckoned step length, relative to the step
            (localisation's process noise), >= 0.
        foot_estimate: the point of the localisation's belief the stance foot is corrected to
            (:data:`controllers.localisation.ESTIMATES`; ``localise`` only): ``"mean"``
            (default) or ``"selected"`` (the mean given the likelier model, right or wrong; see
            :class:`ScanLocaliser`).

    Attributes:
        x: the estimate ``[q1, q2, q1d, q2d]`` [rad, rad/s] (a view, updated in place).
        stance_leg: physical stance leg (0 = A, 1 = B) from the contact switches.
        stance_foot: estimated stance-foot position ``(x, y)`` [m].
        terrain: the terrain map the touchdowns are located on (the env's course).
        t: time since the start of the episode [s].
        touchdowns_located, touchdowns_guessed: touchdowns located inside their period, and
            those taken at the end of the period (none found by the model).
        scan: the scanner's heights of the last decoded observation [m] (relative to the
            stance foot).
        corrections: per touchdown, the localisation's :class:`LocalisationResult` (empty
            without ``localise``).
        map: the :class:`ScanMap` being built (``mapping``), else None.
        angle_sigma: standard deviation of a decoded angle [rad] (encoder noise and
            quantisation).
    """

    def __init__(
        self,
        env: gym.Env,
        eps: float | None = None,
        initial_velocity: tuple[float, float] | None = None,
        localise: bool | None = False,
        mapping: bool = False,
        odometry_error: float = 0.02,
        foot_estimate: str = "mean",
    ) -> None:
        u = env.unwrapped
        for name in ("robot", "dt", "u_max", "sensor_layout"):
            if not hasattr(u, name):
                raise ValueError(f"the environment does not expose '{name}' (env.unwrapped.{name})")
        if getattr(u, "observation_mode", "sensors") != "sensors":
            raise ValueError(
                "state estimation reads the sensor observation: make the env "
                "with observation='sensors'"
            )
        self.env = u
        self.robot = u.robot
        self.P = self.robot.vector()
        self.dt = float(u.dt)
        self.u_max = float(u.u_max)
        self.layout = u.sensor_layout
        self._obs_shape, self._scan = (self.layout.size,), self.layout.scan
        if initial_velocity is None:
            init = getattr(getattr(u, "settings", None), "initial_state", None)
            initial_velocity = tuple(init.qd) if init is not None else (0.0, 0.0)
        self.initial_velocity = np.asarray(initial_velocity, dtype=np.float64)
        self._nsub_td = 16
        self.offsets = np.asarray(self.layout.scan_offsets, dtype=np.float64)
        sensors = getattr(getattr(u, "settings", None), "sensors", None)
        scans = sensors is not None and self.offsets.size >= 2
        if localise is None:
            localise = scans and not mapping
        self.localise, self.mapping = bool(localise), bool(mapping)
        if not (math.isfinite(odometry_error) and odometry_error >= 0):
            raise ValueError(f"odometry_error = {odometry_error!r} out of range; allowed: >= 0")
        if (self.localise or self.mapping) and not scans:
            raise ValueError(
                "localise and mapping read the terrain scan: the env needs sensors.scan_count >= 2"
            )
        if foot_estimate not in ESTIMATES:
            raise ValueError(f"foot_estimate = {foot_estimate!r}; allowed: {', '.join(ESTIMATES)}")
        if foot_estimate != "mean" and not self.localise:
            raise ValueError(
                f"foot_estimate = {foot_estimate!r}: a point of the localisation's belief, which "
                "needs localise (a scanner, mapping off)"
            )
        self.foot_estimate = foot_estimate
        if self.localise and self.mapping:
            raise ValueError(
                "localise and mapping cannot be combined yet: a map built from the scans is in "
                "the frame of the dead-reckoned foot (choose one)"
            )
        enc = (sensors.encoder_noise, sensors.encoder_resolution) if sensors else (1e-3, 0.0)
        self.angle_sigma = max(angle_sigma(*enc), 1e-4)
        self.observer = HighGainObserver(
            self.robot, self.dt, eps_for_noise(self.angle_sigma) if eps is None else eps
        )
        self.localiser: ScanLocaliser | None = None
        self.map: ScanMap | None = None
        if self.localise:
            self.localiser = ScanLocaliser(
                self.offsets,
                max(_scan_sigma(sensors), 5e-4),
                sensors.scan_range,
                odometry_error,
                estimate=foot_estimate,
            )
        if self.mapping:
            self.map = ScanMap(noise=_scan_sigma(sensors))
            self._scan_range = sensors.scan_range
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call after ``env.reset``); the next update starts a new one."""
        self.started = False
        # no estimate until the first update: what a new estimator holds, not the last episode's
        self.observer.x[:] = 0.0
        self.stance_leg = 0
        self.stance_foot = (0.0, 0.0)
        self.t = 0.0
        self.terrain = Terrain.flat()
        self._tx, self._ty = self.terrain.arrays()
        self.touchdowns_located = 0
        self.touchdowns_guessed = 0
        self.scan = np.zeros(self.offsets.size)
        self._scan_sum = np.zeros(self.offsets.size)
        self._scan_n = 0
        self.corrections: list[LocalisationResult] = []
        if self.localiser is not None:
            self.localiser.reset()
        if self.map is not None:
            self.map.reset()

    @property
    def x(self) -> np.ndarray:
        """The estimate ``[q1, q2, q1d, q2d]`` [rad, rad/s] (the observer's, updated in place)."""
        return self.observer.x

    def set_robot(self, robot: RobotParams) -> None:
        """Estimate with the model ``robot`` from now on (an identified one, say), keeping the
        estimate. With localisation, the learnt drift is re-referred to the new leg length
        (dead reckoning with the new ``l`` already moves the foot by the ratio of the two)."""
        obs = self.observer
        new = HighGainObserver(robot, self.dt, obs.eps)
        new.x[:] = obs.x
        new.q_last = obs.q_last.copy()
        if self.localiser is not None:
            ratio = robot.l / self.robot.l
            self.localiser.rescale(ratio)
        self.observer = new
        self.robot = robot
        self.P = robot.vector()

    def decode(self, obs: Any) -> tuple[np.ndarray, int]:
        """Measured ``q`` [rad] and the stance leg from one sensor observation.

        Raises:
            ValueError: the observation has the wrong size or is not finite.
        """
        o = np.asarray(obs, dtype=np.float64)
        lay = self.layout
        v = o.tolist() if o.shape == self._obs_shape else None
        if v is None or not all(map(math.isfinite, v)):
            raise ValueError(f"observation must be {lay.size} finite numbers")
        leg = stance_from_contacts(v[lay.contact_a], v[lay.contact_b], self.stance_leg)
        self.scan = o[self._scan].copy()
        return np.array(encoders_to_q(v[lay.hip], v[lay.leg_a], leg)), leg

    def update(self, q: np.ndarray, leg: int, u: float) -> str:
        """Take the decoded measurement of a new tick; ``u`` [input units] is the input applied
        over the period that ended with it. Returns ``"start"`` (first tick of an episode:
        the estimate starts at ``q`` and the initial velocity guess), ``"impact"`` (a touchdown
        happened in the period: estimate mapped, stance foot moved) or ``"tick"``.

        Raises:
            FloatingPointError: the estimate is no longer finite.
        """
        if not self.started:
            if self.map is not None:
                # the robot stands on level ground around its first foothold
                self.map.add(np.linspace(-0.1, 0.0, 21), np.zeros(21))
                self._add_scan((0.0, 0.0), self.scan, 1)
                self.terrain = self.map.terrain()
            else:
                terrain = getattr(self.env, "terrain", None)
                self.terrain = terrain if isinstance(terrain, Terrain) else Terrain.flat()
            self._tx, self._ty = self.terrain.arrays()
            self.stance_foot = (0.0, float(self.terrain.height(0.0)))
            self.stance_leg = leg
            self.observer.reset(q, self.initial_velocity)
            self._scan_sum[:] = self.scan
            self._scan_n = 1
            self.started = True
            return START
        self.t += self.dt
        event = TICK
        if leg != self.stance_leg:
            self._touchdown(q, u)
            self.stance_leg = leg
            event = IMPACT
        else:
            self.observer.update(q, u)
            self._scan_sum += self.scan
            self._scan_n += 1
        if not all(map(math.isfinite, self.observer.x.tolist())):
            raise FloatingPointError("non-finite observer estimate")
        return event

    def _touchdown(self, q_meas: np.ndarray, u: float) -> None:
        """Impact inside the last period: locate it, map the estimate, move the stance foot."""
        x = self.observer.x
        xs, ys = self.stance_foot
        found, tau, xpre, fx = predict_touchdown(
            self.P,
            x.copy(),
            u,
            2.0 * self.dt,  # the estimate may lag the touchdown a little: search a bit beyond
            self._tx,
            self._ty,
            self._tx.size,
            xs,
            ys,
            2 * self._nsub_td,
            # a crossing counts once the full-length swing foot is the robot's arming distance
            # ahead of the stance foot (the simulator's and the planner's rule)
            self.robot.arm_distance * self.robot.l,
        )
        if not found:  # take the state at the end of the period as the pre-impact state
            _, tau, xpre, fx = predict_touchdown(
                self.P,
                x.copy(),
                u,
                self.dt,
                self._tx,
                self._ty,
                self._tx.size,
                xs,
                ys,
                self._nsub_td,
                math.inf,
            )
        if found:
            self.touchdowns_located += 1
        else:
            self.touchdowns_guessed += 1
        x[:] = xpre
        observer_impact(self.P, x)
        rest = self.dt - min(tau, self.dt)
        if rest > 1e-9:
            # the measurement goes from the mapped estimate to the new sample
            nsub = substeps_for(rest, self.observer.eps)
            observer_update(
                self.P, x, x[0], x[1], q_meas[0], q_meas[1], u, rest, self.observer.eps, nsub
            )
        self.observer.q_last = q_meas.copy()
        self.stance_foot = self._locate(float(fx))

    def refresh_map(self) -> None:
        """Fuse the scans averaged since the last touchdown into the map now (``mapping``; the
        first stance's map otherwise rests on one noisy scan until the first touchdown)."""
        if self.map is None or self._scan_n == 0:
            return
        self._add_scan(self.stance_foot, self._scan_sum / self._scan_n, self._scan_n)
        self._scan_sum[:] = 0.0
        self._scan_n = 0
        self.terrain = self.map.terrain()
        self._tx, self._ty = self.terrain.arrays()

    def _add_scan(self, foot: tuple[float, float], scan: np.ndarray, readings: int) -> None:
        """Fuse ``scan`` (the mean of ``readings`` readings) taken from the stance foot
        ``foot`` [m] into the map."""
        self.map.add_scan(foot, self.offsets, self._clipped(scan), readings)

    def _clipped(self, scan: np.ndarray) -> np.ndarray:
        """``scan`` [m] with the readings clipped at the scanner's range replaced by NaN."""
        return np.where(np.abs(scan) < self._scan_range, scan, np.nan)

    def _locate(self, fx: float) -> tuple[float, float]:
        """The new stance foot from the dead-reckoned foothold ``fx`` [m]: corrected by the
        scans (``localise``: the mean scan over the last stance refines the last foothold,
        the new scan the new one) or fused into the map (``mapping``)."""
        xs, ys = self.stance_foot
        n = max(min(self._scan_n, _MAX_READINGS), 1)
        mean_scan = self._scan_sum / self._scan_n if self._scan_n else self.scan
        self._scan_sum[:] = self.scan
        self._scan_n = 1
        loc = self.localiser
        if loc is not None:
            shift = loc.update(xs, mean_scan, self.terrain.height, readings=n).shift
            fx += shift
            fx += loc.predict(fx - xs - shift)
            res = loc.update(fx, self.scan, self.terrain.height)
            self.corrections.append(res)
            fx += res.shift
            return (fx, float(self.terrain.height(fx)))
        if self.map is not None:
            # the last foothold's height refitted to the map with the stance's mean scan
            ys = self.map.foot_height(xs, self.offsets, self._clipped(mean_scan))
            self._add_scan((xs, ys), mean_scan, n)
            # the vertical offset that fits the new scan to the map (the contact's height)
            fy = self.map.foot_height(fx, self.offsets, self._clipped(self.scan))
            self.map.add([fx], [fy])  # the foothold is a reading of the ground too
            self._add_scan((fx, fy), self.scan, 1)
            self.terrain = self.map.terrain()
            self._tx, self._ty = self.terrain.arrays()
            return (fx, fy)
        return (fx, float(self.terrain.height(fx)))
