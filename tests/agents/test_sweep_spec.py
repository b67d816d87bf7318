"""Sweep specs: the grid they describe, and bad specs rejected before any episode runs."""

from pathlib import Path

import pytest
import yaml

from agents.sweep import SpecError, check_spec, load_spec, spec_from_dict
from configs import CONFIG_DIR

SWEEPS = CONFIG_DIR / "sweeps"
FLAT = "roughwalk/CompassGaitFlat-v0"
ROUGH = "roughwalk/CompassGaitRough-v0"


def spec(**changes):
    data = {
        "episodes": 2,
        "policies": ["passive", "pd"],
        "envs": [
            {"name": "flat", "id": FLAT},
            {"name": "rough", "id": ROUGH, "sweep": {"difficulty": [1.0, 2.0]}},
        ],
    }
    data.update(changes)
    return data


def test_grid_is_policies_by_envs_by_swept_values():
    s = spec_from_dict(spec(seed=5))
    keys = [c.key for c in s.cells()]
    assert keys == [
        "passive/flat",
        "passive/rough[difficulty=1.0]",
        "passive/rough[difficulty=2.0]",
        "pd/flat",
        "pd/rough[difficulty=1.0]",
        "pd/rough[difficulty=2.0]",
    ]
    assert s.seeds == [1_000_005, 1_000_006]  # the held-out seeds of roughwalk evaluate
    cell = s.cells()[2]
    assert cell.env_kwargs == {"difficulty": 2.0}
    assert cell.swept == {"difficulty": 2.0}
    assert cell.setting == "rough[difficulty=2.0]"


def test_default_seed_is_the_test_seed_and_policies_can_be_restricted():
    s = spec_from_dict(spec(policies=["passive", {"policy": "pd", "name": "PD", "envs": ["flat"]}]))
    assert s.seeds[0] == 1_001_000
    assert [c.key for c in s.cells()][-1] == "PD/flat"
    assert len(s.cells()) == 4


def test_dotted_sweep_keys_set_fields_of_mapping_arguments():
    env = {
        "name": "noisy",
        "id": FLAT,
        "kwargs": {"sensors": {"scan_noise": 0.0}},
        "sweep": {"sensors.encoder_noise": [0.001, 0.005]},
    }
    s = spec_from_dict(spec(envs=[env], policies=["passive"]))
    kwargs = [c.env_kwargs for c in s.cells()]
    assert kwargs[1] == {"sensors": {"scan_noise": 0.0, "encoder_noise": 0.005}}
    assert env["kwargs"] == {"sensors": {"scan_noise": 0.0}}  # the spec is left unchanged
    check_spec(s)  # the env accepts them


def test_policy_options_reach_the_policy():
    entry = {"policy": "reference", "name": "fixed", "options": {"controller_mode": "fixed-plan"}}
    s = spec_from_dict(spec(policies=[entry], envs=[{"id": FLAT}]))
    assert s.cells()[0].policy_options == {"controller_mode": "fixed-plan"}
    check_spec(s)
    bad = spec_from_dict(spec(policies=[{**entry, "policy": "passive"}], envs=[{"id": FLAT}]))
    with pytest.raises(SpecError, match="cell fixed/CompassGaitFlat-v0: controller_mode: applies"):
        check_spec(bad)


