"""URDF in and out: load a serial chain from a URDF, write a model as a URDF for RViz.

* :mod:`~manip_kin.core.urdf.document`: the XML read into a checked kinematic tree;
* :mod:`~manip_kin.core.urdf.chain`: a base-to-tip chain of that tree as a
  :class:`~manip_kin.core.model.RobotModel` (:func:`load_urdf`, :func:`load_urdf_string`);
* :mod:`~manip_kin.core.urdf.writer`: a model as a URDF with simple visuals (:func:`model_to_urdf`).

Loading walks the kinematic tree from a base link to a tip link:

* ``revolute`` and ``continuous`` joints become revolute joints (continuous ones get
  infinite position limits), ``prismatic`` joints stay prismatic;
* ``fixed`` joints are folded into the origin of the next movable joint, and the fixed
  joints after the last movable joint become the model's ``ee_offset``;
* ``floating`` and ``planar`` joints and ``<mimic>`` joints on the chain are rejected
  with a :class:`~manip_kin.errors.ModelFileError` naming the joint;
* a missing or zero ``<limit velocity>`` means "no limit given": the joint gets an
  infinite velocity limit (:func:`joints_without_velocity_limit` names them, so a caller
  can warn and supply limits);
* each model joint reports the frame of its URDF child link (``link_name``), so
  ``frame_pose(model, q, "panda_link4")`` works;
* an optional ``tool_link`` below the tip (fixed joints only) becomes the model's ``tool``.

Default tip link: starting at the base (default: the root), follow the only child joint of
each link. When a link has several child joints, follow the only one whose subtree holds a
movable joint (decorative fixed branches such as the UR ``base`` frame are skipped); stop
where no child, or more than one child, leads on to a movable joint. For the Franka Panda of
example-robot-data this stops at ``panda_hand``, where the two finger joints branch off,
so the model is the 7-DoF arm with ``ee`` at the hand flange (no fingers, no TCP). When the
tree branches into several movable chains before any movable joint (two arms on one base),
there is no default: the error lists the candidate tips and says to set ``tip_link``.
A gripper joint at the end of the default chain is left out: a movable joint whose name or
child link name contains ``gripper``, ``finger``, ``jaw`` or ``claw`` and below which
nothing moves (the Unitree Z1's single ``jointGripper``); the tip is then its parent link
(``gripperStator`` for the Z1, a 6-DoF arm). Name a tip below it to include it. For
the Panda TCP and the UR5 tool flange, name the tip::

    panda = load_urdf("panda.urdf", tip_link="panda_hand_tcp")
    ur5 = load_urdf("ur5_robot.urdf", base_link="base_link", tip_link="tool0")
"""

from manip_kin.core.urdf.chain import joints_without_velocity_limit, load_urdf, load_urdf_string
from manip_kin.core.urdf.writer import model_to_urdf, with_chain_hint

__all__ = [
    "joints_without_velocity_limit",
    "load_urdf",
    "load_urdf_string",
    "model_to_urdf",
    "with_chain_hint",
]
