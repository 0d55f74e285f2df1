"""The navigator service in lockstep with fake neighbours: a toy robot (odometry, and a toy local
planner answering local_cmd every tick for the path it follows) and a toy global planner
answering plan_request. Goal → plan_request → follow_path → cmd_vel_nav → succeeded; a failing
planner → recoveries (costmap/clear) → aborted naming the reason; cancel; preemption; status on
`get`; with the real local planner, a map pose corrected off the goal after arrival is approached
again; move_base parameter files; and `omninav run navigator` answering `get` over the bus."""
import math

import numpy as np
import pytest

from conftest import wait_until
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import (GOAL_REACHED, CancelGoal, Costmap, Goal, Header, LocalCommand, MapMetaData,
                                      Odometry, OdometryDoubt, Path, Pose2D, PoseFit, Transform)
from omninav.services.local_planner.node import LocalPlannerNode, LocalPlannerNodeParams
from omninav.services.navigator.core import WAITING_FOR_CONFIDENT_POSE, WAITING_FOR_TRUSTED_ODOMETRY, State
from omninav.services.navigator.node import NavigatorNode, NavigatorNodeParams
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.merge import StampMerger
from omninav.services.runtime.node import NS_PER_S, Node, QueryError
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.geometry.se2 import integrate, relative, wrap_angle

KEYS = KeyLayout("r1")
DT = 0.05
NAV_KEYS = ("plan_request", "follow_path", "cmd_vel_nav", "costmap/clear", "nav_status", "local_cmd", "plan")


def ns(seconds: float) -> int:
    return round(seconds * NS_PER_S)


class ToyRobot(Node):
    """A source: drives the last cmd_vel_nav, publishes odometry (odom = map) and, for the path it
    was told to follow, a local_cmd towards the path's end (idle without one; none at all without
    local_planner, when a real one answers), every DT; publishes scheduled goals and cancels."""
    service = "toy_robot"

    def __init__(self, events: dict[int, list[tuple[str, object]]], controller_ok: bool = True,
                 local_planner: bool = True):
        self.events, self.controller_ok, self.local_planner = events, controller_ok, local_planner
        super().__init__()

    def setup(self) -> None:
        self.step, self.pose, self.cmd, self.path = 0, np.zeros(3), np.zeros(3), None
        self.odom_pub = self.publisher("odom")
        self.cmd_pub = self.publisher("local_cmd") if self.local_planner else None
        self.event_pubs = {topic: self.publisher(topic) for topic in ("goal", "cancel", "odom_doubt")}
        self.subscribe("cmd_vel_nav", self.on_cmd, synced=False)
        self.subscribe("follow_path", self.on_path, synced=False)

    def on_cmd(self, msg) -> None:
        self.cmd = np.array([msg.linear_x, msg.linear_y, msg.angular_z])

    def on_path(self, msg: Path) -> None:
        self.path = msg if len(msg.poses) else None

    def pace_s(self) -> float:
        return DT

    def tick(self) -> None:
        self.step += 1
        self.now_ns = ns(self.step * DT)
        self.pose = integrate(self.pose, self.cmd, DT)
        for topic, msg in self.events.get(self.step, ()):
            msg.header.stamp_ns = self.now_ns
            self.event_pubs[topic].publish(msg)
        x, y, theta = (float(v) for v in self.pose)
        self.odom_pub.publish(Odometry(header=self.header("odom"), pose=Pose2D(x, y, theta)))
        if self.cmd_pub is not None:
            self.cmd_pub.publish(self.local_command())

    def local_command(self) -> LocalCommand:
        if self.path is None:
            return LocalCommand(header=self.header(), ok=True, reason="idle")
        if not self.controller_ok:
            return LocalCommand(header=self.header(), goal_id=self.path.goal_id, ok=False,
                                reason="no valid trajectory")
        err = relative(self.pose, self.path.poses[-1])
        v = err[:2] * 1.5
        v *= min(1.0, 0.5 / max(float(np.hypot(*v)), 1e-12))
        wz = float(np.clip(1.5 * err[2], -1.0, 1.0))
        return LocalCommand(header=self.header(), goal_id=self.path.goal_id, linear_x=float(v[0]),
                            linear_y=float(v[1]), angular_z=wz)


