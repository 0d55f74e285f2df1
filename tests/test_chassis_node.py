"""The chassis node in-process: odometry from synthetic wheel states, limited wheel commands,
the cmd_vel timeout and delay, rejected input, and byte-exact determinism live vs replay."""
import dataclasses

import numpy as np
import pytest

from omninav.schemas import decode, encode
from omninav.schemas.messages import Header, Twist, WheelState
from omninav.services.chassis.follower_wheels import follower_readings
from omninav.services.chassis.kinematics import Kinematics
from omninav.services.chassis.node import ChassisNode, ChassisNodeParams
from omninav.services.recorder.mcap_io import Record
from omninav.services.replay.into import replay_into
from omninav.services.runtime.live import LiveRunner, Received
from omninav.services.runtime.node import NS_PER_S
from omninav.parameters.declare import ParamError
from omninav.parameters.from_mapping import load_params
from omninav.geometry.se2 import integrate, wrap_angle

DT = 0.01
STEP_NS = round(DT * NS_PER_S)
WHEEL_STATE, CMD_VEL = "omninav/r1/wheel_state", "omninav/r1/cmd_vel"


def capture(node):
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append((p.key, payload))
    return out


def of(out, key):
    return [decode(payload) for k, payload in out if k == key]


def drive(params, segments, start_ns=0):
    """WheelStates every DT for piecewise-constant twists [(twist, seconds)], and the true poses."""
    kin = Kinematics(params)
    positions, followers, pose, t = np.zeros(kin.n_wheels), np.zeros(2), np.zeros(3), start_ns
    states = [WheelState(header=Header(stamp_ns=t), drive=params.drive, positions=positions.copy(),
                         velocities=np.zeros(kin.n_wheels), follower_positions=followers.copy())]
    poses = [pose]
    for twist, seconds in segments:
        twist = np.asarray(twist, float)
        for _ in range(round(seconds / DT)):
            positions = positions + kin.ik(twist) * DT
            followers = followers + follower_readings(params, twist * DT)
            pose = integrate(pose, twist, DT)
            t += STEP_NS
            states.append(WheelState(header=Header(stamp_ns=t, seq=len(states) + 1), drive=params.drive,
                                     positions=positions, velocities=kin.ik(twist),
                                     follower_positions=followers, gyro_z=float(twist[2])))
            poses.append(pose)
    for seq, state in enumerate(states, 1):
        state.header.seq = seq
    return states, np.array(poses)


def cmd(t_s, vx=0.0, vy=0.0, wz=0.0, seq=1):
    return Twist(header=Header(stamp_ns=round(t_s * NS_PER_S), seq=seq), linear_x=vx, linear_y=vy, angular_z=wz)


def in_stamp_order(node, states, commands=()):
    """Feed as replay does: sorted by (stamp, input index, seq)."""
    items = [(s.header.stamp_ns, 0, s.header.seq, s) for s in states]
    items += [(c.header.stamp_ns, 1, c.header.seq, c) for c in commands]
    for _, index, _, msg in sorted(items, key=lambda i: i[:3]):
        node.process(index, msg)


@pytest.mark.parametrize("drive_name", ["mecanum", "omni3", "diff"])
def test_odometry_follows_the_known_motion(drive_name):
    params = ChassisNodeParams(drive=drive_name)
    vy = 0.0 if drive_name == "diff" else 0.2
    states, poses = drive(params, [((0.4, vy, 0.3), 1.0), ((0.5, -vy, -0.6), 1.5), ((0.0, 0.0, 1.0), 0.5)])
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states)
    odom = of(out, "omninav/r1/odom")
    follower = of(out, "omninav/r1/odom_follower")
    tf = of(out, "omninav/r1/tf/odom_base")
    assert len(odom) == len(follower) == len(tf) == len(states)
    for k in (50, 200, len(states) - 1):
        for msg in (odom[k], follower[k]):
            got = np.array([msg.pose.x, msg.pose.y, msg.pose.theta])
            assert np.allclose(got[:2], poses[k][:2], atol=1e-9)
            assert abs(wrap_angle(got[2] - poses[k][2])) < 1e-9
    last = odom[-1]
    assert last.header.frame_id == "odom" and last.child_frame_id == "base_link"
    assert (tf[-1].transform.x, tf[-1].transform.y) == (last.pose.x, last.pose.y)
    assert tf[-1].header.frame_id == "odom" and tf[-1].child_frame_id == "base_link"
    assert last.twist.angular_z == pytest.approx(1.0)
    cov = last.pose_covariance
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) >= -1e-15) and cov[0, 0] > odom[10].pose_covariance[0, 0]
    assert node.answer("omninav/r1/odom", {}) is not None
    assert encode(node.answer("omninav/r1/odom", {})) == encode(last)


