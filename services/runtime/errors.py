"""User errors: a bad file, argument or request, told in one line with exit status 2, no traceback."""
from __future__ import annotations

import functools
import sys
from typing import Callable


class UserError(Exception):
    """A mistake in what the user asked for; the text says what is wrong."""


def exits_2_on_user_error(program: str) -> Callable:
    """Decorate a command's main(args): a UserError becomes 'omninav PROGRAM: error: …' and exit 2."""
    def wrap(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def run(*args, **kwargs) -> int:
            try:
                return main(*args, **kwargs)
            except UserError as exc:
                print(f"omninav {program}: error: {exc}", file=sys.stderr)
                return 2
        return run
    return wrap
