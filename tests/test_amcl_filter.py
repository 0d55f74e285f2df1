"""AMCL core, the particle filter: KLD bound, resampling, update gating, estimate, and whole runs
(tracking, global localization, kidnapping) against the simulator's ground truth."""
import math
import os

import numpy as np
import pytest
import yaml
from scipy import stats

from omninav.services.localizer.filter import Amcl, kld_limit, map_to_odom, systematic_indices
from omninav.services.localizer.params import AmclParams
from omninav.services.localizer.sensor import prepare_scan
from omninav.geometry.se2 import compose, wrap_angle
from omninav.sim.lidar import LidarParams, scan
from omninav.sim.world import load_world, world_path

SEED = int(os.environ.get("AMCL_TEST_SEED", "0"))
LIDAR = LidarParams(beams=360, range_max=10.0, noise_std=0.01)
# tracking settings: odometry noise as a good wheel odometry has it, an update every 0.1 m or 0.2 rad
TRACKING = dict(laser_max_beams=60, odom_model_type="diff-corrected", odom_alpha1=0.02, odom_alpha2=0.02,
                odom_alpha3=0.02, odom_alpha4=0.02, odom_alpha5=0.02, update_min_d=0.1, update_min_a=0.2,
                resample_interval=1)

# ---------------------------------------------------------------- the KLD bound


@pytest.mark.parametrize("k, err, z, expected", [
    # ⌈(k−1)/(2ε)·(1 − 2/(9(k−1)) + √(2/(9(k−1)))·z)³⌉, worked by hand:
    (2, 0.01, 0.99, 97),       # 50 · (1 − 0.222222 + 0.471405·0.99)³ = 50 · 1.244472³ = 96.37
    (10, 0.05, 3.0, 273),      # 90 · (1 − 0.024691 + 0.157135·3)³ = 90 · 1.446714³ = 272.51
    (50, 0.05, 0.99, 588),     # 490 · (1 − 0.004535 + 0.067344·0.99)³ = 490 · 1.062135³ = 587.13
    (100, 0.01, 0.99, 5644),   # 4950 · (1 − 0.002245 + 0.047379·0.99)³ = 4950 · 1.044660³ = 5643.25
])
def test_the_kld_bound_is_fox_formula(k, err, z, expected):
    assert kld_limit(k, err, z, 1, 10 ** 6) == expected


def test_the_kld_bound_is_clamped_and_one_bin_needs_the_most():
    assert kld_limit(2, 0.01, 0.99, 100, 5000) == 100
    assert kld_limit(100, 0.01, 0.99, 100, 5000) == 5000
    assert kld_limit(1, 0.01, 0.99, 100, 5000) == 5000
    assert kld_limit(0, 0.01, 0.99, 100, 5000) == 5000


@pytest.mark.parametrize("k", [10, 30, 100, 1000])
def test_the_kld_bound_approximates_the_chi_square_quantile(k):
    # Fox 2003: n = χ²_{k−1, 1−δ} / (2ε), z the standard normal quantile of 1 − δ
    delta, err = 0.01, 0.05
    exact = stats.chi2.ppf(1 - delta, k - 1) / (2 * err)
    assert kld_limit(k, err, stats.norm.ppf(1 - delta), 1, 10 ** 9) == pytest.approx(exact, rel=0.01)


# ---------------------------------------------------------------- resampling

@pytest.mark.parametrize("count", [7, 100, 1000, 2500])
def test_systematic_resampling_keeps_the_distribution(count):
    rng = np.random.default_rng(count)
    weights = rng.dirichlet(np.full(300, 0.3))
    for u0 in (0.0, 0.37, 0.999):
        out = np.zeros(count, np.int64)
        systematic_indices(np.cumsum(weights), 300, count, u0, out)
        copies = np.bincount(out, minlength=300)
        assert copies.sum() == count
        assert np.all(np.abs(copies - count * weights) < 1.0 + 1e-9)


# ---------------------------------------------------------------- the filter, step by step

@pytest.fixture(scope="module")
def room():
    world = load_world(world_path("room"))
    return world, world.rasterize(0.05)


def _beams(world, pose, params, rng):
    ranges = scan(world, pose, None, LIDAR, rng)
    return prepare_scan(ranges, LIDAR.angle_min, LIDAR.angle_increment, LIDAR.range_min, LIDAR.range_max, params)


