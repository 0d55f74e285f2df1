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
