"""Training: every shipped config trains end to end; save/load, resume, seeds, CLI, rl-zoo3."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecNormalize

from agents.config import EVAL_SEED_OFFSET, TRAIN_SEED_LIMIT, ConfigError, load_config
from agents.evaluate import evaluate
from agents.runs import find_vecnormalize, load_vecnormalize
from agents.train import build, save, train
from agents.trained import TrainedPolicy

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "agents"
CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_smoke_training_of_every_config(path: Path, smoke, tmp_path: Path):
    cfg = smoke(path)
    run = train(cfg, log_dir=tmp_path, progress_bar=False)
    assert run == tmp_path / f"{cfg.name}_s{cfg.seed}"
    assert (run / "model.zip").is_file() and (run / "vecnormalize.pkl").is_file()
    half = cfg.n_timesteps // 2
    ckpt = run / "checkpoints" / f"rl_model_{half}_steps.zip"
    assert ckpt.is_file() and find_vecnormalize(ckpt) is not None
    evals = np.load(run / "eval" / "evaluations.npz")
    assert list(evals["timesteps"]) == [half, cfg.n_timesteps]
    assert evals["results"].shape == (2, cfg.eval_episodes)
    assert any((run / "tb").rglob("events.out.tfevents.*"))
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["num_timesteps"] == cfg.n_timesteps
    assert manifest["residual"] == cfg.is_residual
    seeds = manifest["seeds"]
    assert all(0 <= s < TRAIN_SEED_LIMIT for s in seeds["training_envs"])
    assert all(s >= EVAL_SEED_OFFSET for s in seeds["evaluation"])
    assert manifest["config"]["run"]["env"] == cfg.env_id
    # the base an agent acts on, resolved: the residual's or the per-footstep wrapper's
    bases = [b["wrapper"] for b in manifest["base_settings"]]
    assert bases == (
        ["ResidualWrapper"] if cfg.is_residual else ["FootstepWrapper"] if cfg.is_footstep else []
    )
    for base in manifest["base_settings"]:
        assert base["controller"]["horizon"] >= 1 and "torque_fraction" in base["planner"]


@pytest.mark.parametrize("name", ["ppo_flat", "sac_rough"])
def test_save_and_load_reproduce_deterministic_actions(name: str, smoke, tmp_path: Path):
    cfg = smoke(CONFIG_DIR / f"{name}.yaml", timesteps=1024)
    model, env, _ = build(cfg, tmp_path, tensorboard=False)
    model.learn(cfg.n_timesteps)
    assert isinstance(env, VecNormalize) and env.obs_rms.count > 100
    obs = np.stack([env.get_original_obs()] + [env.unnormalize_obs(env.reset())] * 1)
    obs = obs.reshape(-1, obs.shape[-1])
    rng = np.random.default_rng(0)
    obs = np.concatenate([obs, obs + rng.normal(0, 0.05, obs.shape).astype(np.float32)])
    before = np.stack([model.predict(env.normalize_obs(o), deterministic=True)[0] for o in obs])
    save(model, tmp_path / "model.zip")
    loaded = TrainedPolicy(tmp_path / "model.zip", algo=cfg.algo)
    after = np.stack([loaded(o) for o in obs])
    np.testing.assert_array_equal(before, after)
    assert np.ptp(before) > 0  # the actions depend on the observation


def test_frame_stack_is_applied_in_training_and_in_evaluation(smoke, tmp_path: Path):
    """rl-zoo3's ``frame_stack``: training stacks normalised observations with VecFrameStack;
    a loaded model stacks them the same way, episode by episode."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import VecFrameStack
    from stable_baselines3.common.vec_env.stacked_observations import StackedObservations

    cfg = smoke(CONFIG_DIR / "ppo_flat.yaml", timesteps=1024)
    cfg.hyperparams["frame_stack"] = 3
    model, env, eval_env = build(cfg, tmp_path / "built", tensorboard=False)
    assert isinstance(env, VecFrameStack) and isinstance(eval_env, VecFrameStack)
    run = train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    policy = TrainedPolicy(run / "model.zip")
    assert policy.frame_stack == 3
    single = policy.wrap_env(gym.make(cfg.env_id, **cfg.env_kwargs))
    for seed in (5, 6):  # two episodes: the stack starts afresh at each reset
        obs, _ = single.reset(seed=seed)
        policy.reset()
        stacker = StackedObservations(1, 3, single.observation_space)
        stacked = stacker.reset(policy.obs_norm.normalize_obs(obs)[None])
        for _ in range(25):
            action = policy(obs)
            expected = policy.model.predict(stacked, deterministic=True)[0][0]
            np.testing.assert_array_equal(action, expected)
            obs, *_ = single.step(action)
            norm = policy.obs_norm.normalize_obs(obs)[None]
            stacked, _ = stacker.update(norm, np.array([False]), [{}])


def test_resuming_a_finished_run_continues_into_a_new_run_folder(smoke, tmp_path: Path):
    cfg = smoke(CONFIG_DIR / "ppo_stairs.yaml", timesteps=2048)
    run = train(cfg, log_dir=tmp_path, progress_bar=False)
    ckpt = run / "checkpoints" / "rl_model_1024_steps.zip"
    stats_at_ckpt = load_vecnormalize(find_vecnormalize(ckpt)).obs_rms.count
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    resumed = train(cfg, log_dir=None, resume=ckpt, progress_bar=False)
    # the finished run is kept as it was; the continuation is a new run beside it
    assert resumed == tmp_path / f"{run.name}_2"
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
    manifest = json.loads((resumed / "manifest.json").read_text())
    assert manifest["resumed_from"] == [str(ckpt)]
    assert manifest["status"] == "finished"
    assert manifest["num_timesteps"] == cfg.n_timesteps
    # the normalisation statistics continued from the checkpoint's (not from scratch)
    stats_end = load_vecnormalize(resumed / "vecnormalize.pkl").obs_rms.count
    assert stats_end == pytest.approx(stats_at_ckpt + 1024, abs=2)
    evals = np.load(resumed / "eval" / "evaluations.npz")
    assert list(evals["timesteps"]) == [cfg.n_timesteps]
    assert any((resumed / "monitor").glob("*.monitor.csv"))


