"""Hypothesis strategies that build any registered wire message from its declared fields."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from omninav.schemas.codec import _plan

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
text = st.text(max_size=12)


def _array_strategy(spec):
    dims = tuple(st.integers(0, 6) if n is None else st.just(n) for n in spec.shape)
    dtype = np.dtype(spec.dtype)
    if dtype.kind == "f":
        elements = st.floats(allow_nan=spec.allow_nonfinite, allow_infinity=spec.allow_nonfinite,
                             width=dtype.itemsize * 8)
    else:
        info = np.iinfo(dtype)
        elements = st.integers(int(info.min), int(info.max))
    return st.tuples(*dims).flatmap(lambda shape: arrays(dtype, shape, elements=elements))


def struct_strategy(cls):
    fields = {}
    for f in _plan(cls):
        if f.kind == "array":
            fields[f.name] = _array_strategy(f.array)
        elif f.kind == "struct":
            fields[f.name] = struct_strategy(f.struct)
        elif f.kind == "float":
            fields[f.name] = st.floats(allow_nan=False, width=64) if f.allow_nonfinite else finite
        elif f.kind == "int":
            fields[f.name] = st.integers(0, 2**63 - 1)
        elif f.kind == "str":
            fields[f.name] = text
        elif f.kind == "bool":
            fields[f.name] = st.booleans()
        else:
            fields[f.name] = st.dictionaries(text, st.one_of(st.integers(-2**31, 2**31), finite, text), max_size=4)
    return st.builds(cls, **fields)
