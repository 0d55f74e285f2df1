"""The house rules that a reader of the code should not have to police: ruff's checks pass, and
imports point the way docs/architecture.md draws them (ROOMS below is that drawing's allow-list)."""
from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pkgutil
import re
import subprocess
import sys
import textwrap

import pytest

from conftest import REPO

# What each room may import besides itself. A room is a top-level package, or one folder of
# services/ (one process each). Every service may also import schemas, geometry and services/runtime
# (SERVICE_BASE); the few arrows between services are core reuse, each named here with its reason.
# parameters (how a parameter class declares and checks its fields) is neutral like geometry: every
# core, node and geometry's frame mixin declare their parameters with it, and it imports nothing of ours.
SERVICE_BASE = {"schemas", "geometry", "parameters", "services/runtime"}
LIBRARY = {"schemas", "geometry", "parameters", "sim"} | {f"services/{p.name}" for p in (REPO / "services").iterdir()
                                            if (p / "__init__.py").is_file()}
ROOMS: dict[str, set[str]] = {
    "schemas": set(),                                       # the wire contract
    "parameters": set(),                                    # the standard library only
    "geometry": {"schemas", "parameters"},                  # numpy/numba, message types, FrameParams' declaration
    "services/runtime": {"schemas", "parameters"},
    "sim": {"schemas", "geometry", "parameters", "services/runtime",
            "services/chassis",                             # the sim drives the chassis's kinematics
            "services/map_server"},                         # worlds may load a map file
    "services/lidar": SERVICE_BASE | {"sim"},               # the simulated lidar casts into the sim's world
    "services/costmap": SERVICE_BASE | {"services/map_server"},       # static layer from a map file
    "services/localizer": SERVICE_BASE | {"services/map_server"},     # map_file parameter
    "services/replay": SERVICE_BASE | {"services/recorder"},          # reads MCAP with the recorder's mcap_io
    "services/view": SERVICE_BASE | {"services/recorder"},            # export reads MCAP the same way
    "services/local_planner": SERVICE_BASE | {"services/costmap"},    # the cost values of the costmap it reads
    "services/collision_monitor": SERVICE_BASE,
    "services/explore": SERVICE_BASE | {"services/costmap", "services/global_planner"},   # inflation, A*
    "services/ros2_bridge": SERVICE_BASE | {"services/importers"},    # the ROS → omninav conversions of rosbag.py
    "services/laser_odometry": SERVICE_BASE | {"services/slam"},      # hector's grids and matcher, in a local window
    "cli": LIBRARY | {"experiments", "bench"},              # the command reaches everything
    "experiments": LIBRARY | {"cli"},                       # harnesses run what `omninav navigate` composes
    "bench": LIBRARY | {"cli", "experiments"},
}


def test_ruff_finds_nothing():
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", str(REPO)], capture_output=True,
                          text=True, cwd=REPO)
    assert done.returncode == 0, done.stdout + done.stderr


def _room(parts: tuple[str, ...]) -> str:
    return f"services/{parts[1]}" if parts[0] == "services" and len(parts) > 1 else parts[0]


def _imports(path) -> list[tuple[str, set[str], int]]:
    """(room, names imported, line) for every import of our own code in a file."""
    found = []
    package = path.relative_to(REPO).parent.parts
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - node.level + 1]
            target = (*base, *(node.module.split(".") if node.module else ()))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("omninav."):
            target = tuple(node.module.split(".")[1:])
        elif isinstance(node, ast.Import) and any(a.name.startswith("omninav.") for a in node.names):
            raise AssertionError(f"{path}:{node.lineno}: write `from omninav.x import y`, so the room is visible")
        else:
            continue
        names = {a.name for a in node.names}
        if target == ("services",):   # from .. import <service>
            found += [(f"services/{name}", set(), node.lineno) for name in names]
        elif target:
            found.append((_room(target), names, node.lineno))
    return found


def _library_files():
    for room in ROOMS:
        if room not in ("cli", "experiments", "bench"):
            yield from (REPO / room).rglob("*.py")


def test_the_allow_list_names_only_rooms_that_exist():
    stale = [room for room in ROOMS if not (REPO / room).is_dir()]
    stale += [f"{room} -> {target}" for room, targets in ROOMS.items() for target in targets
              if not (REPO / target).is_dir()]
    assert not stale, stale


def test_imports_point_the_way_the_house_is_drawn():
    wrong = []
    for top in ("schemas", "geometry", "parameters", "services", "sim", "cli", "experiments", "bench"):
        for path in (REPO / top).rglob("*.py"):
            room = _room(path.relative_to(REPO).parts)
            allowed = ROOMS.get(room, SERVICE_BASE)
            for target, _, line in _imports(path):
                if target != room and target not in allowed:
                    wrong.append(f"{path.relative_to(REPO)}:{line}: {room} imports {target}")
    assert not wrong, "imports outside the allow-list in tests/test_house.py:\n" + "\n".join(wrong)


def test_nothing_imports_another_modules_private_names():
    wrong = []
    for top in ("schemas", "geometry", "parameters", "services", "sim", "cli", "experiments", "bench"):
        for path in (REPO / top).rglob("*.py"):
            for _, names, line in _imports(path):
                wrong += [f"{path.relative_to(REPO)}:{line}: {name}" for name in names
                          if name.startswith("_") and not name.startswith("__")]
    assert not wrong, "private names imported across modules:\n" + "\n".join(wrong)


def test_services_holds_only_folders():
    """One folder per process: no module loose in services/ (what services share is in geometry/)."""
    loose = [p.name for p in (REPO / "services").glob("*.py") if p.name != "__init__.py"]
    assert not loose, loose


