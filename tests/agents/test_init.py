"""The ``agents`` package: its public names, and no torch or stable-baselines3 on import."""

import ast
import subprocess
import sys
from pathlib import Path

import agents


def test_every_public_name_resolves():
    for name in agents.__all__:
        assert getattr(agents, name) is not None, name
    assert set(agents.__all__) <= set(dir(agents))


def test_lazy_names_are_the_module_objects():
    from agents.sb3_vec_env import SB3VecEnv

    assert agents.SB3VecEnv is SB3VecEnv


def test_import_loads_neither_torch_nor_stable_baselines3():
    code = (
        "import sys\n"
        "import agents\n"
        "from agents.residual import ResidualWrapper\n"
        "heavy = {'torch', 'stable_baselines3'} & set(sys.modules)\n"
        "print(sorted(heavy))\n"
        "agents.SB3VecEnv\n"
        "print('stable_baselines3' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["[]", "True"]


def _module_level_imports(path: Path, package: str) -> set[str]:
    """Modules of ``package`` that the file ``path`` imports at module level."""
    found = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom):
            base = f"{package}.{node.module or ''}".rstrip(".") if node.level else node.module
            names = [f"{base}.{a.name}" for a in node.names] + [base or ""]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        found |= {n for n in names if n.startswith(package + ".") and n.count(".") == 1}
    return found


def test_module_level_imports_between_the_modules_are_acyclic():
    folder = Path(agents.__file__).parent
    graph = {
        f"agents.{p.stem}": _module_level_imports(p, "agents")
        for p in folder.glob("*.py")
        if p.stem != "__init__"
    }
    done: set[str] = set()

    def visit(module: str, path: tuple[str, ...]) -> None:
        assert module not in path, f"import cycle: {' -> '.join((*path, module))}"
        if module in done:
            return
        for dep in graph.get(module, ()):
            visit(dep, (*path, module))
        done.add(module)

    for module in graph:
        visit(module, ())
    assert "agents.residual" in graph["agents.config"]  # the edge that used to close a cycle
