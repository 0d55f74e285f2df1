"""Command mux (ROS twist_mux style): of several velocity command streams, the one with the highest
priority that spoke recently wins.

A source is active from a command's stamp until `timeout` seconds of sim time after it; a command
from a source is passed on only while no source of higher priority is active, so a human driving
by hand (teleop) overrides navigation for as long as the keys are held plus the timeout, and
navigation resumes by itself afterwards. Pure: no transport, no clock of its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Source:
    name: str
    priority: int          # higher wins
    timeout: float         # s of sim time a command keeps its source active

    def __post_init__(self):
        if not (np.isfinite(self.timeout) and self.timeout > 0):
            raise ValueError(f"source {self.name}: timeout must be positive and finite, got {self.timeout}")


class CommandMux:
    def __init__(self, sources: list[Source]):
        names = [s.name for s in sources]
        if len(set(names)) != len(names):
            raise ValueError(f"source names must be unique, got {names}")
        self.sources = {s.name: s for s in sources}
        self.last_ns: dict[str, int] = {}          # source -> stamp of its latest command

    def active(self, name: str, now_ns: int) -> bool:
        last = self.last_ns.get(name)
        return last is not None and last <= now_ns <= last + round(self.sources[name].timeout * NS_PER_S)

    def offer(self, name: str, stamp_ns: int) -> bool:
        """A command from `name` stamped stamp_ns: whether it is passed on (no higher source active)."""
        self.last_ns[name] = max(stamp_ns, self.last_ns.get(name, stamp_ns))
        priority = self.sources[name].priority
        return not any(self.active(other.name, stamp_ns) for other in self.sources.values()
                       if other.priority > priority)
