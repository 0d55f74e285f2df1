"""`omninav bench NAME [--json] [--save-results [DIR]]`: each benchmark prints medians against a reference measured in
the same run; `--save-results` keeps that JSON with its provenance as a results file (bench/results.py).
`omninav bench report [--check]` writes docs/measurements.md and the README's headline table from those files."""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

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
# not a benchmark: writes the record from the results files the others leave
REPORT = "report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=sorted([*BENCHES, REPORT]),
                        help=f"which benchmark ('{REPORT}': write docs/measurements.md and the README's table)")
    parser.add_argument("rest", nargs=argparse.REMAINDER, help="the benchmark's own options (--json, ...)")


def main(args: argparse.Namespace) -> int:
    if args.name == REPORT:
        from ..bench import measurements
        parser = argparse.ArgumentParser(prog=f"omninav bench {REPORT}", description=measurements.__doc__)
        measurements.add_arguments(parser)
        return int(measurements.main(parser.parse_args(args.rest)) or 0)
    from ..bench import results
    module = importlib.import_module(BENCHES[args.name])
    parser = argparse.ArgumentParser(prog=f"omninav bench {args.name}")
    parser.add_argument("--json", action="store_true", help="print one JSON object of the figures")
    parser.add_argument("--save-results", nargs="?", const=str(results.RESULTS_DIR), metavar="DIR",
                        help="also write that JSON with its provenance (commit, load, duration) "
                             "to a results file in DIR (default docs/results/); implies --json")
    module.add_arguments(parser)
    bench_args = parser.parse_args(args.rest)
    if bench_args.save_results is None:
        return int(module.main(bench_args) or 0)
    bench_args.json = True
    return results.run_recorded(args.name, args.rest, lambda: int(module.main(bench_args) or 0),
                                results_dir=Path(bench_args.save_results))


if __name__ == "__main__":
    sys.exit(main(argparse.Namespace(name=sys.argv[1], rest=sys.argv[2:])))
