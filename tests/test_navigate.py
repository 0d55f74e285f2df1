"""`omninav navigate` and what it stands on: the truth_pose relay, the mission summary of a
recording, the command's argument errors and one whole mission as separate processes."""
from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml

from omninav.bench.determinism import messages_by_key
from omninav.cli.main import main as cli_main
from omninav.cli.navigate import REPO, compose_for, in_containers, map_for
from omninav.cli.profile import load_profile
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Clock, Goal, Header, NavStatus, Odometry, Pose2D, Twist
from omninav.schemas.messages import Path as PathMsg
from omninav.services.chassis.node import ChassisNode
from omninav.services.navigator.params import NavigatorParams
from omninav.experiments.mission_score import (MissionError, MissionRecord, goal_tolerance, load_mission, summarize_mission,
                                                summary_lines)
from omninav.services.truth_pose.node import TruthPoseNode, TruthPoseParams
from omninav.services.map_server.mapio import load_map
from omninav.services.recorder.mcap_io import read_records
from omninav.services.runtime.acl import TOOL
from omninav.services.runtime.compose import load_compose
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.node import NS_PER_S, Node
from omninav.services.runtime.zenoh_config import open_client
from omninav.geometry.se2 import compose
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import load_world, world_path

from launching import children, processes_using, router_of, service_pids, wait_for


class Driver(Node):
    """Turns while driving forward: odometry drifts from the truth (slip, a gyro-free chassis)."""
    service = "driver"

    def setup(self) -> None:
        self.cmd = self.publisher("cmd_vel")
        self.subscribe("sim/clock", self.on_clock)

    def on_clock(self, msg: Clock) -> None:
        self.cmd.publish(Twist(header=self.header("base_link"), linear_x=0.3, angular_z=0.4))


def test_truth_pose_relays_the_truth_and_carries_odometry_onto_it():
    nodes = [SimNode(SimNodeParams(wheel_slip_std=0.05, seed=3)), ChassisNode(), Driver(),
             TruthPoseNode(TruthPoseParams(publish_rate_hz=10.0))]
    runner = InProcessRunner(nodes)
    seen: dict[str, list] = {}
    runner.tap(lambda key, payload, stamp: seen.setdefault(key, []).append(decode(payload)))
    runner.run_until(lambda: False, max_steps=300)           # 3 sim s
    truth = {m.header.stamp_ns: m for m in seen["omninav/sim/r1/truth"]}
    odom = {m.header.stamp_ns: m for m in seen["omninav/r1/odom"]}
    poses, transforms = seen["omninav/r1/pose"], seen["omninav/r1/tf/map_odom"]
    assert 29 <= len(poses) <= 31 and len(transforms) == len(poses)      # 10 per sim second
    drift = 0.0
    for pose, tf in zip(poses, transforms):
        t = pose.header.stamp_ns
        assert tf.header.stamp_ns == t and pose.header.frame_id == "map"
        assert (tf.header.frame_id, tf.child_frame_id) == ("map", "odom")
        true = truth[t].pose
        assert (pose.pose.x, pose.pose.y, pose.pose.theta) == (true.x, true.y, true.theta)
        o = odom[t].pose
        carried = compose([tf.transform.x, tf.transform.y, tf.transform.theta], [o.x, o.y, o.theta])
        np.testing.assert_allclose(carried, [true.x, true.y, true.theta], atol=1e-9)
        drift = max(drift, np.hypot(o.x + 1.2 - true.x, o.y + 1.0 - true.y))
    assert drift > 1e-3          # the transform did correct something: odometry is not the truth
    assert np.all(np.diag(poses[0].covariance) > 0)