def test_wheel_commands_respect_wheel_and_acceleration_limits():
    params = ChassisNodeParams()
    kin = Kinematics(params)
    states, _ = drive(params, [((0.0, 0.0, 0.0), 3.0)])
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states, [cmd(0.0, vx=3.0, vy=1.0, wz=2.0)] + [cmd(0.1 * k, vx=3.0, vy=1.0, wz=2.0, seq=k + 1)
                                                                        for k in range(1, 30)])
    wheel_cmds = of(out, "omninav/r1/wheel_cmd")
    assert len(wheel_cmds) == len(states)
    assert all(c.header.stamp_ns == s.header.stamp_ns and c.drive == "mecanum" for c, s in zip(wheel_cmds, states))
    wheels = np.array([c.velocities for c in wheel_cmds])
    assert np.max(np.abs(wheels)) <= params.max_wheel_speed * (1 + 1e-9)
    twists = kin.fk(wheels)
    steps = np.abs(np.diff(twists, axis=0))
    assert np.all(steps <= params.acc_limits * DT * (1 + 1e-9) + 1e-12)
    # the robot reaches the saturated request, in the requested direction
    final = twists[-1]
    assert np.max(np.abs(kin.ik(final))) == pytest.approx(params.max_wheel_speed)
    assert np.allclose(final / np.linalg.norm(final), np.array([3.0, 1.0, 2.0]) / np.linalg.norm([3.0, 1.0, 2.0]))
    assert node.counters["saturated"] > 0 and node.counters["accel_limited"] > 0


def test_a_command_takes_effect_after_the_delay_and_stops_after_the_timeout():
    params = ChassisNodeParams(cmd_vel_delay_s=0.05, cmd_vel_timeout_s=0.5, acc_lim_x=100.0)
    states, _ = drive(params, [((0.0, 0.0, 0.0), 2.0)])
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states, [cmd(0.2, vx=0.3)])
    kin = Kinematics(params)
    vx = {c.header.stamp_ns: kin.fk(c.velocities)[0] for c in of(out, "omninav/r1/wheel_cmd")}
    moving = sorted(t for t, v in vx.items() if v > 1e-9)
    # in effect from the first reading stamped after 0.2 + 0.05 s, until it is older than 0.5 s
    assert moving[0] == round(0.26 * NS_PER_S)
    assert vx[round(0.3 * NS_PER_S)] == pytest.approx(0.3)
    assert vx[round(0.7 * NS_PER_S)] == pytest.approx(0.3)
    assert all(v == 0.0 for t, v in vx.items() if t > round(0.7 * NS_PER_S) + 5 * STEP_NS)
    assert moving[-1] < round(0.8 * NS_PER_S)


def test_a_diff_drive_drops_sideways_commands():
    params = ChassisNodeParams(drive="diff")
    states, _ = drive(params, [((0.0, 0.0, 0.0), 1.0)])
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states, [cmd(0.0, vx=0.2, vy=0.5)])
    twists = Kinematics(params).fk(np.array([c.velocities for c in of(out, "omninav/r1/wheel_cmd")]))
    assert np.all(twists[:, 1] == 0.0) and twists[30, 0] == pytest.approx(0.2)     # at 0.3 s
    assert node.counters["dropped_vy"] > 0


def test_bad_wheel_states_are_rejected_clearly_and_counted(caplog):
    params = ChassisNodeParams()
    states, _ = drive(params, [((0.2, 0.0, 0.0), 0.1)])
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states[:5])
    before = len(out)
    bad = [dataclasses.replace(states[5], drive="diff"),
           dataclasses.replace(states[5], positions=np.zeros(3)),
           dataclasses.replace(states[5], follower_positions=np.zeros(0)),
           dataclasses.replace(states[1], header=Header(stamp_ns=1, seq=99))]
    for msg in bad:
        node.process(0, msg)
    assert len(out) == before                            # nothing published for them
    assert node.counters[f"malformed/{WHEEL_STATE}"] == 4
    assert "configured for 'mecanum'" in caplog.text      # logged once per key, naming the problem
    assert node.diagnostic().level == 1
    node.process(0, states[5])                            # and it carries on
    assert len(out) == before + 4


