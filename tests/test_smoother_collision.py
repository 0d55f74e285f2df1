"""Velocity smoother and collision monitor."""
import math

import numpy as np
import pytest

from omninav.schemas.messages import LaserScan
from omninav.services.collision_monitor.collision import (APPROACH_TOLERANCE_SPEED, CollisionMonitor, distance_to_outline,
                                                          robot_frame_points)
from omninav.geometry.se2 import integrate
from omninav.geometry.movers import Movers
from omninav.services.collision_monitor.collision import CollisionMonitorParams
from omninav.services.velocity_smoother.smoother import VelocitySmootherParams
from omninav.services.velocity_smoother.smoother import VelocitySmoother

PARAMS = VelocitySmootherParams(max_velocity=(0.5, 0.5, 2.0), min_velocity=(-0.5, -0.5, -2.0),
                                max_accel=(1.0, 0.8, 2.0), max_decel=(-2.0, -1.6, -4.0))
SEC = 1_000_000_000


def run(smoother, commands, steps):
    """Step the smoother at its frequency; commands maps a step index to a twist sent just before."""
    period_ns = int(SEC / smoother.params.smoothing_frequency)
    outputs = []
    for k in range(steps):
        if k in commands:
            smoother.command(commands[k], k * period_ns)
        outputs.append(smoother.step(k * period_ns))
    return outputs


def test_the_smoother_respects_acceleration_and_deceleration_limits():
    smoother = VelocitySmoother(PARAMS)
    # full speed ahead, then a hard reverse, resent every step so no timeout
    commands = {k: (0.5, -0.5, 2.0) if k < 30 else (-0.5, 0.5, -2.0) for k in range(60)}
    twists = np.array([o.twist for o in run(smoother, commands, 60)])
    dt = 1.0 / PARAMS.smoothing_frequency
    change = np.abs(np.diff(np.vstack([np.zeros(3), twists]), axis=0))
    assert np.all(change <= np.array([2.0, 1.6, 4.0]) * dt + 1e-12)   # never beyond the deceleration limit
    speeding_up = (np.abs(twists[1:]) > np.abs(twists[:-1])) & (twists[1:] * twists[:-1] > 0)
    assert np.all(change[1:][speeding_up] <= (np.array([1.0, 0.8, 2.0]) * dt + 1e-12)[np.nonzero(speeding_up)[1]])
    assert np.allclose(twists[29], (0.5, -0.5, 2.0))                   # reached the target
    assert np.isclose(twists[5, 0], 6 * 1.0 * dt)                      # ramping at max_accel
    assert np.allclose(twists[-1], (-0.5, 0.5, -2.0))
    assert np.all(np.abs(twists) <= np.array([0.5, 0.5, 2.0]) + 1e-12)


def test_the_smoother_stops_when_commands_time_out():
    smoother = VelocitySmoother(PARAMS)
    outputs = run(smoother, {k: (0.5, 0.0, 1.0) for k in range(20)}, 60)
    timeout_steps = PARAMS.velocity_timeout * PARAMS.smoothing_frequency
    assert not any(o.timed_out for o in outputs[:20 + int(timeout_steps)])
    late = [o for o in outputs[20 + int(timeout_steps) + 1:]]
    assert late and all(o.timed_out for o in late)
    assert np.allclose(outputs[-1].twist, 0.0)
    # the stop is at the deceleration limit, not a jump
    speeds = np.array([o.twist[0] for o in outputs])
    assert np.all(np.diff(speeds) >= -2.0 / PARAMS.smoothing_frequency - 1e-12)


def test_the_smoother_without_any_command_stays_still_and_applies_the_deadband():
    assert np.allclose(run(VelocitySmoother(PARAMS), {}, 5)[-1].twist, 0.0)
    params = VelocitySmootherParams(deadband_velocity=(0.05, 0.0, 0.1))
    out = run(VelocitySmoother(params), {0: (0.03, 0.0, 0.05), 1: (0.03, 0.0, 0.05)}, 2)
    assert np.allclose(out[-1].twist, 0.0)


def scan_with_obstacle(distance, bearing=0.0, width=0.3):
    """A 360-beam scan, everything out of range except an obstacle `width` wide at `distance`."""
    angles = -math.pi + np.arange(360) * (2 * math.pi / 360)
    ranges = np.full(360, np.inf, np.float32)
    half = math.atan2(width / 2, distance)
    ranges[np.abs(np.angle(np.exp(1j * (angles - bearing)))) <= half] = distance
    return LaserScan(angle_min=-math.pi, angle_max=math.pi - 2 * math.pi / 360, angle_increment=2 * math.pi / 360,
                     range_min=0.05, range_max=10.0, ranges=ranges)


