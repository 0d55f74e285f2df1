"""Laser odometry (services/laser_odometry): scans matched to a local map. A robot shoved while its
wheels say it stood still is followed; a loop driven in a room drifts little while the wheels'
odometry drifts far; along a featureless corridor the covariance is much larger than across it and
the pose keeps the wheels' motion there; a refused match is flagged; same inputs, same outputs;
bad parameters are refused by name; the node publishes odom_laser at each scan's stamp once the
wheel odometry has passed it. Scans are cast by the simulator's lidar into small worlds."""
from __future__ import annotations

import math

import numpy as np
import pytest

from omninav.geometry.frames import scan_points
from omninav.geometry.se2 import compose, relative
from omninav.parameters.declare import ParamError
from omninav.schemas import decode
from omninav.schemas.messages import Header, Odometry, Pose2D
from omninav.services.laser_odometry.laser_odometry import (COST_TOO_HIGH, DIVERGED, FIRST_SCAN, TOO_FEW_POINTS,
                                                            LaserOdometry, LaserOdometryParams)
from omninav.services.laser_odometry.node import LaserOdometryNode, LaserOdometryNodeParams
from omninav.sim.lidar import LidarParams, make_scan, scan as cast
from omninav.sim.world import world_from_mapping

SCAN_NS = 100_000_000       # 10 Hz
ROOM = world_from_mapping({
    "bounds": [8.0, 6.0], "robot": {"start": [2.0, 2.0, 0.0]},
    "boxes": [{"center": [5.5, 4.5], "size": [1.0, 0.6], "yaw": 0.3}, {"center": [1.0, 5.0], "size": [1.2, 0.5]}],
    "circles": [{"center": [6.0, 1.5], "radius": 0.3}, {"center": [3.5, 3.0], "radius": 0.2}]}, "room.yaml")
CORRIDOR = world_from_mapping({"bounds": [60.0, 2.0], "robot": {"start": [20.0, 1.0, 0.0]}}, "corridor.yaml")
LIDAR = LidarParams()       # 360 beams, 12 m, 1 cm range noise


def scan_at(world, pose, rng, stamp_ns=0):
    return make_scan(LIDAR, cast(world, pose, None, LIDAR, rng), stamp_ns)


def run(world, truths, odometry, params=LaserOdometryParams(), seed=0):
    """The core over scans cast at the true poses, with the wheels' poses given; the results."""
    core, rng = LaserOdometry(params), np.random.default_rng(seed)
    return [core.step(k * SCAN_NS, scan_points(scan_at(world, truth, rng), (0.0, 0.0, 0.0), False), odom)
            for k, (truth, odom) in enumerate(zip(truths, odometry))]


def in_world(start, result) -> np.ndarray:
    """A laser pose (odom frame, which started at `start` with the wheel odometry at zero) in the world."""
    return compose(start, result.pose)


@pytest.mark.parametrize("total, per_scan", [(0.5, 0.25), (0.3, 0.3), (1.5, 0.15)],
                         ids=["0.5m-in-2-scans", "0.3m-in-1-scan", "1.5m-in-10-scans"])
def test_a_shove_the_wheels_did_not_see_is_followed(total, per_scan):
    """Standing still (the wheels say so throughout), then pushed sideways and diagonally: the laser
    pose follows the truth (measured: within 0.6 cm on every scan)."""
    start, heading = np.array([3.0, 2.0, 0.4]), 0.5
    steps = round(total / per_scan)
    truths = [start] * 3 + [start + [per_scan * k * math.cos(heading), per_scan * k * math.sin(heading), 0.0]
                            for k in range(1, steps + 1)]
    truths += [truths[-1]] * 3
    results = run(ROOM, truths, [np.zeros(3)] * len(truths))
    assert results[0].failure == FIRST_SCAN and all(r.ok for r in results[1:])
    errors = [math.hypot(*(in_world(start, r)[:2] - t[:2])) for r, t in zip(results, truths)]
    assert max(errors) < 0.03, errors
    assert math.hypot(*(in_world(start, results[-1])[:2] - start[:2])) == pytest.approx(total, abs=0.03)


def loop(corners, speed=0.5, turn_rate=1.0) -> list[np.ndarray]:
    """Poses at 10 Hz along a closed polygon, driving its sides and turning in place at its corners."""
    poses = []
    for a, b in zip(corners, corners[1:] + corners[:1]):
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if poses:
            last = poses[-1][2]
            turn = math.remainder(heading - last, math.tau)
            n = max(1, int(abs(turn) / (turn_rate / 10)))
            poses += [np.array([a[0], a[1], last + turn * (i + 1) / n]) for i in range(n)]
        n = int(math.hypot(b[0] - a[0], b[1] - a[1]) / (speed / 10))
        poses += [np.array([a[0] + (b[0] - a[0]) * i / n, a[1] + (b[1] - a[1]) * i / n, heading]) for i in range(n)]
    return poses


