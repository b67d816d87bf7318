"""The physics subpackage stands on its own: no module of ``envs/physics`` imports Gymnasium,
the Gym layer of ``envs`` or the packages above it."""

import ast
from pathlib import Path

import pytest

import envs.physics

PHYSICS_DIR = Path(envs.physics.__file__).resolve().parent
MODULES = sorted(PHYSICS_DIR.rglob("*.py"))
# the Gym layer of envs, under its present and its planned module names
GYM_LAYER = {
    "compass_gait_env",
    "vector_env",
    "sensors",
    "rendering",
    "registration",
    "env",
    "batch",
    "task",
    "settings",
}
FORBIDDEN_TOP = {"gymnasium", "gym", "controllers", "agents", "commands"}
ALLOWED_ENVS = {"envs.physics", "envs.config_util"}


def _package_of(path: Path) -> list[str]:
    """Dotted parts of the package that holds the module ``path`` (for ``__init__.py``: its own
    package), the base of its relative imports."""
    return list(path.relative_to(PHYSICS_DIR.parent.parent).parts[:-1])


def _imported(path: Path) -> list[str]:
    """Absolute names of every module (or module attribute) ``path`` imports."""
    package = _package_of(path)
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            names += [f"{mod}.{a.name}" for a in node.names]
    return names


def test_the_physics_package_has_its_modules():
    stems = {p.stem for p in MODULES}
    assert {"params", "model", "terrain", "kernel", "simulator", "passive"} <= stems


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.stem)
def test_no_gym_or_upper_layer_import(path):
    for name in _imported(path):
        parts = name.split(".")
        assert parts[0] not in FORBIDDEN_TOP, f"{path.name} imports {name}"
        if parts[0] == "envs":
            assert not GYM_LAYER & set(parts[1:2]), f"{path.name} imports {name}"
            assert any(name == a or name.startswith(a + ".") for a in ALLOWED_ENVS), (
                f"{path.name} imports {name}, outside envs.physics and envs.config_util"
            )


def test_the_import_parser_sees_relative_imports():
    init = PHYSICS_DIR / "__init__.py"
    kernel = PHYSICS_DIR / "kernel.py"
    params = PHYSICS_DIR / "params.py"
    assert "envs.physics.model" in _imported(init)
    assert "envs.physics.model" in _imported(kernel)
    assert "envs.config_util.dataclass_from_mapping" in _imported(params)
