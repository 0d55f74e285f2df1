"""What a recording saw per key: message counts and sequence gaps (messages lost before recording).

Publishers number each key's messages 1, 2, 3 … (Header.seq, also in the attachment), so a jump by
more than one between consecutive messages of a key means messages that never reached the recorder.
A jump backwards means the publisher restarted; counting starts again from there. Seq 0 means the
publisher sent no sequence number (a foreign publisher): such messages are counted, never gaps.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class KeyTally:
    type_name: str
    messages: int = 0
    lost: int = 0          # messages missing inside seq jumps
    gaps: int = 0          # how many jumps
    restarts: int = 0      # seq went backwards
    first_seq: int = 0
    last_seq: int = 0


class SequenceTally:
    def __init__(self) -> None:
        self.keys: dict[str, KeyTally] = {}
        self.total = 0

    def add(self, key: str, type_name: str, seq: int) -> None:
        tally = self.keys.get(key)
        if tally is None:
            tally = self.keys[key] = KeyTally(type_name, first_seq=seq)
        elif seq:
            last = tally.last_seq
            if seq > last + 1 and last:
                tally.gaps += 1
                tally.lost += seq - last - 1
            elif seq <= last:
                tally.restarts += 1
        tally.messages += 1
        if seq:
            tally.last_seq = seq
        self.total += 1

    @property
    def lost(self) -> int:
        return sum(t.lost for t in self.keys.values())

    def report(self) -> str:
        """A table of keys with their counts, then one line on gaps (or their absence)."""
        width = max((len(k) for k in self.keys), default=3)
        lines = [f"{'key':<{width}}  {'type':<20} {'messages':>9} {'lost':>6} {'gaps':>5}"]
        for key in sorted(self.keys):
            t = self.keys[key]
            lines.append(f"{key:<{width}}  {t.type_name or '?':<20} {t.messages:>9} {t.lost:>6} {t.gaps:>5}"
                         + (f"  (seq restarted {t.restarts}x)" if t.restarts else ""))
        lossy = [f"{k} lost {t.lost} in {t.gaps} gap(s)" for k, t in sorted(self.keys.items()) if t.lost]
        lines.append("sequence gaps: " + "; ".join(lossy) if lossy else "no sequence gaps")
        return "\n".join(lines)
