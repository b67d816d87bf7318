"""The shipped agents: names resolve, bad names are clear errors, and every shipped model still
walks the courses its card says it was evaluated on (a physics or controller change that
breaks them is caught here)."""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from agents.evaluate import BaseChangedWarning, evaluate
from agents.pretrained import PREFIX, PRETRAINED_DIR, available, card, pack_run, resolve_model
from agents.sweep.spec import SpecError, check_spec, load_spec
from agents.trained import TrainedPolicy, load_policy

SHIPPED = available()


def test_agents_are_shipped_with_their_statistics_manifest_and_card():
    assert SHIPPED, "no pretrained agent shipped"
    for name in SHIPPED:
        folder = PRETRAINED_DIR / name
        for f in ("best_model.zip", "best_vecnormalize.pkl", "manifest.json", "card.json"):
            assert (folder / f).is_file(), f"{name}: {f} missing"
        info = card(name)
        for key in ("agent", "train", "evaluate", "held_out"):
            assert key in info, f"{name}: card has no {key!r}"
        # nothing of the machine it was trained on
        for f in ("manifest.json", "card.json"):
            text = (folder / f).read_text()
            assert "/work/" not in text and "/tmp/" not in text and "/home/" not in text
    total = sum(f.stat().st_size for f in PRETRAINED_DIR.rglob("*") if f.is_file())
    assert total < 5e6  # a few MB at most


def test_unknown_names_are_errors_listing_the_available_ones():
    with pytest.raises(ValueError, match="unknown pretrained agent 'nope'; available: ") as exc:
        resolve_model(f"{PREFIX}nope")
    for name in SHIPPED:
        assert f"{PREFIX}{name}" in str(exc.value)
    with pytest.raises(ValueError, match="unknown pretrained agent"):
        load_policy(f"{PREFIX}nope")
    with pytest.raises(ValueError, match="unknown pretrained agent"):
        card("nope")
    assert resolve_model("reference") == "reference"  # anything else passes through


def test_the_command_line_rejects_an_unknown_name_in_one_line():
    out = subprocess.run(
        [sys.executable, "-m", "commands.cli", "evaluate", "--policy", f"{PREFIX}nope"],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown pretrained agent 'nope'; available:" in lines[0]


@pytest.mark.parametrize("name", SHIPPED)
def test_a_sweep_spec_names_a_shipped_agent(name, tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        f"episodes: 1\npolicies:\n  - {PREFIX}{name}\n"
        "envs:\n  - {name: flat, id: roughwalk/CompassGaitFlat-v0}\n"
    )
    loaded = load_spec(spec)
    assert loaded.policies[0].policy == f"{PREFIX}{name}" and loaded.policies[0].name == name
    bad = tmp_path / "bad.yaml"
    bad.write_text(spec.read_text().replace(name, "nope"))
    with pytest.raises(SpecError, match="unknown pretrained agent 'nope'"):
        check_spec(load_spec(bad))


@pytest.mark.parametrize("name", SHIPPED)
def test_each_shipped_agent_still_walks_its_held_out_courses(name):
    """The card's first held-out courses, evaluated as `roughwalk evaluate` does: every course
    the card says was walked is walked again (the agent and the controllers underneath
    unchanged), on the base its manifest records (``base_settings``: no changed setting)."""
    info = card(name)
    policy = load_policy(f"{PREFIX}{name}")
    assert isinstance(policy, TrainedPolicy)
    check = info["check"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ev = evaluate(
            f"{PREFIX}{name}",
            check["env_id"],
            env_kwargs=check.get("env_kwargs"),
            episodes=len(check["walked"]),
            seed=check["seed"],
        )
    # its base is the one its manifest records: a changed default must be pinned in its config
    changed = [str(w.message) for w in caught if w.category is BaseChangedWarning]
    assert changed == []
    walked = [e.success for e in ev.episodes]
    assert walked == check["walked"], json.dumps(info["held_out"])
    assert np.isfinite(ev.summary["mean_distance"])


def test_a_finished_run_packs_into_a_loadable_agent_without_machine_paths(
    trained_ppo_run, tmp_path
):
    fields = {
        "agent": "PPO from scratch, flat ground (a smoke run)",
        "train": "roughwalk train configs/agents/ppo_flat.yaml --seed 0",
        "evaluate": "roughwalk evaluate --policy pretrained:tiny --episodes 1",
        "held_out": {},
        "check": {"env_id": "roughwalk/CompassGaitFlat-v0", "seed": 1000, "walked": []},
    }
    out = pack_run(trained_ppo_run, "tiny", fields, dest=tmp_path)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config_file"] == "configs/agents/ppo_flat.yaml"
    assert manifest["commands"] == [fields["train"]]
    assert str(trained_ppo_run) not in (out / "manifest.json").read_text()
    assert json.loads((out / "card.json").read_text()) == fields
    policy = TrainedPolicy(str(out / "best_model.zip"))
    assert policy.config is not None and policy.config.env_id == "roughwalk/CompassGaitFlat-v0"
    with pytest.raises(FileExistsError, match="never overwritten"):
        pack_run(trained_ppo_run, "tiny", fields, dest=tmp_path)
    with pytest.raises(ValueError, match="name = 'Bad-name'"):
        pack_run(trained_ppo_run, "Bad-name", fields, dest=tmp_path)
    with pytest.raises(ValueError, match="card: missing check"):
        pack_run(trained_ppo_run, "other", {k: v for k, v in fields.items() if k != "check"})
