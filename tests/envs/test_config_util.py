import math
from dataclasses import dataclass, field
from types import MappingProxyType

import pytest

from controllers.controller import ControllerConfig
from controllers.planner import PlannerConfig
from envs.config_util import dataclass_from_mapping, preset_settings, reject_moved_fields
from envs.physics import RobotParams
from envs.sensors import SensorConfig
from envs.settings import EnvSettings


@dataclass(frozen=True)
class _Gains:
    kp: float
    kd: float = 1.0
    extra: tuple[float, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.kp) and self.kp > 0):
            raise ValueError(f"gains.kp = {self.kp!r} out of range; allowed: > 0")


def test_builds_from_any_mapping_and_passes_instances_through() -> None:
    g = dataclass_from_mapping(_Gains, {"kp": 2.0}, "gain")
    assert g == _Gains(kp=2.0, kd=1.0, extra=())
    assert (
        dataclass_from_mapping(_Gains, MappingProxyType({"kp": 3.0, "kd": 0.5}), "gain").kd == 0.5
    )
    assert dataclass_from_mapping(_Gains, g, "gain") is g


def test_rejects_non_mappings_naming_the_settings() -> None:
    with pytest.raises(ValueError, match=r"gain settings must be a mapping, got list"):
        dataclass_from_mapping(_Gains, [("kp", 1.0)], "gain")
    with pytest.raises(ValueError, match=r"gain parameters must be a mapping, got NoneType"):
        dataclass_from_mapping(_Gains, None, "gain", item="parameter")


def test_unknown_keys_are_named_with_the_allowed_fields() -> None:
    with pytest.raises(ValueError) as err:
        dataclass_from_mapping(_Gains, {"kp": 1.0, "ki": 0.1, 3: "x"}, "gain")
    assert str(err.value) == "unknown gain setting(s) [3, 'ki']; allowed: ['extra', 'kd', 'kp']"


def test_missing_required_fields_and_bad_types_raise_value_errors() -> None:
    with pytest.raises(ValueError, match=r"missing gain parameter\(s\) \['kp'\]"):
        dataclass_from_mapping(_Gains, {"kd": 1.0}, "gain", item="parameter")
    with pytest.raises(ValueError, match=r"bad gain settings: .*"):
        dataclass_from_mapping(_Gains, {"kp": "fast"}, "gain")  # math.isfinite(str) -> TypeError
    with pytest.raises(ValueError, match=r"gains\.kp = -1\.0 out of range"):  # __post_init__'s own
        dataclass_from_mapping(_Gains, {"kp": -1.0}, "gain")
    with pytest.raises(TypeError, match="dataclass"):
        dataclass_from_mapping(dict, {}, "gain")


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (RobotParams.from_dict, r"unknown robot parameter\(s\) \['colour'\]; allowed: \["),
        (SensorConfig.from_dict, r"unknown sensor setting\(s\) \['colour'\]; allowed: \["),
        (PlannerConfig.from_dict, r"unknown planner setting\(s\) \['colour'\]; allowed: \["),
        (ControllerConfig.from_dict, r"unknown controller setting\(s\) \['colour'\]; allowed: \["),
    ],
)
def test_project_configs_share_the_messages(build, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build({"colour": "red"})
    with pytest.raises(ValueError, match="must be a mapping"):
        build(["colour"])


def test_robot_params_round_trip_and_missing_field() -> None:
    p = RobotParams.from_preset("classic")
    assert RobotParams.from_dict(p.to_dict()) == p
    d = p.to_dict()
    del d["m"]
    with pytest.raises(ValueError, match=r"missing robot parameter\(s\) \['m'\]"):
        RobotParams.from_dict(d)


@pytest.mark.parametrize("section", ["reward", "initial_state", "simulator"])
def test_env_sections_share_the_messages(section: str) -> None:
    with pytest.raises(ValueError, match=rf"unknown {section} setting\(s\) \['colour'\]"):
        EnvSettings.build("flat", **{section: {"colour": "red"}})


@dataclass(frozen=True)
class _Renamed:
    MOVED_FIELDS = {"gain": "use kp"}
    kp: float = 1.0


def test_moved_fields_name_their_replacement() -> None:
    with pytest.raises(ValueError, match=r"_Renamed\.gain moved: use kp"):
        dataclass_from_mapping(_Renamed, {"gain": 2.0}, "gain")
    with pytest.raises(ValueError, match=r"_Renamed\.gain moved: use kp"):
        reject_moved_fields(_Renamed, ["kp", "gain"])
    reject_moved_fields(_Renamed, ["kp"])
    reject_moved_fields(_Gains, ["gain"])  # a class without MOVED_FIELDS moves nothing


def test_preset_settings_read_the_robots_file_and_apply_the_changes():
    """The paper robot's controller preset (its stiff weights), updated by the changes; no
    file, or no robot, gives the changes alone."""
    paper = preset_settings("controller", "paper", "controller config", {"horizon": 2})
    assert paper["Q"] == [1.0, 40000.0, 400.0] and paper["horizon"] == 2
    overridden = preset_settings("controller", "paper", "controller config", {"Q": [1, 1, 1]})
    assert overridden["Q"] == [1, 1, 1]
    assert preset_settings("controller", "classic", "controller config", {"grid": 8}) == {"grid": 8}
    assert preset_settings("planner", None, "planner config", {}) == {}
