"""stable-baselines3 callbacks for roughwalk training runs: a progress bar to the steps the
run will really end at, checkpoints and best models written all or nothing, the held-out
periodic evaluation, reported one line per evaluation, the critic warm-up of residual learning
and the terrain curriculum's log."""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from agents.runs import save_checkpoint, save_model


class ProgressBar(BaseCallback):
    """A tqdm/rich progress bar over ``total`` env steps (the steps the run will end at, not
    the requested budget: PPO collects whole rollouts).

    Unlike SB3's ``progress_bar=True``, it can be closed when training stops with an
    exception (:meth:`close`), so that no half-open live display is left behind.

    Args:
        total: env steps of this training (from its start).
    """

    def __init__(self, total: int) -> None:
        super().__init__()
        self.total = int(total)
        self.pbar: Any = None
        self._start = 0

    def _on_training_start(self) -> None:
        from tqdm import TqdmExperimentalWarning

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TqdmExperimentalWarning)
            from tqdm.rich import tqdm

            self.pbar = tqdm(total=self.total)
        self._start = self.model.num_timesteps

    def _on_step(self) -> bool:
        done = min(self.model.num_timesteps - self._start, self.total)
        self.pbar.update(done - self.pbar.n)
        return True

    def _on_training_end(self) -> None:
        self.close()

    def close(self) -> None:
        """Stop the bar (idempotent)."""
        if self.pbar is not None:
            self.pbar.refresh()
            self.pbar.close()
            self.pbar = None


class Checkpoint(BaseCallback):
    """Every ``save_freq`` calls (vec-env steps), save ``<folder>/rl_model_<N>_steps.zip``
    with its ``VecNormalize`` statistics and, if asked, its replay buffer, each file all or
    nothing (``agents.runs.save_checkpoint``).

    Args:
        save_freq: calls between checkpoints (env steps / number of envs).
        folder: the checkpoint folder.
        replay_buffer: also save the replay buffer (off-policy algorithms).
    """

    def __init__(self, save_freq: int, folder: str | Path, replay_buffer: bool = False) -> None:
        super().__init__()
        self.save_freq = max(int(save_freq), 1)
        self.folder = Path(folder)
        self.replay_buffer = replay_buffer

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            save_checkpoint(self.model, self.folder, self.replay_buffer)
        return True


class SaveBestModel(BaseCallback):
    """Save ``best_model.zip`` and its ``VecNormalize`` statistics ``best_vecnormalize.pkl``
    (``callback_on_new_best`` of the evaluation), all or nothing.

    Args:
        save_path: the run folder.
    """

    def __init__(self, save_path: str | Path) -> None:
        super().__init__()
        self.save_path = Path(save_path)

    def _on_step(self) -> bool:
        save_model(self.model, self.save_path / "best_model.zip")
        return True


SaveVecNormalizeOnBest = SaveBestModel  # the name of earlier versions


