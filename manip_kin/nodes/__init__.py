"""ROS 2 nodes: thin adapters between ROS topics and the numpy core."""
