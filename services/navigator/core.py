"""move_base as a deterministic state machine: goals in, plan requests, commands and status out.

The node calls `Navigator.step(now_s, inputs)` at controller_frequency in sim time (and whenever
a goal or cancel arrives) with what it has received since the previous step; the returned
actions say what to do. Nothing here reads a clock or does I/O, so the same inputs always give
the same actions.

States: PENDING (goal accepted, no pose yet) → PLANNING → CONTROLLING ⇄ RECOVERING →
SUCCEEDED | ABORTED(reason) | CANCELED(reason). The move_base rules kept:

- a plan is requested at once on a new goal (and on each new waypoint), retried while PLANNING
  (throttled to planner_frequency when it is > 0) and repeated at planner_frequency while
  CONTROLLING; only the answer to the latest request counts.
- no valid plan for longer than planner_patience since the last one (or more failed plans than
  max_planning_retries when that is ≥ 0) → recovery. Unlike move_base, the patience also runs
  when the planner does not answer at all.
- the local planner reporting no valid trajectory: within controller_patience, stop and replan
  (move_base's "go back to planning"); past it → recovery. A step without any answer from the
  local planner stops the robot and lets the patience run, but does not replan.
- the local planner reporting the goal reached (GOAL_REACHED) while the robot is not within the
  tolerances of the target as the navigator sees it (its pose corrected after the local planner
  arrived, or the local planner's tolerances wider than these) counts as no valid command, as
  above: replan from where the robot is, and past controller_patience recover. move_base lets the
  local planner decide arrival; here the navigator does, and a disagreement must not leave the robot
  standing with an active goal for good.
- not moving oscillation_distance within oscillation_timeout while CONTROLLING → recovery.
- recovery behaviours run each at most once per target (waypoint or goal): after one, the timers
  restart and planning resumes (from where the robot is); they may all run again once the failure
  that triggered recovery goes away (a valid plan, a valid command, or enough motion). When none
  are left: ABORTED, naming the failure and the behaviours tried. Not move_base's: with
  recovery_by_cause (the default) the configured behaviours run in the order that suits what
  blocked the robot (RECOVERY_BY_TRIGGER): no plan — clear the marks first, then wait for whoever
  stands in the way, then look round; no valid command — clear, then back off to get room to turn;
  no progress although commands are valid — move_base's own order: clear, look round, back off
  (backing off first was tried: building-diff-3, a robot wedged diagonally in a door, took 65.6 s
  against 53.8 s — 0.15 m back left it as wedged, and turning was what freed it). move_base runs its
  one list whatever the cause (recovery_by_cause false).
- a plan the global planner failed as PLAN_UNREACHABLE (the goal cannot be reached on the map
  itself: global_planner/map_reach.py) ends the goal ABORTED at once, "goal unreachable: <why>":
  no recovery changes the map.
- a new goal preempts the current one: the old goal ends CANCELED with the reason
  "preempted by goal <id>" (actionlib's PREEMPTED; NavStatus has no such status).
- arrival: within xy_goal_tolerance of an intermediate waypoint (no yaw check), and within
  xy_goal_tolerance and yaw_goal_tolerance of the final pose, moving no faster than
  trans_stopped_vel / rot_stopped_vel (when the velocity is known). With latch_xy_goal_tolerance the
  final position, once within xy_goal_tolerance, stays reached while the robot turns to the yaw,
  unless it drifts beyond the latch's slack (geometry/goal_latch.py), as the local planner's final
  approach latches it.

Not move_base's: the goal never succeeds on a pose the localizer doubts. While the latest beam fit
(the share of a scan's returns on mapped obstacles at the localizer's pose) is below
min_pose_beam_fit, arrival waits with the reason WAITING_FOR_CONFIDENT_POSE and the goal stays
active (control, oscillation and recovery go on as before). When the fit comes back while
controlling, the plan is made afresh from the pose the localizer has found (the local planner may
have stopped at the old plan's end, where the doubted pose put the goal). Without any beam fit (a
pose from SLAM or the simulator's truth) nothing is doubted. The same holds while the odometry
fusion (services/ekf) doubts its odometry — the wheels, the gyro and the scans disagree: a slip, a
push — with the reason WAITING_FOR_TRUSTED_ODOMETRY; without a fusion nothing is doubted.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from ...schemas.messages import GOAL_REACHED, PLAN_UNREACHABLE, CancelGoal, Goal, Header, NavStatus
from ...geometry.goal_latch import GoalLatch
from ...geometry.se2 import wrap_angle
from .params import NavigatorParams
from .recovery import ZERO, Behaviour, Twist3, behaviour

GOAL_FRAMES = ("", "map")
WAITING_FOR_CONFIDENT_POSE = "at the goal, waiting for a pose the scans agree with (beam fit below min_pose_beam_fit)"
WAITING_FOR_TRUSTED_ODOMETRY = "at the goal, waiting for odometry the wheels, gyro and scans agree on"


class State(enum.Enum):
    PENDING = "pending"
    PLANNING = "planning"
    CONTROLLING = "controlling"
    RECOVERING = "recovering"
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"
    CANCELED = "canceled"


ACTIVE = (State.PENDING, State.PLANNING, State.CONTROLLING, State.RECOVERING)
NAV_STATUS = {State.PENDING: "pending", State.PLANNING: "active", State.CONTROLLING: "active",
              State.RECOVERING: "active", State.SUCCEEDED: "succeeded", State.ABORTED: "aborted",
              State.CANCELED: "canceled"}


class Trigger(enum.Enum):
    """What started the recovery behaviours (move_base's RecoveryTrigger)."""
    PLANNING = "planning"
    CONTROLLING = "controlling"
    OSCILLATION = "oscillation"


# with recovery_by_cause: the order the configured behaviours run in, by what blocked the robot
RECOVERY_BY_TRIGGER = {Trigger.PLANNING: ("clear_costmaps", "wait", "rotate", "back_up"),
                       Trigger.CONTROLLING: ("clear_costmaps", "back_up", "rotate", "wait"),
                       Trigger.OSCILLATION: ("clear_costmaps", "rotate", "back_up", "wait")}


@dataclass(frozen=True)
class PlanRequest:
    request_id: int
    start: tuple[float, float, float]   # map frame
    goal: tuple[float, float, float]


@dataclass(frozen=True)
class PlanResult:
    request_id: int                     # the PlanRequest this answers
    ok: bool
    path: np.ndarray | None = None      # (N, 3) map frame, when ok
    reason: str = ""                    # why not, when not ok


@dataclass(frozen=True)
class ControlResult:
    ok: bool
    cmd: Twist3 = ZERO                  # body twist (vx, vy, wz), when ok
    reason: str = ""                    # e.g. "no valid trajectory"


@dataclass(frozen=True)
class NavInputs:
    pose: tuple[float, float, float] | np.ndarray | None = None   # robot pose, map frame
    velocity: tuple[float, float, float] | np.ndarray | None = None   # body twist (odometry); None: unknown
    beam_fit: float | None = None           # the localizer's latest beam fit; None: no news
    odometry_doubt: str | None = None       # the fusion's latest verdict: why it doubts, "" it does not; None: no news
    plan: PlanResult | None = None
    control: ControlResult | None = None   # the local planner's answer for this control cycle
    goal: Goal | None = None
    cancel: CancelGoal | None = None        # handled before `goal` of the same step


@dataclass
class NavActions:
    plan_request: PlanRequest | None = None
    controller_plan: np.ndarray | None = None  # a newly accepted plan for the local planner
    cmd: Twist3 | None = None                  # None: no goal running, send nothing
    recovery: Behaviour | None = None          # a behaviour started this step (the node clears costmaps)
    statuses: list[NavStatus] = field(default_factory=list)   # ended-by-preemption first, then the current


class Navigator:
    def __init__(self, params: NavigatorParams | None = None):
        self.params = params or NavigatorParams()
        self.period_s = 1.0 / self.params.controller_frequency
        self.state: State | None = None       # None: no goal yet
        self.reason = ""
        self.goal_id = ""
        self.targets = np.zeros((0, 3))       # waypoints then the final pose
        self.target_index = 0
        self.pose: np.ndarray | None = None
        self.velocity: np.ndarray | None = None
        self.beam_fit: float | None = None    # None: no localizer says how well its scans fit
        self.odometry_doubt = ""              # why the odometry fusion doubts its odometry ("": it does not)
        self.path: np.ndarray | None = None
        self._latch = GoalLatch(self.params.xy_goal_tolerance, self.params.latch_xy_goal_tolerance)
        self._now: float | None = None
        self._next_request_id = 1
        self._outstanding: int | None = None  # the plan request whose answer counts
        self._last_request_s = -math.inf
        self._want_plan = False
        self._fresh_plan = False
        self._last_valid_plan_s = 0.0
        self._last_valid_control_s = 0.0
        self._last_oscillation_reset_s = 0.0
        self._oscillation_pose: np.ndarray | None = None
        self._planning_retries = 0
        self._last_failure = ""
        self._trigger: Trigger | None = None
        self._tried: list[str] = []           # the behaviours run for this target since the failure began
        self._recovery: Behaviour | None = None
        self._recovery_start_s = 0.0

    # ---- the one entry point -------------------------------------------------------------
    def step(self, now_s: float, inputs: NavInputs) -> NavActions:
        if self._now is not None and now_s < self._now:
            raise ValueError(f"step time {now_s} s is earlier than the previous {self._now} s")
        self._now = now_s
        out = NavActions()
        self._fresh_plan = False
        if inputs.pose is not None:
            self.pose = np.asarray(inputs.pose, dtype=float).reshape(3)
        if inputs.velocity is not None:
            self.velocity = np.asarray(inputs.velocity, dtype=float).reshape(3)
        if inputs.beam_fit is not None or inputs.odometry_doubt is not None:
            was_doubted = bool(self._doubt())
            self.beam_fit = self.beam_fit if inputs.beam_fit is None else float(inputs.beam_fit)
            self.odometry_doubt = self.odometry_doubt if inputs.odometry_doubt is None else inputs.odometry_doubt
            if was_doubted and not self._doubt() and self.state is State.CONTROLLING:
                self._want_plan = True   # the pose the plan started from was wrong: plan from the found one
        if inputs.cancel is not None and self._cancel(inputs.cancel, out) and inputs.goal is not None:
            out.statuses.append(self.status())
        if inputs.goal is not None:
            self._accept(inputs.goal, out)
        if self.state is State.PENDING and self.pose is not None:
            self._begin_target()
        if self.state in (State.PLANNING, State.CONTROLLING):
            self._take_plan(inputs.plan, out)
        if self.state in (State.PLANNING, State.CONTROLLING):
            self._track_motion()
            self._check_arrival(out)
        if self.state is State.PLANNING and now_s > self._last_valid_plan_s + self.params.planner_patience:
            self._recover(Trigger.PLANNING, out)
        if self.state is State.CONTROLLING:
            self._control(inputs.control, out)
        if self.state is State.RECOVERING:
            self._run_recovery(out)
        if self.state in (State.PLANNING, State.CONTROLLING) and self._plan_due():
            self._request_plan(out)
        if self.state in ACTIVE and out.cmd is None:
            out.cmd = ZERO
        if self.state is not None:
            out.statuses.append(self.status())
        return out

    def status(self) -> NavStatus:
        stamp_ns = round((self._now or 0.0) * 1e9)
        return NavStatus(Header(stamp_ns=stamp_ns, frame_id="map"), self.goal_id,
                         NAV_STATUS[self.state], self.reason, self._distance_remaining())

    # ---- goals ---------------------------------------------------------------------------
    def _accept(self, goal: Goal, out: NavActions) -> None:
        if self.state in ACTIVE:
            self._finish(State.CANCELED, f"preempted by goal {goal.goal_id!r}", out)
            out.statuses.append(self.status())
        self.goal_id = goal.goal_id
        self.reason = ""
        self.path = None
        self._outstanding = None
        self._tried.clear()
        self._trigger = None
        waypoints = np.asarray(goal.waypoints, dtype=float).reshape(-1, 3)
        self.targets = np.vstack([waypoints, [[goal.pose.x, goal.pose.y, goal.pose.theta]]])
        self.target_index = 0
        self.state = State.PENDING
        if goal.header.frame_id not in GOAL_FRAMES:
            self._finish(State.ABORTED, f"goal frame {goal.header.frame_id!r} is not 'map'", out)
        elif not np.all(np.isfinite(self.targets)):
            self._finish(State.ABORTED, "goal pose or waypoints are not finite", out)

    def _cancel(self, cancel: CancelGoal, out: NavActions) -> bool:
        # A cancel naming another goal (an old or unknown one) has nothing to stop.
        if self.state in ACTIVE and cancel.goal_id in ("", self.goal_id):
            self._finish(State.CANCELED, "canceled", out)
            return True
        return False

    def _finish(self, state: State, reason: str, out: NavActions) -> None:
        self.state = state
        self.reason = reason
        self._outstanding = None
        self._recovery = None
        out.cmd = ZERO

    def _begin_target(self) -> None:
        """Plan afresh towards targets[target_index]: a new goal or the next waypoint."""
        now = self._now
        self.state = State.PLANNING
        self.path = None
        self._outstanding = None
        self._want_plan = True
        self._last_valid_plan_s = self._last_valid_control_s = self._last_oscillation_reset_s = now
        self._oscillation_pose = self.pose.copy()
        self._planning_retries = 0
        self._last_failure = ""
        self._latch.reset()

    def _check_arrival(self, out: NavActions) -> None:
        self.reason = ""   # an active goal's only reason is the wait below, decided afresh each step
        while True:
            if not self._at_target():
                return
            if self.target_index < len(self.targets) - 1:
                self.target_index += 1
                self._tried.clear()
                self._begin_target()
                continue
            if self._stopped():
                doubt = self._doubt()
                if doubt:
                    self.reason = doubt
                else:
                    self._finish(State.SUCCEEDED, "", out)
            return

    def _target_miss(self) -> tuple[float, float]:
        """The robot's distance (m) and yaw error (rad) from the current target; a waypoint's yaw is
        not checked (0)."""
        target = self.targets[self.target_index]
        final = self.target_index == len(self.targets) - 1
        yaw_error = abs(float(wrap_angle(target[2] - self.pose[2]))) if final else 0.0
        return math.hypot(*(target[:2] - self.pose[:2])), yaw_error

    def _at_target(self) -> bool:
        distance, yaw_error = self._target_miss()
        if self.target_index < len(self.targets) - 1:
            return distance <= self.params.xy_goal_tolerance
        return self._latch.within(distance) and yaw_error <= self.params.yaw_goal_tolerance

    def _doubt(self) -> str:
        """Why the pose is not trusted now: the localizer's beam fit is too low, or the odometry fusion
        doubts its odometry; '' when neither."""
        if self.beam_fit is not None and self.beam_fit < self.params.min_pose_beam_fit:
            return WAITING_FOR_CONFIDENT_POSE
        return f"{WAITING_FOR_TRUSTED_ODOMETRY} ({self.odometry_doubt})" if self.odometry_doubt else ""

    def _stopped(self) -> bool:
        """As base_local_planner's goal check: at the goal only once the robot has (nearly) stopped,
        or it would coast past the tolerance on the commands still on their way to the wheels."""
        if self.velocity is None:
            return True
        p = self.params
        return (math.hypot(self.velocity[0], self.velocity[1]) <= p.trans_stopped_vel
                and abs(self.velocity[2]) <= p.rot_stopped_vel)

    # ---- planning ------------------------------------------------------------------------
    def _plan_due(self) -> bool:
        if self._want_plan:
            return True
        f = self.params.planner_frequency
        throttled = f > 0 and self._now < self._last_request_s + 1.0 / f
        if self.state is State.PLANNING:
            return self._outstanding is None and not throttled
        return f > 0 and not throttled

    def _request_plan(self, out: NavActions) -> None:
        request = PlanRequest(self._next_request_id, tuple(float(v) for v in self.pose),
                              tuple(float(v) for v in self.targets[self.target_index]))
        self._next_request_id += 1
        self._outstanding = request.request_id
        self._last_request_s = self._now
        self._want_plan = False
        out.plan_request = request

    def _take_plan(self, result: PlanResult | None, out: NavActions) -> None:
        if result is None or result.request_id != self._outstanding:
            return
        self._outstanding = None
        path = None if result.path is None else np.asarray(result.path, dtype=float).reshape(-1, 3)
        if result.ok and path is not None and len(path):
            self.path = path
            out.controller_plan = path
            self._last_valid_plan_s = self._now
            self._planning_retries = 0
            if self._trigger is Trigger.PLANNING:
                self._tried.clear()
            if self.state is State.PLANNING:
                # The local planner's answer in this same step was made without this plan.
                self.state = State.CONTROLLING
                self._fresh_plan = True
            return
        self._planning_retries += 1
        self._last_failure = result.reason or "empty plan"
        if self._last_failure.startswith(f"{PLAN_UNREACHABLE}:"):
            self._finish(State.ABORTED, f"goal unreachable: {self._last_failure[len(PLAN_UNREACHABLE) + 1:].strip()}", out)
            return
        p = self.params
        too_many = 0 <= p.max_planning_retries < self._planning_retries
        if too_many or self._now > self._last_valid_plan_s + p.planner_patience:
            self._recover(Trigger.PLANNING, out)

    # ---- controlling ---------------------------------------------------------------------
    def _track_motion(self) -> None:
        if math.hypot(*(self.pose[:2] - self._oscillation_pose[:2])) >= self.params.oscillation_distance:
            self._oscillation_pose = self.pose.copy()
            self._last_oscillation_reset_s = self._now
            if self._trigger is Trigger.OSCILLATION:
                self._tried.clear()

    def _control(self, result: ControlResult | None, out: NavActions) -> None:
        p = self.params
        now = self._now
        if p.oscillation_timeout > 0 and now > self._last_oscillation_reset_s + p.oscillation_timeout:
            self._recover(Trigger.OSCILLATION, out)
            return
        if self._fresh_plan:
            return
        if result is not None and result.ok and result.reason == GOAL_REACHED and not self._at_target():
            distance, yaw_error = self._target_miss()
            result = ControlResult(False, reason=f"the local planner reports {GOAL_REACHED} {distance:.3f} m and "
                                                 f"{yaw_error:.3f} rad from the target")
        if result is not None and result.ok:
            out.cmd = tuple(float(v) for v in result.cmd)
            self._last_valid_control_s = now
            if self._trigger is Trigger.CONTROLLING:
                self._tried.clear()
            return
        if result is not None:
            self._last_failure = result.reason or "no valid command"
        if now > self._last_valid_control_s + p.controller_patience:
            self._recover(Trigger.CONTROLLING, out)
        elif result is not None:
            self.state = State.PLANNING
            self._last_valid_plan_s = now
            self._planning_retries = 0
            self._want_plan = True

    # ---- recovering ----------------------------------------------------------------------
    def _recovery_order(self, trigger: Trigger) -> list[str]:
        """The configured behaviours (a name may come twice, as in ROS files) in the order they run for
        this trigger."""
        order = list(self.params.recovery_order)
        if self.params.recovery_by_cause:
            order.sort(key=RECOVERY_BY_TRIGGER[trigger].index)
        return order

    def _recover(self, trigger: Trigger, out: NavActions) -> None:
        self._trigger = trigger
        left = self._recovery_order(trigger)
        for name in self._tried:
            if name in left:
                left.remove(name)
        if not left:
            self._finish(State.ABORTED, self._abort_reason(trigger), out)
            return
        self._recovery = behaviour(left[0], self.params)
        self._tried.append(left[0])
        self._recovery_start_s = self._now
        self._outstanding = None
        self.state = State.RECOVERING
        out.recovery = self._recovery
        out.cmd = ZERO

    def _run_recovery(self, out: NavActions) -> None:
        cmd = self._recovery.command(self._now - self._recovery_start_s, self.period_s)
        if cmd is not None:
            out.cmd = cmd
            return
        # Done: give planning and control a fresh start, as move_base does after each behaviour.
        self._recovery = None
        self._begin_target()
        out.cmd = ZERO

    def _abort_reason(self, trigger: Trigger) -> str:
        p = self.params
        if trigger is Trigger.PLANNING:
            what = f"no valid plan within planner_patience {p.planner_patience:g} s"
        elif trigger is Trigger.CONTROLLING:
            what = f"no valid velocity command within controller_patience {p.controller_patience:g} s"
        else:
            what = (f"oscillating: moved less than oscillation_distance {p.oscillation_distance:g} m "
                    f"in oscillation_timeout {p.oscillation_timeout:g} s")
        if trigger is not Trigger.OSCILLATION and self._last_failure:
            what += f" ({self._last_failure})"
        tried = f"even after recovery behaviours {', '.join(self._tried)}" if self._tried else "recovery behaviours disabled"
        return f"{what}, {tried}"

    # ---- status --------------------------------------------------------------------------
    def _distance_remaining(self) -> float:
        """Along the plan from its vertex nearest the robot, then straight through the remaining
        waypoints; straight to the target while there is no plan. 0 once succeeded."""
        if self.state is State.SUCCEEDED:
            return 0.0
        if self.pose is None or not len(self.targets):
            return math.inf
        legs = float(np.sum(np.hypot(*np.diff(self.targets[self.target_index:, :2], axis=0).T)))
        if self.path is None:
            return math.hypot(*(self.targets[self.target_index, :2] - self.pose[:2])) + legs
        gaps = np.hypot(*(self.path[:, :2] - self.pose[:2]).T)
        nearest = int(np.argmin(gaps))
        along = float(np.sum(np.hypot(*np.diff(self.path[nearest:, :2], axis=0).T)))
        return float(gaps[nearest]) + along + legs