def test_truth_pose_skips_odometry_without_a_truth_at_its_stamp():
    node = TruthPoseNode()
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append(p.key)
    def truth(t):
        node.process(0, Odometry(header=Header(stamp_ns=t, frame_id="world"), pose=Pose2D(1.0, 2.0, 0.5)))

    def odom(t):
        node.process(1, Odometry(header=Header(stamp_ns=t, frame_id="odom")))

    odom(NS_PER_S)                       # no truth yet
    truth(2 * NS_PER_S)
    odom(2 * NS_PER_S + 1)               # a truth, but of another stamp
    assert out == [] and node.counters["odom_without_truth"] == 2
    truth(3 * NS_PER_S)
    odom(3 * NS_PER_S)
    assert out == ["omninav/r1/pose", "omninav/r1/tf/map_odom"]


def test_truth_pose_rejects_bad_parameters():
    with pytest.raises(ValueError, match="publish_rate_hz"):
        TruthPoseParams(publish_rate_hz=-1.0)


# ---------------------------------------------------------------- the mission summary

@pytest.fixture(scope="module")
def box_world(tmp_path_factory):
    """A 6 m × 4 m room with one box; the robot starts at (1, 1)."""
    path = tmp_path_factory.mktemp("world") / "box.yaml"
    path.write_text("name: box\nbounds: [6.0, 4.0]\nboxes: [{center: [3.0, 3.0], size: [1.0, 1.0]}]\n"
                    "robot: {start: [1.0, 1.0, 0.0]}\n")
    return load_world(path)


def straight_run(stamps_s, start=(1.0, 1.0, 0.0), end=(4.0, 1.0, 0.5)):
    """Truth moving linearly from start to end over the stamps."""
    f = np.linspace(0.0, 1.0, len(stamps_s))[:, None]
    poses = np.asarray(start) + f * (np.asarray(end) - np.asarray(start))
    return np.round(np.asarray(stamps_s) * NS_PER_S).astype(np.int64), poses


def goal(goal_id, x, y, yaw, at_s):
    return Goal(header=Header(stamp_ns=round(at_s * NS_PER_S), frame_id="map"), goal_id=goal_id,
                pose=Pose2D(x, y, yaw))


def status(goal_id, state, at_s, reason=""):
    return NavStatus(header=Header(stamp_ns=round(at_s * NS_PER_S)), goal_id=goal_id, status=state, reason=reason)


def plan(goal_id, poses):
    return PathMsg(header=Header(), goal_id=goal_id, poses=np.asarray(poses, np.float64))


def test_summary_of_a_mission_with_two_goals(box_world):
    world = box_world
    stamps, poses = straight_run(np.arange(0.0, 10.01, 0.01))
    record = MissionRecord(stamps, poses,
                           goals=[goal("g1", 2.5, 1.0, 0.0, 1.0), goal("g2", 4.0, 1.02, 0.5, 5.5)],
                           statuses=[status("g1", "active", 1.1), status("g1", "succeeded", 5.0),
                                     status("g2", "active", 5.6), status("g2", "succeeded", 10.0)],
                           plans=[plan("g1#1", []), plan("g1#2", [[1, 1, 0], [2, 1, 0], [2.5, 1, 0]]),
                                  plan("g1#3", [[1, 1, 0], [9, 1, 0]]), plan("g2#4", [[2.5, 1, 0], [4, 1, 0]])],
                           sim_values={"collisions": 0})
    s = summarize_mission(record, world, recording="run.mcap")
    assert s.success and (s.goals_reached, s.goals_total) == (2, 2)
    assert s.time_s == pytest.approx(9.0)                        # first goal sent at 1 s, last ended at 10 s
    assert s.path_length_m == pytest.approx(2.7, abs=1e-9)       # truth from 1 s to the end (10 s)
    assert s.plan_length_m == pytest.approx(1.5 + 1.5)           # the first non-empty plan of each goal
    assert s.final_xy_error_m == pytest.approx(0.02) and s.final_yaw_error_deg == pytest.approx(0.0, abs=1e-9)
    g1 = s.goals[0]                                              # at 5 s the truth was at x = 2.5
    assert g1.status == "succeeded" and g1.time_s == pytest.approx(4.0)
    assert g1.xy_error_m == pytest.approx(0.0, abs=1e-9) and g1.yaw_error_deg == pytest.approx(math.degrees(0.25))
    assert s.to_json()["goals"][1]["goal_id"] == "g2"
    assert json.loads(json.dumps(s.to_json()))["recording"] == "run.mcap"


