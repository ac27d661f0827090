"""manip_kin: kinematic control of serial manipulators.

The core (model, kinematics, IK, control, trajectories, simulation) is plain
numpy and never imports rclpy; ROS nodes live in :mod:`manip_kin.ros.nodes`.
"""

__version__ = "0.1.0"
