import math
from concurrent.futures import ThreadPoolExecutor

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from omninav.schemas import MessageError, all_types, decode, encode, peek_type
from omninav.schemas.codec import _checked_decode, _fast_decoder, describe, to_wire
from omninav.schemas.fields import sign_bytes, surely_finite
from omninav.experiments.fuzz import example, mutated_payloads
from omninav.schemas.messages import (Chatter, Clock, Costmap, Imu, LaserScan, MapMetaData, Obstacles, OccupancyGrid,
                                      Odometry, ParticleCloud, Path, PoseWithCovariance, WheelCommand, WheelState)

from strategies import sound, struct_strategy

ALL_TYPES = sorted(all_types().items())


def assert_same(a, b):
    assert type(a) is type(b)
    for name in a.__slots__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape
            assert np.array_equal(x, y, equal_nan=True)
        elif hasattr(x, "__slots__"):
            assert_same(x, y)
        else:
            assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))


@pytest.mark.parametrize("name,cls", ALL_TYPES)
@settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_every_type_round_trips_byte_for_byte(name, cls, data):
    msg = sound(data.draw(struct_strategy(cls)))
    assert getattr(msg, "problem", lambda: None)() is None
    payload = encode(msg)
    back = decode(payload, cls)
    assert_same(msg, back)
    assert encode(back) == payload          # deterministic: the same message, the same bytes
    assert peek_type(payload) == name


@pytest.mark.parametrize("name,cls", ALL_TYPES)
@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_damaged_payloads_raise_message_error_only(name, cls, data):
    payload = encode(sound(data.draw(struct_strategy(cls))))
    cut = data.draw(st.integers(0, len(payload) - 1))
    with pytest.raises(MessageError):
        decode(payload[:cut])
    flip = data.draw(st.integers(0, len(payload) - 1))
    damaged = bytearray(payload)
    damaged[flip] ^= 0xFF
    try:
        decode(bytes(damaged))
    except MessageError:
        pass                                 # a clean refusal; anything else fails the test


@pytest.mark.parametrize("name,cls", ALL_TYPES)
def test_the_fast_decoder_accepts_only_what_the_checking_decoder_accepts_and_as_the_same_message(name, cls):
    """Every one-field mutation of a sound message, and every other type's payload: where the fast
    path (msgspec) gives a message, the checking decoder gives the same; where it doubts, decode()
    answers as the checking decoder does."""
    fast = _fast_decoder(cls)
    accepted = 0
    for payload in [encode(example(cls)), *mutated_payloads(example(cls)),
                    *(encode(example(other)) for _, other in ALL_TYPES)]:
        try:
            checked = _checked_decode(msgspec.msgpack.decode(payload), cls)
        except MessageError:
            checked = None
        quick = fast(payload)
        if quick is not None:
            accepted += 1
            assert checked is not None, payload
            assert_same(quick, checked)
        if checked is None:
            with pytest.raises(MessageError):
                decode(payload, cls)
    assert accepted >= 2        # the sound example, and at least one harmless edge value


def test_a_payload_changed_after_decoding_leaves_the_message_alone():
    ranges = np.ones(10, np.float32).tobytes()
    payload = bytearray(encode(scan_of(np.ones(10))))
    scan = decode(payload, LaserScan)
    start = payload.index(ranges)
    payload[start:start + len(ranges)] = bytes(len(ranges))
    assert scan.ranges.tolist() == [1.0] * 10


def scan_of(ranges, angle_increment=0.01, **fields) -> LaserScan:
    ranges = np.asarray(ranges, np.float32)
    return LaserScan(ranges=ranges, angle_increment=angle_increment, range_max=30.0,
                     angle_max=(len(ranges) - 1) * angle_increment, **fields)


def test_arrays_decode_without_copy():
    scan = scan_of(np.arange(360))
    back = decode(encode(scan))
    assert not back.ranges.flags.writeable   # a view over the received bytes
    assert back.ranges.base is not None


def wire_with(msg, **changes):
    wire = to_wire(msg)
    for path, value in changes.items():
        node = wire
        *parents, leaf = path.split("__")
        for p in parents:
            node = node[p]
        node[leaf] = value
    return msgspec.msgpack.encode(wire)


