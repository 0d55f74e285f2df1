"""What a navigation mission achieved, from its recording and its world: the figures `omninav
navigate` prints and `omninav bench missions` tabulates.

`load_mission` reads what the summary needs from a recording (the ground truth, the movers, the
goals sent, nav_status, the global plans and the sim's last Diagnostic); `summarize_mission` is
pure and computes:

- per goal: its last status (nav_status), the sim time from sending it to that status, the length
  of its first global plan (the first non-empty plan whose goal_id is "<goal_id>#…") and the pose
  error against the goal: at the status's stamp, or for the last goal where the robot came to
  rest (the last ground truth recorded);
- for the mission: time_s from the first goal sent to the last goal's end (or the last truth),
  path_length_m of the true trajectory over that span, min_clearance_m between the footprint and
  static obstacles and movers along it, and the collisions the sim counted (its contact starts;
  sim/physics.py), split into the robot's fault and the movers' (a mover drove into a robot
  standing still or moving away);
- per goal, within_1m_s: the sim s from sending it until the robot's true position first came
  within WITHIN_M of it (None if it never did) — how long the way took, apart from the final approach.

A goal is reached when the navigator said succeeded and the truth agrees: when it said so the robot
stood within the navigator's xy_goal_tolerance + FALSE_SUCCESS_MARGIN_M of the goal. A navigator
misled by its pose (a shove, a slip, a localizer settled on a wrong pose) can declare a goal reached
metres away from it; that is a false success, not a reached goal, and it fails the mission.

success: every requested goal reached and no contact of any kind (BARN's rule): the robot's and
the movers' shares (sim/contacts.py) and the seconds in contact are reported beside it; a
recording without the sim's counts is no success.

restarts: per service named to load_mission, how many times it was restarted during the mission:
the distinct runs (run_started_ns) its Diagnostics came from, minus one. A run that died before
its first Diagnostic (published a second after it starts) is not seen.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..schemas import MessageError, decode
from ..schemas.keys import DEFAULT_ROBOT, KeyLayout, type_for_key
from ..schemas.messages import Goal, NavStatus, Path as PathMsg
from ..services.navigator.params import NavigatorParams
from ..sim.world import World
from ..geometry.polygons import point_segment_distance, points_in_polygons, transform_points
from ..services.recorder.mcap_io import RecordingError, read_records
from ..services.runtime.errors import UserError
from ..services.runtime.live import RUN_STARTED
from ..services.runtime.node import NS_PER_S
from ..geometry.se2 import wrap_angle

TERMINAL = ("succeeded", "aborted", "canceled")
CLEARANCE_CHUNK = 2048      # poses per vectorised clearance computation (bounds the temporaries)
WITHIN_M = 1.0              # the radius of a goal's within_1m_s
# a goal said succeeded while the truth stood farther than the navigator's xy_goal_tolerance plus this
# was a false success (issue 36: the tolerance + 5 cm)
FALSE_SUCCESS_MARGIN_M = 0.05
FAR = 1.0e6             # m: where a moment with fewer movers puts the ones it lacks


class MissionError(UserError):
    """A recording that does not hold a mission (no ground truth, unreadable)."""


@dataclass
class MissionRecord:
    """What a recording says about a mission; every list in stamp order."""
    truth_stamps: np.ndarray                    # (N,) ns
    truth_poses: np.ndarray                     # (N, 3) world = map frame
    mover_stamps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    mover_circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))   # (T, K, 3)
    goals: list[Goal] = field(default_factory=list)
    statuses: list[NavStatus] = field(default_factory=list)
    plans: list[PathMsg] = field(default_factory=list)
    sim_values: dict = field(default_factory=dict)      # the sim's last Diagnostic values
    restarts: dict[str, int] = field(default_factory=dict)   # service -> times restarted


@dataclass(frozen=True)
class GoalOutcome:
    goal_id: str
    goal: tuple[float, float, float]
    status: str                     # the last nav_status, "none" if the navigator never answered
    reason: str
    time_s: float                   # sim s from sending the goal to its last status
    xy_error_m: float
    yaw_error_deg: float
    plan_length_m: float | None     # the first global plan's length
    within_1m_s: float | None       # sim s from sending it until the robot first came within WITHIN_M
    false_success: bool = False     # said succeeded while the truth stood beyond the tolerance + margin

    @property
    def reached(self) -> bool:
        """Succeeded, and the truth agreed when it was said (not a false success)."""
        return self.status == "succeeded" and not self.false_success


@dataclass(frozen=True)
class MissionSummary:
    success: bool
    goals_reached: int
    goals_total: int
    time_s: float
    path_length_m: float
    plan_length_m: float | None     # the first global plans of the goals sent, summed
    final_xy_error_m: float | None
    final_yaw_error_deg: float | None
    collisions: int | None          # contacts begun; None: the recording holds no sim Diagnostic
    robot_fault_collisions: int | None   # contacts with a substep of the robot's (it moved towards it, or stayed in a way it saw coming)
    mover_fault_collisions: int | None   # contacts all the movers' (one walked into a robot standing or leaving)
    shoved_collisions: int | None        # static contacts begun while a mover touched the robot
    min_clearance_m: float
    min_mover_clearance_m: float | None     # the closest the footprint came to a mover; None: no movers
    recording: str
    goals: list[GoalOutcome]
    restarts: dict[str, int] = field(default_factory=dict)   # service -> times restarted (only those that were)
    contact_s: float | None = None          # s in contact with anything (None: a sim from before it was counted)
    robot_contact_s: float | None = None    # s of that the robot's
    false_successes: int = 0                # goals said succeeded the truth did not reach

    def to_json(self) -> dict:
        mapping = asdict(self)
        for outcome, goal in zip(mapping["goals"], self.goals):
            outcome["reached"] = goal.reached
        return mapping


# ---------------------------------------------------------------- reading a recording

def mission_keys(robot: str = DEFAULT_ROBOT) -> dict[str, str]:
    """The keys a mission summary reads -> the MissionRecord part each fills."""
    keys = KeyLayout(robot)
    return {keys.sim_robot("truth"): "truth", keys.sim("movers"): "movers", keys.robot("goal"): "goals",
            keys.robot("nav_status"): "statuses", keys.robot("plan"): "plans", keys.diagnostics("sim"): "sim"}


class MissionCollector:
    """Gathers what a mission summary needs from (key, payload) pairs, in any order: the messages
    of a recording, or of an in-process run as they are published."""

    def __init__(self, robot: str = DEFAULT_ROBOT, services: tuple[str, ...] = ()):
        self.robot = robot
        self.wanted = mission_keys(robot)
        self.found: dict[str, list] = {name: [] for name in self.wanted.values()}
        self.diagnostics = {KeyLayout(robot).diagnostics(name): name for name in services}
        self.runs: dict[str, set[int]] = {name: set() for name in services}

    @property
    def keys(self) -> list[str]:
        """Every key this collector reads."""
        return [*self.wanted, *self.diagnostics]

    def add(self, key: str, payload: bytes) -> None:
        if key in self.diagnostics or key in self.wanted:
            try:
                msg = decode(payload, type_for_key(key), key=key)
            except MessageError:
                return      # a malformed message counts as not sent
            self.add_message(key, msg)

    def add_message(self, key: str, msg) -> None:
        """As add, for a message already decoded (kept: it must not change afterwards)."""
        service = self.diagnostics.get(key)
        if service is not None:
            run = msg.values.get(RUN_STARTED)
            if isinstance(run, int):
                self.runs[service].add(run)
        part = self.wanted.get(key)
        if part is not None:
            self.found[part].append(msg)

    def record(self, source: str) -> MissionRecord:
        """The MissionRecord (MissionError naming `source` if it holds no ground truth)."""
        found = {name: sorted(messages, key=lambda m: (m.header.stamp_ns, m.header.seq))
                 for name, messages in self.found.items()}
        truth = found["truth"]
        if not truth:
            raise MissionError(f"{source}: no ground truth ({KeyLayout(self.robot).sim_robot('truth')}): "
                               "was the sim recorded?")
        record = MissionRecord(np.array([m.header.stamp_ns for m in truth], np.int64),
                               np.array([(m.pose.x, m.pose.y, m.pose.theta) for m in truth], np.float64),
                               goals=found["goals"], statuses=found["statuses"], plans=found["plans"],
                               sim_values=dict(found["sim"][-1].values) if found["sim"] else {},
                               restarts={name: len(runs) - 1 for name, runs in self.runs.items() if len(runs) > 1})
        movers = found["movers"]
        count = max((len(m.circles) for m in movers), default=0)
        if count:
            # people come and go: every moment padded to the most there were, with circles of
            # radius 0 far away (nothing comes near them)
            circles = np.tile(np.array([FAR, FAR, 0.0]), (len(movers), count, 1))
            for row, m in zip(circles, movers):
                row[:len(m.circles)] = m.circles
            record.mover_stamps = np.array([m.header.stamp_ns for m in movers], np.int64)
            record.mover_circles = circles
        return record


def load_mission(path: str | Path, robot: str = DEFAULT_ROBOT, services: tuple[str, ...] = ()) -> MissionRecord:
    """The mission's messages from a recording (MissionError if unreadable or without truth); the
    restarts of `services` (names) from their Diagnostics."""
    path, collector = Path(path), MissionCollector(robot, services)
    try:
        for rec in read_records(path, collector.keys):
            collector.add(rec.key, rec.payload)
    except RecordingError as exc:
        raise MissionError(str(exc)) from None
    return collector.record(str(path))


# ---------------------------------------------------------------- the figures

def path_length(poses: np.ndarray) -> float:
    return float(np.hypot(*np.diff(poses[:, :2], axis=0).T).sum()) if len(poses) > 1 else 0.0


def movers_clearance(footprint: np.ndarray, poses: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Distance (Q,) between the footprint at each pose (Q, 3) and that moment's movers (Q, K, 3);
    0 when they overlap, inf without movers."""
    if circles.shape[1] == 0:
        return np.full(len(poses), np.inf)
    poly = transform_points(footprint, poses)                            # (Q, P, 2)
    a, b = poly[:, :, None, :], np.roll(poly, -1, axis=1)[:, :, None, :]
    centres = circles[:, None, :, :2]                                     # (Q, 1, K, 2)
    gap = np.maximum(point_segment_distance(centres, a, b).min(axis=1) - circles[:, :, 2], 0.0)   # (Q, K)
    gap[points_in_polygons(circles[:, :, :2], poly[:, None])[..., 0]] = 0.0
    return gap.min(axis=1)


