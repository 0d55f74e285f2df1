"""The sim service: in-process (tick, publish, commands, diagnostics) and as its own process."""
import logging

import numpy as np
import pytest

from omninav.schemas import MessageError, decode, encode
from omninav.schemas.messages import Clock, Header, Imu, Obstacles, Odometry, WheelCommand, WheelState
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import WorldError

from conftest import wait_until

STEP_NS = 10_000_000
NS_PER_S = 1_000_000_000


def capture(node):
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append((p.key, stamp, decode(payload)))
    return out


def command(node, velocities, drive="mecanum", stamp_ns=0):
    msg = WheelCommand(header=Header(stamp_ns=stamp_ns), drive=drive, velocities=np.asarray(velocities, float))
    node.process(0, decode(encode(msg)))


def test_tick_publishes_five_outputs_stamped_with_the_new_sim_time():
    node = SimNode(SimNodeParams(world="warehouse", rate=2.0))
    assert node.pace_s() == pytest.approx(0.005)
    assert [i.key for i in node.inputs] == ["omninav/r1/wheel_cmd"] and not node.inputs[0].synced
    out = capture(node)
    node.tick()
    node.tick()
    assert [k for k, _, _ in out[:5]] == ["omninav/r1/wheel_state", "omninav/r1/imu", "omninav/sim/r1/truth",
                                          "omninav/sim/movers", "omninav/sim/clock"]   # the clock last
    for tick, batch in enumerate((out[:5], out[5:]), start=1):
        for key, stamp, msg in batch:
            assert stamp == msg.header.stamp_ns == tick * STEP_NS and msg.header.seq == tick
    state, imu, truth, movers, clock = (m for _, _, m in out[5:])
    assert isinstance(state, WheelState) and state.drive == "mecanum" and state.positions.shape == (4,)
    assert state.follower_positions.shape == (2,) and state.header.frame_id == "base_link"
    assert isinstance(imu, Imu) and imu.header.frame_id == "base_link"
    assert isinstance(truth, Odometry) and truth.header.frame_id == "world" and truth.child_frame_id == "base_link"
    assert [truth.pose.x, truth.pose.y, truth.pose.theta] == pytest.approx([1.0, 1.0, 0.0], abs=1e-6)
    assert not truth.pose_covariance.any() and not truth.twist_covariance.any()
    assert isinstance(movers, Obstacles) and movers.circles.shape == (3, 3) and movers.velocities.shape == (3, 2)
    assert movers.circles == pytest.approx(node.world.movers.circles_at(0.02))
    assert isinstance(clock, Clock) and clock.rate == 2.0


def test_wheel_commands_drive_the_robot_and_truth_answers_get():
    node = SimNode(SimNodeParams(world="room", wheel_cmd_timeout_s=0.0).without_noise())     # one command held
    out = capture(node)
    truth_key = "omninav/sim/r1/truth"
    assert node.answer(truth_key, {}).pose.x == pytest.approx(1.2)     # before the first step: the start
    command(node, node.sim.kinematics.ik((0.5, 0.0, 0.0)))
    for _ in range(200):
        node.tick()
    last = {key: msg for key, _, msg in out}
    truth, state = last[truth_key], last["omninav/r1/wheel_state"]
    assert truth.pose.x == pytest.approx(1.2 + 0.5 * 2.0, abs=0.05) and truth.twist.linear_x == pytest.approx(0.5)
    assert state.velocities == pytest.approx(node.sim.kinematics.ik((0.5, 0.0, 0.0)))
    # cumulative wheel angles (rad): without noise, exactly the distance rolled
    assert state.positions == pytest.approx((truth.pose.x - 1.2) / node.sim.chassis.wheel_radius, abs=1e-9)
    answer = node.answer(truth_key, {})
    assert answer.header.stamp_ns == 200 * STEP_NS and answer.pose.x == truth.pose.x
    assert node.counters["received/omninav/r1/wheel_cmd"] == 1


def test_the_wheels_stop_when_their_command_goes_stale():
    """A chassis that dies leaves its last wheel command behind: the sim's watchdog stops the robot
    after wheel_cmd_timeout_s of its own steps without a new one, as a motor driver would."""
    node = SimNode(SimNodeParams(world="room", wheel_cmd_timeout_s=0.5).without_noise())
    out = capture(node)
    command(node, node.sim.kinematics.ik((0.5, 0.0, 0.0)))
    for _ in range(300):
        node.tick()
    truths = [msg for key, _, msg in out if key == "omninav/sim/r1/truth"]
    moving = [t.header.stamp_ns for t in truths if t.twist.linear_x > 0.01]
    assert 0.5 * NS_PER_S <= moving[-1] <= 0.7 * NS_PER_S          # stopped (decelerating) after 0.5 s
    assert truths[-1].twist.linear_x == pytest.approx(0.0, abs=1e-9) and truths[-1].pose.x < 1.2 + 0.5
    assert node.counters["wheel_cmd_timeouts"] == 1
    command(node, node.sim.kinematics.ik((0.5, 0.0, 0.0)), stamp_ns=node.now_ns)   # a fresh command drives again
    node.tick()
    node.tick()
    assert node.sim.command.any()