@pytest.mark.parametrize("msg,change,field", [
    (Chatter(), {"value": "x"}, "Chatter.value"),
    (Chatter(), {"header__stamp_ns": 1.5}, "Chatter.header.stamp_ns"),
    (Chatter(), {"text": 3}, "Chatter.text"),
    (Chatter(), {"value": math.nan}, "Chatter.value"),
    (Odometry(), {"pose__theta": math.inf}, "Odometry.pose.theta"),
    (Path(), {"poses": {"dtype": "<f8", "shape": [2, 2], "data": bytes(32)}}, "Path.poses"),
    (Path(), {"poses": {"dtype": "<f4", "shape": [1, 3], "data": bytes(12)}}, "Path.poses"),
    (Path(), {"poses": {"dtype": "<f8", "shape": [1, 3], "data": bytes(5)}}, "Path.poses"),
    (OccupancyGrid(), {"data": [1, 2, 3]}, "OccupancyGrid.data"),
    (Chatter(), {"bogus": 1}, "Chatter"),
])
def test_bad_fields_are_named(msg, change, field):
    with pytest.raises(MessageError) as err:
        decode(wire_with(msg, **change), key="omninav/r1/x")
    assert field in str(err.value) and "omninav/r1/x" in str(err.value)


def test_missing_field_and_wrong_type_and_version():
    wire = to_wire(Chatter())
    del wire["text"]
    with pytest.raises(MessageError, match=r"Chatter\.text: missing"):
        decode(msgspec.msgpack.encode(wire))
    with pytest.raises(MessageError, match="expected LaserScan"):
        decode(encode(Chatter()), LaserScan)
    with pytest.raises(MessageError, match="version"):
        decode(wire_with(Chatter(), _version=99))
    with pytest.raises(MessageError, match="unknown message type"):
        decode(msgspec.msgpack.encode({"_type": "Nope", "_version": 1}))
    for junk in (b"", b"\xc1", msgspec.msgpack.encode([1, 2]), msgspec.msgpack.encode("text")):
        with pytest.raises(MessageError):
            decode(junk)


def test_nan_allowed_only_where_declared():
    scan = scan_of([1.0, np.inf, np.nan, -np.inf])
    assert np.isinf(decode(encode(scan)).ranges[1])
    odom = Odometry(pose_covariance=np.full((3, 3), np.nan))
    with pytest.raises(MessageError, match="pose_covariance"):
        decode(encode(odom))


def test_finite_values_whose_sum_overflows_are_accepted_and_nan_among_them_refused():
    huge = WheelCommand(drive="diff", velocities=np.array([1.7e308, 1.7e308]))
    assert decode(encode(huge)).velocities.tolist() == [1.7e308, 1.7e308]
    huge.velocities[1] = np.nan
    with pytest.raises(MessageError, match="WheelCommand.velocities"):
        decode(encode(huge))


def test_threads_encoding_at_once_get_the_bytes_one_thread_gets():
    messages = [Chatter(text="x" * n, value=float(n)) for n in range(200)]
    expected = [encode(msg) for msg in messages]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(5):
            assert list(pool.map(encode, messages)) == expected


def test_threads_decoding_at_once_get_the_messages_one_thread_gets():
    scans = [encode(scan_of(np.full(n + 1, n, np.float32))) for n in range(200)]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(5):
            decoded = list(pool.map(lambda payload: decode(payload, LaserScan), scans))
            assert [scan.ranges.tolist() for scan in decoded] == [[float(n)] * (n + 1) for n in range(200)]


@pytest.mark.parametrize("name,cls", ALL_TYPES)
def test_every_type_has_a_schema(name, cls):
    schema = describe(cls)
    assert schema["title"] == name and "header" in schema["properties"]