@pytest.mark.parametrize("bearing", [0.0, math.pi / 2, math.pi])
def test_the_collision_monitor_stops_slows_or_lets_pass(bearing):
    monitor = CollisionMonitor(CollisionMonitorParams())    # 0.832 x 0.636 m footprint
    edge = 0.416 if bearing in (0.0, math.pi) else 0.318     # footprint half-size towards the obstacle
    cmd = 0.4 * np.array([math.cos(bearing), math.sin(bearing), 0.0]) + (0.0, 0.0, 0.5)   # towards it, turning
    near = monitor.check(cmd, robot_frame_points(scan_with_obstacle(edge + 0.03, bearing), (0.0, 0.0, 0.0)))
    assert near.action == "stop" and np.all(near.twist == 0.0) and near.points >= 4
    middle = monitor.check(cmd, robot_frame_points(scan_with_obstacle(edge + 0.2, bearing), (0.0, 0.0, 0.0)))
    assert middle.action == "slowdown" and np.allclose(middle.twist, cmd * 0.5)
    far = monitor.check(cmd, robot_frame_points(scan_with_obstacle(edge + 0.5, bearing), (0.0, 0.0, 0.0)))
    assert far.action == "none" and np.array_equal(far.twist, cmd)


@pytest.mark.parametrize("cmd, action", [((-0.2, 0.0, 0.0), "none"), ((0.0, 0.2, 0.0), "none"),
                                          ((0.05, 0.0, 0.0), "stop"), ((0.0, 0.2, 0.8), "stop")],
                         ids=["back-away", "slide-along", "creep-closer", "swing-a-corner-into-it"])
def test_within_the_stop_zone_only_a_command_that_approaches_the_obstacle_is_stopped(cmd, action):
    """A robot 3 cm from a wall ahead may still back away or slide along it (at full speed: it
    brings nothing nearer than the wall is), not come closer."""
    monitor = CollisionMonitor(CollisionMonitorParams())
    wall = [(0.446, y) for y in np.linspace(-0.6, 0.6, 25)]
    result = monitor.check(cmd, wall)
    assert result.action == action
    assert np.allclose(result.twist, 0.0 if action == "stop" else np.asarray(cmd))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_the_slowdown_zone_slows_a_robot_closing_in_not_one_keeping_its_clearance(side):
    """Through a door or along a wall 0.15 m beside the robot the clearance stays as it is: full
    speed. Turning towards the wall, or a wall ahead within the zone, is slowed."""
    monitor = CollisionMonitor(CollisionMonitorParams())
    wall = [(x, side * (0.318 + 0.15)) for x in np.linspace(-1.5, 1.5, 61)]
    along = monitor.check((0.5, 0.0, 0.0), wall)
    assert along.action == "none" and np.allclose(along.twist, (0.5, 0.0, 0.0))
    towards = monitor.check((0.5, side * 0.2, 0.0), wall)
    assert towards.action == "slowdown" and np.allclose(towards.twist, (0.25, side * 0.1, 0.0))
    ahead = [(0.416 + 0.2, y) for y in np.linspace(-0.5, 0.5, 21)]
    assert monitor.check((0.5, 0.0, 0.0), ahead).action == "slowdown"


def test_the_collision_monitor_ignores_fewer_than_min_points_and_uses_the_sensor_pose():
    monitor = CollisionMonitor(CollisionMonitorParams(min_points=4))
    assert monitor.check((0.3, 0, 0), [[0.43, 0.0], [0.43, 0.05], [0.43, -0.05]]).action == "none"
    # a laser mounted 0.3 m ahead sees an obstacle 0.15 m in front of it: 0.45 m from the centre
    result = monitor.check((0.3, 0, 0), robot_frame_points(scan_with_obstacle(0.15, width=0.2), (0.3, 0.0, 0.0)))
    assert result.action == "stop"


def movers(*tracks) -> Movers:
    """Tracks (x, y, vx, vy, radius) in the robot frame, known exactly."""
    t = np.array(tracks, float).reshape(-1, 5)
    return Movers(t[:, :2], t[:, 2:4], t[:, 4], np.zeros((len(t), 3)))


@pytest.mark.parametrize("track, cmd, action", [
    ((3.0, 0.0, -0.8, 0.0, 0.3), (0.5, 0.0, 0.0), "approach"),     # head-on, met within 2 s: slowed or stopped
    ((1.5, -1.8, 0.0, 0.9, 0.3), (0.5, 0.0, 0.0), "approach"),     # crossing ahead, met on the way
    ((6.0, 0.0, -0.5, 0.0, 0.3), (0.5, 0.0, 0.0), "none"),         # head-on but beyond 2 s
    ((2.0, 0.0, -1.5, 0.0, 0.3), (-0.3, 0.0, 0.0), "none"),        # coming at the robot, which backs away: sooner standing
    ((-2.0, 0.0, 0.0, 0.0, 0.3), (0.5, 0.0, 0.0), "none"),         # behind, standing
])
def test_the_collision_monitor_slows_or_stops_a_command_that_meets_a_track_sooner_than_standing(track, cmd, action):
    monitor = CollisionMonitor(CollisionMonitorParams())
    result = monitor.check(cmd, np.zeros((0, 2)), movers(track))
    assert result.action == action, result.reason
    if action == "approach":
        ttc = monitor.time_to_collision(result.twist, movers(track))
        standing = monitor.time_to_collision(np.zeros(3), movers(track))
        assert not ttc < min(monitor.params.time_before_collision, standing)
        assert np.linalg.norm(result.twist) < np.linalg.norm(cmd)


