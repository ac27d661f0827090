"""Inverse kinematics: iterative (damped least squares with restarts) and closed form (no ROS)."""
