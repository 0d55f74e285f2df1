"""`omninav bench kills [--seeds N] [--first-seed S] [--services a,b] [--json]`: does a mission survive a crash?

For each service of `omninav navigate`'s stack but the sim and the recorder (which the mission
cannot do without, see cli/navigate.py) and each seed, one room mission (the demo's two goals, amcl
localization) runs as `navigate` runs it — every service its own process, real time (--lockstep:
at most real time, every service keeping up), the ACL on —
and the service is sent SIGKILL at a moment drawn from the seed: KILL_WINDOW_S sim seconds after the
first goal was sent. The bench watches the bus with the run's read-only tool identity (the sim
clock, the goals) and finds the service's process in `up`'s log ("started NAME (pid N)", the last
one). Per run: the service, the seed, the kill time (sim s after the first goal; none if the mission
ended first), the restarts and success the mission's summary reports, its collisions that were the
robot's fault, its time; then the totals.
"""
from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..cli.demo import GOALS
from ..cli.navigate import NOT_RESTARTED, REPO
from ..schemas import decode
from ..schemas.keys import KeyLayout
from ..services.runtime.acl import TOOL
from ..services.runtime.zenoh_config import ROUTER_ENV, free_loopback_endpoint, open_client

SERVICES = ("chassis", "lidar", "map_server", "localizer", "costmap", "tracker", "global_planner", "local_planner",
            "cmd_vel_mux", "velocity_smoother", "collision_monitor", "navigator")
KILL_WINDOW_S = (2.0, 30.0)     # sim s after the first goal: the robot is under way to the first goal
MISSION_TIMEOUT_S = 1800        # wall s for one mission (a liveness bound)
POLL_S = 0.1


@dataclass(frozen=True)
class KillRun:
    service: str
    seed: int
    kill_s: float | None        # sim s after the first goal; None: the mission ended before the moment came
    restarts: dict[str, int]
    completed: bool             # navigate ran to its summary (exit 0 or 1), it did not give up
    success: bool
    robot_fault_collisions: int | None
    time_s: float | None
    wall_s: float
    exit: int


def kill_moment(service: str, seed: int) -> float:
    """The kill time (sim s after the first goal) of this service and seed: the same every run."""
    rng = np.random.default_rng([seed, SERVICES.index(service)])
    return float(rng.uniform(*KILL_WINDOW_S))


def service_pid(log: Path, name: str) -> int | None:
    """The pid `up` last started the service with, from its log."""
    found = re.findall(rf"\[up\] started {re.escape(name)} \(pid (\d+)\)", log.read_text(errors="replace")) \
        if log.exists() else []
    return int(found[-1]) if found else None


class Watch:
    """The sim clock and the first goal's stamp, seen on the bus with the run's tool identity."""

    def __init__(self, router: str, credentials: Path):
        keys = KeyLayout()
        self.now_ns = 0
        self.first_goal_ns: int | None = None
        self.session = open_client(router, credentials=str(credentials))
        self.subs = [self.session.declare_subscriber(keys.sim("clock"), self._on_clock),
                     self.session.declare_subscriber(keys.robot("goal"), self._on_goal)]

    def _on_clock(self, sample) -> None:
        self.now_ns = decode(sample.payload.to_bytes()).header.stamp_ns

    def _on_goal(self, sample) -> None:
        if self.first_goal_ns is None:
            self.first_goal_ns = decode(sample.payload.to_bytes()).header.stamp_ns

    def close(self) -> None:
        for sub in self.subs:
            sub.undeclare()
        self.session.close()


def _wait(condition, process: subprocess.Popen, deadline: float) -> bool:
    """Until condition() (True) or the process ended or the deadline passed (False)."""
    while not condition():
        if process.poll() is not None or time.monotonic() > deadline:
            return False
        time.sleep(POLL_S)
    return True


def run_one(service: str, seed: int, out: Path, rate: float, lockstep: bool, say) -> KillRun:
    folder = out / f"{service}-seed{seed}"
    router = free_loopback_endpoint()
    goals = [str(v) for goal in GOALS for v in ("--goal", *goal)]
    cmd = [sys.executable, "-m", "omninav.cli.main", "navigate", "--world", "room", *goals, "--seed", str(seed),
           "--rate", str(rate), *(["--lockstep"] if lockstep else []), "-o", str(folder), "--json"]
    started = time.monotonic()
    deadline = started + MISSION_TIMEOUT_S
    moment = kill_moment(service, seed)
    kill_s = None
    with open(out / f"{service}-seed{seed}.navigate.log", "wb") as log:
        navigate = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=log,
                                    env={**os.environ, ROUTER_ENV: router})
        reader = threading.Thread(target=lambda: setattr(navigate, "output", navigate.stdout.read()), daemon=True)
        reader.start()
        try:
            credentials = folder / "credentials" / TOOL
            if _wait(credentials.exists, navigate, deadline):
                watch = Watch(router, credentials)
                try:
                    if _wait(lambda: watch.first_goal_ns is not None and
                             watch.now_ns >= watch.first_goal_ns + round(moment * 1e9), navigate, deadline):
                        pid = service_pid(folder / "services.log", service)
                        if pid is not None:
                            os.kill(pid, signal.SIGKILL)
                            kill_s = (watch.now_ns - watch.first_goal_ns) / 1e9
                            say(f"{service} seed {seed}: SIGKILL to pid {pid} at {kill_s:.1f} sim s after the first goal")
                finally:
                    watch.close()
            navigate.wait(max(deadline - time.monotonic(), 1.0))
        except subprocess.TimeoutExpired:
            navigate.send_signal(signal.SIGINT)
            navigate.wait(300)
        finally:
            reader.join(60)
    summary = _last_json(getattr(navigate, "output", b""))
    return KillRun(service, seed, kill_s, dict(summary.get("restarts", {})), navigate.returncode in (0, 1),
                   bool(summary.get("success", False)), summary.get("robot_fault_collisions"), summary.get("time_s"),
                   time.monotonic() - started, navigate.returncode)


