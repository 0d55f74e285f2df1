"""The local planner cores: DWA / trajectory rollout, the path follower, the velocity smoother and the
collision monitor (pure numpy/numba; the node lives elsewhere)."""
