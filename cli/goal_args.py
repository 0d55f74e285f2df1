"""`--goal X Y YAW` as the commands take it: metres, metres, and a heading in degrees unless it says
`rad` (`90`, `90deg`, `1.57rad`), since world files and messages use radians while people type
degrees. Parsed goals are (x, y, yaw in radians)."""
from __future__ import annotations

import argparse
import math
import re

_ANGLE = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(deg|rad)?\s*")
_NEGATIVE_NUMBER = re.compile(r"^-\.?\d")
YAW_HELP = "YAW in degrees, or with a unit: 90deg, 1.57rad"


def parse_yaw(text: str) -> float:
    """Radians from '90', '90deg' or '1.57rad'; ValueError naming what is wrong."""
    match = _ANGLE.fullmatch(text)
    if match is None:
        raise ValueError(f"yaw {text!r} is not a number with an optional unit deg or rad (90, 90deg, 1.57rad)")
    value = float(match.group(1))
    if not math.isfinite(value):
        raise ValueError(f"yaw {text!r} is not finite")
    return value if match.group(2) == "rad" else math.radians(value)


class GoalAction(argparse.Action):
    """Appends (x, y, yaw_rad) for each --goal X Y YAW; a bad value is a usage error naming it."""

    def __call__(self, parser, namespace, values, option_string=None):
        x, y, yaw = values
        try:
            goal = (float(x), float(y), parse_yaw(yaw))
        except ValueError as exc:
            text = str(exc) if str(exc).startswith("yaw") else f"X and Y must be numbers in metres, got {x!r} {y!r}"
            parser.error(f"{option_string} {x} {y} {yaw}: {text}")
        if not all(math.isfinite(v) for v in goal):
            parser.error(f"{option_string} {x} {y} {yaw}: not a finite pose")
        items = list(getattr(namespace, self.dest) or [])
        items.append(goal)
        setattr(namespace, self.dest, items)


def add_goal_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """--goal X Y YAW, repeatable; `what` says where the goal is and what the default is."""
    parser.add_argument("--goal", nargs=3, action=GoalAction, metavar=("X", "Y", "YAW"),
                        help=f"{what}: metres, metres, {YAW_HELP}; repeat for several, visited in order")
    # argparse before Python 3.13 takes '-1.57rad' for an option (only bare numbers count as negative
    # numbers); 3.13 recognises a negative number by its start, as here. The commands have no option
    # that starts with a digit, so nothing else changes.
    parser._negative_number_matcher = _NEGATIVE_NUMBER
