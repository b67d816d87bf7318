"""Evaluation of a policy on held-out courses: success, footsteps, distance, speed, cost of
transport.

Seed split: training envs are seeded below 1,000,000 (``agents.config.TRAIN_SEED_LIMIT``);
evaluation episode ``k`` resets its env with seed ``1,000,000 + S + k`` (``seed=S``, S >= 0),
so evaluation courses are never the ones a training run starts from. Seeds 1,000,000 to
1,000,999 are the validation courses of the periodic evaluation during training (which selects
``best_model.zip``); ``seed`` defaults to 1000 (``agents.config.TEST_SEED``), past them. The
absolute seed of every episode is recorded in the JSON/CSV output: ``env.reset(seed=...)``
replays it.

Metrics per episode: success (no failure before the episode ended, i.e. the time limit was
reached), footsteps taken (until failure or time limit), distance walked [m], mean speed
[m/s] (distance over episode duration), motor work [J] (absolute, ``int |tau q1dot| dt``), and
cost of transport ``work / (m g distance)`` with ``m`` the robot's total mass. Summary: means
over episodes; the summary cost of transport is total work over total ``m g distance``.

Certificate (the ``reference`` policy only: the transverse controller's Riccati gains; None for
every other policy): per completed footstep the Lyapunov value ``V = x_perp' P x_perp`` at its
first and last tick, their ratio, the largest ``|x_perp|`` and ``|u|``
(:meth:`controllers.controller.StepRecord.certificate`), and per episode and in the summary
the median and largest ratio and the fraction of footsteps with ratio below 1. The
``controller_mode`` (``replan`` or ``fixed-plan``) says which certificate that is: in replan
mode every step starts at ``V`` about 0 and the ratios are not a certificate.
"""

from __future__ import annotations

import csv
import json
import warnings
import zipfile
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs  # noqa: F401  (registers the roughwalk ids)
from agents.config import EVAL_SEED_OFFSET, MAX_SEED, TEST_SEED, ConfigError
from agents.policies import (
    BASELINES,
    Policy,
    base_settings,
    make_baseline_policy,
    settings_changes,
)
from agents.pretrained import resolve_model
from agents.runs import atomic_write_stream, find_vecnormalize, load_vecnormalize
from agents.trained import TrainedPolicy, load_policy
from controllers.controller import ControllerConfig, PDController, TransverseController
from controllers.planner import PlannerConfig
from controllers.reference import ADDED_SETTINGS
from envs.config_util import real_setting

#: the baselines that take a controller mode (``--controller-mode``)
CONTROLLED_BASELINES = ("pd", "reference")
#: how the pd and reference baselines know where they are and what the ground is
#: (``controllers.ReferencePolicy``'s ``localise`` and ``mapping``)
PERCEPTION_MODES = ("known-map", "localise", "mapping")


def eval_seeds(seed: int, episodes: int) -> list[int]:
    """Absolute reset seeds of ``episodes`` evaluation episodes for user seed ``seed`` >= 0."""
    if seed < 0 or EVAL_SEED_OFFSET + seed + episodes - 1 > MAX_SEED:
        hi = MAX_SEED - EVAL_SEED_OFFSET - episodes + 1
        raise ValueError(
            f"seed = {seed} is out of range; allowed: [0, {hi}]"
            " (evaluation seeds are offset by 1,000,000 to stay disjoint from training seeds)"
        )
    if episodes < 1:
        raise ValueError(f"episodes = {episodes} is out of range; allowed: >= 1")
    return [EVAL_SEED_OFFSET + seed + k for k in range(episodes)]