@pytest.mark.parametrize("msg,field", [
    (OccupancyGrid(info=MapMetaData(resolution=0.0, width=2, height=1), data=np.zeros((1, 2), np.int8)),
     "OccupancyGrid.info.resolution"),
    (OccupancyGrid(info=MapMetaData(resolution=math.nan, width=2, height=1), data=np.zeros((1, 2), np.int8)),
     "OccupancyGrid.info.resolution"),
    (OccupancyGrid(info=MapMetaData(width=3, height=1), data=np.zeros((1, 2), np.int8)), "OccupancyGrid.data"),
    (OccupancyGrid(info=MapMetaData(width=1, height=1), data=np.full((1, 1), 101, np.int8)), "OccupancyGrid.data"),
    (Costmap(info=MapMetaData(width=2, height=2), data=np.zeros((1, 2), np.uint8)), "Costmap.data"),
    (scan_of([1.0, -0.5, 2.0]), "LaserScan.ranges"),
    (scan_of([np.nan, -0.5, 2.0]), "LaserScan.ranges"),
    (scan_of([1.0, 2.0], angle_increment=0.0), "LaserScan.angle_increment"),
    (LaserScan(ranges=np.ones(3, np.float32), angle_increment=-0.01, angle_max=0.02, range_max=5.0),
     "LaserScan.angle_increment"),
    (LaserScan(ranges=np.ones(10, np.float32), angle_increment=0.1, angle_max=0.3, range_max=5.0),
     "LaserScan.ranges"),
    (scan_of([1.0, 2.0], intensities=np.ones(3, np.float32)), "LaserScan.intensities"),
    (PoseWithCovariance(covariance=np.array([[1.0, 0.5, 0], [0, 1.0, 0], [0, 0, 1.0]])),
     "PoseWithCovariance.covariance"),
    (PoseWithCovariance(covariance=np.diag([1.0, -1.0, 1.0])), "PoseWithCovariance.covariance"),
    (Odometry(twist_covariance=np.diag([0.0, 0.0, -1e-3])), "Odometry.twist_covariance"),
    (WheelCommand(drive="tank", velocities=np.zeros(2)), "WheelCommand.drive"),
    (WheelCommand(drive="mecanum", velocities=np.zeros(3)), "WheelCommand.velocities"),
    (WheelState(drive="diff", velocities=np.zeros(2), positions=np.zeros(1)), "WheelState.positions"),
    (ParticleCloud(poses=np.zeros((2, 3)), weights=np.ones(3)), "ParticleCloud.weights"),
    (Obstacles(circles=np.array([[0.0, 0.0, -0.3]]), velocities=np.zeros((1, 2))), "Obstacles.circles"),
    (Clock(rate=-1.0), "Clock.rate"),
    (Imu(linear_acceleration_y_variance=-1e-4), "Imu.linear_acceleration_y_variance"),
])
def test_messages_whose_fields_disagree_are_refused_naming_the_field(msg, field):
    with pytest.raises(MessageError) as err:
        decode(encode(msg), key="omninav/r1/x")
    assert field in str(err.value) and "omninav/r1/x" in str(err.value)


def test_rep_117_ranges_and_a_last_beam_convention_are_accepted():
    scan = scan_of([0.0, np.inf, np.nan, -np.inf, 3.0])
    assert decode(encode(scan)).ranges.size == 5
    scan.angle_max += scan.angle_increment      # angle_max at the end of the last beam, as some drivers do
    assert decode(encode(scan)).ranges.size == 5
    clockwise = scan_of([1.0, 2.0, 3.0], angle_increment=-0.01)      # angle_max below angle_min
    assert decode(encode(clockwise)).angle_increment == -0.01


@settings(max_examples=300)
@given(dtype=st.sampled_from(["<f4", "<f8", ">f8"]), data=st.data())
def test_sign_bytes_tell_signs_and_finiteness_as_numpy_does(dtype, data):
    values = np.array(data.draw(st.lists(st.floats(width=32 if dtype == "<f4" else 64), max_size=40)), dtype)
    assert sign_bytes(values).isascii() == (not np.signbit(values).any())
    if surely_finite(values):
        assert np.isfinite(values).all()
    if len(values) and np.abs(values[np.isfinite(values)]).max(initial=0.0) < 1e38:
        assert surely_finite(values) == np.isfinite(values).all()   # exact below the float32 exponent's top