def clearance_along(world: World, poses: np.ndarray, mover_circles: np.ndarray) -> tuple[float, float]:
    """The smallest distances between the footprint and (any obstacle or mover, a mover) along a
    trajectory; the second is inf without movers."""
    best, best_mover = math.inf, math.inf
    for start in range(0, len(poses), CLEARANCE_CHUNK):
        chunk = slice(start, start + CLEARANCE_CHUNK)
        static = world.footprint_clearance(poses[chunk])
        moving = movers_clearance(world.robot.footprint, poses[chunk], mover_circles[chunk])
        best = min(best, float(np.minimum(static, moving).min()))
        best_mover = min(best_mover, float(moving.min()))
    return best, best_mover


def _pose_error(pose: np.ndarray, goal: np.ndarray) -> tuple[float, float]:
    return (float(np.hypot(*(pose[:2] - goal[:2]))), abs(math.degrees(float(wrap_angle(pose[2] - goal[2])))))


def _truth_at(record: MissionRecord, stamp_ns: int) -> np.ndarray:
    """The last true pose stamped at or before stamp_ns (the first one if none is)."""
    i = max(int(np.searchsorted(record.truth_stamps, stamp_ns, side="right")) - 1, 0)
    return record.truth_poses[i]


def _movers_at(record: MissionRecord, stamps: np.ndarray) -> np.ndarray:
    """The movers (len(stamps), K, 3) at the truth's stamps (the last recorded at or before each)."""
    if len(record.mover_stamps) == 0:
        return np.zeros((len(stamps), 0, 3))
    i = np.clip(np.searchsorted(record.mover_stamps, stamps, side="right") - 1, 0, len(record.mover_stamps) - 1)
    return record.mover_circles[i]


