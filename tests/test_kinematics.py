import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from omninav.geometry.command_response import limit_acceleration
from omninav.services.chassis.kinematics import DRIVES, ChassisParams, Kinematics
from omninav.parameters.declare import ParamError
from omninav.parameters.from_mapping import load_params

MECANUM = ChassisParams(drive="mecanum")
speed = st.floats(-3.0, 3.0, allow_nan=False)
twists = arrays(np.float64, 3, elements=speed)


def drive_params(drive: str) -> ChassisParams:
    return ChassisParams(drive=drive)


def contact_velocity(twist, position):
    vx, vy, wz = twist
    return np.array([vx - wz * position[1], vy + wz * position[0]])


def test_mecanum_wheel_signs_match_known_behaviour():
    kin = Kinematics(MECANUM)
    r, k = MECANUM.wheel_radius, MECANUM.l1 + MECANUM.l2
    assert kin.wheel_names == ("front_left", "front_right", "rear_left", "rear_right")
    # forward: all wheels turn forward at v / r
    np.testing.assert_allclose(kin.ik([0.5, 0, 0]), np.full(4, 0.5 / r))
    # strafe left: front-left and rear-right turn backwards, the diagonal pair forwards
    np.testing.assert_allclose(kin.ik([0, 0.5, 0]), np.array([-1, 1, 1, -1]) * 0.5 / r)
    # turn counter-clockwise: left side backwards, right side forwards, lever l1 + l2
    np.testing.assert_allclose(kin.ik([0, 0, 1.0]), np.array([-1, 1, -1, 1]) * k / r)


@pytest.mark.parametrize("index,roller", [(0, (1, 1)), (1, (1, -1)), (2, (1, -1)), (3, (1, 1))])
def test_mecanum_rows_leave_only_roller_motion(index, roller):
    """At each contact point, what the wheel rim does not supply is motion along the free roller."""
    p = MECANUM
    position = [(p.l1, p.l2), (p.l1, -p.l2), (-p.l1, p.l2), (-p.l1, -p.l2)][index]
    kin = Kinematics(p)
    for twist in ([0.4, 0, 0], [0, 0.4, 0], [0, 0, 0.7], [0.3, -0.2, 0.5]):
        rim = np.array([p.wheel_radius * kin.ik(twist)[index], 0.0])
        rest = contact_velocity(twist, position) - rim
        assert rest[0] * roller[1] - rest[1] * roller[0] == pytest.approx(0.0, abs=1e-12)


def test_mecanum_forward_matrix_is_the_derived_closed_form():
    p = MECANUM
    r, k = p.wheel_radius, p.l1 + p.l2
    expected = r / 4 * np.array([[1, 1, 1, 1], [-1, 1, 1, -1], [-1 / k, 1 / k, -1 / k, 1 / k]])
    np.testing.assert_allclose(Kinematics(p).fk_matrix, expected, atol=1e-12)


def test_omni3_wheels_sit_at_120_degrees_and_drive_tangentially():
    p = ChassisParams(drive="omni3", omni_main_direction=0.3)
    kin = Kinematics(p)
    r, dist = p.wheel_radius, p.omni_wheel_distance
    np.testing.assert_allclose(kin.ik([0, 0, 1.0]), np.full(3, dist / r))
    for k in range(3):
        angle = 0.3 + k * 2 * math.pi / 3
        radial = [math.cos(angle), math.sin(angle), 0.0]
        tangential = [-math.sin(angle), math.cos(angle), 0.0]
        # moving along a wheel's axle only spins its rollers; along its tangent only the wheel
        assert kin.ik(radial)[k] == pytest.approx(0.0, abs=1e-12)
        assert kin.ik(tangential)[k] == pytest.approx(1 / r)


def test_omni3_forward_matrix_is_the_derived_closed_form():
    p = ChassisParams(drive="omni3", omni_main_direction=-0.7)
    angles = -0.7 + np.arange(3) * 2 * np.pi / 3
    expected = p.wheel_radius * np.array([-2 / 3 * np.sin(angles), 2 / 3 * np.cos(angles),
                                          np.full(3, 1 / (3 * p.omni_wheel_distance))])
    np.testing.assert_allclose(Kinematics(p).fk_matrix, expected, atol=1e-12)