class ToyPlanner(Node):
    """Answers each plan_request at once with a straight line from the robot, or with the error
    of a goal in an obstacle when the target is within 0.3 m of `pillar`."""
    service = "toy_planner"

    def __init__(self, pillar=(100.0, 100.0)):
        self.pillar = np.asarray(pillar, dtype=float)
        super().__init__()

    def setup(self) -> None:
        self.robot = np.zeros(3)
        self.plan_pub = self.publisher("plan")
        self.subscribe("odom", lambda msg: setattr(self, "robot", np.array([msg.pose.x, msg.pose.y, msg.pose.theta])))
        self.subscribe("plan_request", self.on_request, synced=False)

    def on_request(self, request: Goal) -> None:
        target = np.array([request.pose.x, request.pose.y, request.pose.theta])
        if math.hypot(*(target[:2] - self.pillar)) < 0.3:
            self.plan_pub.publish(Path(header=self.header("map"), poses=np.zeros((0, 3)), goal_id=request.goal_id,
                                       error="goal_in_obstacle: the goal cell has cost 254"))
            return
        poses = np.linspace(self.robot, target, 10)
        poses[:, 2] = target[2]
        self.plan_pub.publish(Path(header=self.header("map"), poses=poses, goal_id=request.goal_id))


def goal(x, y, yaw=0.0, goal_id="g1") -> Goal:
    return Goal(header=Header(frame_id="map"), goal_id=goal_id, pose=Pose2D(x, y, yaw))


def navigate(events, steps, params=None, planner=None, controller_ok=True, done=None):
    """Run the toy robot, the toy planner and the navigator; returns (navigator, robot, messages by topic)."""
    robot = ToyRobot(events, controller_ok)
    navigator = NavigatorNode(params or NavigatorNodeParams())
    runner = InProcessRunner([robot, planner or ToyPlanner(), navigator])
    published: dict[str, list] = {topic: [] for topic in NAV_KEYS}
    topics = {KEYS.robot(t): t for t in NAV_KEYS}
    runner.tap(lambda key, payload, stamp: published[topics[key]].append(decode(payload)) if key in topics else None)
    runner.run_until(done or (lambda: False), steps)
    runner.close()
    return navigator, robot, published


def statuses(published) -> list[tuple[str, str, str]]:
    return [(s.goal_id, s.status, s.reason) for s in published["nav_status"]]


def test_a_goal_is_planned_followed_on_the_local_planners_commands_and_reached():
    target = (2.0, 1.0, math.pi / 2)
    navigator, robot, out = navigate({2: [("goal", goal(*target))]}, 200, NavigatorNodeParams(request_delay_s=0.3))
    # the goal (stamped 0.1 s) takes effect at the first tick after 0.4 s, the plan 0.3 s after it was made
    request = out["plan_request"][0]
    assert (request.goal_id, request.header.frame_id, request.header.stamp_ns) == ("g1#1", "map", ns(0.45))
    assert (request.pose.x, request.pose.y, request.pose.theta) == target
    follow = out["follow_path"][0]
    assert follow.goal_id == "g1" and follow.header.stamp_ns == ns(0.8)
    np.testing.assert_allclose(follow.poses[-1], target)
    # while controlling, the command is the local planner's of the same tick
    local = {c.header.stamp_ns: c for c in out["local_cmd"]}
    moving = [c for c in out["cmd_vel_nav"] if (c.linear_x, c.linear_y, c.angular_z) != (0.0, 0.0, 0.0)]
    assert len(moving) > 20
    for cmd in moving:
        answer = local[cmd.header.stamp_ns]
        assert answer.goal_id == "g1" and (cmd.linear_x, cmd.linear_y, cmd.angular_z) == (
            answer.linear_x, answer.linear_y, answer.angular_z)
    assert [s[:2] for s in statuses(out)][0] == ("g1", "active") and statuses(out)[-1] == ("g1", "succeeded", "")
    done = out["nav_status"][-1]
    assert done.distance_remaining == 0.0
    actives = [s.header.stamp_ns for s in out["nav_status"] if s.status == "active"]
    assert len(actives) >= 3 and max(np.diff(actives)) <= ns(1.0)       # at least 1 Hz while active
    assert math.hypot(robot.pose[0] - 2.0, robot.pose[1] - 1.0) <= 0.10    # xy_goal_tolerance
    assert abs(wrap_angle(robot.pose[2] - math.pi / 2)) <= 0.05             # yaw_goal_tolerance
    # then the local planner is told to stop, and zeros follow for stop_duration_s, nothing after
    assert out["follow_path"][-1].goal_id == "g1" and len(out["follow_path"][-1].poses) == 0
    after = [c for c in out["cmd_vel_nav"] if c.header.stamp_ns >= done.header.stamp_ns]
    assert all((c.linear_x, c.linear_y, c.angular_z) == (0.0, 0.0, 0.0) for c in after)
    assert after[-1].header.stamp_ns == done.header.stamp_ns + ns(0.5)
    assert out["cmd_vel_nav"][-1].header.stamp_ns < ns(200 * DT)
    assert navigator.answer(KEYS.robot("nav_status"), {}).status == "succeeded"


