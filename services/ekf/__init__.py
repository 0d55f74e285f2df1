"""The odometry fusion service (issue 36): robot_localization's EKF over wheels, IMU and laser odometry, and its doubt."""
