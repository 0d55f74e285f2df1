"""`omninav record [-o FILE] [KEYEXPR…]`: the recorder service in the foreground; Ctrl-C finishes the file."""
from __future__ import annotations

import argparse
import logging

from ...schemas.keys import ALL
from ...parameters.declare import ParamError
from ...parameters.from_mapping import load_params
from ..runtime.joining import LoginRefused
from ..runtime.run import configure_logging
from ..runtime.zenoh_config import router_endpoint
from .node import RecorderNode, RecorderParams
from ..runtime.stop_signals import on_parent_exit, stop_event


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("keys", nargs="*", metavar="KEYEXPR", help=f"Zenoh key expressions (default {ALL})")
    parser.add_argument("-o", "--output", help="MCAP file (default recordings/omninav-<date>-<time>.mcap)")
    parser.add_argument("--split-size", type=float, default=0.0, metavar="MB",
                        help="start a new numbered file (NAME_000.mcap, NAME_001.mcap, ...) past this size")
    parser.add_argument("--split-duration", type=float, default=0.0, metavar="S",
                        help="start a new numbered file every S seconds")
    parser.add_argument("--flush-period", type=float, default=RecorderParams.flush_period_s, metavar="S",
                        help="write buffered messages to disk this often; a crash loses at most this much "
                             f"(default {RecorderParams.flush_period_s})")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--log-level", default="INFO")


def main(args: argparse.Namespace) -> int:
    configure_logging("record", args.log_level)
    values = {"split_size_mb": args.split_size, "split_duration_s": args.split_duration,
              "flush_period_s": args.flush_period}
    if args.keys:
        values["keys"] = list(args.keys)
    if args.output:
        values["output"] = args.output
    try:
        router = router_endpoint(args.router)
        node = RecorderNode(load_params(RecorderParams, values, "omninav record"))
    except (ParamError, ValueError) as exc:
        logging.getLogger("omninav.record").error("%s", exc)
        return 2
    stop = stop_event()
    on_parent_exit(stop.set)        # its starter gone: the recording is closed, not left open
    try:
        node.run_live(router, stop)
    except LoginRefused as exc:
        logging.getLogger("omninav.record").error("%s", exc)
        return 1
    return 1 if node.failed else 0
