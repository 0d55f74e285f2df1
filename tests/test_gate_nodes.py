"""velocity_smoother and collision_monitor as services: the smoother's acceleration limits, its
one-period delay and its timeout to zero on the sim clock; the monitor's zones on deferred scans,
its stop without a scan; and, with the simulated robot driven straight at a box, the monitor slows
it down and stops it short of the box without a collision."""
import math

import numpy as np
import pytest

from local_pipeline import KEYS, pipeline
from omninav.schemas import decode
from omninav.schemas.messages import Clock, Header, LaserScan, Twist
from omninav.services.cmd_vel_mux.mux import CommandMux, Source
from omninav.services.cmd_vel_mux.node import CmdVelMuxNode
from omninav.services.velocity_smoother.node import VelocitySmootherNode, VelocitySmootherNodeParams
from omninav.services.collision_monitor.node import CollisionMonitorNode, CollisionMonitorNodeParams
from omninav.services.runtime.node import NS_PER_S
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node

MS = 1_000_000


def twist(stamp_ns: int, vx: float = 0.0, vy: float = 0.0, wz: float = 0.0, seq: int = 0) -> Twist:
    return Twist(header=Header(stamp_ns=stamp_ns, frame_id="base_link", seq=seq), linear_x=vx, linear_y=vy,
                 angular_z=wz)


def outputs(node) -> list[Twist]:
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append(decode(payload, Twist))
    return out


def feed(node, messages) -> None:
    """(topic, message) pairs in the order replay feeds them: (stamp, input index, seq)."""
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    keyed = [(m.header.stamp_ns, index[KEYS.resolve(t)], m.header.seq, m) for t, m in messages]
    for stamp, i, seq, msg in sorted(keyed, key=lambda item: item[:3]):
        node.process(i, msg)


def clocks(until_s: float, step_ms: int = 10):
    return [("sim/clock", Clock(header=Header(stamp_ns=k * step_ms * MS, seq=k + 1)))
            for k in range(round(until_s * 1000 / step_ms) + 1)]


def test_the_smoother_limits_acceleration_waits_one_period_and_times_out_to_zero():
    node = VelocitySmootherNode(VelocitySmootherNodeParams(velocity_timeout=0.5))
    out = outputs(node)
    commands = [("cmd_vel_mux", twist(k * 50 * MS, vx=0.5, vy=-0.3, wz=1.0, seq=k)) for k in range(1, 21)]  # to 1 s
    feed(node, clocks(3.0) + commands)
    stamps = [m.header.stamp_ns for m in out]
    assert stamps == [k * 50 * MS for k in range(61)]                    # every tick, on multiples of 50 ms
    vx = np.array([m.linear_x for m in out])
    vy = np.array([m.linear_y for m in out])
    wz = np.array([m.angular_z for m in out])
    assert vx[1] == 0.0 and vx[2] > 0.0           # the command stamped 50 ms takes effect at 100 ms
    dt = 0.05
    assert np.all(np.diff(vx) <= 2.5 * dt + 1e-12) and np.all(np.diff(wz) <= 3.2 * dt + 1e-12)
    assert np.all(np.diff(vy) >= -2.5 * dt - 1e-12)
    assert vx[10] == pytest.approx(0.5) and vy[10] == pytest.approx(-0.3) and wz[10] == pytest.approx(1.0)
    # the last command is stamped 1.0 s: from 1.5 s (velocity_timeout) on the output falls to zero at max_decel
    assert vx[30] == pytest.approx(0.5)
    falling = vx[30:]
    assert np.all(np.diff(falling) >= -2.5 * dt - 1e-12) and falling[-1] == 0.0 and wz[-1] == 0.0 and vy[-1] == 0.0
    assert np.count_nonzero(falling) <= 1 + math.ceil(0.5 / (2.5 * dt))
    assert node.counters["timed_out_ticks"] > 0 and node.counters["commands"] == 20


