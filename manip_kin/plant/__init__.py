"""Plants: what robot_state drives with the joint-rate command (without ROS).

* :class:`~manip_kin.plant.kinematic.KinematicPlant`: a perfect integrator (the default);
* :class:`~manip_kin.plant.mujoco_plant.MujocoPlant`: MuJoCo rigid-body dynamics with
  gravity, a velocity servo per joint with torque limits, and contact with obstacles.

Both take ``step(command, dt)`` (joint rates, shape (n,), or None for "no fresh command")
and then hold the same outputs (:class:`~manip_kin.plant.outputs.ChainOutputs`: positions,
velocities, efforts, poses and twists as plain floats), ``set_scene(scene)`` and
``take_contact()``.
"""

import os

# mujoco picks its OpenGL backend when first imported, and every manip_kin import of it comes
# through this package: without a display its default (GLFW) cannot render offscreen, EGL can.
os.environ.setdefault("MUJOCO_GL", "egl")

from manip_kin.plant.kinematic import KinematicPlant  # noqa: E402

#: Values of robot_state's ``plant`` parameter.
PLANT_NAMES = ("kinematic", "mujoco")

__all__ = ["PLANT_NAMES", "KinematicPlant"]
