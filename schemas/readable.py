"""Decoded messages as people read them: a JSON-able dict, and YAML-like text built from it.

Large ndarrays are summarised (dtype, shape, the first few values) unless `full` is asked for;
small ones (covariances, a few wheels) are always shown whole. Non-finite floats become the
strings "inf", "-inf" and "nan" so that the dict is strict JSON.
"""
from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

import numpy as np

from .registry import type_info

TYPE_FIELD = "_type"
HEAD = 6            # values shown of a summarised array
SMALL_ARRAY = 16    # arrays up to this many values are shown whole


class ArraySummary(dict):
    """{"dtype", "shape", "first"}: a dict, so it is JSON-able; its own class, so text can inline it."""


def _number(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


def _values(arr: np.ndarray) -> list:
    """Array values as Python numbers; float32 keeps its short decimal form (1.2, not 1.2000000476…)."""
    if arr.dtype.kind == "f" and arr.dtype.itemsize < 8:
        flat = [_number(float(str(v))) for v in arr.reshape(-1)]
    else:
        flat = [_number(v) for v in arr.reshape(-1).tolist()]
    for n in reversed(arr.shape[1:]):  # regroup into the array's rows
        flat = [flat[i:i + n] for i in range(0, len(flat), n)] if n else []
    return flat


def _array(arr: np.ndarray, full: bool) -> Any:
    if full or arr.size <= SMALL_ARRAY:
        return _values(arr)
    return ArraySummary(dtype=arr.dtype.name, shape=list(arr.shape), first=_values(arr.reshape(-1)[:HEAD]))


def _plain(value: Any, full: bool) -> Any:
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name), full) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        return _array(value, full)
    if isinstance(value, dict):
        return {str(k): _plain(v, full) for k, v in value.items()}
    return _number(value)


def to_plain(msg: Any, *, full: bool = False) -> dict:
    """A message as a JSON-able dict, its type name first under "_type"."""
    return {TYPE_FIELD: type_info(type(msg))[0], **_plain(msg, full)}


def _inline(value: Any) -> str:
    if isinstance(value, ArraySummary):
        shape = ", ".join(map(str, value["shape"]))
        return f"{value['dtype']}[{shape}] {_inline(value['first'])[:-1]}, ...]"
    if isinstance(value, list):
        return "[" + ", ".join(_inline(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_inline(v)}" for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str) and value not in ("inf", "-inf", "nan"):
        return json.dumps(value, ensure_ascii=False)
    return str(value)


def plain_to_text(plain: dict, indent: str = "") -> str:
    """YAML-like lines: nested structs indented, arrays and summaries on one line."""
    lines = []
    for name, value in plain.items():
        if isinstance(value, dict) and not isinstance(value, ArraySummary) and value:
            lines.append(f"{indent}{name}:")
            lines.append(plain_to_text(value, indent + "  "))
        else:
            lines.append(f"{indent}{name}: {_inline(value)}")
    return "\n".join(lines)


def to_text(msg: Any, *, full: bool = False) -> str:
    """A message as readable YAML-like text (without its type line; callers print that with the key)."""
    plain = to_plain(msg, full=full)
    del plain[TYPE_FIELD]
    return plain_to_text(plain)
