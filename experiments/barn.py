"""`omninav bench barn`: the BARN Challenge's worlds run as the challenge runs them.

Each world (sim/barn_world.py reads its `.world` file) is one mission in lockstep, in-process
(experiments/lockstep_mission.py) with the services `compose_for` defines for the Jackal profile
and no prior map (localization `odom`: the costmaps come from the robot's own scans, map→odom
stays the start pose, as BARN's move_base baseline works in the odom frame). The rules
(../shared/data/barn/README.md): success = the robot's centre within 1 m of the goal within
100 s of when it starts moving, without touching an obstacle; score = success × OT /
clip(t, 2·OT, 8·OT), t from the moment the robot starts moving, OT = the reference path's length
(start → path_files/path_N.npy → goal) / 2 m/s. The run ends once the robot is within 1 m: the
challenge judges arrival there, the navigator need not stop.

Worlds run in worker processes (--workers), each world on its own and seeded alike, so a world's
result does not depend on which worker ran it or in which order.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import re
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..cli.navigate import ODOMETRIES, compose_for
from ..cli.profile import load_profile
from ..schemas.codec import decode
from ..schemas.keys import KeyLayout, type_for_key
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..sim.barn_world import GOAL, START
from ..sim.world import World, load_world, shared_data_dir
from ..services.recorder.mcap_io import read_records
from .lockstep_mission import START_S, LockstepRun, run_mission
from .progress import progress
from .realtime import run_live

REPO = Path(__file__).resolve().parents[1]
CELL = 0.15                    # m, BARN's lattice
CELL_OFFSET = (-0.075 - 4.5, 0.075 + 5.0)   # m: cell (x, y) is at (x·CELL + offset x, y·CELL + offset y)
TOP_SPEED = 2.0                # m/s: OT = reference length / TOP_SPEED
SUCCESS_RADIUS = 1.0           # m from the goal
TIME_LIMIT_S = 100.0           # s from the moment the robot starts moving
MOVING_M = 0.01                # m from the start: the robot has started moving
START_WAIT_S = 10.0            # sim s a robot may stand before it starts moving (then it times out)
PROFILE = "jackal"
SIM_DT = 0.02                  # s: the physics step; half the default's steps, 4 cm apart at 2 m/s
ROBOT = "r1"
# the challenge's published baseline (README): move_base with DWA, 50 worlds × 10 runs
REFERENCE = {"name": "move_base DWA (published)", "success_rate": 0.88, "collision_rate": 0.048,
             "timeout_rate": 0.072, "mean_score": 0.169}


class BarnError(UserError):
    """Bad input to the BARN benchmark (a missing folder, a range with no worlds): one line."""


# ---------------------------------------------------------------- the challenge's score

def reference_length(path_cells: np.ndarray) -> float:
    """Length (m) of start → the reference path (lattice cells (x, y)) → goal, as the challenge
    measures it."""
    cells = np.asarray(path_cells, np.float64).reshape(-1, 2)
    points = np.vstack([START[:2], cells * CELL + np.array(CELL_OFFSET), GOAL[:2]])
    return float(np.hypot(*np.diff(points, axis=0).T).sum())


def optimal_time(path_cells: np.ndarray) -> float:
    """OT (s): the reference path's length at the Jackal's top speed."""
    return reference_length(path_cells) / TOP_SPEED


def barn_score(success: bool, time_s: float, ot_s: float) -> float:
    """success × OT / clip(t, 2·OT, 8·OT)."""
    return float(success) * ot_s / min(max(time_s, 2.0 * ot_s), 8.0 * ot_s)


# ---------------------------------------------------------------- one world

class ArrivalWatch:
    """Follows the ground truth of a run: when the robot first moved, when it first came within
    SUCCESS_RADIUS of the goal."""

    def __init__(self, start, goal, robot: str):
        self.start, self.goal = np.asarray(start[:2], float), np.asarray(goal[:2], float)
        self.truth_key = KeyLayout(robot).sim_robot("truth")
        self.moved_s: float | None = None
        self.arrived_s: float | None = None
        self.now_s = 0.0

    def see(self, key: str, payload: bytes, stamp_ns: int) -> None:
        if key != self.truth_key or self.arrived_s is not None:
            return
        msg = decode(payload, type_for_key(key), key=key)
        xy, now_s = np.array([msg.pose.x, msg.pose.y]), stamp_ns * 1e-9
        self.now_s = now_s
        if self.moved_s is None and np.hypot(*(xy - self.start)) > MOVING_M:
            self.moved_s = now_s
        if np.hypot(*(xy - self.goal)) <= SUCCESS_RADIUS:
            self.arrived_s = now_s

    @property
    def arrived(self) -> bool:
        return self.arrived_s is not None

    @property
    def done(self) -> bool:
        """Arrived, or out of time since the robot started moving."""
        return self.arrived or (self.moved_s is not None and self.now_s - self.moved_s > TIME_LIMIT_S)


@dataclass
class Verdict:
    """A run judged by the challenge's rules."""
    success: bool
    collision: bool
    timeout: bool
    false_success: bool        # the navigator said the goal succeeded where the truth had not reached it
    time_s: float | None       # from starting to move to within 1 m of the goal (None: never)
    ot_s: float
    score: float