def test_a_restarted_navigator_resumes_the_active_goal_from_its_goal_file(tmp_path):
    """Killed mid-goal, the navigator left its goal in goal_file: the next one takes it at its first
    tick under the same goal_id, plans afresh and reaches it; the file goes when the goal ends."""
    goal_file = tmp_path / "goal.yaml"
    params = NavigatorNodeParams(goal_file=str(goal_file))
    navigator, robot, out = navigate({2: [("goal", goal(2.0, 1.0, 0.5))]}, 40, params)
    assert statuses(out)[-1][:2] == ("g1", "active") and goal_file.exists()
    assert robot.pose[0] > 0.1                                     # under way when it died
    navigator, robot, out = navigate({}, 300, params)             # no goal sent to this one
    assert navigator.counters["goals_resumed"] == 1 and out["plan_request"][0].goal_id == "g1#1"
    assert statuses(out)[-1] == ("g1", "succeeded", "") and not goal_file.exists()
    assert math.hypot(robot.pose[0] - 2.0, robot.pose[1] - 1.0) <= 0.10
    navigator, _, out = navigate({}, 20, params)                  # nothing left to resume
    assert navigator.counters["goals_resumed"] == 0 and out["nav_status"] == []


class ForgetfulRobot(ToyRobot):
    """A toy robot whose local planner loses its path at step `forget_at` (it was restarted)."""

    def __init__(self, events, forget_at: int):
        self.forget_at = forget_at
        super().__init__(events)

    def tick(self) -> None:
        if self.step + 1 == self.forget_at:
            self.path = None
        super().tick()


def test_a_local_planner_that_lost_its_path_is_sent_it_again():
    robot = ForgetfulRobot({2: [("goal", goal(2.0, 1.0))]}, forget_at=30)
    navigator = NavigatorNode(NavigatorNodeParams(resend_path_after_s=1.0))
    runner = InProcessRunner([robot, ToyPlanner(), navigator])
    follows = []
    runner.tap(lambda key, payload, stamp: follows.append(decode(payload)) if key == KEYS.robot("follow_path") else None)
    runner.run_until(lambda: navigator.core.state is State.SUCCEEDED, 300)
    runner.close()
    assert navigator.counters["follow_path_resent"] == 1
    first, again = follows[0], follows[1]
    assert again.goal_id == "g1" and np.array_equal(again.poses, first.poses)
    assert again.header.stamp_ns >= ns(30 * DT)                   # only once it answered idle
    assert math.hypot(robot.pose[0] - 2.0, robot.pose[1] - 1.0) <= 0.10


class DoubtedRobot(ToyRobot):
    """The toy robot for the real local planner: also a free local costmap (odom frame) and a low
    beam fit (the localizer doubts its pose, so a goal stays active at the goal) every tick, and at
    the steps of `corrections` a map→odom transform (the localizer moving its pose)."""

    def __init__(self, events, corrections: dict[int, tuple[float, float, float]]):
        self.corrections = corrections
        super().__init__(events, local_planner=False)

    def setup(self) -> None:
        super().setup()
        self.costmap_pub, self.fit_pub = self.publisher("costmap/local"), self.publisher("pose_fit")
        self.map_odom_pub = self.publisher("tf/map_odom")
        self.free = np.zeros((80, 120), np.uint8)     # 6 x 4 m around the start

    def tick(self) -> None:
        super().tick()
        self.costmap_pub.publish(Costmap(self.header("odom"), MapMetaData(resolution=0.05, width=120, height=80,
                                                                          origin=Pose2D(-3.0, -2.0)), self.free))
        self.fit_pub.publish(PoseFit(self.header("map"), beam_fit=0.2, beams=100))
        if self.step in self.corrections:
            self.map_odom_pub.publish(Transform(self.header("map"), "odom", Pose2D(*self.corrections[self.step])))


