"""A service's state kept in a small file, so that a restarted process resumes where the killed
one was: the localizer's pose, the chassis's odometry, the navigator's active goal.

The file is replaced atomically (written beside it, then renamed over it): a process killed
mid-write leaves the previous state, never half of one. It is read back into a frozen dataclass
with load_params, so a damaged or foreign file is a ParamError naming the file and the field.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import yaml

from ...parameters.from_mapping import load_params
from .params import read_params_mapping

# libyaml's emitter where PyYAML was built with it: the same text as safe_dump's in a quarter of the
# time (0.2 against 0.8 ms for the chassis's odometry, which it saves ten times a sim second)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def write_state(path: str | Path, state: Any, comment: str) -> None:
    """Replace the file at `path` with the dataclass `state` (YAML, one `# comment` line first)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.part")
    values = {k: _plain(v) for k, v in dataclasses.asdict(state).items()}
    tmp.write_text(f"# {comment}\n" + yaml.dump(values, Dumper=_DUMPER, sort_keys=False))
    os.replace(tmp, path)


def read_state(cls: type, path: str | Path) -> Any:
    """The state saved at `path` as a `cls` (ParamError naming the file if it is damaged)."""
    return load_params(cls, read_params_mapping(path), str(path))


def remove_state(path: str | Path) -> None:
    """Forget the state: nothing is left to resume."""
    Path(path).unlink(missing_ok=True)


def _plain(value: Any) -> Any:
    """numpy scalars and tuples as the plain YAML numbers and lists load_params reads back."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (str, bool, int)) and not hasattr(value, "dtype"):
        return value
    return float(value)