def judge(watch: ArrivalWatch, collision: bool, ot_s: float, false_success: bool) -> Verdict:
    """Success: within SUCCESS_RADIUS of the goal within TIME_LIMIT_S of starting to move, no
    collision, and no goal said succeeded that the truth had not reached (issue 36)."""
    time_s = None if not watch.arrived else watch.arrived_s - (watch.moved_s or START_S)
    in_time = time_s is not None and time_s <= TIME_LIMIT_S
    success = in_time and not collision and not false_success
    return Verdict(success=success, collision=collision, timeout=not in_time and not collision,
                   false_success=false_success, time_s=time_s, ot_s=ot_s,
                   score=barn_score(success, time_s or 0.0, ot_s))


@dataclass
class WorldResult(Verdict):
    world: int


def barn_mission(world: World, seed: int, controller: str | None = None, odometry: str = "auto") -> list[dict]:
    """The services of a BARN run: the Jackal, no map, goal from the rules; `controller` the local
    planner's (default its own), `odometry` navigate's ODOMETRIES."""
    profile = load_profile(PROFILE)
    world_file = Path(world.source).resolve()
    return compose_for(world, world_file, None, profile.drive, "odom", None, seed, 1.0, ROBOT, profile,
                       sim_dt=SIM_DT, controller=controller, odometry=odometry)["services"]


def drive_to_goal(world: World, seed: int, start, goal, controller: str | None = None,
                  odometry: str = "auto") -> tuple[ArrivalWatch, LockstepRun]:
    """One run as the challenge runs it: the Jackal's stack driven in lockstep from start to goal,
    ended once the robot is within SUCCESS_RADIUS of the goal or out of time; the watch knows when
    it moved and when it arrived."""
    watch = ArrivalWatch(start, goal, ROBOT)
    run = run_mission(barn_mission(world, seed, controller, odometry), world, np.array([goal]),
                      timeout_s=TIME_LIMIT_S + START_WAIT_S,
                      robot=ROBOT, max_sim_s=START_S + TIME_LIMIT_S + START_WAIT_S, watch=watch.see,
                      until=lambda: watch.done)
    return watch, run


def run_world(world_file: Path, path_file: Path, seed: int, odometry: str = "auto") -> WorldResult:
    """One BARN run in lockstep, in this process."""
    world = load_world(world_file)
    watch, run = drive_to_goal(world, seed, START, GOAL, odometry=odometry)
    collision = bool(run.summary.collisions) or run.summary.min_clearance_m <= 0.0
    verdict = judge(watch, collision, optimal_time(np.load(path_file)), run.summary.false_successes > 0)
    return WorldResult(world=world_number(world_file), **asdict(verdict))


def run_world_live(world_file: Path, path_file: Path, seed: int, out: Path) -> WorldResult:
    """One BARN run on the wall clock, every service its own process (experiments/realtime.py)."""
    verdict, _ = drive_to_goal_live(world_file, seed, START, GOAL, optimal_time(np.load(path_file)), out)
    return WorldResult(world=world_number(world_file), **asdict(verdict))


