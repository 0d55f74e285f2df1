"""`omninav services`: the registered services."""
from __future__ import annotations

import argparse

from ..services.runtime.service_registry import SERVICES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def main(args: argparse.Namespace) -> int:
    for name, target in sorted(SERVICES.items()):
        print(f"{name:16s} {target}")
    return 0