def test_time_within_1m_of_each_goal_on_a_synthetic_record(box_world):
    stamps, poses = straight_run(np.arange(0.0, 10.01, 0.01))     # x = 1 + 0.3 t, y = 1
    record = MissionRecord(stamps, poses, goals=[goal("g1", 2.5, 1.0, 0.0, 1.0), goal("g2", 4.0, 1.02, 0.5, 5.5),
                                                 goal("g3", 1.0, 3.5, 0.0, 9.0)],
                           statuses=[status("g1", "succeeded", 5.0), status("g2", "succeeded", 9.0)],
                           sim_values={"collisions": 0})
    g1, g2, g3 = summarize_mission(record, box_world).goals
    assert g1.within_1m_s == pytest.approx((1.5 - 1.0) / 0.3 - 1.0, abs=0.011)   # x = 1.5
    assert g2.within_1m_s == pytest.approx((3.0002 - 1.0) / 0.3 - 5.5, abs=0.011)   # sqrt(1 - 0.02²) short of x = 4
    assert g3.within_1m_s is None                                  # 2.5 m away the whole time
    assert "never within 1 m" in "\n".join(summary_lines(summarize_mission(record, box_world)))


def test_a_goal_said_succeeded_beyond_the_tolerance_and_5_cm_is_a_false_success(box_world):
    """Issue 36: the truth must stand within the navigator's xy_goal_tolerance + 5 cm when success is said."""
    stamps, poses = straight_run(np.arange(0.0, 4.01, 0.01))     # the robot ends at (4, 1)
    for goal_x, tolerance, reached in ((4.07, 0.03, True), (4.09, 0.03, False), (4.09, 0.1, True), (5.0, 0.1, False)):
        record = MissionRecord(stamps, poses, goals=[goal("g1", goal_x, 1.0, 0.5, 0.5)],
                               statuses=[status("g1", "succeeded", 4.0)], sim_values={"collisions": 0})
        s = summarize_mission(record, box_world, goal_tolerance_m=tolerance)
        assert (s.success, s.goals_reached, s.goals[0].reached, s.to_json()["goals"][0]["reached"]) == (
            reached, int(reached), reached, reached)
        assert (s.false_successes, s.goals[0].false_success) == (int(not reached), not reached)
        assert ("a FALSE SUCCESS" in "\n".join(summary_lines(s))) == (not reached)


def test_a_false_success_is_judged_where_the_robot_stood_when_it_was_said(box_world):
    """A shove after the goal succeeded moves the robot away from it: no false success."""
    stamps, poses = straight_run(np.arange(0.0, 4.01, 0.01))     # x = 1 + 0.75 t: at 2 s it stood at x = 2.5
    record = MissionRecord(stamps, poses, goals=[goal("g1", 2.5, 1.0, 0.5, 0.5)],
                           statuses=[status("g1", "succeeded", 2.0)], sim_values={"collisions": 0})
    s = summarize_mission(record, box_world, goal_tolerance_m=0.03)
    assert s.success and not s.goals[0].false_success and s.goals[0].xy_error_m == pytest.approx(1.5)


def test_the_goal_tolerance_of_a_compose_is_its_navigators():
    assert goal_tolerance([{"name": "nav", "service": "navigator", "params": {"xy_goal_tolerance": 0.03}}]) == 0.03
    assert goal_tolerance([{"name": "navigator", "service": "navigator"}]) == NavigatorParams().xy_goal_tolerance


