"""`omninav bench scenarios --kind K --count N [--seed S] [--drive D] [--json]`: N generated
worlds of one kind (seeds S … S+N−1), each driven as one lockstep mission from its start to its
goal with the stack `omninav navigate` composes (cli/navigate.py compose_for) — deterministic per
world, as fast as the CPU computes, on --workers processes.

Per world and overall: success (the goal reached — the navigator said so and the truth agrees —
and no contact of any kind), false arrivals (succeeded, but far from the goal), robot-fault and
mover-fault collisions and the seconds in contact, the closest the footprint came to a mover, the
sim time, the driven path against the first global plan, and when the robot first came within
1 m of the goal. `--real-time` drives each world again on the wall clock (experiments/realtime.py),
one at a time, and reports it beside the lockstep figure.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from ..cli.navigate import LOCALIZATIONS, compose_for, map_for
from ..services.chassis.kinematics import DRIVES
from ..services.local_planner.control import CONTROLLERS, DEFAULT_CONTROLLER
from ..services.runtime.errors import exits_2_on_user_error
from ..sim.world import load_world
from ..experiments.mission_score import false_success_runs
from ..experiments.lockstep_mission import run_mission
from ..experiments.realtime import run_live
from ..experiments.workers import run_in_workers
from ..experiments.scenarios import EXPLORE_KINDS, ScenarioError, check_kind, generate_world, world_text

REPO = Path(__file__).resolve().parents[1]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--kind", required=True, help="the kind of world (omninav scenario generate --kind)")
    parser.add_argument("--count", type=int, default=20, help="worlds to generate and drive (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="the first world's seed (default 0)")
    parser.add_argument("--drive", choices=DRIVES, help="the robot's drive (default: the world's, mecanum)")
    parser.add_argument("--localization", choices=LOCALIZATIONS, default="amcl",
                        help="amcl on the rasterised world (default, as navigate), slam, or truth")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S", help="sim s for the goal (default 120)")
    parser.add_argument("--workers", type=int, default=2, help="missions driven at once, one process each (default 2)")
    parser.add_argument("-o", "--out", help="folder for the worlds and maps (default out/scenarios-<kind>-<date>-<time>)")
    parser.add_argument("--record", action="store_true",
                        help="record each mission to run.mcap in its world's folder (to replay or read a failure)")
    parser.add_argument("--real-time", action="store_true",
                        help="also drive every world on the wall clock, every service its own process, one at a "
                             "time, and report it beside the lockstep figure")
    parser.add_argument("--controller", nargs="+", choices=CONTROLLERS, default=[DEFAULT_CONTROLLER],
                        help="the local planner's controller(s): each world is driven with each, reported side by "
                             "side (default dwa)")


def drive_world(job: tuple[str, int, str | None, str, float, str, bool, str]) -> dict:
    """One world: generate it, write it and its map, drive the mission with the controller (recorded
    when `record`); its row."""
    kind, seed, drive, localization, timeout_s, out, record, controller = job
    # a folder of its own per controller: the same world's missions run at once on two workers
    folder = Path(out) / (f"{kind}-{seed}" if controller == DEFAULT_CONTROLLER else f"{kind}-{seed}-{controller}")
    folder.mkdir(parents=True, exist_ok=True)
    world_file = folder / "world.yaml"
    world_file.write_text(world_text(generate_world(kind, seed)))
    world = load_world(world_file)
    drive = drive or world.robot.drive
    recording = folder / "run.mcap"
    compose = compose_for(world, world_file, map_for(world, world.name, folder), drive, localization,
                          recording, seed, 1.0, "r1", controller=controller)
    began = time.monotonic()
    run = run_mission(compose["services"], world, world.goals, timeout_s=timeout_s,
                      recording=recording if record else None)
    return scenario_row(world.name, seed, drive, controller, run.summary.to_json(), began)


def drive_world_live(job: tuple[str, int, str | None, str, float, str, bool, str]) -> dict:
    """The world drive_world wrote, on the wall clock (experiments/realtime.py), with the default controller."""
    kind, seed, drive, localization, timeout_s, out, _, _ = job
    folder = Path(out) / f"{kind}-{seed}"
    world_file = folder / "world.yaml"
    world = load_world(world_file)
    began = time.monotonic()
    run = run_live(world_file, world.goals, folder / "real-time", localization=localization, timeout_s=timeout_s,
                   seed=seed, drive=drive or world.robot.drive)
    return scenario_row(world.name, seed, drive or world.robot.drive, DEFAULT_CONTROLLER, run.summary or {}, began)


def scenario_row(name: str, seed: int, drive: str, controller: str, summary: dict, began: float) -> dict:
    goal = summary["goals"][0] if summary.get("goals") else {}
    return {"world": name, "seed": seed, "drive": drive, "controller": controller, **{k: summary.get(k) for k in (
        "collisions", "robot_fault_collisions", "mover_fault_collisions", "shoved_collisions",
        "min_mover_clearance_m", "min_clearance_m", "time_s", "path_length_m", "plan_length_m", "final_xy_error_m",
        "contact_s", "robot_contact_s", "false_successes")}, "success": bool(summary.get("success")),
        "status": goal.get("status", "none"), "reached": goal.get("reached", False), "within_1m_s": goal.get("within_1m_s"),
        "wall_s": round(time.monotonic() - began, 1)}


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _ratio(row: dict) -> float | None:
    return row["path_length_m"] / row["plan_length_m"] if row.get("plan_length_m") else None


HEADER = (f"{'world':14} {'ok':3} {'status':13} {'robot':>5} {'mover':>5} {'mover m':>7} {'time s':>7} "
          f"{'1 m s':>6} {'path m':>7} {'plan m':>7} {'ratio':>5}")


def row_line(r: dict) -> str:
    status = "FALSE SUCCESS" if r.get("false_successes") else r["status"]
    world = r["world"] if r["controller"] == DEFAULT_CONTROLLER else f"{r['world']} {r['controller']}"
    return (f"{world:14} {'yes' if r['success'] else 'NO':3} {status:13} "
            f"{_fmt(r['robot_fault_collisions'], 'd'):>5} {_fmt(r['mover_fault_collisions'], 'd'):>5} "
            f"{_fmt(r['min_mover_clearance_m'], '7.3f')} {r['time_s']:7.1f} {_fmt(r['within_1m_s'], '6.1f')} "
            f"{r['path_length_m']:7.2f} {_fmt(r['plan_length_m'], '7.2f')} {_fmt(_ratio(r), '5.2f')}")


def overall(rows: list[dict]) -> dict:
    ratios = [x for x in map(_ratio, rows) if x is not None]
    approaches = [r["min_mover_clearance_m"] for r in rows if r["min_mover_clearance_m"] is not None]
    return {"worlds": len(rows), "success_rate": sum(r["success"] for r in rows) / len(rows),
            "robot_fault_collisions": sum(r["robot_fault_collisions"] or 0 for r in rows),
            "mover_fault_collisions": sum(r["mover_fault_collisions"] or 0 for r in rows),
            "shoved_collisions": sum(r["shoved_collisions"] or 0 for r in rows),
            "contact_s": sum(r.get("contact_s") or 0.0 for r in rows),
            "worlds_with_robot_fault": sum(bool(r["robot_fault_collisions"]) for r in rows),
            "false_successes": len(false_success_runs(rows)), "false_success_worlds": false_success_runs(rows),
            "closest_mover_approach_m": min(approaches) if approaches else None,
            "median_time_s": statistics.median(r["time_s"] for r in rows),
            "median_path_over_plan": statistics.median(ratios) if ratios else None}


@exits_2_on_user_error("bench scenarios")
def main(args: argparse.Namespace) -> int:
    check_kind(args.kind)
    if args.kind in EXPLORE_KINDS:   # with no goal every mission would count as a success
        raise ScenarioError(f"{args.kind} worlds have no goal to drive to; they are for exploring: "
                            f"omninav bench explore --kind {args.kind}")
    if args.count < 1 or args.workers < 1 or args.seed < 0:
        raise ScenarioError(f"--count and --workers must be >= 1 and --seed >= 0, got {args.count}, "
                            f"{args.workers} and {args.seed}")
    out = Path(args.out or REPO / "out" / time.strftime(f"scenarios-{args.kind}-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    controllers = list(dict.fromkeys(args.controller))
    jobs = [(args.kind, seed, args.drive, args.localization, args.timeout, str(out), args.record, controller)
            for seed in range(args.seed, args.seed + args.count) for controller in controllers]
    if not args.json:
        print(f"{args.count} {args.kind} worlds, {args.localization} localization, controller "
              f"{' and '.join(controllers)}, {args.workers} workers; in {out}")
        print(HEADER, flush=True)
    rows = run_in_workers(drive_world, jobs, args.workers, None if args.json else lambda r: print(row_line(r), flush=True),
                          unit="worlds", quiet=args.json)
    by_controller = {c: overall([r for r in rows if r["controller"] == c]) for c in controllers}
    figures = {"kind": args.kind, "seeds": [args.seed, args.seed + args.count - 1], "drive": args.drive or "world's",
               "localization": args.localization, "controller": controllers[0], **by_controller[controllers[0]],
               "by_controller": by_controller, "rows": rows}
    if args.real_time:
        live = []
        for job in jobs:
            if job[-1] == DEFAULT_CONTROLLER:
                live.append(drive_world_live(job))
                if not args.json:
                    print("real time " + row_line(live[-1]), flush=True)
        figures["real_time"] = {**overall(live), "rows": live}
    if args.json:
        print(json.dumps(figures))
    else:
        lines = [(f"{c}: " if len(controllers) > 1 or args.real_time else "", f) for c, f in by_controller.items()]
        for how, f in lines + [("real time: ", figures.get("real_time"))]:
            if f is not None:
                print(how + summary_line(f))
    return 0 if all(f["success_rate"] == 1.0 for f in by_controller.values()) else 1


def summary_line(f: dict) -> str:
    return (f"success {f['success_rate']:.0%} ({round(f['success_rate'] * f['worlds'])}/{f['worlds']}, no contact of "
            f"any kind), contacts: {f['robot_fault_collisions']} the robot's fault (in {f['worlds_with_robot_fault']} "
            f"worlds), {f['mover_fault_collisions']} a mover's ({f['shoved_collisions']} of them the robot shoved "
            f"into a wall), {f['contact_s']:.2f} s in contact; closest to a mover "
            f"{_fmt(f['closest_mover_approach_m'], '.3f')} m; median {f['median_time_s']:.1f} sim s, "
            f"path/plan {_fmt(f['median_path_over_plan'], '.2f')}; false successes {f['false_successes']}"
            + (f" ({', '.join(f['false_success_worlds'])})" if f["false_successes"] else ""))