def _first_plan_length(plans: list[PathMsg], goal_id: str) -> float | None:
    prefix = f"{goal_id}#"
    for plan in plans:
        if plan.goal_id.startswith(prefix) and len(plan.poses):
            return path_length(plan.poses)
    return None


def _sim_count(record: MissionRecord, name: str) -> int | None:
    value = record.sim_values.get(name)
    return int(value) if isinstance(value, (int, float)) else None


def _sim_seconds(record: MissionRecord, name: str) -> float | None:
    value = record.sim_values.get(name)
    return float(value) if isinstance(value, (int, float)) else None


def _first_within(record: MissionRecord, goal: np.ndarray, sent_ns: int, ended_ns: int) -> float | None:
    """Sim s from sent_ns until the first true pose (up to ended_ns) within WITHIN_M of the goal."""
    span = (record.truth_stamps >= sent_ns) & (record.truth_stamps <= ended_ns)
    near = np.flatnonzero(span & (np.hypot(*(record.truth_poses[:, :2] - goal[:2]).T) <= WITHIN_M))
    return (int(record.truth_stamps[near[0]]) - sent_ns) / NS_PER_S if len(near) else None


def goal_tolerance(services: list[dict]) -> float:
    """The xy_goal_tolerance of a compose's navigator (its own default where the compose sets none)."""
    navigator = next((s for s in services if s.get("service") == "navigator"), {})
    return float((navigator.get("params") or {}).get("xy_goal_tolerance", NavigatorParams().xy_goal_tolerance))