def test_a_command_for_another_robot_is_rejected_logged_once_and_counted(caplog):
    node = SimNode(SimNodeParams(world="room"))
    capture(node)
    with caplog.at_level(logging.WARNING):
        command(node, [1.0, 1.0], drive="diff")
        command(node, [1.0, 1.0], drive="diff")
        command(node, [1.0, 1.0, 1.0], drive="omni3")
    with pytest.raises(MessageError, match="3 wheel velocities for a mecanum drive of 4 wheels"):
        command(node, [1.0, 1.0, 1.0], drive="mecanum")       # the codec refuses it before the sim sees it
    assert node.counters["rejected/omninav/r1/wheel_cmd"] == 3
    warnings = [r.getMessage() for r in caplog.records if "rejected" in r.getMessage()]
    assert len(warnings) == 2          # once per kind of problem
    assert "diff drive with 2 wheels" in warnings[0] and "mecanum drive with 4 wheels" in warnings[0]
    assert "omni3 drive with 3 wheels" in warnings[1]
    node.tick()
    assert not node.sim.wheel_speeds.any()                   # none of them was applied
    diag = node.diagnostic()
    assert diag.level == 1 and "rejected" in diag.message
    assert diag.values["rejected/omninav/r1/wheel_cmd"] == 3
    assert diag.values["drive"] == "mecanum" and diag.values["world"].endswith("room.yaml")
    assert diag.values["collisions"] == 0 and diag.values["contact_steps"] == 0
    assert 0 < diag.values["min_clearance_m"] < 1.0


def test_collisions_show_in_the_diagnostic(tmp_path):
    world = tmp_path / "box.yaml"
    world.write_text("bounds: [3.0, 3.0]\nrobot: {start: [1.5, 1.5, 0.0], drive: diff}\n")
    node = SimNode(SimNodeParams(world=str(world), wheel_cmd_timeout_s=0.0))     # one command held
    capture(node)
    assert node.sim.drive == "diff"
    command(node, [10.0, 10.0], drive="diff")
    for _ in range(300):
        node.tick()
    diag = node.diagnostic()
    assert diag.values["collisions"] == 1 and diag.values["contact_steps"] > 0
    assert (diag.values["robot_fault_collisions"], diag.values["mover_fault_collisions"], diag.values["shoved_collisions"]) == (1, 0, 0)   # a wall
    assert diag.values["min_clearance_m"] == 0.0 and diag.level == 0


def test_broken_world_gives_a_clear_error(tmp_path):
    with pytest.raises(WorldError, match="no such file .*nowhere.yaml"):
        SimNode(SimNodeParams(world=str(tmp_path / "nowhere.yaml")))
    with pytest.raises(WorldError, match="shipped worlds: .*room"):
        SimNode(SimNodeParams(world="no_such_world"))
    broken = tmp_path / "broken.yaml"
    broken.write_text("bounds: [10.0, 8.0]\nboxes: [{center: [1, 2], size: [1, -2]}]\nrobot: {start: [1, 1, 0]}\n")
    with pytest.raises(WorldError, match=r"broken.yaml: boxes\[0\].size"):
        build_node("sim", overrides={"world": str(broken)})


def test_sim_process_steps_takes_commands_and_exits_2_on_a_bad_world(processes, router_endpoint, tmp_path):
    bad = processes.omninav("run", "sim", "--set", f"world={tmp_path / 'nowhere.yaml'}")
    assert bad.wait(60) == 2
    log = processes.log_of(bad)
    assert "no such file" in log and "Traceback" not in log

    sim = processes.omninav("run", "sim", "--set", "rate=2.0", "--set", "wheel_cmd_timeout_s=0")   # one command held
    truths = []
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber("omninav/sim/r1/truth",
                                         lambda s: truths.append(decode(s.payload.to_bytes(), Odometry)))
        wait_until(lambda: len(truths) > 10, 60, what="truth from the sim")
        assert truths[-1].pose.x == pytest.approx(1.2, abs=1e-3)          # no command yet: standing
        pub = session.declare_publisher("omninav/r1/wheel_cmd")
        forward = WheelCommand(header=Header(stamp_ns=truths[-1].header.stamp_ns), drive="mecanum",
                               velocities=np.full(4, 0.4 / 0.076))
        pub.put(encode(forward))
        wait_until(lambda: truths[-1].pose.x > 1.4, 60, what="the robot to move forward")
        replies = list(session.get("omninav/sim/r1/truth", timeout=10.0))
        assert replies and replies[0].ok and decode(replies[0].ok.payload.to_bytes(), Odometry).pose.x > 1.4
        sub.undeclare()
        pub.undeclare()
    stamps = [t.header.stamp_ns for t in truths]
    assert stamps == sorted(stamps) and all(s % STEP_NS == 0 for s in stamps)
    assert processes.stop(sim) == 0