def test_the_smoother_keeps_its_nav2_names_and_refuses_bad_values():
    p = build_node("velocity_smoother", overrides={"max_velocity": [0.3, 0.0, 1.0], "min_velocity": [-0.3, 0.0, -1.0],
                                                  "deadband_velocity": [0.01, 0.0, 0.01]}).params
    assert p.max_velocity == (0.3, 0.0, 1.0) and p.command_delay_s == 0.04
    with pytest.raises(ParamError, match="command_delay_s must be ≥ 0, got -0.1"):
        build_node("velocity_smoother", overrides={"command_delay_s": -0.1})
    with pytest.raises(ParamError, match=r"source_timeout must be more than scan_delay_s \(0.05\), got 0.01"):
        build_node("collision_monitor", overrides={"source_timeout": 0.01})


def ring_scan(stamp_ns: int, points, seq: int = 1) -> LaserScan:
    """A full-circle scan from the robot's centre whose beams hit the given (x, y) points, the rest
    nothing (max range)."""
    n = 360
    ranges = np.full(n, np.inf, np.float32)
    for x, y in points:
        beam = round((math.atan2(y, x) + math.pi) / (2 * math.pi / n)) % n
        ranges[beam] = math.hypot(x, y)
    return LaserScan(header=Header(stamp_ns=stamp_ns, frame_id="laser", seq=seq), angle_min=-math.pi,
                     angle_max=math.pi - 2 * math.pi / n, angle_increment=2 * math.pi / n, range_min=0.1,
                     range_max=10.0, ranges=ranges)


