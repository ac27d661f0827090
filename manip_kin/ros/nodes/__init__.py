"""The node programs: thin adapters between ROS topics and one core object each."""