def drive_to_goal_live(world_file: Path, seed: int, start, goal, ot_s: float, out: Path) -> tuple[Verdict, dict]:
    """drive_to_goal on the wall clock (experiments/realtime.py), judged by the same rules from the
    recorded truth; the verdict and navigate's summary."""
    run = run_live(world_file, np.array([goal]), out, profile=PROFILE, localization="odom",
                   timeout_s=TIME_LIMIT_S + START_WAIT_S, seed=seed, sim_dt=SIM_DT)
    watch = ArrivalWatch(start, goal, ROBOT)
    for record in read_records(run.recording, [watch.truth_key]):
        watch.see(record.key, record.payload, record.stamp_ns)
    summary = run.summary or {}
    collision = summary.get("collisions") != 0 or summary.get("min_clearance_m", 0.0) <= 0.0
    return judge(watch, collision, ot_s, bool(summary.get("false_successes"))), summary


def world_number(path: Path) -> int:
    match = re.fullmatch(r"world_(\d+)", path.stem)
    if match is None:
        raise BarnError(f"{path}: not a BARN world file name (world_N.world)")
    return int(match.group(1))


# ---------------------------------------------------------------- many worlds

def _run_one(job: tuple[str, str, int, str]) -> WorldResult:
    world_file, path_file, seed, odometry = job
    return run_world(Path(world_file), Path(path_file), seed, odometry)


def parse_range(text: str) -> range:
    match = re.fullmatch(r"(\d+)-(\d+)", text)
    if match is None or int(match.group(1)) > int(match.group(2)):
        raise BarnError(f"--range {text!r}: expected FIRST-LAST, e.g. 0-149")
    return range(int(match.group(1)), int(match.group(2)) + 1)


def jobs_for(worlds_dir: Path, numbers: list[int], runs: int, first_seed: int = 0) -> list[tuple[str, str, int]]:
    """(world file, path file, seed) per run, seeds first_seed.. first_seed + runs - 1; BarnError
    naming a missing file."""
    paths_dir = worlds_dir.parent / "path_files"
    jobs = []
    for n in numbers:
        world_file, path_file = worlds_dir / f"world_{n}.world", paths_dir / f"path_{n}.npy"
        for needed in (world_file, path_file):
            if not needed.is_file():
                raise BarnError(f"{needed}: no such file (BARN worlds in {worlds_dir}, paths in {paths_dir})")
        jobs += [(str(world_file), str(path_file), seed) for seed in range(first_seed, first_seed + runs)]
    return jobs


def tally(results: list[WorldResult]) -> dict:
    count = len(results)
    if not count:
        return {"runs": 0}
    times = [r.time_s for r in results if r.success]
    return {"runs": count, "success_rate": sum(r.success for r in results) / count,
            "collision_rate": sum(r.collision for r in results) / count,
            "timeout_rate": sum(r.timeout for r in results) / count,
            "collisions": sum(r.collision for r in results), "timeouts": sum(r.timeout for r in results),
            "false_successes": sum(r.false_success for r in results),
            "mean_score": float(np.mean([r.score for r in results])),
            "median_time_s": float(np.median(times)) if times else None}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    default = shared_data_dir(Path(__file__))
    parser.add_argument("--worlds", type=Path, default=default / "barn" / "worlds" if default else None,
                        help="folder of world_N.world files, path_files/ beside it (default ../shared/data/barn/worlds)")
    parser.add_argument("--range", default="0-149", help="world numbers FIRST-LAST (default 0-149)")
    parser.add_argument("--only", choices=("all", "even", "odd"), default="all",
                        help="run only the even or odd worlds of the range (tune on one half, check on the other)")
    parser.add_argument("--runs", type=int, default=1, help="runs per world, seeds SEED..SEED+N-1 (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="the first run's seed (default 0)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--real-time", action="store_true",
                        help="also run every world on the wall clock, every service its own process, one "
                             "world at a time, and report it beside the lockstep figure")
    parser.add_argument("--odometry", choices=ODOMETRIES, default="auto",
                        help="navigate's --odometry for the lockstep runs (default auto: fused, BARN has no map)")


