"""The path follower in a kinematic simulation: commands integrated exactly with the SE(2) helpers."""
import math

import numpy as np
import pytest

from omninav.services.local_planner.path_follower import Arc, Line, PathFollower, segments_from_poses
from omninav.services.local_planner.params import FollowerParams
from omninav.geometry.se2 import integrate

DT = 0.05


def run(follower, pose, steps=2000):
    pose = np.array(pose, float)
    commands, poses = [], [pose]
    for _ in range(steps):
        command = follower.step(pose, DT)
        commands.append(command)
        if command.done:
            break
        pose = integrate(pose, command.twist, DT)
        poses.append(pose)
    return commands, np.array(poses)


@pytest.mark.parametrize("drive", ["holonomic", "diff"])
def test_a_straight_line_is_tracked_and_the_end_reached_within_a_centimetre(drive):
    follower = PathFollower(FollowerParams(drive=drive), [Line((0.0, 0.0), (3.0, 1.0))])
    commands, poses = run(follower, (0.0, 0.08, 0.15))   # starting 8 cm off and 9° askew
    assert commands[-1].done
    assert math.dist(poses[-1][:2], (3.0, 1.0)) < 0.01
    settled = [abs(c.cross_track) for c in commands if c.s > 1.5]
    assert max(settled) < 0.01
    if drive == "diff":
        assert all(c.twist[1] == 0.0 for c in commands)


@pytest.mark.parametrize("drive", ["holonomic", "diff"])
@pytest.mark.parametrize("sweep", [math.pi / 2, -math.pi])
def test_arcs_are_tracked_with_small_cross_track_error(drive, sweep):
    radius = 1.2
    arc = Arc((0.0, math.copysign(radius, sweep)), radius, -math.copysign(math.pi / 2, sweep), sweep)
    lead_in = Line((-1.0, 0.0), (0.0, 0.0))
    end = arc.point(arc.length)
    follower = PathFollower(FollowerParams(drive=drive), [lead_in, arc])
    commands, poses = run(follower, (-1.0, 0.0, 0.0))
    assert commands[-1].done
    assert max(abs(c.cross_track) for c in commands) < 0.02
    assert math.dist(poses[-1][:2], end) < 0.01
    # and the robot really was on the arc: every pose within 2 cm of the circle
    on_arc = poses[poses[:, 0] > 0.05]
    assert np.all(np.abs(np.hypot(on_arc[:, 0] - arc.center[0], on_arc[:, 1] - arc.center[1]) - radius) < 0.02)


@pytest.mark.parametrize("exponent", [0.3, 0.5, 0.8])
def test_the_final_approach_follows_the_deceleration_law(exponent):
    params = FollowerParams(decel_exponent=exponent, decel_distance=0.8, cruise_speed=0.4)
    follower = PathFollower(params, [Line((0.0, 0.0), (2.0, 0.0))])
    commands, poses = run(follower, (0.0, 0.0, 0.0))
    approach = [c for c in commands if not c.done and c.remaining < params.decel_distance]
    assert len(approach) > 10
    for c in approach:
        s = params.decel_distance - c.remaining                  # metres into the final approach
        law = ((params.decel_distance - s) / params.decel_distance) ** exponent * params.cruise_speed
        assert c.speed == pytest.approx(min(law, c.remaining / DT), rel=1e-9)
    cruising = [c.speed for c in commands if c.remaining > params.decel_distance + 0.1 and c.s > 0.2]
    assert min(cruising) == pytest.approx(params.cruise_speed)
    speeds = [c.speed for c in approach]
    assert all(a >= b for a, b in zip(speeds, speeds[1:]))       # slowing all the way in
    assert commands[-1].done and abs(poses[-1][0] - 2.0) < 0.01


def test_a_global_planner_polyline_is_followed():
    t = np.linspace(0.0, math.pi, 60)
    path = np.column_stack([2.0 * t / math.pi, 0.5 * np.sin(t), np.zeros_like(t)])
    follower = PathFollower(FollowerParams(cruise_speed=0.3), segments_from_poses(path))
    commands, poses = run(follower, (0.0, 0.0, 0.0))
    assert commands[-1].done and math.dist(poses[-1][:2], path[-1, :2]) < 0.01
    assert max(abs(c.cross_track) for c in commands) < 0.03
