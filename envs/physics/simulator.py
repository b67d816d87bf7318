"""Hybrid simulator of the compass-gait biped: the :class:`Simulator` (a batch of walkers stepped
by control periods) and :func:`simulate` for one walker; their settings :class:`SimConfig`
live in :mod:`envs.physics.sim_config` (imported here too).

The rules of the hybrid model (retractable feet, touchdown, impact checks, failures) are those
of the compiled kernel, :mod:`envs.physics.kernel`; see also the README section "Simulator".
Time is held in float64 seconds; the hip input is the hip torque in N m (the actuator limit
``u_max`` is the environment's business, not the simulator's).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from . import model
from .kernel import (
    E_FX,
    E_FY,
    E_POST,
    E_PRE,
    E_T,
    F_ARMED,
    F_LEG,
    F_NIMP,
    F_STATUS,
    FAILURES,
    N_E,
    N_F,
    N_O,
    N_X,
    OK,
    X_Q1,
    X_Q1D,
    X_Q2,
    X_Q2D,
    X_T,
    X_XS,
    X_YS,
    initial_flags,
    step_parallel,
    step_serial,
)
from .params import N_PARAMS, RobotParams, as_params
from .sim_config import SimConfig
from .terrain import Terrain, as_terrain


# ---------------------------------------------------------------------------- Python API
@dataclass(frozen=True)
class StepEvents:
    """What happened to each walker during the last :meth:`Simulator.step`.

    The arrays are views of the simulator's buffers, overwritten by the next step (copy them
    to keep them).

    Attributes:
        n_impacts: (N,) int, touchdowns during the step.
        impact_time: (N, K) float, impact times [s]; entries ``>= n_impacts[i]`` are stale.
        foothold: (N, K, 2) float, new stance-foot positions [m].
        pre_impact: (N, K, 4) float, ``(q1, q2, q1d, q2d)`` just before each impact.
        post_impact: (N, K, 4) float, the same just after (legs swapped).
        work: (N, 3) float, motor work over the step [J]: net ``int tau q1d dt``, positive
            part ``int max(tau q1d, 0) dt``, absolute ``int |tau q1d| dt``.
        status: (N,) int, failure code (0 running; see :data:`FAILURES`).
        new_failure: (N,) bool, the walker failed during this step.
    """

    n_impacts: np.ndarray
    impact_time: np.ndarray
    foothold: np.ndarray
    pre_impact: np.ndarray
    post_impact: np.ndarray
    work: np.ndarray
    status: np.ndarray
    new_failure: np.ndarray


class Simulator:
    """A batch of ``num_walkers`` compass-gait walkers stepped together by control periods.

    Each walker has its own parameters and terrain (set at construction or later with
    :meth:`set_terrain`). State lives in preallocated numpy arrays; :meth:`step` does no
    allocation. One walker is a batch of one.

    Args:
        params: a :class:`RobotParams` (or preset name) for all walkers, or one per walker.
        terrain: a :class:`Terrain` (or spec) for all walkers, or one per walker.
        num_walkers: batch size N >= 1.
        dt: control period [s] (the torque is held over it), in (0, 1].
        config: :class:`SimConfig` (default settings if None).
        parallel: use the multi-threaded kernel (same numbers); default: when N >= 16 and
            numba has more than one thread.
    """

    def __init__(
        self,
        params: RobotParams | str | Sequence[RobotParams],
        terrain: Terrain | dict[str, Any] | Sequence[Terrain],
        num_walkers: int = 1,
        *,
        dt: float = 0.01,
        config: SimConfig | None = None,
        parallel: bool | None = None,
    ) -> None:
        if isinstance(num_walkers, bool) or not isinstance(num_walkers, (int, np.integer)):
            raise ValueError(f"num_walkers must be an integer >= 1, got {num_walkers!r}")
        if num_walkers < 1:
            raise ValueError(f"num_walkers = {num_walkers} out of range; allowed: >= 1")
        self.num_walkers = n = int(num_walkers)
        self.dt = _check_dt(dt)
        self.config = config if config is not None else SimConfig()
        if not isinstance(self.config, SimConfig):
            raise ValueError(f"config must be a SimConfig, got {type(self.config).__name__}")
        self._cfg = self.config.vector()
        if parallel is None:
            parallel = n >= 16 and numba.get_num_threads() > 1
        self._parallel = bool(parallel)
        self._kernel = step_parallel if self._parallel else step_serial
        self._P = np.zeros((n, N_PARAMS))
        self._param_view = _read_only(self._P)
        self.params: list[RobotParams] = [None] * n  # type: ignore[list-item]
        self.set_params(params)
        self.terrains: list[Terrain] = [None] * n  # type: ignore[list-item]
        self._tx = np.zeros((n, 2))
        self._ty = np.zeros((n, 2))
        self._tn = np.ones(n, dtype=np.int64)
        self.set_terrain(terrain)
        k = self.config.max_impacts
        self._x = np.zeros((n, N_X))
        self._f = np.zeros((n, N_F), dtype=np.int64)
        self._f[:, F_STATUS] = -1  # not reset yet
        self._ready = False
        self._tau = np.zeros(n)
        self._ev = np.zeros((n, k, N_E))
        self._out = np.zeros((n, N_O))
        self._status_before = np.zeros(n, dtype=np.int64)
        self._new_failure = np.zeros(n, dtype=bool)
        self.events = StepEvents(
            n_impacts=self._f[:, F_NIMP],
            impact_time=self._ev[:, :, E_T],
            foothold=self._ev[:, :, E_FX : E_FY + 1],
            pre_impact=self._ev[:, :, E_PRE : E_PRE + 4],
            post_impact=self._ev[:, :, E_POST : E_POST + 4],
            work=self._out,
            status=self._f[:, F_STATUS],
            new_failure=self._new_failure,
        )
        self._states = _read_only(self._x)
        self._flags = _read_only(self._f)

    # ------------------------------------------------------------------ set-up
    def set_params(self, params: Any, index: int | None = None) -> None:
        """Robot parameters for all walkers (``index`` None) or for walker ``index``.

        Args:
            params: a :class:`RobotParams`, preset name or dict; with ``index`` None also a list
                of them, one per walker.
            index: the walker, or None for all.
        """
        idx = range(self.num_walkers) if index is None else [self._index(index)]
        if isinstance(params, (list, tuple)) and index is None:
            if len(params) != self.num_walkers:
                raise ValueError(f"params: got {len(params)} entries for {self.num_walkers}")
            plist = [as_params(p) for p in params]
        else:
            plist = [as_params(params)] * len(idx)
        h = self.config.substep
        for p in plist:
            if p.Fv > 0.0 and p.Fv > p.viscous_friction_limit(h):
                raise ValueError(
                    f"RobotParams.Fv = {p.Fv!r} N m s/rad is too stiff for the RK4 substep "
                    f"SimConfig.substep = {h!r} s; allowed: [0, {p.viscous_friction_limit(h):.4g}] "
                    "N m s/rad (or a shorter substep)"
                )
        for i, p in zip(idx, plist):
            self.params[i] = p
            self._P[i] = p.vector()

    def set_terrain(self, terrain: Any, index: int | None = None) -> None:
        """Terrain for all walkers (``index`` None) or for walker ``index`` (e.g. on reset).

        Args:
            terrain: a :class:`Terrain`, spec dict or kind name; with ``index`` None also a list
                of them, one per walker.
            index: the walker, or None for all.
        """
        idx = range(self.num_walkers) if index is None else [self._index(index)]
        if isinstance(terrain, (list, tuple)) and index is None:
            if len(terrain) != self.num_walkers:
                raise ValueError(f"terrain: got {len(terrain)} entries for {self.num_walkers}")
            tlist = [as_terrain(t) for t in terrain]
        else:
            tlist = [as_terrain(terrain)] * len(idx)
        need = max(t.xs.size for t in tlist)
        if need > self._tx.shape[1]:
            tx = np.zeros((self.num_walkers, need))
            ty = np.zeros((self.num_walkers, need))
            tx[:, : self._tx.shape[1]] = self._tx
            ty[:, : self._ty.shape[1]] = self._ty
            self._tx, self._ty = tx, ty
        for i, t in zip(idx, tlist):
            self.terrains[i] = t
            m = t.xs.size
            self._tx[i, :m] = t.xs
            self._ty[i, :m] = t.ys
            self._tn[i] = m
        # the kernels get read-only views, like a Terrain's own vertex arrays: one compiled
        # version of the terrain queries serves both
        self._terrain = (_read_only(self._tx), _read_only(self._ty), _read_only(self._tn))

    def _index(self, i: Any) -> int:
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
            raise ValueError(f"walker index must be an integer, got {i!r}")
        if not -self.num_walkers <= i < self.num_walkers:
            raise ValueError(f"walker index {i} out of range 0..{self.num_walkers - 1}")
        return int(i) % self.num_walkers

    # ------------------------------------------------------------------ reset / step
    def reset(
        self,
        q0: Sequence[float] | np.ndarray,
        qd0: Sequence[float] | np.ndarray,
        foot: Sequence[float] | np.ndarray | None = None,
        *,
        index: int | Sequence[int] | np.ndarray | None = None,
        stance_leg: int = 0,
        t: float = 0.0,
    ) -> None:
        """Put walkers in a start state (swing phase, stance foot on the ground).

        Args:
            q0: ``(q1, q2)`` [rad], shape (2,) for every selected walker or (M, 2).
            qd0: ``(q1d, q2d)`` [rad/s], same shapes.
            foot: stance-foot position ``(x, y)`` [m], shape (2,) or (M, 2); default: ``x = 0``
                on the ground. It must lie on the ground (within 1e-6 m).
            index: walkers to reset: None (all), an int, a sequence of ints or a bool mask.
            stance_leg: which physical leg (0 or 1) is the stance leg.
            t: start time [s].

        Raises:
            ValueError: non-finite or out-of-range states (``|q1| > pi``, ``|q2| > q2_limit``,
                a rate above :attr:`RobotParams.max_rate`, hip below ``fall_height * l``,
                retracted swing foot below the ground, foot off the ground).
        """
        idx = self._select(index)
        m = idx.size
        q = _rows("q0", q0, m)
        qd = _rows("qd0", qd0, m)
        if stance_leg not in (0, 1):
            raise ValueError(f"stance_leg = {stance_leg!r}; allowed: 0 or 1")
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"t = {t!r} must be finite")
        cfg = self.config
        for j, i in enumerate(idx):
            ter = self.terrains[i]
            if foot is None:
                fx, fy = 0.0, ter.height(0.0)
            else:
                fx, fy = _rows("foot", foot, m)[j]
                if abs(fy - ter.height(fx)) > 1e-6:
                    raise ValueError(
                        f"foot = ({fx}, {fy}) is not on the ground (height {ter.height(fx)} m)"
                    )
            p = self.params[i]
            q1, q2 = q[j]
            if abs(q1) > math.pi:
                raise ValueError(f"q0[0] = {q1} rad out of range; allowed: |q1| <= pi")
            if abs(q2) > cfg.q2_limit:
                raise ValueError(f"q0[1] = {q2} out of range; allowed |q2| <= {cfg.q2_limit}")
            if max(abs(qd[j, 0]), abs(qd[j, 1])) > p.max_rate:
                raise ValueError(
                    f"qd0 = ({float(qd[j, 0])!r}, {float(qd[j, 1])!r}) rad/s out of range; "
                    f"allowed: |q1d|, |q2d| <= {p.max_rate:.4g} rad/s (RobotParams.max_rate, a "
                    "leg tip at 100 m/s)"
                )
            hx, hy = model.hip_position(self._P[i], q1, q2, fx, fy)
            if hy - ter.height(hx) < cfg.fall_height * p.l:
                raise ValueError(
                    f"start state has the hip {hy - ter.height(hx):.4g} m above the ground; "
                    f"allowed: >= fall_height * l = {cfg.fall_height * p.l}"
                )
            armed, r = initial_flags(
                self._P[i], self._cfg, *(a[i] for a in self._terrain), q1, q2, fx, fy
            )
            if not armed and r < -1e-12:
                raise ValueError(
                    f"start state has the retracted swing foot {-r:.4g} m below the ground"
                )
            self._x[i] = (q1, q2, qd[j, 0], qd[j, 1], fx, fy, t)
            self._f[i] = (stance_leg, int(armed), OK, 0)
            self._ev[i] = 0.0
            self._out[i] = 0.0

    def push_hip(self, index: int, dv: float) -> float:
        """Push walker ``index`` at the hip: its hip's horizontal velocity jumps by ``dv`` [m/s]
        (forwards positive), the stance foot held (:func:`envs.physics.model.hip_push`); returns
        the impulse [N s]. Positions, time and everything else are unchanged.

        Raises:
            ValueError: a non-finite ``dv`` or a walker that is not running.
        """
        i = self._index(index)
        if not math.isfinite(dv):
            raise ValueError(f"dv = {dv!r} must be a finite speed change [m/s]")
        if self._f[i, F_STATUS] != OK:
            raise ValueError(f"walker {i} is not running (reset it first)")
        x = self._x[i]
        d1, d2, impulse = model.hip_push(self._P[i], x[X_Q1], x[X_Q2], float(dv))
        x[X_Q1D] += d1
        x[X_Q2D] += d2
        return float(impulse)

    def _select(self, index: Any) -> np.ndarray:
        if index is None:
            return np.arange(self.num_walkers)
        a = np.asarray(index)
        if a.dtype == bool:
            if a.shape != (self.num_walkers,):
                raise ValueError(f"mask must have shape ({self.num_walkers},), got {a.shape}")
            return np.nonzero(a)[0]
        return np.array([self._index(int(i)) for i in np.atleast_1d(a)], dtype=np.int64)

    def step(self, torque: float | np.ndarray, dt: float | None = None) -> StepEvents:
        """Advance all running walkers by one control period under held hip torques.

        Args:
            torque: hip torque [N m] (no actuator limit applied), a float for all walkers or
                an array of shape (N,).
            dt: this period's length [s]; default the simulator's ``dt``.

        Returns:
            :attr:`events` (views, overwritten by the next step).

        Raises:
            ValueError: non-finite torque (no walker is advanced), or walkers never reset.
        """
        if isinstance(torque, float) or (
            isinstance(torque, (int, np.number)) and not isinstance(torque, bool)
        ):
            self._tau[:] = torque
        else:
            a = np.asarray(torque, dtype=np.float64)
            if a.shape != (self.num_walkers,) and a.size != 1:
                raise ValueError(f"torque must be a float or shape ({self.num_walkers},)")
            self._tau[:] = a.reshape(-1) if a.size == self.num_walkers else a.reshape(())
        h = self.dt if dt is None else _check_dt(dt)
        if not self._ready:
            if self._f[:, F_STATUS].min() < 0:
                raise ValueError("step() before reset(): reset every walker first")
            self._ready = True
        st = self._f[:, F_STATUS]
        np.copyto(self._status_before, st)
        bad = self._kernel(
            self._P,
            self._cfg,
            *self._terrain,
            self._x,
            self._f,
            self._tau,
            h,
            self._ev,
            self._out,
        )
        if bad >= 0:
            raise ValueError(f"torque[{bad}] = {self._tau[bad]!r} must be finite")
        np.not_equal(st, self._status_before, out=self._new_failure)
        return self.events

    # ------------------------------------------------------------------ state access
    @property
    def q(self) -> np.ndarray:
        """(N, 2) view: ``(q1, q2)`` [rad]."""
        return self._x[:, X_Q1 : X_Q2 + 1]

    @property
    def qd(self) -> np.ndarray:
        """(N, 2) view: ``(q1d, q2d)`` [rad/s]."""
        return self._x[:, X_Q1D : X_Q2D + 1]

    @property
    def stance_foot(self) -> np.ndarray:
        """(N, 2) view: stance-foot position [m]."""
        return self._x[:, X_XS : X_YS + 1]

    @property
    def t(self) -> np.ndarray:
        """(N,) view: time [s] (the failure time for failed walkers)."""
        return self._x[:, X_T]

    @property
    def stance_leg(self) -> np.ndarray:
        """(N,) view: physical leg (0 or 1) in stance; flips at every impact."""
        return self._f[:, F_LEG]

    @property
    def armed(self) -> np.ndarray:
        """(N,) view: the swing foot is extended (armed for touchdown)."""
        return self._f[:, F_ARMED]

    @property
    def status(self) -> np.ndarray:
        """(N,) view: failure code, 0 while running (names in :data:`FAILURES`)."""
        return self._f[:, F_STATUS]

    @property
    def states(self) -> np.ndarray:
        """(N, 7) read-only view of every walker's state row
        ``(q1, q2, q1d, q2d, xs, ys, t)`` [rad, rad/s, m, s] as the kernels hold it (columns:
        the ``X_*`` constants of :mod:`envs.physics.kernel`); :attr:`q`, :attr:`qd`,
        :attr:`stance_foot` and :attr:`t` are slices of it. Updated in place by every
        :meth:`step` and :meth:`reset`: copy a row to keep it."""
        return self._states

    @property
    def flags(self) -> np.ndarray:
        """(N, 4) int read-only view of every walker's flags ``(stance_leg, armed, status,
        n_impacts)`` as the kernels hold them (columns: the ``F_*`` constants of
        :mod:`envs.physics.kernel`; ``n_impacts`` counts the touchdowns of the last step). Updated
        in place like :attr:`states`."""
        return self._flags

    @property
    def param_vectors(self) -> np.ndarray:
        """(N, P) read-only view of every walker's parameter vector
        (:meth:`RobotParams.vector`, the layout of :mod:`envs.physics.params`), as the kernels
        read it; :meth:`set_params` updates it in place."""
        return self._param_view

    @property
    def terrain_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Padded terrain vertices ``(tx (N, K), ty (N, K), tn (N,))`` as the kernels see them
        (read-only views; ``envs.physics.terrain.terrain_height(tx[i], ty[i], tn[i], x)``).
        :meth:`set_terrain` may reallocate them: fetch them again after it."""
        return self._terrain

    def failure(self, i: int = 0) -> str | None:
        """Failure reason of walker ``i`` or None while it runs."""
        s = int(self._f[self._index(i), F_STATUS])
        return FAILURES[s] if s > 0 else None

    def state(self, i: int = 0) -> np.ndarray:
        """Copy of walker ``i``'s state ``(q1, q2, q1d, q2d)``."""
        return self._x[self._index(i), :4].copy()


