"""The robot model and what follows from it directly: rotations, kinematics, loaders, bundled robots, URDF, scenes (no ROS)."""
