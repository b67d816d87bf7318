"""The Gymnasium environment of the compass-gait biped (:class:`CompassGaitEnv`).

The env is a :class:`envs.batch.WalkerBatch` of one walker; its settings come from an env config
in ``configs/envs/`` (``config="flat"``, ``"stairs"``, ``"rough"``, ``"slope"`` or a path) and
keyword overrides, resolved by :func:`envs.settings.resolve_env_settings`. The batch turns the
action into the hip torque; the hip command's units from a controller's input to the equations
of motion are documented in :mod:`envs.physics.actuator`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .batch import WalkerBatch
from .physics.actuator import action_from_input, action_from_torque
from .physics.simulator import Simulator
from .physics.terrain import Terrain
from .rendering import WalkerRenderer
from .settings import resolve_env_settings


class CompassGaitEnv(gym.Env):
    """A planar compass-gait biped walking over terrain with one hip motor.

    ## Description

    Two rigid legs joined at the hip, point feet, one motor between the legs (Manchester,
    Mettin, Iida, Tedrake 2011, "Stable Dynamic Walking over Rough Terrain"). The robot walks
    towards +x: each step the swing leg swings forward on a retractable foot and touches down;
    the impact is instantaneous and the legs swap roles. The simulator integrates the swing
    phase exactly and locates touchdowns to 1e-9 s or better (:mod:`envs.physics`). Robots:
    the paper's robot (``"paper"``, legs 0.32 m) and the classic symmetric walker
    (``"classic"``, legs 1 m).

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: the normalised hip command. The motor input is
    ``u = action * u_max`` [input units] and the hip torque ``input_gain * u`` [N m]
    (``input_gain = kI * ktau``; ``env.unwrapped.torque_limit`` N m at ``|action| = 1``), held
    over the control period ``env.unwrapped.dt``. Out-of-range actions are clipped to [-1, 1];
    NaN or inf raise ``ValueError``. :mod:`envs.physics.actuator` documents the whole unit
    chain.

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
    contact switches (``envs.encoders_to_q`` maps encoders and stance leg to ``q``).

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
    ``"slip"``, ``"stuck"`` or ``"invalid"``; see :mod:`envs.physics`). Truncation: the time
    limit of the registered id (``max_episode_steps``, applied by ``gym.make``).

    ``"invalid"`` means the simulation blew up (a non-finite state, or angles or rates beyond
    physical bounds: :mod:`envs.physics.kernel`). The walker is then put back to its last valid
    state (the start of the RK4 substep that diverged), and the observation, reward, info and
    rendering of that step are those of this state: always finite and within the observation
    space, the reward with the failure penalty. Absurd settings and start states that would
    blow up are rejected up front (:class:`envs.physics.RobotParams` bounds, the reset option
    ``"state"`` bounded by ``RobotParams.max_rate``).

    ## Info

    Every ``reset`` and ``step`` returns ``state`` (true ``[q1, q2, q1dot, q2dot]``),
    ``stance_foot`` (``[x, y]`` m), ``stance_leg`` (0 = A, 1 = B), ``time`` (s),
    ``footsteps`` (impacts since reset), ``distance`` (hip displacement since reset, m),
    ``impacts`` (in this step), ``motor_work`` (this step, J, the kind ``reward.work``),
    ``failure`` (name or None); ``reset`` and the step that terminates an episode also return
    ``terrain`` (the course's spec dict: ``Terrain.from_dict`` rebuilds it exactly, so any
    episode can be replayed; do not modify it). The vector env returns it at every step.
    Under a model error (``robot_error``) ``robot`` (the true parameters of this episode, a
    dict of floats: ``RobotParams.from_dict`` rebuilds it) comes with ``terrain``, also at
    every step of the vector env (do not modify it); a step in which the hip was pushed
    (``push``) has ``push``: ``{"time": s, "dv": m/s (signed, forwards positive),
    "impulse": N s}`` (in the vector env, Gymnasium's nested arrays with their ``_`` masks).

    ## Arguments

    ``gym.make("roughwalk/CompassGait-v0", config="flat", robot=None, terrain=None,
    difficulty=None, dt=None, u_max=None, torque_limit=None, observation=None, sensors=None,
    reward=None, initial_state=None, simulator=None, robot_error=None, push=None,
    render_mode=None)``: ``config`` names a
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
    * ``reward``: :class:`envs.task.RewardConfig` fields; ``initial_state``:
      :class:`envs.task.InitialState` fields (nominal state, spread, stance leg); ``simulator``:
      :class:`envs.physics.SimConfig` fields;
    * ``robot_error``: model error (:class:`envs.disturbances.RobotError`): a relative
      half-width for every physical parameter (``m, mH, mHg, Ic, l, lc, Fc, Fv, ktau``) or a
      mapping ``{parameter: half-width}``, each in [0, 0.5); at every reset the simulated
      robot is drawn uniformly within it from ``np_random`` (``lc`` moves with ``l``), while
      ``env.unwrapped.robot`` stays the nominal model. Default 0: none;
    * ``push``: hip pushes (:class:`envs.disturbances.PushConfig`), e.g.
      ``{"dv": 0.1, "at": "mid_stance"}`` or ``{"dv": [0.05, 0.15], "every": [1, 2]}``: the
      hip's horizontal speed jumps by ``dv`` [m/s] (forwards or backwards at random, or
      ``direction``), through the model with the stance foot held
      (:func:`envs.physics.model.hip_push`). Default None (``False`` switches a config's
      pushes off).

    ``settings`` (an :class:`envs.settings.EnvSettings`) may replace ``config`` and the
    overrides.

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
            settings = resolve_env_settings(config, **kwargs)
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

    @property
    def simulator(self) -> Simulator:
        """The batched simulator (of one walker) this env steps, for diagnostics and benchmarks;
        stepping or resetting it directly desynchronises the env."""
        return self._batch.sim

    # ------------------------------------------------------------------ controller helpers
    def action_from_input(self, u: float | np.ndarray) -> np.ndarray:
        """Action for a motor input ``u`` [input units] (``u / u_max``, clipped, float32)."""
        return np.array([action_from_input(_one("u", u), self.u_max)], dtype=np.float32)

    def action_from_torque(self, tau: float | np.ndarray) -> np.ndarray:
        """Action for a hip torque ``tau`` [N m] (``tau / torque_limit``, clipped, float32)."""
        return np.array([action_from_torque(_one("tau", tau), self.torque_limit)], dtype=np.float32)

    # ------------------------------------------------------------------ gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; returns the observation and the info.

        Args:
            seed: seed of the env's random generator (None: keep the current one, or draw a
                fresh one on the first reset).
            options: ``"state"``, ``"terrain"``, ``"stance_leg"`` (see the class docstring).
        """
        super().reset(seed=seed)
        b = self._batch
        b.reset_walker(0, self.np_random, options)
        self.terrain = b.terrains[0]
        self.planned_footholds = []
        if self.render_mode == "human":
            self.render()
        return b.observation(0), b.info(0)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the hip command ``action`` in [-1, 1] for one control period."""
        b = self._batch
        b.step(action)
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
        """An RGB frame (``"rgb_array"``) or a window update (``"human"``)."""
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        if self._renderer is None:
            self._renderer = WalkerRenderer(
                self.robot.l, self.render_mode, fps=self.metadata["render_fps"]
            )
        if self._batch.terrains[0] is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        return self._renderer.render(**self._batch.render_args(0), planned=self.planned_footholds)

    def close(self) -> None:
        """Close the renderer (its window, if any)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def _one(name: str, value: float | np.ndarray) -> float:
    """``value`` as one float (a number or an array of one entry)."""
    a = np.asarray(value, dtype=np.float64)
    if a.size != 1:
        raise ValueError(f"{name} must be one number, got shape {a.shape}")
    return float(a.reshape(-1)[0])
