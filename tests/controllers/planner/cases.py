"""Terrain cases of the planner tests, per robot."""

from configs import CONFIG_DIR
from controllers.planner import TerrainMap
from controllers.planner.problem import FixedStep, SearchBudget, StepEvaluator, gait_reference
from envs.physics.terrain import Terrain

PAPER_STAIRS = Terrain.from_yaml(CONFIG_DIR / "terrains" / "paper_stairs.yaml")
# terrain cases per robot (the classic walker's legs are l = 1 m, the paper robot's 0.32 m)
CASES = {
    "paper": {
        "flat": Terrain.flat(),
        "paper_stairs": PAPER_STAIRS,
        "stairs_up": Terrain.staircase(0.4, 3, 0.3, 0.01),
        "blocks_low": Terrain.random_blocks(1, 0.3, 3.0, (0.15, 0.3), (-0.003, 0.003)),
        "blocks_high": Terrain.random_blocks(1, 0.3, 3.0, (0.15, 0.3), (-0.01, 0.01)),
    },
    "classic": {
        "flat": Terrain.flat(),
        "stairs_down": Terrain.stairs([1.25, 1.94], [-0.01, -0.01]),
        "stairs_up": Terrain.staircase(1.0, 3, 1.0, 0.01),
        "blocks_low": Terrain.random_blocks(1, 1.0, 6.0, (0.45, 0.9), (-0.0025, 0.0025)),
        "blocks_high": Terrain.random_blocks(1, 1.0, 6.0, (0.45, 0.9), (-0.005, 0.005)),
        "downhill": Terrain.slope(-0.0525),
    },
}
HORIZON = {"paper": 7, "classic": 7}
ALL_CASES = [(r, t) for r in CASES for t in CASES[r]]


def gait_step(planner, terrain, stance=(0.25, 0.0), length=None, rise=0.0, ref=True):
    """A step problem shaped like ``planner``'s periodic gait step on ``terrain``: from the
    stance foot ``stance`` [m] to the foothold ``length`` [m] ahead (the gait's step length by
    default) and ``rise`` [m] up, with the gait's start and end phases. Returns the evaluator
    (pulling towards the gait with ``ref``, else the periodic gait's effort cost), the
    :class:`FixedStep` and the gait's step."""
    g = planner.periodic_gait()
    st = g.step
    sm = StepEvaluator(planner.params, planner.config, TerrainMap(terrain))
    if ref:
        sm.ref = gait_reference(g)
    length = st.step_length if length is None else length
    fx = FixedStep(
        st.theta_plus,
        st.coeffs[0],
        st.slope_plus,
        st.thetadot_plus,
        stance,
        (stance[0] + length, stance[1] + rise),
        st.theta_minus,
        st.coeffs[-1],
    )
    return sm, fx, st


class RecordedBudget(SearchBudget):
    """A :class:`SearchBudget` that records each ``spend``: ``(used before, n)``."""

    def __init__(self, evaluations: int):
        super().__init__(evaluations)
        self.spent: list[tuple[int, int]] = []

    def spend(self, n: int) -> None:
        self.spent.append((self.used, n))
        super().spend(n)
