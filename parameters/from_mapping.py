"""Build a parameter class from a mapping (a YAML file's, or ROS-style flat names): every name must
be a field (an unknown one is refused naming it, the closest known name and all known ones), every
value of the field's type (coerced: ints where floats are wanted, lists as tuples), then the class
checks what each field allows (declare.py). One function, load_params, for every parameter class.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from typing import Any

from .declare import ParamError


def _coerce(name: str, hint: Any, value: Any, source: str) -> Any:
    where = f"{source}: parameter {name!r}"
    origin = typing.get_origin(hint)
    if hint is bool:
        if isinstance(value, bool):
            return value
        raise ParamError(f"{where} must be true or false, got {value!r}")
    if hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ParamError(f"{where} must be an integer, got {value!r}")
    if hint is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ParamError(f"{where} must be a number, got {value!r}")
    if hint is str:
        if isinstance(value, str):
            return value
        raise ParamError(f"{where} must be a string, got {value!r}")
    if hint is dict or origin is dict:
        if isinstance(value, dict):
            return value
        raise ParamError(f"{where} must be a mapping of names to values, got {value!r}")
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ParamError(f"{where} must be a list, got {value!r}")
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ParamError(f"{where} must have {len(args)} items, got {len(value)}")
            return tuple(_coerce(name, a, v, source) for a, v in zip(args, value))
        item = args[0] if args else Any
        items = [v if item is Any else _coerce(name, item, v, source) for v in value]
        return tuple(items) if origin is tuple else items
    if origin is typing.Union or origin is types.UnionType:
        errors = []
        for option in typing.get_args(hint):
            if option is type(None):
                if value is None:
                    return None
                continue
            try:
                return _coerce(name, option, value, source)
            except ParamError as exc:
                errors.append(str(exc))
        raise ParamError(errors[0] if errors else f"{where}: unsupported value {value!r}")
    return value


def unknown_names(given, known, what: str = "key") -> str:
    """'' when every given name is known; else one line naming each unknown one with the closest
    known name: "unknown key 'boxs' (did you mean 'boxes'?)"."""
    known = sorted(map(str, known))
    parts = []
    for name in sorted(map(str, set(given) - set(known))):
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
        parts.append(f"unknown {what} {name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return "; ".join(parts) + (f"; known: {', '.join(known)}" if parts else "")


def load_params(cls: type, values: dict | None, source: str = "parameters", aliases=()) -> Any:
    """Build `cls` (a dataclass) from a mapping; unknown names and wrong types raise ParamError.
    aliases: names a caller already translated (another stack's), offered as known in the error."""
    values = dict(values or {})
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls) if f.init}
    problem = unknown_names(values, known | set(aliases), "parameter")
    if problem:
        raise ParamError(f"{source}: {cls.__name__}: {problem}")
    kwargs = {name: _coerce(name, hints[name], v, source) for name, v in values.items()}
    for name, v in kwargs.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise ParamError(f"{source}: parameter {name!r} must be finite, got {v}")
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:  # what a field or a rule allows (declare.check)
        raise ParamError(f"{source}: {exc}") from None