def test_the_monitor_stops_slows_or_passes_on_the_scan_in_effect_and_stops_without_one():
    node = CollisionMonitorNode(CollisionMonitorNodeParams(laser_x=0.0))
    out = outputs(node)
    ahead = [(0.416 + d, y) for d in (0.03,) for y in (-0.1, -0.05, 0.0, 0.05, 0.1)]   # within the stop zone
    near = [(0.416 + 0.2, y) for y in (-0.1, -0.05, 0.0, 0.05, 0.1)]                  # within the slowdown zone
    far = [(2.0, y) for y in (-0.1, -0.05, 0.0, 0.05, 0.1)]
    scans = [("scan", ring_scan(100 * MS, far, 1)), ("scan", ring_scan(200 * MS, near, 2)),
             ("scan", ring_scan(300 * MS, ahead, 3))]
    commands = [("cmd_vel_smoothed", twist(k * 50 * MS, vx=0.4, wz=0.2, seq=k)) for k in range(1, 9)]
    feed(node, scans + commands)
    got = {m.header.stamp_ns // MS: (m.linear_x, m.angular_z) for m in out}
    assert got[50] == got[100] == got[150] == (0.0, 0.0)     # no scan in effect yet: stop
    assert got[200] == got[250] == (0.4, 0.2)                # the far scan (from 150 ms on): pass
    assert got[300] == got[350] == (0.2, 0.1)                # the near one: half speed
    assert got[400] == (0.0, 0.0)                            # the one ahead: stop
    assert node.counters["action/no_scan"] == 3 and node.counters["action/stop"] == 1
    # a scan older than source_timeout is no scan
    feed(node, [("cmd_vel_smoothed", twist(1500 * MS, vx=0.1, seq=20))])
    assert (out[-1].linear_x, node.counters["action/no_scan"]) == (0.0, 4)


@pytest.mark.parametrize("topic", ["cmd_vel_nav", "cmd_vel_teleop"])   # navigation, or a human by hand
def test_driven_straight_at_a_box_the_robot_is_slowed_and_stopped_short_of_it(tmp_path, topic):
    world_file = tmp_path / "box.yaml"
    world_file.write_text("name: box\nbounds: [8.0, 3.0]\nboxes:\n  - {center: [4.0, 1.5], size: [0.4, 1.6]}\n"
                          "robot:\n  start: [1.2, 1.5, 0.0]\n  drive: mecanum\n")
    forward = [(0.5 + 0.05 * k, twist(0, vx=0.4)) for k in range(200)]      # 0.4 m/s for 10 s, at 20 Hz
    run = pipeline(str(world_file), "mecanum", forward, topic=topic, watch=["cmd_vel_smoothed", "cmd_vel"])
    run.run(10.0)
    assert run.sim.sim.collisions == 0 and run.sim.sim.contact_steps == 0
    assert np.abs(run.truths[-1][4:]).max() < 1e-3                          # standing
    gap = 3.8 - (run.truth()[0] + 0.416)                                    # the box's face to the robot's front
    assert 0.0 < gap <= 0.05 + 0.1 and run.sim.sim.min_clearance > 0.0
    counters = run.monitor.counters
    assert counters["action/slowdown"] > 0 and counters["action/stop"] > 0
    sent = {m.header.stamp_ns: m.linear_x for m in run.published[KEYS.robot("cmd_vel")]}
    smoothed = {m.header.stamp_ns: m.linear_x for m in run.published[KEYS.robot("cmd_vel_smoothed")]}
    slowed = [t for t, v in sent.items() if 0 < v < smoothed[t]]
    assert slowed and all(sent[t] == pytest.approx(0.5 * smoothed[t]) for t in slowed)
    assert max(t for t, v in sent.items() if v > 0) < run.truths[-1][0] * NS_PER_S


def test_the_mux_passes_teleop_over_navigation_until_teleop_times_out():
    mux = CommandMux([Source("teleop", 100, 0.5), Source("navigation", 10, 0.5)])
    assert mux.offer("navigation", 0)                       # nobody above it spoke
    assert mux.offer("teleop", 100 * MS)
    assert not mux.offer("navigation", 200 * MS)            # teleop active until 600 ms
    assert not mux.offer("navigation", 600 * MS)
    assert mux.offer("navigation", 601 * MS)                # teleop silent for longer than its timeout
    assert mux.offer("teleop", 700 * MS)                    # the higher priority always passes
    with pytest.raises(ValueError, match="timeout must be positive"):
        Source("teleop", 100, 0.0)


def test_the_mux_node_passes_teleop_over_navigation_and_navigation_again_after_the_timeout():
    node = CmdVelMuxNode()
    out = outputs(node)
    teleop = [("cmd_vel_teleop", twist(k * 100 * MS, vx=-0.2, seq=k)) for k in range(1, 4)]   # 0.1 .. 0.3 s
    navigation = [("cmd_vel_nav", twist(k * 50 * MS, vx=0.4, seq=k)) for k in range(1, 21)]   # to 1 s
    feed(node, clocks(2.0) + navigation + teleop)
    passed = [(m.header.stamp_ns // MS, m.linear_x) for m in out]
    assert passed[:2] == [(50, 0.4), (100, -0.2)]           # navigation until teleop speaks, in stamp order
    assert all(vx == -0.2 for t, vx in passed if 100 <= t <= 800)   # teleop's last at 0.3 s holds to 0.8 s
    assert [t for t, vx in passed if vx == 0.4] == [50, 850, 900, 950, 1000]
    assert node.counters["overridden/navigation"] == 15


@pytest.mark.parametrize("wz", [0.5, 3.0])
def test_a_turn_beside_a_wall_is_stopped_before_a_corner_reaches_the_stop_zone(tmp_path, wz):
    """The robot turns on the spot beside a wall its front corner would swing 2.4 cm into (maze 35's
    contact): the monitor stops the turn in time for the chassis's delay and deceleration, so the
    corner stays out of the 5 cm stop zone (judged on the instant, by the commands as sent, the
    corner came within 3.8 cm at 0.5 rad/s and touched the wall at 3 rad/s)."""
    world_file = tmp_path / "wall.yaml"
    world_file.write_text("name: wall\nbounds: [6.0, 4.0]\nboxes:\n  - {center: [2.7, 2.0], size: [0.4, 3.0]}\n"
                          "robot:\n  start: [2.0, 2.0, 0.0]\n  drive: mecanum\n")   # the wall's face 0.5 m ahead
    turn = [(0.5 + 0.05 * k, twist(0, wz=wz)) for k in range(100)]          # for 5 s, at 20 Hz
    run = pipeline(str(world_file), "mecanum", turn, topic="cmd_vel_nav")
    run.run(6.0)
    assert run.sim.sim.collisions == 0 and run.sim.sim.min_clearance > 0.04
    assert run.truths[-1][3] > 0.05 and run.monitor.counters["action/stop"] > 0   # it turned until stopped
