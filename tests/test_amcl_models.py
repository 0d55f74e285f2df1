"""AMCL core, models: parameters (ROS names, defaults, YAML layouts), motion and laser models."""
import dataclasses
import math

import numpy as np
import pytest

from omninav.schemas.messages import MapMetaData, OccupancyGrid, Pose2D
from omninav.services.localizer import motion
from omninav.services.localizer.reference import likelihood_field_numpy
from omninav.services.localizer.params import (AmclParams, BeamModelParams, DiffMotionParams, LikelihoodFieldParams,
                                              OmniMotionParams)
from omninav.services.localizer.sensor import LaserModel, prepare_scan
from omninav.geometry.grid import cell_to_world
from omninav.services.runtime.params import load_params_file
from omninav.parameters.declare import ParamError
from omninav.parameters.from_mapping import load_params
from omninav.geometry.se2 import compose, wrap_angle
from omninav.sim.lidar import LidarParams, scan
from omninav.sim.world import load_world, world_path

# ROS 1 amcl (navigation noetic-devel, amcl_node.cpp / cfg/AMCL.cfg), transcribed by hand
ROS1_DEFAULTS = {
    "min_particles": 100, "max_particles": 5000, "kld_err": 0.01, "kld_z": 0.99, "update_min_d": 0.2,
    "update_min_a": math.pi / 6, "resample_interval": 2, "selective_resampling": False,
    "transform_tolerance": 0.1, "recovery_alpha_slow": 0.0, "recovery_alpha_fast": 0.0,
    "initial_pose_x": 0.0, "initial_pose_y": 0.0, "initial_pose_a": 0.0, "initial_cov_xx": 0.25,
    "initial_cov_yy": 0.25, "initial_cov_aa": (math.pi / 12) ** 2, "gui_publish_rate": -1.0,
    "save_pose_rate": 0.5, "use_map_topic": False, "first_map_only": False,
    "force_update_after_initialpose": False, "force_update_after_set_map": False,
    "std_warn_level_x": 0.2, "std_warn_level_y": 0.2, "std_warn_level_yaw": 0.1,
    "laser_min_range": -1.0, "laser_max_range": -1.0, "laser_max_beams": 30, "laser_z_hit": 0.95,
    "laser_z_short": 0.1, "laser_z_max": 0.05, "laser_z_rand": 0.05, "laser_sigma_hit": 0.2,
    "laser_lambda_short": 0.1, "laser_likelihood_max_dist": 2.0, "laser_model_type": "likelihood_field",
    "do_beamskip": False, "beam_skip_distance": 0.5, "beam_skip_threshold": 0.3,
    "beam_skip_error_threshold": 0.9, "odom_model_type": "diff", "odom_alpha1": 0.2, "odom_alpha2": 0.2,
    "odom_alpha3": 0.2, "odom_alpha4": 0.2, "odom_alpha5": 0.2, "odom_frame_id": "odom",
    "base_frame_id": "base_link", "global_frame_id": "map", "tf_broadcast": True,
}
# ours, not amcl's; their defaults leave amcl's behaviour unchanged (docs/localizer.md)
EXTENSIONS = {"temporal_update": -1.0, "temporal_update_jitter_xy": 0.02, "temporal_update_jitter_a": 0.02,
              "recovery_reset_after_injection": True, "recovery_local_share": 0.0, "recovery_local_std_xy": 0.5,
              "recovery_local_std_a": 0.5, "beam_fit_distance": 0.1}

# a mecanum robot's amcl settings, as such papers print them (ROS 1 names)
MECANUM_AMCL = """\
odom_model_type: omni-corrected
odom_alpha1: 0.005
odom_alpha2: 0.005
odom_alpha3: 0.01
odom_alpha4: 0.005
odom_alpha5: 0.003
laser_model_type: likelihood_field
laser_max_beams: 60
laser_max_range: 12.0
laser_z_hit: 0.5
laser_z_rand: 0.5
laser_sigma_hit: 0.2
laser_likelihood_max_dist: 2.0
min_particles: 500
max_particles: 3000
kld_err: 0.05
kld_z: 0.99
update_min_d: 0.1
update_min_a: 0.2
resample_interval: 1
transform_tolerance: 0.5
recovery_alpha_slow: 0.001
recovery_alpha_fast: 0.1
gui_publish_rate: 10.0
base_frame_id: base_footprint
use_map_topic: true
"""


# ---------------------------------------------------------------- parameters

