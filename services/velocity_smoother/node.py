"""velocity_smoother, the first of the two gates between the navigator and the chassis (the collision
monitor, services/collision_monitor/, is the second):

    cmd_vel_mux --cmd_vel_mux--> velocity_smoother --cmd_vel_smoothed--> collision_monitor --cmd_vel--> chassis

(the mux takes the navigator's cmd_vel_nav and teleop's cmd_vel_teleop: services/cmd_vel_mux/)

The smoother (VelocitySmoother, smoother.py) runs on the sim clock: a smoothing tick falls on
the clock stamped at or first after each multiple of 1/smoothing_frequency of sim time, and every
tick publishes the smoothed command (zeros while there is nothing to do, so the collision monitor
downstream always has a stream to follow). cmd_vel_mux is sporadic: a command stamped t takes
effect at the first tick after t + command_delay_s — the time the navigator's command may take to
get here (through the mux), live, behind the clock; whether it arrives before or after the clocks stamped in
(t, t + delay] then cannot change the output. Added latency: with the local planner and the
smoother both at 20 Hz (ticks on the same multiples of 50 ms) and the default 0.04 s delay, one
period, 50 ms. No command for velocity_timeout seconds of sim time → the output decelerates to zero.
"""
from __future__ import annotations

from dataclasses import dataclass

from ...geometry.frames import twist_message, twist_vector
from ...schemas.messages import Clock
from ..runtime.deferred import Deferred
from ..runtime.node import Node, Ticks
from .smoother import VelocitySmoother, VelocitySmootherParams
from ...parameters.declare import param


@dataclass(frozen=True)
class VelocitySmootherNodeParams(VelocitySmootherParams):
    """Nav2's velocity_smoother names (VelocitySmootherParams) and the node's own."""
    command_delay_s: float = param(0.04, ge=0)       # sim s from a command's stamp until it takes effect


class VelocitySmootherNode(Node):
    service = "velocity_smoother"
    Params = VelocitySmootherNodeParams

    def setup(self) -> None:
        p = self.params
        self.smoother = VelocitySmoother(p)
        self.ticks = Ticks(p.smoothing_frequency)
        self.pending = Deferred(p.command_delay_s)   # commands not yet in effect
        self.out_pub = self.publisher("cmd_vel_smoothed")
        self.subscribe("sim/clock", self.on_clock)
        self.subscribe_deferred("cmd_vel_mux", self.pending)

    def on_clock(self, msg: Clock) -> None:
        t = msg.header.stamp_ns
        if not self.ticks.due(t):
            return
        for _, command in self.pending.due(t):
            self.smoother.command(twist_vector(command), command.header.stamp_ns)
            self.counters["commands"] += 1
        out = self.smoother.step(t)
        self.counters["timed_out_ticks" if out.timed_out else "ticks"] += 1
        self.out_pub.publish(twist_message(out.twist, t))