def test_updates_only_after_enough_motion_as_amcl_measures_it(room):
    world, grid = room
    params = AmclParams(min_particles=50, max_particles=200)      # update_min_d 0.2, update_min_a π/6
    amcl = Amcl(params, grid, np.random.default_rng(0))
    beams = _beams(world, (1.2, 1.0, 0.0), params, np.random.default_rng(1))
    assert amcl.update((0.0, 0.0, 0.0), beams)                    # the first scan starts the filter
    assert not amcl.update((0.15, 0.15, 0.0), beams)              # 0.21 m, but under 0.2 along each axis
    assert not amcl.update((0.0, 0.0, 0.5), beams)                # under π/6
    assert amcl.update((0.0, 0.0, 0.53), beams)
    assert not amcl.update((0.19, 0.0, 0.53), beams)              # measured from the last update
    assert amcl.update((0.0, -0.21, 0.53), beams)
    amcl.request_nomotion_update()
    assert amcl.update((0.0, -0.21, 0.53), beams)
    assert not amcl.update((0.0, -0.21, 0.53), beams)
    amcl.set_initial_pose((1.2, 1.0, 0.0), np.eye(3) * 0.01)   # the next scan restarts the filter
    assert amcl.update((5.0, 5.0, 0.0), beams) and not amcl.update((5.0, 5.0, 0.0), beams)


def test_temporal_updates_come_at_their_period_without_motion_and_never_by_default(room):
    world, grid = room
    beams = _beams(world, (1.2, 1.0, 0.0), AmclParams(), np.random.default_rng(1))
    stamps = np.arange(0.0, 2.05, 0.1)
    ros = Amcl(AmclParams(min_particles=50, max_particles=200), grid, np.random.default_rng(0))
    assert [ros.update((0.0, 0.0, 0.0), beams, t) for t in stamps].count(True) == 1   # the first scan only
    params = AmclParams(min_particles=50, max_particles=200, temporal_update=0.5)
    amcl = Amcl(params, grid, np.random.default_rng(0))
    updated = [t for t in stamps if amcl.update((0.0, 0.0, 0.0), beams, t)]
    assert updated == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0])
    assert amcl.update((0.3, 0.0, 0.0), beams, 2.1)                     # motion updates as before ...
    assert not amcl.update((0.3, 0.0, 0.0), beams, 2.5)                 # ... and restart the period
    assert not amcl.update((0.3, 0.0, 0.0), beams)                      # no stamp: no temporal update


def _stopped_behind(grid, world, temporal_update, jitter):
    """The robot stands at (1.6, 1.0) but the filter believes it 0.3 m behind, all its particles
    within a few cm of that: 5 s of scans without motion."""
    params = AmclParams(min_particles=200, max_particles=500, laser_max_beams=60, resample_interval=1,
                        laser_model_type="likelihood_field_prob", initial_pose_x=1.3, initial_pose_y=1.0,
                        initial_cov_xx=0.03 ** 2, initial_cov_yy=0.03 ** 2, initial_cov_aa=0.01 ** 2,
                        temporal_update=temporal_update, temporal_update_jitter_xy=jitter,
                        temporal_update_jitter_a=jitter)
    amcl = Amcl(params, grid, np.random.default_rng(SEED))
    rng = np.random.default_rng(SEED + 1)
    for t in np.arange(0.0, 5.0, 0.1):
        amcl.update((0.0, 0.0, 0.0), _beams(world, (1.6, 1.0, 0.0), params, rng), t)
    return amcl


def test_without_motion_temporal_updates_bring_the_estimate_to_what_the_scans_say(room):
    world, grid = room
    amcl = _stopped_behind(grid, world, 0.1, 0.02)
    x, y, theta = amcl.estimate().pose
    assert math.hypot(x - 1.6, y - 1.0) < 0.03 and abs(theta) < 0.02
    assert len(np.unique(amcl.poses, axis=0)) > 0.3 * amcl.n        # still a cloud, not copies of a few
    ros = _stopped_behind(grid, world, -1.0, 0.02)                      # amcl: no update without motion
    assert math.hypot(ros.estimate().pose[0] - 1.6, ros.estimate().pose[1] - 1.0) > 0.2


def test_without_jitter_repeated_updates_collapse_the_particles(room):
    world, grid = room
    amcl = _stopped_behind(grid, world, 0.1, 0.0)
    assert len(np.unique(amcl.poses, axis=0)) < 10                      # particle deprivation
    assert math.hypot(amcl.estimate().pose[0] - 1.6, amcl.estimate().pose[1] - 1.0) > 0.15