def test_resuming_within_a_rollout_ends_as_the_uninterrupted_run(
    smoke, tmp_path: Path, capsys: pytest.CaptureFixture
):
    """A PPO checkpoint saved inside a rollout holds the model of the update before it: the
    resumed run collects that rollout again from there and ends, as the uninterrupted run, at
    the budget rounded up to whole rollouts, after as many updates."""
    cfg = smoke(CONFIG_DIR / "ppo_stairs.yaml", timesteps=2048)
    cfg.checkpoint_freq = 768  # rollouts of 1,024 env steps: checkpoints at 768 and 1,536
    run = train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    ckpt = run / "checkpoints" / "rl_model_1536_steps.zip"
    capsys.readouterr()
    resumed = train(cfg, log_dir=None, resume=ckpt, progress_bar=False, tensorboard=False)
    assert "512 env steps into a rollout of 1,024" in capsys.readouterr().out
    for folder in (run, resumed):
        assert json.loads((folder / "manifest.json").read_text())["num_timesteps"] == 2048
    updates = [TrainedPolicy(r / "model.zip").model._n_updates for r in (run, resumed)]
    assert updates[0] == updates[1] == 2 * cfg.hyperparams["n_epochs"]


def test_periodic_evaluation_uses_the_same_held_out_courses(smoke, tmp_path: Path):
    # a frozen agent (no learning, no normalisation updates) must score identically each time
    cfg = smoke(CONFIG_DIR / "ppo_rough.yaml", timesteps=1536)
    cfg.hyperparams.update(learning_rate=0.0, normalize=False)
    cfg.eval_freq, cfg.eval_episodes = 512, 3
    run = train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    results = np.load(run / "eval" / "evaluations.npz")["results"]
    assert results.shape == (3, 3)
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_array_equal(results[0], results[2])
    assert len(set(results[0])) > 1  # three different courses, not one course three times


def test_rl_zoo3_reads_our_configs(tmp_path: Path):
    pytest.importorskip("rl_zoo3")
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo"]
    cmd += ["--env", "roughwalk/CompassGaitRough-v0", "--gym-packages", "envs"]
    cmd += ["--conf-file", str(CONFIG_DIR / "ppo_rough.yaml"), "-n", "256", "--seed", "1"]
    cmd += ["-params", "n_envs:2", "n_steps:64", "batch_size:64", "n_epochs:1"]
    cmd += ["--eval-freq", "-1", "--log-folder", str(tmp_path)]
    # SB3's logger folder of a run without TensorBoard: by default a new one in the system's
    # temp folder
    env = {**os.environ, "SB3_LOGDIR": str(tmp_path / "sb3_log")}
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "'difficulty': 1.0" in out.stdout  # env_kwargs of the file were used
    saved = list(tmp_path.rglob("roughwalk-CompassGaitRough-v0.zip"))
    assert len(saved) == 1
    assert list(tmp_path.rglob("vecnormalize.pkl"))
    # and roughwalk evaluate reads the model with rl-zoo3's saved settings
    ev = evaluate(str(saved[0]), None, episodes=1, seed=0, env_kwargs={"max_episode_steps": 50})
    assert ev.env_id == "roughwalk/CompassGaitRough-v0" and ev.episodes[0].steps <= 50


@pytest.mark.parametrize(
    ("name", "kind"), [("ppo_flat", "native"), ("ppo_residual_flat", "subproc")]
)
def test_other_vectorisations(name: str, kind: str, smoke, tmp_path: Path):
    cfg = smoke(CONFIG_DIR / f"{name}.yaml", timesteps=512)
    cfg.vec_env = kind
    run = train(cfg, log_dir=tmp_path, progress_bar=False, tensorboard=False)
    assert json.loads((run / "manifest.json").read_text())["num_timesteps"] == 512
    assert any((run / "monitor").glob("*.monitor.csv"))


def test_native_vec_env_refuses_env_wrappers():
    with pytest.raises(ConfigError, match="run.vec_env = 'native' cannot apply env_wrapper"):
        load_config(CONFIG_DIR / "sac_residual_rough.yaml", run_overrides={"vec_env": "native"})


def test_same_seed_same_agent(smoke, tmp_path: Path):
    import torch

    cfg = smoke(CONFIG_DIR / "ppo_rough.yaml", timesteps=512)
    runs = [train(cfg, log_dir=tmp_path / d, progress_bar=False, tensorboard=False) for d in "ab"]
    params = [TrainedPolicy(r / "model.zip").model.policy.state_dict() for r in runs]
    assert all(torch.equal(params[0][k], params[1][k]) for k in params[0])
    other = load_config(cfg.path, cfg.hyperparams, {"seed": 1, "eval_freq": 0})
    run_c = train(other, log_dir=tmp_path / "c", progress_bar=False, tensorboard=False)
    params_c = TrainedPolicy(run_c / "model.zip").model.policy.state_dict()
    assert not all(torch.equal(params[0][k], params_c[k]) for k in params[0])