@dataclass
class EpisodeResult:
    """One evaluation episode.

    Attributes:
        seed: the absolute reset seed (``env.reset(seed=seed)`` replays the episode).
        success: no failure before the episode ended.
        failure: the failure's name (``envs.FAILURES``), or None.
        steps: control steps taken.
        duration: ``steps`` times the control period [s].
        footsteps: footsteps taken.
        distance: distance walked [m].
        speed: ``distance / duration`` [m/s].
        motor_work: absolute motor work [J].
        cost_of_transport: ``motor_work / (m g distance)``, None without forward progress.
        episode_return: sum of the rewards.
        certificate: per completed footstep (the step in progress at the end left out) its
            ``index`` and :meth:`controllers.controller.StepRecord.certificate` values; None
            for a policy without the transverse controller.
        V_ratio_median, V_ratio_max: median and largest ``V_end / V_start`` over those
            footsteps (None without any).
        V_ratio_below_1: fraction of those footsteps with ``V_end / V_start < 1``.
        foot_error_max: largest ``|estimated - true|`` stance-foot x over the touchdowns [m]
            (the policy's ``stance_foot`` against ``info["stance_foot"]``); None for a policy
            that does not estimate it.
        policy_error: the error the policy raised and survived by going limp (the reference
            and PD policies never crash a rollout: ``diagnostics["error"]``), or None. A
            failure after one is a defect of the policy, not of the walk.
    """

    seed: int
    success: bool
    failure: str | None
    steps: int
    duration: float
    footsteps: int
    distance: float
    speed: float
    motor_work: float
    cost_of_transport: float | None  # None when the walker made no forward progress
    episode_return: float
    certificate: list[dict[str, Any]] | None = None
    V_ratio_median: float | None = None
    V_ratio_max: float | None = None
    V_ratio_below_1: float | None = None
    foot_error_max: float | None = None
    policy_error: str | None = None


@dataclass
class Evaluation:
    """Episodes of one policy on one env, and their summary.

    Attributes:
        policy: the policy evaluated (a baseline's name or a model's path).
        env_id: Gymnasium id of the env.
        env_kwargs: keyword arguments the env was made with.
        episodes: the episodes, in seed order.
        total_mass: the robot's total mass [kg].
        gravity: gravitational acceleration [m/s^2].
        summary: the metrics over the episodes (computed by :func:`summarize` when empty).
        controller_mode: the transverse controller's mode (``replan`` or ``fixed-plan``) for
            the ``pd`` and ``reference`` policies, else None.
    """

    policy: str
    env_id: str
    env_kwargs: dict[str, Any]
    episodes: list[EpisodeResult]
    total_mass: float
    gravity: float
    summary: dict[str, Any] = field(default_factory=dict)
    controller_mode: str | None = None

    def __post_init__(self) -> None:
        if not self.summary:
            self.summary = summarize(self.episodes, self.total_mass, self.gravity)

    def to_dict(self) -> dict[str, Any]:
        """The evaluation as plain data (the JSON output)."""
        return {
            "policy": self.policy,
            "env_id": self.env_id,
            "env_kwargs": self.env_kwargs,
            "total_mass": self.total_mass,
            "gravity": self.gravity,
            "summary": self.summary,
            "controller_mode": self.controller_mode,
            "episodes": [asdict(e) for e in self.episodes],
        }


def summarize(episodes: Sequence[EpisodeResult], total_mass: float, g: float) -> dict[str, Any]:
    """Aggregate metrics over episodes (see the module docstring)."""
    n = len(episodes)
    failed = [e for e in episodes if not e.success]
    distance = sum(e.distance for e in episodes)
    work = sum(e.motor_work for e in episodes)
    return {
        "episodes": n,
        "success_rate": sum(e.success for e in episodes) / n,
        "mean_footsteps": float(np.mean([e.footsteps for e in episodes])),
        "mean_footsteps_failed": (
            float(np.mean([e.footsteps for e in failed])) if failed else None
        ),
        "mean_distance": float(np.mean([e.distance for e in episodes])),
        "mean_speed": float(np.mean([e.speed for e in episodes])),
        "cost_of_transport": work / (total_mass * g * distance) if distance > 0 else None,
        "mean_return": float(np.mean([e.episode_return for e in episodes])),
        "failure_reasons": dict(Counter(e.failure for e in failed if e.failure)),
        "policy_errors": sum(e.policy_error is not None for e in episodes),
        **ratio_summary(
            None if all(e.certificate is None for e in episodes) else _ratios(episodes)
        ),
    }


def _ratios(episodes: Sequence[EpisodeResult]) -> list[float]:
    """The known ``V_end / V_start`` of every completed footstep of the ``episodes``."""
    return [c["V_ratio"] for e in episodes for c in e.certificate or () if c["V_ratio"] is not None]


