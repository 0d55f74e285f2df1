"""The odometry fusion (services/ekf): robot_localization's EKF over wheels, IMU and laser odometry,
and its doubt - a push the wheels miss, a skid they overstate, featureless scans, agreeing
sources, late laser poses, determinism, parameters; then the node in-process."""
import math

import numpy as np
import pytest

from ekf_scenes import LASER_STD, STEP_NS, Scene, run_core, scene
from omninav.parameters.declare import ParamError
from omninav.schemas import decode
from omninav.services.ekf.ekf import EkfParams, OdometryFusion, config
from omninav.services.ekf.node import EkfNode, EkfNodeParams

IMU, WHEELS, LASER = 0, 1, 2        # the node's input indices
DOUBT_LATENCY_S = 0.5
SHOVE_START = 1.0


def shove(distance: float, seconds: float = 1.0):
    """A standing robot shoved `distance` m along x in `seconds`: constant push then constant braking."""
    a = 4 * distance / seconds ** 2
    half = seconds / 2

    def twist(t):
        s = t - SHOVE_START
        v = a * s if 0 <= s < half else a * (seconds - s) if half <= s < seconds else 0.0
        return np.array([v, 0.0, 0.0])
    return twist


def track(fusion: OdometryFusion, s: Scene, delay_s: float = 0.25):
    poses, covs, verdicts = [], [], []

    def keep(_, f):
        est = f.estimate()
        poses.append(est.pose.copy())
        covs.append(est.pose_covariance.copy())
    verdicts = run_core(fusion, s, delay_s, keep)
    return np.array(poses), np.array(covs), verdicts


def step_at(t: float) -> int:
    return round(t / 0.01)


@pytest.mark.parametrize("distance", [0.5, 1.0, 2.0])
def test_a_push_while_standing_is_doubted_and_followed(distance):
    s = scene(SHOVE_START + 3.0, shove(distance), lambda t, v: np.zeros(3))      # the wheels never turn
    fusion = OdometryFusion(EkfParams())
    poses, _, verdicts = track(fusion, s)
    first = next(k for k, v in enumerate(verdicts) if v.doubtful)
    latency = first * 0.01 - SHOVE_START
    assert 0 <= latency <= DOUBT_LATENCY_S, latency
    assert "wheels vs" in verdicts[first].reason and "sigma" in verdicts[first].reason
    end = SHOVE_START + 1.0
    truth = np.array(s.truth)
    errors = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
    after = errors[step_at(end + 1.0):]
    assert after.max() < 0.10, (latency, after.max())
    assert abs(truth[-1, 0] - distance) < 1e-6 and np.hypot(*s.wheel_poses[-1][:2]) < 0.01
    assert fusion.counters["slip_events"] >= 1 and fusion.counters["held_out/odom0"] > 0
    print(f"shove {distance} m: doubt after {latency:.2f} s, error {errors[step_at(end)]:.3f} m at its end, "
          f"at most {after.max():.3f} m from 1 s after; doubtful at the end: {verdicts[-1].doubtful}")
    assert not verdicts[-1].doubtful        # the sources agree again for longer than doubt_clear_time


def test_only_the_scans_clear_a_doubt_and_not_once_their_track_broke():
    """The wheels, gyro and IMU agree again as soon as a shove is over; only laser odometry measures
    what it did. Without laser poses after the shove the doubt stays; with a laser track broken
    (matches refused for 0.5 s) during the doubt it stays for good; unbroken, it clears."""
    s = scene(SHOVE_START + 4.0, shove(1.0), lambda t, v: np.zeros(3))
    until = round((SHOVE_START + 0.2) * 1e9)
    outcomes = {}
    for name, lasers in (("all", s.lasers), ("none after", [m for m in s.lasers if m.header.stamp_ns < until]),
                         ("gap", [m for m in s.lasers if not until <= m.header.stamp_ns < until + 500_000_000])):
        verdicts = run_core(OdometryFusion(EkfParams()), Scene(s.wheels, s.imus, lasers, s.truth, s.wheel_poses))
        outcomes[name] = (any(v.doubtful for v in verdicts), verdicts[-1].doubtful, verdicts[-1].reason)
    assert outcomes["all"][:2] == (True, False)
    assert outcomes["none after"][:2] == (True, True)
    assert outcomes["gap"][:2] == (True, True) and "the scans lost track since" in outcomes["gap"][2]
    # without laser odometry fused, the other sources' agreement clears it, as before
    no_laser = EkfParams(odom1_config=config())
    assert not run_core(OdometryFusion(no_laser), Scene(s.wheels, s.imus, [], s.truth, s.wheel_poses))[-1].doubtful


