"""amcl's likelihood-field weighing written as plain vectorised numpy over an (N, beams) array: the
oracle tests/test_amcl_models.py and `omninav bench amcl` hold the numba kernel in sensor.py to."""
from __future__ import annotations

import numpy as np

from .sensor import LaserModel, ScanBeams

def likelihood_field_numpy(laser: LaserModel, poses: np.ndarray, scan_beams: ScanBeams) -> np.ndarray:
    """The reference: amcl's likelihood-field weight 1 + Σ pz³ per particle, as (N, beams) numpy arrays."""
    p = laser.params
    end_x, end_y = scan_beams.end_points()
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    x = poses[:, 0:1] + c * end_x - s * end_y
    y = poses[:, 1:2] + s * end_x + c * end_y
    a = laser.frame.affine
    col = np.floor(a[0, 0] * x + a[0, 1] * y + a[0, 2]).astype(np.int64)
    row = np.floor(a[1, 0] * x + a[1, 1] * y + a[1, 2]).astype(np.int64)
    height, width = laser.hit.shape
    inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
    hit = np.where(inside, laser.hit[np.clip(row, 0, height - 1), np.clip(col, 0, width - 1)],
                   np.float64(laser.off_map_hit))
    pz = p.laser_z_hit * hit + p.laser_z_rand / scan_beams.range_max
    return 1.0 + (pz ** 3).sum(axis=1)