def summarize_mission(record: MissionRecord, world: World, goals_total: int | None = None,
                      recording: str = "", goal_tolerance_m: float | None = None) -> MissionSummary:
    """The mission's figures; goals_total is how many goals were to be sent (default: those sent);
    goal_tolerance_m the navigator's xy_goal_tolerance (default its own default), which a success
    must have been within, plus FALSE_SUCCESS_MARGIN_M, by the truth."""
    tolerance = NavigatorParams().xy_goal_tolerance if goal_tolerance_m is None else goal_tolerance_m
    goals_total = len(record.goals) if goals_total is None else goals_total
    end_ns = int(record.truth_stamps[-1])
    outcomes, last_end_ns = [], None
    for index, goal in enumerate(record.goals):
        statuses = [s for s in record.statuses if s.goal_id == goal.goal_id]
        final = next((s for s in reversed(statuses) if s.status in TERMINAL), statuses[-1] if statuses else None)
        ended_ns = final.header.stamp_ns if final is not None and final.status in TERMINAL else end_ns
        last_end_ns = ended_ns
        target = np.array([goal.pose.x, goal.pose.y, goal.pose.theta])
        pose = record.truth_poses[-1] if index == len(record.goals) - 1 else _truth_at(record, ended_ns)
        xy, yaw = _pose_error(pose, target)
        status = final.status if final is not None else "none"
        # judged where the robot stood when success was said: a shove after it is no false success
        said_xy = _pose_error(_truth_at(record, ended_ns), target)[0]
        outcomes.append(GoalOutcome(goal.goal_id, tuple(float(v) for v in target), status,
                                    final.reason if final is not None else "",
                                    (ended_ns - goal.header.stamp_ns) / NS_PER_S, xy, yaw,
                                    _first_plan_length(record.plans, goal.goal_id),
                                    _first_within(record, target, goal.header.stamp_ns, ended_ns),
                                    status == "succeeded" and said_xy > tolerance + FALSE_SUCCESS_MARGIN_M))
    start_ns = record.goals[0].header.stamp_ns if record.goals else int(record.truth_stamps[0])
    span = (record.truth_stamps >= start_ns) & (record.truth_stamps <= end_ns)
    poses = record.truth_poses[span] if span.any() else record.truth_poses[-1:]
    stamps = record.truth_stamps[span] if span.any() else record.truth_stamps[-1:]
    reached = sum(o.reached for o in outcomes)
    collisions, robot_fault, mover_fault, shoved = (_sim_count(record, name) for name in (
        "collisions", "robot_fault_collisions", "mover_fault_collisions", "shoved_collisions"))
    if robot_fault is None:
        robot_fault = collisions
    contact_s, robot_contact_s = (_sim_seconds(record, name) for name in ("contact_s", "robot_contact_s"))
    plan_lengths = [o.plan_length_m for o in outcomes if o.plan_length_m is not None]
    clearance, mover_clearance = clearance_along(world, poses, _movers_at(record, stamps))
    return MissionSummary(
        success=reached == goals_total and collisions == 0,
        goals_reached=reached, goals_total=goals_total,
        time_s=((last_end_ns if last_end_ns is not None else end_ns) - start_ns) / NS_PER_S,
        path_length_m=path_length(poses),
        plan_length_m=sum(plan_lengths) if plan_lengths else None,
        final_xy_error_m=outcomes[-1].xy_error_m if outcomes else None,
        final_yaw_error_deg=outcomes[-1].yaw_error_deg if outcomes else None,
        collisions=collisions, robot_fault_collisions=robot_fault, mover_fault_collisions=mover_fault,
        shoved_collisions=shoved, min_clearance_m=clearance, min_mover_clearance_m=mover_clearance if math.isfinite(mover_clearance) else None,
        recording=recording, goals=outcomes, restarts=dict(record.restarts), contact_s=contact_s,
        robot_contact_s=robot_contact_s, false_successes=sum(o.false_success for o in outcomes))