def test_wheel_slip_on_a_turn_is_corrected_by_the_gyro_and_the_scans():
    true = np.array([0.3, 0.0, 0.5])
    s = scene(6.0, lambda t: true, lambda t, v: v * np.array([1.0, 1.0, 1.6]))    # a skid steer overstates the turn
    fusion = OdometryFusion(EkfParams())
    poses, _, verdicts = track(fusion, s)
    truth = np.array(s.truth)
    wheel_error = abs(float(np.angle(np.exp(1j * (s.wheel_poses[-1][2] - truth[-1, 2])))))
    yaw_error = abs(float(np.angle(np.exp(1j * (poses[-1, 2] - truth[-1, 2])))))
    assert wheel_error > 1.0 and yaw_error < 0.03, (wheel_error, yaw_error)
    assert np.hypot(*(poses[-1, :2] - truth[-1, :2])) < 0.05
    doubted = [v for v in verdicts if v.doubtful]
    assert doubted and "gyro" in doubted[0].reason
    print(f"skid: wheels' heading {wheel_error:.2f} rad off, fused {yaw_error:.3f} rad; {doubted[0].reason}")


def test_featureless_scans_let_the_covariance_along_the_corridor_grow():
    laser_std = np.array([0.5, LASER_STD[1], LASER_STD[2]])
    s = scene(8.0, lambda t: np.array([0.5, 0.0, 0.0]), laser_std=laser_std)
    _, covs, verdicts = track(OdometryFusion(EkfParams()), s)
    xx = covs[:, 0, 0]
    yy = covs[:, 1, 1]
    assert xx[step_at(2.0)] < xx[step_at(5.0)] < xx[step_at(8.0)]
    assert xx[-1] > 2 * yy[-1]      # y is seen by the scans: only the process noise since the last one
    assert not any(v.doubtful for v in verdicts)


def test_agreeing_sources_raise_no_doubt_and_keep_to_the_wheels():
    s = scene(6.0, lambda t: np.array([0.4, 0.1, 0.3 * math.sin(t)]))
    fusion = OdometryFusion(EkfParams())
    poses, _, verdicts = track(fusion, s)
    assert not any(v.doubtful for v in verdicts)
    assert fusion.counters["slip_events"] == 0 and fusion.counters["held_out/odom0"] == 0
    assert np.abs(poses[:, :2] - np.array(s.wheel_poses)[:, :2]).max() < 0.03


