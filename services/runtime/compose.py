"""Compose files: which services `omninav up` starts, in which order, with which parameters.

Loading validates everything that can be checked without starting a process — service names,
module paths, parameter files and every parameter against the node's Params dataclass — so a
broken file is one clear error naming the file and the key, and nothing is started. See
docs/compose.md for the format.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...schemas.keys import DEFAULT_ROBOT, KeyLayout
from .node import Node
from ...parameters.declare import ParamError
from ...parameters.from_mapping import unknown_names
from .params import load_node_params, read_params_mapping, read_yaml
from .service_registry import UnknownService, node_class
from .zenoh_config import check_loopback

RESTART_POLICIES = ("no", "on-failure", "always")
TOP_KEYS = ("router", "robot", "services")
SERVICE_KEYS = ("name", "service", "module", "params", "params_file", "robot", "restart", "max_restarts", "process")


class ComposeError(ValueError):
    """A compose file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class ServiceSpec:
    name: str                 # instance name: log prefix, diagnostics key, ROS node name in params files
    service: str | None       # a name in the registry, or
    module: str | None        # "package.module:Class" for a Node class that is not registered
    params: dict[str, Any]    # the effective mapping (params_file, then inline params), validated
    robot: str
    restart: str              # one of RESTART_POLICIES
    max_restarts: int | None  # None: no limit
    process: str              # the OS process (container) it runs in: its own name unless `process` says
    # its Node class, imported once while the file is loaded (what `up` and a container then build)
    node_type: type | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class ProcessSpec:
    """One OS process of a run: a single service, or a container of several sharing one Zenoh
    session and one identity (container.py). Its restart policy is its services' (they agree)."""
    name: str
    services: tuple[ServiceSpec, ...]
    restart: str
    max_restarts: int | None

    @property
    def container(self) -> bool:
        return len(self.services) > 1 or self.services[0].name != self.name


@dataclass(frozen=True)
class Compose:
    path: Path
    router: str | None        # None: $OMNINAV_ROUTER or the default
    robot: str
    services: tuple[ServiceSpec, ...]
    processes: tuple[ProcessSpec, ...]     # in the order of their first service


def load_compose(path: str | Path) -> Compose:
    path = Path(path)
    try:
        data = read_yaml(path)
    except ParamError as exc:
        raise ComposeError(str(exc)) from None
    if not isinstance(data, dict):
        raise ComposeError(f"{path}: expected a mapping with a 'services' list")
    _no_unknown_keys(data, TOP_KEYS, f"{path}")

    router = data.get("router")
    if router is not None:
        if not isinstance(router, str):
            raise ComposeError(f"{path}: router must be an endpoint string such as tcp/127.0.0.1:7447")
        try:
            check_loopback(router)
        except ValueError as exc:
            raise ComposeError(f"{path}: router: {exc}") from None
    robot = _robot(data.get("robot", DEFAULT_ROBOT), f"{path}: robot")

    entries = data.get("services")
    if not isinstance(entries, list) or not entries:
        raise ComposeError(f"{path}: services must be a non-empty list")
    services: list[ServiceSpec] = []
    for index, entry in enumerate(entries):
        spec = _service(entry, f"{path}: services[{index}]", path.parent, robot)
        if any(s.name == spec.name for s in services):
            raise ComposeError(f"{path}: services[{index}]: duplicate name {spec.name!r}")
        services.append(spec)
    return Compose(path, router, robot, tuple(services), _processes(services, path))


def _processes(services: list[ServiceSpec], path: Path) -> tuple[ProcessSpec, ...]:
    """Services grouped by their process; a process name is an identity, so it may not be the name
    of a service running elsewhere, and the services of one process share one restart policy."""
    groups: dict[str, list[ServiceSpec]] = {}
    for spec in services:
        groups.setdefault(spec.process, []).append(spec)
    processes = []
    for name, members in groups.items():
        clash = next((s for s in services if s.name == name and s.process != name), None)
        if clash is not None:
            raise ComposeError(f"{path}: process {name!r} has the name of service {clash.name!r}, which runs "
                               f"in process {clash.process!r}")
        first = members[0]
        for other in members[1:]:
            if (other.restart, other.max_restarts) != (first.restart, first.max_restarts):
                raise ComposeError(f"{path}: {other.name} (restart {other.restart}, max_restarts "
                                   f"{other.max_restarts}) runs in process {name!r} with {first.name} (restart "
                                   f"{first.restart}, max_restarts {first.max_restarts}): a process restarts as "
                                   f"a whole, give its services the same policy")
        processes.append(ProcessSpec(name, tuple(members), first.restart, first.max_restarts))
    return tuple(processes)