def test_a_chassis_without_followers_publishes_no_follower_odometry():
    params = ChassisNodeParams(follower_odometry=False)
    states, _ = drive(params, [((0.2, 0.0, 0.0), 0.1)])
    for s in states:
        s.follower_positions = np.zeros(0)
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, states)
    assert "omninav/r1/odom_follower" not in node.outputs
    assert len(of(out, "omninav/r1/odom")) == len(states) and not node.counters[f"malformed/{WHEEL_STATE}"]


def pushed(params, shove=(0.3, 0.1, 0.2), steps=100):
    """WheelStates of a robot standing on its wheels while something pushes it by `shove` (body
    frame) over `steps`: the driven wheels' encoders stand still, the followers and the gyro see it."""
    per_step = np.asarray(shove) / steps
    states, followers = [], np.zeros(2)
    for k in range(steps + 1):
        states.append(WheelState(header=Header(stamp_ns=k * STEP_NS, seq=k + 1), drive=params.drive,
                                 positions=np.zeros(4), velocities=np.zeros(4),
                                 follower_positions=followers.copy(), gyro_z=0.0 if k == 0 else per_step[2] / DT))
        followers = followers + follower_readings(params, per_step)
    return states


@pytest.mark.parametrize("source", ["wheels", "followers"])
def test_odom_source_decides_whether_odom_sees_a_push(source):
    params = ChassisNodeParams(odom_source=source)
    node = ChassisNode(params)
    out = capture(node)
    in_stamp_order(node, pushed(params))
    odom, follower, tf = (of(out, f"omninav/r1/{k}")[-1] for k in ("odom", "odom_follower", "tf/odom_base"))
    moved = np.hypot(odom.pose.x, odom.pose.y)
    assert np.hypot(follower.pose.x, follower.pose.y) == pytest.approx(np.hypot(0.3, 0.1), rel=0.05)
    if source == "followers":
        assert encode(odom) == encode(follower) and moved > 0.3
    else:
        assert moved == 0.0 and odom.pose.theta == 0.0
    assert (tf.transform.x, tf.transform.y, tf.transform.theta) == (odom.pose.x, odom.pose.y, odom.pose.theta)


@pytest.mark.parametrize("source", ["wheels", "followers"])
def test_fused_odometry_puts_the_odometry_on_odom_wheel_and_leaves_tf_to_the_fusion(source):
    states, _ = drive(ChassisNodeParams(), [((0.4, 0.1, 0.3), 0.5)])
    outputs = {}
    for fused in (False, True):
        node = ChassisNode(ChassisNodeParams(odom_source=source, fused_odometry=fused))
        out = capture(node)
        in_stamp_order(node, states)
        outputs[fused] = out
    alone, beside = ({key for key, _ in outputs[f]} for f in (False, True))
    assert alone - beside == {"omninav/r1/odom", "omninav/r1/tf/odom_base"} and beside - alone == {"omninav/r1/odom_wheel"}
    # the same odometry, on the other key; the wheel commands the same
    assert [p for k, p in outputs[True] if k == "omninav/r1/odom_wheel"] == [p for k, p in outputs[False] if k == "omninav/r1/odom"]
    assert \
        [p for k, p in outputs[True] if k.endswith("wheel_cmd")] == [p for k, p in outputs[False] if k.endswith("wheel_cmd")]
    assert "omninav/r1/odom_wheel" in node.queryables and "omninav/r1/odom" not in node.queryables


def test_parameters_are_validated():
    with pytest.raises(ParamError, match="cmd_vel_delay_s"):
        load_params(ChassisNodeParams, {"cmd_vel_delay_s": 1.0, "cmd_vel_timeout_s": 0.5})
    with pytest.raises(ParamError, match="drive must be one of"):
        load_params(ChassisNodeParams, {"drive": "tank"})
    assert load_params(ChassisNodeParams, {"drive": "omni3", "follower_odometry": False}).drive == "omni3"
    with pytest.raises(ParamError, match="odom_source must be one of 'wheels', 'followers', got 'gps'"):
        load_params(ChassisNodeParams, {"odom_source": "gps"})
    with pytest.raises(ParamError, match="unless follower_odometry is true"):
        load_params(ChassisNodeParams, {"odom_source": "followers", "follower_odometry": False})


# ---------------------------------------------------------------- determinism

