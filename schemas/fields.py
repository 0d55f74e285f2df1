"""Field declarations for wire messages: what each field may hold, checked on decode."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ArraySpec:
    """A numpy field: its dtype and shape; None in `shape` means any length on that axis."""

    dtype: str
    shape: tuple[int | None, ...]
    allow_nonfinite: bool = False

    def empty(self) -> np.ndarray:
        return np.zeros(tuple(0 if n is None else n for n in self.shape), dtype=self.dtype)


def array(dtype: str, shape: tuple[int | None, ...], *, allow_nonfinite: bool = False) -> Any:
    """Declare an ndarray field (defaults to an empty array of that shape)."""
    spec = ArraySpec(np.dtype(dtype).str, shape, allow_nonfinite)
    return dataclasses.field(default_factory=spec.empty, metadata={"array": spec})


def real(default: float = 0.0, *, allow_nonfinite: bool = False) -> Any:
    """A float field; NaN and infinities are refused unless allowed."""
    return dataclasses.field(default=default, metadata={"allow_nonfinite": allow_nonfinite})


def sign_bytes(values: np.ndarray) -> bytes:
    """The byte of each float that holds its sign bit and the top seven bits of its exponent, in
    one C-level slice of the array's bytes: far cheaper than a numpy reduction on a cold cache
    (a scan's decode in a round trip runs cold: docs/introspection.md). Every byte below 0x80: no
    value is negative (nor -0.0, -inf or a NaN with its sign set). No byte 0x7F or 0xFF: every
    value is finite (either byte may also be a finite value above 2**127 (float32) or 2**1008
    (float64), for which the exact check runs)."""
    itemsize, order = values.dtype.itemsize, values.dtype.byteorder
    big_endian = order == ">" or (order == "=" and not np.little_endian)
    return values.tobytes()[0 if big_endian else itemsize - 1::itemsize]


def surely_finite(values: np.ndarray) -> bool:
    """True only when every value of a float array is finite; False: look closer."""
    high = sign_bytes(values)
    return b"\x7f" not in high and b"\xff" not in high