def test_a_pose_corrected_off_the_goal_after_arrival_is_approached_again_by_the_real_local_planner():
    """The stall of tests/test_navigation_pipeline.py's shoved robot, in small: at the goal, waiting
    for a pose the scans agree with, the localizer moves the robot's map pose 5 cm off the goal. The
    local planner had answered goal_reached and went on answering it there, and the navigator waited
    for good; now the robot goes back to the goal (in the map) and waits there."""
    robot = DoubtedRobot({2: [("goal", goal(0.5, 0.0))]}, corrections={150: (0.0, 0.05, 0.0)})
    local_planner = LocalPlannerNode(LocalPlannerNodeParams())
    navigator = NavigatorNode(NavigatorNodeParams(xy_goal_tolerance=0.03, yaw_goal_tolerance=0.03))
    runner = InProcessRunner([robot, ToyPlanner(), local_planner, navigator])
    published = {"nav_status": [], "local_cmd": []}
    topics = {KEYS.robot(t): t for t in published}
    runner.tap(lambda key, payload, stamp: published[topics[key]].append(decode(payload)) if key in topics else None)
    runner.run_until(lambda: robot.step == 149, 200)
    assert navigator.core.reason == WAITING_FOR_CONFIDENT_POSE and abs(robot.pose[1]) <= 0.02
    runner.run_until(lambda: False, 150)
    runner.close()
    assert navigator.core.reason == WAITING_FOR_CONFIDENT_POSE      # at the goal again, by the map pose
    x, y = robot.pose[0], robot.pose[1] + 0.05
    assert math.hypot(x - 0.5, y) <= 0.03
    assert {s.status for s in published["nav_status"]} == {"active"} and not navigator.counters["recoveries/clear_costmaps"]
    assert published["local_cmd"][-1].reason == GOAL_REACHED


def test_no_success_while_the_odometry_fusion_doubts_and_success_once_it_trusts_again():
    """odom_doubt (services/ekf's verdict) holds the goal active at the goal, with the fusion's reason."""
    doubt = OdometryDoubt(Header(frame_id="odom"), doubtful=True, reason="wheels vs scans 0.61 m", mahalanobis=40.0)
    trust = OdometryDoubt(Header(frame_id="odom"))
    navigator, robot, out = navigate({2: [("goal", goal(1.0, 0.0)), ("odom_doubt", doubt)], 150: [("odom_doubt", trust)]},
                                     200)
    said = statuses(out)
    waiting = [reason for _, status, reason in said if status == "active" and reason]
    assert waiting and set(waiting) == {f"{WAITING_FOR_TRUSTED_ODOMETRY} (wheels vs scans 0.61 m)"}
    ended = out["nav_status"][-1]
    assert ended.status == "succeeded" and ended.header.stamp_ns > ns(150 * DT)
    assert math.hypot(robot.pose[0] - 1.0, robot.pose[1]) <= 0.1
    # a pose from a localizer on a map (use_odometry_doubt false): the doubt is not its to heed
    navigator, _, out = navigate({2: [("goal", goal(1.0, 0.0)), ("odom_doubt", doubt)]}, 200,
                                 NavigatorNodeParams(use_odometry_doubt=False))
    assert out["nav_status"][-1].status == "succeeded" and out["nav_status"][-1].header.stamp_ns < ns(150 * DT)


def test_before_any_goal_the_status_query_says_so_and_nothing_is_commanded():
    navigator, _, out = navigate({}, 20)
    with pytest.raises(QueryError, match=r"nav_status: no goal yet \(send one on omninav/r1/goal\)"):
        navigator.answer(KEYS.robot("nav_status"), {})
    with pytest.raises(QueryError, match="takes no parameters"):
        navigator.answer(KEYS.robot("nav_status"), {"goal": "g1"})
    assert not out["cmd_vel_nav"] and not out["plan_request"] and not out["nav_status"]


