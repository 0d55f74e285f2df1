"""cmd_vel_mux: teleop and navigation into one command stream, in front of the velocity smoother.

    teleop --cmd_vel_teleop--+
                             +--> cmd_vel_mux --cmd_vel_mux--> velocity_smoother --> collision_monitor --cmd_vel--> chassis
    navigator --cmd_vel_nav--+

Priorities as twist_mux's: teleop (100) over navigation (10), each active for its timeout after a
command. Both inputs are sporadic and held command_delay_s of sim time after their stamp
(deferred.py), then offered in stamp order at the clock tick where they fall due: so whether a
teleop command arrived before or after a navigation command stamped close to it cannot change
which one passes. A passed command keeps its stamp; the smoother's own delay (0.04 s by default)
is measured from that stamp, so with this mux's 0.02 s it adds no latency.
"""
from __future__ import annotations

from dataclasses import dataclass

from ...schemas.messages import Clock
from ..runtime.deferred import Deferred
from ..runtime.node import Node
from .mux import CommandMux, Source
from ...parameters.declare import Parameters, param

TELEOP, NAVIGATION = 0, 1       # Deferred kinds


@dataclass(frozen=True)
class CmdVelMuxParams(Parameters):
    teleop_priority: int = 100
    teleop_timeout: float = param(0.5, gt=0)    # s of sim time (twist_mux's example uses 0.5)
    navigation_priority: int = 10
    navigation_timeout: float = param(0.5, gt=0)
    command_delay_s: float = param(0.02, ge=0)  # sim s from a command's stamp until it is offered


class CmdVelMuxNode(Node):
    service = "cmd_vel_mux"
    Params = CmdVelMuxParams

    def setup(self) -> None:
        p = self.params
        self.mux = CommandMux([Source("teleop", p.teleop_priority, p.teleop_timeout),
                               Source("navigation", p.navigation_priority, p.navigation_timeout)])
        self.pending = Deferred(p.command_delay_s)
        self.out_pub = self.publisher("cmd_vel_mux")
        self.subscribe("sim/clock", self.on_clock)
        self.subscribe_deferred("cmd_vel_teleop", self.pending, TELEOP)
        self.subscribe_deferred("cmd_vel_nav", self.pending, NAVIGATION)

    def on_clock(self, msg: Clock) -> None:
        for kind, command in self.pending.due(msg.header.stamp_ns):
            source = "teleop" if kind == TELEOP else "navigation"
            if self.mux.offer(source, command.header.stamp_ns):
                self.counters[f"passed/{source}"] += 1
                self.out_pub.publish(command)
            else:
                self.counters[f"overridden/{source}"] += 1
