"""`omninav view [--port 8765] [--allow-goals [--allow-origin ORIGIN ...]]`: the running stack in the
Foxglove app (the `view` service, run here).
`omninav view --rerun [--port 9090] [--grpc-port 9876]`: the running stack in a browser, in Rerun's
web viewer served from here (the `rerun_view` service); it prints the URL to open.

Foxglove: open the Foxglove app, "Open connection" → Foxglove WebSocket → ws://127.0.0.1:8765, and
import docs/foxglove/omninav_layout.json. The servers listen on 127.0.0.1 only. Goals sent from the
app ("Publish pose") are dropped unless --allow-goals; then the view prints a URL with this run's
token, and only a connection to that URL, from a program or an allowed browser origin, may send
goals. The Rerun view only shows: nothing a browser does reaches the bus.
"""
from __future__ import annotations

import argparse
import importlib.util
import json

from ..services.runtime import run

FOXGLOVE_SERVICE, RERUN_SERVICE = "view", "rerun_view"
FOXGLOVE_PORT, RERUN_PORT, RERUN_GRPC_PORT = 8765, 9090, 9876


def rerun_missing(command: str) -> str | None:
    """What to do when rerun-sdk (the `rerun` extra, not a dependency: about 650 MB) is not installed."""
    if importlib.util.find_spec("rerun") is None:
        return f"{command} --rerun needs rerun-sdk: pip install -e '.[rerun]' (make venv installs it)"
    return None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rerun", action="store_true",
                        help="serve Rerun's web viewer for a browser instead of the Foxglove WebSocket server")
    parser.add_argument("--port", type=int,
                        help=f"port on 127.0.0.1: the WebSocket (default {FOXGLOVE_PORT}) or with --rerun the "
                             f"viewer page (default {RERUN_PORT}); 0: any free")
    parser.add_argument("--grpc-port", type=int, default=RERUN_GRPC_PORT,
                        help=f"with --rerun: the port of the proxy the page reads from (default {RERUN_GRPC_PORT}; "
                             "0: any free)")
    parser.add_argument("--robot", default="r1", help="robot namespace (default r1)")
    parser.add_argument("--params", help="YAML parameter file of the view service (footprint, laser_mount, ...)")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--allow-goals", action="store_true",
                        help="forward goals from connections that present this run's token (printed) from an "
                             "allowed origin (default: off, no goal from a client reaches the bus; Foxglove only)")
    parser.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                        help="a browser origin (http(s)://host[:port]) allowed besides https://app.foxglove.dev "
                             "and http://localhost, http://127.0.0.1 on any port; repeatable")
    parser.add_argument("--log-level", default="INFO")


def main(args: argparse.Namespace) -> int:
    # the same as `omninav run view --set …` (or rerun_view): one way to build and run the service
    if args.rerun:
        if args.allow_goals or args.allow_origin:
            raise SystemExit("view: --allow-goals and --allow-origin are the Foxglove view's; the Rerun view only shows")
        if missing := rerun_missing("view"):
            raise SystemExit(missing)
        service = RERUN_SERVICE
        settings = [f"port={RERUN_PORT if args.port is None else args.port}", f"grpc_port={args.grpc_port}"]
    else:
        service = FOXGLOVE_SERVICE
        settings = [f"port={FOXGLOVE_PORT if args.port is None else args.port}",
                    f"allow_goals={json.dumps(args.allow_goals)}"]
        if args.allow_origin:
            settings.append(f"allow_origins={json.dumps(args.allow_origin)}")
    return run.main(argparse.Namespace(service=service, module=None, params=args.params, set=settings,
                                       robot=args.robot, name=None, router=args.router, log_level=args.log_level,
                                       lockstep=None))