def ratio_summary(ratios: Sequence[float] | None) -> dict[str, float | None]:
    """``V_ratio_median``, ``V_ratio_max`` and ``V_ratio_below_1`` (the fraction below 1) of
    the footsteps' ``ratios`` (all None for None or none)."""
    if not ratios:
        return {"V_ratio_median": None, "V_ratio_max": None, "V_ratio_below_1": None}
    r = np.asarray(ratios, dtype=float)
    return {
        "V_ratio_median": float(np.median(r)),
        "V_ratio_max": float(r.max()),
        "V_ratio_below_1": float(np.mean(r < 1)),
    }


def footstep_certificate(policy: Policy) -> list[dict[str, Any]] | None:
    """Per completed footstep of ``policy``'s last episode: ``index`` and the
    :meth:`controllers.controller.StepRecord.certificate` values; None unless the policy runs
    the transverse controller (plain PD has no Lyapunov function)."""
    ctrl = getattr(policy, "controller", None)
    if not isinstance(ctrl, TransverseController) or isinstance(ctrl, PDController):
        return None
    ran = [r for r in ctrl.records if r.ticks > 0]
    return [{"index": r.index, **r.certificate()} for r in ran[:-1]]


def _robot(env: gym.Env) -> tuple[float, float, float]:
    """(total mass [kg], g [m/s^2], control period [s]) of a roughwalk env."""
    base = env.unwrapped
    params = base.params
    return float(params.total_mass), float(params.g), float(base.dt)


def run_episode(
    env: gym.Env, policy: Policy, seed: int, max_steps: int | None = None
) -> EpisodeResult:
    """Roll ``policy`` out on ``env`` from ``reset(seed=seed)`` until the episode ends (or
    after ``max_steps`` control steps, if given; an agent step of
    :class:`agents.footstep.FootstepWrapper` counts its ``info["ticks"]``)."""
    mass, g, dt = _robot(env)
    obs, info = env.reset(seed=seed)
    policy.reset()
    total_return = 0.0
    steps = 0
    work = 0.0
    terminated = truncated = False
    estimates = hasattr(policy, "stance_foot")
    foot, foot_error = None, None
    while not (terminated or truncated):
        action = policy(obs)
        true = info.get("stance_foot")
        if estimates and true is not None and (foot is None or true[0] != foot):
            foot = true[0]  # a touchdown (or the start): the policy has located it by now
            err = abs(float(policy.stance_foot[0]) - float(foot))
            foot_error = err if foot_error is None else max(foot_error, err)
        obs, reward, terminated, truncated, info = env.step(action)
        total_return += float(reward)
        work += float(info.get("motor_work", 0.0))
        steps += int(info.get("ticks", 1))  # control periods (a footstep wrapper's many)
        if max_steps is not None and steps >= max_steps:
            break
    failure = info.get("failure") or None
    distance = float(info.get("distance", 0.0))
    duration = steps * dt
    cert = footstep_certificate(policy)
    ratios = None if cert is None else [c["V_ratio"] for c in cert if c["V_ratio"] is not None]
    return EpisodeResult(
        seed=seed,
        success=failure is None,
        failure=failure,
        steps=steps,
        duration=duration,
        footsteps=int(info.get("footsteps", 0)),
        distance=distance,
        speed=distance / duration if duration > 0 else 0.0,
        motor_work=work,
        cost_of_transport=work / (mass * g * distance) if distance > 0 else None,
        episode_return=total_return,
        certificate=cert,
        **ratio_summary(ratios),
        foot_error_max=foot_error,
        policy_error=(getattr(policy, "diagnostics", None) or {}).get("error"),
    )


