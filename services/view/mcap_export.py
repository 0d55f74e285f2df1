"""A recording in Foxglove's well-known schemas: the live view's channels, written with foxglove-sdk's
MCAP writer. The input recording is only read (its msgpack channels stay the replayable original).

log_time of every exported message is its sim stamp, so the Foxglove app's timeline is sim time.
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Callable

import foxglove

from ...schemas.keys import DEFAULT_ROBOT, KeyLayout
from .channels import ChannelSet
from .convert import Converter, RouteTable, ViewParams
from .recorded import new_output, routed_records

PROFILE = "omninav-foxglove"


def export_foxglove(source: str | Path, target: str | Path, robot: str = DEFAULT_ROBOT,
                    params: ViewParams | None = None, on_record: Callable[[], None] | None = None) -> Counter[str]:
    """Write target from the recording at source; returns how many messages went to each topic, and
    under 'malformed/<key>' how many recorded payloads did not decode (they are skipped). Raises
    RecordingError for an unreadable source and FileExistsError when target exists. on_record() is
    called after each recorded message is read (a progress bar)."""
    routes = RouteTable(KeyLayout(robot))
    converter = Converter(params)
    context = foxglove.Context()     # its own: nothing else logged in this process lands in the file
    channels = ChannelSet(context)
    counts: Counter[str] = Counter()
    with new_output(target) as target:
        writer = foxglove.open_mcap(target, context=context,
                                    writer_options=foxglove.mcap.MCAPWriteOptions(profile=PROFILE))
        try:
            for msg, outputs in routed_records(source, routes, converter, counts, on_record):
                for topic, message in outputs:
                    channels.log(topic, message, log_time_ns=max(msg.header.stamp_ns, 0))
                    counts[topic] += 1
        finally:
            writer.close()
            channels.close()
    return counts
