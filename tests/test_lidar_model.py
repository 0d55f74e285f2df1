"""The lidar's sensor model: σ growing with range, dropouts beyond the rated range and at grazing
incidence (with the incidence the ray cast finds), mixed pixels at edges, the old sensor kept
exactly when these are off, a fixed number of draws per scan, and the Jackal's UST-10LX."""
import dataclasses
import math

import numpy as np
import pytest
import yaml

from omninav.cli.profile import load_profile
from omninav.parameters.from_mapping import load_params
from omninav.services.lidar.node import LidarNodeParams
from omninav.sim.lidar import (LidarParams, cast, cast_with_incidence, dropout_chance, laser_pose, scan,
                               sensor_model)
from omninav.sim.world import load_world, world_path

from conftest import SHARED_DATA

# every parameter of the new effects at its default: the sensor as it was
OFF = dict(noise_std_per_m=0.0, range_dropout_start=0.0, range_dropout_prob=0.0, incidence_dropout_start=0.0,
           incidence_dropout_prob=0.0, beam_divergence=0.0, mixed_pixel_threshold=0.1, mixed_pixel_prob=0.0)
EXACT = dict(noise_std=0.0, range_min=0.0, range_max=100.0, mount_x=0.0, mount_y=0.0, mount_yaw=0.0)


def box_world(tmp_path, **extra):
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump({"bounds": [10.0, 8.0], "robot": {"start": [5.0, 4.0, 0.0]}, **extra}))
    return load_world(path)


def old_sensor_model(true_ranges, params, rng):
    """sensor_model as it was at c047751, before range-dependent noise, the dropout causes and mixed pixels."""
    ranges = np.array(true_ranges, np.float64)
    hit = np.isfinite(ranges)
    if params.noise_std > 0:
        noise = rng.normal(0.0, params.noise_std, ranges.shape)
        ranges[hit] = np.clip(ranges[hit] + noise[hit], params.range_min, params.range_max)
    ranges[hit & (np.asarray(true_ranges) < params.range_min)] = -np.inf
    if params.dropout_prob > 0:
        ranges[rng.random(ranges.shape) < params.dropout_prob] = np.inf
    return ranges


# ---------------------------------------------------------------- the old sensor, exactly

WILLOW = pytest.param("willow", False, marks=pytest.mark.skipif(
    not (SHARED_DATA / "maps" / "willow-full-0.05.yaml").is_file(), reason="no shared map data"))


@pytest.mark.parametrize("name, movers", [("room", False), ("warehouse", True), WILLOW])
@pytest.mark.parametrize("old", [{}, dict(noise_std=0.05, dropout_prob=0.2), dict(noise_std=0.0, dropout_prob=0.1),
                                 dict(noise_std=0.3, range_min=0.5, range_max=4.0)])
def test_with_the_new_effects_off_scans_are_the_old_sensors_byte_for_byte(name, movers, old):
    world = load_world(world_path(name))
    params = LidarParams(beams=720, **old, **OFF)
    circles = world.movers.circles_at(0.0) if movers else None
    new_rng, old_rng = np.random.default_rng(11), np.random.default_rng(11)
    x0, y0, yaw0 = world.robot.start
    for k in range(3):                                  # in turn from one generator, as the node scans
        pose = (x0 + 0.1 * k, y0 + 0.05 * k, yaw0 + 0.3 * k)
        lx, ly, lyaw = laser_pose(pose, params)
        true = cast(world, lx, ly, lyaw + params.angles(), circles, params.range_max)
        expected = old_sensor_model(true, params, old_rng)
        assert np.array_equal(scan(world, pose, circles, params, new_rng), expected)
    assert new_rng.random() == old_rng.random()         # and the generators stand at the same draw


@pytest.mark.parametrize("p", [0.1, 0.2, 0.3, 0.7])
def test_with_the_other_causes_off_the_dropout_chance_is_dropout_prob_to_the_bit(p):
    """Not 1 − (1 − p)·1, which is p only to within a rounding: the old comparisons must hold for every draw."""
    true = np.array([0.0, 0.5, 3.0, 11.9, np.inf])
    assert (dropout_chance(true, np.linspace(0.0, 1.0, 5), LidarParams(dropout_prob=p, **OFF)) == p).all()


