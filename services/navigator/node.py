"""The navigator service: move_base around the Navigator state machine (core.py).

It ticks on the local planner's answers: every `local_cmd` (LocalCommand, stamped with the
odometry it was computed on) calls Navigator.step(now = its stamp, ...) with that answer as the
control result when its goal_id is the active goal's (an idle or stale answer counts as none),
and with the robot's pose (below). Then it carries out the actions:

- plan_request (Goal, map frame): goal_id "<goal_id>#<request_id>", pose = the target (the next
  waypoint or the goal); the global planner (goal_topic: plan_request) plans it from its own pose
  estimate and answers on `plan` with that goal_id. An answer counts when its goal_id names the
  active goal and its request id is the latest request's; a Path with an error (or no poses) is a
  failed plan with the error as the reason.
- follow_path (Path, map frame, goal_id = the user's goal): each newly accepted plan; an empty
  Path when the goal ends, is preempted, or recovery starts (the local planner then stops).
- cmd_vel_nav (Twist, base_link): every tick while a goal is active (the local planner's twist
  while controlling, a recovery's motion, else zeros), then zeros for stop_duration_s of sim
  time after it ends, so a smoother downstream brings the robot to rest.
- costmap/clear (ClearCostmaps, reset_distance = conservative_reset_dist) when the
  clear_costmaps recovery starts.
- nav_status (NavStatus): whenever goal, status or reason change, and every status_period_s of
  sim time while the goal is pending or active. `get` on nav_status answers the latest status;
  before the first goal it answers an error saying there is none yet.

Inputs, in merge order: local_cmd, odom (synced); then tf/map_odom, pose, plan, goal, cancel,
pose_fit (sporadic; the localizer's beam fit, which the goal check needs high enough), odom_doubt
(sporadic; the odometry fusion's verdict: no goal succeeds while it doubts). local_cmd goes first so that a tick waits for nothing but the odometry stamped at
it: the tick at t uses the odometry stamped before t (the odometry at t sorts after the tick),
one odometry period older than the local planner's; ordered the other way, every tick would wait
for the next odometry, delaying every command by an odometry period. A sporadic message stamped
t takes effect at the first tick stamped after t + request_delay_s, as the global planner defers
its inputs: so whether it arrived before or after the ticks in (t, t + delay], the outputs are
the same, and a live run replays byte for byte. Goals and cancels that take effect at the same tick each get a
step of their own, in stamp order, before the tick's step.

The robot's pose: the latest `pose` in effect (map frame) when newer than the odometry, else the
odometry carried into the map by tf/map_odom (or initial_pose_* until one comes), as the planner.

Restarts. With goal_file set, the active goal (goal_id, the targets not yet reached) is written
there whenever it or its next waypoint changes, and the file is removed when the goal ends; a
navigator started with that file takes the goal at its first tick, as if it had just been sent
(same goal_id: whoever waits for its status sees it go on), and plans afresh from where the robot
is. A local planner that was restarted answers idle (goal_id "") although it was given a path:
once an idle answer is stamped resend_path_after_s after the last follow_path, the plan is sent again.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path as FilePath

import numpy as np

from ...schemas.messages import (CancelGoal, ClearCostmaps, Goal, Header, LocalCommand, NavStatus, Odometry, Path,
                                 Pose2D, Twist)
from ...geometry.frames import FrameParams
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node, QueryError
from ...parameters.declare import ParamError, param
from ..runtime.state_file import read_state, remove_state, write_state
from .core import ACTIVE, ControlResult, Navigator, NavActions, NavInputs, PlanResult, State
from .params import NavigatorParams
from .recovery import ZERO

MAP_ODOM, POSE, PLAN, GOAL, CANCEL, POSE_FIT, ODOM_DOUBT = range(7)   # sporadic inputs, in input order (the order of equal stamps)
REQUEST_SEPARATOR = "#"                        # plan_request goal_id: "<goal_id>#<request_id>"
FOLLOWING = (State.PLANNING, State.CONTROLLING)   # states in which the local planner keeps its plan


@dataclass(frozen=True)
class NavigatorNodeParams(FrameParams, NavigatorParams):
    """move_base's parameters (params.py) plus the frames and what the node needs around the core."""
    base_frame: str = "base_link"
    request_delay_s: float = param(0.3, ge=0)      # sim s from a tf / pose / plan / goal / cancel stamp to its effect
    stop_duration_s: float = param(0.5, ge=0)      # sim s of zero commands after a goal ends
    status_period_s: float = param(1.0, gt=0)      # sim s between repeated statuses while a goal is pending or active
    goal_file: str = ""                            # where the active goal is kept for a restarted navigator; "": nowhere
    resend_path_after_s: float = param(1.0, gt=0)  # sim s after a follow_path before an idle local planner is sent it again


