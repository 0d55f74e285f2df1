"""Lockstep across processes: the simulator steps only when every service is done with the last step.

No wall clock decides anything in a lockstep run, so the same command gives the same messages at
any machine load and runs as fast as the stack computes. The rule is counted on sequence numbers:

- every service that takes part (a *participant*) reports on its lockstep key, after each burst of
  work, the last seq it received on each of its input keys and the last seq it published on each of
  its outputs (a message held in its stamp merger counts as received: it waits for a later step);
- the coordinator (the simulator's runner) ticks only when, for every key someone reports
  publishing, every participant subscribed to it has received up to that seq — nothing is in flight
  and nothing is being worked on, because a participant reports only after the work a message
  caused, its own publications included.

Zenoh delivers each publisher's messages in order, so "received seq n" means "received all up to
n". A participant that joins (or rejoins after a restart, with its seqs starting again) is admitted
only at a moment when it is caught up; until it hears a key it only waits for publications made
after it joined. The services the coordinator waits for before its first step come from the
launcher (OMNINAV_LOCKSTEP), so a whole run starts the same way every time.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Iterable, Mapping

from ...schemas.messages import Diagnostic, Header

LOCKSTEP_ENV = "OMNINAV_LOCKSTEP"   # set (to the services to wait for, comma-separated, maybe none): lockstep on
NOBODY = "-"                        # the env value for "lockstep on, wait for no one in particular"

_IN, _OUT, _RUN, _SUBSCRIBED, _HOLD = "in/", "out/", "run", "subscribed", "hold"


@dataclass(frozen=True)
class Lockstep:
    """A run's lockstep setting: on, and whom the coordinator waits for before its first step."""
    wait_for: tuple[str, ...] = ()

    @classmethod
    def from_env(cls, environ: Mapping[str, str] = os.environ) -> "Lockstep | None":
        value = environ.get(LOCKSTEP_ENV)
        return None if value is None else cls(service_names(value))

    def env_value(self) -> str:
        return ",".join(self.wait_for) or NOBODY


@dataclass
class Report:
    """One participant's progress: per key the last seq received / published, for one run of it."""
    name: str
    run: int
    subscribed: tuple[str, ...]
    received: dict[str, int]
    published: dict[str, int]
    hold: bool = False      # it wants no further step (a mission that is over): the run ends here

    def to_message(self, stamp_ns: int) -> Diagnostic:
        values: dict[str, float | int | str] = {_RUN: self.run, _SUBSCRIBED: " ".join(self.subscribed),
                                                _HOLD: int(self.hold)}
        values.update({_IN + k: v for k, v in self.received.items()})
        values.update({_OUT + k: v for k, v in self.published.items()})
        return Diagnostic(header=Header(stamp_ns=stamp_ns), name=self.name, level=0, message="lockstep",
                          values=values)

    @classmethod
    def from_message(cls, msg: Diagnostic) -> "Report":
        values = msg.values
        return cls(name=msg.name, run=int(values.get(_RUN, 0)), subscribed=tuple(str(values.get(_SUBSCRIBED, "")).split()),
                   received={k[len(_IN):]: int(v) for k, v in values.items() if k.startswith(_IN)},
                   published={k[len(_OUT):]: int(v) for k, v in values.items() if k.startswith(_OUT)},
                   hold=bool(values.get(_HOLD, 0)))


def service_names(text: str) -> tuple[str, ...]:
    """The service names of a comma-separated list (as OMNINAV_LOCKSTEP and --lockstep give them)."""
    return tuple(n for n in text.split(",") if n and n != NOBODY)


def matches(expr: str, key: str) -> bool:
    """Whether a concrete key is in a subscription's key expression (`*` one chunk, `**` any)."""
    if "*" not in expr:
        return expr == key
    chunks = (re.escape(part).replace(r"\*", "[^/]*") for part in expr.split("**"))
    return re.fullmatch(".*".join(chunks), key) is not None


@dataclass
class _Member:
    report: Report
    baseline: dict[str, int]        # what was published on each key when it was admitted


@dataclass
class Barrier:
    """The coordinator's view: the latest report of each participant, and whether the next step may go."""
    wait_for: tuple[str, ...] = ()     # before the first step only: later, one that left is not waited for
    members: dict[str, _Member] = field(default_factory=dict)
    pending: dict[str, Report] = field(default_factory=dict)     # reported but not yet admitted
    # who held the run: it is over for good, also once the holder has left the bus (navigate stops
    # its own session before `up` has stopped the sim)
    held_by: str = ""
    _match_cache: dict[tuple[str, str], bool] = field(default_factory=dict)

    def update(self, report: Report) -> None:
        member = self.members.get(report.name)
        if member is not None and member.report.run == report.run:
            member.report = report
        else:               # new, or a new run of it: its seqs start again
            self.members.pop(report.name, None)
            self.pending[report.name] = report

    def leave(self, name: str) -> None:
        """A participant is gone (its liveliness token went away): no longer waited for."""
        self.members.pop(name, None)
        self.pending.pop(name, None)

    def published(self, own: Mapping[str, int]) -> dict[str, int]:
        out = dict(own)
        for member in self.members.values():
            out.update(member.report.published)
        return out

    def ready(self, own_published: Mapping[str, int], own_received: Mapping[str, int],
              own_subscribed: Iterable[str]) -> bool:
        """Whether every participant (and the coordinator itself) has everything that was published
        to it; admits those that reported meanwhile when they are caught up. False until everyone
        in wait_for has been admitted."""
        self.held_by = self.held_by or next((r.name for r in self._reports() if r.hold), "")
        if self.held_by:
            return False
        published = self.published(own_published)
        if not self._caught_up(tuple(own_subscribed), own_received, published, {}):
            return False
        if any(not self._caught_up(m.report.subscribed, m.report.received, published, m.baseline)
               for m in self.members.values()):
            return False
        for name, report in list(self.pending.items()):
            if self._caught_up(report.subscribed, report.received, published, None):
                del self.pending[name]
                self.members[name] = _Member(report, published)
        if not all(name in self.members for name in self.wait_for):
            return False
        self.wait_for = ()
        return True

    def waiting_on(self, own_published: Mapping[str, int]) -> list[str]:
        """Who holds the next step up (for a log line when it takes long)."""
        published = self.published(own_published)
        held = [f"{self.held_by} (held the run: it is over)"] if self.held_by else []
        behind = [m.report.name for m in self.members.values()
                  if not self._caught_up(m.report.subscribed, m.report.received, published, m.baseline)]
        return held + behind + [f"{n} (not started)" for n in self.wait_for if n not in self.members]

    def _reports(self) -> list[Report]:
        return [*(m.report for m in self.members.values()), *self.pending.values()]

    def _caught_up(self, subscribed: tuple[str, ...], received: Mapping[str, int], published: Mapping[str, int],
                   baseline: Mapping[str, int] | None) -> bool:
        """Every key published to it was received up to its last seq. A key it never heard: fine if
        nothing was published on it since it was admitted (baseline; None: a join, fine at once)."""
        for key, seq in published.items():
            if not any(self._matches(expr, key) for expr in subscribed):
                continue
            got = received.get(key)
            if got is None:
                if baseline is not None and baseline.get(key) != seq:
                    return False
            elif got != seq:
                return False
        return True

    def _matches(self, expr: str, key: str) -> bool:
        known = self._match_cache.get((expr, key))
        if known is None:
            known = self._match_cache[(expr, key)] = matches(expr, key)
        return known
