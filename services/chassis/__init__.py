"""The chassis service: drive kinematics and limits, wheel and follower-wheel odometry."""