def test_every_parameter_has_the_ros1_name_and_default():
    params = AmclParams()
    fields = set(AmclParams.__dataclass_fields__)
    assert fields == set(ROS1_DEFAULTS) | set(EXTENSIONS)
    for name, default in {**ROS1_DEFAULTS, **EXTENSIONS}.items():
        assert getattr(params, name) == pytest.approx(default) if isinstance(default, float) else \
            getattr(params, name) == default, name


def _check_mecanum(params: AmclParams):
    assert params.odom_model_type == "omni-corrected" and params.motion_params().alphas == (0.005, 0.005, 0.01, 0.005, 0.003)
    assert params.laser_max_beams == 60 and params.max_particles == 3000 and params.use_map_topic is True
    assert params.recovery_alpha_fast == 0.1 and params.base_frame_id == "base_footprint"
    assert params.laser_z_short == 0.1    # not in the file: ROS default


def test_a_ros1_flat_yaml_loads(tmp_path):
    path = tmp_path / "amcl.yaml"
    path.write_text(MECANUM_AMCL)
    _check_mecanum(load_params_file(AmclParams, path))


def test_a_ros2_layout_loads(tmp_path):
    path = tmp_path / "amcl_params.yaml"
    indented = "".join(f"    {line}\n" for line in MECANUM_AMCL.splitlines())
    path.write_text("amcl:\n  ros__parameters:\n" + indented)
    _check_mecanum(load_params_file(AmclParams, path, "amcl"))


def test_an_unknown_parameter_is_named(tmp_path):
    path = tmp_path / "amcl.yaml"
    path.write_text(MECANUM_AMCL + "laser_max_beam: 30\n")
    with pytest.raises(ParamError, match=r"unknown parameter 'laser_max_beam' \(did you mean 'laser_max_beams'\?\)") as err:
        load_params_file(AmclParams, path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("values, needle", [
    ({"laser_model_type": "lidar"}, "laser_model_type"),
    ({"odom_model_type": "mecanum"}, "odom_model_type"),
    ({"min_particles": 600, "max_particles": 500}, "max_particles"),
    ({"resample_interval": 0}, "resample_interval"),
    ({"kld_err": 0.0}, "kld_err"),
    ({"recovery_alpha_fast": 1.5}, "recovery_alpha_fast"),
    ({"laser_max_beams": 1}, "laser_max_beams"),
    ({"odom_alpha3": -0.1}, "odom_alpha3"),
    ({"beam_skip_threshold": 2.0}, "beam_skip_threshold"),
])
def test_out_of_range_values_are_named(values, needle):
    with pytest.raises(ParamError, match=needle):
        load_params(AmclParams, values, "amcl.yaml")


# ---------------------------------------------------------------- motion models

ALPHAS = (0.01, 0.02, 0.03, 0.04, 0.05)
OLD_ODOM = np.array([5.0, -1.0, 1.0])
START = np.array([1.0, 2.0, 0.3])         # every particle starts here (a different frame than odom)


def _odom_after(local_step):
    return compose(OLD_ODOM, np.asarray(local_step, float))


def _expected_diff(local_step, corrected):
    """sample_motion_model_odometry's σ, transcribed from amcl_odom.cpp for this step."""
    rot1 = math.atan2(local_step[1], local_step[0])
    trans = math.hypot(local_step[0], local_step[1])
    rot2 = local_step[2] - rot1
    a1, a2, a3, a4, _ = ALPHAS
    var = [a1 * rot1 ** 2 + a2 * trans ** 2, a3 * trans ** 2 + a4 * rot1 ** 2 + a4 * rot2 ** 2,
           a1 * rot2 ** 2 + a2 * trans ** 2]
    return (rot1, trans, rot2), [math.sqrt(v) for v in var] if corrected else var


def _expected_omni(local_step, corrected):
    t, r = math.hypot(local_step[0], local_step[1]), local_step[2]
    a1, a2, a3, a4, a5 = ALPHAS
    if corrected:
        sd = [math.sqrt(a3 * t * t + a4 * r * r), math.sqrt(a1 * r * r + a2 * t * t), math.sqrt(a4 * r * r + a5 * t * t)]
    else:
        sd = [a3 * t * t + a1 * r * r, a4 * r * r + a2 * t * t, a1 * r * r + a5 * t * t]
    return (math.atan2(local_step[1], local_step[0]), t, r), sd


@pytest.mark.parametrize("model", ["diff", "diff-corrected"])
def test_diff_models_sample_the_odometry_step_with_alpha_noise(model):
    local_step = (0.5, 0.15, 0.2)          # long enough that no sampled translation turns negative
    means, sds = _expected_diff(local_step, model == "diff-corrected")
    step = motion.decompose(model, OLD_ODOM, _odom_after(local_step), ALPHAS)
    assert (step.first, step.trans, step.second) == pytest.approx(means, abs=1e-12)
    assert step.sd == pytest.approx(sds, rel=1e-12)
    n = 20000
    poses = np.tile(START, (n, 1))
    motion.sample_motion(poses, n, step, np.random.default_rng(5))
    d = poses[:, :2] - START[:2]
    rot1 = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - START[2])
    trans = np.hypot(d[:, 0], d[:, 1])
    rot2 = wrap_angle(poses[:, 2] - START[2] - rot1)
    for values, mean, sd in zip((rot1, trans, rot2), means, sds):
        assert abs(values.mean() - mean) < 5 * sd / math.sqrt(n)
        assert values.std() == pytest.approx(sd, rel=0.04)


