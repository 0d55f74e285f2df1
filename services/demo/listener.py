"""A stateful echo: republishes each Chatter with a running sum, and a summary every sim second.

Stateful on purpose, with two synced inputs (chatter and the clock behind its timer), so that a
deterministic replay of it proves the stamp-ordered merge, not just a pure function.
"""
from __future__ import annotations

from dataclasses import dataclass

from ...schemas.messages import Chatter
from ..runtime.node import Node
from ...parameters.declare import Parameters, param


@dataclass(frozen=True)
class ListenerParams(Parameters):
    summary_period_s: float = param(1.0, gt=0)
    gain: float = param(1.0, finite=True)  # scales the running sum, so parameter files have something to set


class Listener(Node):
    service = "listener"
    Params = ListenerParams

    def setup(self) -> None:
        self.echo = self.publisher("echo")
        self.subscribe("chatter", self.on_chatter)
        self.every(self.params.summary_period_s, self.on_summary)
        self.queryable("echo", lambda _params: self.last)
        self.total = 0.0
        self.count = 0
        self.last: Chatter | None = None

    def on_chatter(self, msg: Chatter) -> None:
        self.count += 1
        self.total += self.params.gain * msg.value
        self.last = Chatter(header=self.header("listener"), text=f"echo: {msg.text}", value=self.total)
        self.echo.publish(self.last)

    def on_summary(self) -> None:
        self.echo.publish(Chatter(header=self.header("listener"), text=f"summary: {self.count} messages",
                                  value=self.total))
