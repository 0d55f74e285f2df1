"""The modules whose warm_up() compiles (or loads from numba's cache) the kernels a service's setup
needs: `omninav warm` runs them all once after installing, the fork server of forked.py at its start
(navigate's goal check uses the planner's)."""
from __future__ import annotations

import importlib
import time
from typing import Callable

KERNEL_MODULES = ("omninav.sim.lidar", "omninav.sim.people.social_force", "omninav.services.costmap.layers", "omninav.services.global_planner.astar",
                  "omninav.services.local_planner.dwa", "omninav.services.local_planner.eband",
                  "omninav.services.localizer.filter", "omninav.services.tracker.tracker",
                  "omninav.services.laser_odometry.laser_odometry")


def warm_all(report: Callable[[str, float], None] | None = None) -> None:
    """Every module's warm_up(); report(module, seconds) after each."""
    for name in KERNEL_MODULES:
        started = time.monotonic()
        importlib.import_module(name).warm_up()
        if report is not None:
            report(name, time.monotonic() - started)