def test_time_to_collision_is_when_the_track_reaches_the_stop_zone():
    monitor = CollisionMonitor(CollisionMonitorParams(stop_padding=0.0))
    # front edge at x = 0.416; a 0.3 m circle from x = 2.0 at 1 m/s touches it after 1.284 s
    ttc = monitor.time_to_collision(np.zeros(3), movers((2.0, 0.0, -1.0, 0.0, 0.3)))
    assert ttc == pytest.approx(1.3, abs=1e-9)     # the first 0.1 s step at or after


def test_nothing_close_behind_slows_a_robot_driving_away_but_backing_into_it_is_slowed():
    monitor = CollisionMonitor(CollisionMonitorParams())
    behind = [(-0.416 - 0.2, y) for y in np.linspace(-0.25, 0.25, 11)]        # 0.2 m behind: the slowdown zone
    cmd = (0.4, 0.0, 0.0)
    assert monitor.check(cmd, behind).action == "none"                       # a wall (no track there)
    assert monitor.check((-0.2, 0.0, 0.0), behind).action == "slowdown"
    person = movers((-0.416 - 0.5, 0.0, 0.8, 0.0, 0.3))                      # a person right there, coming on
    result = monitor.check(cmd, behind, person)
    assert result.action == "none" and np.array_equal(result.twist, cmd)


FRONT, LEFT = (0.416 + 0.3 + 0.03, 0.0), (0.3, 0.318 + 0.3 + 0.03)   # 3 cm off the footprint: in the stop zone


@pytest.mark.parametrize("where, cmd, action", [
    (FRONT, (0.05, 0.0, 0.0), "approach"),    # creeping on: the contact would be the robot's (sim fault_speed 0.02)
    (LEFT, (0.0, 0.0, 0.3), "approach"),      # turning swings the left side towards the person
    (FRONT, (-0.2, 0.0, 0.0), "none"),        # backing away
    (FRONT, (0.0, 0.3, 0.0), "none"),         # strafing out of their way
    (LEFT, (0.0, 0.0, -0.3), "none"),         # turning the other way
])
def test_a_person_already_in_the_stop_zone_is_not_closed_in_on(where, cmd, action):
    # a person standing in the 5 cm stop zone: standing still the robot never touches them, so only
    # what the command itself does to the gap can matter
    monitor = CollisionMonitor(CollisionMonitorParams())
    result = monitor.check(cmd, np.zeros((0, 2)), movers((*where, 0.0, 0.0, 0.3)))
    assert result.action == action, result.reason
    if action == "approach":
        assert np.allclose(result.twist, 0.0)


@pytest.mark.parametrize("gap, track_off", [(0.03, 0.10), (0.2, 0.12)])   # the stop zone; the slowdown zone
@pytest.mark.parametrize("cmd, action", [
    ((0.02, 0.0, 0.0), "approach"),       # creeping on at the simulator's fault_speed
    ((0.0, 0.0, 0.15), "approach"),       # turning swings the front edge into them
    ((0.0, 0.3, 0.0), "none"),            # strafing out of their way
    ((-0.2, 0.0, 0.0), "none"),           # backing away
])
def test_a_person_pressing_on_is_not_closed_in_on_where_their_track_is_off(gap, track_off, cmd, action):
    # the scan shows the person `gap` off the front edge, across its whole width; their track puts
    # them `track_off` farther on: by the track alone a slow creep would not reach them in time
    monitor = CollisionMonitor(CollisionMonitorParams())
    edge = 0.416 + gap
    surface = [(edge, y) for y in np.linspace(-0.15, 0.15, 13)]
    person = movers((edge + 0.3 + track_off, 0.0, 0.0, 0.0, 0.3))
    assert monitor.check(cmd, np.zeros((0, 2)), person).action == "none"     # the track alone lets it pass
    result = monitor.check(cmd, surface, person)
    assert result.action == action, result.reason
    if action == "approach":      # what is left of the command closes in slower than the tolerance (but on noise)
        step = monitor.params.approach_check_s
        dx, dy, dtheta = integrate((0.0, 0.0, 0.0), result.twist, step)
        c, s = math.cos(dtheta), math.sin(dtheta)
        moved = [(c * (x - dx) + s * (y - dy), -s * (x - dx) + c * (y - dy)) for x, y in surface]
        footprint = np.asarray(monitor.params.footprint)
        closing = distance_to_outline(np.asarray(surface), footprint) - distance_to_outline(np.asarray(moved), footprint)
        assert np.count_nonzero(closing > APPROACH_TOLERANCE_SPEED * step + 1e-9) < monitor.params.min_points
