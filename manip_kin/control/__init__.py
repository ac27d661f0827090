"""Control laws and what shapes their commands: limits, integration, prediction, state machines, servoing, the QP law, offline simulation (no ROS)."""
