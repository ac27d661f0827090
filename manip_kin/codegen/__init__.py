"""Code generation, the only place that writes Python source: unrolled kinematics, linear algebra, the control step and the IK iteration, and their one cache."""