def drifting_wheels(truths, scale=(1.03, 1.03, 1.02)) -> list[np.ndarray]:
    """Wheel odometry from zero that overstates every motion by `scale` (x, y, yaw)."""
    odometry = [np.zeros(3)]
    for a, b in zip(truths, truths[1:]):
        odometry.append(compose(odometry[-1], relative(a, b) * scale))
    return odometry


def test_a_loop_driven_three_times_drifts_little():
    """Three laps of a 15.6 m loop in the room (1005 scans, 47 m), the wheels 3 % long and 2 % over
    in turns (they end 1.1 m off): the laser pose stays within 8 cm and 1° of the truth (measured:
    3.8 cm, 0.67°); the local map rolls as the robot crosses its re-centring distance."""
    truths = loop([(1.5, 1.0), (6.5, 1.0), (6.5, 3.5), (2.5, 4.0)]) * 3
    odometry = drifting_wheels(truths)
    results = run(ROOM, truths, odometry)
    start = truths[0]
    wheel_errors = [math.hypot(*(compose(start, o)[:2] - t[:2])) for o, t in zip(odometry, truths)]
    errors = [math.hypot(*(in_world(start, r)[:2] - t[:2])) for r, t in zip(results, truths)]
    headings = [abs(math.remainder(in_world(start, r)[2] - t[2], math.tau)) for r, t in zip(results, truths)]
    assert max(wheel_errors) > 0.8
    assert max(errors) < 0.08 and max(headings) < math.radians(1.0)
    assert all(r.ok for r in results[1:]) and any(r.recentred for r in results)


def test_along_a_featureless_corridor_the_covariance_is_long_and_the_wheels_carry_the_pose():
    """A 60 m corridor, 2 m wide, its ends beyond the laser's 12 m, driven 5 m along at 45° to the
    odom frame's axes (exact wheels): the variance along it is over 100 times the variance across
    (measured: 300–1300 times), and the pose moves with the wheels along it — the matcher alone
    would snap back to the map's wall texture and report the robot standing."""
    start = np.array([20.0, 1.0, 0.7])
    truths = [start + [0.05 * k, 0.0, 0.0] for k in range(100)]
    results = run(CORRIDOR, truths, [relative(start, t) for t in truths])
    c, s = math.cos(start[2]), math.sin(start[2])
    into_world = np.array([[c, -s], [s, c]])
    for result in results[1:]:
        assert result.ok
        covariance = into_world @ result.covariance[:2, :2] @ into_world.T
        assert covariance[0, 0] > 100 * covariance[1, 1]
    error = in_world(start, results[-1]) - truths[-1]
    assert abs(error[0]) < 0.01 and abs(error[1]) < 0.05


