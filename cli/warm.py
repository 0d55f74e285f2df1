"""`omninav warm`: compile every kernel the services warm up into numba's cache (`cache=True`: beside
each source file, in __pycache__), once after installing — `make venv` runs it. On a cold cache each
service compiled its kernels as it started, seconds each, and processes starting together compiled
the same kernels side by side: `navigate --composed` in the room took 48 s to its first goal, 5.7 s
once warmed (load average 5-6; `omninav warm` itself 37 s). A kernel whose source changed is
compiled again at its first use."""
from __future__ import annotations

import argparse

from ..services.runtime.kernels import warm_all


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def main(args: argparse.Namespace) -> int:
    warm_all(lambda name, seconds: print(f"warm: {name} in {seconds:.1f} s", flush=True))
    return 0
