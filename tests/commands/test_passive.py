"""``roughwalk passive``: the walker converges to the passive limit cycle the command finds."""

import re

from commands.cli import main
from envs import RobotParams
from envs.physics.passive import CLASSIC_CYCLE, passive_limit_cycle


def test_passive_walk_converges_to_the_limit_cycle(capsys):
    assert main(["passive", "--steps", "12", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    # the command prints the cycle it found (its figures are asserted in the physics tests), and
    # a distance to it that shrinks over the run
    cycle = passive_limit_cycle(
        RobotParams.from_preset("classic"), CLASSIC_CYCLE.slope, CLASSIC_CYCLE.section
    )
    assert f"{cycle.period:.6f}" in out and f"{cycle.step_length:.6f}" in out
    dists = [float(m) for m in re.findall(r"(\d\.\d+e[-+]\d+)\W*$", out, flags=re.M)]
    assert len(dists) >= 10
    assert dists[-1] < 0.05 * dists[0]
