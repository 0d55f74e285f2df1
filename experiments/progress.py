"""A progress bar with an estimate for the long commands (benches, mapping, export, import): tqdm
on stderr, and nothing at all under --json or when stderr is not a terminal (a log, CI, a pipe).

tqdm (MPL/MIT, no dependencies of its own) rather than a bar of our own: its rate and remaining-time
estimate, terminal-width handling and clean interleaving with printed lines are what a bar needs.
"""
from __future__ import annotations

import contextlib
import sys
from typing import Iterator

from tqdm import tqdm


class Progress:
    """What a long command reports to: `advance()` after each unit of work, and `printing()` around
    its own output so a line never lands in the middle of the bar."""

    def __init__(self, bar: tqdm | None):
        self._bar = bar

    @property
    def drawn(self) -> bool:
        return self._bar is not None

    def advance(self, units: int = 1) -> None:
        if self._bar is not None:
            self._bar.update(units)

    def note(self, text: str) -> None:
        """What the bar says beside its count (the sim time, the goals sent)."""
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)

    def printing(self) -> contextlib.AbstractContextManager:
        return tqdm.external_write_mode(file=sys.stdout) if self._bar is not None else contextlib.nullcontext()


def shown(quiet: bool = False) -> bool:
    """Whether a bar is drawn: a terminal on stderr and no --json."""
    return not quiet and sys.stderr is not None and sys.stderr.isatty()


@contextlib.contextmanager
def progress(total: int | None, unit: str, quiet: bool = False) -> Iterator[Progress]:
    """A bar over `total` units (None: a count without an estimate) while the block runs."""
    if not shown(quiet):
        yield Progress(None)
        return
    with tqdm(total=total, unit=f" {unit}", file=sys.stderr, dynamic_ncols=True, leave=False) as bar:
        yield Progress(bar)
