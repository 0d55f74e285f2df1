"""`omninav bench NAME [--json]`: each benchmark prints medians against a reference measured in the same run."""
from __future__ import annotations

import argparse
import importlib
import sys

# name -> module with add_arguments(parser) and main(args) -> int
BENCHES: dict[str, str] = {
    "transport": "omninav.bench.transport",
    "recorder": "omninav.bench.recorder",
    "sim": "omninav.bench.sim",
    "amcl": "omninav.bench.amcl",
    "planner": "omninav.bench.planner",
    "local": "omninav.bench.local_planner",
    "fuzz": "omninav.experiments.fuzz",
    "missions": "omninav.bench.missions",
    "paper": "omninav.bench.paper",
    "scenarios": "omninav.bench.scenarios",
    "buildings": "omninav.bench.buildings",
    "regress": "omninav.bench.regress",
    "barn": "omninav.experiments.barn",
    "dynabarn": "omninav.experiments.dynabarn_bench",
    "explore": "omninav.bench.explore",
    "kills": "omninav.experiments.kills",
    "footprint": "omninav.bench.process_footprint",
    "cpu": "omninav.bench.service_cpu",
    "lockstep": "omninav.bench.determinism",
    "people": "omninav.bench.people",
    "shove": "omninav.bench.shove",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=sorted(BENCHES), help="which benchmark")
    parser.add_argument("rest", nargs=argparse.REMAINDER, help="the benchmark's own options (--json, ...)")


def main(args: argparse.Namespace) -> int:
    module = importlib.import_module(BENCHES[args.name])
    parser = argparse.ArgumentParser(prog=f"omninav bench {args.name}")
    parser.add_argument("--json", action="store_true", help="print one JSON object of the figures")
    module.add_arguments(parser)
    return int(module.main(parser.parse_args(args.rest)) or 0)


if __name__ == "__main__":
    sys.exit(main(argparse.Namespace(name=sys.argv[1], rest=sys.argv[2:])))
