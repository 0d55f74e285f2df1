"""The maneuver core (services/local_planner/maneuver.py): its search finds turns and straight drives
whose every pose the footprint check allows, ending nearer the local goal and facing the way on,
with no more changes between turning and driving than the way needs; walled in, it finds none; its
driver drives the segments as planned, each in about the time its distance takes."""
import math

import numpy as np
import pytest

from omninav.geometry.se2 import integrate, wrap_angle
from omninav.schemas.messages import MapMetaData, Pose2D
from omninav.services.local_planner.dwa import path_maps
from omninav.services.local_planner.footprint_check import FootprintCheck
from omninav.services.local_planner.maneuver import (DRIVE_TOLERANCE, FACING, SETTLE_S, TURN_STEP, TURN_TOLERANCE,
                                                     ManeuverDriver, ManeuverParams, Segment, plan_maneuver)

INFO = MapMetaData(resolution=0.05, width=160, height=120, origin=Pose2D(-2.0, -3.0))   # x -2..6, y -3..3 m
FOOTPRINT = np.array([[0.42, 0.32], [-0.42, 0.32], [-0.42, -0.32], [0.42, -0.32]])
DT = 0.05
TOP, ACCEL = (2.0, 3.0), (2.5, 3.2)   # the robot's limits: m/s and rad/s, m/s² and rad/s²


def grid(*boxes) -> np.ndarray:
    data = np.zeros((INFO.height, INFO.width), np.uint8)
    for x0, y0, x1, y1 in boxes:
        data[round((y0 + 3.0) / 0.05):round((y1 + 3.0) / 0.05), round((x0 + 2.0) / 0.05):round((x1 + 2.0) / 0.05)] = 254
    return data


def along(a, b, spacing=0.05) -> np.ndarray:
    n = math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / spacing)
    yaw = math.atan2(b[1] - a[1], b[0] - a[0])
    return np.array([[a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n, yaw] for k in range(n + 1)])


def driven(start, segments, turn_step=math.radians(1), drive_step=0.01) -> np.ndarray:
    """The poses the segments pass through, exactly as planned, 1 cm and 1° apart (or as given)."""
    poses = [np.array(start, float)]
    for segment in segments:
        x, y, th = poses[-1]
        if segment.kind == "turn":
            turn = float(wrap_angle(segment.value - th))
            n = max(1, math.ceil(abs(turn) / turn_step))
            poses += [np.array([x, y, th + turn * k / n]) for k in range(1, n + 1)]
        else:
            n = max(1, math.ceil(abs(segment.value) / drive_step))
            poses += [np.array([x + math.cos(th) * segment.value * k / n, y + math.sin(th) * segment.value * k / n, th])
                      for k in range(1, n + 1)]
    return np.array(poses)


SLOT = grid((0.5, 0.45, 3.5, 0.6), (0.5, -0.6, 3.5, -0.45), (3.0, -0.6, 3.2, 0.6))   # open to the west


def test_the_maneuver_out_of_a_slot_backs_out_turns_round_and_every_pose_is_legal():
    check_of = FootprintCheck(FOOTPRINT, stop_padding=0.05)
    start = (2.0, 0.0, 0.0)                       # facing the slot's closed end; the way on lies west
    maps = path_maps(along((2.0, 0.0), (-1.0, 0.0)), start, INFO, SLOT)
    check = check_of.setup(start, SLOT, INFO)
    params = ManeuverParams()
    segments = plan_maneuver(start, check_of, check, SLOT, INFO, maps.goal_dist, params)
    assert segments and {s.kind for s in segments} == {"turn", "drive"}
    assert segments[0].kind == "drive" and segments[0].value < -1.0     # backs out first: no room to turn
    poses = driven(start, segments)
    assert check_of.check_poses(check, poses, SLOT, INFO).all()
    end = poses[-1]
    rows, cols = (int((end[1] + 3.0) / 0.05), int((end[0] + 2.0) / 0.05))
    start_distance = maps.goal_dist[int(3.0 / 0.05), int(4.0 / 0.05)]
    assert maps.goal_dist[rows, cols] <= start_distance - params.progress
    assert abs(float(wrap_angle(end[2] - math.pi))) <= FACING            # facing west, the way on