@dataclass(frozen=True)
class SavedGoal:
    """What goal_file holds: the active goal with the targets it has still to reach."""
    goal_id: str
    frame_id: str
    x: float
    y: float
    theta: float
    waypoints: tuple[float, ...] = ()     # the waypoints not yet reached, flattened (x, y, theta, ...)

    def goal(self) -> Goal:
        return Goal(header=Header(frame_id=self.frame_id), goal_id=self.goal_id, pose=Pose2D(self.x, self.y, self.theta),
                    waypoints=np.array(self.waypoints, np.float64).reshape(-1, 3))


def plan_result(plan: Path, request_id: int) -> PlanResult:
    if plan.error or not len(plan.poses):
        return PlanResult(request_id, False, reason=plan.error or "empty plan")
    return PlanResult(request_id, True, np.asarray(plan.poses, dtype=float))


class NavigatorNode(Node):
    service = "navigator"
    Params = NavigatorNodeParams
    state_files = ("goal_file",)

    def setup(self) -> None:
        p = self.params
        self.core = Navigator(p)
        self.frames = p.robot_frames()
        self.stop_ns = round(p.stop_duration_s * NS_PER_S)
        self.status_period_ns = round(p.status_period_s * NS_PER_S)
        self.pending = Deferred(p.request_delay_s)   # sporadic inputs not yet in effect
        self.pose = None                      # the latest PoseWithCovariance in effect
        self.velocity = None                  # the body twist of the latest odometry
        self.status: NavStatus | None = None  # the latest published
        self.status_ns = 0                    # when it was published
        self.last_cmd_ns: int | None = None   # the last tick a goal was running
        self.followed = ""                    # goal_id of the plan the local planner follows ("" none)
        self.followed_plan: Path | None = None   # the last non-empty follow_path
        self.followed_ns = 0                  # when it was sent
        self.saved: tuple | None = None       # (goal_id, target_index) in goal_file
        self.resumed: Goal | None = self._resume()   # the goal to take at the first tick
        self.plan_request_pub = self.publisher("plan_request")
        self.follow_pub = self.publisher("follow_path")
        self.cmd_pub = self.publisher("cmd_vel_nav")
        self.clear_pub = self.publisher("costmap/clear")
        self.status_pub = self.publisher("nav_status")
        self.subscribe("local_cmd", self.on_local_cmd)
        self.subscribe("odom", self.on_odom)
        for kind, topic, check in ((MAP_ODOM, "tf/map_odom", self.frames.transform_problem),
                                   (POSE, "pose", self._check_map_frame), (PLAN, "plan", self._check_map_frame),
                                   (GOAL, "goal", None), (CANCEL, "cancel", None),
                                   (POSE_FIT, "pose_fit", self._check_map_frame), (ODOM_DOUBT, "odom_doubt", None)):
            if kind != ODOM_DOUBT or p.use_odometry_doubt:
                self.subscribe_deferred(topic, self.pending, kind, check)
        self.queryable("nav_status", self.answer_status)

    def _resume(self) -> Goal | None:
        path = self.params.goal_file
        if not path or not FilePath(path).exists():
            return None
        try:
            goal = read_state(SavedGoal, path).goal()
        except ParamError as exc:
            self.log.warning("not resuming the goal saved in %s: %s", path, exc)
            return None
        self.log.info("resuming goal %r saved in %s", goal.goal_id, path)
        return goal

    def _save_goal(self) -> None:
        """Keep goal_file up to date with the active goal, if there is one (removed when none is)."""
        core, path = self.core, self.params.goal_file
        active = (core.goal_id, core.target_index) if core.state in ACTIVE else None
        if not path or active == self.saved:
            return
        try:
            if active is None:
                remove_state(path)
            else:
                (x, y, theta), rest = core.targets[-1], core.targets[core.target_index:-1]
                write_state(path, SavedGoal(core.goal_id, self.frames.map_frame, x, y, theta,
                                            tuple(float(v) for v in rest.ravel())),
                            "the navigator's active goal and the targets it has still to reach")
        except OSError as exc:
            self.counters["goal_file_errors"] += 1
            if self.counters["goal_file_errors"] == 1:
                self.log.warning("cannot keep the goal in %s: %s", path, exc)
        self.saved = active

    # ------------------------------------------------------------ inputs

    def _check_map_frame(self, msg) -> str:
        if msg.header.frame_id != self.frames.map_frame:
            return f"frame {msg.header.frame_id!r}, expected the map frame {self.frames.map_frame!r}"
        return ""

    def on_odom(self, msg: Odometry) -> None:
        self.frames.set_odom(msg)
        self.velocity = (msg.twist.linear_x, msg.twist.linear_y, msg.twist.angular_z)

    def _due(self, now_ns: int) -> tuple[list[Goal | CancelGoal], Path | None, float | None, str | None]:
        """Put into effect the sporadic inputs stamped before now − request_delay_s, in stamp order;
        returns the goals and cancels among them, the newest plan, the newest beam fit and the
        newest odometry doubt ("" none)."""
        events, plan, beam_fit, doubt = [], None, None, None
        for kind, msg in self.pending.due(now_ns):
            if kind == MAP_ODOM:
                self.frames.set_map_odom(msg)
            elif kind == POSE:
                self.pose = msg
            elif kind == POSE_FIT:
                beam_fit = msg.beam_fit
            elif kind == ODOM_DOUBT:
                doubt = (msg.reason or "doubtful") if msg.doubtful else ""
            elif kind == PLAN:
                plan = msg
            else:
                events.append(msg)
        return events, plan, beam_fit, doubt

    # ------------------------------------------------------------ the tick

    def on_local_cmd(self, msg: LocalCommand) -> None:
        now_s = self.now_ns / NS_PER_S
        events, plan, beam_fit, doubt = self._due(self.now_ns)
        if self.resumed is not None:
            events.insert(0, self.resumed)
            self.resumed = None
            self.counters["goals_resumed"] += 1
        self._resend_path(msg)
        robot = self.frames.robot_with_pose(self.frames.map_frame, self.pose)
        for event in events:
            is_goal = isinstance(event, Goal)
            self.counters["goals" if is_goal else "cancels"] += 1
            self._carry_out(self.core.step(now_s, NavInputs(pose=robot, goal=event if is_goal else None,
                                                            cancel=None if is_goal else event)), final=False)
        inputs = NavInputs(pose=robot, velocity=self.velocity, plan=self._plan_result(plan), control=self._control(msg),
                           beam_fit=beam_fit, odometry_doubt=doubt)
        self._carry_out(self.core.step(now_s, inputs), final=True)
        self._save_goal()

    def _resend_path(self, msg: LocalCommand) -> None:
        """A local planner that answers idle long after it was sent a path has lost it (restarted)."""
        if (self.followed and self.followed_plan is not None and not msg.goal_id
                and msg.header.stamp_ns >= self.followed_ns + round(self.params.resend_path_after_s * NS_PER_S)):
            self.counters["follow_path_resent"] += 1
            self._follow(self.followed, self.followed_plan.poses)

    def _plan_result(self, plan: Path | None) -> PlanResult | None:
        if plan is None:
            return None
        goal_id, _, request = plan.goal_id.rpartition(REQUEST_SEPARATOR)
        if goal_id != self.core.goal_id or not request.isdigit():
            self.counters["plans_of_other_goals"] += 1
            return None
        return plan_result(plan, int(request))

    def _control(self, msg: LocalCommand) -> ControlResult | None:
        if self.core.state not in ACTIVE or msg.goal_id != self.core.goal_id:
            return None   # idle, or still about a goal that has ended
        return ControlResult(msg.ok, (msg.linear_x, msg.linear_y, msg.angular_z), msg.reason)

    def _carry_out(self, actions: NavActions, final: bool) -> None:
        core = self.core
        if actions.cmd is not None:   # a goal ran in this step (perhaps ending in it)
            self.last_cmd_ns = self.now_ns
        if actions.recovery is not None:
            self.counters[f"recoveries/{actions.recovery.name}"] += 1
            if actions.recovery.name == "clear_costmaps":
                self.clear_pub.publish(ClearCostmaps(header=self.header(),
                                                     reset_distance=self.params.conservative_reset_dist))
        if actions.plan_request is not None:
            request = actions.plan_request
            self.plan_request_pub.publish(Goal(header=self.header(self.frames.map_frame),
                                               goal_id=f"{core.goal_id}{REQUEST_SEPARATOR}{request.request_id}",
                                               pose=Pose2D(*request.goal)))
        if actions.controller_plan is not None:
            self._follow(core.goal_id, actions.controller_plan)
        elif self.followed and (core.state not in FOLLOWING or core.goal_id != self.followed):
            self._follow(self.followed, np.zeros((0, 3)))
        for status in actions.statuses[:-1] if final else actions.statuses:
            self._publish_status(status)
        if final:
            self._publish_command(actions)
            if actions.statuses:
                self._publish_status(actions.statuses[-1], periodic=core.state in ACTIVE)

    def _follow(self, goal_id: str, poses: np.ndarray) -> None:
        path = Path(header=self.header(self.frames.map_frame), poses=poses, goal_id=goal_id)
        self.follow_pub.publish(path)
        self.followed = goal_id if len(poses) else ""
        self.followed_plan, self.followed_ns = (path if len(poses) else None), self.now_ns

    def _publish_command(self, actions: NavActions) -> None:
        if actions.cmd is not None:
            cmd = actions.cmd
        elif self.last_cmd_ns is not None and self.now_ns <= self.last_cmd_ns + self.stop_ns:
            cmd = ZERO
        else:
            return
        self.cmd_pub.publish(Twist(header=self.header(self.params.base_frame), linear_x=cmd[0], linear_y=cmd[1],
                                   angular_z=cmd[2]))

    def _publish_status(self, status: NavStatus, periodic: bool = False) -> None:
        last = self.status
        changed = last is None or (status.goal_id, status.status, status.reason) != (last.goal_id, last.status,
                                                                                     last.reason)
        if changed or (periodic and self.now_ns >= self.status_ns + self.status_period_ns):
            self.status = replace(status, header=self.header(self.frames.map_frame))
            self.status_ns = self.now_ns
            self.status_pub.publish(self.status)

    # ------------------------------------------------------------ queries

    def answer_status(self, parameters: dict[str, str]) -> NavStatus:
        if parameters:
            raise QueryError(f"{self.status_pub.key}: takes no parameters, got {sorted(parameters)}")
        if self.status is None:
            raise QueryError(f"{self.status_pub.key}: no goal yet (send one on {self.keys.resolve('goal')})")
        return self.status
