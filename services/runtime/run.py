"""Run one service as its own process: `omninav run SERVICE [--params FILE] [--set k=v] ...`."""
from __future__ import annotations

import argparse
import logging
import sys

from .joining import LoginRefused
from .live import LiveRunner
from .lockstep import Lockstep, service_names
from ...parameters.declare import ParamError
from .params import load_node_params, parse_overrides, read_params_mapping
from .service_registry import UnknownService, node_class
from .stop_signals import on_parent_exit, on_stop_signals


def build_node(service: str, params_file: str | None = None, overrides: dict | None = None,
               robot: str = "r1", name: str | None = None, spec: str | None = None, base: dict | None = None,
               node_type: type | None = None):
    """Construct a service's Node with validated parameters (raises UnknownService / ParamError).

    base: values the file's and the overrides go over (replay: the live run's, from its Diagnostic;
    built values, so an override there does not re-derive what was derived from it live).
    node_type: the Node class when the caller already imported it (a loaded compose file's).
    """
    cls = node_type or node_class(service, spec)
    # merge the raw mappings, not built dataclasses: a built one carries derived defaults
    # (e.g. a lidar's angle_min from its fov) that an override must be free to change
    values = read_params_mapping(params_file, name or service) if params_file else {}
    source = " with overrides".join(filter(None, [params_file or service, "" if overrides else None]))
    if base is not None:
        source += " over the recorded parameters"
    params = load_node_params(cls.Params, {**(base or {}), **values, **(overrides or {})}, source)
    return cls(params, robot=robot, name=name)


def configure_logging(name: str, level: str = "INFO") -> None:
    logging.basicConfig(level=level, stream=sys.stderr, format=f"%(levelname)s [{name}] %(message)s")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("service", help="service name (see `omninav services`)")
    parser.add_argument("--module", help="run this package.module:Class instead of a registered service")
    parser.add_argument("--params", help="YAML parameter file (ROS 1 or ROS 2 layout accepted)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override one parameter")
    parser.add_argument("--robot", default="r1", help="robot namespace (default r1)")
    parser.add_argument("--name", help="instance name (default: the service name)")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--log-level", default="INFO")
    add_lockstep_argument(parser)


def add_lockstep_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--lockstep", nargs="?", const="", metavar="SERVICES",
                        help="step with the simulator (services/runtime/lockstep.py): no wall clock decides "
                             "anything; for the sim, the services (comma-separated) to wait for before its "
                             "first step (default $OMNINAV_LOCKSTEP, set by `up --lockstep`)")


def lockstep_of(args: argparse.Namespace) -> Lockstep | None:
    if args.lockstep is None:
        return None         # LiveRunner then follows $OMNINAV_LOCKSTEP
    return Lockstep(service_names(args.lockstep))


def main(args: argparse.Namespace) -> int:
    configure_logging(args.name or args.service, args.log_level)
    log = logging.getLogger("omninav.run")
    try:
        node = build_node(args.service, args.params, parse_overrides(args.set), args.robot, args.name,
                          args.module)
    except (UnknownService, ParamError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    # a service that talks to Zenoh itself (the recorder) provides run_live(router, stop_event)
    try:
        runner = LiveRunner(node, args.router, lockstep=lockstep_of(args))
    except ValueError as exc:       # a router endpoint off loopback, or not an endpoint at all
        log.error("%s", exc)
        return 2
    on_stop_signals(runner.stop)
    on_parent_exit(runner.stop)     # its `up` (or shell) gone: nobody is left to stop it
    log.info("started (robot %s)", args.robot)
    try:
        if hasattr(node, "run_live"):
            node.run_live(args.router, runner.stop_event)
        else:
            runner.run()
    except LoginRefused as exc:
        log.error("%s", exc)
        return 1
    log.info("stopped")
    return 0
