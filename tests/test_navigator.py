"""The navigator core (move_base as a state machine) and its recovery behaviours, in closed loop
with a toy planner and a toy holonomic controller; no processes, no bus."""
import math

import numpy as np
import pytest

from omninav.schemas.messages import GOAL_REACHED, PLAN_UNREACHABLE, CancelGoal, Goal, Header, Pose2D
from omninav.services.navigator.core import (WAITING_FOR_CONFIDENT_POSE, WAITING_FOR_TRUSTED_ODOMETRY, ControlResult, Navigator, NavInputs,
                                             PlanResult, State)
from omninav.services.navigator.params import NavigatorParams
from omninav.services.navigator.recovery import back_up, behaviour, clear_costmaps, rotate, wait
from omninav.parameters.declare import ParamError
from omninav.geometry.se2 import integrate, relative, wrap_angle

DT = 0.05  # 20 Hz, controller_frequency's default


def goal(x, y, yaw, goal_id="g1", waypoints=(), frame="map"):
    return Goal(Header(frame_id=frame), goal_id, Pose2D(x, y, yaw), np.asarray(waypoints, dtype=float).reshape(-1, 3))


def straight_planner(request):
    start, end = np.array(request.start), np.array(request.goal)
    path = np.linspace(start, end, 20)
    path[:, 2] = end[2]
    return PlanResult(request.request_id, True, path)


def failing_planner(request):
    return PlanResult(request.request_id, False, reason="goal in a lethal cell")


def holonomic_controller(pose, path, turn=True):
    """Drive straight at the plan's end, at most 0.5 m/s and 1 rad/s."""
    if path is None:
        return ControlResult(False, reason="no plan")
    err = relative(pose, path[-1])
    v = err[:2] * 1.5
    v *= min(1.0, 0.5 / max(np.hypot(*v), 1e-12))
    wz = float(np.clip(1.5 * err[2], -1.0, 1.0)) if turn else 0.0
    return ControlResult(True, (float(v[0]), float(v[1]), wz))


class LatchedController:
    """A local planner that drives at its plan's end and, once within latch_m of it, answers
    goal_reached with zeros until it is given another plan (whatever the pose does meanwhile)."""

    def __init__(self, latch_m: float):
        self.latch_m, self.arrived_on = latch_m, None

    def __call__(self, pose, path):
        if path is not None and self.arrived_on is not path and math.hypot(*(path[-1, :2] - pose[:2])) <= self.latch_m:
            self.arrived_on = path
        if path is not None and self.arrived_on is path:
            return ControlResult(True, (0.0, 0.0, 0.0), GOAL_REACHED)
        return holonomic_controller(pose, path)


def run(nav, steps, planner=straight_planner, controller=holonomic_controller, events=None, start=(0, 0, 0),
        beam_fit=lambda k: None, jumps=None, odometry_doubt=lambda k: None):
    """Close the loop: the planner answers a request one step later, the controller answers every
    step from the pose the last command produced; beam_fit(k) is the localizer's news at step k and
    jumps[k] an offset (x, y, yaw) the pose takes before step k (a shove, or a corrected pose).
    Returns (log of actions, poses)."""
    events, jumps = events or {}, jumps or {}
    pose = np.array(start, dtype=float)
    path, plan, control = None, None, None
    log, poses = [], []
    for k in range(steps):
        pose = pose + jumps.get(k, 0.0)
        g, c = events.get(k, (None, None))
        act = nav.step(k * DT, NavInputs(pose=pose, plan=plan, control=control, goal=g, cancel=c,
                                         beam_fit=beam_fit(k), odometry_doubt=odometry_doubt(k)))
        log.append(act)
        plan = planner(act.plan_request) if act.plan_request else None
        if act.controller_plan is not None:
            path = act.controller_plan
        if act.cmd is not None:
            pose = integrate(pose, act.cmd, DT)
        poses.append(pose)
        control = controller(pose, path)
    return log, poses


def current_status(log):
    return [a.statuses[-1].status for a in log if a.statuses]


def recoveries(log):
    return [(i, a.recovery.name) for i, a in enumerate(log) if a.recovery is not None]


