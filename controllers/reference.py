"""Reference policy for the Gymnasium environments: observer + planner + transverse controller.

The policy sees what the paper's controller sees: the sensor observation (two encoders, two
contact switches; the terrain scan with ``localise`` or ``mapping``) plus what the environment
tells a controller about the world and the robot (``env.unwrapped``: ``robot``, ``terrain``,
``dt``, ``u_max``, ``sensor_layout``; with ``mapping`` not the terrain: it plans on a map built
from the scans). It never reads the true state.

Every tick the state estimator (:class:`controllers.estimator.SensorStateEstimator`: encoders
and contact switches decoded into ``q`` and the stance leg, the high-gain observer, touchdowns
located on the terrain map) updates the estimate with the input applied over the last period,
and the controller's input is applied to the estimate. In the default ``replan`` mode
(:attr:`ControllerConfig.mode`) the controller replans from the mapped estimate at every
located touchdown, and, shortly after the start, once the observer has converged
(``settle_time``), replans the current step from the estimate. In ``fixed-plan`` mode it
tracks the plan made at the start and only advances it at each touchdown.

Model: the policy starts on the env's nominal robot and, after each of the first ``identify``
footsteps, fits the swing dynamics to the encoder readings and inputs of the stances walked
(:mod:`controllers.identification`); where the data reject the model in use, the estimator,
planner and feedback switch to the identified robot there, before the replan at that touchdown.

Safe behaviour: if planning fails, the controller degrades in the order of
``ControllerConfig.fallbacks`` (relaxed planning settings, the previous plan, the
least-violating steps, then a single step held with PD on ``y``; see
:mod:`controllers.controller`) and keeps tracking a motion while the robot is upright; zero
input is left only for when there is nothing to track. If anything else fails inside a tick (a
non-finite estimate, say), the policy applies zero input for the rest of the episode. Both are
recorded in :attr:`ReferencePolicy.diagnostics` (``"fallbacks"``: ``(kind, time, reason)``). A
call never raises because of the robot's state.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import gymnasium as gym
import numpy as np

from envs.physics.actuator import action_from_input, input_from_action

from .controller import ControllerConfig, PDController, TransverseController
from .estimator import IMPACT, START, SensorStateEstimator
from .identification import DEFAULT_LONG_SEGMENT, SwingIdentifier, robot_from_coefficients
from .planner import GaitPlanner, PlannerConfig
from .records import IdentificationRecord

__all__ = ["ADDED_SETTINGS", "PDPolicy", "ReferencePolicy", "make_reference_policy"]

#: footsteps after which the reference policy identifies the swing dynamics by default
DEFAULT_IDENTIFY = 6
#: the leg length is re-identified when the localisation's drift is this many of its standard
#: deviations from zero
DRIFT_Z = 1.5
#: an identified robot replaces the one in use when a coefficient or the leg length changes by
#: more than this fraction (a new planner computes its periodic gait, about 0.1-0.5 s)
MODEL_CHANGE = 0.01
#: the leg-length margin's widening is rounded to this [m] (a new planner whenever it changes)
MARGIN_QUANTUM = 0.0025
#: the largest leg_margin and drop_edge_sd [standard deviations]
MAX_LEG_MARGIN = 10.0
#: drop_edge_sd's largest preference margin [m]: about the 2-3 cm by which a foot lands off its
#: plan on a leg 10 % longer or shorter than the model's, before the scans have measured it
DROP_EDGE_CAP = 0.03
#: drop_edge_sd where the policy localises [standard deviations] (without the localisation,
#: which measures the leg length, 0)
DEFAULT_DROP_EDGE_SD = 9.0
#: options of :meth:`ReferencePolicy.settings` added after trained runs began recording their
#: base (``agents.policies.base_settings``), each with the value that does what the policy did
#: before it existed (nested as in the settings: a planner field under ``"planner"``): a base
#: recorded without one had it
ADDED_SETTINGS: dict[str, Any] = {
    "foot_estimate": "mean",
    "long_segment": 0.0,
    "drop_edge_sd": 0.0,
    "planner": {
        "speed_reserve": 0.0,
        "dip_floor": 0.0,
        "drop_edge_margin": 0.0,
        "beam_coarse": 0,
        "beam_full": 1,
        "beam_far": 1,
        "compiled_sqp": 0,
    },
    "controller": {"posture_hold": False, "replan_beam_evaluations": 0},
}


def checked_deviations(name: str, value: Any) -> float:
    """A margin in standard deviations of the leg-length uncertainty (:class:`ReferencePolicy`'s
    ``leg_margin`` and ``drop_edge_sd``): a number in [0, :data:`MAX_LEG_MARGIN`]; anything else
    raises ``ValueError`` naming it and the range."""
    allowed = f"allowed: a number in [0, {MAX_LEG_MARGIN}] (standard deviations)"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise ValueError(f"{name} = {value!r}; {allowed}")
    if not (math.isfinite(value) and 0 <= value <= MAX_LEG_MARGIN):
        raise ValueError(f"{name} = {value!r}; {allowed}")
    return float(value)


def checked_long_segment(value: Any) -> float:
    """The identification's long segments [s] (:class:`ReferencePolicy`'s ``long_segment``):
    a number in [0, 1]; anything else raises ``ValueError`` naming it and the range."""
    allowed = "allowed: a number in [0, 1] (s; 0: short segments only)"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise ValueError(f"long_segment = {value!r}; {allowed}")
    if not (math.isfinite(value) and 0 <= value <= 1):
        raise ValueError(f"long_segment = {value!r}; {allowed}")
    return float(value)


class ReferencePolicy:
    """Sensor-based walking policy: ``action = policy(observation)``.

    Args:
        env: the environment (as ``gym.make`` returns it; wrappers are looked through).
        config: :class:`ControllerConfig`, or a dict of the fields that differ from the robot's
            defaults (:meth:`ControllerConfig.for_robot`; default: those, which replan at every
            footstep with h = 3).
        planner: :class:`GaitPlanner`, :class:`PlannerConfig`, dict or None (robot default).
        eps: observer time constant [s]; None: from the encoders' noise
            (:func:`controllers.observer.eps_for_noise`: 0.04 on the nominal sensors, 0.11 with
            five times their noise; the paper's: 0.02).
        settle_time: time after the start at which the current step is replanned from the
            observer's estimate [s].
        initial_velocity: velocity guess ``(q1d, q2d)`` [rad/s] for the observer at the start;
            default: the environment's nominal start velocity (its configuration, not the
            episode's true state), else zero.
        record_history: keep per-tick ``t, q_meas, x_hat, u, stance_leg, nominal`` in
            :attr:`history` (nominal: ``q1, q1d, q2d`` of the current step at the estimated
            phase).
        localise: correct the stance foot at each touchdown from the terrain scan matched
            against the map (:class:`SensorStateEstimator`; default: on, unless ``mapping``;
            off, the stance foot is dead-reckoned from the model). Needs the scanner
            (``sensors.scan_count >= 2``): without it the default is off.
        mapping: plan on a map built from the terrain scans as the robot walks, never reading
            the true course (:class:`SensorStateEstimator`).
        odometry_error: relative standard deviation of a dead-reckoned step length (the
            localisation's process noise), >= 0.
        foot_estimate: the point of the localisation's belief the stance foot is corrected to:
            ``"mean"`` (default) or ``"selected"``, the mean given the likelier of a right and
            a wrong model (:class:`controllers.localisation.ScanLocaliser`; needs
            ``localise``).
        identify: identify the swing dynamics online (:mod:`controllers.identification`):
            after each of the first ``identify`` footsteps the coefficients are fitted to the
            stances walked so far, and the estimator, planner and feedback switch to the
            nearest robot with them (its leg length from the localisation's drift when
            ``localise`` is on, else the nominal one) when the data reject the model in use;
            0: off (the nominal model throughout). Default :data:`DEFAULT_IDENTIFY`. The fits
            are in :attr:`diagnostics` (``"identified"``: one
            :class:`controllers.records.IdentificationRecord` per fit).
        long_segment: the identification's long shooting segments [s], in [0, 1]: where each
            of them is explained (no push seen) their fit, which sees the level of the stance
            leg's inertia and gravity, replaces the fit on the short segments where that fit
            rejects the nominal model; 0: short segments only (the fits of releases before
            this default). Default :data:`controllers.identification.DEFAULT_LONG_SEGMENT`.
        leg_margin: foothold margins from the leg-length uncertainty: at every touchdown the
            planner's ``edge_margin`` is widened by ``leg_margin`` standard deviations of where
            a step of ``step_length`` lands, from the localiser's belief about the drift rate
            (the relative error of the model's step length, i.e. of its leg length), rounded
            to :data:`MARGIN_QUANTUM`; wide at the first footsteps, before the scans measure
            the leg, and about nothing once they have. Needs ``localise``; 0 (default): off.
            [standard deviations], in [0, :data:`MAX_LEG_MARGIN`].
        drop_edge_sd: footholds near a step-down riser ranked last while the leg length is
            uncertain: at every touchdown the planner's ``drop_edge_margin`` becomes
            ``drop_edge_sd`` standard deviations of where a step of ``step_length`` lands
            (as for ``leg_margin``), rounded to :data:`MARGIN_QUANTUM`, at most
            :data:`DROP_EDGE_CAP` (the configured margin where that is larger). A foot that
            lands off its plan otherwise passes such a riser and swings back into its face;
            once the scans have measured the leg the margin is a few millimetres. Needs
            ``localise``; 0: off; None (default): :data:`DEFAULT_DROP_EDGE_SD` where the
            policy localises, else 0. [standard deviations], in [0, :data:`MAX_LEG_MARGIN`].
        controller_kwargs: passed to the controller class (``kp``, ``kd`` for :class:`PDPolicy`).
    """

    controller_class = TransverseController

    def __init__(
        self,
        env: gym.Env,
        config: ControllerConfig | dict | None = None,
        planner: GaitPlanner | PlannerConfig | dict | None = None,
        eps: float | None = None,
        settle_time: float = 0.1,
        initial_velocity: tuple[float, float] | None = None,
        record_history: bool = False,
        localise: bool | None = None,
        mapping: bool = False,
        odometry_error: float = 0.02,
        foot_estimate: str = "mean",
        identify: int = DEFAULT_IDENTIFY,
        long_segment: float = DEFAULT_LONG_SEGMENT,
        leg_margin: float = 0.0,
        drop_edge_sd: float | None = None,
        **controller_kwargs: Any,
    ):
        est = self.estimator = SensorStateEstimator(
            env, eps, initial_velocity, localise, mapping, odometry_error, foot_estimate
        )
        self.robot, self.u_max = est.robot, est.u_max
        self.nominal_robot = self.robot
        if isinstance(identify, bool) or not isinstance(identify, (int, np.integer)):
            raise ValueError(f"identify = {identify!r}; allowed: an integer >= 0 (footsteps)")
        if identify < 0:
            raise ValueError(f"identify = {identify!r}; allowed: an integer >= 0 (footsteps)")
        self.identify = int(identify)
        self.long_segment = checked_long_segment(long_segment)
        self.leg_margin = checked_deviations("leg_margin", leg_margin)
        if drop_edge_sd is None:
            drop_edge_sd = DEFAULT_DROP_EDGE_SD if est.localiser is not None else 0.0
        self.drop_edge_sd = checked_deviations("drop_edge_sd", drop_edge_sd)
        for name in ("leg_margin", "drop_edge_sd"):
            if getattr(self, name) and est.localiser is None:
                raise ValueError(
                    f"{name}: needs the terrain-scan localisation (localise on, a scanner), "
                    "which measures the leg length"
                )
        self.odometry_error = float(odometry_error)
        self.identifier: SwingIdentifier | None = None
        if self.identify:
            self.identifier = SwingIdentifier(
                self.robot, est.dt, est.angle_sigma, long_segment=self.long_segment
            )
        # the episode's course is known at its first tick: the controller gets it at reset
        self.controller = self.controller_class(
            self.robot, est.terrain, config, planner, **controller_kwargs
        )
        self.initial_velocity = est.initial_velocity
        self.settle_time = float(settle_time)
        self.record_history = bool(record_history)
        self.reset()

    def settings(self) -> dict[str, Any]:
        """What the policy does, resolved: its controller's and planner's settings (every
        field, the robot's defaults filled in) and its own options, in JSON types (a run
        records its base policy's, ``agents.policies.base_settings``)."""
        ctrl = self.controller
        out: dict[str, Any] = {
            "policy": type(self).__name__,
            "controller": ctrl.config.to_dict(),
            "planner": ctrl.configured_planner.config.to_dict(),
            "observer_eps": float(self.estimator.observer.eps),
            "localise": self.estimator.localise,
            "mapping": self.estimator.mapping,
            "odometry_error": self.odometry_error,
            "foot_estimate": self.estimator.foot_estimate,
            "identify": self.identify,
            "long_segment": self.long_segment,
            "leg_margin": self.leg_margin,
            "drop_edge_sd": self.drop_edge_sd,
            "settle_time": self.settle_time,
        }
        for gain in ("kp", "kd"):  # the PD controller's
            if hasattr(ctrl, gain):
                out[gain] = float(getattr(ctrl, gain))
        return json.loads(json.dumps(out))

    # ------------------------------------------------------------------ episode
    def reset(self) -> None:
        """Forget the episode (call after ``env.reset``); the next call starts a new one."""
        if self.robot is not self.nominal_robot:  # the last episode's identified robot
            self.estimator.set_robot(self.nominal_robot)
            self.controller.set_robot(self.nominal_robot)
            self.robot = self.nominal_robot
        self.estimator.reset()
        if self.identifier is not None:
            self.identifier.reset()
        self._stance_q: list[np.ndarray] = []
        self._stance_u: list[float] = []
        self._u = 0.0
        self._settled = False
        self._dead = False
        self.diagnostics: dict[str, Any] = {
            "footsteps": 0,
            "fallbacks": [],
            "touchdowns_located": 0,
            "touchdowns_guessed": 0,
            "identified": [],
            "error": None,
        }
        self.history: dict[str, list] = {
            "t": [],
            "q_meas": [],
            "x_hat": [],
            "u": [],
            "stance_leg": [],
            "nominal": [],
        }

    @property
    def stance_foot(self) -> tuple[float, float]:
        """Estimated stance-foot position ``(x, y)`` [m]."""
        return self.estimator.stance_foot

    @property
    def terrain(self) -> Any:
        """The terrain map of the episode (the env's course, or the map built from the scans)."""
        return self.estimator.terrain

    def applied(self, action: Any) -> None:
        """Tell the policy the action actually applied over the current period, when it differs
        from the one it returned (a residual added to it, say): the observer integrates the
        model with the applied input (``clip(action, -1, 1) * u_max`` [input units])."""
        a = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
        u = input_from_action(a, self.u_max)
        if not math.isfinite(u):
            raise ValueError(f"applied action must be finite, got {action!r}")
        self._u = u

    @property
    def records(self) -> list:
        """The controller's per-footstep :class:`StepRecord` list."""
        return self.controller.records

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Action (float32, shape (1,)) for one sensor observation."""
        q, leg = self.estimator.decode(obs)
        if self._dead:
            return np.zeros(1, dtype=np.float32)
        try:
            u = self._tick(q, leg)
        except Exception as exc:  # never crash a rollout: record and go limp
            self._dead = True
            self.diagnostics["error"] = f"{type(exc).__name__}: {exc}"
            self.diagnostics["fallbacks"].append(("zero input", self.estimator.t, str(exc)))
            u = 0.0
        a = action_from_input(u, self.u_max)
        # the input applied unless `applied` says otherwise
        self._u = input_from_action(a, self.u_max)
        return np.array([a], dtype=np.float32)

    def _tick(self, q: np.ndarray, leg: int) -> float:
        est = self.estimator
        if self._stance_q:
            self._stance_u.append(self._u)  # the input over the period that just ended
        event = est.update(q, leg, self._u)
        x = est.x
        if self.identifier is not None:
            if event == IMPACT:
                self._identify()
                self._stance_q, self._stance_u = [], []
            self._stance_q.append(q.copy())
        if event in (START, IMPACT):
            self._widen_margins()
        if event == START:
            self.controller.reset(
                x[:2].copy(),
                self.initial_velocity.copy(),
                est.stance_foot,
                t=0.0,
                terrain=est.terrain,
            )
        if event == IMPACT:
            self.diagnostics["footsteps"] += 1
            self.diagnostics["touchdowns_located"] = est.touchdowns_located
            self.diagnostics["touchdowns_guessed"] = est.touchdowns_guessed
            # with mapping, the map grew with the new scan
            new_map = est.terrain if est.map is not None else None
            self.controller.on_impact(
                x[:2].copy(), x[2:].copy(), est.stance_foot, t=est.t, terrain=new_map
            )
            self._note_fallback()
        if event != START and not self._settled and est.t >= self.settle_time - 1e-12:
            self._settled = True
            new_map = None
            if est.map is not None:  # the first scans, averaged, before the first replan
                est.refresh_map()
                new_map = est.terrain
            self.controller.replan(x[:2].copy(), x[2:].copy(), terrain=new_map)
            self._note_fallback()
        u = self.controller.control_state(x)
        if self.record_history:
            h = self.history
            h["t"].append(est.t)
            h["q_meas"].append(q.copy())
            h["x_hat"].append(x.copy())
            h["u"].append(u)
            h["stance_leg"].append(est.stance_leg)
            h["nominal"].append(self.controller.nominal(x[1]))
        return u

    def _widen_margins(self) -> None:
        """Widen the planner's foothold margins by :attr:`leg_margin` standard deviations of
        where a step of the configured length lands from the leg-length uncertainty (the
        localiser's drift-rate belief), and its drop-edge preference to :attr:`drop_edge_sd`
        of them (at most :data:`DROP_EDGE_CAP`), in steps of :data:`MARGIN_QUANTUM`."""
        loc = self.estimator.localiser
        if not (self.leg_margin or self.drop_edge_sd) or loc is None:
            return
        sd = self.controller.configured_planner.config.step_length * loc.drift_sd

        def quantised(z: float) -> float:
            return MARGIN_QUANTUM * math.floor(z * sd / MARGIN_QUANTUM + 0.5)

        drop_edge = min(DROP_EDGE_CAP, quantised(self.drop_edge_sd))
        self.controller.widen_margins(quantised(self.leg_margin), drop_edge)

    def _identify(self) -> None:
        """A stance ended: fit the swing dynamics to the stances so far and switch the model
        (the first :attr:`identify` footsteps)."""
        n = self.diagnostics["footsteps"] + 1  # the footstep that just ended the stance
        if n > self.identify or len(self._stance_q) != len(self._stance_u):
            return
        t0 = time.perf_counter()
        est, l = self.estimator, self.robot.l  # noqa: E741
        loc = est.localiser
        if loc is not None and abs(loc.drift) > DRIFT_Z * loc.drift_sd:
            l = self.robot.l * (1.0 + loc.drift)  # noqa: E741  (a drift the scans are sure of)
        ident = self.identifier
        ident.leg_length = l
        ident.add_stance(np.asarray(self._stance_q), np.asarray(self._stance_u))
        fit = ident.fit()
        if fit is None:
            return
        # data that do not reject the nominal model (with its leg) bring it back
        robot, note = self.nominal_robot, None
        if fit.significant or l != self.nominal_robot.l:
            try:
                robot = robot_from_coefficients(self.nominal_robot, fit.theta, l)
            except ValueError as exc:
                robot, note = self.robot, str(exc)
        old, new = self.robot.coefficients(), robot.coefficients()
        change = max(abs(new[k] / old[k] - 1.0) for k in ("p1", "p2", "p3", "p4", "p5"))
        # below MODEL_CHANGE the model in use already explains the data: no new planner
        switch = max(change, abs(robot.l / self.robot.l - 1.0)) >= MODEL_CHANGE
        if switch:
            est.set_robot(robot)
            self.controller.set_robot(robot)
            self.robot = robot
        self.diagnostics["identified"].append(
            IdentificationRecord(
                n,
                tuple(fit.relative.tolist()),
                fit.distance2,
                self.robot.l,
                switch,
                time.perf_counter() - t0,
                note,
            )
        )

    def _note_fallback(self) -> None:
        rec = self.controller.records[-1] if self.controller.records else None
        if rec is not None and rec.fallback is not None:
            self.diagnostics["fallbacks"].append((rec.fallback, self.estimator.t, rec.reason))


class PDPolicy(ReferencePolicy):
    """The reference policy with the transverse feedback replaced by plain PD on ``y``
    (:class:`controllers.controller.PDController`; keyword arguments ``kp``, ``kd``)."""

    controller_class = PDController


def make_reference_policy(env: gym.Env, **kwargs: Any) -> ReferencePolicy:
    """The reference policy for ``env`` (see :class:`ReferencePolicy` for the options)."""
    return ReferencePolicy(env, **kwargs)
