"""A benchmark's mission on the wall clock: every service its own process, the simulator at real
time beside them, as a Gazebo run is — compute costs time, and a service that falls behind sees
the world move on without it (`omninav navigate` without --lockstep, run as a child process).

Lockstep (experiments/lockstep_mission.py) stays what tests and reproducible figures use; a
real-time figure is reported beside it, never instead of it. A live run is not reproducible: the
machine's load decides which command arrives in time.
"""
from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..services.runtime.errors import UserError

STOP_S = 60.0           # wall s a navigate child gets to stop its services after SIGINT


class RealTimeError(UserError):
    """A live mission that could not be run at all (its services did not start): one line."""


@dataclass
class LiveRun:
    recording: Path
    summary: dict | None        # navigate's JSON summary; None if it printed none
    exit_code: int


def run_live(world_file: Path, goals: np.ndarray, out: Path, *, profile: str | None = None, localization: str,
             timeout_s: float, seed: int, sim_dt: float | None = None, drive: str | None = None) -> LiveRun:
    """`omninav navigate` on the wall clock (rate 1) in `out`; goals (K, 3) in metres and radians."""
    out.mkdir(parents=True, exist_ok=True)
    recording = out / "run.mcap"
    recording.unlink(missing_ok=True)
    command = [sys.executable, "-m", "omninav.cli.main", "navigate", "--world", str(world_file),
               "--localization", localization, "--timeout", repr(timeout_s), "--seed", str(seed),
               "--record", str(recording), "-o", str(out), "--json", "--quiet"]
    for x, y, yaw in goals:
        command += ["--goal", repr(float(x)), repr(float(y)), f"{math.degrees(yaw)!r}deg"]
    if profile:
        command += ["--profile", profile]
    if sim_dt:
        command += ["--sim-dt", repr(sim_dt)]
    if drive:
        command += ["--drive", drive]
    with open(out / "navigate.log", "wb") as log:
        child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=log, start_new_session=True)
        try:
            stdout, _ = child.communicate()
        except BaseException:          # Ctrl-C or a kill of the bench: navigate stops its services first
            child.send_signal(signal.SIGINT)
            try:
                child.wait(STOP_S)
            except subprocess.TimeoutExpired:
                child.kill()
            raise
    lines = [line for line in stdout.decode(errors="replace").splitlines() if line.startswith("{")]
    summary = json.loads(lines[-1]) if lines else None
    if summary is None and not recording.is_file():
        raise RealTimeError(f"navigate on {world_file} exited {child.returncode} without a recording; "
                            f"see {out / 'navigate.log'}")
    return LiveRun(recording, summary, child.returncode)