def test_defaults_are_move_base_and_base_local_planner():
    p = NavigatorParams()
    assert (p.planner_frequency, p.controller_frequency, p.planner_patience, p.controller_patience) == (0.0, 20.0, 5.0, 15.0)
    assert (p.oscillation_timeout, p.oscillation_distance, p.conservative_reset_dist) == (0.0, 0.5, 3.0)
    assert (p.max_planning_retries, p.xy_goal_tolerance, p.yaw_goal_tolerance, p.escape_vel) == (-1, 0.10, 0.05, -0.1)
    assert p.recovery_order == ("clear_costmaps", "rotate", "back_up", "wait")
    assert NavigatorParams(clearing_rotation_allowed=False).recovery_order == ("clear_costmaps", "back_up", "wait")
    loaded = NavigatorParams.from_mapping({"planner_patience": 2, "recovery_behaviors": ["wait", "back_up"],
                                           "shutdown_costmaps": True})
    assert loaded.planner_patience == 2.0 and loaded.recovery_behaviors == ("wait", "back_up")
    with pytest.raises(ParamError, match="spin"):
        NavigatorParams.from_mapping({"recovery_behaviors": ["spin"]})
    with pytest.raises(ParamError, match="planner_patiense"):
        NavigatorParams.from_mapping({"planner_patiense": 1.0})


