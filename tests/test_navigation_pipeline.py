"""The whole navigation stack in lockstep, in one process: sim (room), chassis, lidar, map_server,
truth_pose (the pose source), costmap, tracker, global_planner (answering plan_request), local_planner,
velocity_smoother, collision_monitor and navigator. A goal across the room is reached without
touching anything, within 5 cm and 2° by the simulator's truth; a goal inside the pillar ends
aborted, naming why."""
import math

import numpy as np
import pytest

from conftest import REPO
from omninav.cli.navigate import drive_params, map_for
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Goal, Header, Pose2D
from omninav.services.chassis.node import ChassisNode, ChassisNodeParams
from omninav.services.cmd_vel_mux.node import CmdVelMuxNode
from omninav.services.costmap.node import CostmapNode, CostmapNodeParams
from omninav.services.global_planner.node import PlannerNode, PlannerNodeParams
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.services.velocity_smoother.node import VelocitySmootherNode
from omninav.services.collision_monitor.node import CollisionMonitorNode
from omninav.services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from omninav.services.map_server.node import MapServerNode, MapServerParams
from omninav.services.localizer.node import LocalizerNode, LocalizerParams
from omninav.services.navigator.core import WAITING_FOR_CONFIDENT_POSE
from omninav.services.navigator.node import NavigatorNode, NavigatorNodeParams
from omninav.services.truth_pose.node import TruthPoseNode
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.node import NS_PER_S, Node
from omninav.services.runtime.params import read_params_mapping
from omninav.geometry.se2 import wrap_angle
from omninav.services.tracker.node import TrackerNode, TrackerNodeParams
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import load_world, world_path

KEYS = KeyLayout("r1")
PARAMS = REPO / "compose" / "params"
START = tuple(float(v) for v in load_world(world_path("room")).robot.start)


class GoalAt(Node):
    """Sends one goal on the first clock at or after `at_s` of sim time (a user, in lockstep)."""
    service = "goal_sender"

    def __init__(self, goal: Goal, at_s: float):
        self.goal, self.at_ns = goal, round(at_s * NS_PER_S)
        super().__init__()

    def setup(self) -> None:
        self.sent = False
        self.goal_pub = self.publisher("goal")
        self.subscribe("sim/clock", self.on_clock)

    def on_clock(self, clock) -> None:
        if not self.sent and clock.header.stamp_ns >= self.at_ns:
            self.goal.header.stamp_ns = clock.header.stamp_ns
            self.goal_pub.publish(self.goal)
            self.sent = True


def navigate(x: float, y: float, yaw: float, goal_id: str, max_sim_s: float, world_name: str = "room",
             map_folder=None, localizer=None, after_step=None, drive: str = "", **navigator_params):
    """Run the stack until the goal ends (or max_sim_s); returns (sim node, the statuses).
    A world without a shipped map is rasterized into map_folder, as `omninav navigate` does. The
    pose comes from the simulator's truth unless `localizer(map_file, start)` makes a localizer node;
    after_step(sim, statuses) is called after every step."""
    world = load_world(world_path(world_name))
    start = dict(zip(("initial_pose_x", "initial_pose_y", "initial_pose_a"), map(float, world.robot.start)))
    sim = SimNode(SimNodeParams(world=str(world_name), dt=0.02, drive=drive))   # 50 Hz physics: control runs at 20 Hz
    drive = sim.sim.drive
    strafing = drive_params(drive)                  # as `omninav navigate` sets the local planner
    navigator = NavigatorNode(NavigatorNodeParams(**{"xy_goal_tolerance": 0.03, "yaw_goal_tolerance": 0.025,
                                                     "planner_patience": 2.0, "recovery_behaviors": ("clear_costmaps",),
                                                     **start, **navigator_params}))
    map_file = str(map_for(world, world_name, map_folder))
    nodes = [sim, ChassisNode(ChassisNodeParams(drive=drive)), LidarNode(LidarNodeParams(world=str(world_name))),
             MapServerNode(MapServerParams(yaml_filename=map_file, publish_period_s=1.0)),
             TruthPoseNode() if localizer is None else localizer(map_file, start),
             CostmapNode(CostmapNodeParams(
                 global_costmap_files=(str(PARAMS / "costmap_common_params.yaml"),
                                       str(PARAMS / "costmap_global_params.yaml")),
                 local_costmap_files=(str(PARAMS / "costmap_common_params.yaml"),
                                      str(PARAMS / "costmap_local_params.yaml")), **start)),
             TrackerNode(TrackerNodeParams(**start)),
             PlannerNode(PlannerNodeParams(goal_topic="plan_request", planner_frequency=0.0, use_dijkstra=False,
                                           **start)),
             LocalPlannerNode(LocalPlannerNodeParams(**strafing, **start)),
             CmdVelMuxNode(), VelocitySmootherNode(), CollisionMonitorNode(), navigator,
             GoalAt(Goal(header=Header(frame_id="map"), goal_id=goal_id, pose=Pose2D(x, y, yaw)), at_s=1.0)]
    runner = InProcessRunner(nodes)
    statuses = []
    runner.tap(lambda key, payload, stamp: statuses.append(decode(payload))
               if key == KEYS.robot("nav_status") else None)
    ended = lambda: bool(statuses) and statuses[-1].status in ("succeeded", "aborted", "canceled")
    for _ in range(round(max_sim_s / sim.params.dt)):
        runner.step()
        if after_step is not None:
            after_step(sim, statuses)
        if ended():
            break
    runner.run_until(lambda: False, round(1.0 / sim.params.dt))     # the robot comes to rest
    runner.close()
    return sim, statuses


