import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from omninav.services.chassis.follower_wheels import (calibrate_followers, follower_odometry,
                                               follower_readings)
from omninav.services.chassis.kinematics import DRIVES, ChassisParams, Kinematics
from omninav.services.chassis.odometry import wheel_odometry
from omninav.geometry.se2 import compose, integrate, inverse, relative, se2_exp, wrap_angle

poses = arrays(np.float64, 3, elements=st.floats(-20.0, 20.0, allow_nan=False))
NS = 1_000_000_000


def circle_truth(start, twist, t):
    """Pose after a constant body twist, from the integral of the rotating world velocity."""
    x0, y0, th0 = start
    vx, vy, wz = twist
    th1 = th0 + wz * t
    # (sin(th1) - sin(th0)) / wz and (cos(th1) - cos(th0)) / wz in product form, with
    # sin(wz t / 2) / wz = t/2 sinc(wz t / 2), which neither cancels nor divides by zero
    half = t / 2 * float(np.sinc(wz * t / (2 * math.pi)))
    mid = (th0 + th1) / 2
    ds, dc = 2 * math.cos(mid) * half, -2 * math.sin(mid) * half
    return np.array([x0 + ds * vx + dc * vy, y0 - dc * vx + ds * vy, float(wrap_angle(th1))])


def assert_pose_close(actual, expected, tol):
    np.testing.assert_allclose(actual[:2], expected[:2], atol=tol)
    assert abs(float(wrap_angle(actual[2] - expected[2]))) <= tol


# --- SE(2) helpers ---

@given(a=poses, b=poses, c=poses)
def test_compose_inverse_relative_are_consistent(a, b, c):
    assert_pose_close(compose(a, inverse(a)), np.zeros(3), 1e-9)
    assert_pose_close(relative(a, compose(a, b)), b, 1e-9)
    assert_pose_close(compose(compose(a, b), c), compose(a, compose(b, c)), 1e-9)


def test_pose_helpers_broadcast_over_batches():
    rng = np.random.default_rng(1)
    a, b = rng.uniform(-3, 3, (5, 3)), rng.uniform(-3, 3, (5, 3))
    batch = relative(a, b)
    assert batch.shape == (5, 3)
    for i in range(5):
        np.testing.assert_allclose(batch[i], relative(a[i], b[i]))
    np.testing.assert_allclose(compose(a[0], b), [compose(a[0], row) for row in b])
    np.testing.assert_allclose(compose([1.0, 2.0, math.pi / 2], [1.0, 0.0, 0.0]), [1.0, 3.0, math.pi / 2])


def test_wrap_angle_range():
    angles = np.array([-7.0, -math.pi, 0.0, math.pi, 3 * math.pi + 0.1, 100.0])
    wrapped = wrap_angle(angles)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angles), atol=1e-12)


def test_se2_exp_near_zero_rotation_matches_the_series():
    for phi in (0.0, 1e-12, 1e-8, 1e-5, 1e-3):
        dx, dy = 0.7, -0.4
        along = 1 - phi ** 2 / 6 + phi ** 4 / 120
        across = phi / 2 - phi ** 3 / 24 + phi ** 5 / 720
        expected = [along * dx - across * dy, across * dx + along * dy, phi]
        np.testing.assert_allclose(se2_exp([dx, dy, phi]), expected, rtol=1e-15, atol=1e-17)


@settings(max_examples=15, deadline=None)
@given(start=poses, twist=arrays(np.float64, 3, elements=st.floats(-2.0, 2.0, allow_nan=False)),
       duration=st.floats(0.05, 2.0))
def test_exact_integration_matches_fine_euler_steps(start, twist, duration):
    steps = 20_000
    h = duration / steps
    x, y, th = (float(v) for v in start)
    vx, vy, wz = (float(v) for v in twist)
    for _ in range(steps):
        c, s = math.cos(th), math.sin(th)
        x, y, th = x + (c * vx - s * vy) * h, y + (s * vx + c * vy) * h, th + wz * h
    exact = integrate(start, twist, duration)
    # Euler's error over the run is about |v| |wz| duration h / 2 per axis
    assert_pose_close(exact, [x, y, th], math.hypot(vx, vy) * abs(wz) * duration * h + 1e-9)
    assert_pose_close(exact, circle_truth(start, twist, duration), 1e-9)


