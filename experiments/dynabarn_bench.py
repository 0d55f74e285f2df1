"""`omninav bench dynabarn`: DynaBARN worlds (experiments/scenarios/dynabarn.py) run by BARN's rules.

Each world is drawn from its seed at a difficulty, written to a folder (the services read it from
the file) and driven as `bench barn` drives a BARN world (experiments/barn.py `drive_to_goal`): one
lockstep mission in-process with the Jackal's stack, localization `odom`, no map. The rules, as
the BARN Challenge applies them to its dynamic worlds: start (11, 0, 180°), goal 20 m ahead at
(−9, 0); success = the robot's centre within 1 m of the goal within 100 s of when it starts moving
with no contact of any kind — every collision the simulator counts (sim/physics.py), the robot's
fault or a mover's alike (both are reported); score = success × OT / clip(t, 2·OT, 8·OT) with
OT = 10 s (20 m at the Jackal's 2 m/s). Seeds 0–99 of each difficulty are for tuning, 100100–100199
for reporting (docs/dynabarn.md).
"""
from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from ..cli.navigate import ODOMETRIES
from ..services.local_planner.control import CONTROLLERS, DEFAULT_CONTROLLER
from ..services.runtime.errors import exits_2_on_user_error
from ..sim.world import load_world
from .barn import Verdict, drive_to_goal, drive_to_goal_live, judge, tally
from .scenarios import ScenarioError, generate_world, world_text
from .scenarios.dynabarn import DIFFICULTIES
from .workers import run_in_workers

KIND = "dynabarn"
OT_S = 10.0        # s: DynaBARN's optimal time, the 20 m from start to goal at the Jackal's 2 m/s


@dataclass
class DynaBarnResult(Verdict):
    difficulty: str
    seed: int
    robot_fault_collisions: int
    mover_fault_collisions: int
    controller: str = DEFAULT_CONTROLLER


def run_seed(job: tuple[str, int, str, str, str]) -> DynaBarnResult:
    """One world (difficulty, seed, folder, controller, odometry): draw it, write it into the folder,
    drive it with the controller on that odometry (navigate's ODOMETRIES), judge it."""
    difficulty, seed, folder, controller, odometry = job
    # a file of its own per controller: the same world's runs go at once on two workers
    own = "" if controller == DEFAULT_CONTROLLER else f"-{controller}"
    world_file = Path(folder) / f"{KIND}-{difficulty}-{seed}{own}.yaml"
    world_file.write_text(world_text(generate_world(KIND, seed, difficulty)))
    world = load_world(world_file)
    watch, run = drive_to_goal(world, seed, world.robot.start, world.goals[0], controller, odometry)
    sim = run.nodes["sim"].sim
    verdict = judge(watch, sim.collisions > 0, OT_S, run.summary.false_successes > 0)
    return DynaBarnResult(**asdict(verdict), difficulty=difficulty, seed=seed,
                          robot_fault_collisions=sim.robot_fault_collisions,
                          mover_fault_collisions=sim.mover_fault_collisions, controller=controller)


def run_seed_live(difficulty: str, seed: int, folder: Path) -> DynaBarnResult:
    """The same world on the wall clock, every service its own process (experiments/realtime.py)."""
    world_file = folder / f"{KIND}-{difficulty}-{seed}.yaml"
    world_file.write_text(world_text(generate_world(KIND, seed, difficulty)))
    world = load_world(world_file)
    verdict, summary = drive_to_goal_live(world_file, seed, world.robot.start, world.goals[0], OT_S,
                                          folder / f"{KIND}-{difficulty}-{seed}-real-time")
    return DynaBarnResult(**asdict(verdict), difficulty=difficulty, seed=seed,
                          robot_fault_collisions=summary.get("robot_fault_collisions") or 0,
                          mover_fault_collisions=summary.get("mover_fault_collisions") or 0)


def figures(results: list[DynaBarnResult]) -> dict:
    """BARN's tally of the runs (experiments/barn.py) and the contacts split by fault."""
    return {**tally(results), "robot_fault_collisions": sum(r.robot_fault_collisions for r in results),
            "mover_fault_collisions": sum(r.mover_fault_collisions for r in results)}


