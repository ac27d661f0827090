"""Motions to follow: straight pose lines and joint-space trajectories, with their timing checks (no ROS)."""