def test_happy_path_reaches_goal_within_tolerances_then_stops():
    nav = Navigator()
    log, poses = run(nav, 400, events={0: (goal(2.0, 1.0, math.pi / 2), None)})
    assert log[0].plan_request is not None and log[0].plan_request.goal == (2.0, 1.0, math.pi / 2)
    assert log[1].controller_plan is not None
    statuses = current_status(log)
    assert statuses[0] == "active" and statuses[-1] == "succeeded"
    end = statuses.index("succeeded")
    assert log[end].cmd == (0.0, 0.0, 0.0)
    assert all(a.cmd is None for a in log[end + 1:])
    final = poses[end]
    assert math.hypot(final[0] - 2.0, final[1] - 1.0) <= 0.10
    assert abs(wrap_angle(final[2] - math.pi / 2)) <= 0.05
    distances = [a.statuses[-1].distance_remaining for a in log[:end]]
    assert distances[0] == pytest.approx(math.hypot(2.0, 1.0))
    assert distances[end // 2] < distances[0] and log[end].statuses[-1].distance_remaining == 0.0
    assert not recoveries(log)


def test_no_success_on_a_pose_the_localizer_doubts():
    # the scans stop fitting the map at step 20 (a shove) and fit again from step 300 (recovered)
    def fit(k):
        return 0.95 if k < 20 else 0.2 if k < 300 else 0.9 if k % 10 == 0 else None
    nav = Navigator()
    log, poses = run(nav, 400, events={0: (goal(2.0, 1.0, 0.0), None)}, beam_fit=fit)
    statuses = current_status(log)
    arrived = next(k for k, p in enumerate(poses) if math.hypot(p[0] - 2.0, p[1] - 1.0) <= 0.1)
    assert arrived < 250                                       # long before the pose is trusted again
    assert statuses.index("succeeded") == 300
    waiting = [a.statuses[-1].reason for a in log[arrived + 5:300]]
    assert set(waiting) == {WAITING_FOR_CONFIDENT_POSE} and set(statuses[:300]) == {"active"}
    assert log[299].cmd is not None and not recoveries(log)
    # off, or without a localizer's beam fit at all, the goal succeeds as move_base's would
    for params, news in ((NavigatorParams(min_pose_beam_fit=0.0), fit), (NavigatorParams(), lambda k: None)):
        assert "succeeded" in current_status(run(Navigator(params), 300, events={0: (goal(2.0, 1.0, 0.0), None)},
                                                 beam_fit=news)[0])


def test_no_success_while_the_odometry_fusion_doubts_its_odometry():
    """Issue 36: wheels, gyro and scans disagree (a push) from step 20 to 300: the goal waits, naming why."""
    def doubt(k):
        return None if k < 20 and k % 10 else "" if k < 20 else "wheels vs scans 0.52 m" if k < 300 else \
            "" if k % 10 == 0 else None
    log, poses = run(Navigator(), 400, events={0: (goal(2.0, 1.0, 0.0), None)}, odometry_doubt=doubt)
    statuses = current_status(log)
    arrived = next(k for k, p in enumerate(poses) if math.hypot(p[0] - 2.0, p[1] - 1.0) <= 0.1)
    assert arrived < 250 and statuses.index("succeeded") == 300 and set(statuses[:300]) == {"active"}
    waiting = {a.statuses[-1].reason for a in log[arrived + 5:300]}
    assert waiting == {f"{WAITING_FOR_TRUSTED_ODOMETRY} (wheels vs scans 0.52 m)"} and not recoveries(log)
    # a fusion that never doubts, or none at all, lets the goal succeed on arrival
    for news in (lambda k: "", lambda k: None):
        first = current_status(run(Navigator(), 300, events={0: (goal(2.0, 1.0, 0.0), None)}, odometry_doubt=news)[0])
        assert first.index("succeeded") <= arrived + 5


def test_a_plan_is_made_afresh_when_the_doubted_pose_is_trusted_again():
    nav = Navigator()
    request = nav.step(0.0, NavInputs(pose=(0, 0, 0), goal=goal(5.0, 0.0, 0.0), beam_fit=0.9)).plan_request
    nav.step(2 * DT, NavInputs(pose=(0, 0, 0), plan=straight_planner(request)))
    assert nav.state is State.CONTROLLING
    steps = [nav.step((3 + k) * DT, NavInputs(pose=(0.1, 0, 0), beam_fit=fit)) for k, fit in
             enumerate([0.2, None, 0.3, 0.8, 0.9])]
    assert [a.plan_request is not None for a in steps] == [False, False, False, True, False]


def test_cancel_stops_the_robot_and_ignores_other_ids():
    nav = Navigator()
    events = {0: (goal(5.0, 0.0, 0.0), None), 10: (None, CancelGoal(goal_id="someone-else")),
              20: (None, CancelGoal(goal_id=""))}
    log, poses = run(nav, 40, events=events)
    assert log[10].statuses[-1].status == "active" and log[10].cmd != (0.0, 0.0, 0.0)
    assert log[20].statuses[-1].status == "canceled" and log[20].cmd == (0.0, 0.0, 0.0)
    assert all(a.cmd is None and a.plan_request is None for a in log[21:])
    assert poses[-1][0] < 5.0 - 0.1


def test_new_goal_preempts_and_stale_plan_answers_are_ignored():
    nav = Navigator()
    a = nav.step(0.0, NavInputs(pose=(0, 0, 0), goal=goal(3.0, 0.0, 0.0, "A")))
    old_request = a.plan_request
    b = nav.step(DT, NavInputs(pose=(0, 0, 0), goal=goal(0.0, 2.0, 0.0, "B")))
    assert [(s.goal_id, s.status) for s in b.statuses] == [("A", "canceled"), ("B", "active")]
    assert b.statuses[0].reason == "preempted by goal 'B'"
    assert b.plan_request.goal == (0.0, 2.0, 0.0)
    stale = nav.step(2 * DT, NavInputs(pose=(0, 0, 0), plan=straight_planner(old_request)))
    assert stale.controller_plan is None and nav.state is State.PLANNING
    fresh = nav.step(3 * DT, NavInputs(pose=(0, 0, 0), plan=straight_planner(b.plan_request)))
    assert fresh.controller_plan[-1][1] == 2.0 and nav.state is State.CONTROLLING


def test_cancel_and_new_goal_in_one_step_report_both():
    nav = Navigator()
    nav.step(0.0, NavInputs(pose=(0, 0, 0), goal=goal(3.0, 0.0, 0.0, "A")))
    act = nav.step(DT, NavInputs(pose=(0, 0, 0), cancel=CancelGoal(goal_id="A"), goal=goal(1, 1, 0, "B")))
    assert [(s.goal_id, s.status, s.reason) for s in act.statuses] == [("A", "canceled", "canceled"), ("B", "active", "")]


def test_planner_failure_runs_recoveries_in_order_then_aborts_with_reason():
    nav = Navigator()
    log, poses = run(nav, 900, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    rec = recoveries(log)
    # no plan: clear the marks, wait for whoever stands in the way, look round, then back off
    assert [name for _, name in rec] == ["clear_costmaps", "wait", "rotate", "back_up"]
    first = rec[0][0]
    assert 5.0 < first * DT <= 5.0 + 2 * DT          # planner_patience
    assert log[first].recovery.reset_distance == 3.0  # conservative_reset_dist
    # After each behaviour, planning starts again and gets another planner_patience.
    assert all(b - a > 5.0 / DT for (a, _), (b, _) in zip(rec, rec[1:]))
    statuses = current_status(log)
    end = statuses.index("aborted")
    reason = log[end].statuses[-1].reason
    assert "no valid plan" in reason and "goal in a lethal cell" in reason
    assert "clear_costmaps, wait, rotate, back_up" in reason
    assert log[end].cmd == (0.0, 0.0, 0.0) and all(a.cmd is None for a in log[end + 1:])
    # The failing planner was asked again and again while PLANNING (planner_frequency 0: every step).
    assert sum(a.plan_request is not None for a in log[:first]) > 50


def test_configured_order_disabled_recovery_and_retry_limit():
    # move_base's way: the configured list in its order, whatever the cause
    nav = Navigator(NavigatorParams(recovery_behaviors=("wait", "clear_costmaps"), wait_duration=0.5,
                                    recovery_by_cause=False))
    log, _ = run(nav, 400, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    assert [name for _, name in recoveries(log)] == ["wait", "clear_costmaps"]
    assert current_status(log)[-1] == "aborted"
    # by cause, only the configured behaviours run (and each once), reordered for a planning failure
    nav = Navigator(NavigatorParams(recovery_behaviors=("back_up", "wait", "clear_costmaps"), wait_duration=0.5))
    log, _ = run(nav, 600, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    assert [name for _, name in recoveries(log)] == ["clear_costmaps", "wait", "back_up"]
    assert current_status(log)[-1] == "aborted"

    nav = Navigator(NavigatorParams(recovery_behavior_enabled=False))
    log, _ = run(nav, 200, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    assert not recoveries(log)
    end = current_status(log).index("aborted")
    assert 5.0 < end * DT <= 5.0 + 2 * DT and "recovery behaviours disabled" in log[end].statuses[-1].reason

    nav = Navigator(NavigatorParams(max_planning_retries=2))
    log, _ = run(nav, 20, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    (first, name), *_ = recoveries(log)
    requests_before = sum(a.plan_request is not None for a in log[:first])
    assert name == "clear_costmaps" and requests_before == 3   # the third failure exceeds 2 retries


def test_a_goal_unreachable_on_the_map_is_aborted_at_once_with_the_reason():
    def walled_off(request):
        return PlanResult(request.request_id, False,
                          reason=f"{PLAN_UNREACHABLE}: the goal (2.00, 0.00) lies in a part of the map no way "
                                 "through free cells joins to the robot's (0.00, 0.00) (no_path: ...)")

    log, poses = run(Navigator(), 100, planner=walled_off, events={0: (goal(2.0, 0.0, 0.0), None)})
    statuses = current_status(log)
    end = statuses.index("aborted")
    assert end <= 2 and not recoveries(log)              # the first answer ends it: no recovery changes a map
    reason = log[end].statuses[-1].reason
    assert reason.startswith("goal unreachable: the goal (2.00, 0.00) lies in a part of the map")
    assert np.allclose(poses[-1], 0.0)


def test_the_final_position_is_latched_while_the_robot_turns_to_the_goal_yaw_within_a_slack():
    """A turn on the spot moves the centre a little (a skid steer slips, the pose jitters): the
    position once reached stays reached while it turns, up to twice the tolerance, not beyond."""
    def drifting_turn(pose, path, drift):
        if path is None:
            return ControlResult(True)
        error = wrap_angle(path[-1, 2] - pose[2])
        if math.hypot(*(path[-1, :2] - pose[:2])) > 0.01 and abs(error) > 0.5:
            return holonomic_controller(pose, path, turn=False)
        if abs(error) <= 0.01:
            return ControlResult(True, reason=GOAL_REACHED)
        return ControlResult(True, (drift, 0.0, math.copysign(0.5, error)))   # sideways creep while turning

    for drift, latch, ends in ((0.04, True, "succeeded"), (0.04, False, "active"), (0.06, True, "active")):
        nav = Navigator(NavigatorParams(xy_goal_tolerance=0.03, latch_xy_goal_tolerance=latch,
                                        controller_patience=60.0))
        log, poses = run(nav, 300, controller=lambda pose, path: drifting_turn(pose, path, drift),
                         events={0: (goal(1.0, 0.0, math.pi / 2), None)})
        assert current_status(log)[-1] == ends, (drift, latch)
        if ends == "succeeded":   # it left the tolerance while turning, and stayed within the slack
            misses = [math.hypot(x - 1.0, y) for x, y, _ in poses[:current_status(log).index("succeeded")]]
            assert max(misses[-40:]) > 0.03 and misses[-1] <= 0.06


def test_controller_failure_replans_then_recovers_then_aborts():
    params = NavigatorParams(controller_patience=2.0)
    nav = Navigator(params)

    def stuck(pose, path):
        return ControlResult(False, reason="no valid trajectory")

    log, _ = run(nav, 1200, controller=stuck, events={0: (goal(2.0, 0.0, 0.0), None)})
    rec = recoveries(log)
    # no valid command: clear the marks, then back off to get room to turn
    assert [name for _, name in rec] == ["clear_costmaps", "back_up", "rotate", "wait"]
    assert 2.0 < rec[0][0] * DT <= 2.0 + 4 * DT
    # Within the patience, each failure stops the robot and asks for a new plan.
    assert sum(a.plan_request is not None for a in log[:rec[0][0]]) > 5
    assert all(a.cmd == (0.0, 0.0, 0.0) for a in log[:rec[0][0]])
    statuses = current_status(log)
    reason = log[statuses.index("aborted")].statuses[-1].reason
    assert "no valid velocity command" in reason and "no valid trajectory" in reason


def test_oscillation_triggers_recovery_only_when_enabled():
    def dither(pose, path):
        return ControlResult(True, (0.4 if round(pose[0] * 1000) <= 0 else -0.4, 0.0, 0.0))

    nav = Navigator(NavigatorParams(oscillation_timeout=3.0, oscillation_distance=0.5))
    log, _ = run(nav, 1000, controller=dither, events={0: (goal(2.0, 0.0, 0.0), None)})
    rec = recoveries(log)
    # valid commands and no progress: move_base's order
    assert [name for _, name in rec] == ["clear_costmaps", "rotate", "back_up", "wait"]
    assert 3.0 < rec[0][0] * DT <= 3.0 + 3 * DT
    statuses = current_status(log)
    assert "oscillating" in log[statuses.index("aborted")].statuses[-1].reason

    nav = Navigator()  # oscillation_timeout 0: off
    log, _ = run(nav, 400, controller=dither, events={0: (goal(2.0, 0.0, 0.0), None)})
    assert not recoveries(log) and current_status(log)[-1] == "active"


def test_recovery_that_fixes_planning_returns_to_controlling():
    nav = Navigator()

    def flaky(request):  # fails until a costmap clear has happened, as if an old obstacle blocked the way
        return straight_planner(request) if len(recovered) else failing_planner(request)

    recovered = []
    events = {0: (goal(2.0, 0.0, 0.0), None)}
    pose = np.zeros(3)
    path = plan = control = None
    states = []
    for k in range(400):
        g, _ = events.get(k, (None, None))
        act = nav.step(k * DT, NavInputs(pose=pose, plan=plan, control=control, goal=g))
        if act.recovery is not None:
            recovered.append(act.recovery.name)
            after = k
        states.append(nav.state)
        plan = flaky(act.plan_request) if act.plan_request else None
        if act.controller_plan is not None:
            path = act.controller_plan
        if act.cmd is not None:
            pose = integrate(pose, act.cmd, DT)
        control = holonomic_controller(pose, path)
    assert recovered == ["clear_costmaps"]
    assert State.CONTROLLING in states[after:] and states[-1] is State.SUCCEEDED


def test_recovery_that_fixes_control_returns_to_controlling():
    nav = Navigator(NavigatorParams(controller_patience=1.0))
    seen = []

    def stuck_until_rotated(pose, path):
        if abs(pose[2]) < 1e-6 and not seen:
            return ControlResult(False, reason="no valid trajectory")
        seen.append(True)
        return holonomic_controller(pose, path)

    log, poses = run(nav, 800, controller=stuck_until_rotated, events={0: (goal(2.0, 0.0, 0.0), None)})
    # clear_costmaps and back_up leave the robot facing the same way; rotate turns it, and the
    # controller recovers
    assert [name for _, name in recoveries(log)] == ["clear_costmaps", "back_up", "rotate"]
    assert current_status(log)[-1] == "succeeded"


def test_waypoints_visited_in_order_without_yaw_check():
    nav = Navigator()
    waypoints = [(1.0, 0.0, 2.0), (1.0, 1.0, -2.0)]   # yaws the robot never turns to
    log, poses = run(nav, 600, controller=lambda p, path: holonomic_controller(p, path, turn=False),
                     events={0: (goal(0.0, 1.0, 0.0, waypoints=waypoints), None)})
    assert log[0].statuses[-1].distance_remaining == pytest.approx(3.0)
    targets = [a.plan_request.goal for a in log if a.plan_request is not None]
    assert targets == [(1.0, 0.0, 2.0), (1.0, 1.0, -2.0), (0.0, 1.0, 0.0)]
    # Each target passed within xy_goal_tolerance, in order.
    visits = [next(i for i, p in enumerate(poses) if math.hypot(p[0] - x, p[1] - y) <= 0.10) for x, y, _ in targets]
    assert visits == sorted(visits)
    assert current_status(log)[-1] == "succeeded"


def test_same_inputs_same_outputs():
    def transcript():
        nav = Navigator(NavigatorParams(planner_frequency=1.0, controller_patience=1.0))
        flaky_count = iter(range(10_000))

        def sometimes(request):
            return failing_planner(request) if next(flaky_count) % 3 == 0 else straight_planner(request)

        log, poses = run(nav, 300, planner=sometimes, events={0: (goal(2.0, -1.0, 1.0, waypoints=[(1, 1, 0)]), None),
                                                              150: (goal(-1.0, 0.5, 0.0, "g2"), None)})
        return [(a.plan_request, a.cmd, a.recovery, [(s.goal_id, s.status, s.reason, s.distance_remaining)
                                                     for s in a.statuses]) for a in log], [tuple(p) for p in poses]

    assert transcript() == transcript()


def test_bad_goals_and_time_going_backwards():
    nav = Navigator()
    act = nav.step(0.0, NavInputs(pose=(0, 0, 0), goal=goal(1, 1, 0, frame="odom")))
    assert act.statuses[-1].status == "aborted" and "'odom'" in act.statuses[-1].reason
    act = nav.step(0.1, NavInputs(goal=goal(float("nan"), 1, 0)))
    assert act.statuses[-1].status == "aborted" and "not finite" in act.statuses[-1].reason
    with pytest.raises(ValueError, match="earlier"):
        nav.step(0.05, NavInputs())


def test_pending_until_a_pose_arrives():
    nav = Navigator()
    act = nav.step(0.0, NavInputs(goal=goal(1, 0, 0)))
    assert act.statuses[-1].status == "pending" and act.plan_request is None and act.cmd == (0.0, 0.0, 0.0)
    act = nav.step(DT, NavInputs(pose=(0, 0, 0)))
    assert act.statuses[-1].status == "active" and act.plan_request.start == (0.0, 0.0, 0.0)


def drive(b, period=DT):
    cmds = []
    while (cmd := b.command(len(cmds) * period, period)) is not None:
        cmds.append(cmd)
    return np.array(cmds).reshape(-1, 3)


@pytest.mark.parametrize("angle, speed", [(2 * math.pi, 1.0), (-math.pi / 2, 0.7), (0.3, 2.0)])
def test_rotate_turns_exactly_the_angle(angle, speed):
    cmds = drive(rotate(angle, speed))
    assert len(cmds) == math.ceil(abs(angle) / speed / DT - 1e-9)
    assert np.all(cmds[:, :2] == 0) and np.all(np.sign(cmds[:, 2]) == np.sign(angle))
    assert np.all(np.abs(cmds[:, 2]) <= speed)
    assert cmds[:, 2].sum() * DT == pytest.approx(angle)


def test_back_up_and_wait_and_clear():
    cmds = drive(back_up(0.15, -0.1))
    assert len(cmds) == 30 and np.all(cmds[:, 0] == pytest.approx(-0.1)) and np.all(cmds[:, 1:] == 0)
    assert cmds[:, 0].sum() * DT == pytest.approx(-0.15)
    cmds = drive(wait(1.0))
    assert len(cmds) == 20 and np.all(cmds == 0)
    assert drive(clear_costmaps(3.0)).size == 0 and clear_costmaps(3.0).reset_distance == 3.0
    p = NavigatorParams(backup_dist=0.3, escape_vel=-0.2, rotate_angle=1.0, max_rotational_vel=0.5)
    assert behaviour("back_up", p).twist == (-0.2, 0.0, 0.0) and behaviour("back_up", p).duration_s == pytest.approx(1.5)
    assert behaviour("rotate", p).duration_s == pytest.approx(2.0)


def test_navigator_drives_recovery_motions_for_their_sim_duration():
    # Only back_up configured: the robot backs up backup_dist at escape_vel, then plans again.
    nav = Navigator(NavigatorParams(recovery_behaviors=("back_up",), backup_dist=0.2))
    log, poses = run(nav, 200, planner=failing_planner, events={0: (goal(2.0, 0.0, 0.0), None)})
    (first, _), = recoveries(log)
    backing = [a.cmd for a in log[first:] if a.cmd is not None and a.cmd[0] < 0]
    assert len(backing) == 40 and sum(c[0] for c in backing) * DT == pytest.approx(-0.2)   # 0.2 m at 0.1 m/s
    assert poses[first + 45][0] == pytest.approx(-0.2)
    assert log[first + 40].plan_request is not None   # planning resumes right after


def test_the_final_pose_counts_only_once_the_robot_has_stopped():
    nav = Navigator(NavigatorParams(rot_stopped_vel=0.1))
    nav.step(0.0, NavInputs(goal=goal(0, 0, 0), pose=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.5)))
    assert nav.state is not State.SUCCEEDED          # at the pose, but still turning at 0.5 rad/s
    act = nav.step(DT, NavInputs(pose=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.05)))
    assert nav.state is State.SUCCEEDED and act.statuses[-1].status == "succeeded"


def test_a_pose_corrected_off_the_goal_after_the_local_planner_arrived_is_approached_again():
    # the pipeline's stall in small: the local planner answered goal_reached, the localizer then put the
    # doubted pose 6 cm off the goal, and the local planner went on answering goal_reached there
    nav = Navigator(NavigatorParams(xy_goal_tolerance=0.03))
    log, poses = run(nav, 300, controller=LatchedController(0.02), events={0: (goal(2.0, 0.0, 0.0), None)},
                     beam_fit=lambda k: 0.2, jumps={150: (0.0, 0.06, 0.0)})
    assert log[149].statuses[-1].reason == WAITING_FOR_CONFIDENT_POSE
    assert log[150].plan_request is not None and log[150].plan_request.start[1] == pytest.approx(0.06, abs=0.02)
    assert not recoveries(log) and set(current_status(log)) == {"active"}
    assert log[-1].statuses[-1].reason == WAITING_FOR_CONFIDENT_POSE
    assert math.hypot(poses[-1][0] - 2.0, poses[-1][1]) <= 0.03


def test_a_local_planner_that_stops_short_of_the_tolerance_replans_then_recovers_then_aborts():
    # its goal_reached 8 cm from the goal, where the navigator wants 3 cm: the robot does not stand for good
    params = NavigatorParams(xy_goal_tolerance=0.03, controller_patience=2.0, recovery_behaviors=("clear_costmaps",))
    log, poses = run(Navigator(params), 600, controller=LatchedController(0.08), events={0: (goal(2.0, 0.0, 0.0), None)})
    statuses = current_status(log)
    end = statuses.index("aborted")
    reached = next(k for k, a in enumerate(log) if a.cmd is not None and math.hypot(poses[k][0] - 2.0, poses[k][1]) <= 0.08)
    assert [name for _, name in recoveries(log)] == ["clear_costmaps"]
    assert sum(a.plan_request is not None for a in log[reached:end]) > 2     # stopped and replanned meanwhile
    assert end * DT <= reached * DT + 2 * params.controller_patience + 1.0
    reason = log[end].statuses[-1].reason
    assert "no valid velocity command" in reason and GOAL_REACHED in reason and "0.08" in reason