def test_a_goal_the_planner_cannot_reach_ends_aborted_after_the_recoveries_naming_why():
    params = NavigatorNodeParams(planner_patience=1.0, recovery_behaviors=("clear_costmaps", "wait"),
                                 wait_duration=0.5)
    navigator, robot, out = navigate({2: [("goal", goal(3.0, 0.0, goal_id="in-pillar"))]}, 200, params,
                                     planner=ToyPlanner(pillar=(3.0, 0.0)))
    final = statuses(out)[-1]
    assert final[:2] == ("in-pillar", "aborted")
    assert final[2] == ("no valid plan within planner_patience 1 s (goal_in_obstacle: the goal cell has cost 254), "
                        "even after recovery behaviours clear_costmaps, wait")
    # failed plans are retried (each request numbered), the costmaps cleared once, nothing followed
    ids = [r.goal_id for r in out["plan_request"]]
    assert len(ids) >= 3 and ids == [f"in-pillar#{k}" for k in range(1, len(ids) + 1)]
    assert [c.reset_distance for c in out["costmap/clear"]] == [3.0]     # conservative_reset_dist
    assert not out["follow_path"]
    assert np.allclose(robot.pose, 0.0, atol=1e-9)                      # clear and wait do not move
    assert navigator.counters["recoveries/clear_costmaps"] == navigator.counters["recoveries/wait"] == 1


def test_a_local_planner_without_valid_commands_stops_the_robot_and_ends_in_recovery():
    params = NavigatorNodeParams(controller_patience=1.0, planner_patience=1.0, recovery_behaviors=("back_up",),
                                 backup_dist=0.1)
    _, robot, out = navigate({2: [("goal", goal(2.0, 0.0))]}, 200, params, controller_ok=False)
    assert statuses(out)[-1][:2] == ("g1", "aborted")
    assert "no valid velocity command within controller_patience 1 s (no valid trajectory)" in statuses(out)[-1][2]
    # the only motion is back_up's 0.1 m backwards; while recovering the local planner follows nothing
    assert robot.pose[0] == pytest.approx(-0.1, abs=1e-6)
    empties = [p for p in out["follow_path"] if not len(p.poses)]
    assert empties and all(p.goal_id == "g1" for p in out["follow_path"])


def test_cancel_stops_the_robot_and_the_local_planner():
    navigator, robot, out = navigate({2: [("goal", goal(5.0, 0.0))], 40: [("cancel", CancelGoal(goal_id="other"))],
                                      50: [("cancel", CancelGoal(goal_id="g1"))]}, 100)
    assert statuses(out)[-1] == ("g1", "canceled", "canceled")
    canceled = out["nav_status"][-1].header.stamp_ns
    assert canceled == ns(50 * DT + 0.3 + DT)                    # the cancel naming another goal did nothing
    assert 0.5 < robot.pose[0] < 5.0 - 0.5
    stop = out["follow_path"][-1]
    assert stop.header.stamp_ns == canceled and len(stop.poses) == 0
    assert out["cmd_vel_nav"][-1].header.stamp_ns == canceled + ns(0.5)
    assert navigator.counters["cancels"] == 2


def test_a_new_goal_preempts_the_active_one_and_a_late_plan_for_it_is_ignored():
    # g2 takes effect between g1's plan request (0.45 s) and that plan's effect (0.8 s)
    navigator, robot, out = navigate({2: [("goal", goal(5.0, 0.0))], 8: [("goal", goal(0.0, 1.0, goal_id="g2"))]},
                                     200)
    assert statuses(out)[:3] == [("g1", "active", ""), ("g1", "canceled", "preempted by goal 'g2'"),
                                 ("g2", "active", "")]
    assert statuses(out)[-1] == ("g2", "succeeded", "")
    assert [r.goal_id for r in out["plan_request"]] == ["g1#1", "g2#2"]
    assert {p.goal_id for p in out["follow_path"]} == {"g2"}
    assert navigator.counters["plans_of_other_goals"] == 1
    assert math.hypot(robot.pose[0], robot.pose[1] - 1.0) <= 0.10


