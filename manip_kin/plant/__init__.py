"""Plants: what robot_state drives with the joint-rate command (without ROS).

* :class:`~manip_kin.plant.kinematic.KinematicPlant`: a perfect integrator (the default);
* :class:`~manip_kin.plant.mujoco_plant.MujocoPlant`: MuJoCo rigid-body dynamics with
  gravity, a velocity servo per joint with torque limits, and contact with obstacles.

Both take ``step(command, dt)`` (joint rates, shape (n,), or None for "no fresh command")
and then hold the same outputs (:class:`~manip_kin.plant.outputs.ChainOutputs`: positions,
velocities, efforts, poses and twists as plain floats), ``set_scene(scene)`` and
``take_contact()``.
"""

from manip_kin.plant.kinematic import KinematicPlant

#: Values of robot_state's ``plant`` parameter.
PLANT_NAMES = ("kinematic", "mujoco")

__all__ = ["PLANT_NAMES", "KinematicPlant"]
