"""`omninav scenario generate --kind K [--difficulty D | --robot R] --seed N -o W.yaml`: write a generated world file."""
from __future__ import annotations

import argparse
from pathlib import Path

from ...services.runtime.errors import exits_2_on_user_error
from . import KINDS, VARIANT_KINDS, ScenarioError, generate_world, world_text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    generate = sub.add_parser("generate", help="draw a world of one kind from a seed and write it")
    generate.add_argument("--kind", required=True, help=f"one of {', '.join(sorted({*KINDS, *VARIANT_KINDS}))}")
    for kind, variants in sorted(VARIANT_KINDS.items()):
        generate.add_argument(f"--{variants.option}", help=f"for {kind} (and only): {' | '.join(variants.values)}")
    generate.add_argument("--seed", type=int, default=0, help="the same seed always gives the same file (default 0)")
    generate.add_argument("-o", "--out", required=True, metavar="W.yaml", help="the world file to write")


@exits_2_on_user_error("scenario")
def main(args: argparse.Namespace) -> int:
    given = [(v.option, getattr(args, v.option)) for v in VARIANT_KINDS.values() if getattr(args, v.option) is not None]
    if len(given) > 1:
        raise ScenarioError(f"one variant at most: got {' and '.join(f'--{o} {v}' for o, v in given)}")
    variant = given[0][1] if given else None
    text = world_text(generate_world(args.kind, args.seed, variant))
    out = Path(args.out)
    if not out.parent.is_dir():
        raise ScenarioError(f"cannot write {out}: no folder {out.parent}")
    out.write_text(text)
    print(f"{out}: a {args.kind} world ({f'{variant}, ' if variant else ''}seed {args.seed})")
    return 0
