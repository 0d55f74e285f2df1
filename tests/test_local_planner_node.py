"""The local_planner service: the simulated room with the sample local costmap, the two gates and a
stand-in navigator; straight and L-shaped paths end within 5 cm and 2° of the path's end by ground
truth, without collisions, for a mecanum and a differential drive; idle and stop answers every
tick; ROS planner files configure it; a robot facing away from its path turns on the spot first
(the rotation shim); a live multi-process run replays byte for byte into it and into both gates."""
import math
import signal

import numpy as np
import pytest
import zenoh

from conftest import REPO, wait_until
from local_pipeline import KEYS, follow_path, pipeline, polyline, recorder_tap
from omninav.cli.main import main
from omninav.schemas import decode, encode
from omninav.schemas.attachment import pack_attachment
from omninav.schemas.messages import Header, LocalCommand, Odometry, Path
from omninav.services.local_planner.approach import FinalApproach
from omninav.services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from omninav.services.local_planner.params import FollowerParams
from omninav.services.recorder.mcap_io import RecordingWriter, read_records
from omninav.services.runtime.node import NS_PER_S
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.geometry.se2 import integrate

LOCAL_CMD = KEYS.robot("local_cmd")
START = (1.2, 1.0)                       # the room's robot start
STRAIGHT = ([START, (3.6, 1.0)], 0.6)    # corners, goal yaw: a turn on the way for the holonomic robot
L_SHAPED = ([START, (4.2, 1.0), (4.2, 3.2)], math.pi / 2)