def make_env(env_id: str, env_kwargs: dict[str, Any] | None = None) -> gym.Env:
    """``gym.make(env_id, **env_kwargs)`` for a roughwalk env, with bad input as ``ValueError``.

    Args:
        env_id: a registered ``roughwalk/...`` Gymnasium id.
        env_kwargs: keyword arguments of ``gym.make`` (settings of ``envs.CompassGaitEnv``).

    Raises:
        ConfigError: ``env_id`` is not registered, or not a roughwalk env.
        ValueError: a keyword argument is unknown or has a bad value, or a settings file it
            names is not valid YAML.
    """
    ours = sorted(k for k in gym.registry if k.startswith("roughwalk/"))
    if env_id not in ours:
        what = "not a roughwalk env" if env_id in gym.registry else "unknown environment id"
        raise ConfigError(f"{what} {env_id!r}; registered: {', '.join(ours)}")
    env_kwargs = dict(env_kwargs or {})
    try:
        env = gym.make(env_id, **env_kwargs)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" ({mark.name}, line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or " ".join(str(exc).split())
        raise ValueError(
            f"{env_id} with {env_kwargs}: a settings file is not valid YAML{where}: {problem}"
        ) from exc
    except TypeError as exc:  # an unknown keyword, or a value of the wrong kind
        raise ValueError(f"{env_id} with {env_kwargs}: {exc}") from exc
    if not isinstance(env.unwrapped, envs.CompassGaitEnv):
        env.close()
        raise ConfigError(f"{env_id} is not a roughwalk env (envs.CompassGaitEnv)")
    return env


