"""`omninav bench lockstep [--runs 3] [--burn] [--json]`: a mission in lockstep, as processes and in one.

The room mission of the demo's first goal (AMCL, seed 0) driven `--runs` times each way:
`navigate --lockstep` (every service its own process, stepped with the simulator), optionally with a
CPU burner per core beside it (`--burn`), and `navigate --in-process` as the reference (the same
services in one process). Per way: the median wall time of the whole command (start-up included)
and of the mission's sim time, and whether every run gave the same messages on every key
(diagnostics aside) as the first in-process run.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..schemas.keys import KeyLayout
from ..services.recorder.mcap_io import read_records

REPO = Path(__file__).resolve().parents[1]
GOAL = ("3.2", "0.9", "30")
RUN_TIMEOUT_S = 1800
CLOCK_KEY = KeyLayout.sim("clock")


def add_arguments(parser) -> None:
    parser.add_argument("--runs", type=int, default=3, help="runs of each way (default 3)")
    parser.add_argument("--burn", action="store_true",
                        help="also run the lockstep processes beside one busy process per core")
    parser.add_argument("-o", "--out", help="keep the runs here (default: a temporary folder)")


def messages_by_key(recording: Path) -> dict[str, list[bytes]]:
    """Every message but the diagnostics (they count wall-time events), per key in seq order, before
    the run's last step: the stop may come while the services still work on that step's messages
    (what they held for a later step is dropped at the stop: services/runtime/live.py)."""
    last_step = max(rec.stamp_ns for rec in read_records(recording, [CLOCK_KEY]))
    by_key: dict[str, list[tuple[int, bytes]]] = {}
    for rec in read_records(recording):
        if "/diagnostics/" not in rec.key and rec.stamp_ns < last_step:
            by_key.setdefault(rec.key, []).append((rec.seq, rec.payload))
    return {key: [payload for _, payload in sorted(items)] for key, items in by_key.items()}


def one_run(how: str, folder: Path) -> dict:
    cmd = [sys.executable, "-m", "omninav.cli.main", "navigate", "--world", "room", "--goal", *GOAL,
           "--lockstep" if how != "in-process" else "--in-process", "-o", str(folder), "--json", "--quiet"]
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
               for _ in range(os.cpu_count() or 2)] if how == "burned" else []
    began = time.monotonic()
    try:
        done = subprocess.run(cmd, cwd=REPO, capture_output=True, timeout=RUN_TIMEOUT_S)
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    wall = time.monotonic() - began
    if done.returncode not in (0, 1):
        raise SystemExit(f"omninav bench lockstep: {' '.join(cmd[3:])} failed (exit {done.returncode}): "
                         f"{done.stderr.decode(errors='replace')[-500:]}")
    summary = json.loads(done.stdout.decode().strip().splitlines()[-1])
    return {"wall_s": wall, "sim_s": summary["time_s"], "success": summary["success"]}


def main(args) -> int:
    if args.runs < 1:
        raise SystemExit("omninav bench lockstep: --runs must be ≥ 1")
    ways = ["in-process", "processes", *(["burned"] if args.burn else [])]
    with tempfile.TemporaryDirectory(prefix="omninav-bench-lockstep-") as scratch:
        out = Path(args.out or scratch)
        results: dict[str, dict] = {}
        reference = None
        for how in ways:
            runs, same = [], 0
            for k in range(args.runs):
                folder = out / f"{how}-{k}"
                runs.append(one_run(how, folder))
                messages = messages_by_key(folder / "run.mcap")
                reference = reference if reference is not None else messages
                same += messages == reference
                if not args.json:
                    print(f"{how} run {k}: {runs[-1]['wall_s']:.1f} wall s, "
                          f"{'the same messages' if messages == reference else 'DIFFERENT messages'}", flush=True)
            results[how] = {"median_wall_s": round(statistics.median(r["wall_s"] for r in runs), 1),
                            "sim_s": runs[0]["sim_s"], "succeeded": sum(r["success"] for r in runs),
                            "runs": len(runs), "same_messages_as_reference": same}
    if args.json:
        print(json.dumps({"ways": results, "goal": list(map(float, GOAL))}))
    else:
        print(f"{'way':<12} {'median wall s':>13} {'sim s':>6} {'succeeded':>9} {'same messages':>13}")
        for how, r in results.items():
            print(f"{how:<12} {r['median_wall_s']:>13.1f} {r['sim_s']:>6.1f} {r['succeeded']:>6}/{r['runs']:<2} "
                  f"{r['same_messages_as_reference']:>10}/{r['runs']}")
        print("reference: in-process (the same services in one process, stepped by the InProcessRunner)")
    return 0 if all(r["same_messages_as_reference"] == r["runs"] for r in results.values()) else 1
