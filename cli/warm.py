"""`omninav warm`: compile every kernel the services warm up into numba's cache (`cache=True`: beside
each source file, in __pycache__), once after installing — `make venv` runs it. On a cold cache each
service compiled its kernels as it started, seconds each, and processes starting together compiled
the same kernels side by side: `navigate --composed` in the room took 48 s to its first goal, 5.7 s
once warmed (load average 5-6; `omninav warm` itself 37 s). A kernel whose source changed is
compiled again at its first use."""
from __future__ import annotations

import argparse
import importlib
import time

# the modules whose warm_up() a service's setup calls (navigate's goal check uses the planner's)
WARM_UPS = ("omninav.sim.lidar", "omninav.services.costmap.layers", "omninav.services.global_planner.astar",
            "omninav.services.local_planner.dwa", "omninav.services.local_planner.eband",
            "omninav.services.localizer.filter", "omninav.services.tracker.tracker")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def main(args: argparse.Namespace) -> int:
    for name in WARM_UPS:
        started = time.monotonic()
        importlib.import_module(name).warm_up()
        print(f"warm: {name} in {time.monotonic() - started:.1f} s", flush=True)
    return 0
