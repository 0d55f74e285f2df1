"""Bench results files: the JSON a bench prints under `--json`, kept with where and how it was measured.

`omninav bench NAME --save-results [DIR]` runs the bench as `--json` would, prints the same object, and
writes it to DIR (default docs/results/) wrapped with its provenance: the command line, the git
commit and whether the tree was dirty, the date (UTC), the machine's cores and load average at the
start and the end, and the wall duration. `omninav bench report` writes docs/measurements.md and
the README's headline table from these files, so no figure is copied by hand.

Files transcribed from the record kept as text before results files existed carry
`"source": "transcribed from …"` instead of a measured provenance (see docs/results/README.md).
"""
from __future__ import annotations

import contextlib
import datetime as dt
import io
import json
import os
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# relative to the directory the bench runs in (the repository), as compose files' paths are
RESULTS_DIR = Path("docs") / "results"
INTERRUPTED = 130     # Ctrl-C: the figures are of the runs done so far
FORMAT = 1


def git_state(repo: Path = REPO) -> tuple[str | None, bool | None]:
    """(commit, dirty) of the checkout the bench ran from; (None, None) outside a git work tree."""
    def git(*argv: str) -> str:
        return subprocess.run(["git", "-C", str(repo), *argv], capture_output=True, text=True, check=True).stdout
    try:
        commit = git("rev-parse", "HEAD").strip()
        # results files written by earlier runs are not the code: a tree dirty only there is clean
        dirty = bool(git("status", "--porcelain", "--", ".", ":(exclude)docs/results").strip())
    except (OSError, subprocess.CalledProcessError):
        return None, None
    return commit, dirty


def machine_load() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


class _Tee(io.TextIOBase):
    """Writes through to the real stdout and keeps a copy, so the bench prints as it always does."""

    def __init__(self, through):
        self.through = through
        self.copy = io.StringIO()

    def write(self, text: str) -> int:
        self.copy.write(text)
        return self.through.write(text)

    def flush(self) -> None:
        self.through.flush()

    def fileno(self) -> int:
        return self.through.fileno()

    def isatty(self) -> bool:
        return self.through.isatty()


def last_json_object(text: str) -> dict | None:
    """The last JSON object printed on lines of its own (one line, or indented over several)."""
    decoder = json.JSONDecoder()
    found = None
    for match in re.finditer(r"^\{", text, flags=re.MULTILINE):
        try:
            value, _ = decoder.raw_decode(text, match.start())
        except json.JSONDecodeError:
            continue
        if isinstance(value, dict):
            found = value
    return found


@contextlib.contextmanager
def captured_stdout() -> Iterator[_Tee]:
    tee = _Tee(sys.stdout)
    saved, sys.stdout = sys.stdout, tee
    try:
        yield tee
    finally:
        sys.stdout = saved


def results_file_name(bench: str, started: dt.datetime) -> str:
    return f"{started.strftime('%Y-%m-%dT%H%M%SZ')}-{bench}.json"


def run_recorded(bench: str, argv: list[str], run: Callable[[], int], results_dir: Path = RESULTS_DIR) -> int:
    """Run `run` (a bench already set to --json), print what it prints, and keep its JSON with provenance.

    A bench that finished with its aim missed exits nonzero and is kept all the same, with its exit
    code (a record of only the runs that met their aims would be no record). Nothing is written when
    it printed no JSON object (it broke) or was interrupted: a results file is a finished run.
    """
    commit, dirty = git_state()
    started = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    load_start, t0 = machine_load(), time.monotonic()
    with captured_stdout() as tee:
        code = run()
    duration = time.monotonic() - t0
    figures = last_json_object(tee.copy.getvalue())
    interrupted = code == INTERRUPTED or (figures or {}).get("interrupted") is True
    if figures is None or interrupted:
        why = "interrupted" if interrupted else f"no JSON object printed (exit code {code})"
        print(f"omninav bench {bench} --save-results: nothing written ({why})", file=sys.stderr)
        return code or 1
    record = {
        "format": FORMAT,
        "bench": bench,
        "source": "measured",
        "command": shlex.join(["omninav", "bench", bench, *argv]),
        "commit": commit,
        "dirty": dirty,
        "date_utc": started.isoformat().replace("+00:00", "Z"),
        "machine": {"cores": os.cpu_count(), "load_start": load_start, "load_end": machine_load()},
        "duration_s": round(duration, 1),
        "exit_code": code,
        "figures": figures,
    }
    results_dir.mkdir(parents=True, exist_ok=True)
    path = results_dir / results_file_name(bench, started)
    path.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
    print(f"omninav bench {bench}: recorded {path}", file=sys.stderr)
    return code


def load_results(results_dir: Path = RESULTS_DIR) -> list[tuple[Path, dict]]:
    """Every results file in the folder, in file-name order; a file that is not a results object is an error."""
    out = []
    for path in sorted(results_dir.glob("*.json")):
        try:
            record = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not JSON ({exc})") from None
        if not isinstance(record, dict) or "bench" not in record:
            raise ValueError(f"{path}: not a results file (no 'bench')")
        out.append((path, record))
    return out
