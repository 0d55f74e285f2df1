"""`omninav view [--port 8765]`: the running stack in the Foxglove app (the `view` service, run here).

Open the Foxglove app, "Open connection" → Foxglove WebSocket → ws://127.0.0.1:8765, and import
docs/foxglove/omninav_layout.json. The server listens on 127.0.0.1 only.
"""
from __future__ import annotations

import argparse

from ..services.runtime import run

SERVICE = "view"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", type=int, default=8765, help="WebSocket port on 127.0.0.1 (default 8765; 0: any free)")
    parser.add_argument("--robot", default="r1", help="robot namespace (default r1)")
    parser.add_argument("--params", help="YAML parameter file of the view service (footprint, laser_mount, ...)")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--log-level", default="INFO")


def main(args: argparse.Namespace) -> int:
    # the same as `omninav run view --set port=…`: one way to build and run the service
    return run.main(argparse.Namespace(service=SERVICE, module=None, params=args.params, set=[f"port={args.port}"],
                                       robot=args.robot, name=None, router=args.router, log_level=args.log_level,
                                       lockstep=None))
