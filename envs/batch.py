"""The walkers behind both environments: :class:`WalkerBatch` and its compiled kernels.

A :class:`WalkerBatch` holds ``n`` walkers of one :class:`envs.settings.EnvSettings` on one
batched :class:`envs.physics.Simulator`. It takes the env's actions, turns them into hip torques
in its own buffer (:func:`envs.physics.actuator.actions_to_torques`; the unit chain of the hip
command is documented in :mod:`envs.physics.actuator`) and steps the simulator with them. After
every simulator step one compiled call computes
each walker's reward and episode counters and its observation (rescanning the terrain only when
the stance foot moved). :class:`envs.CompassGaitEnv` is a batch of one and the vector env a batch
of ``num_envs``, so both give the same numbers step by step.

Its buffers come in three groups: :class:`SimulatorViews` (the simulator's state, read in place),
:class:`EpisodeBuffers` (reward and counters) and :class:`ObservationBuffers` (sensor noise,
terrain scan, the latest observation and its delay line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numba import njit, prange

from .disturbances import PushSchedule, robot_dict
from .physics import model
from .physics.actuator import actions_to_torques
from .physics.kernel import (
    F_LEG,
    F_NIMP,
    F_STATUS,
    FAILURES,
    X_Q1,
    X_Q1D,
    X_Q2,
    X_Q2D,
    X_XS,
    X_YS,
)
from .physics.simulator import Simulator
from .physics.terrain import Terrain
from .sensors import (
    K_SCAN_RANGE,
    SensorConfig,
    SensorLayout,
    measure_walker,
    observation_bounds,
    scan_walker,
    seed_streams,
    state_walker,
)
from .settings import EnvSettings
from .task import W_ENERGY, W_FAILURE, W_PROGRESS, TerrainSource

#: batches at least this large use the multi-threaded kernels by default (below it the threads'
#: start-up cost exceeds the gain on a 2-core machine)
PARALLEL_MIN_WALKERS = 256
#: observation kernel modes
OBS_SENSORS, OBS_STATE = 0, 1
#: status code -> failure name (None while running), for batched infos
FAILURE_NAMES = np.array([None] + list(FAILURES[1:]), dtype=object)
RESET_OPTIONS = ("terrain", "state", "stance_leg", "reset_mask")


# ---------------------------------------------------------------------------- compiled step
# The kernels read the simulator's whole state and flag arrays (rows ``X_*``, ``F_*``) and its
# work array: those are C-contiguous for every batch size, so one compiled version serves the
# env and the vector env (column views such as ``sim.q`` are contiguous only for one walker).
@njit(cache=True)
def _observe_walker(i, mode, refresh, x, f, tx, ty, tn, settings, offsets, scan, streams, obs):
    if refresh:
        scan_walker(i, x[i, X_XS], x[i, X_YS], tx, ty, tn, offsets, scan)
    if mode == OBS_SENSORS:
        measure_walker(i, x[i, X_Q1], x[i, X_Q2], f[i, F_LEG], settings, scan, streams, obs)
    else:
        state_walker(i, x[i, X_Q1], x[i, X_Q2], x[i, X_Q1D], x[i, X_Q2D], f[i, F_LEG], scan,
                     settings[K_SCAN_RANGE], obs)  # fmt: skip


@njit(cache=True)
def _post_walker(i, P, x, f, work, wcol, new_fail, weights, hip_x, distance, step_work,
                 footsteps, reward, terminated):  # fmt: skip
    hx, _ = model.hip_position(P[i], x[i, X_Q1], x[i, X_Q2], x[i, X_XS], x[i, X_YS])
    progress = hx - hip_x[i]
    hip_x[i] = hx
    w = work[i, wcol]
    distance[i] += progress
    step_work[i] = w
    footsteps[i] += f[i, F_NIMP]
    r = weights[W_PROGRESS] * progress - weights[W_ENERGY] * w
    if new_fail[i]:
        r -= weights[W_FAILURE]
    if not math.isfinite(r):  # never with the simulator's divergence check; kept finite anyway
        r = -weights[W_FAILURE]
    reward[i] = r
    terminated[i] = f[i, F_STATUS] != 0


@njit(cache=True)
def _after_step_serial(mode, P, x, f, work, wcol, new_fail, tx, ty, tn, weights, settings,
                       offsets, scan, streams, hip_x, distance, step_work, footsteps, reward,
                       terminated, obs):  # fmt: skip
    """Rewards, counters and observations of every walker after a simulator step."""
    for i in range(x.shape[0]):
        _post_walker(i, P, x, f, work, wcol, new_fail, weights, hip_x, distance, step_work,
                     footsteps, reward, terminated)  # fmt: skip
        refresh = f[i, F_NIMP] > 0 or new_fail[i]  # the stance foot moved: rescan the terrain
        _observe_walker(i, mode, refresh, x, f, tx, ty, tn, settings, offsets, scan, streams,
                        obs)  # fmt: skip


@njit(cache=True, parallel=True)
def _after_step_parallel(mode, P, x, f, work, wcol, new_fail, tx, ty, tn, weights, settings,
                         offsets, scan, streams, hip_x, distance, step_work, footsteps, reward,
                         terminated, obs):  # fmt: skip
    """:func:`_after_step_serial` with the walkers spread over threads (same numbers)."""
    for i in prange(x.shape[0]):
        _post_walker(i, P, x, f, work, wcol, new_fail, weights, hip_x, distance, step_work,
                     footsteps, reward, terminated)  # fmt: skip
        refresh = f[i, F_NIMP] > 0 or new_fail[i]
        _observe_walker(i, mode, refresh, x, f, tx, ty, tn, settings, offsets, scan, streams,
                        obs)  # fmt: skip


@njit(cache=True)
def _observe(idx, mode, x, f, tx, ty, tn, settings, offsets, scan, streams, obs):
    """Observations of walkers ``idx`` after a reset (terrain rescanned)."""
    # a computed flag (True here), not the literal True: the literal would compile another
    # version of _observe_walker
    refresh = idx.size > 0
    for j in range(idx.size):
        _observe_walker(idx[j], mode, refresh, x, f, tx, ty, tn, settings, offsets, scan,
                        streams, obs)  # fmt: skip


# ---------------------------------------------------------------------------- buffers
@dataclass(frozen=True)
class SimulatorViews:
    """Views of a simulator's per-walker buffers (fixed arrays, updated in place by each step).

    Attributes:
        q, qd: ``(n, 2)`` joint angles [rad] and rates [rad/s].
        stance_foot: ``(n, 2)`` stance-foot position [m].
        stance_leg: ``(n,)`` physical stance leg (0 = A, 1 = B).
        status: ``(n,)`` failure code (0 while running).
        time: ``(n,)`` simulated time [s].
        n_impacts: ``(n,)`` touchdowns during the last step.
        new_failure: ``(n,)`` the walker failed during the last step.
        footholds: ``(n, K, 2)`` new stance-foot positions of the last step's touchdowns [m].
        work: ``(n,)`` the reward's kind of motor work over the last step [J].
        x6: ``(n, 6)`` ``(q1, q2, q1d, q2d, xs, ys)``, one strided view for batched infos.
        states, flags: the simulator's whole ``(n, 7)`` state and ``(n, 4)`` flag arrays
            (read-only, C-contiguous: what the compiled kernels read).
        works: ``(n, 3)`` the motor work of every kind over the last step [J].
        work_column: the column of ``works`` that is ``work``.
    """

    q: np.ndarray
    qd: np.ndarray
    stance_foot: np.ndarray
    stance_leg: np.ndarray
    status: np.ndarray
    time: np.ndarray
    n_impacts: np.ndarray
    new_failure: np.ndarray
    footholds: np.ndarray
    work: np.ndarray
    x6: np.ndarray
    states: np.ndarray
    flags: np.ndarray
    works: np.ndarray
    work_column: int

    @classmethod
    def of(cls, sim: Simulator, work_column: int) -> SimulatorViews:
        """The views of ``sim``; ``work_column`` picks the column of ``sim.events.work``."""
        ev = sim.events
        return cls(
            q=sim.q,
            qd=sim.qd,
            stance_foot=sim.stance_foot,
            stance_leg=sim.stance_leg,
            status=sim.status,
            time=sim.t,
            n_impacts=ev.n_impacts,
            new_failure=ev.new_failure,
            footholds=ev.foothold,
            work=ev.work[:, work_column],
            # the public q, qd and stance_foot views are slices of the simulator's state array
            x6=sim.states[:, :6],
            states=sim.states,
            flags=sim.flags,
            works=ev.work,
            work_column=int(work_column),
        )


@dataclass(frozen=True)
class EpisodeBuffers:
    """Per-walker reward and episode counters (own arrays, written by the step kernel).

    Attributes:
        hip_x: ``(n,)`` hip x after the last step [m].
        distance: ``(n,)`` hip displacement since the reset [m].
        step_work: ``(n,)`` motor work of the last step [J].
        footsteps: ``(n,)`` touchdowns since the reset.
        reward: ``(n,)`` reward of the last step.
        terminated: ``(n,)`` the walker has failed.
    """

    hip_x: np.ndarray
    distance: np.ndarray
    step_work: np.ndarray
    footsteps: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray

    @classmethod
    def zeros(cls, n: int) -> EpisodeBuffers:
        """Buffers of ``n`` walkers, all zero."""
        return cls(
            hip_x=np.zeros(n),
            distance=np.zeros(n),
            step_work=np.zeros(n),
            footsteps=np.zeros(n, dtype=np.int64),
            reward=np.zeros(n),
            terminated=np.zeros(n, dtype=bool),
        )

    def reset(self, i: int, hip_x: float) -> None:
        """Start walker ``i``'s episode with its hip at ``hip_x`` [m]."""
        self.hip_x[i] = hip_x
        self.distance[i] = 0.0
        self.step_work[i] = 0.0
        self.footsteps[i] = 0
        self.reward[i] = 0.0
        self.terminated[i] = False