def _service(entry: Any, where: str, base: Path, default_robot: str) -> ServiceSpec:
    if not isinstance(entry, dict):
        raise ComposeError(f"{where}: expected a mapping with 'service' or 'module'")
    _no_unknown_keys(entry, SERVICE_KEYS, where)
    service, module = entry.get("service"), entry.get("module")
    if (service is None) == (module is None):
        raise ComposeError(f"{where}: give exactly one of 'service' (a registered name) or 'module' (package.module:Class)")
    for key in ("service", "module", "name", "params_file", "process"):
        if key in entry and not isinstance(entry[key], str):
            raise ComposeError(f"{where}.{key}: must be a string, got {entry[key]!r}")
    if module is not None and (module.count(":") != 1 or not all(module.split(":"))):
        raise ComposeError(f"{where}.module: {module!r} is not 'package.module:Class'")

    name = entry.get("name", service)
    if name is None:
        raise ComposeError(f"{where}: a 'module' service needs a 'name'")
    try:
        KeyLayout(default_robot).diagnostics(name)  # the name becomes a key segment
    except ValueError as exc:
        raise ComposeError(f"{where}.name: {exc}") from None
    where = f"{where} ({name})"

    try:
        cls = node_class(service or name, module)
    except UnknownService as exc:
        raise ComposeError(f"{where}: {exc}") from None
    except Exception as exc:  # a user's module that raises while importing (SyntaxError, ...)
        raise ComposeError(f"{where}: importing {module or service} failed: {type(exc).__name__}: {exc}") from None
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        raise ComposeError(f"{where}.module: {module} is not a Node class")

    params = _params(entry, where, base, name, cls.Params)
    robot = _robot(entry.get("robot", default_robot), f"{where}.robot")

    restart = entry.get("restart", "on-failure")
    if restart is False:  # YAML 1.1 reads an unquoted `no` as false
        restart = "no"
    if restart not in RESTART_POLICIES:
        raise ComposeError(f"{where}.restart: {restart!r} is not one of {list(RESTART_POLICIES)}")
    max_restarts = entry.get("max_restarts")
    if max_restarts is not None and (isinstance(max_restarts, bool) or not isinstance(max_restarts, int)
                                     or max_restarts < 0):
        raise ComposeError(f"{where}.max_restarts: must be a whole number >= 0, got {max_restarts!r}")

    process = entry.get("process", name)
    try:
        KeyLayout(default_robot).diagnostics(process)   # a process name is a Zenoh user name and a file name
    except ValueError as exc:
        raise ComposeError(f"{where}.process: {exc}") from None
    return ServiceSpec(name, service, module, params, robot, restart, max_restarts, process, cls)


def _params(entry: dict, where: str, base: Path, name: str, params_type: type) -> dict:
    """File parameters overridden by inline ones, validated against the node's Params."""
    merged: dict[str, Any] = {}
    if "params_file" in entry:
        file = base / entry["params_file"]
        try:
            merged = read_params_mapping(file, name)
            load_node_params(params_type, merged, str(file))
        except ParamError as exc:
            raise ComposeError(f"{where}.params_file: {exc}") from None
    inline = entry.get("params") or {}
    if not isinstance(inline, dict):
        raise ComposeError(f"{where}.params: must be a mapping of parameter names to values")
    merged = {**merged, **inline}
    try:
        load_node_params(params_type, merged, f"{where}.params")
    except ParamError as exc:
        raise ComposeError(str(exc)) from None
    return merged


def _robot(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise ComposeError(f"{where}: must be a string, got {value!r}")
    try:
        KeyLayout(value)
    except ValueError as exc:
        raise ComposeError(f"{where}: {exc}") from None
    return value


def _no_unknown_keys(mapping: dict, known: tuple[str, ...], where: str) -> None:
    problem = unknown_names(mapping, known)
    if problem:
        raise ComposeError(f"{where}: {problem}")
