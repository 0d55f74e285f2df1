"""`omninav view [--port 8765] [--allow-goals [--allow-origin ORIGIN ...]]`: the running stack in the
Foxglove app (the `view` service, run here).

Open the Foxglove app, "Open connection" → Foxglove WebSocket → ws://127.0.0.1:8765, and import
docs/foxglove/omninav_layout.json. The server listens on 127.0.0.1 only. Goals sent from the app
("Publish pose") are dropped unless --allow-goals; then the view prints a URL with this run's token,
and only a connection to that URL, from a program or an allowed browser origin, may send goals.
"""
from __future__ import annotations

import argparse
import json

from ..services.runtime import run

SERVICE = "view"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", type=int, default=8765, help="WebSocket port on 127.0.0.1 (default 8765; 0: any free)")
    parser.add_argument("--robot", default="r1", help="robot namespace (default r1)")
    parser.add_argument("--params", help="YAML parameter file of the view service (footprint, laser_mount, ...)")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--allow-goals", action="store_true",
                        help="forward goals from connections that present this run's token (printed) from an "
                             "allowed origin (default: off, no goal from a client reaches the bus)")
    parser.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                        help="a browser origin (http(s)://host[:port]) allowed besides https://app.foxglove.dev "
                             "and http://localhost, http://127.0.0.1 on any port; repeatable")
    parser.add_argument("--log-level", default="INFO")


def main(args: argparse.Namespace) -> int:
    # the same as `omninav run view --set port=…`: one way to build and run the service
    settings = [f"port={args.port}", f"allow_goals={json.dumps(args.allow_goals)}"]
    if args.allow_origin:
        settings.append(f"allow_origins={json.dumps(args.allow_origin)}")
    return run.main(argparse.Namespace(service=SERVICE, module=None, params=args.params, set=settings,
                                       robot=args.robot, name=None, router=args.router, log_level=args.log_level,
                                       lockstep=None))
