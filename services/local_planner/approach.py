"""The final approach: the last metres to the goal pose, where DWA is too coarse (it keeps the robot
within about a cell of its local goal and never samples slow turns on the spot).

The robot drives the straight line from where the approach starts to the goal with the path
follower (follower.py), so its speed obeys the distance-based deceleration V = ((l − s)/l)^a · V0
and falls to zero on the goal; it turns to the goal's yaw with ω = kp_heading · yaw error (clipped
to max_vel_theta, and to what closes the error within one period):

- holonomic: translation and turn at once; whatever yaw error is left at the end is turned on the
  spot;
- differential: first turn on the spot towards the line (or away from it, driving backwards, when
  the goal lies behind), follow it, then turn on the spot to the goal's yaw.

Done when the position is within xy_tolerance and the yaw within yaw_tolerance; a line that ends
farther than xy_tolerance from the goal (cross-track error left over, the robot pushed aside) is
followed by a new line from where the robot stands. With latch_xy, a position once reached stays
reached while the robot turns to the goal's yaw, unless it drifts beyond the latch's slack
(geometry/goal_latch.py). Poses are (x, y, yaw) in one frame (the node uses the map frame), twists
body twists.

The turn has no floor at min_in_place_vel_theta (base_local_planner's rotate-to-goal has one): the
command reaches the wheels a few control periods later (smoother, chassis), and a floor then
overshoots the 0.02 rad tolerance and oscillates around it; the proportional law converges.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry.goal_latch import GoalLatch
from ...geometry.se2 import wrap_angle
from .path_follower import Line, PathFollower
from .params import FollowerParams

ALIGNED = 0.2        # rad: a differential drive turns on the spot towards its line until within this
TURN_STEP = 0.1      # rad between the poses that stand for a turn on the spot in planned_poses


@dataclass(frozen=True)
class ApproachCommand:
    twist: np.ndarray    # (3,) vx, vy, wz
    phase: str           # align | drive | turn | arrived


class FinalApproach:
    def __init__(self, params: FollowerParams, goal, pose, speed: float, xy_tolerance: float,
                 yaw_tolerance: float, latch_xy: bool = False):
        self.params = params
        self.goal = np.asarray(goal, float).copy()
        self.xy_tolerance, self.yaw_tolerance = xy_tolerance, yaw_tolerance
        self._latch = GoalLatch(xy_tolerance, latch_xy)
        self.holonomic = params.drive == "holonomic"
        self._start_line(np.asarray(pose, float), speed)

    def _start_line(self, pose: np.ndarray, speed: float) -> None:
        """A line from pose to the goal (none when already within xy_tolerance)."""
        gap = self.goal[:2] - pose[:2]
        self._follower: PathFollower | None = None
        self._heading = math.atan2(gap[1], gap[0])
        self._reverse = (not self.holonomic
                         and abs(float(wrap_angle(self._heading - pose[2]))) > math.pi / 2)
        self._aligned = self.holonomic
        if math.hypot(*gap) > self.xy_tolerance:
            self._follower = PathFollower(self.params, [Line(tuple(pose[:2]), tuple(self.goal[:2]))], speed)

    def _drive_yaw(self, yaw: float) -> float:
        """The direction a differential drive moves in: its heading, or the opposite when reversing."""
        return yaw + math.pi if self._reverse else yaw

    def _turn(self, error: float) -> float:
        p = self.params
        return float(np.clip(p.kp_heading * error, -p.max_vel_theta, p.max_vel_theta))

    def step(self, pose, dt: float) -> ApproachCommand:
        """The command for the robot at pose, the control period being dt seconds."""
        pose = np.asarray(pose, float)
        yaw_error = float(wrap_angle(self.goal[2] - pose[2]))
        if self._follower is not None:
            if not self._aligned:
                line_error = float(wrap_angle(self._heading - self._drive_yaw(pose[2])))
                if abs(line_error) > ALIGNED:
                    return ApproachCommand(np.array([0.0, 0.0, self._turn(line_error)]), "align")
                self._aligned = True
            if self.holonomic:
                cmd = self._follower.step(pose, dt)
                twist = np.array([cmd.twist[0], cmd.twist[1], self._turn(yaw_error)])
            else:
                cmd = self._follower.step((pose[0], pose[1], self._drive_yaw(pose[2])), dt)
                twist = cmd.twist * (-1.0 if self._reverse else 1.0, 0.0, 1.0)
            if not cmd.done:
                return ApproachCommand(twist, "drive")
            self._follower = None
        if not self._latch.within(math.hypot(*(self.goal[:2] - pose[:2]))):
            self._start_line(pose, 0.0)
            return self.step(pose, dt) if self._follower is not None else self._turn_to_goal(yaw_error)
        return self._turn_to_goal(yaw_error)

    def reached(self, pose) -> bool:
        """Whether pose is within the tolerances of the goal (the position's latched), as an arrival
        needs."""
        pose = np.asarray(pose, float)
        return (self._latch.holds(math.hypot(*(self.goal[:2] - pose[:2])))
                and abs(float(wrap_angle(self.goal[2] - pose[2]))) <= self.yaw_tolerance)

    def _turn_to_goal(self, yaw_error: float) -> ApproachCommand:
        if abs(yaw_error) <= self.yaw_tolerance:
            return ApproachCommand(np.zeros(3), "arrived")
        return ApproachCommand(np.array([0.0, 0.0, self._turn(yaw_error)]), "turn")

    def planned_poses(self, pose, spacing: float) -> np.ndarray:
        """(N, 3) the poses the robot will pass through from pose to the goal, at most `spacing`
        metres (or TURN_STEP radians) apart, for the collision check and the picture."""
        pose = np.asarray(pose, float)
        distance = math.hypot(*(self.goal[:2] - pose[:2]))
        n = max(1, int(math.ceil(distance / spacing)))
        along = np.linspace(0.0, 1.0, n + 1)[:, None]
        xy = pose[:2] + along * (self.goal[:2] - pose[:2])
        if self.holonomic:
            yaw = pose[2] + along[:, 0] * float(wrap_angle(self.goal[2] - pose[2]))
            return np.column_stack([xy, yaw])
        drive = (self._heading + math.pi if self._reverse else self._heading) if distance > self.xy_tolerance \
            else pose[2]
        return np.vstack([_turn_poses(pose, drive), np.column_stack([xy, np.full(len(xy), drive)]),
                          _turn_poses((*self.goal[:2], drive), self.goal[2])])


def _turn_poses(pose, to_yaw: float) -> np.ndarray:
    """Poses of a turn on the spot at pose from its yaw to to_yaw (the shorter way)."""
    turn = float(wrap_angle(to_yaw - pose[2]))
    n = max(1, int(math.ceil(abs(turn) / TURN_STEP)))
    yaw = pose[2] + np.linspace(0.0, turn, n + 1)
    return np.column_stack([np.full(n + 1, pose[0]), np.full(n + 1, pose[1]), yaw])
