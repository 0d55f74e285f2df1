"""`omninav recover FILE [-o OUT]`: rewrite what is readable of a damaged recording as a valid MCAP file.

A recorder killed with SIGKILL leaves a file without its summary and with a half-written tail; every
chunk it flushed is still there. This reads those (stopping at the first record that does not
check out), and writes them to a new file with the same keys, types, times and sequence numbers.
The input is only ever read.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from mcap.exceptions import McapError

from .mcap_io import RecordingWriter, check_mcap_file, read_readable_records


def default_output(path: Path) -> Path:
    return path.with_name(f"{path.stem}.recovered.mcap")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="the damaged MCAP recording (never modified)")
    parser.add_argument("-o", "--output", help="where to write (default FILE with suffix .recovered.mcap)")
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")


def _fail(message: str) -> int:
    print(f"omninav recover: {message}", file=sys.stderr)
    return 2


def main(args: argparse.Namespace) -> int:
    try:
        src = check_mcap_file(args.file)
    except (FileNotFoundError, McapError) as exc:
        return _fail(str(exc))
    out = Path(args.output) if args.output else default_output(src)
    if out.exists() and out.samefile(src):
        return _fail(f"{out} is the input file; choose another output")
    if out.exists() and not args.force:
        return _fail(f"{out} exists; use --force to replace it")
    records, why = read_readable_records(src)
    # written beside the target and renamed at the end, so a failure never leaves half a file at OUT
    partial = out.with_name(f".{out.name}.partial")
    try:
        with RecordingWriter(partial, metadata={"recovered_from": src.name, "stopped": why or "end of file"}) as writer:
            for rec in records:
                writer.write_record(rec)
        os.replace(partial, out)
    except OSError as exc:
        partial.unlink(missing_ok=True)
        return _fail(f"cannot write {out}: {exc}")
    keys = len({rec.key for rec in records})
    print(f"saved {len(records)} messages on {keys} key{'' if keys == 1 else 's'} from {src} to {out}")
    print(f"reading stopped early: {why}" if why else "the input was complete: every message was saved")
    return 0
