"""`omninav router`: a Zenoh router on loopback, for running services by hand."""
from __future__ import annotations

import argparse

from ..services.runtime.joining import forget
from ..services.runtime.zenoh_config import open_router, router_endpoint
from ..services.runtime.stop_signals import stop_event


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", help="endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")


def main(args: argparse.Namespace) -> int:
    stop = stop_event()
    endpoint = router_endpoint(args.listen)
    with open_router(endpoint):
        forget(endpoint)    # a killed run's entry: this router, without logins, holds the endpoint now
        print(f"router listening on {endpoint}", flush=True)
        stop.wait()
    return 0
