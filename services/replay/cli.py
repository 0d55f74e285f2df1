"""`omninav replay FILE …`: live onto the bus (live.py), or `--into SERVICE` deterministically (into.py)."""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording")
    live = parser.add_argument_group("live replay onto the bus")
    live.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1.0)")
    live.add_argument("--loop", action="store_true", help="start over at the end")
    live.add_argument("--keys", nargs="+", metavar="KEY", help="only these keys (key expressions allowed)")
    live.add_argument("--start-offset", type=float, default=0.0, metavar="S", help="skip the first S seconds")
    live.add_argument("--clock", action="store_true", help="also publish the Clock from message stamps")
    live.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    live.add_argument("--credentials", metavar="FOLDER",
                      help="the identities folder of the `omninav up` run to replay into: each key is put "
                           "as the service that publishes it (the router's ACL allows nothing else)")
    into = parser.add_argument_group("deterministic replay into one service")
    into.add_argument("--into", metavar="SERVICE", help="drive this service's code in-process")
    into.add_argument("--params", help="parameter file for the service")
    into.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override one parameter")
    into.add_argument("--robot", default="r1", help="robot namespace (default r1)")
    into.add_argument("--name", help="the service instance name in the recording (default: the service)")
    into.add_argument("--out", help="write the service's outputs to this MCAP file")
    into.add_argument("--compare", action="store_true", help="compare outputs byte for byte with the recording")


def main(args: argparse.Namespace) -> int:
    if args.into:
        from .into import main_into
        return main_into(args)
    from .onto_bus import main_live
    return main_live(args)