class ObservationBuffers:
    """What the observation kernel reads and writes for ``n`` walkers, and the delay line.

    Args:
        sensors: the sensor settings.
        observation: ``"sensors"`` or ``"state"``.
        n: number of walkers.
        dim: length of one observation.

    Attributes:
        mode: :data:`OBS_SENSORS` or :data:`OBS_STATE`.
        settings: :meth:`envs.sensors.SensorConfig.kernel_vector`.
        offsets: ``(N,)`` scan offsets ahead of the stance foot [m].
        streams: ``(n,)`` noise stream states (seeded at every reset).
        scan: ``(n, N)`` exact terrain heights ahead of the stance foot [m].
        fresh: ``(n, dim)`` float32 observation of the current state.
        latency: delay of the observations returned, in control periods (0 for ``"state"``).
    """

    def __init__(self, sensors: SensorConfig, observation: str, n: int, dim: int):
        self.mode = OBS_SENSORS if observation == "sensors" else OBS_STATE
        self.settings = sensors.kernel_vector()
        self.offsets = sensors.scan_offsets
        self.latency = sensors.latency if self.mode == OBS_SENSORS else 0
        self.streams = np.zeros(n, dtype=np.uint64)
        self.scan = np.zeros((n, sensors.scan_count))
        self.fresh = np.zeros((n, dim), dtype=np.float32)
        self._ring = np.zeros((self.latency + 1, n, dim), dtype=np.float32)
        self._ring_pos = 0

    def fill(self, i: int) -> None:
        """Fill walker ``i``'s delay line with its fresh observation (after a reset)."""
        self._ring[:, i] = self.fresh[i]

    def push(self) -> None:
        """Enter the fresh observations into the delay line (after a step)."""
        if self.latency:
            self._ring_pos = (self._ring_pos + 1) % (self.latency + 1)
            self._ring[self._ring_pos] = self.fresh

    def delayed(self) -> np.ndarray:
        """The observations returned now, ``(n, dim)`` (a view: copy it to keep it)."""
        if self.latency:
            # the oldest entry of the ring: written `latency` steps ago
            return self._ring[(self._ring_pos + 1) % (self.latency + 1)]
        return self.fresh