@pytest.mark.parametrize("values, success", [
    ({"collisions": 0, "robot_fault_collisions": 0, "mover_fault_collisions": 0, "contact_s": 0.0}, True),
    ({"collisions": 2, "robot_fault_collisions": 0, "mover_fault_collisions": 2, "shoved_collisions": 1,
      "contact_s": 0.5, "robot_contact_s": 0.0}, False),      # the people's contacts fail it too
    ({"collisions": 3, "robot_fault_collisions": 1, "mover_fault_collisions": 2}, False),
    ({"collisions": 1}, False),                 # a sim that does not split: the robot's fault
])
def test_any_contact_fails_a_mission_and_the_shares_are_told(box_world, values, success):
    stamps, poses = straight_run(np.arange(0.0, 4.01, 0.01))
    record = MissionRecord(stamps, poses, goals=[goal("g1", 4.0, 1.0, 0.5, 0.5)],
                           statuses=[status("g1", "succeeded", 4.0)], sim_values=values)
    s = summarize_mission(record, box_world)
    assert s.success == success and s.collisions == values["collisions"]
    assert s.robot_fault_collisions == values.get("robot_fault_collisions", values["collisions"])
    assert s.mover_fault_collisions == values.get("mover_fault_collisions")
    assert s.shoved_collisions == values.get("shoved_collisions")
    assert f"{values['collisions']} collisions ({s.robot_fault_collisions} the robot's fault" in summary_lines(s)[0]
    assert s.contact_s == values.get("contact_s") and s.robot_contact_s == values.get("robot_contact_s")


def test_clearance_counts_movers_and_overlaps(box_world):
    world = box_world
    stamps, poses = straight_run(np.arange(0.0, 2.01, 0.01), start=(1.0, 2.0, 0.0), end=(1.5, 2.0, 0.0))
    clear_static = summarize_mission(MissionRecord(stamps, poses, sim_values={"collisions": 0}), world)
    # walls at x = 0 and y = 0 / 4: the footprint's left edge at x = 1 − 0.416 is nearest
    assert clear_static.min_clearance_m == pytest.approx(1.0 - 0.416)
    mover = np.zeros((len(stamps), 1, 3))
    mover[:, 0] = (2.5, 2.0, 0.2)                                # the robot's front edge reaches 1.916
    record = MissionRecord(stamps, poses, mover_stamps=stamps, mover_circles=mover, sim_values={"collisions": 0})
    assert summarize_mission(record, world).min_clearance_m == pytest.approx(2.5 - 0.2 - 1.916)
    assert summarize_mission(record, world).min_mover_clearance_m == pytest.approx(2.5 - 0.2 - 1.916)
    assert clear_static.min_mover_clearance_m is None
    mover[150:, 0] = (1.8, 2.0, 0.2)                             # inside the footprint
    assert summarize_mission(record, world).min_clearance_m == 0.0


def test_summary_of_a_failed_mission(box_world):
    world = box_world
    stamps, poses = straight_run(np.arange(0.0, 4.01, 0.01))
    record = MissionRecord(stamps, poses, goals=[goal("g1", 4.0, 1.0, 0.5, 0.5)],
                           statuses=[status("g1", "active", 0.6), status("g1", "aborted", 3.0, "no valid plan")],
                           sim_values={"collisions": 2})
    s = summarize_mission(record, world, goals_total=3)
    assert not s.success and (s.goals_reached, s.goals_total, s.collisions) == (0, 3, 2)
    assert s.goals[0].status == "aborted" and s.goals[0].reason == "no valid plan" and s.plan_length_m is None
    text = "\n".join(summary_lines(s))
    assert "FAILED: 0/3 goals" in text and "no valid plan" in text
    no_answer = summarize_mission(MissionRecord(stamps, poses, goals=[goal("g1", 4.0, 1.0, 0.5, 0.5)]), world)
    assert no_answer.goals[0].status == "none" and no_answer.collisions is None and not no_answer.success
    assert no_answer.time_s == pytest.approx(3.5)                # until the last truth
    assert s.restarts == {} and "restarts: none" in text


