"""Residual learning as the literature does it: a zero-initialised actor output that starts the
agent exactly at the reference controller, and a critic warm-up with the actor frozen."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

import controllers
from agents.callbacks import CriticWarmup, actor_parameters
from agents.config import config_from_dict
from agents.residual import init_policy
from agents.train import build, make_callbacks

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "agents"
FLAT = "roughwalk/CompassGaitFlat-v0"


def _snapshot(params) -> list[torch.Tensor]:
    return [p.detach().clone() for p in params]


def _same(a, b) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def _critic_parameters(model) -> list[torch.Tensor]:
    actor = {id(p) for p in actor_parameters(model)}
    critic = model.critic if hasattr(model, "critic") else model.policy
    return [p for p in critic.parameters() if id(p) not in actor]


@pytest.mark.parametrize("name", ["ppo_residual_rough_hard_zero", "sac_residual_rough_hard_zero"])
def test_zero_init_starts_exactly_at_the_reference_controller(name, smoke, tmp_path):
    """At step 0 of training the deterministic action is exactly 0 for any observation, and
    the residual env driven by the agent applies the reference controller's commands bit for
    bit over a whole episode."""
    cfg = smoke(CONFIG_DIR / f"{name}.yaml")
    model, venv, eval_env = build(cfg, tmp_path, tensorboard=False)
    try:
        obs = np.random.default_rng(0).normal(0, 3, (64, *venv.observation_space.shape))
        action, _ = model.predict(obs.astype(np.float32), deterministic=True)
        assert np.array_equal(action, np.zeros_like(action))

        kwargs = cfg.env_kwargs
        agent_env = cfg.wrap(gym.make(cfg.env_id, **kwargs))
        plain = gym.make(cfg.env_id, **kwargs)
        [base] = [kw for cls, kw in cfg.wrapper_specs() if cls.__name__ == "ResidualWrapper"]
        reference = controllers.make_reference_policy(plain, **(base.get("base_kwargs") or {}))
        obs, _ = agent_env.reset(seed=21)
        ref_obs, _ = plain.reset(seed=21)
        reference.reset()
        steps = 0
        while True:
            a, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
            obs, _, term, trunc, info = agent_env.step(a)
            ref_action = reference(ref_obs)
            ref_obs, _, ref_term, ref_trunc, ref_info = plain.step(ref_action)
            steps += 1
            assert info["residual_action"][0] == 0.0
            np.testing.assert_array_equal(info["total_action"], ref_action)
            np.testing.assert_array_equal(info["state"], ref_info["state"])
            assert (term, trunc) == (ref_term, ref_trunc)
            if term or trunc:
                break
        assert steps > 10 and info["footsteps"] == ref_info["footsteps"]
    finally:
        venv.close()
        eval_env.close()


def test_init_policy_sets_the_initial_exploration():
    cfg = config_from_dict(
        {
            "run": {"algo": "sac", "env": FLAT, "residual_init": "zero", "init_log_std": -3.0},
            FLAT: {"n_timesteps": 100, "learning_starts": 0},
        }
    )
    model = cfg.algo_class(env=gym.make(FLAT), device="cpu", **cfg.algo_kwargs())
    init_policy(model, zero_output=True, log_std=-3.0)
    obs = torch.randn(5, *model.observation_space.shape)
    mean, log_std, _ = model.actor.get_action_dist_params(obs)
    assert torch.equal(mean, torch.zeros_like(mean))
    assert torch.equal(log_std, torch.full_like(log_std, -3.0))
    with pytest.raises(ValueError, match=r"log_std = 5.0; allowed: in \[-20, 2\]"):
        init_policy(model, log_std=5.0)


class _ActorSnapshots(BaseCallback):
    """The actor's parameters at the start of every rollout (after the previous update)."""

    def __init__(self) -> None:
        super().__init__()
        self.snapshots: list[list[torch.Tensor]] = []

    def _on_rollout_start(self) -> None:
        self.snapshots.append(_snapshot(actor_parameters(self.model)))

    def _on_step(self) -> bool:
        return True


