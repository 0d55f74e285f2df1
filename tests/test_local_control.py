"""The local planner's control core (services/local_planner/control.py) without any node: a robot
facing away from its path turns on the spot, hands over to DWA, then to the final approach and
arrives, and approaches again when its map pose is corrected off the goal; a final approach whose
line crosses an obstacle leaves the robot to the controller until the line is free; a shim turn that would sweep into a wall is not commanded; no path is idle, no
costmap brakes, an empty path stops. The node (node.py) publishes exactly the core's commands."""
import math

import numpy as np
import pytest

from local_pipeline import KEYS, follow_path, polyline
from omninav.schemas import decode
from omninav.schemas.messages import (GOAL_REACHED, Costmap, Header, LocalCommand, MapMetaData, Odometry, Path, Pose2D,
                                      Tracks, Transform, Twist)
from omninav.geometry.frames import RobotFrames
from omninav.geometry.se2 import integrate
from omninav.services.local_planner.control import ControlInputs, LocalControl, LocalControlParams
from omninav.services.local_planner.dwa import path_maps
from omninav.services.local_planner.maneuver import ManeuverDriver, Segment
from omninav.services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from omninav.services.runtime.node import NS_PER_S

DT = 0.05                       # s: the default 20 Hz control period
TICK_NS = 50_000_000
INFO = MapMetaData(resolution=0.05, width=160, height=120, origin=Pose2D(-2.0, -3.0))   # x -2..6, y -3..3 m
LETHAL = 254
EAST = polyline([(0.0, 0.0), (2.4, 0.0)], 0.6)


def costmap(*boxes) -> Costmap:
    """A local costmap in the odom frame, lethal inside the boxes (x0, y0, x1, y1) and free elsewhere."""
    data = np.zeros((INFO.height, INFO.width), np.uint8)
    for x0, y0, x1, y1 in boxes:
        rows = slice(round((y0 - INFO.origin.y) / INFO.resolution), round((y1 - INFO.origin.y) / INFO.resolution))
        cols = slice(round((x0 - INFO.origin.x) / INFO.resolution), round((x1 - INFO.origin.x) / INFO.resolution))
        data[rows, cols] = LETHAL
    return Costmap(Header(frame_id="odom"), INFO, data)


def odometry(k: int, pose, velocity=(0.0, 0.0, 0.0)) -> Odometry:
    return Odometry(header=Header(stamp_ns=k * TICK_NS, frame_id="odom"), pose=Pose2D(*(float(v) for v in pose)),
                    twist=Twist(linear_x=float(velocity[0]), linear_y=float(velocity[1]),
                                angular_z=float(velocity[2])))


def drive(core: LocalControl, frames: RobotFrames, pose, grid: Costmap | None, ticks: int = 400):
    """A kinematic loop (the robot moves as commanded): the core's answers until goal_reached, and the
    robot's last pose (odom frame)."""
    pose, velocity, answers = np.array(pose, float), np.zeros(3), []
    for k in range(ticks):
        frames.set_odom(odometry(k, pose))
        answer = core.step(ControlInputs(velocity, frames, grid, None, k * DT))
        answers.append(answer)
        if answer.reason == "goal_reached":
            break
        velocity = answer.twist
        pose = integrate(pose, answer.twist, DT)
    return answers, pose


def phases(answers) -> list[str]:
    """The reasons' statuses, each run of equal ones once."""
    runs = []
    for answer in answers:
        status = answer.reason.split(":")[0]
        if not runs or runs[-1] != status:
            runs.append(status)
    return runs


def test_a_robot_facing_away_turns_on_the_spot_then_dwa_drives_then_the_final_approach_lands_it():
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(), DT)
    core.follow(follow_path(EAST), frames)
    answers, pose = drive(core, frames, (0.0, 0.0, math.pi), costmap())
    assert phases(answers) == ["rotate_to_heading", "", "final_approach", "goal_reached"]
    assert all(a.ok for a in answers)
    turning = [a for a in answers if a.reason == "rotate_to_heading"]
    assert len(turning) > 10 and all(a.twist[0] == a.twist[1] == 0.0 and a.twist[2] != 0.0 for a in turning)
    assert [c for a in answers for c in a.counted] == ["shim/aligned"]     # handed over once
    assert math.hypot(pose[0] - 2.4, pose[1]) <= 0.02 and abs(pose[2] - 0.6) <= 0.02
    assert np.all(answers[-1].twist == 0.0)
    # arrived: it stays arrived
    frames.set_odom(odometry(len(answers), pose))
    assert core.step(ControlInputs(np.zeros(3), frames, costmap(), None, len(answers) * DT)).reason == "goal_reached"