def test_inputs_arriving_up_to_request_delay_s_late_change_no_output():
    """The navigator's inputs from a run with a preemption and a cancel, fed again with every
    sporadic message (goal, cancel, plan) arriving as late as allowed — just before the first tick
    stamped request_delay_s after it — give byte for byte the same outputs."""
    recorded = []
    robot = ToyRobot({2: [("goal", goal(5.0, 0.0))], 8: [("goal", goal(0.0, 1.0, goal_id="g2"))],
                      30: [("goal", goal(2.0, 2.0, goal_id="g3"))], 45: [("cancel", CancelGoal())]})
    navigator = NavigatorNode()
    runner = InProcessRunner([robot, ToyPlanner(), navigator])
    runner.tap(lambda key, payload, stamp: recorded.append((key, payload)))
    runner.run_until(lambda: False, 80)
    runner.close()
    outputs = set(navigator.outputs)
    live = [(key, payload) for key, payload in recorded if key in outputs]
    assert {key for key, _ in live} >= {KEYS.robot(t) for t in ("plan_request", "follow_path", "nav_status")}

    fresh = NavigatorNode()
    replayed = []
    for pub in fresh.outputs.values():
        pub.sink = lambda p, payload, stamp: replayed.append((p.key, payload))
    index = {inp.key: i for i, inp in enumerate(fresh.inputs)}
    merger = StampMerger([inp.synced for inp in fresh.inputs])
    held = []       # sporadic messages not delivered yet: (latest allowed arrival, index, message)
    for key, payload in recorded:
        if key not in index:
            continue
        i = index[key]
        msg = decode(payload, fresh.inputs[i].msg_type)
        if not fresh.inputs[i].synced:
            held.append((msg.header.stamp_ns + fresh.pending.delay_ns, i, msg))
            continue
        for item in [h for h in held if h[0] <= msg.header.stamp_ns]:
            held.remove(item)
            merger.push(item[1], item[2].header.stamp_ns, (item[1], item[2]))
            for j, m in merger.pop_ready():
                fresh.process(j, m)
        merger.push(i, msg.header.stamp_ns, (i, msg))
        for j, m in merger.pop_ready():
            fresh.process(j, m)
    assert replayed == live


def test_move_base_parameter_files_load(tmp_path):
    (tmp_path / "move_base_params.yaml").write_text("""
move_base:
  base_global_planner: global_planner/GlobalPlanner
  base_local_planner: dwa_local_planner/DWAPlannerROS
  shutdown_costmaps: false
  controller_frequency: 10.0
  planner_patience: 3.0
  controller_patience: 5.0
  planner_frequency: 0.0
  oscillation_timeout: 10.0
  oscillation_distance: 0.2
  conservative_reset_dist: 2.0
  recovery_behaviors:
    - {name: conservative_reset, type: clear_costmap_recovery/ClearCostmapRecovery}
    - {name: rotate_recovery, type: rotate_recovery/RotateRecovery}
    - {name: aggressive_reset, type: clear_costmap_recovery/ClearCostmapRecovery}
  conservative_reset: {reset_distance: 2.0}
  aggressive_reset: {reset_distance: 0.0}
""")
    node = build_node("navigator", str(tmp_path / "move_base_params.yaml"))
    p = node.params
    assert (p.controller_frequency, p.planner_patience, p.oscillation_timeout, p.conservative_reset_dist) == (
        10.0, 3.0, 10.0, 2.0)
    assert p.recovery_order == ("clear_costmaps", "rotate", "clear_costmaps")
    with pytest.raises(ParamError, match=r"type 'move_slow_and_clear/MoveSlowAndClear' has no equivalent"):
        build_node("navigator", overrides={"recovery_behaviors": [
            {"name": "slow", "type": "move_slow_and_clear/MoveSlowAndClear"}]})
    with pytest.raises(ParamError, match="request_delay_s must be ≥ 0, got -0.1"):
        build_node("navigator", overrides={"request_delay_s": -0.1})


def test_omninav_run_navigator_answers_its_status_over_the_bus(processes, router_endpoint):
    processes.omninav("run", "navigator")
    key = KEYS.robot("nav_status")

    def error_reply():
        with open_client(router_endpoint) as session:
            return [r.err.payload.to_bytes().decode() for r in session.get(key, timeout=2.0) if r.err is not None]

    replies = wait_until(error_reply, timeout=60, what="the navigator's answer")
    assert replies == [f"{key}: no goal yet (send one on omninav/r1/goal)"]
