"""The neutral layer: geometry several rooms share (grid cells, ray casting, polygons and footprints,
odometry history, robot frames, SE(2)). numpy/numba and the message types of `schemas` only; it
imports no service, no sim, no runtime, so any core may stand on it."""
