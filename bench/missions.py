"""`omninav bench missions`: navigation missions over the shipped worlds for each drive.

Each row is one mission driven in lockstep in one process (experiments/lockstep_mission.py, the
services and parameters of `omninav navigate`'s compose_for): deterministic, as fast as the CPU
computes, on --workers processes side by side. Goals are fixed per world, in free space away from
the start: through doors in the corridor and the office, along the aisles of the warehouse where
the forklift and two people move, across the real Willow Garage map, and through the crossing hall
where two people walk across the planned path without giving way.
A row reports the navigate summary (success, goals reached, collisions split into the robot's
fault and the movers', final errors against the ground truth, sim time, the true path length and
the first global plans' length, min clearance); the table adds the driven path over the planned
one. The aim: every mission succeeds — every goal reached with no contact of any kind.
`--real-time` drives each mission again on the wall clock (experiments/realtime.py), one at a
time, and reports it beside the lockstep figure.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from ..cli.navigate import LOCALIZATIONS, compose_for, map_for
from ..services.chassis.kinematics import DRIVES
from ..sim.node import open_world
from ..experiments.mission_score import false_success_runs
from ..experiments.lockstep_mission import run_mission
from ..experiments.realtime import run_live
from ..experiments.workers import run_in_workers

REPO = Path(__file__).resolve().parents[1]
# world -> goals (x m, y m, yaw degrees), visited in order from the world's start
MISSIONS: dict[str, tuple[tuple[float, float, float], ...]] = {
    "room": ((8.3, 3.5, 90.0), (3.0, 4.8, 180.0)),
    "corridor": ((10.0, 6.4, 90.0), (18.5, 4.0, 0.0)),
    "office": ((8.0, 8.3, 90.0), (11.5, 2.5, -90.0)),
    "warehouse": ((13.0, 4.25, 0.0), (18.5, 9.0, 90.0)),
    "willow": ((19.1, 28.6, 90.0),),
    "crossing": ((9.0, 3.0, 0.0),),     # two movers cross the straight way (the mecanum paper's dynamic test)
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--worlds", nargs="+", choices=sorted(MISSIONS), default=list(MISSIONS),
                        help="worlds to run (default: all)")
    parser.add_argument("--drives", nargs="+", choices=DRIVES, default=list(DRIVES), help="drives (default: all)")
    parser.add_argument("--localization", choices=LOCALIZATIONS, default="amcl", help="as navigate's (default amcl)")
    parser.add_argument("--timeout", type=float, default=180.0, metavar="S", help="sim s per goal (default 180)")
    parser.add_argument("--seed", type=int, default=0, help="of the simulator's noise and the filter (default 0)")
    parser.add_argument("--workers", type=int, default=2, help="missions driven at once, one process each (default 2)")
    parser.add_argument("--record", action="store_true", help="write each mission's recording into its folder")
    parser.add_argument("-o", "--out", help="folder for the runs (default out/missions-<date>-<time>)")
    parser.add_argument("--real-time", action="store_true",
                        help="also drive every mission on the wall clock, every service its own process, one at "
                             "a time, and report it beside the lockstep figure")


def drive_mission(job: tuple[str, str, argparse.Namespace, str]) -> dict:
    """One world and drive in lockstep: the navigate summary plus world, drive and wall time."""
    name, drive, args, out = job
    folder = Path(out) / f"{name}-{drive}"
    folder.mkdir(parents=True, exist_ok=True)
    world = open_world(name)
    recording = folder / "run.mcap"
    compose = compose_for(world, Path(world.source).resolve(), map_for(world, name, folder), drive,
                          args.localization, recording, args.seed, 1.0, "r1")
    goals = np.array([(x, y, math.radians(yaw)) for x, y, yaw in MISSIONS[name]])
    began = time.monotonic()
    run = run_mission(compose["services"], world, goals, timeout_s=args.timeout,
                      recording=recording if args.record else None)
    return {**run.summary.to_json(), "world": name, "drive": drive, "wall_s": round(time.monotonic() - began, 1)}


def drive_mission_live(name: str, drive: str, args: argparse.Namespace, out: str) -> dict:
    """The same mission on the wall clock (experiments/realtime.py): navigate's summary plus world,
    drive and wall time."""
    world = open_world(name)
    goals = np.array([(x, y, math.radians(yaw)) for x, y, yaw in MISSIONS[name]])
    began = time.monotonic()
    run = run_live(Path(world.source).resolve(), goals, Path(out) / f"{name}-{drive}-real-time",
                   localization=args.localization, timeout_s=args.timeout, seed=args.seed, drive=drive)
    return {**(run.summary or {"success": False}), "world": name, "drive": drive,
            "wall_s": round(time.monotonic() - began, 1)}


def tallies(rows: list[dict]) -> dict:
    robot_fault = sum(r.get("robot_fault_collisions") or 0 for r in rows)
    mover_fault = sum(r.get("mover_fault_collisions") or 0 for r in rows)
    return {"success_rate": sum(bool(r["success"]) for r in rows) / len(rows), "robot_fault_collisions": robot_fault,
            "mover_fault_collisions": mover_fault, "collisions": robot_fault + mover_fault,
            "contact_s": sum(r.get("contact_s") or 0.0 for r in rows),
            "false_successes": len(false_success_runs(rows)),
            "false_success_missions": [f"{r['world']}-{r['drive']}" for r in rows if r.get("false_successes")]}


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def table(rows: list[dict]) -> list[str]:
    lines = [f"{'world':10} {'drive':8} {'ok':3} {'goals':6} {'robot':>5} {'mover':>5} {'xy err m':>8} {'yaw err°':>8} "
             f"{'time s':>7} {'path m':>7} {'plan m':>7} {'path/plan':>9} {'clear m':>7}"]
    for r in rows:
        ratio = (r["path_length_m"] / r["plan_length_m"]) if r.get("plan_length_m") else None
        lines.append(f"{r['world']:10} {r['drive']:8} {'yes' if r['success'] else 'NO':3} "
                     f"{_fmt(r.get('goals_reached'), 'd')}/{_fmt(r.get('goals_total'), 'd'):4} "
                     f"{_fmt(r.get('robot_fault_collisions'), 'd'):>5} {_fmt(r.get('mover_fault_collisions'), 'd'):>5} "
                     f"{_fmt(r.get('final_xy_error_m'), '8.3f')} "
                     f"{_fmt(r.get('final_yaw_error_deg'), '8.2f')} {_fmt(r.get('time_s'), '7.1f')} "
                     f"{_fmt(r.get('path_length_m'), '7.2f')} {_fmt(r.get('plan_length_m'), '7.2f')} "
                     f"{_fmt(ratio, '9.2f')} {_fmt(r.get('min_clearance_m'), '7.3f')}")
    return lines


def main(args: argparse.Namespace) -> int:
    out = Path(args.out or REPO / "out" / time.strftime("missions-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if not args.json:
        print(table([])[0], flush=True)
    jobs = [(world, drive, args, str(out)) for world in args.worlds for drive in args.drives]
    rows = run_in_workers(drive_mission, jobs, args.workers,
                          None if args.json else lambda row: print(table([row])[-1], flush=True),
                          unit="missions", quiet=args.json)
    figures = {"rows": rows, **tallies(rows), "localization": args.localization}
    if args.real_time:
        if not args.json:
            print("real time:", flush=True)
        live = []
        for world, drive, _, _ in jobs:
            live.append(drive_mission_live(world, drive, args, str(out)))
            if not args.json:
                print(table([live[-1]])[-1], flush=True)
        figures["real_time"] = {"rows": live, **tallies(live)}
    if args.json:
        print(json.dumps(figures))
    for how, f in (("lockstep", figures), ("real time", figures.get("real_time"))):
        if f is not None and not args.json:
            print(f"{how}: success rate {f['success_rate']:.0%} (no contact of any kind), contacts "
                  f"{f['robot_fault_collisions']} the robot's fault, {f['mover_fault_collisions']} a mover's, "
                  f"{f['contact_s']:.2f} s in contact, false successes {f['false_successes']}"
                  f"{' (' + ', '.join(f['false_success_missions']) + ')' if f['false_successes'] else ''} "
                  f"({args.localization} localization; runs in {out})")
    return 0 if figures["success_rate"] == 1.0 else 1