def test_force_update_after_initialpose(room):
    world, grid = room
    params = AmclParams(min_particles=50, max_particles=200, force_update_after_initialpose=True)
    amcl = Amcl(params, grid, np.random.default_rng(0))
    beams = _beams(world, (1.2, 1.0, 0.0), params, np.random.default_rng(1))
    # as amcl: the restart scan, then one more update without motion, then motion is needed again
    assert [amcl.update((0.0, 0.0, 0.0), beams) for _ in range(3)] == [True, True, False]


def test_resampling_every_resample_interval_updates(room):
    world, grid = room
    params = AmclParams(min_particles=50, max_particles=500, resample_interval=3, update_min_d=0.0, update_min_a=0.0)
    amcl = Amcl(params, grid, np.random.default_rng(0))
    beams = _beams(world, (1.2, 1.0, 0.0), params, np.random.default_rng(1))
    resampled = []
    for k in range(9):
        assert amcl.update((0.01 * k, 0.0, 0.0), beams)
        resampled.append(amcl.resampled)
    assert resampled == [False, False, True] * 3
    assert np.allclose(amcl.weights, 1.0 / amcl.n)


def test_the_weight_averages_follow_the_recovery_rates(room):
    world, grid = room
    params = AmclParams(max_particles=500, recovery_alpha_slow=0.01, recovery_alpha_fast=0.3, update_min_d=0.0,
                        resample_interval=100)
    amcl = Amcl(params, grid, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    amcl.update((0.0, 0.0, 0.0), _beams(world, (1.2, 1.0, 0.0), params, rng))
    slow = fast = amcl.w_avg
    assert amcl.w_slow == slow and amcl.w_fast == fast and slow > 0
    for k in range(1, 5):
        amcl.update((0.01 * k, 0.0, 0.0), _beams(world, (1.2 + 0.01 * k, 1.0, 0.0), params, rng))
        slow += 0.01 * (amcl.w_avg - slow)
        fast += 0.3 * (amcl.w_avg - fast)
        assert amcl.w_slow == pytest.approx(slow) and amcl.w_fast == pytest.approx(fast)


def test_the_initial_pose_is_a_gaussian_of_max_particles(room):
    _, grid = room
    params = AmclParams(initial_pose_x=2.0, initial_pose_y=3.0, initial_pose_a=3.0, initial_cov_xx=0.09,
                        initial_cov_yy=0.04, initial_cov_aa=0.01)
    amcl = Amcl(params, grid, np.random.default_rng(0))
    assert amcl.n == 5000 and np.allclose(amcl.weights, 1 / 5000)
    poses = amcl.poses
    assert poses[:, :2].mean(axis=0) == pytest.approx([2.0, 3.0], abs=0.02)
    assert np.var(poses[:, 0]) == pytest.approx(0.09, rel=0.08) and np.var(poses[:, 1]) == pytest.approx(0.04, rel=0.08)
    turn = wrap_angle(poses[:, 2] - 3.0)   # wraps across ±π
    assert np.all((poses[:, 2] >= -math.pi) & (poses[:, 2] < math.pi))
    assert turn.mean() == pytest.approx(0.0, abs=0.01) and np.var(turn) == pytest.approx(0.01, rel=0.08)


def test_global_localization_spreads_the_particles_over_free_space(room):
    world, grid = room
    amcl = Amcl(AmclParams(max_particles=3000), grid, np.random.default_rng(0))
    amcl.global_localization()
    poses = amcl.poses
    assert amcl.n == 3000
    assert np.all(world.distance(poses[:, :2]) > 0.0)             # none inside furniture or walls
    x0, y0, x1, y1 = world.extent
    assert np.ptp(poses[:, 0]) > 0.9 * (x1 - x0) and np.ptp(poses[:, 1]) > 0.9 * (y1 - y0)
    assert np.histogram(poses[:, 2], bins=8, range=(-math.pi, math.pi))[0].min() > 300


def test_the_estimate_is_the_mean_of_the_heaviest_cluster(room):
    _, grid = room
    amcl = Amcl(AmclParams(max_particles=400), grid, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    near = rng.normal((2.0, 2.0, 3.1), (0.05, 0.05, 0.02), (200, 3))   # straddles ±π
    far = rng.normal((7.0, 5.0, 0.0), (0.05, 0.05, 0.02), (200, 3))
    near[:, 2] = wrap_angle(near[:, 2])
    amcl.poses[:] = np.vstack([near, far])
    amcl.weights[:] = np.r_[np.full(200, 0.6 / 200), np.full(200, 0.4 / 200)]
    estimate = amcl.estimate()
    assert estimate.clusters == 2 and estimate.weight == pytest.approx(0.6)
    assert estimate.pose[:2] == pytest.approx(near[:, :2].mean(axis=0))
    assert abs(wrap_angle(estimate.pose[2] - 3.1)) < 0.01
    # the covariance is the whole set's, as amcl publishes it
    mean = 0.6 * near[:, :2].mean(axis=0) + 0.4 * far[:, :2].mean(axis=0)
    xx = 0.6 * np.mean(near[:, 0] ** 2) + 0.4 * np.mean(far[:, 0] ** 2) - mean[0] ** 2
    assert estimate.covariance[0, 0] == pytest.approx(xx)
    assert estimate.covariance[2, 2] > 1.0                     # headings 3.1 and 0: far apart


def test_map_to_odom_carries_the_estimate_with_the_odometry():
    map_pose, odom_pose = np.array([3.0, -1.0, 2.5]), np.array([-7.0, 4.0, -1.0])
    transform = map_to_odom(map_pose, odom_pose)
    assert np.allclose(compose(transform, odom_pose), map_pose)


def test_same_seed_same_particles(room):
    world, grid = room
    params = AmclParams(max_particles=1000, recovery_alpha_slow=0.001, recovery_alpha_fast=0.1, **TRACKING)
    runs = []
    for _ in range(2):
        amcl = Amcl(params, grid, np.random.default_rng(42))
        rng = np.random.default_rng(7)
        for k in range(6):
            amcl.update((0.12 * k, 0.0, 0.0), _beams(world, (1.2 + 0.12 * k, 1.0, 0.0), params, rng))
        runs.append((amcl.poses.copy(), amcl.weights.copy()))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


# ---------------------------------------------------------------- whole runs against ground truth

def drive(world, start, steps, rng, strafe=False, kidnap=None):
    """A scripted route: straight 0.1 m steps (diagonal ones for a holonomic robot), turning on the
    spot by 0.3 rad while something is within 0.45 m ahead. Yields (true pose, odometry pose); the
    odometry is the true motion with Gaussian noise. `kidnap()` returns a pose to teleport to, or None."""
    move = np.array([0.07, 0.07, 0.0]) if strafe else np.array([0.1, 0.0, 0.0])
    ahead = 0.45 * move / np.hypot(move[0], move[1])
    true, odom = np.asarray(start, float), np.zeros(3)
    for _ in range(steps):
        jump = kidnap() if kidnap else None
        if jump is not None:
            true = np.asarray(jump, float)
        clear = world.distance(compose(true, [ahead[0], ahead[1], 0.0])[None, :2])[0] > 0.45
        step = move if clear else np.array([0.0, 0.0, 0.3])
        true = compose(true, step)
        odom = compose(odom, step + rng.normal(0.0, 0.003, 3))
        yield true, odom


def run(amcl, world, route, rng):
    """Errors (m, rad) of the pose the filter gives after each scan (its estimate carried forward by odometry)."""
    errors = []
    for true, odom in route:
        amcl.update(odom, _beams(world, true, amcl.params, rng))
        pose = amcl.pose_at(odom)
        errors.append((math.hypot(pose[0] - true[0], pose[1] - true[1]), abs(float(wrap_angle(pose[2] - true[2])))))
    return np.array(errors)


@pytest.mark.parametrize("model", ["diff-corrected", "omni-corrected"])
def test_tracking_from_a_rough_initial_pose(room, model):
    world, grid = room
    start = np.asarray(world.robot.start, float)
    off = compose(start, (0.5 * math.cos(2.0), 0.5 * math.sin(2.0), math.radians(15)))   # 0.5 m and 15° off
    params = AmclParams(**{**TRACKING, "odom_model_type": model}, min_particles=300, max_particles=2000,
                        initial_pose_x=off[0], initial_pose_y=off[1], initial_pose_a=off[2])
    amcl = Amcl(params, grid, np.random.default_rng(SEED))
    rng = np.random.default_rng(SEED + 1)
    errors = run(amcl, world, drive(world, start, 250, rng, strafe=model.startswith("omni")), rng)
    assert errors[0, 0] > 0.2                                   # it did start off
    settled = errors[100:]                                      # converged within about 25 steps
    assert np.percentile(settled[:, 0], 95) < 0.075 and settled[:, 0].max() < 0.1
    assert math.degrees(settled[:, 1].max()) < 3.0
    assert amcl.n < 2000                                        # KLD shrank the set once converged


SMALL_WORLD = {
    "bounds": [4.0, 3.0], "robot": {"start": [0.7, 0.7, 0.0]},
    "boxes": [{"center": [3.4, 2.5], "size": [1.2, 1.0]}, {"center": [0.9, 2.5], "size": [0.6, 0.3]},
              {"center": [2.9, 0.8], "size": [0.3, 0.6], "yaw": 0.4}],
    "circles": [{"center": [1.9, 1.6], "radius": 0.2}],
}


@pytest.fixture(scope="module")
def small_room(tmp_path_factory):
    path = tmp_path_factory.mktemp("worlds") / "small.yaml"
    path.write_text(yaml.safe_dump(SMALL_WORLD))
    world = load_world(path)
    return world, world.rasterize(0.05)


def test_global_localization_converges(small_room):
    world, grid = small_room
    params = AmclParams(**TRACKING, min_particles=500, max_particles=5000)
    amcl = Amcl(params, grid, np.random.default_rng(SEED))
    amcl.global_localization()
    rng = np.random.default_rng(SEED + 1)
    errors = run(amcl, world, drive(world, world.robot.start, 100, rng), rng)
    assert errors[0, 0] > 1.0
    assert errors[-30:, 0].max() < 0.1 and math.degrees(errors[-30:, 1].max()) < 3.0


def _kidnapped_run(world, grid, alpha_slow, alpha_fast):
    start = np.asarray(world.robot.start, float)
    params = AmclParams(**TRACKING, min_particles=500, max_particles=20000, recovery_alpha_slow=alpha_slow,
                        recovery_alpha_fast=alpha_fast, initial_pose_x=start[0], initial_pose_y=start[1],
                        initial_pose_a=start[2], initial_cov_xx=0.02 ** 2, initial_cov_yy=0.02 ** 2,
                        initial_cov_aa=0.02 ** 2)
    amcl = Amcl(params, grid, np.random.default_rng(SEED))
    rng = np.random.default_rng(SEED + 1)
    spots = np.array([(x, y) for x in np.arange(0.4, 3.7, 0.2) for y in np.arange(0.4, 2.7, 0.2)])
    spots = spots[world.distance(spots) > 0.45]
    state = {"steps": 0, "at": None}
    truth = []

    def kidnap():
        # once tracking for 40 steps, with its weight averages in place (amcl zeroes both after
        # every injection and restarts them at the next update), teleport the robot to the free
        # spot farthest from it, turned by 2.5 rad
        state["steps"] += 1
        if state["at"] is None and state["steps"] > 40 and amcl.w_slow > 0:
            state["at"] = state["steps"] - 1           # the index of the first scan after the jump
            far = spots[np.argmax(np.hypot(*(spots - truth[-1][:2]).T))]
            return far[0], far[1], truth[-1][2] + 2.5
        return None

    route = drive(world, start, 300, rng, kidnap=kidnap)
    errors = []
    for true, odom in route:
        truth.append(true)
        amcl.update(odom, _beams(world, true, params, rng))
        pose = amcl.pose_at(odom)
        errors.append(math.hypot(pose[0] - true[0], pose[1] - true[1]))
    return np.array(errors), state["at"]


def test_a_kidnapped_robot_is_found_again_with_recovery(small_room):
    world, grid = small_room
    errors, at = _kidnapped_run(world, grid, 0.001, 0.1)     # ROS's suggested rates
    assert errors[at - 4:at].max() < 0.05                     # tracking before
    assert errors[at] > 1.0                                   # teleported far
    assert errors[-50:].max() < 0.1                           # and found again


def test_without_recovery_a_kidnapped_robot_stays_lost(small_room):
    world, grid = small_room
    errors, at = _kidnapped_run(world, grid, 0.0, 0.0)
    assert errors[at - 4:at].max() < 0.05 and errors[at] > 1.0 and errors[-50:].min() > 0.5