def test_a_scan_takes_the_same_draws_whatever_it_sees(tmp_path):
    """Replay reproduces a scan only if the generator advances alike whatever the beams hit."""
    world = box_world(tmp_path, boxes=[{"center": [3.5, 4.5], "size": [1.0, 1.0]}])
    params = LidarParams(beams=360, noise_std=0.01, noise_std_per_m=0.001, dropout_prob=0.01, range_max=6.0,
                         range_dropout_start=3.0, range_dropout_prob=0.5, incidence_dropout_prob=0.5,
                         beam_divergence=0.01, mixed_pixel_prob=0.5)
    one, two = np.random.default_rng(5), np.random.default_rng(5)
    near_a_box = scan(world, (1.0, 4.2, 0.0), None, params, one)
    open_space = scan(world, (8.0, 2.0, 2.0), None, params, two)
    assert not np.array_equal(near_a_box, open_space)
    assert one.random() == two.random()


# ---------------------------------------------------------------- range-dependent noise

def test_sigma_grows_with_range_as_parameterised():
    ranges = np.array([1.0, 5.0, 20.0])
    true = np.repeat(ranges, 20000)
    params = LidarParams(noise_std=0.01, noise_std_per_m=0.002, range_min=0.0, range_max=40.0)
    error = (sensor_model(true, params, np.random.default_rng(3)) - true).reshape(3, -1)
    np.testing.assert_allclose(error.std(axis=1), 0.01 + 0.002 * ranges, rtol=0.05)
    assert np.abs(error.mean(axis=1)).max() < 0.005
    flat = dataclasses.replace(params, noise_std_per_m=0.0)       # noise_std alone: σ as it always was
    error = (sensor_model(true, flat, np.random.default_rng(3)) - true).reshape(3, -1)
    np.testing.assert_allclose(error.std(axis=1), 0.01, rtol=0.05)


# ---------------------------------------------------------------- dropouts

def test_dropouts_rise_beyond_the_rated_range():
    ranges = np.array([2.0, 10.0, 15.0, 20.0, 25.0, 29.0])
    params = LidarParams(noise_std=0.0, range_min=0.0, range_max=30.0, dropout_prob=0.05,
                         range_dropout_start=10.0, range_dropout_prob=0.8)
    dropped = np.isinf(sensor_model(np.repeat(ranges, 20000), params, np.random.default_rng(4))).reshape(6, -1)
    beyond = np.clip((ranges - 10.0) / 20.0, 0.0, 1.0)
    np.testing.assert_allclose(dropped.mean(axis=1), 0.05 + 0.95 * 0.8 * beyond, atol=0.015)


def test_the_ray_cast_gives_each_hits_incidence(tmp_path):
    world = box_world(tmp_path, circles=[{"center": [8.0, 4.0], "radius": 0.5}])
    angles = np.linspace(-math.pi + 0.05, -0.05, 200)          # all onto the bottom wall, 0.2 m below
    ranges, cosines = cast_with_incidence(world, 5.0, 0.2, angles)
    np.testing.assert_allclose(cosines, 0.2 / ranges, atol=1e-9)
    # through the circle's centre head-on; 0.3 off it the ray meets the surface at asin(0.3 / 0.5) off its normal
    _, on_circle = cast_with_incidence(world, 5.0, 4.0, np.array([0.0, math.atan2(0.3, 3.0)]))
    offset = 3.0 * math.sin(math.atan2(0.3, 3.0)) / 0.5
    np.testing.assert_allclose(on_circle, [1.0, math.sqrt(1.0 - offset ** 2)], atol=1e-9)
    # a map's cells: the ray enters a wall cell through its face, here the wall's own
    gridded = dataclasses.replace(world, solids=np.zeros((0, 4, 2)), circles=np.zeros((0, 3)),
                                  grid=world.rasterize(0.05))
    cell_ranges, cell_cosines = cast_with_incidence(gridded, 5.02, 0.22, angles)
    assert np.isfinite(cell_ranges).all()
    np.testing.assert_allclose(cell_cosines, np.abs(np.sin(angles)), atol=1e-9)


def test_dropouts_rise_at_grazing_incidence(tmp_path):
    world = box_world(tmp_path)
    angles_deg = np.array([-90.0, -45.0, -25.0, -10.0, -5.0])   # onto the bottom wall, 0.2 m below
    off_normal = np.radians(90.0 + angles_deg)
    params = LidarParams(**EXACT, incidence_dropout_start=math.radians(60.0), incidence_dropout_prob=0.9)
    rng = np.random.default_rng(6)
    lx, ly = 5.0, 0.2
    true, cosines = cast_with_incidence(world, lx, ly, np.radians(angles_deg))
    np.testing.assert_allclose(np.arccos(cosines), off_normal, atol=1e-9)
    dropped = np.mean([np.isinf(sensor_model(true, params, rng, cosines)) for _ in range(8000)], axis=0)
    grazing = np.clip((off_normal - math.radians(60.0)) / math.radians(30.0), 0.0, 1.0)
    np.testing.assert_allclose(dropped, 0.9 * grazing, atol=0.02)
    assert dropped[:2].max() == 0.0 and dropped[-1] > 0.6
    # the same through scan(): a beam grazing the wall drops far more often than one meeting it head-on
    scanning = LidarParams(beams=2, fov=math.radians(85.0), angle_min=math.radians(-90.0), **EXACT,
                           incidence_dropout_start=math.radians(60.0), incidence_dropout_prob=0.9)
    drops = np.mean([np.isinf(scan(world, (lx, ly, 0.0), None, scanning, rng)) for _ in range(2000)], axis=0)
    assert drops[0] == 0.0 and drops[1] > 0.6


