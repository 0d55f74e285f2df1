"""`omninav bench cpu [--world room] [--json]`: where a mission's CPU goes, service by service.

The demo's room mission (AMCL, the services and parameters of `omninav navigate`'s compose_for, as
`bench footprint` runs it live) driven in lockstep in this process (experiments/lockstep_mission.py)
with a CpuMeter on the InProcessRunner: each service is charged the thread CPU time of its handlers
and ticks, the encoding of what it publishes included; the runner's delivery (decoding, merging),
the recording (MCAP writes) and the mission's scoring are rows of their own. Figures are
milliseconds of CPU per second of sim time (1000 would be one core at 1× real time) and calls per
sim second; the reference, measured in the same run, is the process's whole CPU time over the same
stretch (numba's and the allocator's threads included), of which the rows are the main thread's.
What a live run adds to this — Zenoh, threads waking for messages, the recorder's session — is
what `bench footprint` measures from outside (docs/navigate.md, CPU per service).
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ..cli.navigate import compose_for, map_for
from ..experiments.lockstep_mission import run_mission
from ..services.runtime.inprocess import CpuMeter
from ..sim.node import open_world
from .missions import MISSIONS

RUNNER = "runner (releasing, stepping)"     # the InProcessRunner's own loop and the merges' releases


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", choices=sorted(MISSIONS), default="room", help="the mission (default room)")
    parser.add_argument("--seed", type=int, default=0, help="of the simulator's noise and the filter (default 0)")
    parser.add_argument("--timeout", type=float, default=180.0, metavar="S", help="sim s per goal (default 180)")


def measure(world_name: str, seed: int, timeout_s: float) -> dict:
    """The mission's rows {name: (ms per sim s, calls per sim s)}, the whole process's ms per sim s, sim s."""
    world = open_world(world_name)
    goals = np.array([(x, y, math.radians(yaw)) for x, y, yaw in MISSIONS[world_name]])
    with tempfile.TemporaryDirectory(prefix="omninav-bench-cpu-") as tmp:
        folder = Path(tmp)
        recording = folder / "run.mcap"
        compose = compose_for(world, Path(world.source).resolve(), map_for(world, world_name, folder),
                              world.robot.drive, "amcl", recording, seed, 1.0, "r1")
        meter = CpuMeter(RUNNER)
        run = run_mission(compose["services"], world, goals, timeout_s=timeout_s, recording=recording, meter=meter)
        process_ms = (time.process_time_ns() - meter.process_started_ns) / 1e6
    sim_s = run.sim_s
    rows = {name: (ns / 1e6 / sim_s, meter.calls[name] / sim_s) for name, ns in meter.ns.most_common()}
    return {"world": world_name, "success": run.summary.success, "sim_s": round(sim_s, 2), "rows": rows,
            "metered_ms_per_sim_s": sum(ms for ms, _ in rows.values()),
            "process_ms_per_sim_s": process_ms / sim_s}


def main(args: argparse.Namespace) -> int:
    result = measure(args.world, args.seed, args.timeout)
    if args.json:
        print(json.dumps(result))
        return 0 if result["success"] else 1
    print(f"{args.world} mission in lockstep in one process: {result['sim_s']:.1f} sim s, "
          f"{'succeeded' if result['success'] else 'FAILED'}")
    print(f"{'what':32} {'ms CPU / sim s':>14} {'calls / sim s':>13} {'µs / call':>9}")
    for name, (ms, calls) in result["rows"].items():
        per_call = f"{ms * 1e3 / calls:9.0f}" if calls else f"{'-':>9}"
        print(f"{name:32} {ms:14.1f} {calls:13.1f} {per_call}")
    print(f"{'sum (this thread)':32} {result['metered_ms_per_sim_s']:14.1f}")
    print(f"{'the whole process (reference)':32} {result['process_ms_per_sim_s']:14.1f}")
    return 0 if result["success"] else 1