def test_an_arrived_robot_whose_map_pose_is_corrected_off_the_goal_approaches_it_again():
    # the stall of a shoved robot under AMCL: after the final approach had arrived, the localizer's
    # correction (a new map→odom) put the robot 4 cm and 0.05 rad off the goal in the map; an arrival
    # that held regardless answered goal_reached there for good
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(), DT)
    core.follow(follow_path(EAST), frames)
    answers, pose = drive(core, frames, (0.0, 0.0, 0.0), costmap())
    assert answers[-1].reason == GOAL_REACHED
    frames.set_map_odom(Transform(Header(frame_id="map"), "odom", Pose2D(0.0, 0.04, 0.05)))
    again, _ = drive(core, frames, pose, costmap())
    assert again[0].counted == ("arrival_lost",) and phases(again) == ["final_approach", GOAL_REACHED]
    x, y, yaw = frames.robot("map")
    assert math.hypot(x - 2.4, y) <= 0.02 and abs(yaw - 0.6) <= 0.02


def test_an_aligned_robot_is_not_shimmed_and_the_map_frame_goal_is_reached_through_map_odom():
    # odometry started 0.5 m east and 0.2 m north of the map's origin, turned 0.3 rad: the path and
    # goal are in the map frame, the costmap and the odometry in the odom frame
    start = (0.5, 0.2, 0.3)
    frames = RobotFrames("map", "odom", start)
    core = LocalControl(LocalControlParams(), DT)
    goal = polyline([start[:2], (2.5, 1.0)], 0.0)
    core.follow(follow_path(goal), frames)
    heading = math.atan2(1.0 - 0.2, 2.5 - 0.5) - 0.3      # along the path, odom frame
    answers, _ = drive(core, frames, (0.0, 0.0, heading), costmap())
    assert phases(answers) == ["", "final_approach", "goal_reached"]
    x, y, yaw = frames.robot("map")
    assert math.hypot(x - 2.5, y - 1.0) <= 0.02 and abs(yaw) <= 0.02


def test_a_final_approach_across_an_obstacle_leaves_the_robot_to_the_controller_until_the_line_is_free():
    # the path goes round a box to a goal 1 m east; the straight line to the goal crosses the box
    around = polyline([(0.0, 0.0), (0.0, 0.8), (1.0, 0.8), (1.0, 0.0)], -math.pi / 2)
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(), DT)
    core.follow(follow_path(around), frames)
    answers, pose = drive(core, frames, (0.0, 0.0, math.pi / 2), costmap((0.35, -0.5, 0.65, 0.4)))
    assert phases(answers) == ["", "final_approach", "goal_reached"]
    blocked = [k for k, a in enumerate(answers) if "approach_blocked" in a.counted]
    assert blocked and all(answers[k].reason == "" for k in blocked)       # DWA drove those ticks
    assert blocked[-1] < next(k for k, a in enumerate(answers) if a.reason == "final_approach")
    assert math.hypot(pose[0] - 1.0, pose[1]) <= 0.02


def test_a_shim_turn_that_would_sweep_into_a_wall_is_left_to_the_controller():
    # the robot (0.83 x 0.64 m) along a wall 0.45 m to its left, its path behind it: turned in place,
    # its front corner would sweep into the wall (tests/test_shim.py)
    west = EAST * (-1.0, 1.0, 1.0)
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(), DT)
    core.follow(follow_path(west), frames)
    frames.set_odom(odometry(0, (0.0, 0.0, 0.0)))
    answer = core.step(ControlInputs(np.zeros(3), frames, costmap((-2.0, 0.45, 6.0, 3.0)), None, 0.0))
    assert answer.counted == ("shim/blocked",) and answer.reason != "rotate_to_heading"
    without_wall = LocalControl(LocalControlParams(), DT)
    without_wall.follow(follow_path(west), frames)
    assert without_wall.step(ControlInputs(np.zeros(3), frames, costmap(), None, 0.0)).reason == "rotate_to_heading"


