"""The planner package's public names, and the former module paths that re-export them."""

import controllers
import controllers.footsteps
import controllers.planner
import controllers.planner.kernel
from controllers.planner import footholds, kernel


def test_public_names_importable_from_the_package():
    for name in controllers.planner.__all__:
        assert getattr(controllers.planner, name) is not None
    for name in ("GaitPlanner", "PeriodicGait", "Plan", "PlannerConfig", "PlanningError"):
        assert getattr(controllers, name) is getattr(controllers.planner, name)


def test_former_module_paths_re_export_the_same_objects():
    for name in controllers.footsteps.__all__:
        assert getattr(controllers.footsteps, name) is getattr(footholds, name)
    for name in controllers.planner.kernel.__all__:
        assert getattr(controllers.planner.kernel, name) is getattr(kernel, name)