def yaw_error(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@pytest.mark.parametrize("drive, corners, goal_yaw, controller", [
    ("mecanum", *STRAIGHT, "dwa"), ("mecanum", *L_SHAPED, "dwa"),
    ("diff", *STRAIGHT, "dwa"), ("diff", *L_SHAPED, "dwa"),
    ("mecanum", *L_SHAPED, "follower"), ("mecanum", *L_SHAPED, "eband"), ("diff", *L_SHAPED, "eband")],
    ids=["mecanum-straight", "mecanum-L", "diff-straight", "diff-L", "follower-L", "eband-mecanum-L", "eband-diff-L"])
def test_the_robot_stops_within_5_cm_and_2_degrees_of_the_paths_end(drive, corners, goal_yaw, controller):
    # the L passes the round table 0.44 m away: TEB's default min_obstacle_dist 0.5 m would refuse it
    band = {"elastic_band": {"min_obstacle_dist": 0.1}} if controller == "eband" else {}
    run = pipeline("room", drive, [(0.5, follow_path(polyline(corners, goal_yaw)))],
                   local_planner={"controller": controller, **band}, watch=["local_cmd"])
    commands = run.published.setdefault(LOCAL_CMD, [])
    run.run(40.0, until=lambda: commands and commands[-1].reason == "goal_reached")
    run.run(1.0)                     # what is still on its way to the wheels
    x, y, yaw = run.truth()
    assert math.hypot(x - corners[-1][0], y - corners[-1][1]) <= 0.05
    assert yaw_error(yaw, goal_yaw) <= math.radians(2)
    assert run.sim.sim.collisions == 0 and run.sim.sim.contact_steps == 0
    assert np.abs(run.truths[-1][4:]).max() < 1e-3                        # standing
    reasons = [c.reason for c in commands]
    assert reasons[0] == "idle" and "" in reasons and "final_approach" in reasons
    assert "rotate_to_heading" not in reasons                             # it faces the path: no shim
    assert all(c.goal_id == "g1" for c in commands if c.reason != "idle")
    assert all(c.ok for c in commands)
    if drive == "diff":
        assert all(c.linear_y == 0.0 for c in commands)
    # the final approach decelerates: the commanded speed falls as the goal comes nearer
    approach = [math.hypot(c.linear_x, c.linear_y) for c in commands if c.reason == "final_approach"]
    assert max(approach[-5:]) < max(approach)


@pytest.mark.parametrize("drive, start", [
    ("holonomic", (0.0, 0.0, 0.0)), ("holonomic", (0.1, -0.4, 2.5)),   # ahead; beside and turned away
    ("diff", (0.0, 0.0, 0.0)), ("diff", (0.9, 0.05, 0.0))])             # ahead; the goal behind it
def test_the_final_approach_lands_on_the_goal_pose_in_a_kinematic_loop(drive, start):
    goal = np.array([0.5, 0.0, math.pi / 2])
    params = FollowerParams(drive=drive)
    approach = FinalApproach(params, goal, start, 0.0, 0.02, 0.02)
    pose, phases, twists = np.array(start, float), [], []
    for _ in range(400):
        command = approach.step(pose, 0.05)
        phases.append(command.phase)
        twists.append(command.twist)
        if command.phase == "arrived":
            break
        pose = integrate(pose, command.twist, 0.05)
    assert phases[-1] == "arrived"
    assert math.hypot(*(pose[:2] - goal[:2])) <= 0.02 and yaw_error(pose[2], goal[2]) <= 0.02
    twists = np.array(twists)
    assert np.abs(twists[:, 2]).max() <= params.max_vel_theta
    assert np.hypot(twists[:, 0], twists[:, 1]).max() <= params.cruise_speed + 1e-9
    if drive == "diff":
        assert np.all(twists[:, 1] == 0.0)
        assert (twists[:, 0] < 0).any() == (start[0] > goal[0])          # backwards to a goal behind
        assert phases.count("turn") > 0                                  # the goal's yaw on the spot
    poses = approach.planned_poses(start, 0.025)
    assert np.allclose(poses[-1], goal) and np.allclose(poses[0][:2], start[:2])


@pytest.mark.parametrize("latch", [True, False])
def test_a_differential_drive_whose_turn_drifts_its_centre_keeps_the_position_it_reached(latch):
    """A skid steer's centre slides while it turns on the spot. Latched, the approach keeps the
    position it reached and finishes the turn; unlatched, the slide the turn to the goal's yaw brings
    (2.4 cm against a 2 cm tolerance) is corrected by turning towards it, and that turn slides it
    again: it turns back and forth for good (the Jackal's 10 s of dithering)."""
    goal = np.array([0.5, 0.0, math.pi / 2])
    approach = FinalApproach(FollowerParams(drive="diff"), goal, (0.0, 0.0, 0.0), 0.0, 0.02, 0.02, latch)
    pose, phases, turned = np.array([0.0, 0.0, 0.0]), [], 0.0
    for _ in range(600):
        command = approach.step(pose, 0.05)
        phases.append(command.phase)
        if command.phase == "arrived":
            break
        slide = 0.015 * abs(command.twist[2]) if command.twist[0] == 0.0 else 0.0   # m/s sideways per rad/s
        pose = integrate(pose, command.twist + np.array([0.0, slide, 0.0]), 0.05)
        turned += abs(command.twist[2]) * 0.05
    aligns = sum(1 for a, b in zip(phases, phases[1:]) if b == "align" and a != "align")
    if latch:   # one turn to the yaw, and the slide it brought kept within twice the tolerance
        assert phases[-1] == "arrived" and approach.reached(pose) and aligns == 0
        assert 0.02 < math.hypot(*(pose[:2] - goal[:2])) <= 0.04 and turned < math.pi / 2 + 0.1
    else:
        assert phases[-1] != "arrived" and aligns >= 5


def test_local_cmd_is_published_every_tick_and_idle_without_a_path():
    node = LocalPlannerNode(LocalPlannerNodeParams())
    out = []
    node.cmd_pub.sink = lambda pub, payload, stamp: out.append(decode(payload, LocalCommand))
    odom = node.inputs.index(next(i for i in node.inputs if i.key == KEYS.robot("odom")))
    for k in range(3, 103):         # 10 ms odometry from 30 ms on: ticks on every multiple of 50 ms
        node.process(odom, Odometry(header=Header(stamp_ns=k * 10_000_000, frame_id="odom", seq=k)))
    assert [c.header.stamp_ns for c in out] == [k * 50_000_000 for k in range(1, 21)]
    assert all(c.ok and c.reason == "idle" and c.goal_id == "" and (c.linear_x, c.linear_y, c.angular_z) == (0, 0, 0)
               for c in out)


def test_an_empty_follow_path_stops_the_robot():
    far = polyline([START, (4.2, 1.0), (4.2, 3.2)], 0.0)
    stop = Path(header=Header(frame_id="map"), goal_id="g1")
    run = pipeline("room", "mecanum", [(0.5, follow_path(far)), (2.5, stop)], watch=["local_cmd"])
    run.run(5.0)
    commands = run.published[LOCAL_CMD]
    moving = [c for c in commands if c.reason == ""]
    assert moving and max(c.linear_x for c in moving) > 0.3                # it was driving
    effect = 2.5 + run.local_planner.params.request_delay_s
    stopped_from = next(i for i, c in enumerate(commands) if c.header.stamp_ns > effect * NS_PER_S)
    assert all(c.reason == "idle" and c.goal_id == "" for c in commands[stopped_from:])
    assert np.abs(run.truths[-1][4:]).max() < 1e-3                          # and it stands
    assert math.hypot(*(run.truth()[:2] - np.array(START))) > 0.5


def test_ros_planner_files_configure_it(tmp_path):
    dwa = tmp_path / "dwa_local_planner_params.yaml"
    dwa.write_text("DWAPlannerROS:\n  max_vel_x: 0.4\n  min_vel_x: -0.1\n  max_vel_y: 0.3\n  min_vel_y: -0.3\n"
                   "  max_vel_trans: 0.4\n  max_rot_vel: 1.5\n  min_rot_vel: 0.3\n  acc_lim_th: 2.0\n"
                   "  vth_samples: 30\n  sim_time: 1.2\n  path_distance_bias: 20.0\n  use_dwa: true\n"
                   "  latch_xy_goal_tolerance: false\n")
    p = build_node("local_planner", str(dwa)).params
    assert (p.max_vel_x, p.min_vel_x, p.max_vel_y, p.max_vel_theta, p.min_vel_theta) == (0.4, -0.1, 0.3, 1.5, -1.5)
    assert (p.min_in_place_vel_theta, p.acc_lim_theta, p.vtheta_samples, p.sim_time) == (0.3, 2.0, 30, 1.2)
    assert p.path_distance_bias == 20.0 and p.xy_goal_tolerance == 0.02
    trajectory = tmp_path / "base_local_planner_params.yaml"
    trajectory.write_text("TrajectoryPlannerROS:\n  max_vel_x: 0.45\n  min_vel_x: 0.1\n  max_rotational_vel: 1.0\n"
                          "  min_in_place_rotational_vel: 0.4\n  holonomic_robot: false\n  meter_scoring: true\n"
                          "  pdist_scale: 0.6\n  gdist_scale: 0.8\n  dwa: false\n")
    p = build_node("local_planner", str(trajectory), {"controller": "follower"}).params
    assert (p.max_vel_x, p.holonomic_robot, p.dwa, p.path_distance_bias, p.goal_distance_bias) == (0.45, False, False,
                                                                                                   0.6, 0.8)
    assert p.follower_params().drive == "diff"
    with pytest.raises(ParamError, match=r"unknown parameter 'max_vel_z' \(did you mean 'max_vel_y'\?\)"):
        build_node("local_planner", overrides={"DWAPlannerROS": {"max_vel_z": 1.0}})
    with pytest.raises(ParamError, match="max_vel_x is given twice"):
        build_node("local_planner", overrides={"DWAPlannerROS": {"max_vel_x": 0.3}, "max_vel_x": 0.4})
    with pytest.raises(ParamError, match="controller must be one of"):
        build_node("local_planner", overrides={"controller": "mpc"})
    with pytest.raises(ParamError, match="path_follower: drive 'holonomic' contradicts holonomic_robot False"):
        build_node("local_planner", overrides={"holonomic_robot": False, "path_follower": {"drive": "holonomic"}})
    with pytest.raises(ParamError, match="path_follower: .*unknown parameter"):
        build_node("local_planner", overrides={"path_follower": {"speed": 1.0}})


# ---------------------------------------------------------------- recorded, replayed

REPLAYED = (("local_planner", ["--set", "initial_pose_x=1.2", "--set", "initial_pose_y=1.0"]),
            ("velocity_smoother", []), ("collision_monitor", []))
# live, on a loaded machine the sim starves and then catches up in bursts of up to 10 steps, so the
# gates' inputs may trail the clock by more than their default margins (40 and 50 ms)
LIVE = (REPLAYED[0], ("cmd_vel_mux", ["--set", "command_delay_s=0.3"]),
        ("velocity_smoother", ["--set", "command_delay_s=0.3"]), ("collision_monitor", ["--set", "scan_delay_s=0.3"]))


def _replays_byte_for_byte(recording, capsys, services=REPLAYED) -> None:
    for service, extra in services:
        assert main(["replay", str(recording), "--into", service, "--compare", *extra]) == 0, capsys.readouterr().out
        assert "replay reproduces the recorded outputs byte for byte" in capsys.readouterr().out


def test_an_in_process_run_replays_byte_for_byte_into_the_local_planner_and_the_gates(tmp_path, capsys):
    run = pipeline("room", "mecanum", [(0.5, follow_path(polyline(STRAIGHT[0], STRAIGHT[1])))], watch=["local_cmd"])
    recording = tmp_path / "in_process.mcap"
    with RecordingWriter(recording) as writer:        # what the recorder would write
        run.runner.tap(recorder_tap(writer))
        commands = run.published.setdefault(LOCAL_CMD, [])
        run.run(20.0, until=lambda: commands and commands[-1].reason == "goal_reached")
    assert commands[-1].reason == "goal_reached"
    _replays_byte_for_byte(recording, capsys)


def test_a_robot_facing_away_from_the_path_turns_on_the_spot_first_then_drives_and_arrives(tmp_path, capsys):
    world = tmp_path / "room_turned.yaml"      # the room, the robot facing west; the path runs east
    world.write_text((REPO / "sim" / "worlds" / "room.yaml").read_text().replace("start: [1.2, 1.0, 0.0]",
                                                                                 f"start: [1.2, 1.0, {math.pi}]"))
    corners, goal_yaw = STRAIGHT
    run = pipeline(str(world), "mecanum", [(0.5, follow_path(polyline(corners, goal_yaw)))], watch=["local_cmd"])
    recording = tmp_path / "turned.mcap"
    with RecordingWriter(recording) as writer:
        run.runner.tap(recorder_tap(writer))
        commands = run.published.setdefault(LOCAL_CMD, [])
        run.run(40.0, until=lambda: commands and commands[-1].reason == "goal_reached")
        run.run(1.0)                     # what is still on its way to the wheels
    reasons = [c.reason for c in commands if c.reason != "idle"]
    turning = reasons.index("")
    assert turning > 10 and set(reasons[:turning]) == {"rotate_to_heading"}
    assert "rotate_to_heading" not in reasons[turning:]                   # once per path
    assert all(c.linear_x == c.linear_y == 0.0 and c.angular_z != 0.0
               for c in commands if c.reason == "rotate_to_heading")
    # no translation until the path lies within the threshold: the robot turned where it stood
    handed_over = next(c.header.stamp_ns for c in commands if c.reason == "") / NS_PER_S
    at_handover = [t for t in run.truths if t[0] <= handed_over]
    assert max(math.hypot(t[1] - START[0], t[2] - START[1]) for t in at_handover) < 0.01
    assert yaw_error(at_handover[-1][3], 0.0) <= run.local_planner.params.angular_dist_threshold + 0.1
    x, y, yaw = run.truth()
    assert math.hypot(x - corners[-1][0], y - corners[-1][1]) <= 0.05 and yaw_error(yaw, goal_yaw) <= math.radians(2)
    assert run.sim.sim.collisions == 0 and run.sim.sim.contact_steps == 0
    turned = [*REPLAYED[0][1], "--set", f"initial_pose_a={math.pi}"]
    _replays_byte_for_byte(recording, capsys, (("local_planner", turned),))


def test_a_live_run_replays_byte_for_byte_into_the_local_planner_and_the_gates(processes, router_endpoint, tmp_path,
                                                                                capsys):
    """Every service its own process in lockstep with the sim at half speed (so the path this test puts
    comes within the deferrals), the gates with wider margins (LIVE); the path is sent once the
    costmap keeps up."""
    recording = tmp_path / "local.mcap"
    recorder = processes.omninav("record", "-o", str(recording))
    wait_until(lambda: "recording" in processes.log_of(recorder), 60, what="the recorder to start")
    costmap_files = ["--set", "local_costmap_files=[compose/params/costmap_common_params.yaml, "
                              "compose/params/costmap_local_params.yaml]"]
    processes.in_lockstep("chassis", "lidar", "costmap", *(service for service, _ in LIVE), "navigator_stand_in")
    services = [processes.omninav("run", "sim", "--set", "rate=0.5"), processes.omninav("run", "chassis"),
                processes.omninav("run", "lidar"),
                processes.omninav("run", "costmap", *REPLAYED[0][1], *costmap_files),
                *(processes.omninav("run", service, *extra) for service, extra in LIVE),
                processes.omninav("run", "navigator_stand_in", "--module", "local_pipeline:NavigatorStandIn",
                                  env={"PYTHONPATH": str(REPO / "tests")})]
    with open_client(router_endpoint) as session:
        clock, commands, lag = [0], [], []
        subscribers = [
            session.declare_subscriber(LOCAL_CMD, lambda s: commands.append(decode(s.payload.to_bytes()))),
            session.declare_subscriber(KEYS.sim("clock"), lambda s: clock.__setitem__(0, decode(s.payload.to_bytes())
                                                                                       .header.stamp_ns)),
            session.declare_subscriber(KEYS.robot("costmap/local"), lambda s: lag.append(
                clock[0] - decode(s.payload.to_bytes()).header.stamp_ns))]
        wait_until(lambda: len(lag) >= 3 and max(lag[-3:]) < 0.25 * NS_PER_S and commands, 120,
                   what="the costmap to keep up with the clock")
        path = follow_path(polyline([START, (2.6, 1.0)], 0.3))
        path.header.stamp_ns, path.header.seq = clock[0], 1
        session.put(KEYS.robot("follow_path"), encode(path), attachment=pack_attachment(1, clock[0], "Path"),
                    congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: any(c.reason == "goal_reached" for c in commands), 90, what="the goal to be reached")
        for subscriber in subscribers:
            subscriber.undeclare()
    for proc in reversed(services):      # their last outputs and diagnostics get recorded
        assert processes.stop(proc, signal.SIGINT) == 0, processes.log_of(proc)
    assert processes.stop(recorder, signal.SIGINT) == 0, processes.log_of(recorder)

    keys = {KEYS.robot(k) for k in ("local_cmd", "local_plan", "cmd_vel_smoothed", "cmd_vel")}
    assert {rec.key for rec in read_records(recording, keys)} == keys
    _replays_byte_for_byte(recording, capsys, LIVE)
