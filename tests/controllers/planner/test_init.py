"""The planner package's public names."""

import controllers
import controllers.planner


def test_public_names_importable_from_the_package():
    for name in controllers.planner.__all__:
        assert getattr(controllers.planner, name) is not None
    for name in ("GaitPlanner", "PeriodicGait", "Plan", "PlannerConfig", "PlanningError"):
        assert getattr(controllers, name) is getattr(controllers.planner, name)