class HeldOutEvalCallback(EvalCallback):
    """``EvalCallback`` on fixed held-out seeds, also logging walking metrics.

    Before every evaluation the eval env is reseeded with ``seed`` (>= the evaluation seed
    offset), so all evaluations of a run use the same held-out courses. Besides SB3's
    ``eval/mean_reward`` it logs ``eval/success_rate`` (episodes ending without failure),
    ``eval/footsteps`` and ``eval/distance`` [m], read from the env's final ``info``, and
    prints one line per evaluation. ``evaluations.npz`` in ``log_path`` is rewritten all or
    nothing after each evaluation.

    Args:
        eval_env: the evaluation env (an SB3 ``VecEnv``).
        seed: the seed of the evaluation courses (>= ``agents.config.EVAL_SEED_OFFSET``).
        report: print one line per evaluation.
        kwargs: the other arguments of SB3's ``EvalCallback``.
    """

    def __init__(self, eval_env: Any, seed: int, report: bool = True, **kwargs: Any) -> None:
        super().__init__(eval_env, **kwargs)
        self.seed = seed
        self.report = report
        self._walk: list[tuple[bool, float, float]] = []
        self._final: str | None = None
        if self.log_path is not None:  # SB3 writes <log_path>.npz; renamed after each write
            self._final = self.log_path + ".npz"
            self.log_path = os.path.join(os.path.dirname(self.log_path), ".evaluations.partial")

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        if locals_["done"]:
            info = locals_["info"]
            self._walk.append(
                (
                    not info.get("failure"),
                    float(info.get("footsteps", 0)),
                    float(info.get("distance", 0.0)),
                )
            )

    def _on_step(self) -> bool:
        due = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
        if due:
            self.eval_env.seed(self.seed)
            self._walk = []
        best_before = self.best_mean_reward
        keep_going = super()._on_step()
        if not due:
            return keep_going
        if self._final is not None and os.path.exists(self.log_path + ".npz"):
            os.replace(self.log_path + ".npz", self._final)
        line = f"eval at {self.num_timesteps:,} steps: reward {self.last_mean_reward:.2f}"
        if self.evaluations_results:
            line += f" +- {np.std(self.evaluations_results[-1]):.2f}"
        if self._walk:
            ok, steps, dist = (np.asarray(c, dtype=float) for c in zip(*self._walk))
            self.logger.record("eval/success_rate", float(ok.mean()))
            self.logger.record("eval/footsteps", float(steps.mean()))
            self.logger.record("eval/distance", float(dist.mean()))
            self.logger.dump(self.num_timesteps)
            line += (
                f", success {int(ok.sum())}/{len(ok)}, footsteps {steps.mean():.1f}, "
                f"distance {dist.mean():.2f} m"
            )
        if self.best_mean_reward > best_before:
            line += " (new best: best_model.zip)"
        if self.report:
            print(line, flush=True)
        return keep_going


def actor_parameters(model: Any) -> list[Any]:
    """The parameters that shape a model's actions: PPO and A2C: the policy branch of the MLP
    extractor, ``action_net``, ``log_std`` and the (policy's) features extractor; SAC and TD3:
    the actor. The others (value function, critics) are the critic's.

    Args:
        model: a stable-baselines3 PPO, A2C, SAC or TD3 model.
    """
    policy = model.policy
    if hasattr(policy, "action_net"):
        extractor = (
            policy.features_extractor
            if policy.share_features_extractor
            else policy.pi_features_extractor
        )
        modules = [extractor, policy.mlp_extractor.policy_net, policy.action_net]
        params = [p for m in modules for p in m.parameters()]
        log_std = getattr(policy, "log_std", None)
        return params + ([log_std] if log_std is not None else [])
    if hasattr(policy, "actor"):
        return list(policy.actor.parameters())
    raise ValueError(f"actor_parameters: unsupported policy {type(policy).__name__}")


