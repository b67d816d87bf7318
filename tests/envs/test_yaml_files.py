"""Every YAML file of the settings is read by one helper: clear ValueErrors naming the file."""

from __future__ import annotations

import pytest

from controllers.controller import ControllerConfig
from controllers.planner import PlannerConfig
from envs.config_util import read_yaml_mapping
from envs.physics import RobotParams, Terrain
from envs.physics.terrain import terrain_spec
from envs.settings import resolve_env_settings

LOADERS = {
    "env config": resolve_env_settings,
    "robot": RobotParams.from_yaml,
    "terrain": Terrain.from_yaml,
    "terrain argument": terrain_spec,
    "planner config": PlannerConfig.from_yaml,
    "controller config": ControllerConfig.from_yaml,
}


@pytest.mark.parametrize("name", sorted(LOADERS))
@pytest.mark.parametrize(
    "text,problem",
    [
        ("a: [1,\n", r"is not valid YAML: line \d+, column \d+: "),
        ("a: 1\n  b: 2\n", r"is not valid YAML: line 2, column"),
        ("- 1\n- 2\n", r"must hold a .*mapping.*, got a list"),
        ("just text\n", r"must hold a .*mapping.*, got a str"),
    ],
)
def test_broken_or_non_mapping_yaml_is_a_value_error_naming_the_file(tmp_path, name, text, problem):
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=problem) as err:
        LOADERS[name](str(path))
    assert str(path) in str(err.value)


@pytest.mark.parametrize("name", ["robot", "terrain", "terrain argument"])
def test_an_empty_file_is_an_error_where_a_mapping_is_required(tmp_path, name):
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing\n")
    with pytest.raises(ValueError, match="is empty"):
        LOADERS[name](str(path))


def test_the_reader_returns_the_mapping_and_reports_non_utf8(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("a: 1\nb: [2, 3]\n")
    assert read_yaml_mapping(path, "test") == {"a": 1, "b": [2, 3]}
    (tmp_path / "empty.yaml").write_text("")
    assert read_yaml_mapping(tmp_path / "empty.yaml", "test") == {}
    (tmp_path / "bin.yaml").write_bytes(b"a: \xff\xfe\n")
    with pytest.raises(ValueError, match="bin.yaml"):
        read_yaml_mapping(tmp_path / "bin.yaml", "test")
    with pytest.raises(OSError):
        read_yaml_mapping(tmp_path / "missing.yaml", "test")
