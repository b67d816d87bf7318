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


def test_the_table_has_units_and_a_fall_before_the_first_step_is_said_so(capsys):
    assert main(["passive", "--steps", "3", "--perturb", "0.2", "--seed", "4"]) == 1
    out = " ".join(capsys.readouterr().out.split())
    assert "time [s]" in out and "step length [m]" in out and "q2dot+ [rad/s]" in out
    assert "no step: the walker failed 0.415 s after the start; FAILED: trip" in out
    assert "nan" not in out