def test_a_partial_summary_counts_the_restarts(box_world):
    """What a mission given up after restarts prints: the goals reached so far, the time, the restarts."""
    stamps, poses = straight_run(np.arange(0.0, 4.01, 0.01))
    record = MissionRecord(stamps, poses, goals=[goal("g1", 3.25, 1.0, 0.375, 0.5), goal("g2", 1.0, 1.0, 0.0, 3.5)],
                           statuses=[status("g1", "succeeded", 3.0), status("g2", "active", 3.6)],
                           sim_values={"collisions": 0}, restarts={"localizer": 2, "chassis": 1})
    s = summarize_mission(record, box_world, goals_total=3)
    assert not s.success and (s.goals_reached, s.goals_total) == (1, 3) and s.time_s == pytest.approx(3.5)
    assert s.to_json()["restarts"] == {"localizer": 2, "chassis": 1}
    assert "restarts: chassis 1, localizer 2" in summary_lines(s)

def test_load_mission_reads_a_recording(tmp_path, box_world):
    from omninav.schemas import encode
    from omninav.schemas.messages import Diagnostic, Obstacles
    from omninav.services.recorder.mcap_io import RecordingWriter
    path = tmp_path / "m.mcap"
    with RecordingWriter(path) as out:
        def put(key, msg):
            out.write(key, type(msg).__name__, encode(msg), msg.header.seq, msg.header.stamp_ns, 0)
        for k in (2, 1, 3):                                      # out of order on purpose
            put("omninav/sim/r1/truth", Odometry(header=Header(stamp_ns=k * NS_PER_S, frame_id="world"),
                                                  pose=Pose2D(float(k), 1.0, 0.0)))
            put("omninav/sim/movers", Obstacles(header=Header(stamp_ns=k * NS_PER_S),
                                                circles=np.array([[5.0, 3.0, 0.2]]), velocities=np.zeros((1, 2))))
        put("omninav/r1/goal", goal("g1", 3.0, 1.0, 0.0, 1.0))
        put("omninav/r1/nav_status", status("g1", "succeeded", 3.0))
        put("omninav/r1/diagnostics/sim", Diagnostic(header=Header(stamp_ns=3 * NS_PER_S), name="sim",
                                                     values={"collisions": 0, "run_started_ns": 5}))
        # the local planner's Diagnostics come from three runs (two restarts), the costmap's from one
        for run, seq in ((10, 1), (10, 2), (20, 1), (30, 1), (30, 2)):
            put("omninav/r1/diagnostics/local_planner", Diagnostic(header=Header(stamp_ns=seq, seq=seq),
                                                                   name="local_planner", values={"run_started_ns": run}))
        put("omninav/r1/diagnostics/costmap", Diagnostic(header=Header(seq=1), name="costmap",
                                                         values={"run_started_ns": 7}))
    record = load_mission(path, services=("sim", "costmap", "local_planner"))
    assert record.truth_poses[:, 0].tolist() == [1.0, 2.0, 3.0] and record.mover_circles.shape == (3, 1, 3)
    assert record.restarts == {"local_planner": 2}
    s = summarize_mission(record, box_world, recording=str(path))
    assert s.success and s.path_length_m == pytest.approx(2.0) and s.restarts == {"local_planner": 2}
    with pytest.raises(MissionError, match="no such recording"):
        load_mission(tmp_path / "missing.mcap")
    empty = tmp_path / "empty.mcap"
    with RecordingWriter(empty):
        pass
    with pytest.raises(MissionError, match="no ground truth"):
        load_mission(empty)


# ---------------------------------------------------------------- the command: arguments and compose

