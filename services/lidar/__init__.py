"""The lidar service: a simulated 2-D laser scanner over the sim's ground truth and world."""