def _tiny(algo: str, warmup: int, timesteps: int) -> tuple:
    hyper = {"n_timesteps": timesteps, "env_kwargs": {"max_episode_steps": 40}}
    if algo == "ppo":
        hyper.update(n_steps=32, batch_size=32, n_epochs=2)
    else:
        hyper.update(learning_starts=0, batch_size=32, train_freq=16, gradient_steps=4)
    run = {"algo": algo, "env": FLAT, "residual_init": "zero", "critic_warmup": warmup}
    run.update(eval_freq=0, checkpoint_freq=0)
    return config_from_dict({"run": run, FLAT: hyper})


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_critic_warmup_freezes_the_actor_and_trains_the_critic(algo, tmp_path):
    cfg = _tiny(algo, warmup=10_000, timesteps=96)
    model, venv, _ = build(cfg, tmp_path, tensorboard=False)
    callbacks = make_callbacks(cfg, tmp_path, None)
    assert [type(c) for c in callbacks] == [CriticWarmup]
    actor, critic = _snapshot(actor_parameters(model)), _snapshot(_critic_parameters(model))
    alpha = model.log_ent_coef.item() if algo == "sac" else None
    model.learn(cfg.n_timesteps, callback=callbacks)
    venv.close()
    assert model.num_timesteps >= 96 and getattr(model, "_n_updates", 0) > 0
    assert _same(actor, actor_parameters(model))  # frozen: not one bit changed
    assert not _same(critic, _critic_parameters(model))  # the critic learnt
    if algo == "sac":
        assert model.log_ent_coef.item() == alpha  # the entropy coefficient was held
    assert all(p.requires_grad for p in actor_parameters(model))  # released at the end


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_actor_learns_once_the_warmup_is_over(algo, tmp_path):
    # one rollout of warm-up: PPO 32 steps; SAC 16 steps (train_freq)
    warmup = 32 if algo == "ppo" else 16
    cfg = _tiny(algo, warmup=warmup, timesteps=3 * warmup)
    model, venv, _ = build(cfg, tmp_path, tensorboard=False)
    probe = _ActorSnapshots()
    model.learn(cfg.n_timesteps, callback=[*make_callbacks(cfg, tmp_path, None), probe])
    venv.close()
    first, after_warmup_update, after_actor_update = probe.snapshots[:3]
    assert _same(first, after_warmup_update)
    assert not _same(after_warmup_update, after_actor_update)


def test_critic_warmup_rejects_a_bad_length():
    with pytest.raises(ValueError, match="critic_warmup: must be an integer >= 0"):
        CriticWarmup(-1)


class _Scales(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.scales: list[list[float]] = []

    def _on_rollout_start(self) -> None:
        self.scales.append(self.training_env.get_attr("scale"))

    def _on_step(self) -> bool:
        return True


def test_scale_ramp_grows_the_residual_authority_of_the_training_envs(tmp_path):
    wrapper = {"agents.residual.ResidualWrapper": {"base": "passive", "scale": 0.5}}
    hyper = {
        "n_timesteps": 128,
        "n_steps": 32,
        "n_envs": 2,
        "batch_size": 32,
        "n_epochs": 1,
        "env_kwargs": {"max_episode_steps": 40},
        "env_wrapper": [wrapper],
    }
    run = {"algo": "ppo", "env": FLAT, "scale_ramp": 128, "eval_freq": 0, "checkpoint_freq": 0}
    cfg = config_from_dict({"run": run, FLAT: hyper})
    model, venv, _ = build(cfg, tmp_path, tensorboard=False)
    probe = _Scales()
    model.learn(cfg.n_timesteps, callback=[*make_callbacks(cfg, tmp_path, None), probe])
    assert probe.scales == [[0.0, 0.0], [0.25, 0.25]]  # rollouts of 64 steps
    assert venv.get_attr("scale") == [0.5, 0.5]  # full scale after training
    venv.close()
    with pytest.raises(ValueError, match=r"scale = 0.6 is out of range; allowed: in \[0, 0.5\]"):
        venv.env_method("set_scale", 0.6, indices=[0])
