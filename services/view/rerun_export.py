"""A recording as a Rerun file (.rrd): the live Rerun view's entities (rerun_scene.py), logged at each
message's sim stamp on the sim_time timeline, with the view's layout as the default blueprint. The
input recording is only read. Open the file in the browser with
`rerun --serve-web --bind 127.0.0.1 OUT.rrd` (the `rerun` command comes with rerun-sdk).
"""
from __future__ import annotations

import uuid
from collections import Counter
from pathlib import Path
from typing import Callable

import rerun as rr

from ...schemas.keys import DEFAULT_ROBOT, KeyLayout
from .convert import Converter, RouteTable, ViewParams
from .recorded import new_output, routed_records
from .rerun_scene import APPLICATION_ID, RERUN_ROUTES, blueprint, log_at, log_static


def export_rerun(source: str | Path, target: str | Path, robot: str = DEFAULT_ROBOT,
                 params: ViewParams | None = None, on_record: Callable[[], None] | None = None) -> Counter[str]:
    """Write target from the recording at source; returns how many log calls went to each entity
    path, and under 'malformed/<key>' how many recorded payloads did not decode (they are skipped).
    Raises RecordingError for an unreadable source and FileExistsError when target exists."""
    routes = RouteTable(KeyLayout(robot), RERUN_ROUTES)
    converter = Converter(params)
    counts: Counter[str] = Counter()
    with new_output(target) as target:
        # its own stream (not the process-global one), so nothing else logged in this process lands in the file
        recording = rr.RecordingStream(APPLICATION_ID, recording_id=str(uuid.uuid4()))
        recording.save(target, default_blueprint=blueprint())
        try:
            log_static(recording)
            for msg, outputs in routed_records(source, routes, converter, counts, on_record):
                log_at(recording, msg.header.stamp_ns, outputs)
                counts.update(logged.path for logged in outputs)
        finally:
            recording.flush()
            recording.disconnect()
    return counts