def run_line(r: DynaBarnResult) -> str:
    time = "-" if r.time_s is None else f"{r.time_s:6.1f} s"
    controller = "" if r.controller == DEFAULT_CONTROLLER else f" {r.controller}"
    return (f"{KIND}-{r.difficulty}-{r.seed}{controller}: {'success' if r.success else 'FAIL   '} contacts "
            f"{r.robot_fault_collisions} robot's, {r.mover_fault_collisions} movers' timeout {r.timeout!s:5} "
            f"{'FALSE SUCCESS ' if r.false_success else ''}"
            f"time {time} score {r.score:.3f}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--difficulty", nargs="+", choices=DIFFICULTIES, default=list(DIFFICULTIES),
                        help="one or more of easy, medium, hard (default all three)")
    parser.add_argument("--count", type=int, default=20, help="worlds per difficulty (default 20)")
    parser.add_argument("--seed", type=int, default=0,
                        help="the first world's seed (default 0; 0-99 are for tuning, 100100-100199 for reporting)")
    parser.add_argument("--workers", type=int, default=2, help="missions driven at once, one process each (default 2)")
    parser.add_argument("-o", "--out", type=Path, help="keep the worlds in this folder (default: a temporary one)")
    parser.add_argument("--real-time", action="store_true",
                        help="also run every world on the wall clock, every service its own process, one world "
                             "at a time, and report it beside the lockstep figure")
    parser.add_argument("--odometry", choices=ODOMETRIES, default="auto",
                        help="navigate's --odometry for the lockstep runs (default auto: fused, there is no map)")
    parser.add_argument("--controller", nargs="+", choices=CONTROLLERS, default=[DEFAULT_CONTROLLER],
                        help="the local planner's controller(s): each world is driven with each, reported side by "
                             "side (default dwa; real time runs the default only)")


@exits_2_on_user_error("bench dynabarn")
def main(args: argparse.Namespace) -> int:
    if args.count < 1 or args.workers < 1 or args.seed < 0:
        raise ScenarioError(f"--count and --workers must be >= 1 and --seed >= 0, got {args.count}, "
                            f"{args.workers} and {args.seed}")
    if args.out is not None and not args.out.is_dir():
        raise ScenarioError(f"-o {args.out}: no such folder")
    difficulties = list(dict.fromkeys(args.difficulty))
    controllers = list(dict.fromkeys(args.controller))
    with tempfile.TemporaryDirectory(prefix="dynabarn-") as scratch:
        folder = str(args.out or scratch)
        jobs = [(d, seed, folder, c, args.odometry) for d in difficulties
                for seed in range(args.seed, args.seed + args.count) for c in controllers]
        results = run_in_workers(run_seed, jobs, args.workers, None if args.json else lambda r: print(run_line(r), flush=True),
                                 unit="worlds", quiet=args.json)
        live = []
        for difficulty, seed, _, controller, _ in jobs if args.real_time else ():
            if controller == DEFAULT_CONTROLLER:
                live.append(run_seed_live(difficulty, seed, Path(folder)))
                if not args.json:
                    print("real time " + run_line(live[-1]), flush=True)
    by_controller = {c: {d: figures([r for r in results if r.difficulty == d and r.controller == c])
                         for d in difficulties} for c in controllers}
    by_difficulty = by_controller[controllers[0]]
    live_by_difficulty = {d: figures([r for r in live if r.difficulty == d]) for d in difficulties} if live else None
    if args.json:
        print(json.dumps({"seeds": [args.seed, args.seed + args.count - 1], "ot_s": OT_S, "controller": controllers[0],
                          "odometry": args.odometry,
                          "difficulties": by_difficulty, "by_controller": by_controller,
                          "runs": [asdict(r) for r in results],
                          **({"real_time": {"difficulties": live_by_difficulty, "runs": [asdict(r) for r in live]}}
                             if live else {})}))
        return 0
    lines = [(f"{c:5} " if len(controllers) > 1 else "", tallies) for c, tallies in by_controller.items()]
    for how, tallies in [(("lockstep  " if live else "") + how, t) for how, t in lines] + [("real time ",
                                                                                            live_by_difficulty)]:
        for d, f in (tallies or {}).items():
            median = "-" if f["median_time_s"] is None else f"{f['median_time_s']:.1f} s"
            print(f"{how}{d:6}: {f['runs']} runs, success {f['success_rate']:.3f}, runs with a contact "
                  f"{f['collisions']} ({f['robot_fault_collisions']} contacts the robot's fault, "
                  f"{f['mover_fault_collisions']} a mover's), timeouts {f['timeouts']}, false successes "
                  f"{f['false_successes']}, mean score "
                  f"{f['mean_score']:.3f}, median time {median}")
    return 0
