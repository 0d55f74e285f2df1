"""The simulated robot with its local costmap, the local planner and the two gates, in lockstep, with
small stand-ins for the navigator (for tests/test_local_planner_node.py and tests/test_gate_nodes.py)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from conftest import REPO
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Header, Path, Twist
from omninav.schemas.registry import type_info
from omninav.services.recorder.mcap_io import Record, RecordingWriter
from omninav.services.chassis.node import ChassisNode, ChassisNodeParams
from omninav.services.cmd_vel_mux.node import CmdVelMuxNode
from omninav.services.costmap.node import CostmapNode, CostmapNodeParams
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.services.velocity_smoother.node import VelocitySmootherNode
from omninav.services.collision_monitor.node import CollisionMonitorNode
from omninav.services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.node import NS_PER_S, Node
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import load_world, world_path

KEYS = KeyLayout("r1")
SAMPLES = REPO / "compose" / "params"
COMMON = str(SAMPLES / "costmap_common_params.yaml")
# compose/nav.yaml's costmap files: the local costmap is a 6 m rolling window in the odom frame
COSTMAP_FILES = dict(global_costmap_files=(COMMON, str(SAMPLES / "costmap_global_params.yaml")),
                     local_costmap_files=(COMMON, str(SAMPLES / "costmap_local_params.yaml")))


class NavigatorStandIn(Node):
    """What the navigator does with local_cmd while a goal runs: its twist on cmd_vel_nav, zero when
    not ok, stamped alike."""
    service = "navigator_stand_in"

    def setup(self) -> None:
        self.out = self.publisher("cmd_vel_nav")
        self.subscribe("local_cmd", self.on_local_cmd)

    def on_local_cmd(self, msg) -> None:
        twist = (msg.linear_x, msg.linear_y, msg.angular_z) if msg.ok else (0.0, 0.0, 0.0)
        self.out.publish(Twist(header=Header(stamp_ns=msg.header.stamp_ns, frame_id="base_link"),
                               linear_x=twist[0], linear_y=twist[1], angular_z=twist[2]))


class Scheduled(Node):
    """Publishes given messages on one topic at given sim times (on the clock)."""
    service = "scheduled"

    def __init__(self, topic: str, schedule: list[tuple[float, object]], **kwargs):
        self.topic, self.schedule = topic, sorted(schedule, key=lambda item: item[0])
        super().__init__(**kwargs)

    def setup(self) -> None:
        self.out = self.publisher(self.topic)
        self.subscribe("sim/clock", self.on_clock)

    def on_clock(self, _clock) -> None:
        while self.schedule and round(self.schedule[0][0] * NS_PER_S) <= self.now_ns:
            _, msg = self.schedule.pop(0)
            msg.header.stamp_ns = self.now_ns
            self.out.publish(msg)


def recorder_tap(writer: RecordingWriter):
    """A tap writing every message as the recorder would."""
    def record(key, payload, stamp):
        msg = decode(payload)
        writer.write_record(Record(key, type_info(type(msg))[0], payload, msg.header.seq, stamp, writer.count))
    return record


def polyline(corners, goal_yaw: float, spacing: float = 0.05) -> np.ndarray:
    """A global planner's kind of path: poses every `spacing` m along the corners, facing along,
    the last one with goal_yaw."""
    corners = np.asarray(corners, float)
    poses = []
    for a, b in zip(corners[:-1], corners[1:]):
        n = max(1, math.ceil(np.hypot(*(b - a)) / spacing))
        poses += [[*(a + (b - a) * k / n), math.atan2(b[1] - a[1], b[0] - a[0])] for k in range(n)]
    return np.array(poses + [[*corners[-1], goal_yaw]])


def follow_path(poses, goal_id: str = "g1") -> Path:
    return Path(header=Header(frame_id="map"), poses=np.asarray(poses, float).reshape(-1, 3), goal_id=goal_id)


@dataclass
class Pipeline:
    runner: InProcessRunner
    sim: SimNode
    local_planner: LocalPlannerNode | None
    monitor: CollisionMonitorNode
    truths: list = field(default_factory=list)        # (t, x, y, yaw, vx, vy, wz) per sim step
    published: dict = field(default_factory=dict)     # key -> decoded messages, in order

    def truth(self) -> np.ndarray:
        return np.array(self.truths[-1][1:4])

    def run(self, seconds: float, until=None) -> None:
        self.runner.run_until(until or (lambda: False), round(seconds / self.sim.params.dt))


def pipeline(world: str, drive: str, schedule: list[tuple[float, object]], *, topic: str = "follow_path",
             local_planner: dict | None = None, watch=()) -> Pipeline:
    """sim, chassis, lidar, costmap, local_planner, the navigator stand-in, cmd_vel_mux,
    velocity_smoother and collision_monitor, with `schedule` published on `topic` (follow_path; or
    cmd_vel_nav or cmd_vel_teleop into the mux, without the local planner and the stand-in)."""
    x, y, yaw = (float(v) for v in load_world(world_path(world)).robot.start)
    sim = SimNode(SimNodeParams(world=world, drive=drive))
    monitor = CollisionMonitorNode()
    nodes = [sim, ChassisNode(ChassisNodeParams(drive=drive)), LidarNode(LidarNodeParams(world=world)),
             CmdVelMuxNode(), VelocitySmootherNode(), monitor, Scheduled(topic, schedule)]
    planner = None
    if topic == "follow_path":
        planner = LocalPlannerNode(LocalPlannerNodeParams.from_mapping(
            {"initial_pose_x": x, "initial_pose_y": y, "initial_pose_a": yaw, "holonomic_robot": drive != "diff",
             **(local_planner or {})}))
        nodes += [CostmapNode(CostmapNodeParams(**COSTMAP_FILES, initial_pose_x=x, initial_pose_y=y,
                                                initial_pose_a=yaw)), planner, NavigatorStandIn()]
    run = Pipeline(InProcessRunner(nodes), sim, planner, monitor)
    truth_key, watched = KEYS.sim_robot("truth"), {KEYS.robot(t) for t in watch}

    def tap(key, payload, _stamp):
        if key == truth_key:
            m = decode(payload)
            run.truths.append((m.header.stamp_ns / NS_PER_S, m.pose.x, m.pose.y, m.pose.theta,
                               m.twist.linear_x, m.twist.linear_y, m.twist.angular_z))
        elif key in watched:
            run.published.setdefault(key, []).append(decode(payload))
    run.runner.tap(tap)
    return run