def test_in_the_open_the_maneuver_turns_once_and_drives_once():
    # facing east with the way on due north: one turn onto it and one drive, not a staircase of
    # 5° turns and one-cell drives (each change costs a stop and a start when driven)
    open_floor = grid()
    check_of = FootprintCheck(FOOTPRINT, stop_padding=0.05)
    start = (1.0, 0.0, 0.0)
    maps = path_maps(along((1.0, 0.0), (1.0, 2.9)), start, INFO, open_floor)
    params = ManeuverParams()
    segments = plan_maneuver(start, check_of, check_of.setup(start, open_floor, INFO), open_floor, INFO,
                             maps.goal_dist, params)
    assert [s.kind for s in segments] == ["turn", "drive"]
    assert abs(float(wrap_angle(segments[0].value - math.pi / 2))) <= FACING
    assert segments[1].value >= params.progress


def test_a_wedged_robot_maneuvers_away_from_the_cells_it_is_forgiven_not_over_them():
    # a jamb one cell thick under the robot's right side (it stands 2 cm into it by the costmap's
    # cells, 5 cm off it in truth) and the way on due south: forgiven those cells, the search turned
    # the robot's front over them, and the collision monitor, on the scan, stopped the turn for 9 s
    # (building-diff-84); it may move off them, not towards them
    jamb = grid((0.1, -0.35, 0.35, -0.30))
    check_of = FootprintCheck(FOOTPRINT, stop_padding=0.05)
    start = (0.0, 0.0, 0.0)
    check = check_of.setup(start, jamb, INFO)
    assert check.wedged
    forgiven = check_of.escape_check(check, start, jamb, INFO)
    assert len(forgiven.forgiven) > 0
    maps = path_maps(along((0.0, 0.0), (0.0, -2.9)), start, INFO, jamb)
    segments = plan_maneuver(start, check_of, forgiven, jamb, INFO, maps.goal_dist, ManeuverParams())
    assert segments
    searched = driven(start, segments, TURN_STEP, INFO.resolution)   # the poses as the search steps them
    assert check_of.keeps_away(forgiven, searched).all()
    assert check_of.check_poses(forgiven, driven(start, segments), jamb, INFO).all()


def test_walled_in_there_is_no_maneuver():
    box = grid((1.4, -0.6, 2.6, -0.45), (1.4, 0.45, 2.6, 0.6), (1.4, -0.6, 1.5, 0.6), (2.5, -0.6, 2.6, 0.6))
    check_of = FootprintCheck(FOOTPRINT)
    start = (2.0, 0.0, 0.0)
    maps = path_maps(along((2.0, 0.0), (-1.0, 0.0)), start, INFO, box)
    segments = plan_maneuver(start, check_of, check_of.setup(start, box, INFO), box, INFO, maps.goal_dist,
                             ManeuverParams(max_expansions=5000))
    assert segments is None


class LateRobot:
    """A robot that answers a twist LATE_TICKS ticks late, each rate ramped at its acceleration
    limits (ACCEL: the velocity smoother's, the motors'), as the Jackal's command chain does."""
    LATE_TICKS = 2

    def __init__(self, pose):
        self.pose, self.twist = np.array(pose, float), np.zeros(3)
        self.waiting = [np.zeros(3)] * self.LATE_TICKS

    def answer(self, command) -> np.ndarray:
        self.waiting.append(np.asarray(command, float))
        wanted = self.waiting.pop(0)
        limit = np.array([ACCEL[0], 0.0, ACCEL[1]]) * DT
        self.twist = self.twist + np.clip(wanted - self.twist, -limit, limit)
        self.pose = integrate(self.pose, self.twist, DT)
        return self.pose


