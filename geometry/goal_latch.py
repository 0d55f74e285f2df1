"""A goal position that stays reached while the robot turns to the goal's yaw.

Once a robot stands within xy_goal_tolerance of its goal it turns on the spot to the goal's yaw, and
a turn moves a real robot's centre by a few centimetres: a skid steer's wheels slip sideways, and the
localizer's pose jitters while the scan sweeps round. With a tolerance of a few centimetres the
position is then lost, and a differential drive corrects a 3 cm miss by turning towards it and back
— building-jackal-1 turned back and forth for 10 s this way. latch_xy_goal_tolerance
(base_local_planner's name; Nav2's SimpleGoalChecker latches by default, `stateful`) keeps the
position reached while the robot turns. Unlike ROS's, this latch holds only within LATCH_SLACK ×
xy_goal_tolerance: a robot pushed farther has left its goal, and no arrival is claimed for it.

The local planner's final approach and the navigator each keep one, with their own tolerances.
"""
from __future__ import annotations

LATCH_SLACK = 2.0   # × xy_goal_tolerance: how far a latched position may drift while the robot turns


class GoalLatch:
    def __init__(self, xy_tolerance: float, enabled: bool):
        self.xy_tolerance = xy_tolerance
        self.enabled = enabled
        self.latched = False

    def within(self, distance: float) -> bool:
        """Whether the position counts as reached at `distance` (m) from the goal; latches on the
        first distance within the tolerance and lets go beyond the slack."""
        if distance <= self.xy_tolerance:
            self.latched = self.enabled
            return True
        if distance > LATCH_SLACK * self.xy_tolerance:
            self.latched = False
        return self.latched

    def holds(self, distance: float) -> bool:
        """As within(), without changing the latch."""
        return distance <= (LATCH_SLACK * self.xy_tolerance if self.latched else self.xy_tolerance)

    def reset(self) -> None:
        """A new goal: nothing reached yet."""
        self.latched = False
