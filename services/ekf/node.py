"""The odometry fusion service: wheel odometry, IMU and laser odometry in; fused odom, tf/odom_base
and the doubt out (core: ekf.py, doubt.py; docs/odometry_fusion.md).

Each odom_wheel message (the chassis with fused_odometry: true) is one filter step and one output
at its stamp, after the IMU readings up to that stamp (imu is synced with it: the sim publishes
both at its step). Laser odometry is sporadic and late (a scan matched at its scan's stamp): it is
held odom_laser_delay_s of sim time after its stamp and then fused as a lagged measurement at its
own stamp, so whether it reached the node before or after the wheel steps stamped within that
delay cannot change the outputs. odom_doubt goes out when the verdict changes and with each laser
pose fused.
"""
from __future__ import annotations

from dataclasses import dataclass

from ...parameters.declare import Rule, param
from ...parameters.from_mapping import load_params
from ...schemas.messages import Header, Imu, Odometry, OdometryDoubt, Pose2D, Transform, Twist
from ..runtime.deferred import Deferred
from ..runtime.node import Node
from ..runtime.params import ForeignNames
from .ekf import EkfParams, OdometryFusion

# robot_localization's names that mean nothing here: the sources are fixed keys (odom0 = odom_wheel,
# odom1 = odom_laser, imu0 = imu), the filter steps on each wheel odometry message, not on a timer
ROBOT_LOCALIZATION = ForeignNames(
    stack="robot_localization", node="ekf_filter_node",
    ignored=frozenset({"odom0", "odom1", "imu0", "frequency", "sensor_timeout", "map_frame", "transform_time_offset",
                       "transform_timeout", "print_diagnostics", "debug", "debug_out_file", "publish_acceleration",
                       "permit_corrected_publication", "reset_on_time_jump", "use_control", "dynamic_process_noise_covariance",
                       "odom0_queue_size", "odom1_queue_size", "imu0_queue_size", "odom0_nodelay", "odom1_nodelay",
                       "imu0_nodelay", "imu0_differential", "imu0_relative", "imu0_remove_gravitational_acceleration",
                       "imu0_pose_rejection_threshold", "imu0_twist_rejection_threshold"}))


@dataclass(frozen=True)
class EkfNodeParams(EkfParams):
    """EkfParams plus what the node needs around the core."""
    publish_tf: bool = True                          # tf/odom_base from the fused pose
    world_frame: str = param("odom", nonempty=True)
    odom_frame: str = param("odom", nonempty=True)
    base_link_frame: str = param("base_link", nonempty=True)
    odom_laser_delay_s: float = param(0.25, ge=0)    # ours: sim s laser odometry is held after its stamp

    rules = (Rule("world_frame", lambda p: p.world_frame == p.odom_frame,
                  "odom_frame ({p.odom_frame}): this fusion runs in the odom frame only"),
             Rule("history_length", lambda p: not p.uses("odom1") or not p.smooth_lagged_data
                  or p.history_length > p.odom_laser_delay_s,
                  "longer than odom_laser_delay_s ({p.odom_laser_delay_s}), or late laser odometry is too old to fuse"))

    @classmethod
    def from_mapping(cls, values: dict | None, source: str = "ekf"):
        """From our names or a robot_localization file's (its topic and queue names accepted without effect)."""
        return load_params(cls, ROBOT_LOCALIZATION.translate(dict(values or {}), source), source,
                           ROBOT_LOCALIZATION.names)


class EkfNode(Node):
    service = "ekf"
    Params = EkfNodeParams

    def setup(self) -> None:
        p = self.params
        self.fusion = OdometryFusion(p)
        self.imus: list[Imu] = []
        if p.uses("imu0"):
            self.subscribe("imu", self.imus.append)          # before odom_wheel: the IMU at t comes first
        self.subscribe("odom_wheel", self.on_wheels)
        self.lasers = Deferred(p.odom_laser_delay_s)
        if p.uses("odom1"):
            self.subscribe_deferred("odom_laser", self.lasers)
        self.odom_pub = self.publisher("odom")
        self.tf_pub = self.publisher("tf/odom_base") if p.publish_tf else None
        self.doubt_pub = self.publisher("odom_doubt")
        self.queryable("odom", lambda _params: self.last_odom)
        self.last_odom: Odometry | None = None
        self.last_doubtful: bool | None = None
        self.last_stamp: int | None = None

    def on_wheels(self, msg: Odometry) -> None:
        t = msg.header.stamp_ns
        if self.last_stamp is not None and t <= self.last_stamp:
            self.counters["wheels_out_of_order"] += 1
            return
        self.last_stamp = t
        lasers = [laser for _, laser in self.lasers.due(t)]
        for laser in lasers:
            self.fusion.laser(laser)
        imus, self.imus[:] = list(self.imus), []
        verdict = self.fusion.step(msg, imus)
        for name, count in self.fusion.counters.items():
            self.counters[name] = count
        self.counters["doubtful"] = int(verdict.doubtful)
        self._publish(t, verdict, bool(lasers))

    def _publish(self, t: int, verdict, laser_fused: bool) -> None:
        p = self.params
        est = self.fusion.estimate()
        x, y, yaw = (float(v) for v in est.pose)
        vx, vy, wz = (float(v) for v in est.twist)
        self.last_odom = Odometry(header=Header(stamp_ns=t, frame_id=p.odom_frame), child_frame_id=p.base_link_frame,
                                  pose=Pose2D(x, y, yaw),
                                  twist=Twist(header=Header(stamp_ns=t, frame_id=p.base_link_frame),
                                              linear_x=vx, linear_y=vy, angular_z=wz),
                                  pose_covariance=est.pose_covariance, twist_covariance=est.twist_covariance)
        self.odom_pub.publish(self.last_odom)
        if self.tf_pub is not None:
            self.tf_pub.publish(Transform(header=Header(stamp_ns=t, frame_id=p.odom_frame),
                                          child_frame_id=p.base_link_frame, transform=Pose2D(x, y, yaw)))
        if laser_fused or verdict.doubtful != self.last_doubtful:
            self.last_doubtful = verdict.doubtful
            self.doubt_pub.publish(OdometryDoubt(header=Header(stamp_ns=t, frame_id=p.odom_frame),
                                                 doubtful=verdict.doubtful, reason=verdict.reason,
                                                 mahalanobis=verdict.mahalanobis))