def _last_json(output: bytes) -> dict:
    """navigate's summary: its last stdout line that is a JSON object (also printed when it gave up)."""
    for line in reversed(output.decode(errors="replace").splitlines()):
        try:
            value = json.loads(line)
        except ValueError:
            continue
        if isinstance(value, dict):
            return value
    return {}


def add_arguments(parser) -> None:
    parser.add_argument("--seeds", type=int, default=3,
                        help="missions per service, seeds FIRST..FIRST+N-1 (default 3)")
    parser.add_argument("--first-seed", type=int, default=0, metavar="FIRST",
                        help="the first seed (default 0): split one experiment over several runs")
    parser.add_argument("--services", help=f"comma-separated, of {', '.join(SERVICES)} (default all)")
    parser.add_argument("--rate", type=float, default=1.0, help="sim seconds per wall second (default 1)")
    parser.add_argument("--lockstep", action="store_true",
                        help="navigate --lockstep at --rate: never faster than that, slower (never late) when "
                             "the machine cannot keep up, so the runs do not depend on its load")
    parser.add_argument("-o", "--out", help="folder for the runs (default out/kills-<date>-<time>)")


def main(args) -> int:
    services = tuple(args.services.split(",")) if args.services else SERVICES
    unknown = [s for s in services if s not in SERVICES]
    if unknown:
        excluded = [s for s in unknown if s in NOT_RESTARTED]
        why = f" ({', '.join(excluded)}: the mission cannot do without it)" if excluded else ""
        raise SystemExit(f"omninav bench kills: unknown service(s) {', '.join(unknown)}{why}; "
                         f"known: {', '.join(SERVICES)}")
    if args.seeds < 1 or args.first_seed < 0 or not (math.isfinite(args.rate) and args.rate > 0):
        raise SystemExit("omninav bench kills: --seeds must be ≥ 1, --first-seed ≥ 0 and --rate positive")
    out = Path(args.out or REPO / "out" / time.strftime("kills-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        print(f"bench kills: {text}", file=sys.stderr if args.json else sys.stdout, flush=True)

    runs = []
    for service in services:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            run = run_one(service, seed, out, args.rate, args.lockstep, say)
            runs.append(run)
            say(f"{service} seed {seed}: {'completed' if run.completed else 'GIVEN UP'}, "
                f"{'success' if run.success else 'FAILED'}, restarts {run.restarts or 'none'}, "
                f"{run.wall_s:.0f} wall s")
    totals = {"runs": len(runs), "killed": sum(r.kill_s is not None for r in runs),
              "completed": sum(r.completed for r in runs), "succeeded": sum(r.success for r in runs),
              "robot_fault_collisions": sum(r.robot_fault_collisions or 0 for r in runs),
              "restarted_as_killed": sum(r.kill_s is not None and r.restarts.get(r.service, 0) >= 1 for r in runs),
              "median_wall_s": float(np.median([r.wall_s for r in runs]))}
    if args.json:
        print(json.dumps({"runs": [asdict(r) for r in runs], "totals": totals, "out": str(out)}))
    else:
        print(f"{'service':<18} {'seed':>4} {'kill s':>7} {'restarts':<28} {'done':>5} {'ok':>5} {'coll':>4} {'time s':>7}")
        for r in runs:
            restarts = ", ".join(f"{k} {v}" for k, v in sorted(r.restarts.items())) or "none"
            kill = f"{r.kill_s:.1f}" if r.kill_s is not None else "—"
            time_s = f"{r.time_s:.1f}" if r.time_s is not None else "—"
            print(f"{r.service:<18} {r.seed:>4} {kill:>7} {restarts:<28} {str(r.completed):>5} {str(r.success):>5} "
                  f"{r.robot_fault_collisions if r.robot_fault_collisions is not None else '—':>4} {time_s:>7}")
        print(f"totals: {totals['completed']}/{totals['runs']} completed, {totals['succeeded']} succeeded, "
              f"{totals['killed']} killed ({totals['restarted_as_killed']} seen restarted), "
              f"{totals['robot_fault_collisions']} robot-fault collisions, median {totals['median_wall_s']:.0f} wall s "
              f"per mission; runs in {out}")
    return 0 if totals["completed"] == totals["runs"] and totals["robot_fault_collisions"] == 0 else 1
