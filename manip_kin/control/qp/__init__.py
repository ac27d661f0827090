"""The control law as a small QP every cycle, made of tasks and limits (mink/pink style).

* :mod:`~manip_kin.control.qp.tasks`: :class:`PoseTask` (today's resolved-rate law as the cost),
  :class:`PostureTask` (a joint reference in the pose task's null space), :class:`JointTask`
  (the joint tracking law as the cost, for joint references and jogs);
* :mod:`~manip_kin.control.qp.limits`: :class:`PositionLimit`, :class:`VelocityLimit`,
  :class:`AccelerationLimit` (boxes on q̇) and :class:`CollisionLimit` (velocity-damper rows);
* :mod:`~manip_kin.control.qp.solver`: the daqp call;
* :mod:`~manip_kin.control.qp.law`: :class:`QpController`, its :class:`QpConfig`, :class:`QpOutput` (pose steps)
  and :class:`QpJointOutput` (joint steps);
* :mod:`~manip_kin.control.qp.blocked`: :func:`blocked_by` and :func:`joint_blocked_by`, "the goal is
  blocked by this pair".
"""
