"""The ROS 2 side: the wire format (``wire``), the node runtime (``runtime``) and the node programs (``nodes``)."""
