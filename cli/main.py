"""The `omninav` command. Each subcommand lives in its own module and is imported only when used."""
from __future__ import annotations

import argparse
import faulthandler
import importlib
import os
import signal
import sys

from ..services.runtime.stop_signals import interrupt_on_stop_signals

# name -> (module with add_arguments(parser) and main(args) -> int, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("omninav.services.runtime.run", "run one service as a process on the bus"),
    "container": ("omninav.services.runtime.container", "run several services of a compose file in one process"),
    "router": ("omninav.cli.router", "run a Zenoh router on loopback"),
    "services": ("omninav.cli.services", "list the services that can be run"),
    "warm": ("omninav.cli.warm", "compile the services' numba kernels into the cache (make venv runs it)"),
    "up": ("omninav.services.runtime.launcher", "start a compose file: router + services as processes"),
    "record": ("omninav.services.recorder.cli", "record messages on the bus to MCAP"),
    "recover": ("omninav.services.recorder.recover", "rewrite a damaged MCAP file with what is readable"),
    "replay": ("omninav.services.replay.cli", "replay a recording live, or deterministically into a service"),
    "topics": ("omninav.cli.introspect", "list keys on the bus with their types and rates"),
    "echo": ("omninav.cli.introspect", "print decoded messages from a key"),
    "hz": ("omninav.cli.introspect", "measure the rate of a key"),
    "get": ("omninav.cli.introspect", "query a queryable and print the reply"),
    "teleop": ("omninav.cli.teleop", "drive the robot from the keyboard"),
    "report": ("omninav.cli.report", "draw a picture of a recording"),
    "view": ("omninav.cli.view", "show the running stack in the Foxglove app, or with --rerun in a browser (servers on 127.0.0.1)"),
    "map": ("omninav.cli.map", "save the map served on the bus, or draw a map file"),
    "export": ("omninav.cli.export", "write a recording in Foxglove's well-known schemas (--foxglove) or as a Rerun file (--rerun)"),
    "import": ("omninav.cli.importers", "convert CARMEN logs or ROS bags into MCAP recordings"),
    "localize-eval": ("omninav.experiments.localize_eval", "score AMCL in the simulator against the ground truth"),
    "slam-eval": ("omninav.experiments.slam_eval", "run SLAM on a CARMEN log and score it with the relations metric"),
    "navigate": ("omninav.cli.navigate", "drive a navigation mission in the simulator and score it"),
    "scenario": ("omninav.experiments.scenarios.cli", "generate worlds of a kind from a seed (crossing, crowd, ...)"),
    "bench": ("omninav.cli.bench", "benchmarks (transport, recorder, sim, amcl, planner, ...)"),
    "bridge": ("omninav.cli.bridge", "drive a ROS 2 robot (rmw_zenoh): the navigation stack and the ros2_bridge"),
    "demo": ("omninav.cli.demo", "the main job: a short run of the stack, recorded and replayed"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="omninav", description="omninav: navigation for wheeled robots over Zenoh")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    if argv is None:        # the program itself (not a caller in-process, nor a service `up` forked)
        interrupt_on_stop_signals()
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        build_parser().parse_args(argv or ["--help"])
        return 2
    name, rest = argv[0], argv[1:]
    module = importlib.import_module(COMMANDS[name][0])
    parser = argparse.ArgumentParser(prog=f"omninav {name}", description=COMMANDS[name][1])
    add = getattr(module, f"add_{name}_arguments", None) or module.add_arguments
    add(parser)
    args = parser.parse_args(rest)
    run = getattr(module, f"main_{name}", None) or module.main
    # `kill -USR1 PID` prints where every thread of any omninav command is, e.g. one that does not stop;
    # to the process's own stderr (fd 2), not sys.stderr, which a caller in-process may have replaced
    if sys.__stderr__ is not None:
        faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)
    try:
        return int(run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:     # `omninav echo … | head`: the reader has what it wanted
        sys.stdout = open(os.devnull, "w")
        return 0


if __name__ == "__main__":
    sys.exit(main())