def test_a_long_way_keeps_the_map_window_and_rolls_it():
    """20 m along the corridor: the grids keep their size and roll to follow the robot."""
    start = np.array([5.0, 1.0, 0.0])
    truths = [start + [0.1 * k, 0.0, 0.0] for k in range(200)]
    params = LaserOdometryParams()
    core, rng = LaserOdometry(params), np.random.default_rng(0)
    recentred = 0
    for k, truth in enumerate(truths):
        result = core.step(k * SCAN_NS, scan_points(scan_at(CORRIDOR, truth, rng), (0.0, 0.0, 0.0), False),
                           relative(start, truth))
        recentred += result.recentred
    assert recentred >= 3          # about one per map_recentre_distance (4 m)
    assert all(grid.shape == (params.map_size // 2 ** i,) * 2 for i, (grid, _) in enumerate(core.mapper.probabilities()))
    assert math.hypot(*(in_world(start, result)[:2] - truths[-1][:2])) < 0.05


def test_a_match_that_cannot_be_trusted_is_flagged_and_carried_by_the_wheels():
    params = LaserOdometryParams()
    core, rng = LaserOdometry(params), np.random.default_rng(0)
    pose = np.array([3.0, 2.0, 0.4])
    points = scan_points(scan_at(ROOM, pose, rng), (0.0, 0.0, 0.0), False)
    assert core.step(0, points, np.zeros(3)).failure == FIRST_SCAN
    unmatched = np.diag([params.unmatched_std_xy ** 2, params.unmatched_std_xy ** 2, params.unmatched_std_yaw ** 2])
    few = core.step(SCAN_NS, points[:5], (0.1, 0.0, 0.0))
    assert not few.ok and few.failure == TOO_FEW_POINTS
    np.testing.assert_allclose(few.pose, (0.1, 0.0, 0.0))
    np.testing.assert_array_equal(few.covariance, unmatched)
    # a scan from 1.5 m and 90° away: no pose near the guess puts it on the room's walls
    elsewhere = scan_points(scan_at(ROOM, (4.5, 2.5, 2.0), rng), (0.0, 0.0, 0.0), False)
    bad = core.step(2 * SCAN_NS, elsewhere, (0.1, 0.0, 0.0))
    assert not bad.ok and bad.failure in (COST_TOO_HIGH, DIVERGED)
    np.testing.assert_allclose(bad.pose, (0.1, 0.0, 0.0), atol=1e-12)
    # and the map was left alone: the room's scan matches again
    assert core.step(3 * SCAN_NS, points, (0.1, 0.0, 0.0)).ok


def test_same_inputs_same_outputs():
    truths = loop([(1.5, 1.0), (4.0, 1.0), (4.0, 2.5)])
    odometry = drifting_wheels(truths)
    first, second = run(ROOM, truths, odometry), run(ROOM, truths, odometry)
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a.pose, b.pose)
        np.testing.assert_array_equal(a.covariance, b.covariance)
        assert (a.ok, a.failure, a.cost) == (b.ok, b.failure, b.cost)


@pytest.mark.parametrize("name, value, says", [
    ("map_resolution", 0.0, "map_resolution must be > 0"),
    ("map_size", 8, "map_size must be ≥ 16"),
    ("laser_max_dist", 0.2, "laser_max_dist must be > laser_min_dist"),
    ("map_recentre_distance", 20.0, "map_recentre_distance must be < half the map's side"),
    ("map_multi_res_levels", 9, "map_multi_res_levels must be few enough"),
    ("max_mismatch", -1.0, "max_mismatch must be > 0"),
    ("min_scan_points", 2, "min_scan_points must be ≥ 3"),
    ("unmatched_std_xy", 0.0, "unmatched_std_xy must be > 0"),
])
def test_bad_parameters_are_refused_by_name(name, value, says):
    with pytest.raises(ParamError, match=says):
        LaserOdometryParams(**{name: value})


def test_the_node_refuses_an_unknown_odometry_topic():
    with pytest.raises(ParamError, match="odom_topic must be one of 'odom_wheel', 'odom'"):
        LaserOdometryNodeParams(odom_topic="odom_laser")


# ---------------------------------------------------------------- the node, in-process

def feed(node, topic, msg):
    index = next(i for i, inp in enumerate(node.inputs) if inp.key == node.keys.resolve(topic))
    node.process(index, msg)


def wheels(stamp_ns, x=0.0):
    return Odometry(header=Header(stamp_ns=stamp_ns, frame_id="odom"), pose=Pose2D(x, 0.0, 0.0))


@pytest.mark.parametrize("topic", ["odom_wheel", "odom"])
def test_the_node_publishes_odom_laser_at_each_scans_stamp_once_odometry_has_passed_it(topic):
    """Scans at 10 Hz, wheel odometry at 20 Hz saying the robot stands at x = 1 while it is pushed
    0.1 m a scan along x: each scan comes out once odometry stamped at or after it has come, stamped
    with the scan, in the odom frame, pushed on from the wheels' pose at the first (which starts the
    map and, matched against nothing, is not published)."""
    node = LaserOdometryNode(LaserOdometryNodeParams(odom_topic=topic))
    out = []
    node.odom_pub.sink = lambda pub, payload, stamp: out.append(decode(payload, Odometry))
    assert {inp.key for inp in node.inputs} == {node.keys.resolve(topic), node.keys.resolve("scan")}
    rng, start = np.random.default_rng(0), np.array([3.0, 2.0, 0.0])
    feed(node, topic, wheels(0, 1.0))
    for k in range(5):
        stamp = (k + 1) * SCAN_NS
        feed(node, "scan", scan_at(ROOM, start + [0.1 * k, 0.0, 0.0], rng, stamp))
        assert len(out) == max(k - 1, 0)      # waits for odometry past the scan's stamp ...
        feed(node, topic, wheels(stamp + SCAN_NS // 2, 1.0))
        assert len(out) == k                  # ... then publishes it (but the first)
    assert [m.header.stamp_ns for m in out] == [(k + 1) * SCAN_NS for k in range(1, 5)]
    assert all((m.header.frame_id, m.child_frame_id) == ("odom", "base_link") for m in out)
    assert out[0].pose.x == pytest.approx(1.1, abs=0.02) and out[0].pose.y == pytest.approx(0.0, abs=0.02)
    assert out[-1].pose.x == pytest.approx(1.4, abs=0.02)
    assert out[-1].twist.linear_x == pytest.approx(1.0, abs=0.2)          # 0.1 m a scan, 10 Hz
    assert out[-1].pose_covariance[0, 0] < 1e-3
    assert node.counters["matches"] == 4 and node.counters["failed_matches"] == 0
    feed(node, "scan", scan_at(ROOM, start, rng, 2 * SCAN_NS))          # back in time: refused, counted
    assert node.counters[f"malformed/{node.keys.resolve('scan')}"] == 1


def test_end_points_beyond_the_window_are_not_counted_against_a_match():
    """A hall larger than the local map (walls 14-30 m off, a 25.6 m window): the far walls fall off
    the grid at every pose alike; the near ones still match, and no scan is refused for the far ones."""
    hall = world_from_mapping({"bounds": [60.0, 40.0], "robot": {"start": [30.0, 20.0, 0.0]},
                               "circles": [{"center": [32.0 + 2.0 * i, 18.0 + (i % 2) * 4.0], "radius": 0.3}
                                           for i in range(4)]}, "hall.yaml")
    lidar = LidarParams(range_max=40.0)
    core, rng, start = LaserOdometry(), np.random.default_rng(0), np.array([30.0, 20.0, 0.0])
    results = []
    for k in range(12):
        truth = start + [0.1 * k, 0.0, 0.0]
        points = scan_points(make_scan(lidar, cast(hall, truth, None, lidar, rng), 0), (0.0, 0.0, 0.0), False)
        results.append(core.step(k * SCAN_NS, points, [0.1 * k, 0.0, 0.0]))
    assert results[0].failure == FIRST_SCAN and all(r.ok for r in results[1:]), [r.failure for r in results]
    assert all(r.cost < 0.1 for r in results[1:])


def test_a_map_that_no_longer_fits_the_world_starts_afresh_after_refusals_in_a_row():
    """The room's walls and furniture moved (another world): every match is refused until, after
    restart_after_refusals of them, the map starts again from the wheels' guess and matches again."""
    params = LaserOdometryParams(restart_after_refusals=3)
    moved = world_from_mapping({"bounds": [11.0, 9.0], "origin": [-2.0, -1.5], "robot": {"start": [2.0, 2.0, 0.0]},
                                "boxes": [{"center": [3.0, 4.0], "size": [2.0, 0.4]}, {"center": [6.0, 2.0], "size": [0.4, 2.0]}],
                                "circles": [{"center": [5.0, 1.0], "radius": 0.4}]}, "moved.yaml")
    core, rng, pose = LaserOdometry(params), np.random.default_rng(0), np.array([3.0, 2.0, 0.0])
    steps = [core.step(k * SCAN_NS, scan_points(scan_at(ROOM if k < 2 else moved, pose, rng), (0.0, 0.0, 0.0), False),
                       np.zeros(3)) for k in range(9)]
    failures = [r.failure for r in steps]
    assert failures[:2] == [FIRST_SCAN, ""] and set(failures[2:5]) <= {COST_TOO_HIGH, DIVERGED}
    assert failures[5] == FIRST_SCAN and all(r.ok for r in steps[6:]) and core.restarts == 1


def drive_beside_movers(params: LaserOdometryParams) -> float:
    """Along a 10 m wide hall whose end lies beyond the window (only the side walls hold the pose
    across; along it, nothing static but a far wall in reach of the 30 m lidar), at 1.5 m/s with
    exact wheels, among cylinders of 0.5 m walking the robot's way and across it at 0.5-1 m/s, as
    DynaBARN's do. The largest error of the laser pose over the drive (m)."""
    hall = world_from_mapping({"bounds": [60.0, 10.0], "robot": {"start": [5.0, 5.0, 0.0]}}, "hall.yaml")
    lidar = LidarParams(range_max=30.0)
    rng, start = np.random.default_rng(0), np.array([5.0, 5.0, 0.0])
    core = LaserOdometry(params)
    errors = []
    for k in range(60):                  # 6 s at 10 Hz
        t = k * 0.1
        truth = start + [1.5 * t, 0.0, 0.0]
        movers = np.array([[8.0 + 1.0 * t, 6.5, 0.5],            # ahead, walking away at 1 m/s
                           [11.0 + 0.5 * t, 3.5, 0.5],           # ahead, walking away at 0.5 m/s
                           [16.0, 1.0 + 0.8 * t, 0.5]])          # crossing ahead
        points = scan_points(make_scan(lidar, cast(hall, truth, movers, lidar, rng), 0), (0.0, 0.0, 0.0), False)
        result = core.step(k * SCAN_NS, points, truth - start)
        errors.append(math.hypot(*(in_world(start, result)[:2] - truth[:2])))
    return max(errors)


def test_moving_bodies_do_not_drag_the_pose_along():
    """What a cylinder leaves in the local map is cleared when later beams cross it, and end points
    on space the map saw empty are not matched: the pose holds. Without either the cylinders walking
    ahead pull it back (measured: 0.049 m against 0.94 m; the clearing alone 0.61 m, the end points
    left out alone 0.039 m)."""
    assert drive_beside_movers(LaserOdometryParams()) < 0.1
    assert drive_beside_movers(LaserOdometryParams(confirmed_hits=0, moving_free_updates=0)) > 0.2