@pytest.mark.parametrize("model", ["omni", "omni-corrected"])
def test_omni_models_sample_the_odometry_step_with_alpha_noise(model):
    local_step = (0.2, -0.25, 0.3)          # forward, strafing right, turning left
    (bearing, trans, rot), sds = _expected_omni(local_step, model == "omni-corrected")
    step = motion.decompose(model, OLD_ODOM, _odom_after(local_step), ALPHAS)
    assert (step.first, step.trans, step.second) == pytest.approx((bearing, trans, rot), abs=1e-12)
    assert step.sd == pytest.approx(sds, rel=1e-12)
    n = 20000
    poses = np.tile(START, (n, 1))
    motion.sample_motion(poses, n, step, np.random.default_rng(6))
    d = poses[:, :2] - START[:2]
    b = START[2] + bearing
    along = d[:, 0] * math.cos(b) + d[:, 1] * math.sin(b)
    side = d[:, 0] * math.sin(b) - d[:, 1] * math.cos(b)
    turn = wrap_angle(poses[:, 2] - START[2])
    for values, mean, sd in zip((along, turn, side), (trans, rot, 0.0), sds):
        assert abs(values.mean() - mean) < 5 * sd / math.sqrt(n)
        assert values.std() == pytest.approx(sd, rel=0.04)


@pytest.mark.parametrize("model", ["diff", "omni", "diff-corrected", "omni-corrected"])
def test_without_noise_every_particle_moves_by_the_odometry_step_in_its_own_frame(model):
    local_step = (0.4, 0.0 if model.startswith("diff") else 0.15, -0.5)
    step = motion.decompose(model, OLD_ODOM, _odom_after(local_step), (0.0,) * 5)
    poses = np.array([START, [-3.0, 4.0, -2.9], [0.0, 0.0, 3.1]])
    expected = compose(poses, np.array(local_step))
    motion.sample_motion(poses, 3, step, np.random.default_rng(0))
    assert np.allclose(poses[:, :2], expected[:, :2], atol=1e-12)
    assert np.allclose(wrap_angle(poses[:, 2] - expected[:, 2]), 0.0, atol=1e-12)


def test_driving_backwards_is_not_a_half_turn_for_the_noise():
    # amcl measures turn noise by min(|rot|, |π − rot|): a straight reverse has no turn noise
    step = motion.decompose("diff-corrected", OLD_ODOM, _odom_after((-0.3, 0.0, 0.0)), (1.0, 0.0, 0.0, 0.0, 0.0))
    assert abs(abs(step.first) - math.pi) < 1e-12 and step.sd[0] == pytest.approx(0.0, abs=1e-12)


# ---------------------------------------------------------------- laser models

@pytest.fixture(scope="module")
def room():
    world = load_world(world_path("room"))
    return world, world.rasterize(0.05)


LIDAR = LidarParams(beams=360, range_max=10.0, noise_std=0.01)


def _scan(world, pose, params, seed=1, movers=None):
    ranges = scan(world, pose, movers, LIDAR, np.random.default_rng(seed))
    return prepare_scan(ranges, LIDAR.angle_min, LIDAR.angle_increment, LIDAR.range_min, LIDAR.range_max, params)


OFFSETS = np.array([(dx, dy, da) for dx in (-0.2, -0.1, 0.0, 0.1, 0.2) for dy in (-0.2, -0.1, 0.0, 0.1, 0.2)
                    for da in (-0.1, 0.0, 0.1)])


