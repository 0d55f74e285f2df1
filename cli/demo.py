"""`omninav demo`: the main job. The simulated robot runs as separate processes under `omninav up`
(recorder, sim, chassis, lidar), a teleop script drives it round the room, and then the recording
is replayed deterministically into the chassis (byte-for-byte compare) and drawn as a picture."""
from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from ..schemas.keys import KeyLayout
from ..services.runtime.zenoh_config import free_loopback_endpoint, open_client

REPO = Path(__file__).resolve().parents[1]
COMPOSE = REPO / "compose" / "sim.yaml"
# along the wall, sideways into the open, a turn on the spot, diagonally on: what a mecanum robot can do
ROUTE = "0.4,0,0,7;0,0.3,0,5;0,0,0.6,2.6;0.3,0.1,0,3"
STEP_TIMEOUT_S = 300
READY_TIMEOUT_S = 180


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--out", help="output folder (default out/demo-<date>-<time>)")
    parser.add_argument("--route", default=ROUTE, help=f"teleop script 'vx,vy,wz,seconds;…' (default {ROUTE})")
    parser.add_argument("--rate", type=float, default=2.0, help="sim speed, sim seconds per wall second (default 2)")


def _omninav(*args: str) -> list[str]:
    return [sys.executable, "-m", "omninav.cli.main", *args]


def _wait_until_ready(router: str, names: list[str], up: subprocess.Popen) -> bool:
    """Until every service of the compose file has declared its liveliness token (or up died)."""
    keys = KeyLayout()
    deadline = time.monotonic() + READY_TIMEOUT_S
    with open_client(router) as session:
        while time.monotonic() < deadline and up.poll() is None:
            if all(any(r.ok is not None for r in session.liveliness().get(keys.alive(n), timeout=0.2)) for n in names):
                return True
            time.sleep(0.2)
    return False


def _compose_for(out: Path, rate: float) -> tuple[Path, list[str]]:
    """compose/sim.yaml with the recording in the demo's folder and the chosen sim rate, and the
    names of its services."""
    compose = yaml.safe_load(COMPOSE.read_text())
    for service in compose["services"]:
        if service.get("service") == "recorder":
            service.setdefault("params", {})["output"] = str(out / "run.mcap")
        if service.get("service") == "sim":
            service.setdefault("params", {})["rate"] = rate
    path = out / "compose.yaml"
    path.write_text(yaml.safe_dump(compose, sort_keys=False))
    return path, [service.get("name") or service["service"] for service in compose["services"]]


def _step(title: str, cmd: list[str], log: Path) -> int:
    print(f"== {title}", flush=True)
    with open(log, "ab") as sink:
        code = subprocess.run(cmd, cwd=REPO, stdout=sink, stderr=subprocess.STDOUT, timeout=STEP_TIMEOUT_S).returncode
    print(f"   {'ok' if code == 0 else f'FAILED (exit {code}), see {log}'}", flush=True)
    return code


def main(args: argparse.Namespace) -> int:
    out = Path(args.out or REPO / "out" / time.strftime("demo-%Y%m%d-%H%M%S")).resolve()
    out.mkdir(parents=True, exist_ok=True)
    router = free_loopback_endpoint()
    log = out / "demo.log"
    print(f"== omninav up {COMPOSE.relative_to(REPO)}: recorder, sim, chassis, lidar (log: {log})", flush=True)
    compose, names = _compose_for(out, args.rate)
    with open(log, "wb") as sink:
        up = subprocess.Popen(_omninav("up", str(compose), "--router", router),
                              cwd=REPO, stdout=sink, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        if not _wait_until_ready(router, names, up):
            print(f"   the services did not all start; see {log}", file=sys.stderr)
            return 1
        drove = _step(f"teleop --script {args.route}", _omninav("teleop", "--script", args.route, "--router", router), log)
    finally:
        up.send_signal(signal.SIGINT)
        stopped = up.wait(60)
    print(f"== stopped every service (up exit {stopped})", flush=True)
    recording = out / "run.mcap"
    if drove != 0 or stopped != 0 or not recording.is_file():
        print(f"demo failed; the log is {log}", file=sys.stderr)
        return 1
    replayed = _step("replay run.mcap --into chassis --compare",
                     _omninav("replay", str(recording), "--into", "chassis", "--compare"), log)
    drawn = _step("report run.mcap -o run.png",
                  _omninav("report", str(recording), "-o", str(out / "run.png"), "--world", "sim/worlds/room.yaml"), log)
    print(f"\nrecording {recording}\npicture   {out / 'run.png'}\nlog       {log}")
    return 0 if replayed == 0 and drawn == 0 else 1
