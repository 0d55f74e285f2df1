"""`omninav bench footprint [--json]`: what the stack costs the computer it runs on.

Runs `omninav navigate` live at 1× real time — the demo's room mission (AMCL) and a BARN world
(odometry only, the Jackal profile) — with every service its own process, composed in two containers
(`--composed`: the simulated hardware apart from the robot's stack, as on a robot whose drivers run
apart) and composed in one (`--composed one`: as Nav2's single component container; the simulator
with it, so its cost is counted too), and measures from outside, through /proc of navigate's process tree:
- start-up: wall seconds from launching navigate to its line saying the first goal was sent;
- CPU: cores used per sim second in steady state: the tree's user + system CPU time over a window
  that starts `settle_s` after the first goal, divided by the sim time that passed in it (read from
  the clock messages of the run's recording at the window's wall times);
- memory: the tree's total proportional set size (PSS, /proc/PID/smaps_rollup) at the window's end.
The mission is stopped (Ctrl-C to navigate) at the window's end. The reference is the other way of
running in the same bench: the separate processes measured beside the composed ones, each a median
of --runs runs. The issue's aims are printed beside the medians.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from ..schemas.keys import KeyLayout
from ..services.recorder.mcap_io import read_records
from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..sim.barn_world import GOAL
from ..sim.world import shared_data_dir

REPO = Path(__file__).resolve().parents[1]
# navigate's flags for each way of running the services
MODES = {"separate": [], "composed": ["--composed"], "composed-one": ["--composed", "one"]}
# the demo's mission (cli/demo.py) and BARN's goal from the start, as navigate takes them (degrees)
ROOM = ["--world", "room", "--localization", "amcl", "--goal", "8.3", "3.5", "90", "--goal", "3.0", "4.8", "180"]
BARN_ARGS = ["--profile", "jackal", "--localization", "odom", "--goal", str(GOAL[0]), str(GOAL[1]), "90"]
# issue 15's aims on this machine: cores, MB, seconds to the first goal
AIMS = {"composed": {"cores": 0.25, "pss_mb": 400, "startup_s": 3.0},
        "composed-one": {"cores": 0.25, "pss_mb": 400, "startup_s": 3.0},
        "separate": {"cores": 0.5, "pss_mb": 800, "startup_s": 5.0}}
FIRST_GOAL = re.compile(r"g1: goal .* sent at sim")
GOAL_ENDED = re.compile(r"g\d+: (succeeded|aborted|canceled|no result)")
LAUNCH_TIMEOUT_S = 600
STOP_TIMEOUT_S = 600    # navigate stops its services one by one, each up to 10 s on a loaded machine
SAMPLE_S = 0.5


class FootprintError(UserError):
    """A run that could not be measured: one line."""


# ---------------------------------------------------------------- /proc readers

def tree_pids(root: int, proc: Path = Path("/proc")) -> list[int]:
    """root and every live descendant of it."""
    parents: dict[int, list[int]] = {}
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rpartition(")")[2].split()[1])
        except (OSError, IndexError, ValueError):
            continue        # ended meanwhile
        parents.setdefault(ppid, []).append(int(entry.name))
    found, todo = [root], [root]
    while todo:
        kids = parents.get(todo.pop(), [])
        found += kids
        todo += kids
    return found


def cpu_seconds(pids: list[int], proc: Path = Path("/proc")) -> float:
    """User + system CPU seconds the processes have used (every thread of each), those still there."""
    ticks = os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in pids:
        try:
            fields = (proc / str(pid) / "stat").read_text().rpartition(")")[2].split()
        except OSError:
            continue
        total += int(fields[11]) + int(fields[12])     # utime, stime (stat fields 14 and 15)
    return total / ticks


def pss_mb(pids: list[int], proc: Path = Path("/proc")) -> float:
    """Total proportional set size of the processes in MB (shared pages split among their users)."""
    total_kb = 0
    for pid in pids:
        try:
            text = (proc / str(pid) / "smaps_rollup").read_text()
        except OSError:
            continue
        found = re.search(r"^Pss:\s+(\d+) kB", text, re.MULTILINE)
        total_kb += int(found.group(1)) if found else 0
    return total_kb / 1024


def sim_time_at(recording: Path, wall_ns: list[int], robot: str = "r1") -> list[float]:
    """The sim time (s) of the last clock message received by each wall time (ns) in a recording."""
    clock = KeyLayout(robot).resolve("sim/clock")
    pairs = sorted((r.log_time_ns, r.stamp_ns) for r in read_records(recording, [clock]))
    if not pairs:
        raise FootprintError(f"{recording}: no clock messages recorded")
    out = []
    for wall in wall_ns:
        before = [stamp for log_time, stamp in pairs if log_time <= wall]
        out.append((before[-1] if before else pairs[0][1]) / 1e9)
    return out


# ---------------------------------------------------------------- one run

@dataclass
class RunFigures:
    startup_s: float
    cores: float            # CPU seconds per sim second
    pss_mb: float
    processes: int


def measure_run(mission: list[str], mode: str, settle_s: float, window_s: float, folder: Path) -> RunFigures:
    cmd = [sys.executable, "-m", "omninav.cli.main", "navigate", *mission, "-o", str(folder), *MODES[mode]]
    lines: list[tuple[float, str]] = []
    sent = threading.Event()
    launched = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)

    def read() -> None:
        for line in proc.stdout:
            lines.append((time.monotonic(), line.rstrip()))
            if FIRST_GOAL.search(line):
                sent.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        give_up = time.monotonic() + LAUNCH_TIMEOUT_S
        while not sent.wait(SAMPLE_S) and proc.poll() is None and time.monotonic() < give_up:
            pass
        if not sent.is_set():
            raise FootprintError(f"{mode}: no first goal; navigate said: " + " | ".join(t for _, t in lines[-5:]))
        startup_s = next(t for t, text in lines if FIRST_GOAL.search(text)) - launched
        time.sleep(settle_s)
        first = sample(proc.pid)
        last = first
        deadline = time.monotonic() + window_s
        # a short mission (a BARN world) may end within the window: its last full sample counts
        while time.monotonic() < deadline and not any(GOAL_ENDED.search(text) for _, text in lines):
            time.sleep(SAMPLE_S)
            now = sample(proc.pid)
            if now.processes < first.processes:
                break
            last = now
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGINT)     # navigate stops its stack, the recorder last
        proc.wait(STOP_TIMEOUT_S)
        reader.join(10)
    sim0, sim1 = sim_time_at(folder / "run.mcap", [first.wall_ns, last.wall_ns])
    if sim1 <= sim0:
        raise FootprintError(f"{mode}: the sim clock did not advance in the window (the mission ended too soon?)")
    return RunFigures(startup_s, (last.cpu_s - first.cpu_s) / (sim1 - sim0), last.pss_mb, last.processes)


@dataclass
class Sample:
    wall_ns: int
    cpu_s: float
    pss_mb: float
    processes: int


def sample(root: int) -> Sample:
    pids = tree_pids(root)
    return Sample(time.time_ns(), cpu_seconds(pids), pss_mb(pids), len(pids))


# ---------------------------------------------------------------- the bench

def add_arguments(parser: argparse.ArgumentParser) -> None:
    default = shared_data_dir(Path(__file__))
    parser.add_argument("--runs", type=int, default=3, help="runs per world and mode (default 3)")
    parser.add_argument("--worlds", nargs="+", choices=("room", "barn"), default=["room", "barn"])
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--barn-world", type=Path,
                        default=default / "barn" / "worlds" / "world_0.world" if default else None,
                        help="the BARN world file (default ../shared/data/barn/worlds/world_0.world)")
    parser.add_argument("--settle", type=float, default=3.0, metavar="S",
                        help="wall s after the first goal before the CPU window (default 3)")
    parser.add_argument("--window", type=float, default=15.0, metavar="S", help="the CPU window, wall s (default 15)")


def _median(runs: list[RunFigures]) -> dict:
    return {name: statistics.median(getattr(r, name) for r in runs) for name in ("startup_s", "cores", "pss_mb")} | \
        {"processes": runs[0].processes, "runs": [asdict(r) for r in runs]}


@exits_2_on_user_error("bench footprint")
def main(args: argparse.Namespace) -> int:
    if args.runs < 1 or args.settle < 0 or args.window <= 0:
        raise FootprintError("--runs must be at least 1, --settle at least 0 and --window positive")
    if "barn" in args.worlds and (args.barn_world is None or not args.barn_world.is_file()):
        raise FootprintError(f"--barn-world {args.barn_world}: no such file")
    missions = {"room": ROOM, "barn": ["--world", str(args.barn_world), *BARN_ARGS]}
    say = (lambda text: print(text, file=sys.stderr, flush=True)) if args.json else print
    load = os.getloadavg()
    result = {"load_average": load, "aims": AIMS, "worlds": {}}
    say(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {args.runs} run(s) per world and mode")
    with tempfile.TemporaryDirectory(prefix="omninav-footprint-") as tmp:
        for world in args.worlds:
            for mode in args.modes:
                runs = []
                for k in range(args.runs):
                    figures = measure_run(missions[world], mode, args.settle, args.window, Path(tmp) / f"{world}-{mode}-{k}")
                    say(f"{world} {mode} run {k + 1}: start-up {figures.startup_s:.2f} s, {figures.cores:.3f} cores, "
                        f"{figures.pss_mb:.0f} MB PSS over {figures.processes} processes")
                    runs.append(figures)
                result["worlds"].setdefault(world, {})[mode] = _median(runs)
    result["load_average_after"] = os.getloadavg()
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{'world':6} {'mode':12} {'start-up s':>10} {'cores':>7} {'PSS MB':>7} {'procs':>5}   aim (s, cores, MB)")
    for world, modes in result["worlds"].items():
        for mode, m in modes.items():
            aim = AIMS[mode]
            print(f"{world:6} {mode:12} {m['startup_s']:10.2f} {m['cores']:7.3f} {m['pss_mb']:7.0f} {m['processes']:5d}"
                  f"   ≤{aim['startup_s']:g}, ≤{aim['cores']:g}, ≤{aim['pss_mb']:g}")
    print(f"medians of {args.runs} run(s); load average before {load[0]:.2f}, after {result['load_average_after'][0]:.2f}")
    return 0