@pytest.mark.parametrize("model", ["beam", "likelihood_field", "likelihood_field_prob"])
@pytest.mark.parametrize("truth", [(2.0, 2.0, 0.3), (6.5, 5.5, -2.0)])
def test_each_laser_model_weighs_the_true_pose_highest(room, model, truth):
    world, grid = room
    params = AmclParams(laser_model_type=model, laser_max_beams=60)
    laser = LaserModel(grid, params)
    poses = np.asarray(truth) + OFFSETS
    weights = np.ones(len(poses))
    total = laser.weigh(poses, len(poses), _scan(world, truth, params), weights)
    assert total == pytest.approx(weights.sum())
    best = int(np.argmax(weights))
    assert np.allclose(OFFSETS[best], 0.0), (OFFSETS[best], weights[best], weights.max())


def test_the_likelihood_field_kernel_equals_the_plain_numpy_formula(room):
    world, grid = room
    params = AmclParams(laser_max_beams=60)
    laser = LaserModel(grid, params)
    beams = _scan(world, (3.0, 4.0, 1.0), params)
    poses = np.random.default_rng(3).normal((3.0, 4.0, 1.0), (1.0, 1.0, 0.5), (500, 3))
    poses[:20, :2] += 30.0                  # some end points off the map
    weights = np.full(500, 2.0)
    laser.weigh(poses, 500, beams, weights)
    assert np.allclose(weights, 2.0 * likelihood_field_numpy(laser, poses, beams), rtol=1e-12)


def _grid(data, resolution, origin):
    data = np.asarray(data, np.int8)
    return OccupancyGrid(info=MapMetaData(resolution=resolution, width=data.shape[1], height=data.shape[0],
                                          origin=Pose2D(*origin)), data=data)


def test_the_field_is_the_clipped_distance_to_the_nearest_obstacle():
    data = np.zeros((20, 20), np.int8)
    data[10, 10] = 100
    data[0, 19] = 50                        # not an obstacle for amcl: only 100 is
    laser = LaserModel(_grid(data, 0.1, (0.0, 0.0, 0.0)), AmclParams(laser_likelihood_max_dist=0.5, laser_sigma_hit=0.2))
    assert laser.distance[10, 10] == 0.0
    assert laser.distance[10, 13] == pytest.approx(0.3)
    assert laser.distance[13, 12] == pytest.approx(math.hypot(0.3, 0.2))
    assert laser.distance[13, 14] == pytest.approx(0.5)      # exactly max, 3-4-5
    assert laser.distance[0, 0] == pytest.approx(0.5) and laser.distance[0, 19] == pytest.approx(0.5)
    assert laser.hit[10, 13] == pytest.approx(math.exp(-0.09 / 0.08))