@pytest.mark.parametrize("argv, message", [
    (["--world", "nowhere", "--goal", "1", "1", "0"], "world 'nowhere': no such file"),
    (["--world", "room", "--goal", "20", "1", "0"], "goal (20, 1) lies outside the map of 'room'"),
    (["--world", "room"], "names no goals: give --goal"),
    (["--world", "room", "--goal", "2", "2", "0", "--timeout", "0"], "--timeout must be a positive number"),
])
def test_navigate_argument_errors_exit_2_naming_the_problem(argv, message, capsys, tmp_path):
    assert cli_main(["navigate", *argv, "-o", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []            # nothing was started or written


def test_navigate_refuses_a_goal_in_an_obstacle_or_out_of_reach_before_starting_anything(capsys, tmp_path):
    walled = tmp_path / "walled.yaml"          # a wall across the whole hall: the right half is closed off
    walled.write_text("bounds: [8.0, 4.0]\nwalls: [[4.0, 0.0, 4.0, 4.0]]\nrobot: {start: [1.0, 2.0, 0.0]}\n")
    cases = [(["--world", "room", "--goal", "5", "4", "0"], "goal 1 (5.00, 4.00) is in an obstacle"),
             (["--world", str(walled), "--goal", "2", "2", "0", "--goal", "6", "2", "0"],
              "goal 2 (6.00, 2.00) cannot be reached from the start (1.00, 2.00)"),
             (["--world", str(walled), "--goal", "3.8", "2", "0"], "goal 1 (3.80, 2.00) is in an obstacle")]
    for k, (argv, message) in enumerate(cases):
        out = tmp_path / f"run{k}"
        assert cli_main(["navigate", *argv, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
        assert not (out / "compose.yaml").exists() and not (out / "services.log").exists()   # nothing started


@pytest.mark.parametrize("localization, service", [("amcl", "localizer"), ("slam", "slam"), ("truth", "truth_pose")])
def test_mission_compose_restarts_every_service_but_the_sim_and_the_recorder(localization, service, tmp_path):
    world = load_world(world_path("office"))
    map_file = map_for(world, "office", tmp_path)
    assert map_file.parent == tmp_path and load_map(map_file).info.resolution == 0.05   # rasterized
    compose = compose_for(world, Path(world.source), map_file, "diff", localization, tmp_path / "run.mcap",
                          seed=3, rate=1.0, robot="r1", state_dir=tmp_path / "state")
    names = [s["name"] for s in compose["services"]]
    assert names[0] == "recorder" and service in names       # the recorder first: it is stopped last
    assert {"sim", "chassis", "lidar", "costmap", "tracker", "global_planner", "local_planner", "velocity_smoother",
            "collision_monitor", "navigator"} <= set(names)
    assert ("map_server" in names) == (localization != "slam")
    by_name = {s["name"]: s for s in compose["services"]}
    assert by_name["sim"]["restart"] == by_name["recorder"]["restart"] == "no"
    assert all((s["restart"], s["max_restarts"]) == ("on-failure", 5) for s in compose["services"]
               if s["name"] not in ("sim", "recorder"))
    # what each resumes from lies in the run's state folder
    assert by_name["chassis"]["params"]["odom_file"] == str(tmp_path / "state" / "chassis_odom.yaml")
    assert by_name["navigator"]["params"]["goal_file"] == str(tmp_path / "state" / "navigator_goal.yaml")
    if localization == "amcl":
        assert by_name["localizer"]["params"]["pose_file"] == str(tmp_path / "state" / "localizer_pose.yaml")
    assert by_name["sim"]["params"]["drive"] == by_name["chassis"]["params"]["drive"] == "diff"
    assert by_name["global_planner"]["params"]["goal_topic"] == "plan_request"
    assert by_name["tracker"]["params"]["use_map"] == (localization != "slam")    # slam's map is being drawn
    x, y, yaw = world.robot.start
    assert by_name["costmap"]["params"]["initial_pose_x"] == x and by_name["navigator"]["params"]["initial_pose_y"] == y
    path = tmp_path / "compose.yaml"
    path.write_text(yaml.safe_dump(compose))
    assert [s.name for s in load_compose(path).services] == names     # every parameter is valid
    # composed, a container restarts as a whole: the simulator's (sim, recorder) not, the robot's does
    composed = {**compose, "services": in_containers(compose["services"], "two")}
    path.write_text(yaml.safe_dump(composed))
    policies = {(s.process, s.restart) for s in load_compose(path).services}
    assert policies == {("simulator", "no"), ("robot", "on-failure")}


def test_the_worlds_robot_drives_on_its_followers_and_a_profiles_robot_on_its_own_odometry(tmp_path):
    world = load_world(world_path("room"))
    def services(profile):
        compose = compose_for(world, Path(world.source), map_for(world, "room", tmp_path), "mecanum", "amcl",
                              tmp_path / "run.mcap", seed=0, rate=1.0, robot="r1", profile=profile)
        path = tmp_path / "compose.yaml"
        path.write_text(yaml.safe_dump(compose))
        load_compose(path)                                  # every parameter is valid
        return {s["name"]: s.get("params", {}) for s in compose["services"]}
    own, jackal = services(None), services(load_profile("jackal"))
    assert own["chassis"]["odom_source"] == "followers"
    assert (own["localizer"]["recovery_alpha_slow"], own["localizer"]["recovery_alpha_fast"]) == (0.001, 0.1)
    assert "odom_source" not in jackal["chassis"] and "recovery_alpha_fast" not in jackal["localizer"]


def test_the_room_uses_its_shipped_map(tmp_path):
    world = load_world(world_path("room"))
    assert map_for(world, "room", tmp_path) == REPO / "compose" / "maps" / "room.yaml"
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- one whole mission

# 1.1 m ahead of the room's start (1.2, 1.0, 0), turned 30°: a plan, a drive, the final approach and a
# turn on arrival as with a goal further off, in 5.6 s of sim rather than the 7.3 s of one at (3.2, 0.9)
GOAL = ("2.3", "0.9", "30")


def _lockstep_mission(out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "omninav.cli.main", "navigate", "--world", "room",
                           "--goal", *GOAL, "--localization", "truth", "--lockstep", "-o", str(out),
                           "--json"], cwd=REPO, capture_output=True, timeout=900)


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    """One mission, every service its own process, in lockstep with the simulator: (the command's
    result, its run folder)."""
    out = tmp_path_factory.mktemp("navigate") / "run"
    return _lockstep_mission(out), out


def test_the_same_lockstep_mission_beside_a_cpu_burner_gives_the_same_messages(mission, tmp_path):
    """The run again with both cores kept busy by other processes: every message on every key is the
    same (services/runtime/lockstep.py: no wall clock decides anything)."""
    done, out = mission
    assert done.returncode == 0, done.stderr.decode()
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
    try:
        again = _lockstep_mission(tmp_path / "again")
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    assert again.returncode == 0, again.stderr.decode()
    first, second = messages_by_key(out / "run.mcap"), messages_by_key(tmp_path / "again" / "run.mcap")
    assert sorted(first) == sorted(second)
    differing = [key for key in first if first[key] != second[key]]
    assert differing == [], f"{len(differing)} keys differ, e.g. {differing[0]}"
    assert len(first["omninav/sim/clock"]) > 500 and len(first["omninav/r1/cmd_vel"]) > 50


def test_navigate_drives_a_mission_as_separate_processes_and_scores_it(mission):
    done, out = mission
    log = (out / "services.log").read_text(errors="replace")
    router = re.search(r"router listening on (\S+)", log).group(1)
    assert processes_using(router) == []                          # every service was stopped
    assert done.returncode == 0, done.stderr.decode() + log[-3000:]
    summary = json.loads(done.stdout.decode().strip().splitlines()[-1])
    assert summary["success"] and (summary["goals_reached"], summary["goals_total"], summary["collisions"]) == (1, 1, 0)
    assert summary["final_xy_error_m"] < 0.05 and summary["final_yaw_error_deg"] < 2.0
    straight = math.hypot(float(GOAL[0]) - 1.2, float(GOAL[1]) - 1.0)
    assert straight - 0.1 < summary["path_length_m"] < 2 * straight and summary["plan_length_m"] > straight - 0.1
    assert 0.0 < summary["min_clearance_m"] < 1.0 and summary["time_s"] > 0
    recording = Path(summary["recording"])
    assert recording == out / "run.mcap"
    keys = {rec.key for rec in read_records(recording)}
    assert {"omninav/r1/goal", "omninav/r1/nav_status", "omninav/r1/plan_request", "omninav/r1/follow_path",
            "omninav/r1/cmd_vel", "omninav/r1/pose"} <= keys


@pytest.mark.parametrize("service", ["local_planner", "navigator", "tracker", "chassis"])
def test_the_live_mission_replays_byte_for_byte_into_the_local_planner_and_the_navigator(mission, service, capsys):
    """No parameters given: replay builds the service with the compose's (xy_goal_tolerance 0.03 m, ...,
    not the defaults), which the live service's Diagnostic carries into the recording; but not with
    its state file (the chassis's odom_file holds where the live run ended: resuming from it would
    put the replayed odometry there)."""
    done, out = mission
    assert done.returncode == 0, done.stderr.decode()
    assert cli_main(["replay", str(out / "run.mcap"), "--into", service, "--compare"]) == 0, capsys.readouterr().out
    printed = capsys.readouterr().out
    assert "parameters: the live run's, from its Diagnostic" in printed
    assert "replay reproduces the recorded outputs byte for byte" in printed and "not exactly replayable" not in printed


def test_the_lockstep_processes_give_the_messages_of_the_same_services_in_one_process(mission, tmp_path, capsys):
    """Run as processes over the bus or as Nodes in navigate's own process (--in-process), the
    services compute the same messages: the bus and the process boundaries change nothing."""
    done, out = mission
    assert done.returncode == 0, done.stderr.decode()
    assert cli_main(["navigate", "--world", "room", "--goal", *GOAL, "--localization", "truth",
                     "--in-process", "-o", str(tmp_path / "one"), "--quiet"]) == 0, capsys.readouterr().out
    assert messages_by_key(out / "run.mcap") == messages_by_key(tmp_path / "one" / "run.mcap")


# ---------------------------------------------------------------- a service dying mid-mission

def test_a_mission_survives_a_local_planner_killed_mid_mission(tmp_path):
    """The local planner is sent SIGKILL while it steers towards the goal: `up` restarts it, the
    navigator sends the restarted one its path again, the goal is reached, and the summary says the
    local planner was restarted once; afterwards no process is left running. In lockstep at half
    real time at most: the simulator goes on without the dead one (about as many sim seconds as the
    restart takes wall seconds, halved) and waits for the restarted one once it is back."""
    out = tmp_path / "run"
    navigate = subprocess.Popen([sys.executable, "-m", "omninav.cli.main", "navigate", "--world", "room",
                                 "--goal", *GOAL, "--localization", "truth", "--lockstep",
                                 "--rate", "0.5", "--timeout", "600", "-o", str(out), "--json"],
                                cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        router = wait_for(lambda: router_of(out / "services.log"), navigate, "router")
        steering = threading.Event()
        with open_client(router, credentials=str(out / "credentials" / TOOL)) as session:    # the ACL is on
            local_cmd = session.declare_subscriber(
                KeyLayout().resolve("local_cmd"),
                lambda sample: decode(sample.payload.to_bytes()).goal_id == "g1" and steering.set())
            wait_for(steering.is_set, navigate, "local planner command for the goal")
            local_cmd.undeclare()
        killed = next(pids["local_planner"] for pids in map(service_pids, children(navigate.pid))
                      if "local_planner" in pids)
        os.kill(killed, signal.SIGKILL)
        stdout, stderr = navigate.communicate(timeout=900)
    finally:
        if navigate.poll() is None:     # a failure above: let navigate stop what it started
            navigate.send_signal(signal.SIGINT)
            navigate.communicate(timeout=300)
    log = (out / "services.log").read_text(errors="replace")
    assert navigate.returncode == 0, stderr.decode() + log[-3000:]
    summary = json.loads(stdout.decode().strip().splitlines()[-1])
    assert summary["success"] and summary["goals_reached"] == 1 and summary["robot_fault_collisions"] == 0
    assert summary["restarts"] == {"local_planner": 1}
    assert "local_planner ended with signal SIGKILL" in log and "restarting in" in log
    assert processes_using(router) == []
    commands = [decode(rec.payload) for rec in read_records(out / "run.mcap", ["omninav/r1/local_cmd"])]
    assert any(cmd.goal_id == "g1" for cmd in commands)
    assert [rec.key for rec in read_records(out / "run.mcap", ["omninav/r1/goal"])] == ["omninav/r1/goal"]   # sent once