# ---------------------------------------------------------------------------- the batch
class WalkerBatch:
    """``n`` walkers of one environment configuration on one batched simulator.

    Holds the simulator, observation buffers (with the latency delay line), reward and episode
    counters. Both :class:`envs.CompassGaitEnv` (``n = 1``) and the vector env use it.

    Args:
        settings: the environment's settings.
        n: number of walkers, >= 1.
        parallel: use the multi-threaded kernels (default: ``n >= PARALLEL_MIN_WALKERS`` and
            numba has more than one thread); the numbers are the same.
    """

    def __init__(self, settings: EnvSettings, n: int, parallel: bool | None = None):
        self.settings = s = settings
        self.n = n
        self.robot = s.robot
        self.torque_limit = s.robot.tau_max  # hip torque at |action| = 1 [N m], nominal robot
        if parallel is None:
            parallel = n >= PARALLEL_MIN_WALKERS and numba.get_num_threads() > 1
        par = bool(parallel)
        self.sim = Simulator(
            s.robot, s.terrain.preview(), n, dt=s.dt, config=s.simulator, parallel=par
        )
        self._P = self.sim.param_vectors  # (n, N_PARAMS): the simulated (true) robots
        self._after_step = _after_step_parallel if par else _after_step_serial
        # model error: each walker's true hip torque at |action| = 1 [N m], and its parameters
        self._tau_limits = np.full(n, self.torque_limit) if s.robot_error.enabled else None
        self.robots = np.full(n, None, dtype=object)  # the true parameters, dicts of floats
        self.pushes = PushSchedule(s.push, n) if s.push is not None else None
        self.layout = SensorLayout.from_config(s.sensors)
        low, high = observation_bounds(s.sensors, s.observation)
        self.obs_low, self.obs_high = low, high
        self.obs_dim = low.size
        self._weights = s.reward.weights()
        self.sim_views = SimulatorViews.of(self.sim, s.reward.work_column)
        self.episode = EpisodeBuffers.zeros(n)
        self.obs_buffers = ObservationBuffers(s.sensors, s.observation, n, self.obs_dim)
        self._torques = np.zeros(n)  # hip torques of the current step [N m]
        self.terrains: list[Terrain | None] = [None] * n
        self.specs = np.full(n, None, dtype=object)
        self.track_footholds = False
        self.footholds: list[list[tuple[float, float]]] = [[] for _ in range(n)]
        self._no_failure = np.full(n, None, dtype=object)

    # ------------------------------------------------------------------ reset
    def reset_walker(
        self, i: int, rng: np.random.Generator, options: dict[str, Any] | None = None
    ) -> None:
        """Start a new episode of walker ``i``; all randomness is drawn from ``rng``.

        ``options`` are the reset options of :class:`envs.CompassGaitEnv` (``"terrain"``,
        ``"state"``, ``"stance_leg"``; the vector env's ``"reset_mask"`` is ignored here).
        """
        s, v, o = self.settings, self.sim_views, self.obs_buffers
        opts = options or {}
        unknown = sorted(set(opts) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {unknown}; allowed: 'terrain', 'state', 'stance_leg'"
            )
        if opts.get("terrain") is not None:
            terrain = TerrainSource(opts["terrain"]).draw(rng)
        else:
            terrain = s.terrain.draw(rng)
        if terrain is not self.sim.terrains[i] or self.terrains[i] is None:
            self.sim.set_terrain(terrain, index=i)
            self.specs[i] = terrain.to_dict()
        self.terrains[i] = terrain
        q, qd, leg = s.initial_state.sample(rng, opts.get("state"), opts.get("stance_leg"))
        o.streams[i] = seed_streams(rng, 1)[0]
        if self._tau_limits is not None:
            robot = s.robot_error.draw(s.robot, rng)
            self.sim.set_params(robot, index=i)
            self._tau_limits[i] = robot.tau_max
            self.robots[i] = robot_dict(robot)
        if self.pushes is not None:
            self.pushes.reset(i, rng)
        try:
            self.sim.reset(q, qd, index=i, stance_leg=leg)
        except ValueError as exc:
            source = "reset option 'state'" if opts.get("state") is not None else "initial_state"
            raise ValueError(f"{source}: {exc}") from None
        hx, _ = model.hip_position(self._P[i], v.q[i, 0], v.q[i, 1], *v.stance_foot[i])
        self.episode.reset(i, hx)
        self.footholds[i] = [(float(v.stance_foot[i, 0]), float(v.stance_foot[i, 1]))]
        tx, ty, tn = self.sim.terrain_arrays
        _observe(
            np.array([i]), o.mode, v.states, v.flags, tx, ty, tn, o.settings, o.offsets, o.scan,
            o.streams, o.fresh,
        )  # fmt: skip
        o.fill(i)

    # ------------------------------------------------------------------ step
    def step(self, actions: Any) -> None:
        """Advance every walker by one control period under its action.

        Args:
            actions: ``(n,)`` or ``(n, 1)`` normalised hip commands [-], clipped to [-1, 1];
                the hip torque is ``action * torque_limit`` [N m], held over the period.

        Raises:
            ValueError: a NaN or infinite action, or a wrong shape (no walker is advanced).
        """
        v, e, o = self.sim_views, self.episode, self.obs_buffers
        if self._tau_limits is None:
            actions_to_torques(actions, self.torque_limit, self._torques)
        else:  # clip(a) * 1.0 is exact: the same torques as with the limit in the kernel
            actions_to_torques(actions, 1.0, self._torques)
            self._torques *= self._tau_limits
        if self.pushes is not None:
            self.pushes.apply(self.sim)
        self.sim.step(self._torques)
        if self.pushes is not None:
            self.pushes.after_step(v.n_impacts)
        tx, ty, tn = self.sim.terrain_arrays
        self._after_step(
            o.mode, self._P, v.states, v.flags, v.works, v.work_column, v.new_failure, tx, ty,
            tn, self._weights, o.settings, o.offsets, o.scan, o.streams, e.hip_x, e.distance,
            e.step_work, e.footsteps, e.reward, e.terminated, o.fresh,
        )  # fmt: skip
        o.push()
        if self.track_footholds:
            for i in np.nonzero(v.n_impacts)[0]:
                for k in range(int(v.n_impacts[i])):
                    fx, fy = v.footholds[i, k]
                    self.footholds[i].append((float(fx), float(fy)))

    @property
    def reward(self) -> np.ndarray:
        """``(n,)`` reward of the last step (the batch's buffer)."""
        return self.episode.reward

    @property
    def terminated(self) -> np.ndarray:
        """``(n,)`` the walker has failed (the batch's buffer)."""
        return self.episode.terminated

    def observations(self) -> np.ndarray:
        """Copy of the current (possibly delayed) observations, ``(n, dim)`` float32."""
        return self.obs_buffers.delayed().copy()

    def observation(self, i: int) -> np.ndarray:
        """Copy of walker ``i``'s current observation."""
        return self.obs_buffers.delayed()[i].copy()

    # ------------------------------------------------------------------ info
    def info(self, i: int, terrain: bool = True) -> dict[str, Any]:
        """Info dict of walker ``i`` (true state etc.; see :class:`envs.CompassGaitEnv`); with
        ``terrain``, also the course's spec (and the true robot under a model error)."""
        v, e = self.sim_views, self.episode
        q, qd, foot = v.q[i], v.qd[i], v.stance_foot[i]
        status = int(v.status[i])
        info = {
            "state": np.array((q[0], q[1], qd[0], qd[1])),
            "stance_foot": np.array((foot[0], foot[1])),
            "stance_leg": int(v.stance_leg[i]),
            "time": float(v.time[i]),
            "footsteps": int(e.footsteps[i]),
            "distance": float(e.distance[i]),
            "impacts": int(v.n_impacts[i]),
            "motor_work": float(e.step_work[i]),
            "failure": FAILURES[status] if status else None,
        }
        if terrain:
            info["terrain"] = dict(self.specs[i])
            if self.robots[i] is not None:
                info["robot"] = dict(self.robots[i])
        if self.pushes is not None and self.pushes.pushed[i]:
            info["push"] = self.pushes.info(i)
        return info

    def infos(self) -> dict[str, Any]:
        """Batched info (arrays over walkers, with Gymnasium's ``_key`` masks all True)."""
        v, e = self.sim_views, self.episode
        x = v.x6.copy()  # one copy of (q1, q2, q1d, q2d, xs, ys) for all walkers
        if v.status.any():
            failure = FAILURE_NAMES[v.status]
        else:
            failure = self._no_failure.copy()
        d = {
            "state": x[:, :4],
            "stance_foot": x[:, 4:6],
            "stance_leg": v.stance_leg.copy(),
            "time": v.time.copy(),
            "footsteps": e.footsteps.copy(),
            "distance": e.distance.copy(),
            "impacts": v.n_impacts.copy(),
            "motor_work": e.step_work.copy(),
            "failure": failure,
            "terrain": self.specs.copy(),
        }
        if self._tau_limits is not None:
            d["robot"] = self.robots.copy()
        mask = np.ones(self.n, dtype=bool)  # one array shared by all keys (every entry is valid)
        for key in list(d):
            d["_" + key] = mask
        if self.pushes is not None and self.pushes.pushed.any():
            d["push"] = self.pushes.infos()
            d["_push"] = self.pushes.pushed.copy()
        return d

    def render_args(self, i: int) -> dict[str, Any]:
        """Keyword arguments of :meth:`envs.rendering.WalkerRenderer.render` for walker ``i``."""
        v = self.sim_views
        t = self.sim.terrains[i]
        status = int(v.status[i])
        return {
            "q": v.q[i],
            "stance_foot": v.stance_foot[i],
            "stance_leg": int(v.stance_leg[i]),
            "terrain_xs": t.xs,
            "terrain_ys": t.ys,
            "leg_length": self.sim.params[i].l,
            "footholds": self.footholds[i],
            "time": float(v.time[i]),
            "distance": float(self.episode.distance[i]),
            "steps": int(self.episode.footsteps[i]),
            "failure": FAILURES[status] if status else None,
        }
