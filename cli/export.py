"""`omninav export --foxglove IN.mcap -o OUT.mcap`: a recording for the Foxglove app (or any MCAP viewer
that knows Foxglove's well-known schemas): map, costmaps, scans, frames, robot, paths, goals, movers
and diagnostics, the channels of `omninav view`.
`omninav export --rerun IN.mcap -o OUT.rrd`: the same as a Rerun file, the entities of
`omninav view --rerun`; `rerun --serve-web --bind 127.0.0.1 OUT.rrd` shows it in a browser.
IN.mcap is only read."""
from __future__ import annotations

import argparse

from mcap.exceptions import McapError

from ..experiments.progress import progress
from ..services.recorder.mcap_io import RecordingError, recording_summary
from ..services.runtime.errors import UserError, exits_2_on_user_error
from .view import rerun_missing


def recorded_messages(path: str) -> int | None:
    """How many messages a recording holds (its summary's statistics); None when it cannot say (the
    export then names what is wrong with it)."""
    try:
        return recording_summary(path).statistics.message_count
    except (McapError, OSError):
        return None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="an omninav recording (MCAP, msgpack messages)")
    form = parser.add_mutually_exclusive_group(required=True)
    form.add_argument("--foxglove", action="store_true", help="an MCAP file in Foxglove's well-known schemas")
    form.add_argument("--rerun", action="store_true", help="a Rerun file (.rrd) for Rerun's viewer")
    parser.add_argument("-o", "--output", required=True, help="the file to write (must not exist)")
    parser.add_argument("--robot", default="r1", help="robot namespace (default r1)")


@exits_2_on_user_error("export")
def main(args: argparse.Namespace) -> int:
    if args.rerun:
        if missing := rerun_missing("export"):
            raise UserError(missing)
        from ..services.view.rerun_export import export_rerun as export      # rerun-sdk only when exporting
    else:
        from ..services.view.mcap_export import export_foxglove as export    # foxglove-sdk only when exporting
    try:
        with progress(recorded_messages(args.input), "messages") as bar:
            counts = export(args.input, args.output, args.robot, on_record=bar.advance)
    except (RecordingError, FileExistsError) as exc:
        raise UserError(str(exc)) from None
    exported = {topic: n for topic, n in counts.items() if not topic.startswith("malformed/")}
    print(f"wrote {sum(exported.values())} messages on {len(exported)} {'entities' if args.rerun else 'channels'} "
          f"to {args.output}")
    for topic, n in sorted(counts.items()):
        print(f"  {topic:32s} {n:8d}")
    return 0