def test_a_lagged_laser_pose_gives_what_it_gives_in_stamp_order():
    s = scene(3.0, lambda t: np.array([0.4, 0.0, 0.4]))
    states = []
    for delay in (0.0, 0.1, 0.3):           # 0: each fused right after its own stamp, in order
        fusion = OdometryFusion(EkfParams())
        run_core(fusion, s, delay)
        states.append((fusion.ekf.x.copy(), fusion.ekf.p.copy()))
    for x, p in states[1:]:
        np.testing.assert_allclose(x, states[0][0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(p, states[0][1], rtol=0, atol=1e-12)


def test_a_laser_pose_older_than_the_history_is_counted_not_fused():
    s = scene(2.0, lambda t: np.array([0.4, 0.0, 0.0]))
    fusion = OdometryFusion(EkfParams(history_length=0.2))
    run_core(fusion, s, delay_s=0.5)
    assert fusion.counters["too_old/odom1"] > 0


def test_parameters_are_refused_by_name():
    with pytest.raises(ParamError, match="parameter odom0_config must be 15 items"):
        EkfParams(odom0_config=(True,) * 14)
    with pytest.raises(ParamError, match="parameter odom1_config must be 15 booleans"):
        EkfParams(odom1_config=(1,) + (False,) * 14)
    with pytest.raises(ParamError, match="parameter imu0_config must be false at x, y, yaw"):
        EkfParams(imu0_config=config("yaw", "vyaw"))
    with pytest.raises(ParamError, match="parameter odom0_config must be false at ax, ay"):
        EkfParams(odom0_config=config("vx", "ax"))
    with pytest.raises(ParamError, match="parameter process_noise_covariance must be 15 values"):
        EkfParams(process_noise_covariance=(0.1,) * 10)
    with pytest.raises(ParamError, match="parameter two_d_mode"):
        EkfParams(two_d_mode=False)
    with pytest.raises(ParamError, match="parameter odom1_relative"):
        EkfParams(odom1_relative=True, odom1_differential=True)
    with pytest.raises(ParamError, match="parameter history_length must be longer than odom_laser_delay_s"):
        EkfNodeParams(history_length=0.2, odom_laser_delay_s=0.25)
    with pytest.raises(ParamError, match="parameter world_frame"):
        EkfNodeParams(world_frame="map")
    with pytest.raises(ParamError, match="odom0_confg"):
        EkfNodeParams.from_mapping({"odom0_confg": list(config("vx"))})


def test_a_robot_localization_file_loads_with_its_topics_accepted_without_effect():
    params = EkfNodeParams.from_mapping({"ekf_filter_node": {"ros__parameters": {
        "frequency": 50.0, "two_d_mode": True, "odom0": "/odometry/wheel", "odom0_queue_size": 10,
        "odom0_config": [False, False, False, False, False, False, True, True, True, False, False, True,
                         False, False, False],
        "imu0": "/imu/data", "imu0_config": list(config("vyaw", "ax")), "imu0_remove_gravitational_acceleration": True,
        "process_noise_covariance": [0.0] * 225, "odom1_twist_rejection_threshold": 3.0}}})
    assert params.odom0_config[8] and params.imu0_config == config("vyaw", "ax")
    assert params.process_noise_covariance == (0.0,) * 225 and params.odom1_twist_rejection_threshold == 3.0


def test_the_core_gives_the_same_outputs_for_the_same_inputs():
    s = scene(SHOVE_START + 2.0, shove(1.0), lambda t, v: np.zeros(3))
    runs = [track(OdometryFusion(EkfParams()), s) for _ in range(2)]
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][2] == runs[1][2]


# ------------------------------------------------------------ the node, in-process


def capture(node):
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append((p.key, payload))
    return out


def of(out, name):
    return [decode(payload) for key, payload in out if key == f"omninav/r1/{name}"]


def feed(node, s: Scene, laser_lag_steps: int = 0):
    """In stamp order as replay feeds a node; each laser pose arriving laser_lag_steps wheel steps after
    its stamp (live it comes late: the deferral makes that change nothing)."""
    items = [(m.header.stamp_ns, IMU, m.header.seq, m) for m in s.imus]
    items += [(m.header.stamp_ns, WHEELS, m.header.seq, m) for m in s.wheels]
    items += [(m.header.stamp_ns + laser_lag_steps * STEP_NS, LASER, m.header.seq, m) for m in s.lasers]
    for _, index, _, msg in sorted(items, key=lambda i: i[:3]):
        node.process(index, msg)


def test_the_node_publishes_fused_odom_tf_and_doubt():
    s = scene(SHOVE_START + 3.0, shove(1.0), lambda t, v: np.zeros(3))
    node = EkfNode()
    assert [i.key.rsplit("/", 1)[1] for i in node.inputs] == ["imu", "odom_wheel", "odom_laser"]
    out = capture(node)
    feed(node, s)
    odom, tf, doubt = of(out, "odom"), of(out, "tf/odom_base"), of(out, "odom_doubt")
    assert len(odom) == len(tf) == len(s.wheels)
    assert [o.header.stamp_ns for o in odom] == [w.header.stamp_ns for w in s.wheels]
    assert abs(odom[-1].pose.x - 1.0) < 0.05 and tf[-1].transform == odom[-1].pose
    assert odom[-1].pose_covariance[0, 0] > 0 and odom[-1].twist_covariance[0, 0] > 0
    became = [d for d in doubt if d.doubtful]
    assert became and became[0].header.stamp_ns - SHOVE_START * 1e9 <= DOUBT_LATENCY_S * 1e9
    assert not doubt[-1].doubtful
    assert len(s.lasers) - 5 <= len(doubt) <= len(s.lasers) + 10      # with each laser pose, and at changes
    assert node.answer("omninav/r1/odom", {}) is node.last_odom
    values = node.diagnostic().values
    assert values["slip_events"] >= 1 and values["doubtful"] == 0 and values["held_out/odom0"] > 0


def test_the_node_gives_the_same_bytes_whenever_the_laser_arrives_within_the_delay():
    s = scene(SHOVE_START + 2.0, shove(1.0), lambda t, v: np.zeros(3))
    runs = []
    for lag in (0, 10, 24):         # up to 0.24 s late; odom_laser_delay_s is 0.25
        node = EkfNode()
        out = capture(node)
        feed(node, s, lag)
        runs.append(out)
    assert runs[0] == runs[1] == runs[2]


def test_the_node_without_imu_or_laser_takes_the_wheels_alone():
    s = scene(2.0, lambda t: np.array([0.4, 0.0, 0.2]))
    node = EkfNode(EkfNodeParams(imu0_config=(False,) * 15, odom1_config=(False,) * 15, publish_tf=False))
    assert [i.key.rsplit("/", 1)[1] for i in node.inputs] == ["odom_wheel"]
    out = capture(node)
    for wheels in s.wheels:
        node.process(0, wheels)
    assert of(out, "tf/odom_base") == []
    assert np.hypot(of(out, "odom")[-1].pose.x - s.wheel_poses[-1][0], of(out, "odom")[-1].pose.y - s.wheel_poses[-1][1]) < 0.02


def test_a_fusion_started_mid_mission_starts_where_the_wheel_odometry_stands():
    """A restarted ekf (its process died) goes on from the chassis's resumed odometry, not the origin."""
    s = scene(1.0, lambda t: np.array([0.5, 0.0, 0.0]))
    later = s.wheels[50:]
    fusion = OdometryFusion(EkfParams(odom1_config=config()))
    for wheels, imu in zip(later, s.imus[50:]):
        fusion.step(wheels, [imu])
    assert np.hypot(*(fusion.estimate().pose[:2] - s.wheel_poses[-1][:2])) < 0.01
    assert s.wheel_poses[50][0] > 0.2


def test_a_long_doubt_while_spinning_fast_stays_bounded():
    """A robot spun at 14 rad/s for 20 s while its wheels stand still: the IMU's change of speed,
    integrated through the frame's rotation over the whole doubt, stays bounded (a first-order rotation
    term fed back grew 1 % a step - 1e17 here, an overflow in a longer DynaBARN run), and so does every
    verdict's distance: the wheels are 0.5 m/s off at most."""
    s = scene(22.0, lambda t: np.array([0.5, 0.0, 14.0]) if 1.0 <= t < 21.0 else np.zeros(3), lambda t, v: np.zeros(3))
    fusion, speeds = OdometryFusion(EkfParams()), []
    verdicts = run_core(fusion, s, on_step=lambda k, f: speeds.append(np.hypot(*f.estimate().twist[:2])))
    assert any(v.doubtful for v in verdicts)
    assert max(v.mahalanobis for v in verdicts) < 1e8
    # the filter too: its body velocity turns with the body (a first-order turn reached 3630 m/s here)
    assert max(speeds) < 1.0 and np.hypot(*(fusion.estimate().pose[:2] - s.truth[-1][:2])) < 0.1


def test_a_step_that_would_leave_the_filter_beyond_any_robot_is_undone_and_counted():
    """A reading no robot gives (an accelerometer claiming 1e5 m/s²) would send the velocity past any
    robot's: the step is undone, counted, and the estimate stays what it was."""
    s = scene(1.0, lambda t: np.zeros(3))
    s.imus[50].linear_acceleration_x = 1e5
    fusion = OdometryFusion(EkfParams())
    run_core(fusion, s)
    assert fusion.counters["beyond_bounds/imu0"] == 1 and np.abs(fusion.estimate().twist).max() < 0.1


def test_a_laser_jump_the_gyro_and_the_imu_did_not_feel_is_set_aside_not_believed():
    """Driving straight with honest wheels, the laser track jumps 0.3 m sideways in one scan (a match
    against a body that moved) and goes on from there: the wheels, gyro and IMU felt nothing, so the
    interval is the laser's error. No doubt, the wheels are not held out, and the fused pose stays
    on the truth while the laser poses after the jump are fused through the new offset."""
    s = scene(6.0, lambda t: np.array([0.5, 0.0, 0.1]))
    jump_at = 2_000_000_000
    for m in s.lasers:
        if m.header.stamp_ns >= jump_at:
            m.pose.y += 0.3
    fusion = OdometryFusion(EkfParams())
    poses, _, verdicts = track(fusion, s)
    truth = np.array(s.truth)
    assert not any(v.doubtful for v in verdicts)
    assert fusion.counters["laser_set_aside/odom1"] == 1 and fusion.counters["held_out/odom0"] == 0
    assert np.hypot(*(poses[:, :2] - truth[:, :2]).T).max() < 0.08     # measured 0.057 (0.03 without the jump)
    believed = OdometryFusion(EkfParams(doubt_laser_needs_inertia=False))
    poses, _, verdicts = track(believed, s)
    assert any(v.doubtful for v in verdicts)
    assert np.hypot(*(poses[-1, :2] - truth[-1, :2])) > 0.2       # it followed the laser