def _scenario():
    params = ChassisNodeParams()
    states, _ = drive(params, [((0.3, 0.1, 0.2), 1.0), ((0.0, 0.0, 0.0), 1.0)])
    commands = [cmd(0.1 * k + 0.013, vx=0.4 * np.sin(k), vy=0.2, wz=0.3 * np.cos(k), seq=k + 1) for k in range(15)]
    return params, states, commands


def _records(states, commands):
    recs = [Record(WHEEL_STATE, "WheelState", encode(s), s.header.seq, s.header.stamp_ns, 0) for s in states]
    recs += [Record(CMD_VEL, "Twist", encode(c), c.header.seq, c.header.stamp_ns, 0) for c in commands]
    return recs


def _live(params, states, commands, lag_steps):
    """Through the live runner's own decode/merge/late-count path; each command arrives `lag_steps`
    wheel states after the one stamped at or after it (as a slow teleop's would)."""
    node = ChassisNode(params)
    runner = LiveRunner(node)
    out = capture(node)
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    pending = list(commands)
    for k, state in enumerate(states):
        runner._handle(("msg", index[WHEEL_STATE], Received(encode(state), WHEEL_STATE), None))
        runner._release()
        while pending and pending[0].header.stamp_ns + lag_steps * STEP_NS <= state.header.stamp_ns:
            runner._handle(("msg", index[CMD_VEL], Received(encode(pending.pop(0)), CMD_VEL), None))
            runner._release()
    return node, out


def test_the_same_inputs_give_byte_identical_outputs():
    params, states, commands = _scenario()
    runs = []
    for _ in range(2):
        node = ChassisNode(params)
        out = capture(node)
        in_stamp_order(node, states, commands)
        runs.append(out)
    assert len(runs[0]) > 4 * len(states) - 1 and runs[0] == runs[1]


def test_commands_arriving_late_within_the_delay_replay_byte_for_byte():
    params, states, commands = _scenario()
    replayed = replay_into(ChassisNode(params), _records(states, commands), None).outputs
    # 3 steps (0.03 s) late: after readings stamped later had been processed, but within the 0.05 s delay
    node, live = _live(params, states, commands, lag_steps=3)
    assert [(r.key, r.payload) for r in replayed] == live
    assert not any(k.startswith("late/") for k in node.counters)
    assert node.diagnostic().level == 0
    # 8 steps late is past the delay: the outputs differ, and the live run says it is not replayable
    node, live = _live(params, states, commands, lag_steps=8)
    assert [(r.key, r.payload) for r in replayed] != live
    assert node.counters[f"late/{CMD_VEL}"] == len(commands)
    assert node.diagnostic().level == 1


def test_a_restarted_chassis_carries_its_odometry_on_from_odom_file(tmp_path):
    """Killed after 1.5 s of driving, the chassis left its odometry in odom_file; the robot rolls on
    for 0.5 s with nobody counting; the restarted chassis's odometry continues where the robot is,
    not at the odometry's origin."""
    odom_file = tmp_path / "odom.yaml"
    params = ChassisNodeParams(drive="mecanum", odom_file=str(odom_file), save_odom_rate=10.0)
    states, poses = drive(params, [((0.4, 0.1, 0.3), 2.0), ((0.0, 0.0, 0.0), 0.5)])
    first = ChassisNode(params)
    out = capture(first)
    in_stamp_order(first, states[:151])                   # to 1.5 s
    saved = of(out, "omninav/r1/odom")
    assert odom_file.exists() and len(saved) == 151
    restarted = ChassisNode(params)
    out = capture(restarted)
    assert restarted.counters["resumed_from_odom_file"] == 1
    in_stamp_order(restarted, states[201:])               # back at 2.0 s
    odom = of(out, "omninav/r1/odom")
    assert odom[0].header.stamp_ns == states[201].header.stamp_ns
    np.testing.assert_allclose([odom[-1].pose.x, odom[-1].pose.y, odom[-1].pose.theta], poses[-1], atol=0.01)
    assert np.hypot(odom[-1].pose.x, odom[-1].pose.y) > 0.5          # not back at the origin
    fresh = ChassisNode(dataclasses.replace(params, odom_file=""))   # without the file: the origin again
    out = capture(fresh)
    in_stamp_order(fresh, states[201:])
    assert np.hypot(of(out, "omninav/r1/odom")[-1].pose.x, of(out, "omninav/r1/odom")[-1].pose.y) < 0.01