def _read_only(a: np.ndarray) -> np.ndarray:
    """A view of ``a`` that cannot be written through (``a`` itself stays writeable)."""
    v = a.view()
    v.flags.writeable = False
    return v


def _check_dt(dt: Any) -> float:
    try:
        v = float(dt)
    except (TypeError, ValueError):
        raise ValueError(f"dt must be a number of seconds, got {dt!r}") from None
    if not (math.isfinite(v) and 0 < v <= 1.0):
        raise ValueError(f"dt = {dt!r} out of range; allowed: (0, 1] s")
    return v


def _rows(name: str, value: Any, m: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if a.shape == (2,):
        a = np.broadcast_to(a, (m, 2))
    if a.shape != (m, 2):
        raise ValueError(f"{name} must have shape (2,) or ({m}, 2), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {value!r} must be finite")
    return a


# ---------------------------------------------------------------------------- simulate()
@dataclass
class SimResult:
    """Trajectory of one walker from :func:`simulate`.

    Samples are taken at the end of every control period and on both sides of every impact
    (two samples with the same time: pre-impact then post-impact, legs swapped).

    Attributes:
        t: (M,) time [s].
        q: (M, 2) ``(q1, q2)`` [rad] (``q1`` inter-leg angle, ``q2`` stance-leg angle).
        qd: (M, 2) ``(q1d, q2d)`` [rad/s].
        stance_foot: (M, 2) stance-foot position [m].
        stance_leg: (M,) physical stance leg (0 or 1).
        torque: (M,) hip torque [N m] held over the period ending at the sample.
        impact_times: (k,) touchdown times [s].
        footholds: (k, 2) touchdown positions [m].
        failure: failure reason (``"fall"``, ``"trip"``, ``"liftoff"``, ``"slip"``,
            ``"stuck"``, ``"invalid"``) or None.
        failure_time: time of the failure [s] or None.
        work: motor work over the run [J]: (net, positive, absolute).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    stance_foot: np.ndarray
    stance_leg: np.ndarray
    torque: np.ndarray
    impact_times: np.ndarray
    footholds: np.ndarray
    failure: str | None
    failure_time: float | None
    work: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def step_periods(self) -> np.ndarray:
        """Durations between consecutive impacts [s]."""
        return np.diff(self.impact_times)

    @property
    def step_lengths(self) -> np.ndarray:
        """Distances between consecutive footholds [m]."""
        return (
            np.hypot(*np.diff(self.footholds, axis=0).T)
            if len(self.footholds) > 1
            else (np.zeros(0))
        )


TorqueSpec = float | Callable[[float, np.ndarray, np.ndarray], float] | None


def simulate(
    params: RobotParams | str,
    terrain: Terrain | dict[str, Any] | str,
    q0: Sequence[float],
    qd0: Sequence[float],
    duration: float,
    torque: TorqueSpec = None,
    *,
    foot: Sequence[float] | None = None,
    dt: float = 0.01,
    config: SimConfig | None = None,
    stance_leg: int = 0,
    stop_at_impacts: int | None = None,
) -> SimResult:
    """Simulate one walker for ``duration`` seconds.

    Args:
        params: robot parameters or a preset name.
        terrain: a :class:`Terrain`, a spec dict, or a name (``"flat"``; see
            :func:`envs.physics.terrain.terrain_spec`).
        q0: start ``(q1, q2)`` [rad]; qd0: start ``(q1d, q2d)`` [rad/s].
        duration: simulated time [s], > 0.
        torque: hip torque [N m] (not limited by ``u_max``): None (passive), a float, or a
            callable ``torque(t, q, qd) -> float`` evaluated at the start of every control
            period and held over it (zero-order hold).
        foot: stance-foot position ``(x, y)`` [m]; default ``x = 0`` on the ground.
        dt: control period and output sampling interval [s].
        config: simulator settings (:class:`SimConfig`; ``SimConfig.accurate()`` for
            reference-quality runs).
        stance_leg: physical stance leg at the start (0 or 1).
        stop_at_impacts: stop at the end of the control period in which this many
            touchdowns have happened (None: run the whole duration).

    Returns:
        :class:`SimResult`. A failure ends the run early.
    """
    T = float(duration)
    if not (math.isfinite(T) and T > 0):
        raise ValueError(f"duration = {duration!r} out of range; allowed: finite > 0 s")
    if torque is not None and not callable(torque):
        tv = float(torque)
        if not math.isfinite(tv):
            raise ValueError(f"torque = {torque!r} must be finite")
        const = tv
        torque_fn = None
    else:
        const = 0.0
        torque_fn = torque
    sim = Simulator(params, terrain, 1, dt=dt, config=config, parallel=False)
    sim.reset(q0, qd0, foot, stance_leg=stance_leg)
    row, ev = sim.states[0], sim.events  # views, updated by every step
    ts, xs_, legs, taus = [float(sim.t[0])], [row[:6].copy()], [int(sim.stance_leg[0])], [0.0]
    imp_t: list[float] = []
    holds: list[tuple[float, float]] = []
    work = np.zeros(3)
    nsteps = int(math.ceil(T / sim.dt - 1e-9))
    for k in range(nsteps):
        h = min(sim.dt, T - k * sim.dt)
        if h <= 1e-12:
            break
        if torque_fn is not None:
            tv = float(torque_fn(float(sim.t[0]), sim.q[0].copy(), sim.qd[0].copy()))
            if not math.isfinite(tv):
                raise ValueError(f"torque(t={sim.t[0]:.6g}) returned {tv!r}; must be finite")
        else:
            tv = const
        foot_before = tuple(xs_[-1][4:6])
        leg_before = legs[-1]
        sim.step(tv, h)
        work += ev.work[0]
        for j in range(int(ev.n_impacts[0])):
            te = float(ev.impact_time[0, j])
            fx, fy = ev.foothold[0, j]
            ts += [te, te]
            xs_ += [
                np.array([*ev.pre_impact[0, j], *foot_before]),
                np.array([*ev.post_impact[0, j], fx, fy]),
            ]
            legs += [leg_before, 1 - leg_before]
            taus += [tv, tv]
            leg_before = 1 - leg_before
            foot_before = (float(fx), float(fy))
            imp_t.append(te)
            holds.append(foot_before)
        ts.append(float(sim.t[0]))
        xs_.append(row[:6].copy())
        legs.append(int(sim.stance_leg[0]))
        taus.append(tv)
        if sim.status[0] != OK:
            break
        if stop_at_impacts is not None and len(imp_t) >= stop_at_impacts:
            break
    arr = np.array(xs_)
    status = int(sim.status[0])
    return SimResult(
        t=np.array(ts),
        q=arr[:, 0:2].copy(),
        qd=arr[:, 2:4].copy(),
        stance_foot=arr[:, 4:6].copy(),
        stance_leg=np.array(legs, dtype=np.int64),
        torque=np.array(taus),
        impact_times=np.array(imp_t),
        footholds=np.array(holds, dtype=np.float64).reshape(-1, 2),
        failure=FAILURES[status] if status else None,
        failure_time=float(sim.t[0]) if status else None,
        work=work,
    )
