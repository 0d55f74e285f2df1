"""The simulated lidar: exact ranges against walls and circles, the grid caster, the sensor model."""
import dataclasses
import math

import numpy as np
import pytest
import yaml

from conftest import SHARED_DATA
from omninav.schemas.codec import decode, encode
from omninav.schemas.messages import LaserScan
from omninav.sim.lidar import LidarParams, cast, laser_pose, make_scan, scan, sensor_model
from omninav.sim.world import load_world, world_path

EXACT = dict(noise_std=0.0, range_min=0.0, range_max=100.0)


def box_world(tmp_path, **extra):
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump({"bounds": [10.0, 8.0], "robot": {"start": [5.0, 4.0, 0.0]}, **extra}))
    return load_world(path)


def distance_to_box_walls(x, y, angles, width=10.0, height=8.0):
    """Where a ray from inside [0, w] × [0, h] leaves it."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (width - x) / c, np.where(c < 0, -x / c, np.inf))
        ty = np.where(s > 0, (height - y) / s, np.where(s < 0, -y / s, np.inf))
    return np.minimum(tx, ty)


@pytest.mark.parametrize("pose, mount", [((3.0, 2.0, 0.0), (0.0, 0.0, 0.0)),
                                         ((7.5, 5.0, 0.7), (0.0, 0.0, 0.0)),
                                         ((1.3, 6.9, -2.0), (0.25, -0.1, 0.4))])
def test_ranges_match_the_walls_exactly(tmp_path, pose, mount):
    world = box_world(tmp_path)
    params = LidarParams(beams=37, mount_x=mount[0], mount_y=mount[1], mount_yaw=mount[2], **EXACT)
    ranges = scan(world, pose, None, params, None)
    lx, ly, lyaw = laser_pose(pose, params)
    np.testing.assert_allclose(ranges, distance_to_box_walls(lx, ly, lyaw + params.angles()), rtol=0, atol=1e-9)


def test_beams_turn_counter_clockwise_from_angle_min(tmp_path):
    world = box_world(tmp_path)
    params = LidarParams(beams=4, **EXACT)  # -π, -π/2, 0, π/2
    np.testing.assert_allclose(scan(world, (5.0, 2.0, 0.0), None, params, None), [5.0, 2.0, 5.0, 6.0], atol=1e-9)
    turned = scan(world, (5.0, 2.0, math.pi / 2), None, params, None)  # now beam 2 looks along +y
    np.testing.assert_allclose(turned, [2.0, 5.0, 6.0, 5.0], atol=1e-9)


def test_static_circles_boxes_and_movers_are_hit(tmp_path):
    world = box_world(tmp_path, circles=[{"center": [8.0, 4.0], "radius": 0.5}],
                      boxes=[{"center": [5.0, 6.0], "size": [2.0, 1.0], "yaw": math.pi / 4}])
    params = LidarParams(beams=4, fov=2 * math.pi, angle_min=0.0, **EXACT)  # 0, π/2, π, 3π/2
    ranges = scan(world, (5.0, 4.0, 0.0), None, params, None)
    # straight up, the ray meets the box's long lower edge (0.5 from its centre, turned 45°)
    np.testing.assert_allclose(ranges, [2.5, 2.0 - 0.5 * math.sqrt(2.0), 5.0, 4.0], atol=1e-9)
    mover = np.array([[2.0, 4.0, 0.3], [5.0, 1.0, 0.2]])
    with_movers = scan(world, (5.0, 4.0, 0.0), mover, params, None)
    np.testing.assert_allclose(with_movers, [2.5, ranges[1], 2.7, 2.8], atol=1e-9)


def test_shipped_movers_are_seen(tmp_path):
    world = load_world(world_path("warehouse"))
    params = LidarParams(beams=360, **EXACT)
    t = 0.0
    x, y, _ = world.movers.circles_at(t)[0]                       # the forklift at (3.0, 1.5)
    pose = (x - 1.0, y, 0.0)
    without = scan(world, pose, None, params, None)
    seen = scan(world, pose, world.movers.circles_at(t), params, None)
    beam = int(np.argmin(np.abs(params.angles())))
    assert seen[beam] == pytest.approx(1.0 - world.movers.radius[0], abs=1e-9)
    assert without[beam] > 5.0


def test_range_limits_follow_rep_117(tmp_path):
    world = box_world(tmp_path)
    params = LidarParams(beams=4, fov=2 * math.pi, angle_min=0.0, noise_std=0.0, range_min=0.5, range_max=6.0)
    ranges = scan(world, (9.7, 1.0, 0.0), None, params, None)  # 0.3 m to the right wall, 7 m up
    np.testing.assert_allclose(ranges, [-np.inf, np.inf, np.inf, 1.0], atol=1e-9)


def test_grid_caster_matches_the_shape_caster_within_a_cell():
    world = load_world(world_path("room"))
    resolution = 0.05
    gridded = dataclasses.replace(world, solids=np.zeros((0, 4, 2)), circles=np.zeros((0, 3)),
                                  grid=world.rasterize(resolution))
    rng = np.random.default_rng(3)
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    checked = 0
    while checked < 20:
        x, y = rng.uniform(0.3, 9.7), rng.uniform(0.3, 7.7)
        if world.distance([x, y]) < 0.2:
            continue
        exact = cast(world, x, y, angles)
        cells = cast(gridded, x, y, angles)
        assert np.isfinite(cells).all()
        assert (cells <= exact + 1e-9).all()  # the rasterized shapes cover the true ones
        hits = np.column_stack([x + cells * np.cos(angles), y + cells * np.sin(angles)])
        assert world.distance(hits).max() <= resolution * math.sqrt(2) + 1e-9  # the hit is in a shape's cell
        assert np.median(np.abs(cells - exact)) < resolution
        checked += 1


def test_grid_caster_respects_the_origin_yaw():
    """The same cells turned about the world origin give the same ranges from the turned pose."""
    world = load_world(world_path("room"))
    grid = world.rasterize(0.05)
    turn = 2.0
    c, s = math.cos(turn), math.sin(turn)
    o = grid.info.origin
    turned_grid = dataclasses.replace(grid, info=dataclasses.replace(
        grid.info, origin=dataclasses.replace(o, x=c * o.x - s * o.y, y=s * o.x + c * o.y, theta=o.theta + turn)))
    empty = dict(solids=np.zeros((0, 4, 2)), circles=np.zeros((0, 3)))
    straight = dataclasses.replace(world, grid=grid, **empty)
    turned = dataclasses.replace(world, grid=turned_grid, origin=(-100.0, -100.0), bounds=(200.0, 200.0), **empty)
    params = LidarParams(beams=360, **EXACT)
    for x, y, yaw in [(1.2, 1.0, 0.0), (5.0, 5.0, 1.0), (8.0, 3.5, -2.5)]:
        expected = scan(straight, (x, y, yaw), None, params, None)
        got = scan(turned, (c * x - s * y, s * x + c * y, yaw + turn), None, params, None)
        np.testing.assert_allclose(got, expected, atol=1e-6)


@pytest.mark.skipif(not (SHARED_DATA / "maps" / "willow-full-0.05.yaml").exists(), reason="shared data not present")
def test_willow_scan_hits_its_walls():
    world = load_world(world_path("willow"))
    params = LidarParams(beams=360, noise_std=0.0)
    ranges = scan(world, world.robot.start, None, params, None)
    assert np.isfinite(ranges).sum() > 100  # a corridor: walls on both sides
    angles = world.robot.start[2] + params.angles()
    ok = np.isfinite(ranges)
    hits = world.robot.start[:2] + ranges[ok, None] * np.column_stack([np.cos(angles[ok]), np.sin(angles[ok])])
    assert world.distance(hits).max() <= 0.05 + 1e-9  # every return lies on an obstacle cell's border


# ---------------------------------------------------------------- the sensor model

def test_noise_and_dropout_statistics(tmp_path):
    world = box_world(tmp_path)
    params = LidarParams(beams=3600, noise_std=0.05, dropout_prob=0.2, range_min=0.0, range_max=100.0)
    rng = np.random.default_rng(42)
    pose = (5.0, 4.0, 0.3)
    true = scan(world, pose, None, dataclasses.replace(params, noise_std=0.0, dropout_prob=0.0), None)
    ranges = scan(world, pose, None, params, rng)
    dropped = np.isinf(ranges)
    assert 0.17 < dropped.mean() < 0.23
    error = ranges[~dropped] - true[~dropped]
    assert abs(error.mean()) < 0.005 and 0.045 < error.std() < 0.055


def test_seeded_scans_repeat(tmp_path):
    world = box_world(tmp_path)
    params = LidarParams(dropout_prob=0.1)
    one = scan(world, (5.0, 4.0, 0.0), None, params, np.random.default_rng(7))
    two = scan(world, (5.0, 4.0, 0.0), None, params, np.random.default_rng(7))
    three = scan(world, (5.0, 4.0, 0.0), None, params, np.random.default_rng(8))
    np.testing.assert_array_equal(one, two)
    assert not np.array_equal(one, three)


def test_noise_keeps_returns_within_the_range_limits():
    params = LidarParams(beams=4, noise_std=1.0, range_min=0.5, range_max=5.0)
    ranges = sensor_model(np.array([0.6, 4.9, 0.2, np.inf] * 250), params, np.random.default_rng(0))
    hits = ranges.reshape(-1, 4)
    assert ((hits[:, :2] >= 0.5) & (hits[:, :2] <= 5.0)).all()
    assert (hits[:, 2] == -np.inf).all() and (hits[:, 3] == np.inf).all()


def test_noise_needs_a_generator():
    with pytest.raises(ValueError, match="Generator"):
        sensor_model(np.ones(3), LidarParams(), None)


# ---------------------------------------------------------------- parameters and the message

def test_angles_follow_laserscan():
    full = LidarParams(beams=360)
    assert full.angle_min == -math.pi and full.angle_increment == pytest.approx(math.radians(1.0))
    assert full.angle_max == pytest.approx(math.pi - math.radians(1.0))  # no beam twice at ±π
    half = LidarParams(beams=361, fov=math.pi)  # a SICK-like 180° scanner, 0.5° steps
    assert half.angle_min == -math.pi / 2 and half.angle_max == pytest.approx(math.pi / 2)
    assert half.angle_increment == pytest.approx(math.radians(0.5))
    np.testing.assert_allclose(half.angles()[[0, -1]], [-math.pi / 2, math.pi / 2])
    assert LidarParams(fov=1.0, angle_min=0.2).angles()[0] == 0.2


@pytest.mark.parametrize("bad", [dict(beams=0), dict(fov=7.0), dict(range_min=5.0, range_max=2.0),
                                 dict(noise_std=-0.1), dict(dropout_prob=1.5), dict(rate_hz=0.0)])
def test_bad_params_are_refused(bad):
    with pytest.raises(ValueError):
        LidarParams(**bad)


def test_make_scan_encodes_with_infinities():
    params = LidarParams(beams=4, range_min=0.1, range_max=5.0, rate_hz=20.0)
    msg = make_scan(params, np.array([1.0, np.inf, -np.inf, 2.5]), stamp_ns=123, frame_id="laser")
    back = decode(encode(msg), LaserScan)
    assert back.header.stamp_ns == 123 and back.header.frame_id == "laser"
    assert back.angle_min == params.angle_min and back.angle_increment == params.angle_increment
    assert back.scan_time == pytest.approx(0.05) and back.range_max == 5.0
    np.testing.assert_array_equal(back.ranges, np.array([1.0, np.inf, -np.inf, 2.5], np.float32))
