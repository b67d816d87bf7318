"""Gymnasium environment of the compass-gait biped walking over terrain (``CompassGaitEnv``).

The environment and its native vector version (:mod:`envs.vector_env`) stand on the same batched
:class:`envs.simulator.Simulator` through :class:`WalkerBatch`; the single env is a batch of one,
so both give the same observations, rewards and infos step by step.

Settings come from a YAML file in ``configs/envs/`` (``config="flat"``, ``"stairs"``, ``"rough"``,
``"slope"`` or a path) and keyword overrides; see :class:`CompassGaitEnv` for the arguments.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numba
import numpy as np
import yaml
from gymnasium import spaces
from numba import njit, prange

from . import model
from .config_util import dataclass_from_mapping
from .params import CONFIG_DIR, RobotParams, as_params
from .sensors import (
    SensorConfig,
    SensorLayout,
    measure_walker,
    observation_bounds,
    scan_walker,
    seed_streams,
    state_walker,
)
from .simulator import FAILURES, O_WABS, O_WNET, O_WPOS, SimConfig, Simulator
from .terrain import Terrain

ENV_CONFIG_DIR = CONFIG_DIR / "envs"
TERRAIN_CONFIG_DIR = CONFIG_DIR / "terrains"
OBSERVATION_MODES = ("sensors", "state")
_RANDOM_KINDS = {"blocks": "height_range", "piecewise": "slope_range"}
_WORK_COLUMNS = {"net": O_WNET, "positive": O_WPOS, "absolute": O_WABS}
_LEGS = {"A": 0, "B": 1, 0: 0, 1: 1}
_FAILURE_NAMES = np.array([None] + list(FAILURES[1:]), dtype=object)
#: batches at least this large use the multi-threaded kernels by default (below it the threads'
#: start-up cost exceeds the gain on a 2-core machine)
PARALLEL_MIN_WALKERS = 256
_SETTING_KEYS = (
    "robot",
    "terrain",
    "difficulty",
    "dt",
    "u_max",
    "torque_limit",
    "observation",
    "sensors",
    "reward",
    "initial_state",
    "simulator",
    "max_episode_steps",
)


# ---------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class RewardConfig:
    """Reward ``r = progress * dx_hip - energy * W - failure * [failed in this step]``.

    Attributes:
        progress: weight of the forward hip displacement over the step [1/m], >= 0.
        energy: weight of the motor work over the step [1/J], >= 0.
        failure: penalty when the walker fails (fall, trip, ...), >= 0.
        work: which motor work: ``"absolute"`` (``int |tau q1dot| dt``, default),
            ``"positive"`` (``int max(tau q1dot, 0) dt``) or ``"net"`` (``int tau q1dot dt``).
    """

    progress: float = 1.0
    energy: float = 0.05
    failure: float = 1.0
    work: str = "absolute"

    def __post_init__(self) -> None:
        for name in ("progress", "energy", "failure"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"reward.{name} must be a finite number, got {v!r}")
            if v < 0:
                raise ValueError(f"reward.{name} = {v!r} out of range; allowed: >= 0")
            object.__setattr__(self, name, float(v))
        if self.work not in _WORK_COLUMNS:
            raise ValueError(f"reward.work = {self.work!r}; allowed: {sorted(_WORK_COLUMNS)}")

    def weights(self) -> np.ndarray:
        return np.array([self.progress, self.energy, self.failure])


@dataclass(frozen=True)
class InitialState:
    """Start of every episode: a post-impact state of a nominal gait plus a uniform spread.

    Attributes:
        q: nominal ``(q1, q2)`` [rad] (paper coordinates).
        qd: nominal ``(q1dot, q2dot)`` [rad/s].
        spread: half-widths of the uniform perturbation of ``(q1, q2, q1dot, q2dot)``
            [rad, rad, rad/s, rad/s], each >= 0.
        stance_leg: physical stance leg at the start: ``"A"``, ``"B"`` or ``"random"``.
    """

    q: tuple[float, float]
    qd: tuple[float, float]
    spread: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    stance_leg: str = "A"

    def __post_init__(self) -> None:
        for name, size in (("q", 2), ("qd", 2), ("spread", 4)):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise ValueError(f"initial_state.{name} must be {size} finite numbers, got {v}")
            if name == "spread" and np.any(v < 0):
                raise ValueError(f"initial_state.spread = {v.tolist()}; allowed: each >= 0")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if self.stance_leg not in ("A", "B", "random"):
            raise ValueError(
                f"initial_state.stance_leg = {self.stance_leg!r}; allowed: 'A', 'B', 'random'"
            )


def available_env_configs() -> list[str]:
    """Names of the env variants shipped in ``configs/envs``."""
    return sorted(p.stem for p in ENV_CONFIG_DIR.glob("*.yaml"))


def load_env_config(config: str | Path | dict[str, Any]) -> dict[str, Any]:
    """Raw settings of an env variant: a name in ``configs/envs``, a YAML path, or a dict."""
    if isinstance(config, dict):
        data = copy.deepcopy(config)
    else:
        path = Path(config)
        if path.suffix not in (".yaml", ".yml"):
            if str(config) not in available_env_configs():
                raise ValueError(
                    f"unknown env config {config!r}; available: {available_env_configs()} "
                    "or a path to a YAML file"
                )
            path = ENV_CONFIG_DIR / f"{config}.yaml"
        if not path.is_file():
            raise ValueError(f"env config file {str(path)!r} does not exist")
        with open(path) as fh:
            data = yaml.safe_load(fh) or {}
    if not isinstance(data, dict):
        raise ValueError(f"env config must be a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_SETTING_KEYS))
    if unknown:
        raise ValueError(f"unknown env setting(s) {unknown}; allowed: {list(_SETTING_KEYS)}")
    return data


def terrain_spec(terrain: Terrain | dict[str, Any] | str) -> Terrain | dict[str, Any]:
    """Resolve a terrain argument: a :class:`Terrain` is kept; a name of a file in
    ``configs/terrains`` or a kind name (``"flat"``) gives its spec dict; a dict is copied."""
    if isinstance(terrain, Terrain):
        return terrain
    if isinstance(terrain, str):
        path = TERRAIN_CONFIG_DIR / f"{terrain}.yaml"
        if path.is_file():
            with open(path) as fh:
                return dict(yaml.safe_load(fh))
        if terrain.endswith((".yaml", ".yml")) and Path(terrain).is_file():
            with open(terrain) as fh:
                return dict(yaml.safe_load(fh))
        if terrain == "flat":
            return {"kind": "flat"}
        names = sorted(p.stem for p in TERRAIN_CONFIG_DIR.glob("*.yaml"))
        raise ValueError(
            f"unknown terrain {terrain!r}; use a name in {names}, a YAML path, a spec dict "
            "or an envs.Terrain"
        )
    if isinstance(terrain, dict):
        return copy.deepcopy(terrain)
    raise ValueError(f"terrain must be a Terrain, a spec dict or a name, got {type(terrain)}")


class TerrainSource:
    """Fixed terrain, or a generator of random terrain drawn anew from a seed at each reset.

    A spec dict of a random kind (``blocks``, ``piecewise``) without a ``seed`` is a generator:
    each episode draws ``seed`` from the env's ``np_random``. ``difficulty`` scales the random
    kinds' heights (``height_range`` of blocks, ``slope_range`` of piecewise ground).
    """

    def __init__(self, terrain: Terrain | dict[str, Any] | str, difficulty: float = 1.0):
        if isinstance(difficulty, bool) or not isinstance(difficulty, (int, float)):
            raise ValueError(f"difficulty must be a number >= 0, got {difficulty!r}")
        if not (math.isfinite(difficulty) and difficulty >= 0):
            raise ValueError(f"difficulty = {difficulty!r} out of range; allowed: finite >= 0")
        self.difficulty = float(difficulty)
        spec = terrain_spec(terrain)
        self.template: dict[str, Any] | None = None
        self.fixed: Terrain | None = None
        if isinstance(spec, Terrain):
            if self.difficulty != 1.0:
                raise ValueError("difficulty applies to terrain specs, not to a built Terrain")
            self.fixed = spec
            return
        kind = spec.get("kind")
        if self.difficulty != 1.0:
            key = _RANDOM_KINDS.get(kind)
            if key is None:
                raise ValueError(
                    f"difficulty = {difficulty} scales random terrain only (kinds "
                    f"{sorted(_RANDOM_KINDS)}); the terrain kind is {kind!r}"
                )
            if "xs" in spec:
                raise ValueError("difficulty cannot rescale a terrain given by its vertices")
            lo, hi = spec.get(key, (-0.02, 0.02) if kind == "blocks" else (-0.1, 0.1))
            spec[key] = [float(lo) * self.difficulty, float(hi) * self.difficulty]
        if kind in _RANDOM_KINDS and "seed" not in spec:
            self.template = spec
            Terrain.from_dict({**spec, "seed": 0})  # validate the fields now
        else:
            self.fixed = Terrain.from_dict(spec)

    @property
    def is_random(self) -> bool:
        return self.template is not None

    def draw(self, rng: np.random.Generator) -> Terrain:
        """The terrain of a new episode (a fresh random course when this is a generator)."""
        if self.fixed is not None:
            return self.fixed
        seed = int(rng.integers(0, 2**31 - 1))
        return Terrain.from_dict({**self.template, "seed": seed})

    def preview(self) -> Terrain:
        """A terrain to build the simulator with before the first reset."""
        return (
            self.fixed
            if self.fixed is not None
            else Terrain.from_dict({**self.template, "seed": 0})
        )


@dataclass(frozen=True)
class EnvSettings:
    """All settings of a compass-gait environment (see :class:`CompassGaitEnv`)."""

    robot: RobotParams
    terrain: TerrainSource
    dt: float
    observation: str
    sensors: SensorConfig
    reward: RewardConfig
    initial_state: InitialState
    simulator: SimConfig
    max_episode_steps: int | None

    @classmethod
    def build(cls, config: str | Path | dict[str, Any] = "flat", **overrides: Any) -> EnvSettings:
        """Settings from an env config plus keyword overrides (``None`` keeps the config's).

        ``sensors``, ``reward``, ``initial_state`` and ``simulator`` overrides are merged into
        the config's mappings field by field.
        """
        data = load_env_config(config)
        for key, value in overrides.items():
            if key not in _SETTING_KEYS:
                raise ValueError(f"unknown env argument {key!r}; allowed: {list(_SETTING_KEYS)}")
            if value is None:
                continue
            if key in ("sensors", "reward", "initial_state", "simulator") and isinstance(
                value, dict
            ):
                merged = dict(data.get(key) or {})
                merged.update(value)
                data[key] = merged
            else:
                data[key] = value
            if key in ("u_max", "torque_limit"):  # an override replaces the other form
                data.pop("torque_limit" if key == "u_max" else "u_max", None)
        robot = as_params(data.get("robot", "paper"))
        u_max, torque_limit = data.get("u_max"), data.get("torque_limit")
        if u_max is not None and torque_limit is not None:
            raise ValueError("give the actuator limit as u_max or as torque_limit, not both")
        if torque_limit is not None:
            if isinstance(torque_limit, bool) or not isinstance(torque_limit, (int, float)):
                raise ValueError(f"torque_limit must be a number of N m, got {torque_limit!r}")
            u_max = torque_limit / (robot.kI * robot.ktau)
        if u_max is not None:
            robot = robot.replace(u_max=u_max)
        dt = data.get("dt", 0.005)
        if isinstance(dt, bool) or not isinstance(dt, (int, float)):
            raise ValueError(f"dt must be a number of seconds, got {dt!r}")
        if not (math.isfinite(dt) and 0 < dt <= 0.1):
            raise ValueError(f"dt = {dt!r} out of range; allowed: (0, 0.1] s")
        obs = data.get("observation", "sensors")
        if obs not in OBSERVATION_MODES:
            raise ValueError(f"observation = {obs!r}; allowed: {list(OBSERVATION_MODES)}")
        if "initial_state" not in data:
            raise ValueError("env config needs an 'initial_state' with q and qd")
        sim = data.get("simulator") or {}
        if isinstance(sim, dict):
            sim = dataclass_from_mapping(SimConfig, sim, "simulator")
        elif not isinstance(sim, SimConfig):
            raise ValueError(f"simulator must be a mapping or SimConfig, got {type(sim)}")
        mes = data.get("max_episode_steps")
        if mes is not None and (isinstance(mes, bool) or int(mes) != mes or mes < 1):
            raise ValueError(f"max_episode_steps = {mes!r}; allowed: integer >= 1 or None")
        return cls(
            robot=robot,
            terrain=TerrainSource(data.get("terrain", "flat"), data.get("difficulty", 1.0)),
            dt=float(dt),
            observation=obs,
            sensors=SensorConfig.from_dict(data.get("sensors")),
            reward=dataclass_from_mapping(RewardConfig, data.get("reward") or {}, "reward"),
            initial_state=dataclass_from_mapping(
                InitialState, data["initial_state"], "initial_state"
            ),
            simulator=sim,
            max_episode_steps=None if mes is None else int(mes),
        )


# ---------------------------------------------------------------------------- compiled step
@njit(cache=True)
def _observe_walker(i, mode, refresh, q, qd, foot, leg, tx, ty, tn, settings, offsets, scan,
                    streams, obs):  # fmt: skip
    if refresh:
        scan_walker(i, foot[i, 0], foot[i, 1], tx, ty, tn, offsets, scan)
    if mode == 0:
        measure_walker(i, q[i, 0], q[i, 1], leg[i], settings, scan, streams, obs)
    else:
        state_walker(i, q[i, 0], q[i, 1], qd[i, 0], qd[i, 1], leg[i], scan, settings[4], obs)


@njit(cache=True)
def _post_walker(i, P, q, foot, status, nimp, work, wcol, new_fail, weights, hip_x, acc, cnt,
                 reward, terminated):  # fmt: skip
    hx, _ = model.hip_position(P, q[i, 0], q[i, 1], foot[i, 0], foot[i, 1])
    progress = hx - hip_x[i]
    hip_x[i] = hx
    w = work[i, wcol]
    acc[i, 0] += progress  # distance
    acc[i, 1] = w  # motor work of this step
    cnt[i] += nimp[i]
    r = weights[0] * progress - weights[1] * w
    if new_fail[i]:
        r -= weights[2]
    reward[i] = r
    terminated[i] = status[i] != 0


@njit(cache=True)
def _after_step_serial(mode, P, q, qd, foot, leg, status, nimp, work, wcol, new_fail, tx, ty, tn,
                       weights, settings, offsets, scan, streams, hip_x, acc, cnt, reward,
                       terminated, obs):  # fmt: skip
    """Rewards, counters and observations of every walker after a simulator step."""
    for i in range(q.shape[0]):
        _post_walker(i, P, q, foot, status, nimp, work, wcol, new_fail, weights, hip_x, acc, cnt,
                     reward, terminated)  # fmt: skip
        refresh = nimp[i] > 0 or new_fail[i]  # the stance foot moved: rescan the terrain
        _observe_walker(i, mode, refresh, q, qd, foot, leg, tx, ty, tn, settings, offsets, scan,
                        streams, obs)  # fmt: skip


@njit(cache=True, parallel=True)
def _after_step_parallel(mode, P, q, qd, foot, leg, status, nimp, work, wcol, new_fail, tx, ty,
                         tn, weights, settings, offsets, scan, streams, hip_x, acc, cnt, reward,
                         terminated, obs):  # fmt: skip
    """:func:`_after_step_serial` with the walkers spread over threads (same numbers)."""
    for i in prange(q.shape[0]):
        _post_walker(i, P, q, foot, status, nimp, work, wcol, new_fail, weights, hip_x, acc, cnt,
                     reward, terminated)  # fmt: skip
        refresh = nimp[i] > 0 or new_fail[i]
        _observe_walker(i, mode, refresh, q, qd, foot, leg, tx, ty, tn, settings, offsets, scan,
                        streams, obs)  # fmt: skip


@njit(cache=True)
def _observe(idx, mode, q, qd, foot, leg, tx, ty, tn, settings, offsets, scan, streams, obs):
    """Observations of walkers ``idx`` after a reset (terrain rescanned)."""
    for j in range(idx.size):
        _observe_walker(idx[j], mode, True, q, qd, foot, leg, tx, ty, tn, settings, offsets,
                        scan, streams, obs)  # fmt: skip


# ---------------------------------------------------------------------------- batch core
class WalkerBatch:
    """``n`` walkers of one environment configuration on one batched simulator.

    Holds the simulator, observation buffers (with the latency ring), reward and episode
    counters. Both :class:`CompassGaitEnv` (``n = 1``) and the vector env use it.
    """

    def __init__(self, settings: EnvSettings, n: int, parallel: bool | None = None):
        self.settings = s = settings
        self.n = n
        self.robot = s.robot
        self._P = s.robot.vector()
        self.torque_per_action = s.robot.tau_max  # [N m] per unit action
        if parallel is None:
            parallel = n >= PARALLEL_MIN_WALKERS and numba.get_num_threads() > 1
        par = bool(parallel)
        self.sim = Simulator(
            s.robot, s.terrain.preview(), n, dt=s.dt, config=s.simulator, parallel=par
        )
        self._after_step = _after_step_parallel if par else _after_step_serial
        self.mode = 0 if s.observation == "sensors" else 1
        self.layout = SensorLayout.from_config(s.sensors)
        low, high = observation_bounds(s.sensors, s.observation)
        self.obs_low, self.obs_high = low, high
        self.obs_dim = low.size
        self._settings_vec = s.sensors.kernel_vector()
        self._offsets = s.sensors.scan_offsets
        self._weights = s.reward.weights()
        self._wcol = _WORK_COLUMNS[s.reward.work]
        self.latency = s.sensors.latency if self.mode == 0 else 0
        # views of the simulator's state (fixed buffers)
        ev = self.sim.events
        self._q, self._qd, self._foot = self.sim.q, self.sim.qd, self.sim.stance_foot
        self._leg, self._status, self._time = self.sim.stance_leg, self.sim.status, self.sim.t
        self._nimp, self._work, self._new_fail = ev.n_impacts, ev.work, ev.new_failure
        self._footholds_ev = ev.foothold
        # (q1, q2, q1d, q2d, xs, ys) of all walkers as one strided view of the simulator's state
        # array (the public q, qd and stance_foot views are slices of it)
        self._x6 = self.sim._x[:, :6]
        self._no_failure = np.full(n, None, dtype=object)
        # own buffers
        self.tau = np.zeros(n)
        self.streams = np.zeros(n, dtype=np.uint64)
        self.hip_x = np.zeros(n)
        self.acc = np.zeros((n, 2))  # distance [m], motor work of the last step [J]
        self.footsteps = np.zeros(n, dtype=np.int64)
        self.reward = np.zeros(n)
        self.terminated = np.zeros(n, dtype=bool)
        self.fresh = np.zeros((n, self.obs_dim), dtype=np.float32)
        self.scan = np.zeros((n, s.sensors.scan_count))  # exact heights ahead [m]
        self._ring = np.zeros((self.latency + 1, n, self.obs_dim), dtype=np.float32)
        self._ring_pos = 0
        self.terrains: list[Terrain | None] = [None] * n
        self.specs = np.full(n, None, dtype=object)
        self.track_footholds = False
        self.footholds: list[list[tuple[float, float]]] = [[] for _ in range(n)]

    # ------------------------------------------------------------------ reset
    def reset_walker(
        self, i: int, rng: np.random.Generator, options: dict[str, Any] | None = None
    ) -> None:
        """Start a new episode of walker ``i``; all randomness is drawn from ``rng``."""
        s = self.settings
        opts = options or {}
        unknown = sorted(set(opts) - {"terrain", "state", "stance_leg", "reset_mask"})
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
        init = s.initial_state
        if opts.get("state") is not None:
            q, qd = _state_option(opts["state"])
        else:
            x = np.array(init.q + init.qd)
            if any(init.spread):
                x = x + np.asarray(init.spread) * rng.uniform(-1.0, 1.0, size=4)
            q, qd = x[:2], x[2:]
        leg_opt = opts.get("stance_leg")
        if leg_opt is not None:
            if leg_opt not in _LEGS:
                raise ValueError(f"reset option stance_leg = {leg_opt!r}; allowed: 'A', 'B'")
            leg = _LEGS[leg_opt]
        elif init.stance_leg == "random":
            leg = int(rng.integers(0, 2))
        else:
            leg = _LEGS[init.stance_leg]
        self.sim.reset(q, qd, index=i, stance_leg=leg)
        self.streams[i] = seed_streams(rng, 1)[0]
        hx, _ = model.hip_position(self._P, self._q[i, 0], self._q[i, 1], *self._foot[i])
        self.hip_x[i] = hx
        self.acc[i] = 0.0
        self.footsteps[i] = 0
        self.reward[i] = 0.0
        self.terminated[i] = False
        self.footholds[i] = [(float(self._foot[i, 0]), float(self._foot[i, 1]))]
        tx, ty, tn = self.sim.terrain_arrays
        _observe(
            np.array([i]), self.mode, self._q, self._qd, self._foot, self._leg, tx, ty, tn,
            self._settings_vec, self._offsets, self.scan, self.streams, self.fresh,
        )  # fmt: skip
        self._ring[:, i] = self.fresh[i]

    # ------------------------------------------------------------------ step
    def step(self) -> None:
        """Advance every walker by one control period under ``self.tau`` [N m]."""
        self.sim.step(self.tau)
        tx, ty, tn = self.sim.terrain_arrays
        self._after_step(
            self.mode, self._P, self._q, self._qd, self._foot, self._leg, self._status,
            self._nimp, self._work, self._wcol, self._new_fail, tx, ty, tn, self._weights,
            self._settings_vec, self._offsets, self.scan,
            self.streams, self.hip_x, self.acc, self.footsteps, self.reward, self.terminated,
            self.fresh,
        )  # fmt: skip
        if self.latency:
            self._ring_pos = (self._ring_pos + 1) % (self.latency + 1)
            self._ring[self._ring_pos] = self.fresh
        if self.track_footholds:
            for i in np.nonzero(self._nimp)[0]:
                for k in range(int(self._nimp[i])):
                    fx, fy = self._footholds_ev[i, k]
                    self.footholds[i].append((float(fx), float(fy)))

    def observations(self) -> np.ndarray:
        """Copy of the current (possibly delayed) observations, ``(n, dim)`` float32."""
        if self.latency:
            # the oldest entry of the ring: written `latency` steps ago
            return self._ring[(self._ring_pos + 1) % (self.latency + 1)].copy()
        return self.fresh.copy()

    def observation(self, i: int) -> np.ndarray:
        """Copy of walker ``i``'s current observation."""
        if self.latency:
            return self._ring[(self._ring_pos + 1) % (self.latency + 1), i].copy()
        return self.fresh[i].copy()

    # ------------------------------------------------------------------ info
    def info(self, i: int, terrain: bool = True) -> dict[str, Any]:
        """Info dict of walker ``i`` (true state etc.; see :class:`CompassGaitEnv`); with
        ``terrain``, also the course's spec."""
        q, qd, foot = self._q[i], self._qd[i], self._foot[i]
        status = int(self._status[i])
        info = {
            "state": np.array((q[0], q[1], qd[0], qd[1])),
            "stance_foot": np.array((foot[0], foot[1])),
            "stance_leg": int(self._leg[i]),
            "time": float(self._time[i]),
            "footsteps": int(self.footsteps[i]),
            "distance": float(self.acc[i, 0]),
            "impacts": int(self._nimp[i]),
            "motor_work": float(self.acc[i, 1]),
            "failure": FAILURES[status] if status else None,
        }
        if terrain:
            info["terrain"] = dict(self.specs[i])
        return info

    def infos(self) -> dict[str, Any]:
        """Batched info (arrays over walkers, with Gymnasium's ``_key`` masks all True)."""
        x = self._x6.copy()  # one copy of (q1, q2, q1d, q2d, xs, ys) for all walkers
        if self._status.any():
            failure = _FAILURE_NAMES[self._status]
        else:
            failure = self._no_failure.copy()
        d = {
            "state": x[:, :4],
            "stance_foot": x[:, 4:6],
            "stance_leg": self._leg.copy(),
            "time": self._time.copy(),
            "footsteps": self.footsteps.copy(),
            "distance": self.acc[:, 0].copy(),
            "impacts": self._nimp.copy(),
            "motor_work": self.acc[:, 1].copy(),
            "failure": failure,
            "terrain": self.specs.copy(),
        }
        mask = np.ones(self.n, dtype=bool)  # one array shared by all keys (every entry is valid)
        for key in list(d):
            d["_" + key] = mask
        return d

    def render_args(self, i: int) -> dict[str, Any]:
        """Keyword arguments of :meth:`envs.rendering.WalkerRenderer.render` for walker ``i``."""
        t = self.sim.terrains[i]
        status = int(self._status[i])
        return {
            "q": self._q[i],
            "stance_foot": self._foot[i],
            "stance_leg": int(self._leg[i]),
            "terrain_xs": t.xs,
            "terrain_ys": t.ys,
            "footholds": self.footholds[i],
            "time": float(self._time[i]),
            "distance": float(self.acc[i, 0]),
            "steps": int(self.footsteps[i]),
            "failure": FAILURES[status] if status else None,
        }


def _state_option(state: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        q, qd = state
        q = np.asarray(q, dtype=np.float64)
        qd = np.asarray(qd, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"reset option 'state' must be (q, qd) with two angles and two rates, got {state!r}"
        ) from None
    if (
        q.shape != (2,)
        or qd.shape != (2,)
        or not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd)))
    ):
        raise ValueError(
            f"reset option 'state' must be finite (q, qd) of shape (2,), got {state!r}"
        )
    return q, qd


