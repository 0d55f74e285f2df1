"""Hypothesis strategies that build any registered wire message from its declared fields."""
from __future__ import annotations

import math

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


def sound(msg):
    """The message with its fields made consistent with each other (a scan's angles with its ranges,
    a grid's size with its data, symmetric covariances …), so the type's problem() finds nothing."""
    for name in getattr(msg, "__slots__", ()):
        value = getattr(msg, name)
        if hasattr(value, "__slots__"):
            sound(value)
        elif isinstance(value, np.ndarray) and value.ndim == 2 and value.shape[0] == value.shape[1] == 3 \
                and "covariance" in name:
            value = value / 2.0 + value.T / 2.0     # halves first: no overflow near the float limit
            np.fill_diagonal(value, np.abs(np.diagonal(value)))
            setattr(msg, name, value)
        elif isinstance(value, float) and name.endswith("_variance"):
            setattr(msg, name, abs(value))
    kind = type(msg).__name__
    if kind in ("OccupancyGrid", "Costmap"):
        msg.info.height, msg.info.width = msg.data.shape
        msg.info.resolution = abs(msg.info.resolution) + 0.01
        if kind == "OccupancyGrid":
            msg.data = np.clip(msg.data, -1, 100).astype(msg.data.dtype)
    elif kind == "LaserScan":
        msg.angle_increment = abs(msg.angle_increment) % 1.0 + 0.001
        msg.angle_min = math.fmod(msg.angle_min, 4.0)
        msg.angle_max = msg.angle_min + (len(msg.ranges) - 1) * msg.angle_increment
        msg.ranges = np.abs(msg.ranges)
        msg.intensities = msg.intensities[:0]
        msg.range_min, msg.range_max = sorted((abs(msg.range_min), abs(msg.range_max)))
    elif kind in ("WheelCommand", "WheelState"):
        msg.drive = "diff"
        msg.velocities = np.resize(msg.velocities, 2)
        if kind == "WheelState":
            msg.positions = np.resize(msg.positions, 2)
    elif kind == "ParticleCloud":
        n = min(len(msg.poses), len(msg.weights))
        msg.poses, msg.weights = msg.poses[:n], np.abs(msg.weights[:n])
    elif kind == "Obstacles":
        n = min(len(msg.circles), len(msg.velocities))
        msg.circles, msg.velocities = msg.circles[:n].copy(), msg.velocities[:n]
        msg.circles[:, 2] = np.abs(msg.circles[:, 2])
    elif kind == "Clock":
        msg.rate = abs(msg.rate) + 1.0
    elif kind == "PoseFit":
        msg.beam_fit = min(abs(msg.beam_fit), 1.0)
        msg.beams = abs(msg.beams)
    elif kind == "OdometryDoubt":
        msg.mahalanobis = abs(msg.mahalanobis)
    elif kind == "ClearCostmaps":
        msg.reset_distance = abs(msg.reset_distance)
    return msg