def false_success_runs(rows: list[dict], name: str = "world") -> list:
    """The runs of a bench (rows holding their summary's false_successes) in which a goal was said
    succeeded that the truth had not reached: each of them failed, and a bench lists them."""
    return [r[name] for r in rows if r.get("false_successes")]


def summary_lines(summary: MissionSummary) -> list[str]:
    """The summary as text, one fact per line."""
    def num(value, fmt):
        return "n/a" if value is None else format(value, fmt)

    lines = [f"{'SUCCESS' if summary.success else 'FAILED'}: {summary.goals_reached}/{summary.goals_total} goals "
             f"reached, {num(summary.collisions, 'd')} collisions ({num(summary.robot_fault_collisions, 'd')} "
             f"the robot's fault, {num(summary.mover_fault_collisions, 'd')} a mover's, "
             f"{num(summary.shoved_collisions, 'd')} shoved into a wall; in contact "
             f"{num(summary.contact_s, '.2f')} s, the robot's {num(summary.robot_contact_s, '.2f')} s)",
             f"time {summary.time_s:.1f} sim s, driven {summary.path_length_m:.2f} m "
             f"(first global plans {num(summary.plan_length_m, '.2f')} m), min clearance {summary.min_clearance_m:.3f} m"
             + (f" ({summary.min_mover_clearance_m:.3f} m to a mover)" if summary.min_mover_clearance_m is not None else ""),
             f"final error {num(summary.final_xy_error_m, '.3f')} m, {num(summary.final_yaw_error_deg, '.2f')} deg",
             "restarts: " + (", ".join(f"{name} {n}" for name, n in sorted(summary.restarts.items())) or "none")]
    for o in summary.goals:
        why = f" ({o.reason})" if o.reason else ""
        if o.false_success:
            why += f" (a FALSE SUCCESS: {o.xy_error_m:.2f} m from the goal by the truth)"
        near = f"within {WITHIN_M:g} m after {o.within_1m_s:.1f} s" if o.within_1m_s is not None else \
            f"never within {WITHIN_M:g} m"
        lines.append(f"  {o.goal_id} ({o.goal[0]:.2f}, {o.goal[1]:.2f}, {math.degrees(o.goal[2]):.1f} deg): "
                     f"{o.status}{why} after {o.time_s:.1f} s ({near}), error {o.xy_error_m:.3f} m "
                     f"{o.yaw_error_deg:.2f} deg")
    lines.append(f"recording {summary.recording}")
    return lines