@njit(cache=True)
def _scale_actions(a, scale, out):
    """``out = clip(a, -1, 1) * scale`` in float64; returns -1 or the first non-finite index."""
    for i in range(a.size):
        if not math.isfinite(a[i]):
            return i
    for i in range(a.size):
        x = np.float64(a[i])
        if x > 1.0:
            x = 1.0
        elif x < -1.0:
            x = -1.0
        out[i] = x * scale
    return -1


def actions_to_torques(actions: Any, scale: float, out: np.ndarray) -> None:
    """Hip torques ``out = clip(actions, -1, 1) * scale`` [N m] for a batch of actions.

    Raises ``ValueError`` on NaN/inf (nothing written) or a shape other than ``(n,)``/``(n, 1)``.
    """
    n = out.size
    a = actions if type(actions) is np.ndarray else np.asarray(actions)
    if a.dtype != np.float32 and a.dtype != np.float64:
        a = a.astype(np.float64)
    if a.size != n or a.ndim > 2:
        raise ValueError(f"actions must have shape ({n}, 1), got {a.shape}")
    bad = _scale_actions(a.reshape(n), float(scale), out)
    if bad >= 0:
        raise ValueError(f"action[{bad}] = {a.reshape(n)[bad]!r} must be finite (allowed: [-1, 1])")