def test_dwa_backing_up_arms_the_shim_again_and_the_robot_turns_round_once_the_turn_is_free():
    # a differential robot 3 cm from a wall ahead, its path behind it: the shim's turn would sweep its
    # front corners into the wall (blocked, handed over); DWA backs away (escape), which arms the shim
    # again, and once backed far enough the turn is free and the shim turns the robot round — rather
    # than DWA creeping at the wall and backing off in turn (BARN world 58)
    west = polyline([(0.0, 0.0), (-2.0, 0.0)], math.pi)
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(holonomic_robot=False, min_vel_x=0.0), DT)
    core.follow(follow_path(west), frames)
    answers, pose = drive(core, frames, (0.0, 0.0, 0.0), costmap((0.445, -3.0, 0.6, 3.0)), 600)
    counted = [c for a in answers for c in a.counted]
    assert counted[0] == "shim/blocked" and "shim/rearmed" in counted
    first_escape = next(k for k, a in enumerate(answers) if a.reason == "escape")
    assert any(a.reason == "rotate_to_heading" for a in answers[first_escape:])
    assert answers[-1].reason == GOAL_REACHED and math.hypot(pose[0] + 2.0, pose[1]) <= 0.02


def tracks(t: float, *people) -> Tracks:
    """Tracks (odom frame) stamped t of people given as (x, y, vx, vy)."""
    return Tracks(header=Header(stamp_ns=round(t * NS_PER_S), frame_id="odom"), ids=np.arange(len(people)),
                  states=np.array(people, float).reshape(-1, 4), covariances=np.zeros((len(people), 4, 4)),
                  radii=np.full(len(people), 0.3))


def test_a_shim_turn_with_a_person_coming_is_left_to_the_controller():
    # its path behind it, a person walking up from behind along its lane: turned in place, the robot
    # would stand in their way while the corners swing; someone far off or walking away changes nothing
    west = EAST * (-1.0, 1.0, 1.0)
    frames = RobotFrames("map", "odom")
    frames.set_odom(odometry(0, (0.0, 0.0, 0.0)))
    for person, turns in (((-1.6, 0.0, 1.2, 0.0), False), ((-5.0, 0.0, 1.2, 0.0), True), ((-1.6, 0.0, -1.2, 0.0), True)):
        core = LocalControl(LocalControlParams(), DT)
        core.follow(follow_path(west), frames)
        answer = core.step(ControlInputs(np.zeros(3), frames, costmap(), tracks(0.0, person), 0.0))
        assert (answer.reason == "rotate_to_heading") is turns, person
        if not turns:
            assert answer.counted == ("shim/blocked",)


def test_no_path_is_idle_no_costmap_brakes_and_an_empty_path_stops():
    frames = RobotFrames("map", "odom")
    core = LocalControl(LocalControlParams(), DT)
    frames.set_odom(odometry(0, (0.0, 0.0, 0.0)))
    idle = core.step(ControlInputs(np.zeros(3), frames, costmap(), None, 0.0))
    assert (idle.ok, idle.reason, idle.trajectory.shape) == (True, "idle", (0, 3)) and np.all(idle.twist == 0.0)
    core.follow(follow_path(EAST), frames)
    moving = np.array([0.4, 0.0, 0.0])
    blind = core.step(ControlInputs(moving, frames, None, None, 0.0))
    assert not blind.ok and blind.reason.startswith("no_costmap:") and 0.0 <= blind.twist[0] < 0.4   # braking
    answers, pose = drive(core, frames, (0.0, 0.0, 0.0), costmap(), ticks=20)
    assert answers[-1].reason == "" and answers[-1].twist[0] > 0.3 and core.path is not None     # driving
    core.follow(Path(header=Header(frame_id="map"), goal_id="g1"), frames)
    frames.set_odom(odometry(21, pose))
    stop = core.step(ControlInputs(answers[-1].twist, frames, costmap(), None, 21 * DT))
    assert core.path is None and (stop.ok, stop.reason) == (True, "idle") and np.all(stop.twist == 0.0)