def test_a_full_circle_comes_back_to_the_start():
    start = np.array([1.0, -2.0, 0.4])
    assert_pose_close(integrate(start, [0.5, 0.2, 0.8], 2 * math.pi / 0.8), start, 1e-12)


# --- wheel odometry ---

def drive_wheels(params, twists, dt, start=(0.0, 0.0, 0.0), gyro=None):
    """Feed wheel angles accumulated from commanded twists (one per step) into wheel odometry."""
    kin = Kinematics(params)
    odom = wheel_odometry(params, start)
    angles = np.zeros(kin.n_wheels)
    estimate = odom.update(0, angles)
    for k, twist in enumerate(twists, start=1):
        angles = angles + kin.ik(twist) * dt
        rate = twist[2] if gyro is None else gyro
        estimate = odom.update(round(k * dt * NS), angles, rate)
    return estimate


@pytest.mark.parametrize("drive", DRIVES)
def test_straight_5_m_drive_gives_the_true_pose(drive):
    params = ChassisParams(drive=drive)
    estimate = drive_wheels(params, [np.array([0.5, 0.0, 0.0])] * 500, 0.02)
    np.testing.assert_allclose(estimate.pose, [5.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(estimate.twist, [0.5, 0.0, 0.0], atol=1e-9)
    assert estimate.distance == pytest.approx(5.0)


@pytest.mark.parametrize("drive,twist", [("mecanum", (0.3, 0.0, 0.4)), ("mecanum", (0.0, 0.3, 0.0)),
                                         ("mecanum", (0.2, -0.3, 0.5)), ("omni3", (0.1, 0.3, -0.6)),
                                         ("diff", (0.4, 0.0, -0.7))])
def test_constant_twist_gives_the_true_arc(drive, twist):
    start = (1.0, 2.0, -0.5)
    estimate = drive_wheels(ChassisParams(drive=drive), [np.array(twist)] * 400, 0.025, start)
    assert_pose_close(estimate.pose, circle_truth(start, twist, 10.0), 1e-9)


@pytest.mark.parametrize("weight", [0.0, 0.5, 1.0])
def test_gyro_weight_blends_the_heading(weight):
    # wheels claim 0.4 rad/s (slipping), the gyro measures 0.1 rad/s
    params = ChassisParams(odom_gyro_weight=weight)
    estimate = drive_wheels(params, [np.array([0.0, 0.0, 0.4])] * 100, 0.01, gyro=0.1)
    turned = (1 - weight) * 0.4 + weight * 0.1
    assert estimate.pose[2] == pytest.approx(turned, abs=1e-12)
    assert estimate.twist[2] == pytest.approx(turned, abs=1e-9)


def test_covariance_grows_with_distance_and_turn_at_any_rate():
    params = ChassisParams(odom_trans_var_per_m=2e-4, odom_rot_var_per_m=1e-4, odom_rot_var_per_rad=3e-4)
    straight = drive_wheels(params, [np.array([0.5, 0.0, 0.0])] * 400, 0.01)      # 2 m
    assert straight.pose_covariance[0, 0] == pytest.approx(2e-4 * 2.0)
    assert straight.pose_covariance[2, 2] == pytest.approx(1e-4 * 2.0)
    # heading uncertainty spreads sideways: kt d + krd d^3 / 3
    assert straight.pose_covariance[1, 1] == pytest.approx(2e-4 * 2.0 + 1e-4 * 8.0 / 3, rel=1e-2)
    turn = drive_wheels(params, [np.array([0.0, 0.0, 0.5])] * 400, 0.01)          # 2 rad in place
    np.testing.assert_allclose(turn.pose_covariance, np.diag([0.0, 0.0, 3e-4 * 2.0]), atol=1e-15)
    assert turn.rotation == pytest.approx(2.0)
    coarse = drive_wheels(params, [np.array([0.4, 0.0, 0.3])] * 200, 0.02)
    fine = drive_wheels(params, [np.array([0.4, 0.0, 0.3])] * 800, 0.005)
    np.testing.assert_allclose(coarse.pose_covariance, fine.pose_covariance, rtol=0.02, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(fine.pose_covariance) >= 0)


def test_covariance_turns_with_the_starting_heading():
    params = ChassisParams(odom_rot_var_per_m=1e-3)
    twists = [np.array([0.3, 0.1, 0.2])] * 300
    plain = drive_wheels(params, twists, 0.02).pose_covariance
    turned = drive_wheels(params, twists, 0.02, start=(0.0, 0.0, 1.1)).pose_covariance
    c, s = math.cos(1.1), math.sin(1.1)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(turned, rotation @ plain @ rotation.T, atol=1e-12)


def test_twist_covariance_follows_from_the_encoder_noise():
    params = ChassisParams(drive="diff", odom_encoder_rate_std=0.1)
    cov = wheel_odometry(params).update(0, [0.0, 0.0]).twist_covariance
    r, half = params.wheel_radius, params.l2
    np.testing.assert_allclose(np.diag(cov), [(r * 0.1) ** 2 / 2, 0.0, (r * 0.1) ** 2 / (2 * half ** 2)])


def test_bad_readings_are_refused_with_a_reason():
    odom = wheel_odometry(ChassisParams())
    odom.update(10, np.zeros(4))
    with pytest.raises(ValueError, match="4 encoder positions"):
        odom.update(20, np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        odom.update(20, [0.0, math.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="earlier"):
        odom.update(5, np.zeros(4))
    moved = odom.update(10, np.ones(4))          # same stamp: the motion counts, the twist stays
    assert moved.pose[0] > 0 and np.all(moved.twist == 0)


# --- follower wheels ---

FOLLOWERS = ChassisParams(follower_alpha=0.35, follower_beta=1.7, follower_ka=0.0241, follower_kb=0.0263,
                          follower_a_offset=(0.12, -0.05), follower_b_offset=(-0.08, 0.15))


def follower_run(params, segments, dt=0.02, substeps=20):
    """Truth poses and sensor readings for (twist, duration) segments, from rigid-body geometry:
    each follower's reading grows by its contact point's world displacement along its rolling
    direction, summed over small substeps; the gyro reports the mean rate of each step."""
    offsets = np.array([params.follower_a_offset, params.follower_b_offset])
    rolling = np.array([params.follower_alpha, params.follower_beta])
    scales = np.array([params.follower_ka, params.follower_kb])

    def contacts(pose):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return pose[:2] + offsets @ np.array([[c, s], [-s, c]])

    pose = np.array([0.5, -1.0, 0.2])
    readings = np.zeros(2)
    truth, sensed = [pose], [(readings.copy(), 0.0)]
    for twist, duration in segments:
        for _ in range(round(duration / dt)):
            for _ in range(substeps):
                nxt = circle_truth(pose, twist, dt / substeps)
                heading = rolling + pose[2] + wrap_angle(nxt[2] - pose[2]) / 2   # chord is parallel to it
                moved = contacts(nxt) - contacts(pose)
                readings = readings + (moved[:, 0] * np.cos(heading) + moved[:, 1] * np.sin(heading)) / scales
                pose = nxt
            truth.append(pose)
            sensed.append((readings.copy(), twist[2]))
    return np.array(truth), sensed


SEGMENTS = [((0.4, 0.0, 0.0), 2.0),          # straight
            ((0.3, 0.0, 0.5), 3.0),          # arc
            ((0.0, 0.35, 0.0), 2.0),         # sideways
            ((0.1, -0.3, -0.4), 2.0),        # holonomic sideways arc
            ((0.0, 0.0, 0.8), 1.0)]          # turn in place


def test_follower_readings_match_rigid_body_geometry():
    for twist, _ in SEGMENTS:
        _, sensed = follower_run(FOLLOWERS, [(twist, 0.02)])
        expected = follower_readings(FOLLOWERS, np.array(twist) * 0.02)
        np.testing.assert_allclose(sensed[-1][0], expected, rtol=1e-7, atol=1e-12)


def test_follower_odometry_reproduces_straight_arc_and_sideways_motion():
    truth, sensed = follower_run(FOLLOWERS, SEGMENTS)
    odom = follower_odometry(FOLLOWERS, truth[0])
    for k, (readings, gyro) in enumerate(sensed):
        estimate = odom.update(k * 20_000_000, readings, gyro)
        assert_pose_close(estimate.pose, truth[k], 1e-6)
    assert estimate.distance == pytest.approx(0.8 + 0.9 + 0.7 + 2 * math.hypot(0.1, 0.3), rel=1e-6)


def test_follower_odometry_uses_the_gyro_for_heading():
    params = ChassisParams(follower_a_offset=(0.2, 0.1), follower_b_offset=(-0.1, 0.2))
    odom = follower_odometry(params)
    odom.update(0, [0.0, 0.0], 0.0)
    # a turn in place rolls offset followers; with the gyro's turn taken out nothing translates
    turned = follower_readings(params, [0.0, 0.0, 0.5])
    estimate = odom.update(NS, turned, 0.5)
    np.testing.assert_allclose(estimate.pose, [0.0, 0.0, 0.5], atol=1e-12)


def true_runs(params, distances, directions):
    motions = np.stack([distances * np.cos(directions), distances * np.sin(directions),
                        np.zeros_like(distances)], axis=1)
    return follower_readings(params, motions)


def test_calibration_recovers_scales_and_angles_from_two_exact_runs():
    found = calibrate_followers(true_runs(FOLLOWERS, np.array([3.0, 2.0]), np.array([0.0, math.pi / 2])),
                                [3.0, 2.0])
    assert found.ka == pytest.approx(FOLLOWERS.follower_ka, rel=1e-12)
    assert found.kb == pytest.approx(FOLLOWERS.follower_kb, rel=1e-12)
    assert found.alpha == pytest.approx(FOLLOWERS.follower_alpha, abs=1e-12)
    assert found.beta == pytest.approx(FOLLOWERS.follower_beta, abs=1e-12)
    assert found.residual == pytest.approx(0.0, abs=1e-9)
    assert found.apply(ChassisParams()).follower_kb == found.kb


@pytest.mark.parametrize("seed", range(10))
def test_calibration_from_noisy_runs_is_as_good_as_the_noise(seed):
    rng = np.random.default_rng(seed)
    noise = 0.003            # 0.3 % slip on each encoder, 3 mm error per metre of measured distance
    distances = np.array([3.0, 2.0])
    directions = np.array([0.1, 1.8])                  # any two clearly different directions
    readings = true_runs(FOLLOWERS, distances, directions) * (1 + noise * rng.standard_normal((2, 2)))
    measured = distances * (1 + noise * rng.standard_normal(2))
    found = calibrate_followers(readings, measured, directions)
    bound = 6 * noise        # several standard deviations of the propagated error
    assert found.ka == pytest.approx(FOLLOWERS.follower_ka, rel=bound)
    assert found.kb == pytest.approx(FOLLOWERS.follower_kb, rel=bound)
    assert abs(wrap_angle(found.alpha - FOLLOWERS.follower_alpha)) < bound
    assert abs(wrap_angle(found.beta - FOLLOWERS.follower_beta)) < bound


def test_calibration_with_more_runs_averages_the_noise():
    rng = np.random.default_rng(7)
    errors = []
    for n_runs in (2, 40):
        trial = []
        for _ in range(50):
            directions = np.tile([0.0, math.pi / 2], n_runs // 2)
            distances = np.full(n_runs, 2.0)
            slip = 1 + 0.01 * rng.standard_normal((n_runs, 2))
            readings = true_runs(FOLLOWERS, distances, directions) * slip
            trial.append(calibrate_followers(readings, distances, directions).ka / FOLLOWERS.follower_ka - 1)
        errors.append(np.sqrt(np.mean(np.square(trial))))
    assert errors[1] < errors[0] / 2       # 20 times the runs: about 4.5 times smaller


def test_calibration_handles_a_backwards_encoder_and_refuses_parallel_runs():
    flipped = true_runs(FOLLOWERS, np.array([3.0, 2.0]), np.array([0.0, math.pi / 2])) * [-1.0, 1.0]
    found = calibrate_followers(flipped, [3.0, 2.0])
    assert found.alpha == pytest.approx(float(wrap_angle(FOLLOWERS.follower_alpha + math.pi)))
    assert found.ka == pytest.approx(FOLLOWERS.follower_ka)
    with pytest.raises(ValueError, match="different directions"):
        calibrate_followers([[10.0, 2.0], [20.0, 4.0]], [1.0, 2.0], [0.3, 0.3])
    with pytest.raises(ValueError, match="distances positive"):
        calibrate_followers([[10.0, 2.0], [2.0, 40.0]], [1.0, -2.0])
    with pytest.raises(ValueError, match="one direction per distance"):
        calibrate_followers([[10.0, 2.0]], [1.0, 2.0])