# ---------------------------------------------------------------------------- the env
class CompassGaitEnv(gym.Env):
    """A planar compass-gait biped walking over terrain with one hip motor.

    ## Description

    Two rigid legs joined at the hip, point feet, one motor between the legs (Manchester,
    Mettin, Iida, Tedrake 2011, "Stable Dynamic Walking over Rough Terrain"). The robot walks
    towards +x: each step the swing leg swings forward on a retractable foot and touches down;
    the impact is instantaneous and the legs swap roles. The simulator integrates the swing
    phase exactly and locates touchdowns to 1e-9 s or better (:mod:`envs.simulator`). Robots:
    the paper's robot (``"paper"``, legs 0.32 m) and the classic symmetric walker
    (``"classic"``, legs 1 m).

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: the normalised hip command. The motor input is
    ``u = action * u_max`` [input units] and the hip torque ``kI * ktau * u`` [N m]
    (``env.unwrapped.torque_limit`` N m at ``|action| = 1``), held over the control period
    ``env.unwrapped.dt``. Out-of-range actions are clipped to [-1, 1]; NaN or inf raise
    ``ValueError``.

    ## Observation Space

    ``observation="sensors"`` (default): float32 vector of length ``4 + N`` (see
    :mod:`envs.sensors`; decode with ``env.unwrapped.sensor_layout.decode(obs)``):

    | Num      | Observation                                                 | Min    | Max   |
    |----------|-------------------------------------------------------------|--------|-------|
    | 0        | hip encoder ``alpha_A - alpha_B`` [rad]                     | -pi    | pi    |
    | 1        | leg-A absolute angle encoder ``alpha_A`` [rad]              | -pi    | pi    |
    | 2        | contact switch of foot A (0 or 1)                           | 0      | 1     |
    | 3        | contact switch of foot B (0 or 1)                           | 0      | 1     |
    | 4..3+N   | terrain height at ``x_stance + offset + k * spacing``       | -range | range |
    |          | relative to the stance-foot height [m], ``k = 0..N-1``      |        |       |

    Encoders are quantised (``sensors.encoder_resolution``, default ``2 pi / 4096`` rad) after
    Gaussian noise (``sensors.encoder_noise`` rad); heights get ``sensors.scan_noise`` m noise
    and ``sensors.scan_resolution`` quantisation; ``sensors.latency`` delays the whole vector
    by whole control periods. The stance leg is not observed directly: it follows from the
    contact switches (``envs.sensors.encoders_to_q`` maps encoders and stance leg to ``q``).

    ``observation="state"``: the true state, float32 of length ``5 + N``: ``q1, q2`` [rad],
    ``q1dot, q2dot`` [rad/s] (clipped to +-100), ``1.0`` if leg B is the stance leg else
    ``0.0``, and the ``N`` exact terrain heights relative to the stance foot.

    ## Rewards

    ``r = progress * dx_hip - energy * W - failure * [the walker failed in this step]``, where
    ``dx_hip`` [m] is the forward displacement of the hip over the step and ``W`` [J] the motor
    work over the step (``reward.work``: ``"absolute"`` ``int |tau q1dot| dt`` by default).
    Weights in ``reward`` (presets: ``progress = 1``, ``energy = 0.05`` (paper robot) or
    ``0.01`` (classic), ``failure = 1``).

    ## Starting State

    A post-impact state of a nominal gait (``initial_state.q``, ``initial_state.qd``) plus a
    uniform perturbation of half-widths ``initial_state.spread`` drawn from ``np_random``, the
    stance foot at ``x = 0`` on the ground, leg ``initial_state.stance_leg`` in stance.
    ``reset(options=...)`` accepts ``"state": (q, qd)`` (exact start, no spread),
    ``"terrain"`` (a Terrain, spec dict or name, for this episode) and ``"stance_leg"``
    (``"A"`` or ``"B"``).

    ## Episode End

    Termination: the walker fails (``info["failure"]``: ``"fall"``, ``"trip"``, ``"liftoff"``,
    ``"slip"``, ``"stuck"`` or ``"invalid"``; see :mod:`envs.simulator`). Truncation: the time
    limit of the registered id (``max_episode_steps``, applied by ``gym.make``).

    ## Info

    Every ``reset`` and ``step`` returns ``state`` (true ``[q1, q2, q1dot, q2dot]``),
    ``stance_foot`` (``[x, y]`` m), ``stance_leg`` (0 = A, 1 = B), ``time`` (s),
    ``footsteps`` (impacts since reset), ``distance`` (hip displacement since reset, m),
    ``impacts`` (in this step), ``motor_work`` (this step, J, the kind ``reward.work``),
    ``failure`` (name or None); ``reset`` and the step that terminates an episode also return
    ``terrain`` (the course's spec dict: ``Terrain.from_dict`` rebuilds it exactly, so any
    episode can be replayed; do not modify it). The vector env returns it at every step.

    ## Arguments

    ``gym.make("roughwalk/CompassGait-v0", config="flat", robot=None, terrain=None,
    difficulty=None, dt=None, u_max=None, torque_limit=None, observation=None, sensors=None,
    reward=None, initial_state=None, simulator=None, render_mode=None)``: ``config`` names a
    file in ``configs/envs`` (or a YAML path / dict); every other argument overrides it
    (``None`` keeps the config's value; mappings are merged field by field):

    * ``robot``: preset name (``"paper"``, ``"classic"``), dict or RobotParams;
    * ``terrain``: Terrain, spec dict, or a name in ``configs/terrains``; a ``blocks`` or
      ``piecewise`` spec without ``seed`` draws a new course from ``np_random`` at every reset;
    * ``difficulty``: scales the heights of random terrain;
    * ``dt``: control period [s];
    * ``u_max`` (actuator limit [input units]) or ``torque_limit`` (the same as a hip torque
      [N m]);
    * ``observation``: ``"sensors"`` or ``"state"``;
    * ``sensors``: :class:`envs.sensors.SensorConfig` fields (resolution, noise, scan count,
      offset, spacing, range, latency);
    * ``reward``: :class:`RewardConfig` fields; ``initial_state``: :class:`InitialState`
      fields (nominal state, spread, stance leg); ``simulator``:
      :class:`envs.simulator.SimConfig` fields.

    For a controller, ``env.unwrapped`` exposes ``robot`` (RobotParams; alias ``params``),
    ``terrain`` (this episode's Terrain), ``dt``, ``u_max``, ``torque_limit``,
    ``sensor_config``, ``sensor_layout`` and :meth:`action_from_input`.

    ## Version History

    * v0: initial version.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 200}

    def __init__(
        self,
        config: str | Path | dict[str, Any] = "flat",
        *,
        render_mode: str | None = None,
        **kwargs: Any,
    ):
        settings = kwargs.pop("settings", None)
        if settings is None:
            settings = EnvSettings.build(config, **kwargs)
        elif kwargs:
            raise ValueError("pass either settings or keyword overrides, not both")
        self.settings = settings
        self._batch = b = WalkerBatch(settings, 1, parallel=False)
        self.robot = self.params = settings.robot
        self.dt = settings.dt
        self.u_max = settings.robot.u_max
        self.torque_limit = settings.robot.tau_max
        self.sensor_config = settings.sensors
        self.sensor_layout = b.layout
        self.observation_mode = settings.observation
        self.terrain: Terrain | None = settings.terrain.fixed
        self.planned_footholds: list[float] = []
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / settings.dt}
        self.action_space = spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)
        self.observation_space = spaces.Box(b.obs_low, b.obs_high, dtype=np.float32)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode = {render_mode!r}; allowed: {self.metadata['render_modes']}"
            )
        self.render_mode = render_mode
        b.track_footholds = render_mode is not None
        self._renderer = None
        self._tau = b.tau
        self._scale = self.torque_limit

    # ------------------------------------------------------------------ controller helpers
    def action_from_input(self, u: float | np.ndarray) -> np.ndarray:
        """Action for a motor input ``u`` [input units] (``u / u_max``, clipped, float32)."""
        return (
            np.clip(np.asarray(u, dtype=np.float64) / self.u_max, -1, 1)
            .astype(np.float32)
            .reshape(1)
        )

    def action_from_torque(self, tau: float | np.ndarray) -> np.ndarray:
        """Action for a hip torque ``tau`` [N m] (clipped, float32)."""
        return (
            np.clip(np.asarray(tau, dtype=np.float64) / self.torque_limit, -1, 1)
            .astype(np.float32)
            .reshape(1)
        )

    # ------------------------------------------------------------------ gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        b = self._batch
        b.reset_walker(0, self.np_random, options)
        self.terrain = b.terrains[0]
        self.planned_footholds = []
        if self.render_mode == "human":
            self.render()
        return b.observation(0), b.info(0)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        b = self._batch
        if type(action) is np.ndarray and action.shape == (1,):
            a = float(action[0])
            if not math.isfinite(a):
                raise ValueError(f"action = {a!r} must be finite (allowed: [-1, 1])")
            if a > 1.0:
                a = 1.0
            elif a < -1.0:
                a = -1.0
            self._tau[0] = a * self._scale
        else:
            actions_to_torques(action, self._scale, self._tau)
        b.step()
        if self.render_mode == "human":
            self.render()
        terminated = bool(b.terminated[0])
        return (
            b.observation(0),
            float(b.reward[0]),
            terminated,
            False,
            b.info(0, terrain=terminated),
        )

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        if self._renderer is None:
            from .rendering import WalkerRenderer

            self._renderer = WalkerRenderer(
                self.robot.l, self.render_mode, fps=self.metadata["render_fps"]
            )
        if self._batch.terrains[0] is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        return self._renderer.render(**self._batch.render_args(0), planned=self.planned_footholds)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
