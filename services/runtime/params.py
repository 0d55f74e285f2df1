"""Typed parameters: one frozen dataclass per core, loaded from YAML with errors that name the key.

ROS parameter files load unchanged: a ROS 2 file ({node: {ros__parameters: {...}}}) or a ROS 1
file (flat, or under the node's name) both give the flat mapping.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import typing
from pathlib import Path
from typing import Any, Callable

import yaml


class ParamError(ValueError):
    """A parameter that is unknown, of the wrong type or out of range; says which and where."""


def read_yaml(path: str | Path) -> Any:
    path = Path(path)
    if not path.is_file():
        raise ParamError(f"{path}: no such file")
    try:
        return yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ParamError(f"{path}: not valid YAML: {exc}") from None


def unwrap_ros(mapping: dict, node_name: str = "") -> dict:
    """Strip the ROS 2 `node: ros__parameters:` or ROS 1 `node:` wrapping, if present."""
    if len(mapping) == 1:
        (only_key, inner), = mapping.items()
        if isinstance(inner, dict) and "ros__parameters" in inner:
            return inner["ros__parameters"] or {}
        if only_key == node_name and isinstance(inner, dict):
            return inner
    if "ros__parameters" in mapping:
        return mapping["ros__parameters"] or {}
    return mapping


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
    if origin is typing.Union or origin is getattr(__import__("types"), "UnionType", None):
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


def load_params(cls: type, values: dict | None, source: str = "parameters") -> Any:
    """Build `cls` (a dataclass) from a mapping; unknown names and wrong types raise ParamError."""
    values = dict(values or {})
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls) if f.init}
    problem = unknown_names(values, known, "parameter")
    if problem:
        raise ParamError(f"{source}: {cls.__name__}: {problem}")
    kwargs = {name: _coerce(name, hints[name], v, source) for name, v in values.items()}
    for name, v in kwargs.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise ParamError(f"{source}: parameter {name!r} must be finite, got {v}")
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:  # __post_init__ range checks
        raise ParamError(f"{source}: {exc}") from None


def require_nonnegative(params: Any, *names: str) -> None:
    """For a dataclass's __post_init__: ValueError naming the first of its fields `names` that is
    not a finite number ≥ 0 (load_params turns it into a ParamError naming the source)."""
    _require(params, names, lambda value: value >= 0, "zero or positive")


def require_positive(params: Any, *names: str) -> None:
    """As require_nonnegative, for fields that must be finite and > 0."""
    _require(params, names, lambda value: value > 0, "positive")


def require_at_least(params: Any, minimum: float, *names: str) -> None:
    """As require_nonnegative, for fields that must be finite and ≥ minimum (counts: 1)."""
    _require(params, names, lambda value: value >= minimum, f"≥ {minimum}")


def _require(params: Any, names: tuple[str, ...], within: Callable[[float], bool], what: str) -> None:
    for name in names:
        value = getattr(params, name)
        if not (math.isfinite(value) and within(value)):
            raise ValueError(f"{name} must be {what}, got {value}")


def read_params_mapping(path: str | Path, node_name: str = "") -> dict:
    """The flat parameter mapping of a ROS 1 or ROS 2 style YAML file."""
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ParamError(f"{path}: expected a mapping of parameter names to values")
    return unwrap_ros(data, node_name)


def load_params_file(cls: type, path: str | Path, node_name: str = "") -> Any:
    return load_params(cls, read_params_mapping(path, node_name), str(path))


def parse_overrides(pairs: list[str]) -> dict:
    """`name=value` strings (values parsed as YAML scalars) into a mapping."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        if not sep or not name:
            raise ParamError(f"override {pair!r} is not name=value")
        out[name] = yaml.safe_load(raw)
    return out