class CriticWarmup(BaseCallback):
    """Critic warm-up of residual learning (Silver et al. 2018): for the first ``steps`` env
    steps of training the actor is frozen and only the critic learns, on the transitions of
    the frozen policy (with ``agents.residual.init_policy``: the base policy's, plus the
    configured exploration noise).

    The actor's parameters (:func:`actor_parameters`) stop requiring gradients, so the
    optimisers leave them (and their moments) untouched while the value function (PPO, A2C)
    or the critics (SAC, TD3) learn as usual; SAC's learnt entropy coefficient is held at its
    value too (restored after each of its optimiser's steps; its moments are cleared at the
    end). The updates on data collected before step ``steps`` are critic-only: PPO's first
    ``ceil(steps / (n_steps * n_envs))`` updates, SAC's updates up to that step. Logs
    ``train/actor_frozen`` (1 during the warm-up).

    Args:
        steps: length of the warm-up [env steps, all envs together], >= 0.
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
            raise ValueError(f"critic_warmup: must be an integer >= 0 (env steps), got {steps!r}")
        self.steps = steps
        self._frozen: list[Any] = []
        self._hook: Any = None

    @property
    def active(self) -> bool:
        """Whether the actor is frozen now."""
        return bool(self._frozen)

    def _on_training_start(self) -> None:
        if self.model.num_timesteps < self.steps:
            self._freeze()

    def _on_rollout_start(self) -> None:
        if self._frozen and self.model.num_timesteps >= self.steps:
            self._release()

    def _on_rollout_end(self) -> None:
        self.logger.record("train/actor_frozen", int(self.active))

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self._release()

    def _freeze(self) -> None:
        import torch

        self._frozen = [p for p in actor_parameters(self.model) if p.requires_grad]
        for p in self._frozen:
            p.requires_grad_(False)
        log_alpha = getattr(self.model, "log_ent_coef", None)
        optimizer = getattr(self.model, "ent_coef_optimizer", None)
        if log_alpha is not None and optimizer is not None:
            held = log_alpha.detach().clone()

            def hold(*_: Any) -> None:
                with torch.no_grad():
                    log_alpha.copy_(held)

            self._hook = optimizer.register_step_post_hook(hold)

    def _release(self) -> None:
        for p in self._frozen:
            p.requires_grad_(True)
        self._frozen = []
        if self._hook is not None:
            self._hook.remove()
            self._hook = None
            self.model.ent_coef_optimizer.state.clear()


class ResidualScaleRamp(BaseCallback):
    """Ramps the residual authority of the training envs (``agents.residual.ResidualWrapper``'s
    ``scale``) linearly from 0 to its configured value over the first ``steps`` env steps,
    set at the start of every rollout (the evaluation envs keep the full scale). Logs
    ``train/residual_scale_fraction``.

    Args:
        steps: length of the ramp [env steps, all envs together], >= 1.
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
            raise ValueError(f"scale_ramp: must be an integer >= 1 (env steps), got {steps!r}")
        self.steps = steps
        self.full: list[float] = []

    def fraction(self) -> float:
        """The fraction of the full scale at the current step."""
        return min(self.model.num_timesteps / self.steps, 1.0)

    def _on_training_start(self) -> None:
        self.full = [float(s) for s in self.training_env.get_attr("max_scale")]
        self._apply(self.fraction())

    def _on_rollout_start(self) -> None:
        self._apply(self.fraction())

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self._apply(1.0)

    def _apply(self, fraction: float) -> None:
        for i, full in enumerate(self.full):
            self.training_env.env_method("set_scale", full * fraction, indices=[i])
        self.logger.record("train/residual_scale_fraction", fraction)


class CurriculumLog(BaseCallback):
    """Logs the terrain curriculum (``agents.curriculum.TerrainCurriculum``) of the training
    envs at the end of every rollout: ``curriculum/difficulty_mean``, ``_min``, ``_max``, the
    mean level ``curriculum/level_mean``, the episodes promoted and demoted so far
    (``curriculum/promoted``, ``curriculum/demoted``) and, in TensorBoard, the histogram of
    the envs' difficulties ``curriculum/difficulty``."""

    def __init__(self) -> None:
        super().__init__()
        self.difficulty: np.ndarray = np.zeros(0)
        self.level: np.ndarray = np.zeros(0)
        self.promoted = 0
        self.demoted = 0

    def _on_training_start(self) -> None:
        env = self.training_env
        self.difficulty = np.asarray(env.get_attr("curriculum_difficulty"), dtype=float)
        self.level = np.asarray(env.get_attr("curriculum_level"), dtype=float)

    def _on_step(self) -> bool:
        for i, info in enumerate(self.locals.get("infos") or ()):
            event = info.get("curriculum")
            if event is not None:
                self.difficulty[i] = event["next_difficulty"]
                self.level[i] = event["next_level"]
                self.promoted += event["next_level"] > event["level"]
                self.demoted += event["next_level"] < event["level"]
        return True

    def _on_rollout_end(self) -> None:
        self.record()

    def record(self) -> None:
        """Record the current levels in the logger."""
        import torch

        log = self.logger.record
        log("curriculum/difficulty_mean", float(np.mean(self.difficulty)))
        log("curriculum/difficulty_min", float(np.min(self.difficulty)))
        log("curriculum/difficulty_max", float(np.max(self.difficulty)))
        log("curriculum/level_mean", float(np.mean(self.level)))
        log("curriculum/promoted", self.promoted)
        log("curriculum/demoted", self.demoted)
        log(
            "curriculum/difficulty",
            torch.as_tensor(self.difficulty),
            exclude=("stdout", "log", "json", "csv"),
        )