def test_run_folder_resolves_to_its_best_model(tmp_path):
    run = tmp_path / "ppo_flat_s0"
    run.mkdir()
    (run / "model.zip").write_bytes(b"")
    (run / "best_model.zip").write_bytes(b"")
    s = spec_from_dict(spec(policies=[{"policy": str(run), "group": "ppo"}]))
    assert s.policies[0].policy == str(run / "best_model.zip")
    assert s.policies[0].name == "ppo_flat_s0"
    assert s.cells()[0].group == "ppo"


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"policies": ["nope"]}, r"policies\[0\].policy: unknown policy 'nope'; allowed: passive"),
        ({"envs": []}, "envs: must be a non-empty list"),
        ({"policies": []}, "policies: must be a non-empty list"),
        ({"episode": 3}, "unknown key 'episode'; allowed: name"),
        ({"episodes": 0}, "episodes: must be an integer >= 1, got 0"),
        ({"episodes": True}, "episodes: must be an integer"),
        ({"seed": -1}, "seed: must be an integer >= 0, got -1"),
        ({"seed": 2**32}, "seed: .*out of range"),
        ({"policies": [{"policy": "pd", "envs": ["hills"]}]}, "unknown env 'hills'"),
        ({"policies": [{"policy": "pd", "color": 1}]}, r"policies\[0\]: unknown key 'color'"),
        ({"policies": ["pd", "pd"]}, "two entries give the cell 'pd/flat'"),
        ({"envs": [{"id": FLAT, "sweep": {"difficulty": []}}]}, "non-empty list of values"),
        ({"envs": [{"id": FLAT}, {"id": FLAT}]}, "the name 'CompassGaitFlat-v0' is used twice"),
        ({"envs": [{"id": FLAT, "terrain": "x"}]}, r"envs\[0\]: unknown key 'terrain'"),
        ({"envs": [{"name": "flat"}]}, r"envs\[0\].id: required"),
        ({"policies": [{"policy": "pd", "options": {"gain": 2}}]}, "unknown option 'gain'"),
    ],
)
def test_bad_spec_form(changes, match):
    with pytest.raises(SpecError, match=match):
        spec_from_dict(spec(**changes))


@pytest.mark.parametrize(
    "env, match",
    [
        ({"id": "roughwalk/Nowhere-v0"}, "unknown environment id 'roughwalk/Nowhere-v0'"),
        ({"id": "CartPole-v1"}, "not a roughwalk env"),
        ({"id": FLAT, "kwargs": {"bogus": 1}}, r"envs\[0\] \(CompassGaitFlat-v0\): .*bogus"),
        ({"id": ROUGH, "sweep": {"difficulty": [1.0, -3.0]}}, r"difficulty': -3.0.*difficulty"),
        ({"id": FLAT, "sweep": {"push.dv": [0.1]}}, r"push.dv.*push"),  # no time for the push
        ({"id": FLAT, "sweep": {"robot_error": [0.1, 0.7]}}, r"robot_error': 0.7.*robot_error"),
    ],
)
def test_bad_env_found_by_constructing_it(env, match):
    s = spec_from_dict(spec(envs=[env]))
    with pytest.raises(SpecError, match=match):
        check_spec(s)


def test_load_spec_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("episodes: [1\n")
    with pytest.raises(SpecError, match="bad.yaml: not valid YAML"):
        load_spec(path)
    path.write_text("episodes: 1\npolicies: [pd]\nenvs: []\n")
    with pytest.raises(SpecError, match="bad.yaml: envs: must be a non-empty list"):
        load_spec(path)
    with pytest.raises(FileNotFoundError, match="sweep spec not found"):
        load_spec(tmp_path / "missing.yaml")


@pytest.mark.parametrize("path", sorted(SWEEPS.glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_specs_read(path: Path, tmp_path, monkeypatch):
    # trained agents are run folders below the working directory: stand-ins for them
    monkeypatch.chdir(tmp_path)
    stand_ins = False
    for entry in yaml.safe_load(path.read_text())["policies"]:
        if isinstance(entry, dict) and entry["policy"].startswith("runs/"):
            Path(entry["policy"]).mkdir(parents=True)
            (Path(entry["policy"]) / "best_model.zip").write_bytes(b"")
            stand_ins = True
    s = load_spec(path)
    assert s.cells()
    if not stand_ins:  # (stand-in models cannot be loaded)
        check_spec(s)
    if path.stem == "readme_results":
        assert s.episodes >= 200
        assert {c.env for c in s.cells()} == {"flat", "stairs", "rough", "rough-hard"}
