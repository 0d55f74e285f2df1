"""The truth_pose service: the simulator's ground truth as if it were a perfect localizer.

For `omninav navigate --localization truth`: the navigation stack then runs on the true pose, so a
mission measures planning and control alone. The map frame is the world frame (the shipped maps
are rasterized worlds), so the truth is already a pose in the map.

Inputs, in merge order: sim/<robot>/truth and odom, both synced (the sim stamps the truth of a
step with the same time as the wheel state the chassis turns into odometry). At every odometry
stamped t that has a truth stamped t, at most publish_rate_hz times per sim second, it publishes,
stamped t: `pose` (PoseWithCovariance in the map frame, a small fixed covariance) and
`tf/map_odom` = truth ∘ odometry⁻¹, so odometry carried into the map lands on the truth. An
odometry without a truth at its stamp is skipped and counted (odom_without_truth).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...schemas.messages import Header, Odometry, Pose2D, PoseWithCovariance, Transform
from ..runtime.node import NS_PER_S, Node
from ...geometry.se2 import compose, inverse
from ...parameters.declare import Parameters, param


@dataclass(frozen=True)
class TruthPoseParams(Parameters):
    publish_rate_hz: float = param(20.0, ge=0)  # sim Hz of pose and tf/map_odom; 0 = at every odometry
    position_std: float = param(0.005, ge=0)    # m, stated in the covariance (the truth is exact; consumers may divide by it)
    yaw_std: float = param(0.005, ge=0)         # rad
    map_frame: str = param("map", nonempty=True)
    odom_frame: str = param("odom", nonempty=True)


class TruthPoseNode(Node):
    service = "truth_pose"
    Params = TruthPoseParams

    def setup(self) -> None:
        p = self.params
        self.period_ns = round(NS_PER_S / p.publish_rate_hz) if p.publish_rate_hz > 0 else 0
        self.covariance = np.diag([p.position_std ** 2, p.position_std ** 2, p.yaw_std ** 2])
        self.truth: Odometry | None = None
        self.last_published_ns: int | None = None
        self.pose_pub = self.publisher("pose")
        self.tf_pub = self.publisher("tf/map_odom")
        self.subscribe("sim/truth", self.on_truth)
        self.subscribe("odom", self.on_odom)

    def on_truth(self, msg: Odometry) -> None:
        self.truth = msg

    def on_odom(self, msg: Odometry) -> None:
        stamp = msg.header.stamp_ns
        if self.truth is None or self.truth.header.stamp_ns != stamp:
            self.counters["odom_without_truth"] += 1
            return
        if self.last_published_ns is not None and stamp - self.last_published_ns < self.period_ns:
            return
        self.last_published_ns = stamp
        p, t = self.params, self.truth.pose
        true_pose = np.array([t.x, t.y, t.theta])
        self.pose_pub.publish(PoseWithCovariance(header=Header(stamp_ns=stamp, frame_id=p.map_frame),
                                                 pose=Pose2D(t.x, t.y, t.theta), covariance=self.covariance.copy()))
        map_odom = compose(true_pose, inverse([msg.pose.x, msg.pose.y, msg.pose.theta]))
        x, y, theta = (float(v) for v in map_odom)
        self.tf_pub.publish(Transform(header=Header(stamp_ns=stamp, frame_id=p.map_frame),
                                      child_frame_id=p.odom_frame, transform=Pose2D(x, y, theta)))