def test_diff_drive_ignores_and_reports_sideways_requests():
    p = ChassisParams(drive="diff")
    kin = Kinematics(p)
    r, half = p.wheel_radius, p.l2
    assert kin.wheel_names == ("left", "right")
    np.testing.assert_allclose(kin.ik([0.5, 0, 0]), [0.5 / r, 0.5 / r])
    np.testing.assert_allclose(kin.ik([0, 0, 1.0]), [-half / r, half / r])
    np.testing.assert_allclose(kin.ik([0, 0.8, 0]), [0.0, 0.0])
    assert kin.fk([3.0, -1.0])[1] == 0.0
    command = kin.limit([0.2, 0.3, 0.1], [0.2, 0.0, 0.1], 0.1)
    assert command.dropped_vy and command.twist[1] == 0.0
    assert not kin.limit([0.2, 0.0, 0.1], [0.2, 0.0, 0.1], 0.1).dropped_vy
    assert not Kinematics(MECANUM).limit([0.2, 0.3, 0.1], [0.2, 0.3, 0.1], 0.1).dropped_vy


@pytest.mark.parametrize("drive", DRIVES)
@given(batch=arrays(np.float64, st.tuples(st.integers(1, 8), st.just(3)), elements=speed))
def test_forward_undoes_inverse_for_a_batch(drive, batch):
    kin = Kinematics(drive_params(drive))
    if not kin.holonomic:
        batch = batch * [1.0, 0.0, 1.0]
    wheels = kin.ik(batch)
    assert wheels.shape == (len(batch), kin.n_wheels)
    np.testing.assert_allclose(kin.fk(wheels), batch, atol=1e-9)
    np.testing.assert_allclose(wheels[-1], kin.ik(batch[-1]), atol=1e-12)   # a row is its own command


@pytest.mark.parametrize("drive", DRIVES)
@given(twist=arrays(np.float64, 3, elements=st.floats(-10.0, 10.0, allow_nan=False)))
def test_saturation_keeps_direction_and_respects_the_wheel_limit(drive, twist):
    kin = Kinematics(drive_params(drive))
    limit = kin.params.max_wheel_speed
    scaled = kin.saturate(twist)
    peak = np.max(np.abs(kin.ik(twist)))
    assert np.max(np.abs(kin.ik(scaled))) <= limit * (1 + 1e-12)
    if peak <= limit:
        np.testing.assert_array_equal(scaled, twist)
    else:
        factor = limit / peak
        np.testing.assert_allclose(scaled, factor * twist, rtol=1e-12, atol=1e-15)
        assert np.max(np.abs(kin.ik(scaled))) == pytest.approx(limit)   # no slower than needed


def test_saturation_of_a_batch_scales_each_row_on_its_own():
    kin = Kinematics(MECANUM)
    batch = np.array([[0.1, 0, 0], [5.0, 0, 0], [0, 0, 30.0]])
    out = kin.saturate(batch)
    np.testing.assert_array_equal(out[0], batch[0])
    assert kin.saturation_scale(batch).shape == (3,)
    np.testing.assert_allclose(np.max(np.abs(kin.ik(out[1:])), axis=1), MECANUM.max_wheel_speed)


@given(requested=twists, previous=twists, dt=st.floats(0.0, 0.5))
def test_acceleration_limits_hold_per_axis(requested, previous, dt):
    limits = MECANUM.acc_limits
    out = limit_acceleration(requested, previous, dt, limits)
    change = np.abs(out - previous)
    assert np.all(change <= limits * dt * (1 + 1e-12) + 1e-15)
    within = np.abs(requested - previous) <= limits * dt
    np.testing.assert_array_equal(out[within], requested[within])


def test_acceleration_limit_rejects_negative_dt():
    with pytest.raises(ValueError, match="dt"):
        limit_acceleration([1, 0, 0], [0, 0, 0], -0.1, MECANUM.acc_limits)