def test_a_goal_across_the_room_is_reached_without_touching_anything():
    goal = (8.3, 3.8, math.pi / 2)          # past the round table, between the pillar and the desk
    sim, statuses = navigate(*goal, goal_id="across", max_sim_s=60.0)
    assert [(s.goal_id, s.status) for s in statuses][-1] == ("across", "succeeded"), statuses[-1].reason
    assert sim.sim.collisions == 0
    truth = sim.last_truth.pose
    assert math.hypot(truth.x - goal[0], truth.y - goal[1]) <= 0.05
    assert abs(float(wrap_angle(truth.theta - goal[2]))) <= math.radians(2.0)


def test_a_goal_inside_the_pillar_ends_aborted_naming_why():
    sim, statuses = navigate(5.0, 4.0, 0.0, goal_id="pillar", max_sim_s=30.0)
    final = statuses[-1]
    assert (final.goal_id, final.status) == ("pillar", "aborted")
    # the map itself walls it off: reported on the first plan, no recovery tried
    assert final.reason.startswith("goal unreachable: the goal (5.00, 4.00) lies on no free cell of the map")
    assert "goal_in_obstacle" in final.reason and "recovery" not in final.reason
    assert final.header.stamp_ns < 5e9
    assert sim.sim.collisions == 0
    start = np.array(START[:2])
    assert np.hypot(sim.last_truth.pose.x - start[0], sim.last_truth.pose.y - start[1]) < 0.05   # never moved


def crossing_variant(folder, speeds, reversed_paths, name: str):
    """The crossing hall with its two people at other speeds, each starting from the other end of
    their way where `reversed_paths` says so (another phase of their meeting with the robot)."""
    movers = []
    for speed, flip, (x, a, b) in zip(speeds, reversed_paths, ((4.5, 0.6, 5.4), (6.5, 5.4, 0.6))):
        a, b = (b, a) if flip else (a, b)
        movers.append(f"  - {{radius: 0.3, speed: {speed}, path: [[{x}, {a}], [{x}, {b}]], loop: false}}")
    path = folder / f"{name}.yaml"
    path.write_text(f"name: {name}\nbounds: [10.0, 6.0]\nmovers:\n" + "\n".join(movers) +
                    "\ngoals:\n  - [9.0, 3.0, 0.0]\nrobot:\n  start: [1.0, 3.0, 0.0]\n  drive: mecanum\n")
    return path


# the shipped world (0.5 and 0.4 m/s), and variants nobody tuned on: faster, slower, other phases
CROSSINGS = {"shipped": None, "fast": ((0.8, 0.7), (False, True)), "slow_late": ((0.3, 0.35), (True, False)),
             "brisk_both_reversed": ((0.6, 0.9), (True, True))}
# two of them here (a mission is about a minute of CPU); every variant and drive is measured in
# docs/tracker.md, generated crossings at scale by `omninav bench scenarios --kind crossing`