def drive(driver, robot, ticks=400) -> list[np.ndarray]:
    poses = [robot.pose.copy()]
    while (twist := driver.step(robot.pose, DT)) is not None and len(poses) < ticks:
        poses.append(robot.answer(twist).copy())
    return poses


def test_the_driver_drives_the_segments_as_planned():
    params = ManeuverParams()
    segments = [Segment("drive", -0.4, 0.0), Segment("turn", math.pi / 2), Segment("drive", 0.3, math.pi / 2)]
    robot = LateRobot([1.0, 0.5, 0.0])
    driver = ManeuverDriver(segments, robot.pose, params, TOP, ACCEL)
    poses = drive(driver, robot)
    assert len(poses) < 400 and driver.finished
    pose = poses[-1]
    assert math.hypot(pose[0] - 0.6, pose[1] - 0.8) <= 2 * DRIVE_TOLERANCE + 0.01
    assert abs(float(wrap_angle(pose[2] - math.pi / 2))) <= TURN_TOLERANCE + 0.02


def test_a_turn_ends_settled_on_its_heading_and_the_drive_after_it_holds_the_planned_one():
    # a robot answering late swung on 9° past a turn ended the tick it came within tolerance, and
    # the drive after it, holding the heading it began with, carried the Jackal's corner into a
    # cylinder (BARN world 112)
    params = ManeuverParams()
    segments = [Segment("turn", math.pi / 2), Segment("drive", 0.6, math.pi / 2)]
    robot = LateRobot([0.0, 0.0, 0.0])
    driver = ManeuverDriver(segments, robot.pose, params, TOP, ACCEL)
    poses = np.array(drive(driver, robot))
    assert driver.finished
    driving = poses[poses[:, 1] > 0.05]              # once it has moved off the spot it turned on
    assert len(driving) > 5
    assert np.abs(wrap_angle(driving[:, 2] - math.pi / 2)).max() <= math.radians(4.0)
    assert np.abs(driving[:, 0]).max() <= 0.01        # on the planned line, within a centimetre
    assert abs(poses[-1][1] - 0.6) <= 2 * DRIVE_TOLERANCE + 0.01
    turning = poses[poses[:, 1] <= 0.05]
    assert wrap_angle(turning[:, 2] - math.pi / 2).max() <= math.radians(4.0)   # overshoots by little


def test_a_driver_held_back_gives_up_after_twice_its_time_and_a_settling():
    params = ManeuverParams()
    driver = ManeuverDriver([Segment("drive", 0.5)], (0.0, 0.0, 0.0), params, TOP, ACCEL)
    ticks = 0
    while driver.step((0.0, 0.0, 0.0), DT) is not None:     # the robot never moves
        ticks += 1
    assert not driver.finished
    assert ticks * DT == pytest.approx(2 * 0.5 / params.speed + SETTLE_S + 1.0, abs=2 * DT)


@pytest.mark.parametrize("segment, at_full_speed", [(Segment("drive", 0.5), 0.5 / ManeuverParams().speed),
                                                    (Segment("turn", math.pi / 2), math.pi / 2 / ManeuverParams().turn_speed)])
def test_a_segment_ends_braking_at_the_robots_limits_not_creeping_up_on_its_end(segment, at_full_speed):
    # speeding up and braking at the robot's limits (half of them to brake) and answering late add
    # top / (2 · accel) + top / (2 · braking) + the lateness: under a second to a turn; an approach
    # slowing in proportion to what is left, or one swinging about its end, takes seconds more
    params = ManeuverParams()
    top, accel = (params.speed, ACCEL[0]) if segment.kind == "drive" else (params.turn_speed, ACCEL[1])
    robot = LateRobot(np.zeros(3))
    driver = ManeuverDriver([segment], robot.pose, params, TOP, ACCEL)
    poses = drive(driver, robot)
    assert driver.finished
    late = LateRobot.LATE_TICKS * DT
    assert (len(poses) - 1) * DT <= at_full_speed + top / (2 * accel) + top / accel + late + 3 * DT