def test_a_map_with_a_yawed_origin_gives_the_same_weights():
    """The same cells stored half a turn around (origin yaw π, as the Stata basement map)."""
    rng = np.random.default_rng(2)
    data = np.where(rng.random((30, 40)) < 0.05, 100, 0).astype(np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    res = 0.1
    plain = _grid(data, res, (1.0, 2.0, 0.0))
    turned = _grid(data[::-1, ::-1], res, (1.0 + 40 * res, 2.0 + 30 * res, math.pi))
    # the same world point falls in corresponding cells
    assert np.allclose(cell_to_world(plain.info, 3, 7), cell_to_world(turned.info, 26, 32))
    params = AmclParams(laser_max_beams=30)
    beams = prepare_scan(rng.uniform(0.3, 2.5, 90), -math.pi, 2 * math.pi / 90, 0.1, 8.0, params)
    poses = rng.normal((3.0, 3.5, 0.5), (0.8, 0.6, 1.0), (200, 3))
    w_plain, w_turned = np.ones(200), np.ones(200)
    LaserModel(plain, params).weigh(poses, 200, beams, w_plain)
    LaserModel(turned, params).weigh(poses, 200, beams, w_turned)
    assert np.allclose(w_plain, w_turned, rtol=1e-9)


def test_scan_preparation_picks_beams_and_handles_short_and_long_readings():
    ranges = np.full(1081, 5.0)
    ranges[0], ranges[18], ranges[36], ranges[54] = 0.01, np.inf, -np.inf, np.nan
    lf = prepare_scan(ranges, -2.356, 0.0043633, 0.06, 30.0, AmclParams(laser_max_beams=60))
    assert len(lf.ranges) == 61                    # every (1081 − 1) // 59 = 18th beam, as amcl
    assert lf.ranges[0] == 30.0 and lf.ranges[2] == 30.0    # too short (and −inf): range_max
    assert lf.ranges[1] == np.inf and np.isnan(lf.ranges[3])
    assert lf.bearings[1] == pytest.approx(-2.356 + 18 * 0.0043633)
    prob = prepare_scan(ranges, -2.356, 0.0043633, 0.06, 30.0,
                        AmclParams(laser_max_beams=60, laser_model_type="likelihood_field_prob"))
    assert len(prob.ranges) == 57                  # every ceil(1081 / 60) = 19th beam
    capped = prepare_scan(ranges, 0.0, 0.01, 0.06, 30.0,
                          AmclParams(laser_max_beams=60, laser_max_range=4.0, laser_min_range=0.5))
    assert capped.range_max == 4.0 and np.all((capped.ranges == 4.0) | ~np.isfinite(capped.ranges))
    assert len(lf.end_points()[0]) == 61 - 4       # max-range, beyond-range and NaN readings are not used


def test_beam_skipping_drops_the_beams_that_disagree_with_the_map(room):
    world, grid = room
    truth = np.array([1.8, 4.25, 0.0])
    person = np.array([[3.0, 4.25, 0.3]])  # in open space, not in the map
    params = AmclParams(laser_model_type="likelihood_field_prob", laser_max_beams=60, do_beamskip=True)
    laser = LaserModel(grid, params)
    beams = _scan(world, truth, params, movers=person)
    end_x, end_y = beams.end_points()
    on_person = np.hypot(truth[0] + end_x - person[0, 0], truth[1] + end_y - person[0, 1]) < person[0, 2] + 0.05
    assert 2 <= on_person.sum() < 0.5 * len(end_x)
    assert world.distance(np.column_stack([truth[0] + end_x, truth[1] + end_y])[on_person]).min() > 0.6
    poses = truth + np.random.default_rng(4).normal(0.0, (0.03, 0.03, 0.01), (300, 3))
    poses[0] = truth

    skipping = np.ones(300)
    laser.weigh(poses, 300, beams, skipping, converged=True)
    assert laser.beams_skipped == on_person.sum()
    # the same weights as a scan without those beams at all
    ranges = beams.ranges.copy()
    ranges[np.flatnonzero(beams.ranges < beams.range_max)[on_person]] = np.inf
    kept = dataclasses.replace(beams, ranges=ranges)
    plain_laser = LaserModel(grid, AmclParams(laser_model_type="likelihood_field_prob", laser_max_beams=60))
    without = np.ones(300)
    plain_laser.weigh(poses, 300, kept, without)
    assert np.allclose(skipping, without, rtol=1e-9)

    laser.weigh(poses, 300, beams, np.ones(300), converged=False)   # amcl skips only once converged
    assert laser.beams_skipped == 0
    # a cloud converged at a wrong pose: most beams disagree, which means the filter is lost, and
    # from beam_skip_error_threshold on every beam is used again
    lost = poses + (2.5, 1.5, 1.0)
    laser.weigh(lost, 300, beams, np.ones(300), converged=True)
    share = laser.beams_skipped / len(end_x)
    assert 0.5 < share < 0.9
    strict = LaserModel(grid, dataclasses.replace(params, beam_skip_error_threshold=0.5))
    lost_weights = np.ones(300)
    strict.weigh(lost, 300, beams, lost_weights, converged=True)
    assert strict.beams_skipped == 0
    all_beams = np.ones(300)
    plain_laser.weigh(lost, 300, beams, all_beams)
    assert np.allclose(lost_weights, all_beams, rtol=1e-9)


def test_each_model_gets_its_own_group_of_the_flat_ros_names():
    """ROS amcl's flat names load as they are; the laser and motion models in use each get their group."""
    params = load_params(AmclParams, {"laser_model_type": "beam", "laser_z_hit": 0.8, "laser_z_short": 0.2,
                                      "odom_model_type": "omni", "odom_alpha5": 0.3, "odom_alpha1": 0.1})
    assert params.laser_params() == BeamModelParams(laser_z_hit=0.8, laser_z_short=0.2)
    assert params.motion_params() == OmniMotionParams(odom_alpha1=0.1, odom_alpha5=0.3)
    likelihood = dataclasses.replace(params, laser_model_type="likelihood_field", odom_model_type="diff-corrected")
    assert type(likelihood.laser_params()) is LikelihoodFieldParams
    assert likelihood.motion_params() == DiffMotionParams(odom_alpha1=0.1)
    assert likelihood.motion_params().alphas == (0.1, 0.2, 0.2, 0.2, 0.0)    # no strafe noise on a diff drive
    with pytest.raises(ParamError, match="parameter laser_z_short must be ≥ 0, got -0.1"):
        load_params(AmclParams, {"laser_z_short": -0.1})
