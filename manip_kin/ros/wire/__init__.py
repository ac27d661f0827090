"""Messages on the wire: ROS messages <-> numpy, pre-serialised CDR, validation, topic names."""
