"""Which services exist: name -> the module and Node class that implement it.

Compose files, `omninav run` and `replay --into` name services by these names.
"""
from __future__ import annotations

import importlib

SERVICES: dict[str, str] = {
    "talker": "omninav.services.demo.talker:Talker",
    "listener": "omninav.services.demo.listener:Listener",
    "recorder": "omninav.services.recorder.node:RecorderNode",
    "sim": "omninav.sim.node:SimNode",
    "chassis": "omninav.services.chassis.node:ChassisNode",
    "lidar": "omninav.services.lidar.node:LidarNode",
    "localizer": "omninav.services.localizer.node:LocalizerNode",
    "map_server": "omninav.services.map_server.node:MapServerNode",
    "costmap": "omninav.services.costmap.node:CostmapNode",
    "slam": "omninav.services.slam.node:SlamNode",
    "laser_odometry": "omninav.services.laser_odometry.node:LaserOdometryNode",
    "explore": "omninav.services.explore.node:ExploreNode",
    "global_planner": "omninav.services.global_planner.node:PlannerNode",
    "local_planner": "omninav.services.local_planner.node:LocalPlannerNode",
    "cmd_vel_mux": "omninav.services.cmd_vel_mux.node:CmdVelMuxNode",
    "velocity_smoother": "omninav.services.velocity_smoother.node:VelocitySmootherNode",
    "collision_monitor": "omninav.services.collision_monitor.node:CollisionMonitorNode",
    "navigator": "omninav.services.navigator.node:NavigatorNode",
    "truth_pose": "omninav.services.truth_pose.node:TruthPoseNode",
    "view": "omninav.services.view.node:ViewNode",
    "rerun_view": "omninav.services.view.rerun_node:RerunViewNode",
    "tracker": "omninav.services.tracker.node:TrackerNode",
    "ros2_bridge": "omninav.services.ros2_bridge.node:Ros2BridgeNode",
    "ekf": "omninav.services.ekf.node:EkfNode",
}


class UnknownService(LookupError):
    pass


def node_class(service: str, spec: str | None = None) -> type:
    """The Node class of a registered service, or of an explicit 'package.module:Class' spec."""
    target = spec or SERVICES.get(service)
    if target is None:
        raise UnknownService(f"unknown service {service!r}; known: {sorted(SERVICES)}")
    module_name, _, class_name = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise UnknownService(f"service {service!r}: cannot import {module_name}: {exc}") from None
    try:
        return getattr(module, class_name)
    except AttributeError:
        raise UnknownService(f"service {service!r}: {module_name} has no {class_name}") from None
