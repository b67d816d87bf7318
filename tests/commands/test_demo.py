"""``roughwalk demo``: the paper's experiment runs for the whole episode, prints its table with
units and writes its figures and a small GIF."""

import argparse
import re

import gymnasium as gym
import pytest
from PIL import Image

from commands import demo
from commands.cli import main

STAIRS = "roughwalk/CompassGaitStairs-v0"


def test_demo_writes_table_and_figures(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    demo.configure(parser)
    args = parser.parse_args(["--duration", "2.5", "--output", str(tmp_path)])
    code = demo.run(args)
    out = capsys.readouterr().out
    assert out.count("[rad/s]") == 2 and "[rad]" in out and "[ms]" in out  # units in headers
    for name in ("cartoon.png", "q2.png", "q1.png", "velocities.png"):
        p = tmp_path / name
        assert p.exists() and p.stat().st_size > 5000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"wrote {p}" in out
    assert code == 0, out


def test_the_default_duration_is_the_whole_episode(capsys):
    env = gym.make(STAIRS)
    limit = env.spec.max_episode_steps * env.unwrapped.dt
    assert demo.episode_duration(env) == pytest.approx(10.0) == limit
    assert main(["demo", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert f"in {limit:.2f} s" in out
    rows = [line for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    # two steps on the flat, one down each stair, and on at the gait's 0.68 s per step: 14
    # touchdowns in 10 s (13 if the first steps were slower); the step in progress at the time
    # limit is the last row, marked as such
    walked = int(out.split("walked: ")[1].split()[0])
    assert walked in (13, 14)
    assert "unfinished" in rows[-1] or "unfinished" in rows[-2]


#: the paper's feedback weights without the friction clip, as demo --controller settings
PAPER_WEIGHTS = {"Q": [1.0, 1.0, 1.0], "friction_limit": 0.0}


@pytest.mark.parametrize(("controller", "on_top"), [(None, 3), (PAPER_WEIGHTS, 3)])
def test_the_walk_steps_down_one_stair_at_a_time(controller, on_top):
    """The start foot and ``on_top`` touchdowns on the flat (the first step, from standing, is
    a short one; the replans then take two more short ones: with the paper's weights the
    second comes from the first plans keeping the feet off the top stair's riser,
    ``drop_edge_sd``, without which they took one), then one touchdown on each stair."""
    res = demo.rollout(STAIRS, seed=0, duration=4.0, controller=controller)
    assert res["failure"] is None
    feet = res["foot"]
    heights = [y for i, (x, y) in enumerate(feet) if i == 0 or (feet[i - 1] != feet[i]).any()]
    assert heights[: on_top + 1] == [0.0] * (on_top + 1)
    assert heights[on_top + 1 : on_top + 3] == pytest.approx([-0.03, -0.06])


def test_demo_rollout_and_table_rows():
    res = demo.rollout("roughwalk/CompassGaitFlat-v0", seed=1, duration=1.5)
    rows = demo.step_table(res["records"], last="unfinished")
    assert len(rows) >= 2 and len(rows[0]) == len(demo.STEP_COLUMNS)
    assert rows[-1][-1] == "unfinished" and rows[0][-1] == ""
    h = res["history"]
    assert h["x_hat"].shape[1] == 4 and h["nominal"].shape[1] == 3
    assert res["failure"] is None


def test_the_gif_is_small(tmp_path, capsys):
    argv = ["demo", "--duration", "0.5", "--gif", "--output", str(tmp_path)]
    assert main([*argv, "--env", "roughwalk/CompassGaitFlat-v0"]) == 0
    gif = tmp_path / "walk.gif"
    assert f"wrote {gif}" in capsys.readouterr().out
    with Image.open(gif) as im:
        # 0.5 s at 5 ms per tick, a frame every 8 ticks (25 per simulated second)
        assert im.n_frames == 13 and im.size == (demo.GIF_WIDTH, 320)
        assert im.info["duration"] == 40
    assert gif.stat().st_size < 60_000


def test_the_table_shows_the_lyapunov_value_per_footstep_in_both_modes(capsys):
    """V at each step's start and end, their ratio, the largest |x_perp| and |u|: in replan mode
    every step after the first starts on its own fresh plan (V start about 0)."""
    argv = ["demo", "--no-figures", "--duration", "3"]
    paper = ["--controller", "Q=[1,1,1]", "friction_limit=0"]
    # the paper's weights, then the stiff default, whose P weighs y far more (larger V)
    for settings, footsteps, v_end in ((paper, 4, 1.0), ([], 4, 2.5)):
        assert main([*argv, *settings]) == 0
        out = capsys.readouterr().out
        for header in ("start", "end", "/V start", "|x_perp|", "|u|"):
            assert header in out
        assert f"replan: V end/start < 1 on 0 of {footsteps} completed footsteps" in out
        rows = [ln.split() for ln in out.splitlines() if ln.split() and ln.split()[0].isdigit()]
        assert len(rows) == footsteps + 1 and all(len(r) >= 10 for r in rows)
        assert all(float(r[4]) < 1e-12 for r in rows)  # V start, replanned at every touchdown
        assert all(0 < float(r[5]) < v_end for r in rows)  # V end
        assert all(float(r[8]) <= 15 for r in rows)  # max |u| within the actuator limit
    assert main([*argv, "--controller-mode", "fixed-plan"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    # one plan made at the start: later steps start off it (the observer's and the sensors'
    # errors), so V start is not 0 and the ratio is a number to read
    assert all(float(r[4]) > 1e-4 for r in rows[1:])
    assert "fixed-plan: V end/start < 1 on" in out and "V start fell from one footstep" in out


def test_controller_settings_reach_the_demo(capsys):
    res = demo.rollout(STAIRS, seed=0, duration=0.5, controller={"Q": [1, 1, 1], "R": 2})
    assert res["config"].Q == (1.0, 1.0, 1.0) and res["config"].R == 2.0
    # the fields not given are the robot's defaults
    default = demo.rollout(STAIRS, seed=0, duration=0.5)["config"]
    assert res["config"].friction_limit == default.friction_limit
    for bad, match in (
        (["Qx=1"], "unknown controller setting.*Qx"),
        (["Q=[1,-1,1]"], r"ControllerConfig.Q = \[1, -1, 1\]; allowed: three numbers > 0"),
        (["horizon=2"], "--controller: horizon has its own option, --horizon"),
        (["Q"], "is not KEY=VALUE"),
    ):
        assert main(["demo", "--no-figures", "--controller", *bad]) == 2
        assert re.search(match, capsys.readouterr().err)


def test_plan_steps_needs_the_fixed_plan_mode(capsys):
    assert main(["demo", "--no-figures", "--plan-steps", "5"]) == 2
    err = capsys.readouterr().err
    assert "--plan-steps: applies to --controller-mode fixed-plan only" in err
    assert main(["demo", "--no-figures", "--controller-mode", "fixed"]) == 2
    assert "invalid choice: 'fixed'" in capsys.readouterr().err


def test_a_fixed_plan_is_sized_for_the_duration():
    res = demo.rollout(STAIRS, seed=0, duration=2.0, mode="fixed-plan")
    assert res["config"].mode == "fixed-plan" and res["config"].plan_steps == 3 + 3 + 1
    res = demo.rollout(STAIRS, seed=0, duration=1.0, mode="fixed-plan", plan_steps=6)
    assert res["config"].plan_steps == 6
    assert demo.rollout(STAIRS, seed=0, duration=0.5)["config"].mode == "replan"