def test_incidence_dropouts_need_the_cosines():
    with pytest.raises(ValueError, match="incidence"):
        sensor_model(np.ones(3), LidarParams(incidence_dropout_prob=0.5), np.random.default_rng(0))


# ---------------------------------------------------------------- mixed pixels

EDGE = dict(beams=1, fov=0.01, angle_min=0.001, **EXACT)
POSE = (1.0, 4.0, 0.0)         # the box's corner (3, 4) lies 0.001 rad below the beam: near 2 m, far wall 9 m


def edge_returns(tmp_path, scans=4000, **params):
    world = box_world(tmp_path, boxes=[{"center": [3.5, 4.5], "size": [1.0, 1.0]}])
    rng = np.random.default_rng(9)
    lidar = LidarParams(**{**EDGE, **params})
    return np.array([scan(world, POSE, None, lidar, rng)[0] for _ in range(scans)])


def test_a_beam_straddling_a_box_edge_returns_mixed_ranges_at_the_configured_rate(tmp_path):
    ranges = edge_returns(tmp_path, beam_divergence=0.01, mixed_pixel_prob=0.3)
    centre = 2.0 / math.cos(0.001)                                         # on the box, by a hair
    mixed = ranges[np.abs(ranges - centre) > 1e-9]
    assert abs(len(mixed) / len(ranges) - 0.3) < 0.03
    near, far = 2.0, 9.0
    assert (mixed >= near - 1e-3).all() and (mixed <= far + 1e-3).all()
    assert abs(np.median(mixed) - (near + far) / 2) < 0.5                  # anywhere between the two


@pytest.mark.parametrize("off", [dict(beam_divergence=0.01, mixed_pixel_prob=0.0),
                                 dict(beam_divergence=0.0, mixed_pixel_prob=0.3),
                                 dict(beam_divergence=0.01, mixed_pixel_prob=1.0, mixed_pixel_threshold=8.0),
                                 dict(beam_divergence=0.01, mixed_pixel_prob=1.0, angle_min=0.2)])
def test_without_the_effect_or_an_edge_a_beam_never_mixes(tmp_path, off):
    """Off, a step below the threshold, or a footprint wholly on the box: the beam's own range."""
    ranges = edge_returns(tmp_path, scans=300, **off)
    expected = 2.0 / math.cos(off.get("angle_min", 0.001))
    np.testing.assert_allclose(ranges, expected, atol=1e-9)


def test_mixed_pixels_need_the_footprint():
    with pytest.raises(ValueError, match="footprint"):
        sensor_model(np.ones(3), LidarParams(beam_divergence=0.01, mixed_pixel_prob=0.5), np.random.default_rng(0))


# ---------------------------------------------------------------- parameters and the Jackal's UST-10LX

@pytest.mark.parametrize("bad", [dict(noise_std_per_m=-0.1), dict(range_dropout_prob=1.5),
                                 dict(range_dropout_start=12.0), dict(incidence_dropout_start=math.pi / 2),
                                 dict(incidence_dropout_prob=-0.1), dict(beam_divergence=-0.01),
                                 dict(mixed_pixel_threshold=0.0), dict(mixed_pixel_prob=2.0)])
def test_bad_sensor_model_params_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        LidarParams(**bad)


def test_the_jackal_profile_has_a_ust_10lx():
    params = load_params(LidarNodeParams, load_profile("jackal").params["lidar"])
    assert params.beams == 1081 and params.rate_hz == 40.0
    assert params.angle_increment == pytest.approx(math.radians(0.25))
    assert (params.angle_min, params.angle_max) == (pytest.approx(math.radians(-135)), pytest.approx(math.radians(135)))
    assert (params.range_min, params.range_max) == (0.06, 30.0)
    assert 3 * params.noise_std == pytest.approx(0.04, abs=1e-3)            # ±40 mm as 3σ
    assert params.range_dropout_start == 10.0
    room = load_world(world_path("room"))
    ranges = scan(room, room.robot.start, None, params, np.random.default_rng(0))
    assert ranges.shape == (1081,) and np.isfinite(ranges).mean() > 0.9