@pytest.mark.parametrize("controller", ["dwa", "follower"])
def test_the_node_publishes_the_bare_cores_commands(controller):
    """The same odometry, costmap and path into the node (deferred by request_delay_s) and into the
    core (followed from the tick the node puts them into effect): the same commands, tick by tick."""
    start = (0.3, -0.2, 0.1)
    params = LocalPlannerNodeParams(initial_pose_x=start[0], initial_pose_y=start[1], initial_pose_a=start[2],
                                    controller=controller)
    node = LocalPlannerNode(params)
    published = []
    node.cmd_pub.sink = lambda pub, payload, stamp: published.append(decode(payload, LocalCommand))
    index = {key: i for i, key in enumerate(inp.key for inp in node.inputs)}
    grid, path = costmap((1.2, 0.6, 1.6, 1.0)), follow_path(polyline([start[:2], (2.6, 0.2)], 0.4))
    sent_ns = 20_000_000
    grid.header.stamp_ns = path.header.stamp_ns = sent_ns
    pose, odometries = np.array([0.0, 0.0, 0.0]), []
    for k in range(1, 200):
        if k == 1:
            node.process(index[KEYS.robot("costmap/local")], grid)
            node.process(index[KEYS.robot("follow_path")], path)
        velocity = (published[-1].linear_x, published[-1].linear_y, published[-1].angular_z) if published else (0, 0, 0)
        odometries.append(odometry(k, pose, velocity))
        node.process(index[KEYS.robot("odom")], odometries[-1])
        pose = integrate(pose, np.array([published[-1].linear_x, published[-1].linear_y, published[-1].angular_z]), DT)
    assert [c.header.stamp_ns for c in published] == [o.header.stamp_ns for o in odometries]
    assert {c.reason for c in published} >= {"idle", "", "final_approach", "goal_reached"}

    core, frames = LocalControl(params, DT), RobotFrames("map", "odom", start)
    in_effect = None
    for msg, command in zip(odometries, published):
        frames.set_odom(msg)
        if in_effect is None and msg.header.stamp_ns > sent_ns + params.request_delay_s * NS_PER_S:
            in_effect = grid
            core.follow(path, frames)
        velocity = np.array([msg.twist.linear_x, msg.twist.linear_y, msg.twist.angular_z])
        answer = core.step(ControlInputs(velocity, frames, in_effect, None, msg.header.stamp_ns / NS_PER_S))
        assert (command.linear_x, command.linear_y, command.angular_z) == tuple(float(v) for v in answer.twist)
        assert (command.ok, command.reason, command.goal_id) == (answer.ok, answer.reason,
                                                                 path.goal_id if core.path is not None else "")


def test_a_robot_in_a_slot_too_narrow_to_turn_in_backs_out_and_turns_by_a_maneuver():
    # facing the closed end of a slot its footprint fits but cannot turn in, the path behind it: the
    # shim's turn is blocked and DWA, which samples no backing but its escape, creeps to the end and
    # backs off in turn; once it has stalled, the maneuver backs out of the slot and turns round
    slot = costmap((0.5, 0.45, 3.5, 0.6), (0.5, -0.6, 3.5, -0.45), (3.0, -0.6, 3.2, 0.6))
    west = polyline([(2.0, 0.0), (-1.0, 0.0)], math.pi)
    frames = RobotFrames("map", "odom")
    results = {}
    for enabled in (True, False):
        core = LocalControl(LocalControlParams(holonomic_robot=False, min_vel_x=0.0,
                                               maneuver={"enabled": enabled}), DT)
        core.follow(follow_path(west), frames)
        results[enabled] = drive(core, frames, (2.0, 0.0, 0.0), slot, 1200)
    answers, pose = results[True]
    counted = [c for a in answers for c in a.counted]
    assert "maneuver/planned" in counted and any(a.reason == "maneuver" for a in answers)
    assert answers[-1].reason == GOAL_REACHED and math.hypot(pose[0] + 1.0, pose[1]) <= 0.02
    stuck, stuck_pose = results[False]
    assert stuck[-1].reason != GOAL_REACHED and stuck_pose[0] > 0.5     # still in the slot


def drive_maneuver(core: LocalControl, grid: Costmap, pose) -> np.ndarray:
    """A kinematic loop over the core's maneuver alone, until it ends or is dropped: the last pose."""
    pose = np.asarray(pose, float)
    for _ in range(400):
        answer = core._maneuver(pose, grid)
        if answer is None:
            break
        pose = integrate(pose, answer.twist, DT)
    return pose


