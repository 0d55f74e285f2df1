"""Lockstep missions side by side: one per worker process. Each mission is deterministic on its
own, so how many run at once changes only how long the whole takes."""
from __future__ import annotations

import multiprocessing
from typing import Callable, Iterable

from .progress import progress


def run_in_workers(function: Callable, jobs: Iterable, workers: int, on_result: Callable | None = None,
                   unit: str = "runs", quiet: bool = False) -> list:
    """function(job) for every job (a picklable module-level function) on `workers` fresh processes;
    the results in job order, each handed to on_result as soon as it and those before it are done.
    A progress bar counts the `unit`s done on a terminal unless quiet (--json)."""
    jobs = list(jobs)
    results = []
    # spawn, not fork: a forked child would inherit numba's and zenoh's threads mid-state
    with multiprocessing.get_context("spawn").Pool(max(1, min(workers, len(jobs)))) as pool, \
            progress(len(jobs), unit, quiet) as bar:
        for result in pool.imap(function, jobs):
            results.append(result)
            if on_result is not None:
                with bar.printing():
                    on_result(result)
            bar.advance()
    return results
