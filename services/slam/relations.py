"""The relations metric of Kümmerle et al. 2009, "On measuring the accuracy of SLAM algorithms".

A relation (t1, t2, δ*) is the true motion from the robot's pose at t1 to its pose at t2,
expressed in the frame of the first. For an estimated trajectory, the poses x̂1, x̂2 at t1 and t2
are interpolated, δ = x̂1⁻¹ ⊕ x̂2 and the error e = δ ⊖ δ* (= δ*⁻¹ ⊕ δ). Reported: mean and
standard deviation of |trans(e)| (m) and |rot(e)| (degrees), and the means of their squares.
Because only relative motions are compared, the estimate's frame does not matter.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...geometry.se2 import relative, wrap_angle


class RelationsError(ValueError):
    """A relations file that is missing or malformed."""


def load_relations(path: str | Path) -> np.ndarray:
    """Rows (t1, t2, x, y, yaw) from a file of 't1 t2 x y z roll pitch yaw' lines (times in s)."""
    path = Path(path)
    if not path.is_file():
        raise RelationsError(f"{path}: no such file")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != 8:
            raise RelationsError(f"{path}: line {number}: expected 't1 t2 x y z roll pitch yaw', got {len(fields)} fields")
        try:
            t1, t2, x, y, _z, _roll, _pitch, yaw = (float(f) for f in fields)
        except ValueError:
            raise RelationsError(f"{path}: line {number}: a field is not a number") from None
        rows.append((t1, t2, x, y, yaw))
    if not rows:
        raise RelationsError(f"{path}: no relations in this file")
    return np.array(rows)


def interpolate(stamps, poses, times) -> tuple[np.ndarray, np.ndarray]:
    """Poses at `times` by linear interpolation between the two neighbouring stamps (the heading
    along the shorter way round); returns (poses, inside) where `inside` marks times within the
    stamps' span (outside it, the first or last pose is given)."""
    stamps = np.asarray(stamps, np.float64)
    poses = np.asarray(poses, np.float64)
    times = np.asarray(times, np.float64)
    inside = (times >= stamps[0]) & (times <= stamps[-1])
    hi = np.clip(np.searchsorted(stamps, times, side="left"), 1, len(stamps) - 1) if len(stamps) > 1 \
        else np.zeros(len(times), np.int64)
    lo = np.maximum(hi - 1, 0)
    span = stamps[hi] - stamps[lo]
    f = np.clip(np.where(span > 0, (times - stamps[lo]) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)
    xy = poses[lo, :2] + f[:, None] * (poses[hi, :2] - poses[lo, :2])
    th = poses[lo, 2] + f * wrap_angle(poses[hi, 2] - poses[lo, 2])
    return np.column_stack([xy, wrap_angle(th)]), inside


def relation_errors(stamps, poses, relations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translational error m, rotational error rad, used) per relation; `used` is False where a
    relation's times fall outside the trajectory (its errors are NaN)."""
    relations = np.asarray(relations, np.float64)
    # times relative to the first stamp keep sub-microsecond precision in float64
    t0 = float(np.asarray(stamps, np.float64)[0])
    stamps = np.asarray(stamps, np.float64) - t0
    x1, in1 = interpolate(stamps, poses, relations[:, 0] - t0)
    x2, in2 = interpolate(stamps, poses, relations[:, 1] - t0)
    error = relative(relations[:, 2:5], relative(x1, x2))
    used = in1 & in2
    trans = np.where(used, np.hypot(error[:, 0], error[:, 1]), np.nan)
    rot = np.where(used, np.abs(error[:, 2]), np.nan)
    return trans, rot, used


def score(stamps, poses, relations) -> dict:
    """The metric's figures for a trajectory (stamps in s, poses (n, 3)) against relations."""
    trans, rot, used = relation_errors(stamps, poses, relations)
    trans, rot_deg = trans[used], np.degrees(rot[used])
    if not len(trans):
        raise RelationsError("no relation lies within the trajectory's time span")
    return {"relations": int(used.sum()), "relations_outside": int((~used).sum()),
            "trans_abs_mean_m": float(trans.mean()), "trans_abs_std_m": float(trans.std()),
            "trans_sq_mean": float(np.mean(trans ** 2)), "trans_sq_std": float(np.std(trans ** 2)),
            "rot_abs_mean_deg": float(rot_deg.mean()), "rot_abs_std_deg": float(rot_deg.std()),
            "rot_sq_mean": float(np.mean(rot_deg ** 2)), "rot_sq_std": float(np.std(rot_deg ** 2))}