def test_a_robot_wedged_on_the_costmap_gets_a_maneuver_off_the_cells_it_stands_on():
    # lethal cells under the robot's own side by its rear corner (a post rasterised a cell into it, a noisy
    # mark): every pose near it is illegal by the robot's outline, so the search from it found
    # nothing and the robot stood (building-diff-3, 40 s in a door); those cells forgiven, as DWA's
    # escape forgives them, the maneuver drives it on along its path
    grid = costmap((-0.45, 0.3, -0.2, 0.45))
    params = LocalControlParams(holonomic_robot=False, min_vel_x=0.0)
    core, frames = LocalControl(params, DT), RobotFrames("map", "odom")
    core.follow(follow_path(EAST), frames)
    robot = np.zeros(3)
    assert core.footprint_check.setup(robot, grid.data, grid.info).wedged
    maps = path_maps(EAST, robot, grid.info, grid.data, core.controller.distances)
    first = core._plan_maneuver(robot, grid, maps)
    assert first is not None and first.reason == "maneuver" and "maneuver/planned" in core._counted
    pose = drive_maneuver(core, grid, robot)
    assert pose[0] >= params.maneuver_params().progress - 0.1 and abs(pose[1]) < 0.1


def test_a_maneuver_planned_beside_a_wall_within_the_monitors_zone_is_driven_not_dropped():
    # a wall inside the collision monitor's stop zone (not under the robot's own outline) where a
    # maneuver was planned: held to that zone, its every first step was "blocked" and the robot
    # stood by a door for 25 s (building-mecanum-20); it is held to the padding that pose allows
    grid = costmap((-1.0, 0.35, 3.0, 0.40))
    params = LocalControlParams(holonomic_robot=False, min_vel_x=0.0)
    core = LocalControl(params, DT)
    fc, robot = core.footprint_check, np.zeros(3)
    assert not fc.setup(robot, grid.data, grid.info).wedged
    assert not fc.check_poses(fc.monitor_check(grid.data, grid.info), robot[None], grid.data, grid.info)[0]
    dwa = core.dwa_params
    core.maneuver = ManeuverDriver([Segment("drive", 1.0)], robot, core.maneuver_params,
                                   (dwa.max_vel_x, dwa.max_vel_theta), (dwa.acc_lim_x, dwa.acc_lim_theta))
    core._maneuver_from = robot.copy(), False
    pose = drive_maneuver(core, grid, robot)
    assert "maneuver/blocked" not in core._counted and pose[0] >= 0.95 and abs(pose[1]) < 0.01


@pytest.mark.parametrize("speed, stalls", [(0.05, True), (0.0, True), (0.1, False)])
def test_a_robot_creeping_slower_than_stall_radius_over_stall_time_has_stalled(speed, stalls):
    # the window slides: a robot creeping at 5 cm/s is stalled once stall_time has passed, wherever
    # it started; one making 10 cm/s (0.4 m in 4 s) is not
    core = LocalControl(LocalControlParams(holonomic_robot=False), DT)
    m = core.maneuver_params
    ticks = [k for k in range(int(3 * m.stall_time / DT))
             if core._stalled(np.array([speed * k * DT, 0.0, 0.0]), None)]
    assert bool(ticks) == stalls
    if stalls:
        assert ticks[0] * DT == pytest.approx(m.stall_time)


def test_where_the_padded_footprint_finds_no_way_the_maneuver_searches_within_the_monitors_zone():
    # a gap 0.80 m wide on the path: the robot (0.636 m wide) padded 0.1 m does not pass it, its
    # outline grown by the monitor's 0.02 m stop zone does; the search kept the padding and found
    # nothing twelve times over while the robot stood in a pocket (BARN world 58, the Jackal with
    # its wheels in its footprint)
    grid = costmap((0.9, 0.4, 1.1, 3.0), (0.9, -3.0, 1.1, -0.4))
    params = LocalControlParams(holonomic_robot=False, min_vel_x=0.0, footprint_padding=0.1, stop_padding=0.02)
    core, frames = LocalControl(params, DT), RobotFrames("map", "odom")
    core.follow(follow_path(EAST), frames)
    robot = np.zeros(3)
    maps = path_maps(EAST, robot, grid.info, grid.data, core.controller.distances)
    first = core._plan_maneuver(robot, grid, maps)
    assert first is not None and core._counted == ["maneuver/unpadded", "maneuver/planned"]
    pose = drive_maneuver(core, grid, robot)
    assert pose[0] >= params.maneuver_params().progress - 0.05 and abs(pose[1]) < 0.05   # into the gap