@pytest.mark.parametrize("variant, drive", [("shipped", "mecanum"), ("fast", "diff")])
def test_people_crossing_the_planned_path_are_avoided_and_the_goal_is_reached(tmp_path, variant, drive):
    """The mecanum paper's dynamic-obstacle test: two people who do not give way walk back and forth
    across the straight way; the robot, with the tracker, neither touches them nor stops for good."""
    movers = CROSSINGS[variant]
    world = "crossing" if movers is None else crossing_variant(tmp_path, *movers, name=f"crossing_{variant}")
    goal = tuple(load_world(world_path(world)).goals[0])
    sim, statuses = navigate(*goal, goal_id="crossing", max_sim_s=90.0, world_name=world, map_folder=tmp_path,
                             drive=drive)
    assert statuses[-1].status == "succeeded", statuses[-1].reason
    assert sim.sim.collisions == 0 and sim.sim.contact_steps == 0
    # the hall's walls stay 2.6 m from the way: closer than 1 m was a person, met on the way
    assert 0.0 < sim.sim.min_clearance < 1.0
    truth = sim.last_truth.pose
    assert math.hypot(truth.x - goal[0], truth.y - goal[1]) <= 0.05


# ---------------------------------------------------------------- a shove at the goal, with AMCL

def amcl_localizer(**params):
    """amcl_paper.yaml with `params`, as the navigate() pose source."""
    def make(map_file: str, start: dict) -> LocalizerNode:
        values = read_params_mapping(PARAMS / "amcl_paper.yaml", "amcl")
        return LocalizerNode(LocalizerParams(**{**values, "map_file": map_file, **start, **params}))
    return make


# updates while standing, and a recovery that keeps its averages and searches near the estimate too
RECOVERING = dict(temporal_update=0.2, recovery_reset_after_injection=False, recovery_local_share=0.5)
NOT_RECOVERING = dict(recovery_alpha_slow=0.0, recovery_alpha_fast=0.0)


def shove_near(goal, offset, within_m):
    """Teleport the robot by `offset` (x, y, yaw) once it is within within_m of the goal."""
    done = []

    def after_step(sim, statuses):
        x, y, yaw = sim.sim.pose
        if not done and math.hypot(x - goal[0], y - goal[1]) < within_m:
            sim.sim.teleport((x + offset[0], y + offset[1], yaw + offset[2]))
            done.append(sim.last_truth.header.stamp_ns)
    return after_step, done


GOAL = (3.0, 4.0, 0.0)
SHOVE = (0.0, 0.35, 0.3)


def test_a_robot_shoved_near_the_goal_succeeds_once_the_localizer_has_found_it_again():
    after_step, shoved = shove_near(GOAL, SHOVE, within_m=0.12)
    sim, statuses = navigate(*GOAL, goal_id="shoved", max_sim_s=40.0, localizer=amcl_localizer(**RECOVERING),
                             after_step=after_step)
    assert shoved and statuses[-1].status == "succeeded", statuses[-1].reason
    truth = sim.last_truth.pose
    assert math.hypot(truth.x - GOAL[0], truth.y - GOAL[1]) <= 0.08 and sim.sim.collisions == 0


@pytest.mark.parametrize("min_pose_beam_fit", [0.5, 0.0])
def test_the_navigator_does_not_succeed_on_a_pose_whose_scans_do_not_fit(min_pose_beam_fit):
    # AMCL without recovery: after the shove its pose stays where the odometry carries it, at the goal
    after_step, shoved = shove_near(GOAL, SHOVE, within_m=0.12)
    sim, statuses = navigate(*GOAL, goal_id="doubted", max_sim_s=25.0, localizer=amcl_localizer(**NOT_RECOVERING),
                             after_step=after_step, min_pose_beam_fit=min_pose_beam_fit)
    truth = sim.last_truth.pose
    # truly not there: twice move_base's 0.10 m tolerance away (the 0.35 m shove less what the robot had left)
    assert shoved and math.hypot(truth.x - GOAL[0], truth.y - GOAL[1]) > 0.2
    if min_pose_beam_fit > 0:
        assert statuses[-1].status == "active" and statuses[-1].reason == WAITING_FOR_CONFIDENT_POSE
    else:   # move_base's rule: the pose says it is there
        assert statuses[-1].status == "succeeded"
