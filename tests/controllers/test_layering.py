"""The controllers build on the physics alone: no module of ``controllers`` imports Gymnasium's
env layer of ``envs`` (its env, batch, task, settings, sensors, rendering, registration) or the
packages above it (``agents``, ``commands``). They read an env only through the object passed
in, so the same maths serves the simulator, the envs and a real robot."""

import ast
from pathlib import Path

import pytest

import controllers

ROOT = Path(controllers.__file__).resolve().parent
MODULES = sorted(ROOT.rglob("*.py"))
ALLOWED_ENVS = ("envs.physics", "envs.config_util")
FORBIDDEN_TOP = {"agents", "commands"}


def _imported(path: Path) -> list[str]:
    """Absolute names of the modules ``path`` imports (relative imports stay in controllers)."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names.append(node.module)
    return names


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT)))
def test_controllers_import_the_physics_not_the_gym_layer(path):
    for name in _imported(path):
        top = name.split(".")[0]
        assert top not in FORBIDDEN_TOP, f"{path.name} imports {name}"
        if top == "envs":
            assert name.startswith(ALLOWED_ENVS), f"{path.name} imports {name}"


def test_the_scan_sees_the_physics_imports():
    assert "envs.physics" in _imported(ROOT / "controller.py") or any(
        n.startswith("envs.physics") for n in _imported(ROOT / "controller.py")
    )
