"""A source: advances sim time, publishes the Clock and a Chatter message at a fixed sim rate."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...schemas.messages import Chatter, Clock
from ..runtime.node import NS_PER_S, Node
from ...parameters.declare import Parameters, Rule, param


@dataclass(frozen=True)
class TalkerParams(Parameters):
    clock_hz: float = param(100.0, gt=0)  # sim-time resolution: one Clock per step
    chatter_hz: float = param(10.0, gt=0)
    rate: float = param(1.0, gt=0)        # sim seconds per wall second

    rules = (Rule("chatter_hz", lambda p: p.chatter_hz <= p.clock_hz, "≤ clock_hz ({p.clock_hz})"),)


class Talker(Node):
    service = "talker"
    Params = TalkerParams

    def setup(self) -> None:
        self.clock = self.publisher("sim/clock")
        self.chatter = self.publisher("chatter")
        self.steps = 0
        self.step_ns = round(NS_PER_S / self.params.clock_hz)
        self.steps_per_chatter = max(1, round(self.params.clock_hz / self.params.chatter_hz))

    def pace_s(self) -> float:
        return 1.0 / (self.params.clock_hz * self.params.rate)

    def tick(self) -> None:
        self.steps += 1
        self.now_ns = self.steps * self.step_ns
        self.clock.publish(Clock(header=self.header(), rate=self.params.rate))
        if self.steps % self.steps_per_chatter == 0:
            n = self.steps // self.steps_per_chatter
            t = self.now_ns / NS_PER_S
            self.chatter.publish(Chatter(header=self.header("talker"), text=f"hello {n}", value=math.sin(t)))
