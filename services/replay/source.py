"""A recording as the source of an in-process run: the recorded messages of the chosen keys are
published again, in stamp order, one stamp per tick, so any set of services can be run on a
recording in lockstep (the InProcessRunner) — a pipeline tested by replaying what a robot saw.

Unlike `replay --into SERVICE`, which checks one service against its own recorded outputs, this
feeds services that need not have run when the recording was made, and their results are judged
by outcome (a pose against the recorded truth, a plan found).
"""
from __future__ import annotations

from pathlib import Path

from ...schemas import decode
from ..recorder.mcap_io import Record, read_records
from ..runtime.node import Node, Publisher


class RecordingSource(Node):
    """Publishes the records of `keys` from a recording (RecordingError if it is unreadable), a stamp
    at a time; `finished` once every record is out. Outputs keep the recorded keys: a recording of
    robot r1 feeds services of robot r1."""
    service = "recording_source"

    def __init__(self, path: str | Path, keys: list[str]):
        self.records: list[Record] = sorted(read_records(path, keys), key=lambda r: (r.stamp_ns, r.seq))
        super().__init__()

    def setup(self) -> None:
        for rec in self.records:
            if rec.key not in self.outputs:
                self.outputs[rec.key] = Publisher(rec.key, type(decode(rec.payload, key=rec.key)))
        self.next = 0

    @property
    def finished(self) -> bool:
        return self.next >= len(self.records)

    def pace_s(self) -> float:
        return 0.0      # in-process only: the runner ticks it as fast as the services keep up

    def tick(self) -> None:
        if self.finished:
            return
        stamp = self.records[self.next].stamp_ns
        while not self.finished and self.records[self.next].stamp_ns == stamp:
            rec = self.records[self.next]
            self.now_ns = stamp
            self.outputs[rec.key].publish(decode(rec.payload, key=rec.key))
            self.next += 1
