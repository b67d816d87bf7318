"""The ``agents`` package: its public names, and no torch or stable-baselines3 on import."""

import subprocess
import sys

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
