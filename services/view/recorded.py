"""A recording's messages through a viewer's routes, for the exports (mcap_export.py, rerun_export.py).

Only the recording is read; each message the routes show is decoded and converted, each recorded
payload that does not decode is counted under 'malformed/<key>' and skipped.
"""
from __future__ import annotations

from collections import Counter
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

from ...schemas import MessageError, decode
from ...schemas.keys import type_for_key
from ..recorder.mcap_io import read_records
from .convert import Converter, RouteTable


@contextmanager
def new_output(target: str | Path) -> Iterator[Path]:
    """The export's output, which must not exist yet (FileExistsError); if the export fails - a
    recording that is missing or not MCAP is found only once the output is open - the half-written
    file goes again, so a bad input leaves nothing behind."""
    target = Path(target)
    if target.exists():
        raise FileExistsError(f"{target} exists; the export never overwrites a file (choose another output)")
    try:
        yield target
    except BaseException:
        target.unlink(missing_ok=True)
        raise


def routed_records(source: str | Path, routes: RouteTable, converter: Converter, counts: Counter[str],
                   on_record: Callable[[], None] | None = None) -> Iterator[tuple[Any, list]]:
    """(decoded message, its outputs) for every recorded message a route takes, in recorded order;
    raises RecordingError for an unreadable source. on_record() is called after each recorded
    message is read (a progress bar)."""
    for record in read_records(source):
        if on_record is not None:
            on_record()
        route = routes.route_for(record.key)
        if route is None:
            continue
        try:
            msg = decode(record.payload, type_for_key(record.key), key=record.key)
        except MessageError:
            counts[f"malformed/{record.key}"] += 1
            continue
        yield msg, converter.outputs(route, msg)
