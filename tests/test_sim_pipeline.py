"""Issue 3 end to end: sim, chassis, lidar and recorder as separate processes, driven by a teleop
script, in lockstep with the simulator; the recording replays byte for byte into the chassis and the lidar, and draws as a report."""
import math
import signal

import numpy as np

from omninav.schemas import decode
from omninav.services.recorder.mcap_io import read_records

from conftest import wait_alive, wait_until

# forward 0.9 m, turn in place, strafe right: clear of the room's furniture from the start pose
SCRIPT = "0.3,0,0,3;0,0,0.5,2;0,-0.1,0,1"


def run_omninav(processes, *args, timeout=180):
    proc = processes.omninav(*args)
    code = proc.wait(timeout)
    return code, processes.log_of(proc)


def test_drive_record_replay_and_report(processes, router_endpoint, tmp_path):
    recording = tmp_path / "sim.mcap"
    recorder = processes.omninav("record", "-o", str(recording))
    wait_until(lambda: "recording" in processes.log_of(recorder), 60, what="the recorder to start")
    # in lockstep (services/runtime/lockstep.py): the sim steps once the others, teleop included, are
    # done with a step, so the recording replays exactly however loaded the machine is
    followers = ["chassis", "lidar", "cmd_vel_mux", "velocity_smoother", "collision_monitor"]
    processes.in_lockstep(*followers, "teleop")
    services = [processes.omninav("run", "sim", "--set", "rate=0"),
                *(processes.omninav("run", name) for name in followers)]
    wait_alive(router_endpoint, ["sim", *followers])
    code, log = run_omninav(processes, "teleop", "--script", SCRIPT)
    assert code == 0, log
    for proc in reversed(services):      # lidar and chassis first: their final diagnostics get recorded
        assert processes.stop(proc, signal.SIGINT) == 0, processes.log_of(proc)
    assert processes.stop(recorder, signal.SIGINT) == 0, processes.log_of(recorder)

    keys = {rec.key for rec in read_records(recording)}
    assert {"omninav/r1/scan", "omninav/r1/odom", "omninav/sim/r1/truth", "omninav/r1/wheel_cmd"} <= keys

    truth = [decode(r.payload) for r in read_records(recording, ["omninav/sim/r1/truth"])]
    odom = [decode(r.payload) for r in read_records(recording, ["omninav/r1/odom"])]
    start, end = truth[0].pose, truth[-1].pose
    assert math.hypot(end.x - start.x, end.y - start.y) > 0.6           # the script moved the robot
    # odometry, started at the truth's first pose, ends near the truth (default noise, no contact)
    dx, dy = odom[-1].pose.x - odom[0].pose.x, odom[-1].pose.y - odom[0].pose.y
    c, s = math.cos(start.theta), math.sin(start.theta)
    assert np.hypot(start.x + c * dx - s * dy - end.x, start.y + s * dx + c * dy - end.y) < 0.05

    for service in ("chassis", "lidar"):
        code, log = run_omninav(processes, "replay", str(recording), "--into", service, "--compare")
        assert code == 0, log

    picture = tmp_path / "run.png"
    code, log = run_omninav(processes, "report", str(recording), "-o", str(picture),
                            "--world", "sim/worlds/room.yaml")
    assert code == 0, log
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
