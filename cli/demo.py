"""`omninav demo`: the main job. A navigation mission in the simulated room: `omninav navigate`
starts every service as its own process (recorder, sim, chassis, lidar, map_server, AMCL on the
room's map, costmap, global and local planner, velocity smoother, collision monitor, navigator;
each but the sim and the recorder restarted after a crash, resuming where it was), in lockstep with
the simulator (or at wall-clock pace with --real-time), sends the goals one after another and scores
the run against the ground truth; then the recording
is replayed deterministically into the chassis (byte-for-byte compare) and drawn as a picture:
map, global costmap, planned and driven paths, scans."""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import yaml

from .goal_args import add_goal_argument

REPO = Path(__file__).resolve().parents[1]
# across the room to the square table's side, then back past the pillar to the dining table
GOALS = ((8.3, 3.5, 90.0), (3.0, 4.8, 180.0))
STEP_TIMEOUT_S = 900


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--out", help="output folder (default out/demo-<date>-<time>)")
    add_goal_argument(parser, "a goal in the room (default: "
                      + ", then ".join(f"({x:g}, {y:g}, {yaw:g}°)" for x, y, yaw in GOALS) + ")")
    # lockstep by default: as fast as the services compute and exactly replayable at any machine load;
    # at wall-clock pace a loaded machine can deliver a command later than the chassis waits for it
    parser.add_argument("--real-time", dest="rate", type=float, nargs="?", const=1.0, metavar="RATE",
                        help="run at RATE sim seconds per wall second (default 1) instead of in lockstep")
    parser.add_argument("--composed", nargs="?", const="two", choices=("one", "two"),
                        help="run the services in one or two containers (navigate --composed), not a process each")


def _omninav(*args: str) -> list[str]:
    return [sys.executable, "-m", "omninav.cli.main", *args]


def _step(title: str, cmd: list[str], log: Path, show_output: bool = False) -> int:
    print(f"== {title}", flush=True)
    with open(log, "ab") as sink:
        done = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE if show_output else sink,
                              stderr=sink, timeout=STEP_TIMEOUT_S)
    if show_output:
        print("   " + done.stdout.decode(errors="replace").strip().replace("\n", "\n   "), flush=True)
    print(f"   {'ok' if done.returncode == 0 else f'FAILED (exit {done.returncode}), see {log}'}", flush=True)
    return done.returncode


def _params_of(compose: Path, name: str) -> list[str]:
    """`--set k=v` for each parameter the mission's compose file gave a service: the replay must
    run the service as the live run did (but for its state files, which are the live run's own)."""
    from ..services.runtime.service_registry import node_class

    service = next(s for s in yaml.safe_load(compose.read_text())["services"] if s["name"] == name)
    state_files = node_class(service["service"]).state_files
    return [arg for key, value in service.get("params", {}).items() if key not in state_files
            for arg in ("--set", f"{key}={value}")]


def main(args: argparse.Namespace) -> int:
    out = Path(args.out or REPO / "out" / time.strftime("demo-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    log = out / "demo.log"
    recording = out / "run.mcap"
    goals = [str(v) for goal in (args.goal or [(x, y, math.radians(yaw)) for x, y, yaw in GOALS])
             for v in ("--goal", *goal[:2], f"{goal[2]!r}rad")]
    composed = ["--composed", args.composed] if args.composed else []
    pace = ["--lockstep"] if args.rate is None else ["--rate", str(args.rate)]
    navigated = _step("navigate --world room --localization amcl " +
                      (f"(--composed {args.composed}" if composed else "(every service its own process") +
                      (", in lockstep)" if args.rate is None else f", {args.rate:g}x real time)"),
                      _omninav("navigate", "--world", "room", *goals, "--localization", "amcl", *pace,
                               "-o", str(out), "--record", str(recording), *composed), log, show_output=True)
    if not recording.is_file():
        print(f"demo failed: no recording; the log is {log}", file=sys.stderr)
        return 1
    replayed = _step("replay run.mcap --into chassis --compare",
                     _omninav("replay", str(recording), "--into", "chassis", "--compare",
                              *_params_of(out / "compose.yaml", "chassis")), log)
    drawn = _step("report run.mcap -o run.png",
                  _omninav("report", str(recording), "-o", str(out / "run.png"), "--world", "sim/worlds/room.yaml"), log)
    print(f"\nrecording {recording}\npicture   {out / 'run.png'}\nlog       {log}")
    return 0 if navigated == 0 and replayed == 0 and drawn == 0 else 1