def test_the_library_does_not_import_the_lab_or_the_command_line():
    for path in _library_files():
        rooms = {target for target, _, _ in _imports(path)}
        assert not rooms & {"experiments", "bench", "cli"}, path


def test_no_two_modules_share_a_name_for_different_things():
    """node.py, params.py, reference.py, cli.py and __init__.py are roles every room may have; any
    other module name is used once, so a name says which thing it is."""
    roles = {"__init__.py", "node.py", "params.py", "reference.py", "cli.py"}
    seen: dict[str, list[str]] = {}
    for top in ("schemas", "geometry", "parameters", "services", "sim", "experiments", "bench", "cli"):
        for path in (REPO / top).rglob("*.py"):
            if path.name not in roles:
                seen.setdefault(path.name, []).append(str(path.relative_to(REPO)))
    twice = {name: paths for name, paths in seen.items() if len(paths) > 1}
    assert not twice, twice


def _library_dataclasses():
    """(module, class) of every dataclass the library defines."""
    for top in ("geometry", "services", "sim"):
        package = importlib.import_module(f"omninav.{top}")
        for info in pkgutil.walk_packages(package.__path__, f"omninav.{top}."):
            module = importlib.import_module(info.name)
            for cls in vars(module).values():
                if isinstance(cls, type) and dataclasses.is_dataclass(cls) and cls.__module__ == info.name:
                    yield module, cls


def test_no_parameter_class_redefines_a_field_it_inherits():
    """A node's parameters extend its core's: a field declared again would silently give the node another
    default than the core documents."""
    redefined = []
    for _, cls in _library_dataclasses():
        own = cls.__dict__.get("__annotations__", {})
        redefined += [f"{cls.__qualname__}.{f.name} (from {base.__qualname__})"
                      for base in cls.__mro__[1:] if dataclasses.is_dataclass(base)
                      for f in dataclasses.fields(base) if f.name in own]
    assert not redefined, redefined


def test_every_parameter_class_declares_and_checks_the_one_way():
    """Every class a Node takes as Params, and every class named *Params, derives from Parameters
    (omninav.parameters): its fields say what they allow; no __post_init__ of its own raises."""
    from omninav.parameters.declare import Parameters
    from omninav.services.runtime.node import Node

    classes = {cls for _, cls in _library_dataclasses() if cls.__name__.endswith("Params")}
    classes |= {cls.Params for module, _ in _library_dataclasses() for cls in vars(module).values()
                if isinstance(cls, type) and issubclass(cls, Node) and cls is not Node}
    other_ways = [cls.__qualname__ for cls in classes if not issubclass(cls, Parameters)]
    for cls in classes:
        post_init = cls.__dict__.get("__post_init__")
        if post_init is not None:
            tree = ast.parse(textwrap.dedent(inspect.getsource(post_init)))
            other_ways += [f"{cls.__qualname__}.__post_init__ raises" for node in ast.walk(tree)
                           if isinstance(node, ast.Raise)]
    assert not other_ways, other_ways


# A core's parameter class and the modules of the core that read it: a field none of them reads
# is a parameter that does nothing (or belongs to the node around the core).
CORE_READERS = {
    "services.local_planner.params:DwaParams": ["services/local_planner/dwa.py", "services/local_planner/dynamic.py",
                                                "services/local_planner/control.py"],
    "services.local_planner.params:FollowerParams": ["services/local_planner/path_follower.py",
                                                     "services/local_planner/approach.py"],
    "services.local_planner.params:ElasticBandParams": ["services/local_planner/eband.py"],
    "services.local_planner.shim:RotationShimParams": ["services/local_planner/shim.py"],
    "services.global_planner.params:GlobalPlannerParams": ["services/global_planner/astar.py",
                                                           "services/global_planner/path_smoother.py"],
    "services.slam.params:SlamParams": ["services/slam/rbpf.py", "services/slam/scanmatch.py",
                                        "services/slam/particle_grids.py", "services/slam/relations.py"],
    "services.slam.hector:HectorParams": ["services/slam/hector.py", "services/slam/hector_match.py"],
    "services.localizer.params:DiffMotionParams": ["services/localizer/params.py"],
    "services.localizer.params:OmniMotionParams": ["services/localizer/params.py"],
    "services.localizer.params:BeamModelParams": ["services/localizer/sensor.py"],
    "services.localizer.params:LikelihoodFieldProbParams": ["services/localizer/sensor.py"],
    "services.tracker.tracker:TrackerParams": ["services/tracker/tracker.py"],
    "services.velocity_smoother.smoother:VelocitySmootherParams": ["services/velocity_smoother/smoother.py"],
    "services.collision_monitor.collision:CollisionMonitorParams": ["services/collision_monitor/collision.py"],
    "services.explore.frontiers:ExploreParams": ["services/explore/frontiers.py"],
    "sim.imu:ImuParams": ["sim/imu.py", "sim/node.py"],
}


@pytest.mark.parametrize("target", sorted(CORE_READERS))
def test_no_core_parameter_class_declares_a_field_its_core_never_reads(target):
    module, name = target.split(":")
    cls = getattr(importlib.import_module(f"omninav.{module}"), name)
    own = {f.name for f in dataclasses.fields(cls)} - set().union(
        *({f.name for f in dataclasses.fields(base)} for base in cls.__mro__[1:] if dataclasses.is_dataclass(base)))
    code = "\n".join((REPO / path).read_text() for path in CORE_READERS[target])
    # read as an attribute, or taken by a core function under its own name
    unread = sorted(field for field in own if not re.search(rf"\.{field}\b|\b{field}: ", code))
    assert not unread, f"{name} declares what {', '.join(CORE_READERS[target])} never read: {unread}"