@pytest.mark.parametrize("drive", DRIVES)
@settings(max_examples=200)
@given(requested=arrays(np.float64, 3, elements=st.floats(-10.0, 10.0, allow_nan=False)),
       previous=twists, dt=st.floats(0.0, 0.5))
def test_limited_command_keeps_wheel_and_acceleration_limits(drive, requested, previous, dt):
    kin = Kinematics(drive_params(drive))
    if not kin.holonomic:
        previous = previous * [1.0, 0.0, 1.0]
    previous = kin.saturate(previous)                  # what a previous cycle could have sent
    out = kin.limit(requested, previous, dt)
    limit = kin.params.max_wheel_speed
    np.testing.assert_allclose(out.wheels, kin.ik(out.twist))
    assert np.max(np.abs(out.wheels)) <= limit * (1 + 1e-9)
    assert np.all(np.abs(out.twist - previous) <= kin.params.acc_limits * dt * (1 + 1e-9) + 1e-12)
    reachable = requested * ([1.0, 1.0, 1.0] if kin.holonomic else [1.0, 0.0, 1.0])
    if not out.accel_limited:                          # then it is the request, scaled down
        np.testing.assert_allclose(out.twist, out.saturation * reachable, rtol=1e-12, atol=1e-12)
    assert 0.0 < out.saturation <= 1.0


def test_limited_command_backs_off_along_the_line_from_the_previous_command():
    kin = Kinematics(MECANUM)
    top = MECANUM.max_wheel_speed * MECANUM.wheel_radius
    previous = np.array([top, 0.0, 0.0])               # every wheel at its limit
    # a request for pure rotation: per-axis clipping alone would add rotation to full speed
    out = kin.limit([0.0, 0.0, 2.0], previous, 0.05)
    assert out.accel_limited
    assert np.max(np.abs(out.wheels)) <= MECANUM.max_wheel_speed * (1 + 1e-12)
    assert out.twist[0] < top and out.twist[2] > 0.0


def test_a_command_with_a_wheel_at_its_limit_slides_along_the_limit_towards_the_request():
    """The Jackal (its controller's track × 1.5, 2 m/s at the rim) at full speed in a turn, one wheel
    at its limit, asked to turn less at full speed: the straight line from the previous command
    leaves the wheel limit at once, and a command stopped there kept turning at 0.9 rad/s while the
    planner asked for 0.3 (bench buildings, jackal-112). It turns less by the angular acceleration
    limit every step, keeping that wheel at its limit."""
    kin = Kinematics(ChassisParams(drive="diff", wheel_radius=0.098, l2=0.28169, max_wheel_speed=20.41,
                                   acc_lim_x=3.0, acc_lim_theta=6.0))
    turning = kin.saturate([1.8, 0.0, -0.9])
    out = kin.limit([2.0, 0.0, -0.3], turning, 0.01)
    assert out.accel_limited
    assert out.twist[2] == pytest.approx(turning[2] + 6.0 * 0.01)
    assert out.twist[0] > turning[0]
    assert np.max(np.abs(out.wheels)) == pytest.approx(20.41)


def test_parameters_are_validated_with_their_names():
    with pytest.raises(ValueError, match="drive"):
        ChassisParams(drive="tank")
    with pytest.raises(ValueError, match="wheel_radius"):
        ChassisParams(wheel_radius=0.0)
    with pytest.raises(ValueError, match="odom_gyro_weight"):
        ChassisParams(odom_gyro_weight=1.5)
    with pytest.raises(ValueError, match="follower_alpha"):
        ChassisParams(follower_alpha=0.2, follower_beta=0.2 + math.pi)
    with pytest.raises(ParamError, match="acc_lim_y"):
        load_params(ChassisParams, {"acc_lim_y": -1.0}, "chassis.yaml")
    loaded = load_params(ChassisParams, {"drive": "omni3", "follower_a_offset": [0.1, -0.2]})
    assert loaded.drive == "omni3" and loaded.follower_a_offset == (0.1, -0.2)
