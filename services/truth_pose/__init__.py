"""truth_pose: the simulator's ground truth published as the localization (navigate --localization truth)."""