def say_result(say, result: WorldResult, how: str = "") -> None:
    t = "-" if result.time_s is None else f"{result.time_s:6.1f} s"
    say(f"{how}world {result.world:3d}: {'success' if result.success else 'FAIL   '} collision "
        f"{result.collision!s:5} timeout {result.timeout!s:5} "
        f"{'FALSE SUCCESS ' if result.false_success else ''}time {t} (OT {result.ot_s:.1f} s) "
        f"score {result.score:.3f}")


def halves(results: list[WorldResult]) -> dict:
    return {"all": tally(results), "even": tally([r for r in results if r.world % 2 == 0]),
            "odd": tally([r for r in results if r.world % 2 == 1])}


def run_real_time(jobs: list[tuple[str, str, int, str]], say) -> tuple[list[WorldResult], bool]:
    """The runs on the wall clock, one at a time (each has the machine to itself, as a Gazebo run
    with its stack has), in a fresh folder under out/; (results, interrupted)."""
    out = REPO / "out" / time.strftime("barn-real-time-%Y%m%d-%H%M%S")
    results = []
    try:
        for world_file, path_file, seed, _ in jobs:
            number = world_number(Path(world_file))
            results.append(run_world_live(Path(world_file), Path(path_file), seed, out / f"world_{number}-{seed}"))
            say_result(say, results[-1], "real time ")
    except KeyboardInterrupt:
        return results, True
    return results, False


def print_tallies(figures: dict, how: str) -> None:
    for name in ("all", "even", "odd"):
        f = figures[name]
        if f["runs"]:
            print(f"{how}{name:5}: {f['runs']} runs, success {f['success_rate']:.3f}, collisions {f['collisions']}, "
                  f"timeouts {f['timeouts']}, false successes {f['false_successes']}, mean score {f['mean_score']:.3f}")


@exits_2_on_user_error("bench barn")
def main(args: argparse.Namespace) -> int:
    if args.worlds is None or not args.worlds.is_dir():
        raise BarnError(f"--worlds {args.worlds}: no such folder (the BARN worlds, e.g. ../shared/data/barn/worlds)")
    if args.runs < 1 or args.workers < 1 or args.seed < 0:
        raise BarnError("--runs and --workers must be at least 1, --seed at least 0")
    numbers = [n for n in parse_range(args.range) if args.only == "all" or n % 2 == (args.only == "odd")]
    jobs = [(*job, args.odometry) for job in jobs_for(args.worlds, numbers, args.runs, args.seed)]
    say = (lambda text: print(text, file=sys.stderr, flush=True)) if args.json else print
    results: list[WorldResult] = []
    context = multiprocessing.get_context("spawn")      # numba and the runtime start clean in each worker
    interrupted = False
    with context.Pool(min(args.workers, len(jobs))) as pool, progress(len(jobs), "worlds", args.json) as bar:
        try:
            for result in pool.imap(_run_one, jobs):
                results.append(result)
                with bar.printing():
                    say_result(say, result, "lockstep " if args.real_time else "")
                bar.advance()
        except KeyboardInterrupt:       # Ctrl-C: the figures of the worlds run so far, marked as such
            interrupted = True
            pool.terminate()
    figures = {"interrupted": interrupted, **halves(results), "reference": REFERENCE,
               "range": args.range, "only": args.only, "runs_per_world": args.runs, "odometry": args.odometry,
               "worlds": [asdict(r) for r in results]}
    if args.real_time and not interrupted:
        live, interrupted = run_real_time(jobs, say)
        figures["interrupted"] = interrupted
        figures["real_time"] = {**halves(live), "worlds": [asdict(r) for r in live]}
    if args.json:
        print(json.dumps(figures))
        return 0
    if interrupted:
        print("interrupted: the figures of the runs that finished")
    print_tallies(figures, "lockstep  " if args.real_time else "")
    if "real_time" in figures:
        print_tallies(figures["real_time"], "real time ")
    r = REFERENCE
    print(f"reference, {r['name']}: success {r['success_rate']}, collisions {r['collision_rate']}, "
          f"timeouts {r['timeout_rate']}, mean score {r['mean_score']}")
    return 0