def check_vecnormalize(path: str | Path) -> None:
    """Check that ``path`` holds ``VecNormalize`` statistics saved by stable-baselines3.

    Loading unpickles the file, which can run code: load only files you trust.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is damaged or holds something else.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"VecNormalize statistics not found: {path}")
    try:
        stats = load_vecnormalize(path)
    except Exception as exc:  # unpickling a damaged file can raise almost anything
        detail = " ".join(str(exc).split())
        if isinstance(exc, ValueError) and str(path) in detail:
            raise ValueError(detail) from exc  # already says which file and why
        raise ValueError(
            f"{path}: not VecNormalize statistics saved by stable-baselines3 (damaged or "
            f"another kind of file: {type(exc).__name__}: {detail})"
        ) from exc
    if not callable(getattr(stats, "normalize_obs", None)):
        raise ValueError(f"{path}: holds a {type(stats).__name__}, not VecNormalize statistics")


def load_trained(
    model_path: str | Path, vecnormalize: str | Path | None = None, algo: str | None = None
) -> TrainedPolicy:
    """A trained model with its statistics, damaged files reported as ``ValueError``.

    Loading unpickles the model file and the statistics file, which can run code: load only
    files you trust. Nothing but these two files (and the run's manifest) is read.

    Args:
        model_path: the model file (``.zip``) saved by stable-baselines3, or a shipped agent
            (``pretrained:NAME``, :mod:`agents.pretrained`).
        vecnormalize: its ``VecNormalize`` statistics (default: the file saved beside it).
        algo: its algorithm (``ppo``, ``sac``, ...; default: from its run or the file).

    Raises:
        FileNotFoundError: a file is missing.
        ValueError: a file is damaged, not what it should be, or the algorithm is unknown.
    """
    path = Path(resolve_model(str(model_path)))
    if not path.is_file():
        raise FileNotFoundError(f"model file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: not a model saved by stable-baselines3 (not a zip archive)")
    vn = Path(vecnormalize) if vecnormalize is not None else find_vecnormalize(path)
    if vn is not None:
        check_vecnormalize(vn)
    kwargs: dict[str, Any] = {"vecnormalize": vn}
    if algo is not None:
        kwargs["algo"] = algo
    try:
        policy = load_policy(str(path), **kwargs)
    except (ValueError, OSError):
        raise
    except Exception as exc:  # unpickling a damaged file can raise almost anything
        raise ValueError(
            f"{path}: a damaged model file ({type(exc).__name__}: {' '.join(str(exc).split())})"
        ) from exc
    assert isinstance(policy, TrainedPolicy)
    return policy


class BaseChangedWarning(UserWarning):
    """A trained agent is evaluated on a base policy whose settings differ from those its
    manifest records (``base_settings``: the base it was trained on; for the shipped agents
    trained before runs recorded it, the base their card's check courses were walked on when
    it was first recorded): this release's defaults changed since."""


def _with_added(recorded: dict[str, Any], added: dict[str, Any]) -> dict[str, Any]:
    """``recorded`` with the settings of ``added`` it lacks, nested mappings merged key by
    key (a section the record lacks altogether is not added)."""
    out = dict(recorded)
    for key, value in added.items():
        if isinstance(value, dict):
            if isinstance(out.get(key), dict):
                out[key] = _with_added(out[key], value)
        elif key not in out:
            out[key] = value
    return out


def warn_changed_base(policy_spec: str, manifest: dict[str, Any], env: gym.Env) -> list[str]:
    """Warn (:class:`BaseChangedWarning`) when the base policies of ``env``'s wrappers differ
    from those the run's ``manifest`` records (``base_settings``, written by ``roughwalk
    train``; runs without them are not checked; an option added since,
    ``controllers.reference.ADDED_SETTINGS``, counts at the value that behaves as before),
    naming the settings that changed; returns them."""
    recorded = manifest.get("base_settings")
    if not recorded:
        return []
    # an option added since the run was recorded had the value that behaves as before
    recorded = [_with_added(base, ADDED_SETTINGS) for base in recorded]
    changes = settings_changes(recorded, base_settings(env))
    if changes:
        shown = "; ".join(changes[:4]) + (
            f"; and {len(changes) - 4} more" if len(changes) > 4 else ""
        )
        warnings.warn(
            f"{policy_spec}: its base policy's settings differ from those its manifest records "
            f"(base_settings: {shown}); to evaluate it on its own base, set them in its "
            "config's base_kwargs",
            BaseChangedWarning,
            stacklevel=2,
        )
    return changes


def make_eval_env(
    policy_spec: str,
    env_id: str | None,
    env_kwargs: dict[str, Any] | None = None,
    vecnormalize: str | None = None,
    algo: str | None = None,
    controller_mode: str | None = None,
    plan_steps: int | None = None,
    perception: str | None = None,
    planner: dict[str, Any] | None = None,
    controller: dict[str, Any] | None = None,
    observer_eps: float | None = None,
    identify: int | None = None,
    leg_margin: float | None = None,
    foot_estimate: str | None = None,
    long_segment: float | None = None,
    drop_edge_sd: float | None = None,
) -> tuple[gym.Env, Policy, str, dict[str, Any]]:
    """The env (with the agent's wrappers) and the policy for ``policy_spec``.

    Args:
        policy_spec: a baseline's name (``BASELINES``) or the path of a trained model.
        env_id: Gymnasium id; None for a trained model's own env (from its run).
        env_kwargs: keyword arguments of ``gym.make`` (default: a trained model's own).
        vecnormalize: a trained model's ``VecNormalize`` statistics (default: beside it).
        algo: a trained model's algorithm (default: from its run or the file).
        controller_mode: ``replan`` or ``fixed-plan`` for the ``pd`` and ``reference``
            baselines (None: their default, replan).
        plan_steps: footsteps of the fixed plan (fixed-plan only; None: sized for the env's
            episode, see :meth:`controllers.ControllerConfig.for_mode`).
        perception: for the ``pd`` and ``reference`` baselines, one of ``PERCEPTION_MODES``:
            ``known-map`` (the course's map, the stance foot dead-reckoned from the model),
            ``localise`` (None, their default where the env has a scanner: the stance foot
            located by the terrain scan on the map) or ``mapping`` (plan on a map built from
            the scans, never the course).
        planner: for the ``pd`` and ``reference`` baselines, :class:`controllers.PlannerConfig`
            fields that override the robot's preset (e.g. ``{"min_thetadot": 0.3}``).
        controller: for the ``pd`` and ``reference`` baselines,
            :class:`controllers.ControllerConfig` fields (e.g. ``{"horizon": 2}``; the mode is
            ``controller_mode``'s).
        observer_eps: for the ``pd`` and ``reference`` baselines, the high-gain observer's time
            constant [s] (> 0; None: the policy's default, 0.04 s; the paper's: 0.02 s).
        identify: for the ``pd`` and ``reference`` baselines, identify the swing dynamics
            online after each of the first ``identify`` footsteps (an integer >= 0; 0: off;
            None: the policy's default, 6; see :class:`controllers.ReferencePolicy`).
        leg_margin: for the ``pd`` and ``reference`` baselines, foothold margins widened by
            this many standard deviations of the leg-length uncertainty (in [0, 10]; None: the
            policy's default, 0, off; see :class:`controllers.ReferencePolicy`).
        foot_estimate: for the ``pd`` and ``reference`` baselines, the point of the
            localisation's belief the stance foot is corrected to: ``"mean"`` (None: the
            policy's default) or ``"selected"`` (see :class:`controllers.ReferencePolicy`).
        long_segment: for the ``pd`` and ``reference`` baselines, the online identification's
            long shooting segments [s] (in [0, 1]; 0: short segments only, the fits before
            this default; None: the policy's default, 0.3; see
            :class:`controllers.ReferencePolicy`).
        drop_edge_sd: for the ``pd`` and ``reference`` baselines, footholds near a step-down
            riser ranked last within this many standard deviations of the leg-length
            uncertainty (in [0, 10]; 0: off; None: the policy's default, 9 where it
            localises; see :class:`controllers.ReferencePolicy`).

    Returns:
        ``(env, policy, env_id, env_kwargs)``, with the env id and keyword arguments used.
    """
    settings = {
        "controller_mode": controller_mode,
        "perception": perception,
        "planner": planner,
        "controller": controller,
        "observer_eps": observer_eps,
        "identify": identify,
        "leg_margin": leg_margin,
        "foot_estimate": foot_estimate,
        "long_segment": long_segment,
        "drop_edge_sd": drop_edge_sd,
    }
    for name, value in settings.items():
        if value is not None and policy_spec not in CONTROLLED_BASELINES:
            raise ValueError(
                f"{name}: applies to the {' and '.join(CONTROLLED_BASELINES)} policies, "
                f"not to {policy_spec}"
            )
    if plan_steps is not None and controller_mode != "fixed-plan":
        raise ValueError("plan_steps: applies to controller_mode fixed-plan only")
    options: dict[str, Any] = {}
    if perception is not None:
        if perception not in PERCEPTION_MODES:
            raise ValueError(f"perception = {perception!r}; allowed: {', '.join(PERCEPTION_MODES)}")
        options["localise"] = perception == "localise"
        options["mapping"] = perception == "mapping"
    for name, value in (("planner", planner), ("controller", controller)):
        if value is not None and not isinstance(value, dict):
            raise ValueError(f"{name} = {value!r}; allowed: a mapping of setting names to values")
    if observer_eps is not None:
        eps = real_setting("observer_eps", observer_eps, "a number > 0 [s]")
        if not eps > 0:
            raise ValueError(f"observer_eps = {observer_eps!r}; allowed: a number > 0 [s]")
        options["eps"] = eps
    if identify is not None:
        if isinstance(identify, bool) or not isinstance(identify, int) or identify < 0:
            raise ValueError(f"identify = {identify!r}; allowed: an integer >= 0 (footsteps)")
        options["identify"] = identify
    # checked by the policy (the env is closed if it refuses)
    if leg_margin is not None:
        options["leg_margin"] = leg_margin
    if foot_estimate is not None:
        options["foot_estimate"] = foot_estimate
    if long_segment is not None:
        options["long_segment"] = long_segment
    if drop_edge_sd is not None:
        options["drop_edge_sd"] = drop_edge_sd
    trained = None
    if policy_spec not in BASELINES:
        trained = load_trained(policy_spec, vecnormalize=vecnormalize, algo=algo)
        if env_id is None and trained.config is not None:
            env_id = trained.config.env_id
            if env_kwargs is None:
                env_kwargs = trained.config.env_kwargs
    if env_id is None:
        raise ConfigError("--env is required (no run manifest to take it from)")
    env_kwargs = dict(env_kwargs or {})
    env = make_env(env_id, env_kwargs)
    if trained is not None:
        env = trained.wrap_env(env)
        warn_changed_base(policy_spec, trained.manifest, env)
        if env.observation_space.shape != trained.model.observation_space.shape:
            raise ConfigError(
                f"{policy_spec}: the model expects observations of shape "
                f"{trained.model.observation_space.shape}, {env_id} gives "
                f"{env.observation_space.shape}"
            )
        return env, trained, env_id, env_kwargs
    if controller_mode is None and not options and not planner and not controller:
        return env, load_policy(policy_spec, env), env_id, env_kwargs
    fields = dict(controller or {})
    try:
        if controller_mode is None:
            config = ControllerConfig.for_robot(env.unwrapped.robot.name, **fields)
        else:
            steps = env.spec.max_episode_steps if env.spec is not None else None
            if plan_steps is not None:
                fields["plan_steps"] = plan_steps
            config = ControllerConfig.for_mode(
                controller_mode,
                None if steps is None else steps * env.unwrapped.dt,
                env.unwrapped.robot.name,
                **fields,
            )
        if planner:
            options["planner"] = PlannerConfig.for_robot(env.unwrapped.robot.name, **planner)
    except TypeError as exc:
        env.close()
        raise ValueError(f"controller: {exc}") from exc
    except ValueError:
        env.close()
        raise
    try:
        policy = make_baseline_policy(policy_spec, env, config=config, **options)
    except ValueError:
        env.close()
        raise
    return env, policy, env_id, env_kwargs


def evaluate(
    policy_spec: str,
    env_id: str | None,
    episodes: int = 20,
    seed: int = TEST_SEED,
    env_kwargs: dict[str, Any] | None = None,
    vecnormalize: str | None = None,
    progress: bool = False,
    algo: str | None = None,
    controller_mode: str | None = None,
    plan_steps: int | None = None,
    perception: str | None = None,
    planner: dict[str, Any] | None = None,
    controller: dict[str, Any] | None = None,
    observer_eps: float | None = None,
    identify: int | None = None,
    leg_margin: float | None = None,
    foot_estimate: str | None = None,
    long_segment: float | None = None,
    drop_edge_sd: float | None = None,
) -> Evaluation:
    """Evaluate a baseline (``passive``, ``pd``, ``reference``) or a trained model (path).

    Args:
        policy_spec: a baseline's name or the path of a trained model (``.zip``).
        env_id: Gymnasium id; None for a trained model's own env.
        episodes: number of episodes.
        seed: user seed; episode ``k`` resets with ``EVAL_SEED_OFFSET + seed + k``.
        env_kwargs: keyword arguments of ``gym.make`` (default: a trained model's own).
        vecnormalize: a trained model's ``VecNormalize`` statistics (default: beside it).
        progress: show a progress bar.
        algo: a trained model's algorithm (default: from its run or the file).
        controller_mode, plan_steps, perception, planner, controller, observer_eps, identify,
        leg_margin, foot_estimate, long_segment, drop_edge_sd: the ``pd`` and ``reference``
            baselines' controller mode, fixed-plan length, perception, planner and controller
            settings, observer time constant, online identification, foothold margins from
            the leg-length uncertainty, the localisation's point estimate, the
            identification's long segments and the drop-edge preference from the leg-length
            uncertainty (see :func:`make_eval_env`).
    """
    seeds = eval_seeds(seed, episodes)
    env, policy, env_id, env_kwargs = make_eval_env(
        policy_spec,
        env_id,
        env_kwargs,
        vecnormalize,
        algo,
        controller_mode,
        plan_steps,
        perception,
        planner,
        controller,
        observer_eps,
        identify,
        leg_margin,
        foot_estimate,
        long_segment,
        drop_edge_sd,
    )
    mass, g, _ = _robot(env)
    iterator: Any = seeds
    if progress:
        from rich.progress import track

        iterator = track(seeds, description=f"{Path(policy_spec).name} on {env_id}")
    try:
        results = [run_episode(env, policy, s) for s in iterator]
    finally:
        env.close()
    ctrl = getattr(policy, "controller", None)
    mode = ctrl.config.mode if isinstance(ctrl, TransverseController) else None
    return Evaluation(policy_spec, env_id, env_kwargs, results, mass, g, controller_mode=mode)


def write_json(evaluations: Sequence[Evaluation], path: str | Path) -> None:
    """Write the ``evaluations`` with their per-episode results to ``path`` as JSON (one
    object for one evaluation, else a list); the file appears complete or not at all."""
    data = [ev.to_dict() for ev in evaluations]
    text = json.dumps(data[0] if len(data) == 1 else data, indent=2) + "\n"
    atomic_write_stream(path, lambda fh: fh.write(text))


def write_csv(evaluations: Sequence[Evaluation], path: str | Path) -> None:
    """Write the episodes of the ``evaluations`` to ``path`` as CSV: one row per episode,
    with the policy and env in the first columns; the file appears complete or not at all."""
    # the per-footstep certificate is a list: in the JSON only
    names = [f.name for f in EpisodeResult.__dataclass_fields__.values() if f.name != "certificate"]

    def write(fh: Any) -> None:
        writer = csv.writer(fh)
        writer.writerow(["policy", "env_id", "env_kwargs", *names])
        for ev in evaluations:
            kw = json.dumps(ev.env_kwargs, sort_keys=True)
            for e in ev.episodes:
                writer.writerow([ev.policy, ev.env_id, kw, *(getattr(e, n) for n in names)])

    atomic_write_stream(path, write)


def read_monitor_logs(folder: str | Path) -> np.ndarray:
    """Training episodes of SB3 ``Monitor`` logs: rows ``(return, length, t)`` of all envs in
    ``folder``, in order of wall time ``t`` [s], then those of each resumed segment
    (``folder/resume1``, ``resume2``, ...)."""
    folder = Path(folder)
    segments = [folder] + sorted(
        folder.glob("resume*"), key=lambda p: int(p.name.removeprefix("resume") or 0)
    )
    parts = []
    for seg in segments:
        rows = []
        for path in sorted(seg.glob("*.monitor.csv")):
            with open(path) as fh:
                fh.readline()  # JSON header
                rows += [(float(r["r"]), float(r["l"]), float(r["t"])) for r in csv.DictReader(fh)]
        data = np.array(rows, dtype=np.float64).reshape(-1, 3)
        parts.append(data[np.argsort(data[:, 2], kind="stable")])
    return np.concatenate(parts)


def learning_curve_data(run_dir: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray] | None]:
    """What the learning curve of the run in ``run_dir`` plots: the training episodes (rows
    ``(return, length, t)``, see :func:`read_monitor_logs`) and the periodic evaluations
    (``timesteps``, ``results``), or None without any.

    Raises:
        ValueError: the run has neither training episodes nor evaluations (e.g. a run shorter
            than one episode and one evaluation period), or its evaluations file is damaged.
    """
    run_dir = Path(run_dir)
    episodes = read_monitor_logs(run_dir / "monitor")
    evals = None
    path = run_dir / "eval" / "evaluations.npz"
    if path.is_file():
        try:
            with np.load(path) as data:
                evals = {k: np.asarray(data[k]) for k in ("timesteps", "results")}
        except Exception as exc:  # a damaged or foreign archive
            raise ValueError(f"{path}: not an evaluations file of stable-baselines3") from exc
        if len(evals["timesteps"]) == 0:
            evals = None
    if len(episodes) == 0 and evals is None:
        raise ValueError(
            f"{run_dir}: no learning curve to plot: the run logged no finished training episode "
            "(monitor/) and no periodic evaluation (eval/evaluations.npz)"
        )
    return episodes, evals


def plot_learning_curve(run_dir: str | Path, out: str | Path) -> Path:
    """Plot the training episode returns and the periodic evaluation returns of the run in
    ``run_dir`` against env steps; writes the PNG ``out`` and returns its path (raises
    ``ValueError`` when there is nothing to plot, see :func:`learning_curve_data`)."""
    from matplotlib.figure import Figure

    run_dir = Path(run_dir)
    episodes, evals = learning_curve_data(run_dir)
    fig = Figure(figsize=(7, 4.4), layout="constrained")
    ax = fig.subplots()
    if len(episodes):
        steps = np.cumsum(episodes[:, 1])
        window = max(1, len(episodes) // 50)
        ret = np.convolve(episodes[:, 0], np.ones(window) / window, mode="valid")
        ax.plot(steps[window - 1 :], ret, lw=1, label=f"training (mean of {window} episodes)")
    if evals is not None:
        mean, std = evals["results"].mean(axis=1), evals["results"].std(axis=1)
        ax.errorbar(evals["timesteps"], mean, yerr=std, fmt="o-", ms=3, label="held-out evaluation")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(run_dir.name)
    ax.grid(alpha=0.3)
    fig.legend(loc="outside lower center", ncol=2, frameon=False)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out
