"""Laser odometry: scans matched to a local map (hector's grids and matcher), odometry with covariance."""
