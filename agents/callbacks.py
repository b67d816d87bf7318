"""stable-baselines3 callbacks for roughwalk training runs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback


class SaveVecNormalizeOnBest(BaseCallback):
    """Save the ``VecNormalize`` statistics beside ``best_model.zip`` (``callback_on_new_best``).

    Args:
        save_path: the folder of ``best_model.zip``.
    """

    def __init__(self, save_path: str | Path) -> None:
        super().__init__()
        self.save_path = Path(save_path)

    def _on_step(self) -> bool:
        vn = self.model.get_vec_normalize_env()
        if vn is not None:
            vn.save(str(self.save_path / "best_vecnormalize.pkl"))
        return True


class HeldOutEvalCallback(EvalCallback):
    """``EvalCallback`` on fixed held-out seeds, also logging walking metrics.

    Before every evaluation the eval env is reseeded with ``seed`` (>= the evaluation seed
    offset), so all evaluations of a run use the same held-out courses. Besides SB3's
    ``eval/mean_reward`` it logs ``eval/success_rate`` (episodes ending without failure),
    ``eval/footsteps`` and ``eval/distance`` [m], read from the env's final ``info``.

    Args:
        eval_env: the evaluation env (an SB3 ``VecEnv``).
        seed: the seed of the evaluation courses (>= ``agents.config.EVAL_SEED_OFFSET``).
        kwargs: the other arguments of SB3's ``EvalCallback``.
    """

    def __init__(self, eval_env: Any, seed: int, **kwargs: Any) -> None:
        super().__init__(eval_env, **kwargs)
        self.seed = seed
        self._walk: list[tuple[bool, float, float]] = []

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
        keep_going = super()._on_step()
        if due and self._walk:
            ok, steps, dist = (np.asarray(c, dtype=float) for c in zip(*self._walk))
            self.logger.record("eval/success_rate", float(ok.mean()))
            self.logger.record("eval/footsteps", float(steps.mean()))
            self.logger.record("eval/distance", float(dist.mean()))
            self.logger.dump(self.num_timesteps)
        return keep_going
